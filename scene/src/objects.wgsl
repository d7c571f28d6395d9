// Objects on the terrain (spheres), lit by the package's light for objects: albedo ×
// vbim_irradiance at the object's lightmap coordinates, per pixel of its normal, tone-mapped
// as the terrain is. The scene's uniforms (uniforms.wgsl) and the irradiance buffer's
// declaration and function (vbim_player::irradiance_wgsl(1, 0)) are prepended.

struct ObjOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) uv: vec2<f32>,
    @location(2) albedo: vec3<f32>,
}

@vertex
fn vs_object(
    @location(0) p: vec3<f32>,
    @location(1) centre_radius: vec4<f32>,
    @location(2) uv: vec4<f32>,
    @location(3) albedo: vec4<f32>,
) -> ObjOut {
    var o: ObjOut;
    o.pos = u.view_proj * vec4<f32>(centre_radius.xyz + centre_radius.w * p, 1.0);
    o.normal = p;
    o.uv = uv.xy;
    o.albedo = albedo.rgb;
    return o;
}

@fragment
fn fs_object(i: ObjOut) -> @location(0) vec4<f32> {
    // The world (x east, y up, z south) to the map frame (x east, y south, z up).
    let n = normalize(vec3<f32>(i.normal.x, i.normal.z, i.normal.y));
    let c = i.albedo * max(vbim_irradiance(i.uv, n), vec3<f32>(0.0)) * u.params.x;
    return vec4<f32>(c / (vec3<f32>(1.0) + c), 1.0);
}
