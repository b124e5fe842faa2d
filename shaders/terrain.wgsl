// Terrain nodes: camera-relative positions, reversed-Z, sun + sky ambient shading, ground-type
// colours, distance fog for depth cueing, screen-door dither cross-fades between levels.
// `Frame` and `Node` mirror `engine::render::gpu_data::{FrameUniforms, NodeUniforms}`.

struct Frame {
    // Clip space from camera-relative world space (world axes, camera at the origin).
    clip_from_rel: mat4x4<f32>,
    // Inverse of `clip_from_rel` (for sky directions).
    rel_from_clip: mat4x4<f32>,
    // xyz: unit direction towards the sun; w: unused.
    sun_dir: vec4<f32>,
    // rgb: sun colour (linear); w: unused.
    sun_color: vec4<f32>,
    sky_zenith: vec4<f32>,
    sky_horizon: vec4<f32>,
    // x: fog density per metre, y: largest fog amount, z: debug mode, w: unused.
    fog: vec4<f32>,
};

struct Node {
    // xyz: node origin minus camera (m); w: dither interval start.
    offset_lo: vec4<f32>,
    // x: dither interval end, y: quad-tree level, z: 1 for skirts-as-surface debug, w: unused.
    hi_level: vec4<f32>,
};

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> ground_colors: array<vec4<f32>, 256>;
@group(1) @binding(0) var<uniform> node: Node;

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) ground: u32,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) rel: vec3<f32>,
    @location(1) normal: vec3<f32>,
    // Ground colour looked up per vertex and interpolated, so type borders blend.
    @location(2) albedo: vec3<f32>,
};

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    var out: VertexOut;
    let rel = v.position + node.offset_lo.xyz;
    out.clip = frame.clip_from_rel * vec4<f32>(rel, 1.0);
    out.rel = rel;
    out.normal = v.normal;
    out.albedo = ground_colors[min(v.ground, 255u)].rgb;
    return out;
}

// 8 x 8 ordered-dither threshold in [0, 1): each pixel belongs to exactly one node of a fade.
fn bayer8(p: vec2<u32>) -> f32 {
    var v = 0u;
    var x = p.x;
    var y = p.y;
    for (var bit = 0u; bit < 3u; bit = bit + 1u) {
        let bx = x & 1u;
        let by = y & 1u;
        v = (v << 2u) | ((bx ^ by) << 1u) | by;
        x = x >> 1u;
        y = y >> 1u;
    }
    // The lowest coordinate bits end up as the most significant digit (classic Bayer order).
    return (f32(v) + 0.5) / 64.0;
}

// Whether this node draws the pixel at `xy` (its dither interval holds the pixel's threshold).
fn in_dither(xy: vec2<f32>) -> bool {
    let t = bayer8(vec2<u32>(xy));
    return t >= node.offset_lo.w && t < node.hi_level.x;
}

// Distance fog towards the sky colour (depth cue, capped).
fn fogged(color: vec3<f32>, rel: vec3<f32>) -> vec4<f32> {
    let fog = min(1.0 - exp(-length(rel) * frame.fog.x), frame.fog.y);
    return vec4<f32>(mix(color, sky_color(normalize(rel)), fog), 1.0);
}

fn level_color(level: f32) -> vec3<f32> {
    let t = level * 0.61803;
    return 0.5 + 0.45 * cos(6.28318 * (vec3<f32>(t) + vec3<f32>(0.0, 0.33, 0.67)));
}

fn sky_color(dir: vec3<f32>) -> vec3<f32> {
    let up = clamp(dir.z, 0.0, 1.0);
    return mix(frame.sky_horizon.rgb, frame.sky_zenith.rgb, pow(up, 0.6));
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    if (!in_dither(in.clip.xy)) {
        discard;
    }
    let mode = u32(frame.fog.z + 0.5);
    var albedo = in.albedo;
    if (mode == 1u) {
        albedo = level_color(node.hi_level.y);
    }
    let n = normalize(in.normal);
    let sun = max(dot(n, frame.sun_dir.xyz), 0.0);
    let ambient = mix(frame.sky_horizon.rgb * 0.35, frame.sky_zenith.rgb * 0.6, 0.5 + 0.5 * n.z);
    return fogged(albedo * (frame.sun_color.rgb * sun + ambient), in.rel);
}

