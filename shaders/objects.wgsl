// Progressive-mesh objects (engine::render::objects): per instance an index list at the level
// the pixel metric chose, drawn from pooled pages by multi-draws; the instance index names the
// draw's entry in `draws`. Positions are model units; the entry places them relative to the
// camera.

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
    // Texture cache: x, y the mip level resident for the facade and the roof
    // texture (-1: none, the mean colours in `albedo` and `roof_albedo` stand in); z 1 to tint
    // by that level (debug view); w 1 for a merged far mesh (the vertices carry the colour).
    tex: vec4<f32>,
    // rgb: the roof's albedo where no roof texture level is resident.
    roof_albedo: vec4<f32>,
    // x: the model's first vertex in the shared vertex buffer (vertex_index counts from there);
    // y: the instance's first entry in its morph page.
    pool: vec4<u32>,
};

@group(2) @binding(0) var<storage, read> draws: array<Draw>;
// The instance's facade and roof textures as the texture cache holds them (their resident
// level is their level 0 here; a white 1 x 1 texture when none is resident).
@group(2) @binding(1) var facade_tex: texture_2d<f32>;
@group(2) @binding(2) var roof_tex: texture_2d<f32>;
@group(2) @binding(3) var tex_sampler: sampler;
// A morph page: per morphing instance, for each of its vertices, the position and normal of the
// vertex it collapses onto (two entries per vertex, from the instance's `pool.y`).
@group(3) @binding(0) var<storage, read> morph_to: array<vec4<f32>>;

struct ObjectIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    // Texture coordinates in metres (0 for models without).
    @location(2) uv: vec2<f32>,
};

// The prelude's `VertexOut` plus the texture coordinates.
struct ObjectOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) rel: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) albedo: vec3<f32>,
    @location(3) @interpolate(flat) fade: vec3<f32>,
    @location(4) light: vec4<f32>,
    @location(5) uv: vec2<f32>,
    @location(6) @interpolate(flat) draw_index: u32,
};

@vertex
fn vs_main(
    v: ObjectIn,
    @builtin(vertex_index) vertex: u32,
    @builtin(instance_index) k: u32,
) -> ObjectOut {
    let draw = draws[k];
    var out: ObjectOut;
    out.draw_index = k;
    var p = v.position;
    var n = v.normal;
    // The wedge within the model.
    let vi = vertex - draw.pool.x;
    if (f32(vi) >= draw.morph.x && f32(vi) < draw.morph.y) {
        // Growing out: from the parent (t = 0) to the vertex; shrinking: the other way.
        let t = select(1.0 - draw.morph.z, draw.morph.z, draw.morph.w > 0.5);
        let at = draw.pool.y + 2u * vi;
        p = mix(morph_to[at].xyz, p, t);
        n = mix(morph_to[at + 1u].xyz, n, t);
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
    out.light = node_light(node, local, max(rel.z - draw.base_rel.z, 0.0));
    out.uv = v.uv;
    return out;
}

// Debug colour of a resident mip level: red (full resolution), orange, yellow, green, cyan,
// blue, violet (level 6 and coarser); grey where nothing is resident.
fn mip_color(level: f32) -> vec3<f32> {
    if (level < 0.0) {
        return vec3<f32>(0.3);
    }
    let colors = array<vec3<f32>, 7>(
        vec3<f32>(0.9, 0.05, 0.05),
        vec3<f32>(0.9, 0.4, 0.05),
        vec3<f32>(0.85, 0.8, 0.05),
        vec3<f32>(0.1, 0.75, 0.1),
        vec3<f32>(0.05, 0.7, 0.8),
        vec3<f32>(0.1, 0.2, 0.9),
        vec3<f32>(0.5, 0.1, 0.8),
    );
    return colors[min(u32(level), 6u)];
}

// A node's merged far mesh (HLOD): node-relative positions, flat normals, vertex colours.
struct HlodIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) color: vec3<f32>,
};

@vertex
fn vs_hlod(v: HlodIn, @builtin(instance_index) k: u32) -> ObjectOut {
    let draw = draws[k];
    var out: ObjectOut;
    out.draw_index = k;
    let rel = (draw.rel_from_model * vec4<f32>(v.position, 1.0)).xyz;
    out.rel = rel;
    out.clip = frame.clip_from_rel * vec4<f32>(rel, 1.0);
    out.normal = v.normal;
    out.albedo = v.color;
    out.fade = draw.fade.xyz;
    var node: Node;
    node.light = draw.light;
    let local = draw.base_local.xy + (rel.xy - draw.base_rel.xy);
    out.light = node_light(node, local, max(rel.z - draw.base_rel.z, 0.0));
    out.uv = vec2<f32>(0.0);
    return out;
}

@fragment
fn fs_main(in: ObjectOut) -> @location(0) vec4<f32> {
    let draw = draws[in.draw_index];
    // Both sampled in uniform control flow; the face's normal picks one.
    let uv = in.uv / TEXTURE_TILE_M;
    let facade = textureSample(facade_tex, tex_sampler, uv).rgb;
    let roof = textureSample(roof_tex, tex_sampler, uv).rgb;
    let up = normalize(in.normal).z > ROOF_NORMAL_UP;
    let level = select(draw.tex.x, draw.tex.y, up);
    var albedo = select(in.albedo, draw.roof_albedo.rgb, up);
    if (level >= 0.0) {
        albedo = select(facade, roof, up);
    }
    if (draw.tex.w > 0.5) {
        albedo = in.albedo;
    }
    if (draw.tex.z > 0.5) {
        albedo = mip_color(level);
    }
    return lit_pixel(VertexOut(in.clip, in.rel, in.normal, albedo, in.fade, in.light));
}
