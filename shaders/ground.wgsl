// A node's ground texture (engine::render::ground): one full-target triangle; each fragment is
// one texel of the node's layout (engine::ground::layout). Its colour: the texel's ground type
// (resolved on the CPU at a noise-perturbed position of the map's ground layer, natural borders
// instead of the 4 m staircase: engine::ground::types), shaded with that type's tiled material;
// then the
// node's closed areas (fields, dirt, rock patches) in file order, each as its box with an
// even-odd inside test and a soft edge; then its road and path segments with soft edges, in
// file order, each as a quad around the segment (cost in proportion to the area covered, not
// texels x segments).
//
// The prelude's groups 0 and 1 are not used here; this file's resources are group 2.
//
// Positions come from the texel's integer index on its level's lattice, so a texel shared by two
// nodes is computed from the same numbers by the same operations in both.

struct GroundNode {
    // Lattice index of texel (0, 0) (x east, y north).
    first: vec2<i32>,
    // Material-tile coordinates of lattice index (0, 0)'s corner (fractions), and the texel
    // size in material tiles.
    material_anchor: vec2<f32>,
    material_step: f32,
    // Material mip level the texel size calls for.
    material_lod: f32,
    segment_count: u32,
    // Texel size in metres (patterns finer than a few texels fade to their mean).
    texel_m: f32,
    // The node's first word of `texel_types` (four types a word, low byte first, rows south to
    // north), and what they hold: 0 each texel's type (SIDE x SIDE), 1 the ground cells the
    // texels reach (`window_side` cells from `window_first` on a layer of `map_cells`).
    types_first: u32,
    types_form: u32,
    // Ground-grid coordinates of lattice index (0, 0)'s corner, and (below) the texel size in
    // ground cells.
    ground_anchor: vec2<f32>,
    window_first: vec2<i32>,
    window_side: vec2<i32>,
    map_cells: vec2<i32>,
    ground_step: f32,
    pad: f32,
};

// A road or path segment in texel-lattice units of the node's level (the same numbers in every
// node that draws it).
struct Segment {
    a: vec2<f32>,
    b: vec2<f32>,
    half_width: f32,
    falloff: f32,
    kind: u32,
    pad: u32,
};

@group(2) @binding(0) var<uniform> node: GroundNode;
@group(2) @binding(1) var<storage, read> texel_types: array<u32>;
@group(2) @binding(2) var materials: texture_2d_array<f32>;
@group(2) @binding(3) var material_sampler: sampler;
@group(2) @binding(4) var<storage, read> segments: array<Segment>;

// A closed decal area: its box (texel-lattice units, widened by its soft edge) and its outline
// (points `first .. first + count` of `area_points`, lattice units).
struct Area {
    lo: vec2<f32>,
    hi: vec2<f32>,
    first: u32,
    count: u32,
    half_width: f32,
    falloff: f32,
    kind: u32,
    pad: u32,
    // Fields: the unit direction of the crop rows (lattice units).
    rows: vec2<f32>,
};

@group(2) @binding(5) var<storage, read> areas: array<Area>;
@group(2) @binding(6) var<storage, read> area_points: array<vec2<f32>>;

@vertex
fn vs_fill(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}

fn segment_distance(p: vec2<f32>, a: vec2<f32>, b: vec2<f32>) -> f32 {
    let ab = b - a;
    let t = clamp(dot(p - a, ab) / max(dot(ab, ab), 1e-12), 0.0, 1.0);
    return length(p - (a + t * ab));
}

// A node texel: its type from the node's types, read by one of two indices (both computed, so
// one pipeline serves every node and the fragment shader has no branch): the texel's own
// (`types_form` 0: each texel's type, SIDE x SIDE) or its cell's (`types_form` 1: the nearest
// ground sample to the texel's centre moved by two octaves of noise of up to 0.7 ground cells,
// among the cells the node's CPU phase gathered).
@fragment
fn fs_texel(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    // Framebuffer rows run top down; texel rows run south to north.
    let own = (SIDE - 1u - u32(frag.y)) * SIDE + u32(frag.x);
    let g = node.ground_anchor + texel_centre(frag) * node.ground_step;
    let at = clamp(perturbed_ground_cell(g), vec2<i32>(0), node.map_cells - 1);
    let local = clamp(at - node.window_first, vec2<i32>(0), node.window_side - 1);
    let cell = u32(local.y * node.window_side.x + local.x);
    return texel_color(frag, select(own, cell, node.types_form == 1u));
}

