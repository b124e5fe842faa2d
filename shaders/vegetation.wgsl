// Vegetation: instanced plant meshes, billboards sampling the species atlas, and group
// billboards (per-node impostors); the two bakes that make the atlas and the impostors.
// `MAX_LOOKS`, `ATLAS_TILES`, `CLUSTERS_PER_SIDE` and `CLUSTER_COUNT` come from the renderer
// (`engine::render::vegetation`), so Rust and WGSL share one definition.

// Per-species looks: rgb foliage colour (linear), w: shape (0 conifer, 1 broadleaf,
// 2 bush, 3 grass). Instances (`PlantInstanceIn`, in the prelude) carry the look index.
@group(2) @binding(2) var<uniform> plant_looks: array<vec4<f32>, MAX_LOOKS>;

const TRUNK: vec3<f32> = vec3<f32>(0.16, 0.11, 0.07);

// Instanced unit-shape meshes (height 1, radius 1), scaled, turned and placed per instance.
@vertex
fn vs_plant(v: VertexIn, inst: PlantInstanceIn) -> VertexOut {
    let node = nodes[row_of_entry[inst.entry]];
    let turned = plant_offset(v.position, inst);
    let c = cos(inst.yaw);
    let s = sin(inst.yaw);
    let n = vec3<f32>(v.normal.xy / inst.radius, v.normal.z / inst.height);
    var out: VertexOut;
    let rel = inst.position + turned + node.offset_lo.xyz;
    out.clip = frame.clip_from_rel * vec4<f32>(rel, 1.0);
    out.rel = rel;
    out.normal = normalize(vec3<f32>(c * n.x - s * n.y, s * n.x + c * n.y, n.z));
    let look = plant_looks[min(inst.look, MAX_LOOKS - 1u)];
    out.albedo = select(look.rgb, TRUNK, v.tag == 0u);
    out.fade = node_fade(node);
    out.light = node_light(node, inst.position.xy + turned.xy, turned.z);
    return out;
}

struct BillboardOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) rel: vec3<f32>,
    // x in [-1, 1] across, y in [0, 1] up.
    @location(1) uv: vec2<f32>,
    @location(2) @interpolate(flat) look: u32,
    @location(3) @interpolate(flat) fade: vec3<f32>,
    // The light grid's values (`node_light`).
    @location(4) light: vec4<f32>,
    // Horizontal unit vector from the camera to the quad: the bake's north (the quad's x is
    // the bake's east turned to (-away.y, away.x)).
    @location(5) @interpolate(flat) away: vec2<f32>,
};

@fragment
fn fs_plant(in: VertexOut) -> @location(0) vec4<f32> {
    return lit_pixel(in);
}

// Billboard images: one tile per look (species), baked at start-up from the plant meshes
// (`vs_bake` / `fs_bake`): linear albedo with alpha = coverage, and the unit normals seen
// (x east, y north, z up, stored as n / 2 + 1/2 with alpha = coverage), so the quads are lit
// when drawn, by the frame's sun and their light grid, like the meshes. The impostor pipeline
// binds a node's impostor textures instead.
@group(2) @binding(0) var atlas: texture_2d<f32>;
@group(2) @binding(1) var atlas_sampler: sampler;
@group(2) @binding(5) var atlas_normals: texture_2d<f32>;

// Camera-facing (about the vertical axis) quads: 6 vertices per instance, no vertex buffer.
@vertex
fn vs_billboard(@builtin(vertex_index) i: u32, inst: PlantInstanceIn) -> BillboardOut {
    let corner = quad_corner(i);
    let node = nodes[row_of_entry[inst.entry]];
    let base = inst.position + node.offset_lo.xyz;
    let right = quad_right(base);
    let rel = quad_rel(base, corner, inst);
    var out: BillboardOut;
    out.clip = frame.clip_from_rel * vec4<f32>(rel, 1.0);
    out.rel = rel;
    out.uv = corner;
    out.look = inst.look;
    out.fade = node_fade(node);
    let local = inst.position.xy + right.xy * (corner.x * inst.radius);
    out.light = node_light(node, local, corner.y * inst.height);
    // The horizontal direction from the camera to the quad: `right` turned back a quarter
    // (exact, the same bits as dividing the direction by its length again).
    out.away = vec2<f32>(right.y, -right.x);
    return out;
}