// Sky: one full-screen triangle at the far plane (depth 0 in reversed-Z), drawn first.
struct SkyOut {
    @builtin(position) clip: vec4<f32>,
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

// Vegetation. Per-species looks: rgb foliage colour (linear), w: shape (0 conifer, 1 broadleaf,
// 2 bush, 3 grass). Instances carry the position relative to the node's south-west corner (z
// absolute), height, crown radius, yaw and look index.
@group(0) @binding(2) var<uniform> plant_looks: array<vec4<f32>, 16>;

struct PlantInstanceIn {
    @location(3) position: vec3<f32>,
    @location(4) height: f32,
    @location(5) radius: f32,
    @location(6) yaw: f32,
    @location(7) look: u32,
};

const TRUNK: vec3<f32> = vec3<f32>(0.16, 0.11, 0.07);

// Instanced unit-shape meshes (height 1, radius 1), scaled, turned and placed per instance.
@vertex
fn vs_plant(v: VertexIn, inst: PlantInstanceIn) -> VertexOut {
    let c = cos(inst.yaw);
    let s = sin(inst.yaw);
    let local = vec3<f32>(v.position.xy * inst.radius, v.position.z * inst.height);
    let turned = vec3<f32>(c * local.x - s * local.y, s * local.x + c * local.y, local.z);
    let n = vec3<f32>(v.normal.xy / inst.radius, v.normal.z / inst.height);
    var out: VertexOut;
    let rel = inst.position + turned + node.offset_lo.xyz;
    out.clip = frame.clip_from_rel * vec4<f32>(rel, 1.0);
    out.rel = rel;
    out.normal = normalize(vec3<f32>(c * n.x - s * n.y, s * n.x + c * n.y, n.z));
    let look = plant_looks[min(inst.look, 15u)];
    out.albedo = select(look.rgb, TRUNK, v.ground == 0u);
    return out;
}

struct BillboardOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) rel: vec3<f32>,
    // x in [-1, 1] across, y in [0, 1] up.
    @location(1) uv: vec2<f32>,
    @location(2) @interpolate(flat) look: u32,
};

// Billboard images: one tile per look (species), baked at start-up from the plant meshes
// (`vs_bake` / `fs_bake`): linear colour lit from the front, alpha = coverage.
const ATLAS_TILES: f32 = 16.0;
@group(2) @binding(0) var atlas: texture_2d<f32>;
@group(2) @binding(1) var atlas_sampler: sampler;

// Camera-facing (about the vertical axis) quads: 6 vertices per instance, no vertex buffer.
@vertex
fn vs_billboard(@builtin(vertex_index) i: u32, inst: PlantInstanceIn) -> BillboardOut {
    let corner = array<vec2<f32>, 6>(
        vec2<f32>(-1.0, 0.0), vec2<f32>(1.0, 0.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(-1.0, 0.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
    )[i % 6u];
    let base = inst.position + node.offset_lo.xyz;
    let flat_dir = vec2<f32>(base.x, base.y);
    let len = max(length(flat_dir), 1e-3);
    let right = vec3<f32>(-flat_dir.y / len, flat_dir.x / len, 0.0);
    let rel = base + right * (corner.x * inst.radius) + vec3<f32>(0.0, 0.0, corner.y * inst.height);
    var out: BillboardOut;
    out.clip = frame.clip_from_rel * vec4<f32>(rel, 1.0);
    out.rel = rel;
    out.uv = corner;
    out.look = min(inst.look, 15u);
    return out;
}

@fragment
fn fs_billboard(in: BillboardOut) -> @location(0) vec4<f32> {
    let uv = vec2<f32>((f32(in.look) + 0.5 + 0.5 * in.uv.x) / ATLAS_TILES, 1.0 - in.uv.y);
    return billboard_pixel(in, uv);
}

// A billboard or impostor pixel: dither test, atlas texel at `uv` with an alpha test, fog.
fn billboard_pixel(in: BillboardOut, uv: vec2<f32>) -> vec4<f32> {
    if (!in_dither(in.clip.xy)) {
        discard;
    }
    let texel = textureSampleLevel(atlas, atlas_sampler, uv, 0.0);
    if (texel.a < 0.5) {
        discard;
    }
    return fogged(texel.rgb, in.rel);
}

// Baking the billboard images: the unit shape of look `inst.look` seen from the south (-y),
// orthographic, x in [-1, 1] and z in [0, 1] filling the tile (the viewport picks the tile).
struct BakeOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) albedo: vec3<f32>,
};