// The texel's colour: the material of type `k` of the node's types.
fn texel_color(frag: vec4<f32>, k: u32) -> vec4<f32> {
    let t = (texel_types[node.types_first + k / 4u] >> (8u * (k % 4u))) & 0xffu;
    let uv = fract(node.material_anchor + texel_centre(frag) * node.material_step);
    let albedo = textureSampleLevel(materials, material_sampler, uv, t, node.material_lod).rgb;
    return vec4<f32>(albedo, 1.0);
}

// The texel a fragment covers: its lattice index's centre (the same numbers in every node).
fn texel_centre(frag: vec4<f32>) -> vec2<f32> {
    let texel = vec2<i32>(i32(frag.x), i32(SIDE) - 1 - i32(frag.y));
    return vec2<f32>(node.first + texel) + 0.5;
}

struct DecalOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) segment: u32,
};

// Segment `k` as a quad reaching one texel beyond its soft edge.
@vertex
fn vs_segment(@builtin(vertex_index) v: u32, @builtin(instance_index) k: u32) -> DecalOut {
    let s = segments[k];
    let r = s.half_width + s.falloff + 1.0;
    let d = s.b - s.a;
    let len = length(d);
    var dir = vec2<f32>(1.0, 0.0);
    if (len > 1e-6) {
        dir = d / len;
    }
    let n = vec2<f32>(-dir.y, dir.x);
    var corners = array<vec2<f32>, 4>(
        s.a - dir * r - n * r,
        s.b + dir * r - n * r,
        s.b + dir * r + n * r,
        s.a - dir * r + n * r,
    );
    var order = array<u32, 6>(0u, 1u, 2u, 0u, 2u, 3u);
    let q = (corners[order[v]] - vec2<f32>(node.first)) / f32(SIDE);
    var out: DecalOut;
    out.clip = vec4<f32>(q * 2.0 - 1.0, 0.0, 1.0);
    out.segment = k;
    return out;
}

// The segment's colour with its soft-edge weight as alpha (blended over the texel).
@fragment
fn fs_segment(in: DecalOut) -> @location(0) vec4<f32> {
    let s = segments[in.segment];
    let d = segment_distance(texel_centre(in.clip), s.a, s.b);
    let w = 1.0 - smoothstep(s.half_width, s.half_width + max(s.falloff, 1e-3), d);
    var color = ROAD_COLOR;
    if (s.kind == 1u) {
        color = PATH_COLOR;
    }
    return vec4<f32>(color, w);
}

struct AreaOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) area: u32,
};

// Area `k` as its box.
@vertex
fn vs_area(@builtin(vertex_index) v: u32, @builtin(instance_index) k: u32) -> AreaOut {
    let a = areas[k];
    var corners = array<vec2<f32>, 4>(a.lo, vec2<f32>(a.hi.x, a.lo.y), a.hi, vec2<f32>(a.lo.x, a.hi.y));
    var order = array<u32, 6>(0u, 1u, 2u, 0u, 2u, 3u);
    let q = (corners[order[v]] - vec2<f32>(node.first)) / f32(SIDE);
    var out: AreaOut;
    out.clip = vec4<f32>(q * 2.0 - 1.0, 0.0, 1.0);
    out.area = k;
    return out;
}

// How much of a pattern with features `feature_m` metres across a texel can show: all of it
// from 3 texels per feature, none at 1 (the texel then holds the pattern's mean).
fn resolvable(feature_m: f32) -> f32 {
    return clamp((feature_m / node.texel_m - 1.0) * 0.5, 0.0, 1.0);
}