@fragment
fn fs_billboard(in: BillboardOut) -> @location(0) vec4<f32> {
    let look = min(in.look, MAX_LOOKS - 1u);
    let uv = vec2<f32>((f32(look) + 0.5 + 0.5 * in.uv.x) / f32(ATLAS_TILES), 1.0 - in.uv.y);
    let texel = textureSampleLevel(atlas, atlas_sampler, uv, 0.0);
    let normal = textureSampleLevel(atlas_normals, atlas_sampler, uv, 0.0);
    return billboard_pixel(in, texel, normal);
}

// A billboard or impostor pixel: dither test, alpha test of its `texel`, then lit like a mesh
// with its baked `normal` turned to face the camera (both filtered against the bake's
// transparent background, so divided by their coverage).
fn billboard_pixel(in: BillboardOut, texel: vec4<f32>, normal: vec4<f32>) -> vec4<f32> {
    if (!in_dither(in.clip.xy, in.fade)) {
        discard;
    }
    if (texel.a < 0.5) {
        discard;
    }
    let baked = normal.xyz / max(normal.a, 1e-3) * 2.0 - 1.0;
    let right = vec3<f32>(-in.away.y, in.away.x, 0.0);
    let n = baked.x * right + baked.y * vec3<f32>(in.away, 0.0) + vec3<f32>(0.0, 0.0, baked.z);
    let albedo = texel.rgb / texel.a;
    return lit_color(VertexOut(in.clip, in.rel, n, albedo, in.fade, in.light));
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
    let look = plant_looks[min(inst.look, MAX_LOOKS - 1u)];
    out.albedo = select(look.rgb, TRUNK, v.tag == 0u);
    return out;
}

// What the two bakes write: albedo and coverage, the normal and coverage.
struct Baked {
    @location(0) albedo: vec4<f32>,
    @location(1) normal: vec4<f32>,
};

@fragment
fn fs_bake(in: BakeOut) -> Baked {
    let n = normalize(in.normal);
    return Baked(vec4<f32>(in.albedo, 1.0), vec4<f32>(n * 0.5 + 0.5, 1.0));
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
@group(1) @binding(1) var<uniform> clusters: array<Cluster, CLUSTER_COUNT>;

struct GroupBakeOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
    @location(1) @interpolate(flat) look: u32,
};

// One member billboard (species `look`, cluster index in `entry`) into its cluster's tile.
@vertex
fn vs_group_bake(@builtin(vertex_index) i: u32, inst: PlantInstanceIn) -> GroupBakeOut {
    let cluster = inst.entry;
    let corner = quad_corner(i);
    let c = clusters[min(cluster, CLUSTER_COUNT - 1u)];
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
    out.look = min(inst.look, MAX_LOOKS - 1u);
    return out;
}

@fragment
fn fs_group_bake(in: GroupBakeOut) -> Baked {
    let uv = vec2<f32>((f32(in.look) + 0.5 + 0.5 * in.uv.x) / f32(ATLAS_TILES), 1.0 - in.uv.y);
    let texel = textureSampleLevel(atlas, atlas_sampler, uv, 0.0);
    if (texel.a < 0.5) {
        discard;
    }
    let normal = textureSampleLevel(atlas_normals, atlas_sampler, uv, 0.0);
    return Baked(vec4<f32>(texel.rgb / texel.a, 1.0), vec4<f32>(normal.xyz / normal.a, 1.0));
}

// Drawing the clusters: each node's impostor texture is one layer of a texture array; `look`
// holds layer * CLUSTER_COUNT + the cluster's tile index.
@group(2) @binding(3) var impostors: texture_2d_array<f32>;
@group(2) @binding(4) var impostor_normals: texture_2d_array<f32>;

@fragment
fn fs_impostor(in: BillboardOut) -> @location(0) vec4<f32> {
    let layer = in.look / CLUSTER_COUNT;
    let t = in.look % CLUSTER_COUNT;
    let tile = vec2<f32>(f32(t % CLUSTERS_PER_SIDE), f32(t / CLUSTERS_PER_SIDE));
    let uv = (tile + vec2<f32>(0.5 + 0.5 * in.uv.x, 1.0 - in.uv.y)) / f32(CLUSTERS_PER_SIDE);
    let texel = textureSampleLevel(impostors, atlas_sampler, uv, layer, 0.0);
    let normal = textureSampleLevel(impostor_normals, atlas_sampler, uv, layer, 0.0);
    return billboard_pixel(in, texel, normal);
}
