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
    // Geomorph: vertices with index in [x, y) move between their position and `morph_to`'s
    // (the vertex they collapse onto): z the progress in [0, 1], w 1 when growing out
    // (refining), 0 when shrinking in (coarsening).
    morph: vec4<f32>,
    // The drawing node's light grid (`Node.light`, see the prelude).
    light: vec4<f32>,
    // xy: the instance's base relative to the node's south-west corner (m).
    base_local: vec4<f32>,
    // xyz: the instance's base relative to the camera (m).
    base_rel: vec4<f32>,
};

@group(2) @binding(0) var<uniform> draw: Draw;
// Per instance: for each morphing vertex, the position and normal of the vertex it collapses
// onto (two entries per vertex).
@group(3) @binding(0) var<storage, read> morph_to: array<vec4<f32>>;

struct ObjectIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
};

@vertex
fn vs_main(v: ObjectIn, @builtin(vertex_index) vi: u32) -> VertexOut {
    var out: VertexOut;
    var p = v.position;
    var n = v.normal;
    if (f32(vi) >= draw.morph.x && f32(vi) < draw.morph.y) {
        // Growing out: from the parent (t = 0) to the vertex; shrinking: the other way.
        let t = select(1.0 - draw.morph.z, draw.morph.z, draw.morph.w > 0.5);
        p = mix(morph_to[2u * vi].xyz, p, t);
        n = mix(morph_to[2u * vi + 1u].xyz, n, t);
    }
    let rel = (draw.rel_from_model * vec4<f32>(p, 1.0)).xyz;
    out.rel = rel;
    out.clip = frame.clip_from_rel * vec4<f32>(rel, 1.0);
    out.normal = normalize((draw.normal_from_model * vec4<f32>(n, 0.0)).xyz);
    out.albedo = draw.albedo.rgb;
    out.fade = draw.fade.xyz;
    // Light-grid samples at the vertex: across the node from the base, height above the base.
    var node: Node;
    node.light = draw.light;
    let local = draw.base_local.xy + (rel.xy - draw.base_rel.xy);
    out.light = light_at(light_coords(node, local, max(rel.z - draw.base_rel.z, 0.0)));
    return out;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    return lit_pixel(in);
}
