//! Light for objects in Bevy: a package's irradiance tracks written into an image in the
//! layout of Bevy's `IrradianceVolume` (an ambient cube per cell), so that an ordinary
//! `Mesh3d` with a `StandardMaterial` standing on the terrain inside a `LightProbe` with
//! that volume is lit by the sky and the ground around it, frame by frame. The sun stays
//! Bevy's directional light, with Bevy's own shadows ([`sun_light`](crate::sun_light)).

use std::collections::HashMap;

use bevy::asset::{AssetId, Assets, RenderAssetUsages};
use bevy::ecs::prelude::*;
use bevy::image::{Image, ImageSampler};
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat, TextureUsages};

use vbim_player::Irradiance;

use crate::playback::{VbimPlayback, VbimStats};

/// An image for [`VbimPlayback::irradiance_volume`] over a grid of `nx × ny` cells (the
/// package's `irradiance_grid`; 32 × 32 by default): a 3D `Rgba16Float` texture of
/// nx × 2 × 3·ny texels, Bevy's layout of an irradiance volume one voxel high. Give it to
/// an `IrradianceVolume` (its `intensity`: [`lux_per_unit`](crate::lux_per_unit)`(SUN_LUX)`,
/// as the lightmap's exposure) on a `LightProbe` whose `Transform` spans the terrain: x
/// east across the map, z south, the voxels' height anywhere (the grid has one layer).
pub fn irradiance_volume_image(nx: u32, ny: u32) -> Image {
    let size = Extent3d {
        width: nx.max(1),
        height: 2,
        depth_or_array_layers: 3 * ny.max(1),
    };
    let texels = (size.width * size.height * size.depth_or_array_layers) as usize;
    let mut image = Image::new(
        size,
        TextureDimension::D3,
        vec![0; texels * 8],
        TextureFormat::Rgba16Float,
        RenderAssetUsages::default(),
    );
    image.texture_descriptor.usage = TextureUsages::TEXTURE_BINDING | TextureUsages::COPY_DST;
    image.sampler = ImageSampler::linear();
    image
}

/// The six faces of a voxel in Bevy's layout: (y offset, z slab, the face's normal in the
/// map frame, x east, y south, z up). Bevy's x, y, z (east, up, south) are the map's x, z,
/// y.
const FACES: [(u32, u32, [f32; 3]); 6] = [
    (0, 0, [1.0, 0.0, 0.0]),
    (1, 0, [-1.0, 0.0, 0.0]),
    (0, 1, [0.0, 0.0, 1.0]),
    (1, 1, [0.0, 0.0, -1.0]),
    (0, 2, [0.0, 1.0, 0.0]),
    (1, 2, [0.0, -1.0, 0.0]),
];

/// Writes each playback's shown light for objects into its irradiance volume image: each
/// cell's sky and bounce ([`vbim_player::Irradiance::sky_at`]) towards the six faces.
/// An answer equal to the one last written into the same image (a paused or held
/// display) is not written again: touching the image makes Bevy upload it anew.
pub(crate) fn write_irradiance_volumes(
    playbacks: Query<(Entity, &VbimPlayback, &VbimStats)>,
    mut images: ResMut<Assets<Image>>,
    mut written: Local<HashMap<Entity, (AssetId<Image>, Irradiance)>>,
) {
    written.retain(|e, _| playbacks.contains(*e));
    for (entity, p, stats) in &playbacks {
        let (Some(handle), Some(irr)) = (&p.irradiance_volume, &stats.irradiance) else {
            continue;
        };
        if written
            .get(&entity)
            .is_some_and(|(id, last)| *id == handle.id() && last == irr)
        {
            continue;
        }
        let Some(mut image) = images.get_mut(handle) else {
            continue;
        };
        let size = image.texture_descriptor.size;
        let (nx, ny) = (size.width, size.depth_or_array_layers / 3);
        let fits = image.texture_descriptor.format == TextureFormat::Rgba16Float
            && size.height == 2
            && size.depth_or_array_layers == 3 * ny
            && nx > 0
            && ny > 0;
        let Some(data) = image.data.as_mut().filter(|_| fits) else {
            continue;
        };
        for z in 0..ny {
            for x in 0..nx {
                let (u, v) = ((x as f32 + 0.5) / nx as f32, (z as f32 + 0.5) / ny as f32);
                for (dy, slab, n) in FACES {
                    let e = irr.sky_at(u, v, n);
                    let texel = (((slab * ny + z) * 2 + dy) * nx + x) as usize;
                    let px = [e[0], e[1], e[2], 1.0].map(|c| half::f16::from_f32(c.max(0.0)));
                    for (k, h) in px.iter().enumerate() {
                        data[texel * 8 + 2 * k..][..2].copy_from_slice(&h.to_le_bytes());
                    }
                }
            }
        }
        written.insert(entity, (handle.id(), irr.clone()));
    }
}
