// Light for objects: the shown irradiance grid (vbim_format::irradiance) and the function
// that evaluates it. `vbim_player::irradiance_wgsl(group, binding)` gives this text with
// the binding's numbers in place of GROUP and BINDING; bind `PackagePlayer::irradiance_buffer`
// there (read-only storage). Positions are lightmap coordinates (u east, v south, 0 to 1),
// normals unit vectors in the map frame (x east, y south, z up); the result is
// irradiance / π, linear RGB, in the lightmap's units.

struct VbimIrradianceCell {
    sun: vec4<f32>,
    sh: array<vec4<f32>, 9>,
}

struct VbimIrradiance {
    // cells along u, cells along v, slots in use, 0
    size: vec4<u32>,
    // each slot's weight (two frames of a weather, or of two during a fade)
    weight: vec4<f32>,
    // each slot's sun direction
    sun_dir: array<vec4<f32>, 4>,
    // slot s's cell (i, j) at s · nx · ny + j · nx + i
    cells: array<VbimIrradianceCell>,
}

@group(GROUP) @binding(BINDING) var<storage, read> vbim_irradiance_grid: VbimIrradiance;

fn vbim_irradiance_cell(c: u32, n: vec3<f32>, s: vec3<f32>, y: array<f32, 9>) -> vec3<f32> {
    // Indexed through variables: a value array cannot be indexed by a loop counter.
    var b = y;
    var e = vbim_irradiance_grid.cells[c].sun.rgb * max(dot(n, s), 0.0);
    for (var j = 0u; j < 9u; j++) {
        e += b[j] * vbim_irradiance_grid.cells[c].sh[j].rgb;
    }
    return e;
}

// What a surface at lightmap coordinates `uv` with unit normal `n` receives.
fn vbim_irradiance(uv: vec2<f32>, n: vec3<f32>) -> vec3<f32> {
    let size = vbim_irradiance_grid.size;
    let nx = size.x;
    let ny = size.y;
    let f = clamp(uv * vec2<f32>(f32(nx), f32(ny)) - 0.5, vec2<f32>(0.0), vec2<f32>(f32(nx - 1u), f32(ny - 1u)));
    let x0 = u32(floor(f.x));
    let y0 = u32(floor(f.y));
    let x1 = min(x0 + 1u, nx - 1u);
    let y1 = min(y0 + 1u, ny - 1u);
    let w = f - floor(f);
    let y = array<f32, 9>(
        0.2820948,
        0.4886025 * n.y,
        0.4886025 * n.z,
        0.4886025 * n.x,
        1.0925484 * n.x * n.y,
        1.0925484 * n.y * n.z,
        0.3153916 * (3.0 * n.z * n.z - 1.0),
        1.0925484 * n.x * n.z,
        0.5462742 * (n.x * n.x - n.y * n.y),
    );
    var e = vec3<f32>(0.0);
    for (var s = 0u; s < size.z; s++) {
        let base = s * nx * ny;
        let sd = vbim_irradiance_grid.sun_dir[s].xyz;
        let top = mix(
            vbim_irradiance_cell(base + y0 * nx + x0, n, sd, y),
            vbim_irradiance_cell(base + y0 * nx + x1, n, sd, y),
            w.x,
        );
        let bottom = mix(
            vbim_irradiance_cell(base + y1 * nx + x0, n, sd, y),
            vbim_irradiance_cell(base + y1 * nx + x1, n, sd, y),
            w.x,
        );
        e += vbim_irradiance_grid.weight[s] * mix(top, bottom, w.y);
    }
    return e;
}
