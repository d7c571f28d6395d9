//! `.vbim` files and packages (`.vbimpkg`: weathers, each a lightmap and a sky track) as
//! Bevy assets. The asset is the stream's header and where its file is: the chunks stay on
//! disk and the player reads them through its ring while it plays, so loading a day of
//! lighting costs a few hundred bytes of main-world memory, not the file.

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use bevy::asset::io::file::FileAssetReader;
use bevy::asset::io::{AssetSourceId, Reader};
use bevy::asset::{Asset, AssetLoader, LoadContext, RenderAssetUsages};
use bevy::image::{Image, ImageSampler};
use bevy::reflect::TypePath;
use bevy::render::render_resource::{
    Extent3d, TextureDimension, TextureFormat, TextureUsages, TextureViewDescriptor,
    TextureViewDimension,
};
use vbim_format::{Header, Reader as StreamReader};

/// A `.vbim` stream or a package of weathers: the (first weather's) lightmap header,
/// checked with its index when it was loaded, and the file the player streams it from.
#[derive(Asset, TypePath, Clone, Debug)]
pub struct VbimStream {
    path: Arc<PathBuf>,
    header: Header,
    metadata: Option<Arc<str>>,
    /// The package's weathers (a plain file: one).
    weathers: Arc<[String]>,
    /// The sky tracks' size, when the package has them.
    sky: Option<(u32, u32)>,
    /// The irradiance grid's cells, when the package has irradiance tracks.
    grid: Option<(u32, u32)>,
}

/// Why a stream could not be loaded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StreamError {
    /// The file could not be opened.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the system said.
        source: std::io::Error,
    },
    /// The header or index is invalid (the error names what).
    #[error("{path}: {source}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        source: vbim_format::FormatError,
    },
    /// A package that cannot be played (the error names the package or track file).
    #[error("{0}")]
    Package(String),
    /// The asset does not come from the file system (the player streams from a file).
    #[error("{0}: vbim streams play from files; this asset source is not the file system")]
    NotAFile(String),
}

impl VbimStream {
    /// Opens the stream at `path` and validates its header and index (what
    /// [`AssetServer::load`](bevy::asset::AssetServer::load) does for a `.vbim` asset), for
    /// streams outside the asset folder: add the result to `Assets<VbimStream>`.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, StreamError> {
        let path = path.as_ref().to_path_buf();
        let io = |source| StreamError::Io {
            path: path.clone(),
            source,
        };
        let mut magic = [0u8; 8];
        let is_file = std::io::Read::read_exact(&mut File::open(&path).map_err(io)?, &mut magic)
            .is_ok()
            && magic == vbim_format::MAGIC;
        // A package: its tracks share one timeline (checked); the first weather's lightmap
        // stands for it (its header and the bake's manifest).
        let (lightmap, weathers, sky, grid) = if is_file {
            (
                path.clone(),
                vec![vbim_format::package::SINGLE_WEATHER.to_string()],
                None,
                None,
            )
        } else {
            let p = vbim_player::PackageFile::open(&path)
                .map_err(|e| StreamError::Package(e.to_string()))?;
            let sky = p
                .tracks
                .iter()
                .find(|t| t.kind == vbim_player::TrackKind::Sky)
                .map(|t| (t.header.width, t.header.height));
            let grid = p
                .tracks
                .iter()
                .find(|t| t.kind == vbim_player::TrackKind::Irradiance)
                .and_then(|t| {
                    vbim_format::irradiance::cells_of(
                        t.header.width as usize,
                        t.header.height as usize,
                    )
                })
                .map(|(nx, ny)| (nx as u32, ny as u32));
            let names = p.package.weathers.iter().map(|w| w.name.clone()).collect();
            (p.tracks[0].path.clone(), names, sky, grid)
        };
        let file = File::open(&lightmap).map_err(|source| StreamError::Io {
            path: lightmap.clone(),
            source,
        })?;
        let format = |source| StreamError::Format {
            path: lightmap.clone(),
            source,
        };
        let mut reader = StreamReader::open(BufReader::new(file)).map_err(format)?;
        // The metadata chunk is small (the format bounds it) and read once, here.
        let metadata = reader.metadata().map_err(format)?.map(Arc::from);
        Ok(VbimStream {
            header: reader.header().clone(),
            path: Arc::new(path),
            metadata,
            weathers: weathers.into(),
            sky,
            grid,
        })
    }

    /// The weathers a [`VbimPlayback`](crate::VbimPlayback) can switch between, in the
    /// package's order (a plain `.vbim` file has one).
    pub fn weathers(&self) -> &[String] {
        &self.weathers
    }

    /// An image the sky track can be written into (see [`lightmap_image`]), when the
    /// package has sky tracks: the sky's radiance over the upper hemisphere, equirectangular,
    /// the zenith's row first, column 0 towards north (map frame −y, Bevy's −z), in the
    /// lightmap's units.
    pub fn sky_image(&self) -> Option<Image> {
        self.sky.map(|(w, h)| lightmap_image(w, h))
    }

    /// An image for [`VbimPlayback::irradiance_volume`](crate::VbimPlayback) of the
    /// package's irradiance grid ([`irradiance_volume_image`](crate::irradiance_volume_image)),
    /// when the package has irradiance tracks.
    pub fn irradiance_volume_image(&self) -> Option<Image> {
        self.grid
            .map(|(nx, ny)| crate::irradiance_volume_image(nx, ny))
    }

    /// The stream's header: size, channels, frame rate, frame count, looping.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The stream's metadata: for a stream of `vbim bake` frames, the bake's manifest
    /// (JSON: the sun's direction and colour and the sky's colours for every frame).
    pub fn metadata(&self) -> Option<&str> {
        self.metadata.as_deref()
    }

    /// The file the player streams from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    pub(crate) fn shared_path(&self) -> Arc<PathBuf> {
        self.path.clone()
    }

    /// An image the player can write this stream into: see [`lightmap_image`].
    pub fn lightmap_image(&self) -> Image {
        lightmap_image(self.header.width, self.header.height)
    }

    /// The length of one pass through the day at the stream's own rate.
    pub fn duration(&self) -> std::time::Duration {
        let ns = self.header.frame_count as u128 * 1_000_000_000 * self.header.rate_den as u128
            / self.header.rate_num.max(1) as u128;
        std::time::Duration::from_nanos(ns.min(u64::MAX as u128) as u64)
    }
}

