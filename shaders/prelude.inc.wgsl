// Shared by every renderer's shader (assembled in front of it by `engine::render::shader`):
// the frame binding and the renderer's node table, the mesh vertex, dither cross-fades, fog and
// sun/sky shading. `Frame`, `Node` and `VertexIn` mirror `engine::render::gpu_data`.

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
    // xy: camera position modulo the detail period (engine::render::frame::DETAIL_PERIOD_M).
    camera_wrap: vec4<f32>,
};

// One row of the renderer's node table (`engine::render::node_table`).
struct Node {
    // xyz: node origin minus camera (m); w: dither interval start.
    offset_lo: vec4<f32>,
    // x: dither interval end, y: quad-tree level, zw: the renderer's own (terrain: ground
    // texture layer or -1, texture coordinates per metre).
    hi_level: vec4<f32>,
    // The node's light grid (engine::render::light_pool::LightLease::entry): x its tile in the
    // pool or -1, y columns per metre, zw the node's south-west corner in the grid's columns.
    light: vec4<f32>,
    // xy: more of the renderer's own (terrain: the node's south-west corner in metres from that
    // of the node whose ground texture it shows); z: its sides toward a coarser light grid
    // (engine::lighting::seams::SideSteps), w: its width in its grid's columns (`node_light`).
    more: vec4<f32>,
};

// The light-grid pool (engine::render::light_pool): tiles of COLUMNS x COLUMNS x LAYERS
// samples: r sky visibility, g the canopy's transmittance toward the sun, b the sun's
// elevation over the terrain horizon toward it (`light_visibility`), a the ground's bounce
// (engine::lighting::grid::LightGrid::bounce_at: the sunlit terrain hiding the sky, per unit
// albedo and sun irradiance).
struct LightInfo {
    // Heights of the layers above the ground (m), 7 used.
    layers_m: array<vec4<f32>, 2>,
    // x: tiles per side.
    tiles: vec4<f32>,
    // rgb: the map's mean ground albedo (linear): the colour of the light the terrain bounces.
    ground_albedo: vec4<f32>,
};

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var light_grids: texture_3d<f32>;
@group(0) @binding(3) var<uniform> light_info: LightInfo;
@group(1) @binding(0) var<storage, read> nodes: array<Node>;
// A by-slot node table's row of each entry (engine::render::node_table); a by-draw table's
// draws give their row as the first instance.
@group(1) @binding(1) var<storage, read> row_of_entry: array<u32>;

// A plant instance (engine::render::vegetation::PlantInstance; vegetation and the GPU
// reference): position relative to the node's south-west corner (z absolute), height, crown
// radius, yaw, look index and node-table entry (in the impostor bake: its cluster). A cluster
// quad has its impostor tile as its look.
struct PlantInstanceIn {
    @location(3) position: vec3<f32>,
    @location(4) height: f32,
    @location(5) radius: f32,
    @location(6) yaw: f32,
    @location(7) look: u32,
    @location(8) entry: u32,
};

// A unit plant shape's vertex `p` (height 1, radius 1) scaled and turned for `inst`, from the
// instance's position.
fn plant_offset(p: vec3<f32>, inst: PlantInstanceIn) -> vec3<f32> {
    let c = cos(inst.yaw);
    let s = sin(inst.yaw);
    let local = vec3<f32>(p.xy * inst.radius, p.z * inst.height);
    return vec3<f32>(c * local.x - s * local.y, s * local.x + c * local.y, local.z);
}

