// Sky and debug lines: drawn with the frame bindings only.

// Sky: one full-screen triangle at the far plane (depth 0 in reversed-Z, the cleared depth),
// drawn after the opaque geometry with an Equal depth test: it shades only uncovered pixels.
struct SkyOut {
    // Invariant: the Equal depth test compares this depth (exactly 0) with the cleared buffer.
    @builtin(position) @invariant clip: vec4<f32>,
    @location(0) ndc: vec2<f32>,
};

@vertex
fn vs_sky(@builtin(vertex_index) i: u32) -> SkyOut {
    let xy = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u)) * 2.0 - 1.0;
    var out: SkyOut;
    out.clip = vec4<f32>(xy, 0.0, 1.0);
    out.ndc = xy;
    return out;
}

@fragment
fn fs_sky(in: SkyOut) -> @location(0) vec4<f32> {
    let far = frame.rel_from_clip * vec4<f32>(in.ndc, 0.5, 1.0);
    let dir = normalize(far.xyz / far.w);
    var color = sky_color(dir);
    // Sun disc.
    let s = max(dot(dir, frame.sun_dir.xyz), 0.0);
    color = color + frame.sun_color.rgb * pow(s, 800.0) * 4.0;
    return vec4<f32>(color, 1.0);
}

// Node bounds (debug): line list of camera-relative box corners, one colour.
@vertex
fn vs_lines(@location(0) rel: vec3<f32>) -> @builtin(position) vec4<f32> {
    return frame.clip_from_rel * vec4<f32>(rel, 1.0);
}

@fragment
fn fs_lines() -> @location(0) vec4<f32> {
    return vec4<f32>(1.0, 0.9, 0.1, 1.0);
}