/// A `width × height` image for a stream to play into: `Rgba16Float`, linear, sampled with
/// linear filtering, with the usages the player needs (`STORAGE_BINDING` to write it,
/// `TEXTURE_BINDING` to sample it and to keep the image on screen while it catches up) and
/// `COPY_SRC` for captures. Its texels live only on the GPU: nothing is uploaded from the
/// CPU, ever.
pub fn lightmap_image(width: u32, height: u32) -> Image {
    let mut image = Image::new_uninit(
        Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        TextureFormat::Rgba16Float,
        RenderAssetUsages::RENDER_WORLD,
    );
    image.texture_descriptor.usage = TextureUsages::STORAGE_BINDING
        | TextureUsages::TEXTURE_BINDING
        | TextureUsages::COPY_SRC
        | TextureUsages::COPY_DST;
    image.sampler = ImageSampler::linear();
    image
}

/// A cube map of `size`² faces for a package's sky ([`VbimPlayback::sky_cube`]):
/// `Rgba16Float`, linear, viewed as a cube (Bevy's `Skybox` samples it as it is), with the
/// usages the player needs to write it. Its faces look along (east, up, north) in the
/// bake's frame, which is Bevy's world with x east, y up and z south (the terrain
/// example's): the skybox's own z flip puts north at −z. 64 is plenty for a 128 × 32 sky.
///
/// [`VbimPlayback::sky_cube`]: crate::VbimPlayback::sky_cube
pub fn sky_cube_image(size: u32) -> Image {
    let mut image = Image::new_uninit(
        Extent3d {
            width: size,
            height: size,
            depth_or_array_layers: 6,
        },
        TextureDimension::D2,
        TextureFormat::Rgba16Float,
        RenderAssetUsages::RENDER_WORLD,
    );
    image.texture_descriptor.usage =
        TextureUsages::STORAGE_BINDING | TextureUsages::TEXTURE_BINDING | TextureUsages::COPY_SRC;
    image.texture_view_descriptor = Some(TextureViewDescriptor {
        dimension: Some(TextureViewDimension::Cube),
        ..Default::default()
    });
    image.sampler = ImageSampler::linear();
    image
}

/// Loads `.vbim` files from the asset folder: reads the header and index (checking the
/// index's checksum and every entry), never the chunks.
#[derive(TypePath)]
pub(crate) struct VbimLoader {
    /// The asset folder on disk (`AssetPlugin::file_path` under Bevy's base path).
    pub(crate) root: PathBuf,
}

impl VbimLoader {
    pub(crate) fn new(asset_folder: &str) -> Self {
        VbimLoader {
            root: FileAssetReader::get_base_path().join(asset_folder),
        }
    }
}

impl AssetLoader for VbimLoader {
    type Asset = VbimStream;
    type Settings = ();
    type Error = StreamError;

    async fn load(
        &self,
        _reader: &mut dyn Reader,
        _settings: &(),
        ctx: &mut LoadContext<'_>,
    ) -> Result<VbimStream, StreamError> {
        let asset = ctx.path();
        if !matches!(asset.source(), AssetSourceId::Default) {
            return Err(StreamError::NotAFile(asset.to_string()));
        }
        // The player reads the file on a thread of its own while it plays, so the asset
        // keeps the path, not Bevy's reader. Header and index are small: read them here,
        // blocking this IO task briefly, with the same validation the player applies.
        VbimStream::open(self.root.join(asset.path()))
    }

    fn extensions(&self) -> &[&str] {
        &["vbim", "vbimpkg"]
    }
}
