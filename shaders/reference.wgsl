// The GPU-timing reference: triangles already at camera-relative positions, one flat colour,
// no node uniforms, no textures (see render/reference.rs).

@vertex
fn vs_reference(@location(0) rel: vec3<f32>) -> @builtin(position) vec4<f32> {
    return frame.clip_from_rel * vec4<f32>(rel, 1.0);
}

@fragment
fn fs_reference() -> @location(0) vec4<f32> {
    return vec4<f32>(0.5, 0.5, 0.5, 1.0);
}