// Corner `i % 6` of a quad's two triangles: x in [-1, 1] across, y in [0, 1] up.
fn quad_corner(i: u32) -> vec2<f32> {
    return array<vec2<f32>, 6>(
        vec2<f32>(-1.0, 0.0), vec2<f32>(1.0, 0.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(-1.0, 0.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
    )[i % 6u];
}

// The horizontal unit vector across a camera-facing (about the vertical axis) quad standing at
// `base` (camera-relative).
fn quad_right(base: vec3<f32>) -> vec3<f32> {
    let flat_dir = vec2<f32>(base.x, base.y);
    let len = max(length(flat_dir), 1e-3);
    return vec3<f32>(-flat_dir.y / len, flat_dir.x / len, 0.0);
}

// Camera-relative position of `corner` of instance `inst`'s camera-facing quad (billboards
// and cluster quads), standing at `base`: radius wide each way, height tall.
fn quad_rel(base: vec3<f32>, corner: vec2<f32>, inst: PlantInstanceIn) -> vec3<f32> {
    return base + quad_right(base) * (corner.x * inst.radius)
        + vec3<f32>(0.0, 0.0, corner.y * inst.height);
}

// What the fragment stage needs of a node: x, y its dither interval, z its level.
fn node_fade(n: Node) -> vec3<f32> {
    return vec3<f32>(n.offset_lo.w, n.hi_level.x, n.hi_level.y);
}

// A plant-shape vertex: `tag` is the part (0 trunk, 1 foliage).
struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) tag: u32,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) rel: vec3<f32>,
    @location(1) normal: vec3<f32>,
    // Colour looked up per vertex and interpolated, so ground-type borders blend.
    @location(2) albedo: vec3<f32>,
    // The node's `node_fade` (one node per primitive).
    @location(3) @interpolate(flat) fade: vec3<f32>,
    // The light grid's values (`node_light`; `light_visibility` turns them into sky and sun
    // visibility per pixel, so a terrain shadow's edge stays sharp between columns).
    @location(4) light: vec4<f32>,
};

// The light-grid pool's texture coordinate across the layers for `above_m` over the ground
// (the fractional layer between the grids' layer heights).
fn light_layer_w(above_m: f32) -> f32 {
    var layer = 0.0;
    for (var i = 0u; i + 1u < LIGHT_LAYERS; i = i + 1u) {
        let lo = light_info.layers_m[i / 4u][i % 4u];
        let hi = light_info.layers_m[(i + 1u) / 4u][(i + 1u) % 4u];
        if (above_m >= lo) {
            layer = f32(i) + clamp((above_m - lo) / max(hi - lo, 1e-3), 0.0, 1.0);
        }
    }
    return (layer + 0.5) / f32(LIGHT_LAYERS);
}

// The grid values at column coordinates `g` of the grid in pool tile `slot`, layer coordinate
// `w` (trilinear; clamped to the tile's sample centres, so tiles never bleed). Filtered here from
// the eight samples around, with weights from the coordinates inside the tile: the same values
// whichever tile the grid leased (the sampler's filter weights depend on the texture coordinate,
// so on the tile).
fn light_fetch(slot: f32, g: vec2<f32>, w: f32) -> vec4<f32> {
    let tiles = u32(light_info.tiles.x);
    let s = u32(slot);
    let origin = vec2<i32>(vec2<u32>(s % tiles, s / tiles) * LIGHT_COLUMNS);
    let last = f32(LIGHT_COLUMNS - 1u);
    let c = clamp(g, vec2<f32>(0.0), vec2<f32>(last));
    let z = clamp(w * f32(LIGHT_LAYERS) - 0.5, 0.0, f32(LIGHT_LAYERS - 1u));
    let c0 = min(floor(c), vec2<f32>(last - 1.0));
    let z0 = min(floor(z), f32(LIGHT_LAYERS - 2u));
    let f = c - c0;
    let fz = z - z0;
    let p = origin + vec2<i32>(c0);
    let l = i32(z0);
    let s000 = textureLoad(light_grids, vec3<i32>(p, l), 0);
    let s100 = textureLoad(light_grids, vec3<i32>(p + vec2<i32>(1, 0), l), 0);
    let s010 = textureLoad(light_grids, vec3<i32>(p + vec2<i32>(0, 1), l), 0);
    let s110 = textureLoad(light_grids, vec3<i32>(p + vec2<i32>(1, 1), l), 0);
    let s001 = textureLoad(light_grids, vec3<i32>(p, l + 1), 0);
    let s101 = textureLoad(light_grids, vec3<i32>(p + vec2<i32>(1, 0), l + 1), 0);
    let s011 = textureLoad(light_grids, vec3<i32>(p + vec2<i32>(0, 1), l + 1), 0);
    let s111 = textureLoad(light_grids, vec3<i32>(p + vec2<i32>(1, 1), l + 1), 0);
    let below = mix(mix(s000, s100, f.x), mix(s010, s110, f.x), f.y);
    let above = mix(mix(s001, s101, f.x), mix(s011, s111, f.x), f.y);
    return mix(below, above, fz);
}