@vertex
fn vs_bake(v: VertexIn, inst: PlantInstanceIn) -> BakeOut {
    var out: BakeOut;
    // Depth: nearer to the viewer (smaller y) is larger, as in the reversed-Z main pass.
    out.clip = vec4<f32>(v.position.x, v.position.z * 2.0 - 1.0, 0.5 - 0.5 * v.position.y, 1.0);
    out.normal = v.normal;
    let look = plant_looks[min(inst.look, 15u)];
    out.albedo = select(look.rgb, TRUNK, v.ground == 0u);
    return out;
}

@fragment
fn fs_bake(in: BakeOut) -> @location(0) vec4<f32> {
    let n = normalize(in.normal);
    let sun = max(dot(n, frame.sun_dir.xyz), 0.0);
    let ambient = mix(frame.sky_horizon.rgb * 0.35, frame.sky_zenith.rgb * 0.6, 0.5 + 0.5 * n.z);
    return vec4<f32>(in.albedo * (frame.sun_color.rgb * sun + ambient), 1.0);
}

// Group billboards: per node, the group members of each cluster (an 8 x 8 grid over the node)
// are baked into one tile of the node's 8 x 8 impostor texture, seen from the south; the
// clusters are then drawn as camera-facing quads sampling their tile.
struct Cluster {
    // x, y: centre relative to the node's south-west corner; z: bottom (absolute); w: half width.
    centre_bottom_half: vec4<f32>,
    // x: height; yzw: unused.
    height: vec4<f32>,
};
const CLUSTERS_PER_SIDE: u32 = 8u;
@group(1) @binding(1) var<uniform> clusters: array<Cluster, 64>;

struct GroupBakeOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
    @location(1) @interpolate(flat) look: u32,
};

// One member billboard (species `look`, cluster index in `cluster`) into its cluster's tile.
@vertex
fn vs_group_bake(
    @builtin(vertex_index) i: u32,
    inst: PlantInstanceIn,
    @location(8) cluster: u32,
) -> GroupBakeOut {
    let corner = array<vec2<f32>, 6>(
        vec2<f32>(-1.0, 0.0), vec2<f32>(1.0, 0.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(-1.0, 0.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
    )[i % 6u];
    let c = clusters[min(cluster, 63u)];
    let cb = c.centre_bottom_half;
    let u = (inst.position.x + corner.x * inst.radius - cb.x) / cb.w;
    let h = (inst.position.z + corner.y * inst.height - cb.z) / max(c.height.x, 1e-3);
    let n = f32(CLUSTERS_PER_SIDE);
    let tile = vec2<f32>(f32(cluster % CLUSTERS_PER_SIDE), f32(cluster / CLUSTERS_PER_SIDE));
    let x = ((tile.x + 0.5 + 0.5 * u) / n) * 2.0 - 1.0;
    let y = 1.0 - ((tile.y + 1.0 - h) / n) * 2.0;
    let depth = 0.5 - 0.5 * clamp((inst.position.y - cb.y) / cb.w, -1.0, 1.0);
    var out: GroupBakeOut;
    out.clip = vec4<f32>(x, y, depth, 1.0);
    out.uv = corner;
    out.look = min(inst.look, 15u);
    return out;
}

@fragment
fn fs_group_bake(in: GroupBakeOut) -> @location(0) vec4<f32> {
    let uv = vec2<f32>((f32(in.look) + 0.5 + 0.5 * in.uv.x) / ATLAS_TILES, 1.0 - in.uv.y);
    let texel = textureSampleLevel(atlas, atlas_sampler, uv, 0.0);
    if (texel.a < 0.5) {
        discard;
    }
    return vec4<f32>(texel.rgb, 1.0);
}

// Drawing the clusters: `look` holds the cluster's tile index.
@fragment
fn fs_impostor(in: BillboardOut) -> @location(0) vec4<f32> {
    let tile = vec2<f32>(f32(in.look % CLUSTERS_PER_SIDE), f32(in.look / CLUSTERS_PER_SIDE));
    let uv = (tile + vec2<f32>(0.5 + 0.5 * in.uv.x, 1.0 - in.uv.y)) / f32(CLUSTERS_PER_SIDE);
    return billboard_pixel(in, uv);
}