// The area's colour with its soft-edge weight as alpha: inside the outline (even-odd) weight 1,
// outside it falls off with the distance to the outline.
@fragment
fn fs_area(in: AreaOut) -> @location(0) vec4<f32> {
    let a = areas[in.area];
    let p = texel_centre(in.clip);
    var inside = false;
    var d = 1e30;
    for (var k = 0u; k < a.count; k = k + 1u) {
        let pa = area_points[a.first + k];
        let pb = area_points[a.first + (k + a.count - 1u) % a.count];
        if ((pa.y > p.y) != (pb.y > p.y)) {
            let x = pa.x + (p.y - pa.y) / (pb.y - pa.y) * (pb.x - pa.x);
            if (p.x < x) {
                inside = !inside;
            }
        }
        d = min(d, segment_distance(p, pa, pb));
    }
    var w = 1.0;
    if (!inside) {
        w = 1.0 - smoothstep(a.half_width, a.half_width + max(a.falloff, 1e-3), d);
    }
    // Metres from the tree's south-west corner (the same numbers in every node of the level).
    let m = p * node.texel_m;
    var color = DIRT_PATCH_COLOR;
    if (a.kind == 2u) {
        // Rock: boulders (1.2 m) on slabs (5 m).
        let v = 0.6 * (value_noise(m / 1.2) - 0.5) * resolvable(1.2)
            + 0.5 * (value_noise(m / 5.0 + 31.0) - 0.5) * resolvable(5.0);
        color = ROCK_PATCH_COLOR * (1.0 + v);
    } else if (a.kind == 3u) {
        // Crop rows 2.5 m apart across the first edge; a triangle wave of mean 1/2.
        let u = dot(p, a.rows) * node.texel_m / 2.5;
        let tri = abs(fract(u) - 0.5) * 2.0;
        color = mix(FIELD_LOW_COLOR, FIELD_HIGH_COLOR, 0.5 + (tri - 0.5) * resolvable(1.25));
    } else {
        let v = 0.35 * (value_noise(m / 0.8 + 7.0) - 0.5) * resolvable(0.8)
            + 0.3 * (value_noise(m / 3.0 + 13.0) - 0.5) * resolvable(3.0);
        color = DIRT_PATCH_COLOR * (1.0 + v);
    }
    return vec4<f32>(color, w);
}

// Mip levels 1 - 3 of a node texture (engine::render::ground::GroundTexturer::record_mips),
// one workgroup per 32 x 32 block of level 0: a level-k texel is the mean of the 4^k level-0
// texels under it, in linear light (level 0 is read through its sRGB view, which decodes; the
// levels are written through linear storage views, so this encodes). Each level is averaged
// from the one above before rounding to 8 bits. Blocks never straddle a node edge, so
// neighbours' shared border texels stay equal at every level.
@group(3) @binding(0) var mip_base: texture_2d<f32>;
@group(3) @binding(1) var mip_1: texture_storage_2d<rgba8unorm, write>;
@group(3) @binding(2) var mip_2: texture_storage_2d<rgba8unorm, write>;
@group(3) @binding(3) var mip_3: texture_storage_2d<rgba8unorm, write>;

// Level 1 of the workgroup's block (16 x 16, from 0), then level 2 (8 x 8, from 256).
var<workgroup> mip_block: array<vec4<f32>, 320>;

// The mean of the 2 x 2 texels of a level in `mip_block` (its first texel at `first`,
// `width` a row) under texel `l` of the level below.
fn block_mean(first: u32, width: u32, l: vec2<u32>) -> vec4<f32> {
    let k = first + l.y * 2u * width + l.x * 2u;
    return 0.25 * (mip_block[k] + mip_block[k + 1u] + mip_block[k + width]
        + mip_block[k + width + 1u]);
}

fn srgb_encoded(c: vec4<f32>) -> vec4<f32> {
    let rgb = clamp(c.rgb, vec3<f32>(0.0), vec3<f32>(1.0));
    let curve = 1.055 * pow(rgb, vec3<f32>(1.0 / 2.4)) - 0.055;
    return vec4<f32>(select(curve, rgb * 12.92, rgb <= vec3<f32>(0.0031308)), c.a);
}

@compute @workgroup_size(16, 16)
fn cs_mips(@builtin(workgroup_id) block: vec3<u32>, @builtin(local_invocation_id) l: vec3<u32>) {
    let p1 = block.xy * 16u + l.xy;
    let b = vec2<i32>(p1 * 2u);
    let m1 = 0.25 * (textureLoad(mip_base, b, 0) + textureLoad(mip_base, b + vec2<i32>(1, 0), 0)
        + textureLoad(mip_base, b + vec2<i32>(0, 1), 0)
        + textureLoad(mip_base, b + vec2<i32>(1, 1), 0));
    textureStore(mip_1, p1, srgb_encoded(m1));
    mip_block[l.y * 16u + l.x] = m1;
    workgroupBarrier();
    if (l.x < 8u && l.y < 8u) {
        let m2 = block_mean(0u, 16u, l.xy);
        textureStore(mip_2, block.xy * 8u + l.xy, srgb_encoded(m2));
        mip_block[256u + l.y * 8u + l.x] = m2;
    }
    workgroupBarrier();
    if (l.x < 4u && l.y < 4u) {
        textureStore(mip_3, block.xy * 4u + l.xy, srgb_encoded(block_mean(256u, 8u, l.xy)));
    }
}