// `light_fetch` reading only every `k.x`-th column along x and every `k.y`-th along y (linear
// between them; 1: every column): what a grid `k` times coarser holds there.
fn light_decimated(slot: f32, g: vec2<f32>, w: f32, k: vec2<f32>) -> vec4<f32> {
    let coarse = k > vec2<f32>(1.0);
    let lo = select(g, floor(g / k) * k, coarse);
    let t = select(vec2<f32>(0.0), (g - lo) / k, coarse);
    let step = select(vec2<f32>(0.0), k, coarse);
    let south = mix(light_fetch(slot, lo, w), light_fetch(slot, lo + vec2<f32>(step.x, 0.0), w), t.x);
    let north = mix(light_fetch(slot, lo + vec2<f32>(0.0, step.y), w), light_fetch(slot, lo + step, w), t.x);
    return mix(south, north, t.y);
}

// The light-grid values of a point of node `n` (`local_xy` from its south-west corner,
// `above_m` over the ground; fully lit without a grid), for `light_visibility`. Near a side
// whose drawn neighbour uses a coarser grid (`n.more.z`, engine::lighting::seams), the grid is
// read at that grid's columns only, blending back to every column within one of its column
// steps from the side: both nodes show the same values along the side.
fn node_light(n: Node, local_xy: vec2<f32>, above_m: f32) -> vec4<f32> {
    return grid_light(n.light, n.more, local_xy, above_m);
}

// `node_light` from the node's `light` and `more` fields (which a vertex stage may hand to the
// fragment stage as flat values).
fn grid_light(light: vec4<f32>, more: vec4<f32>, local_xy: vec2<f32>, above_m: f32) -> vec4<f32> {
    if (light.x < 0.0) {
        return vec4<f32>(1.0, 1.0, 1.0, 0.0);
    }
    let slot = light.x;
    let g = light.zw + local_xy * light.y;
    let w = light_layer_w(above_m);
    let code = u32(more.z + 0.5);
    if (code == 0u) {
        return light_fetch(slot, g, w);
    }
    // Column steps toward the west, east, south and north neighbours (1: not coarser).
    let k = vec4<f32>(
        f32(1u << (code & 7u)),
        f32(1u << ((code >> 3u) & 7u)),
        f32(1u << ((code >> 6u) & 7u)),
        f32(1u << ((code >> 9u) & 7u)),
    );
    let lo = light.zw;
    let hi = lo + vec2<f32>(more.w);
    let d = vec4<f32>(g.x - lo.x, hi.x - g.x, g.y - lo.y, hi.y - g.y);
    // 1 on a side toward a coarser grid, 0 one of its steps inward (steps are at most the
    // node's width, so the two weights of an axis never sum above 1).
    let wt = select(vec4<f32>(0.0), clamp(1.0 - d / k, vec4<f32>(0.0), vec4<f32>(1.0)), k > vec4<f32>(1.0));
    // South and north sides run along x (they decimate x); west and east along y.
    let ax = array<f32, 3>(max(1.0 - wt.z - wt.w, 0.0), wt.z, wt.w);
    let kx = array<f32, 3>(1.0, k.z, k.w);
    let ay = array<f32, 3>(max(1.0 - wt.x - wt.y, 0.0), wt.x, wt.y);
    let ky = array<f32, 3>(1.0, k.x, k.y);
    var sum = vec4<f32>(0.0);
    for (var i = 0u; i < 3u; i = i + 1u) {
        for (var j = 0u; j < 3u; j = j + 1u) {
            let a = ax[i] * ay[j];
            if (a > 0.0) {
                sum = sum + a * light_decimated(slot, g, w, vec2<f32>(kx[i], ky[j]));
            }
        }
    }
    return sum;
}

