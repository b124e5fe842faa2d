// Progressive-mesh objects (engine::render::objects): one draw per instance, its index list at
// the level the pixel metric chose. Positions are model units; the per-draw uniform places them
// relative to the camera.

struct Draw {
    // Camera-relative world position from model position (affine; f64 on the CPU, then f32).
    rel_from_model: mat4x4<f32>,
    // World normal from model normal (rotation; uniform scale divided out).
    normal_from_model: mat4x4<f32>,
    // x, y: the node's dither interval; z: the node's level; w: 1 to colour by the PM level.
    fade: vec4<f32>,
    // rgb: albedo, or the level colour when fade.w is 1; w: unused.
    albedo: vec4<f32>,
};

@group(2) @binding(0) var<uniform> draw: Draw;

struct ObjectIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
};

@vertex
fn vs_main(v: ObjectIn) -> VertexOut {
    var out: VertexOut;
    let rel = (draw.rel_from_model * vec4<f32>(v.position, 1.0)).xyz;
    out.rel = rel;
    out.clip = frame.clip_from_rel * vec4<f32>(rel, 1.0);
    out.normal = normalize((draw.normal_from_model * vec4<f32>(v.normal, 0.0)).xyz);
    out.albedo = draw.albedo.rgb;
    out.fade = draw.fade.xyz;
    out.light = vec2<f32>(1.0, 1.0);
    return out;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    return lit_pixel(in);
}