// Sky and sun visibility from interpolated grid values `v` (`node_light`): the sun is the
// canopy's transmittance times the share of its disc above the terrain horizon
// (engine::lighting::grid::terrain_lit).
fn light_visibility(v: vec4<f32>) -> vec2<f32> {
    let margin_rad = (2.0 * v.z - 1.0) * LIGHT_MARGIN_RANGE_RAD;
    return vec2<f32>(v.x, v.y * clamp(0.5 + margin_rad / SUN_DIAMETER_RAD, 0.0, 1.0));
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

// Whether a node of `fade` (see `node_fade`) draws the pixel at `xy` (its dither interval holds
// the pixel's threshold).
fn in_dither(xy: vec2<f32>, fade: vec3<f32>) -> bool {
    let t = bayer8(vec2<u32>(xy));
    return t >= fade.x && t < fade.y;
}

fn sky_color(dir: vec3<f32>) -> vec3<f32> {
    let up = clamp(dir.z, 0.0, 1.0);
    return mix(frame.sky_horizon.rgb, frame.sky_zenith.rgb, pow(up, 0.6));
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

// A lit, fogged, dithered surface pixel (terrain and plant meshes); debug mode 1 colours it by
// the node's level, 4 makes it grey (lighting only), 5 shows the light grid's values (red sky,
// green sun visibility, blue the ground's bounce; unshaded, no fog).
fn lit_pixel(in: VertexOut) -> vec4<f32> {
    if (!in_dither(in.clip.xy, in.fade)) {
        discard;
    }
    return lit_color(in);
}

// `lit_pixel` without the dither test, for nodes that are not fading (their interval is
// [0, 1): every pixel is theirs). A shader without `discard` keeps the early depth test.
fn lit_color(in: VertexOut) -> vec4<f32> {
    let mode = u32(frame.fog.z + 0.5);
    let vis = light_visibility(in.light);
    if (mode == 5u) {
        return vec4<f32>(vis, in.light.w, 1.0);
    }
    var albedo = in.albedo;
    if (mode == 1u) {
        albedo = level_color(in.fade.z);
    }
    if (mode == 4u) {
        albedo = vec3<f32>(0.6);
    }
    let n = normalize(in.normal);
    // The light grid's visibilities scale the direct sun (shadow) and the sky (occlusion).
    let sun = max(dot(n, frame.sun_dir.xyz), 0.0) * vis.y;
    let ambient = mix(frame.sky_horizon.rgb * 0.35, frame.sky_zenith.rgb * 0.6, 0.5 + 0.5 * n.z);
    // One bounce: the sunlit terrain that hides the sky, in the ground's colour.
    let bounce = light_info.ground_albedo.rgb * frame.sun_color.rgb * in.light.w;
    return fogged(albedo * (frame.sun_color.rgb * sun + ambient * vis.x + bounce), in.rel);
}

// A hash of an integer lattice point to [0, 1] (value-noise corners; ground textures and the
// terrain's fine detail).
fn lattice_hash(p: vec2<i32>) -> f32 {
    var h = u32(p.x) * 0x8da6b343u ^ u32(p.y) * 0xd8163841u;
    h = (h ^ (h >> 15u)) * 0x2c1b3c6du;
    h = h ^ (h >> 12u);
    return f32(h & 0xffffu) / 65535.0;
}

// Value noise in [0, 1] at `p` (lattice of unit cells).
fn value_noise(p: vec2<f32>) -> f32 {
    let c = floor(p);
    let f = p - c;
    let u = f * f * (3.0 - 2.0 * f);
    let i = vec2<i32>(c);
    let a = lattice_hash(i);
    let b = lattice_hash(i + vec2<i32>(1, 0));
    let d = lattice_hash(i + vec2<i32>(0, 1));
    let e = lattice_hash(i + vec2<i32>(1, 1));
    return mix(mix(a, b, u.x), mix(d, e, u.x), u.y);
}

// The ground-layer sample whose type shows at `g` (ground-cell coordinates from the map
// origin): the nearest one to `g` moved by two octaves of noise of up to 0.7 cells, so type
// borders are natural instead of the 4 m staircase (ground textures and the terrain's detail).
fn perturbed_ground_cell(g: vec2<f32>) -> vec2<i32> {
    let wobble = vec2<f32>(
        value_noise(g * 1.3) + 0.5 * value_noise(g * 3.7 + 17.0),
        value_noise(g * 1.3 + 41.0) + 0.5 * value_noise(g * 3.7 + 59.0),
    ) / 1.5 - 0.5;
    return vec2<i32>(round(g + 1.4 * wobble));
}
