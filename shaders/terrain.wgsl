// Terrain nodes: camera-relative positions, reversed-Z, sun + sky ambient shading, the node's
// ground texture (ground-type colours per vertex where it has none), distance fog, screen-door
// dither cross-fades between levels (see the prelude).

// Linear colour per ground type (the map's legend); `GROUND_TYPES` comes from the renderer.
@group(2) @binding(0) var<uniform> ground_colors: array<vec4<f32>, GROUND_TYPES>;
// One page of node ground textures (engine::render::ground_pool); the node's layer is in its
// node-table entry.
@group(2) @binding(1) var ground_page: texture_2d_array<f32>;
@group(2) @binding(2) var ground_sampler: sampler;

// The ground's detail below the finest node texel (engine::render::ground_detail): the
// materials (one layer per ground type, tiling over `material_tile_m`), a window of the map's
// ground layer around the camera (row 0 south) and the camera's place in both, in f32 near the
// camera.
struct GroundDetail {
    camera_cells: vec2<f32>,
    camera_tiles: vec2<f32>,
    ground_spacing_m: f32,
    ground_types: u32,
    material_tile_m: f32,
    finest_lod: f32,
    finest_texel_m: f32,
    // Metres of a material's detail height of 1 (alpha 255).
    max_relief_m: f32,
    // Pixels up to this size (m) see the detail height as bumps of the ground's normal.
    bump_px_m: f32,
    pad: f32,
    // The ground cell of `ground_types` texel (0, 0), the window's side in cells (no detail
    // outside it) and the ground layer's cells per side.
    window_first: vec2<i32>,
    window_side: vec2<i32>,
    map_cells: vec2<i32>,
    pad2: vec2<f32>,
};
@group(2) @binding(3) var materials: texture_2d_array<f32>;
@group(2) @binding(4) var ground_types: texture_2d<u32>;
@group(2) @binding(5) var material_sampler: sampler;
@group(2) @binding(6) var<uniform> detail: GroundDetail;

struct TerrainOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) rel: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) albedo: vec3<f32>,
    @location(3) @interpolate(flat) fade: vec3<f32>,
    // Texture coordinates in the node's ground texture.
    @location(4) uv: vec2<f32>,
    // The node's layer in `ground_page`, or -1 without a texture.
    @location(5) @interpolate(flat) layer: i32,
    // The node's light-grid fields (`Node.light`, `Node.more`) and the point's position from
    // the node's corner: the ground layer of the grid is read per pixel (`grid_light`), so a
    // node drawn through fewer vertices shows the same light.
    @location(6) @interpolate(flat) light_node: vec4<f32>,
    @location(7) @interpolate(flat) light_more: vec4<f32>,
    @location(8) local: vec2<f32>,
};

// A terrain vertex, from two streams: its position (metres from the node's south-west corner,
// z absolute) and its shading word (engine::terrain::mesh::pack_shading: the normal in bits
// 0 - 23, the ground type in bits 24 - 31).
struct TerrainVertexIn {
    @location(0) position: vec3<f32>,
    @location(1) shading: u32,
};

// The unit normal of a shading word: two 12-bit coordinates of the upper hemisphere's
// octahedral projection, turned 45 degrees (as engine::terrain::mesh::unpack_normal).
fn shading_normal(word: u32) -> vec3<f32> {
    let uv = vec2<f32>(f32(word & 0xfffu), f32((word >> 12u) & 0xfffu)) / 4095.0 * 2.0 - 1.0;
    let p = vec2<f32>(uv.x + uv.y, uv.x - uv.y) * 0.5;
    return normalize(vec3<f32>(p, 1.0 - abs(p.x) - abs(p.y)));
}

// The draw's first instance is the node's entry in the frame's node table.
@vertex
fn vs_main(v: TerrainVertexIn, @builtin(instance_index) entry: u32) -> TerrainOut {
    let node = nodes[entry];
    var out: TerrainOut;
    let rel = v.position + node.offset_lo.xyz;
    out.clip = frame.clip_from_rel * vec4<f32>(rel, 1.0);
    out.rel = rel;
    out.normal = shading_normal(v.shading);
    out.albedo = ground_colors[min(v.shading >> 24u, GROUND_TYPES - 1u)].rgb;
    out.fade = node_fade(node);
    // Texel columns run east from the west border, rows north from the south border; the
    // texture's row 0 is the north border's.
    let border = f32(GROUND_BORDER) / f32(GROUND_SIDE);
    // The texture may be an ancestor's while the node's own is not made yet: `more.xy` is the
    // node's corner in that texture's node.
    let t = border + (v.position.xy + node.more.xy) * node.hi_level.w;
    out.uv = vec2<f32>(t.x, 1.0 - t.y);
    out.layer = i32(round(node.hi_level.z));
    out.light_node = node.light;
    out.light_more = node.more;
    out.local = v.position.xy;
    return out;
}

// Texels per pixel as the texel-density view encodes it (engine::render::frame::GroundView).
fn density_color(uv: vec2<f32>) -> vec3<f32> {
    let d = uv * f32(GROUND_SIDE);
    let texels = max(length(dpdx(d)), length(dpdy(d)));
    let g = clamp(log2(max(texels, 1e-6)) / 8.0 + 0.5, 0.0, 1.0);
    return vec3<f32>(1.0 - g, g, 0.0);
}

// Value noise in [0, 1] with `cells` lattice cells per detail period, periodic in it, at `p`
// (metres within the period).
fn detail_noise(p: vec2<f32>, cells: i32) -> f32 {
    let q = p * (f32(cells) / DETAIL_PERIOD_M);
    let c = floor(q);
    let f = q - c;
    let u = f * f * (3.0 - 2.0 * f);
    let i = vec2<i32>(c);
    let at = vec2<i32>(((i.x % cells) + cells) % cells, ((i.y % cells) + cells) % cells);
    let next = vec2<i32>((at.x + 1) % cells, (at.y + 1) % cells);
    let a = lattice_hash(at);
    let b = lattice_hash(vec2<i32>(next.x, at.y));
    let d = lattice_hash(vec2<i32>(at.x, next.y));
    let e = lattice_hash(next);
    return mix(mix(a, b, u.x), mix(d, e, u.x), u.y);
}

// Nodes drawn with legend colours (no ground texture): an albedo factor of mean 1
// from two octaves of world-anchored noise (cells of 1/32 and 1/16 m), each shown only where a
// pixel is a few times smaller than its cells (`px_m`: metres per pixel), so it fades in with
// distance continuously, whatever node or level the pixel belongs to: no seam.
fn fine_detail(rel: vec3<f32>, px_m: f32) -> f32 {
    let p = rel.xy + frame.camera_wrap.xy;
    var v = 0.0;
    let fine = clamp((DETAIL_PERIOD_M / 2048.0 / px_m - 1.5) * 0.5, 0.0, 1.0);
    let coarse = clamp((DETAIL_PERIOD_M / 1024.0 / px_m - 1.5) * 0.5, 0.0, 1.0);
    v = v + 0.22 * (detail_noise(p, 2048) - 0.5) * fine;
    v = v + 0.22 * (detail_noise(p + vec2<f32>(17.0, 5.0), 1024) - 0.5) * coarse;
    return 1.0 + v;
}

// The material's detail at a pixel `rel` (camera-relative) of `px_m` metres:
// - `factor`: the ground type's material luminance at the pixel's scale over its luminance at
//   the finest node texel's scale (what the node texture already holds), 1 where a pixel is a
//   finest texel or larger, in full from a third of one;
// - `slope`: the gradient (m/m, east and north) of the material's detail height at the
//   pixel's scale (central differences one mip texel apart), in full where a pixel is a
//   quarter of `bump_px_m` or less, none from `bump_px_m` on.
// Both fade by metres per pixel only, so no node or level border can show. Explicit mip
// levels, so pixels beyond both reaches skip the lookups.
struct Detail {
    factor: f32,
    slope: vec2<f32>,
};

fn material_detail(rel: vec3<f32>, px_m: f32) -> Detail {
    var out = Detail(1.0, vec2<f32>(0.0));
    let w = clamp((detail.finest_texel_m / px_m - 1.0) * 0.5, 0.0, 1.0);
    let wb = clamp((detail.bump_px_m / px_m - 1.0) / 3.0, 0.0, 1.0);
    if (max(w, wb) <= 0.0) {
        return out;
    }
    let g = detail.camera_cells + rel.xy / detail.ground_spacing_m;
    let at = clamp(perturbed_ground_cell(g), vec2<i32>(0), detail.map_cells - 1) - detail.window_first;
    if (any(at < vec2<i32>(0)) || any(at >= detail.window_side)) {
        return out;
    }
    let t = min(textureLoad(ground_types, at, 0).r, detail.ground_types - 1u);
    // Material coordinates as the node texture's pass has them (engine::render::ground); rows
    // run south to north, so u is east and v north.
    let uv = detail.camera_tiles + rel.xy / detail.material_tile_m;
    let texels = f32(textureDimensions(materials).x);
    let texel_m = detail.material_tile_m / texels;
    let lod = max(log2(px_m / texel_m), 0.0);
    if (w > 0.0) {
        let fine = textureSampleLevel(materials, material_sampler, uv, t, lod).rgb;
        let coarse = textureSampleLevel(materials, material_sampler, uv, t, detail.finest_lod).rgb;
        let luma = vec3<f32>(0.2126, 0.7152, 0.0722);
        let ratio = dot(fine, luma) / max(dot(coarse, luma), 1e-4);
        out.factor = mix(1.0, ratio, w);
    }
    if (wb > 0.0) {
        let step = exp2(lod) / texels;
        let east = textureSampleLevel(materials, material_sampler, uv + vec2<f32>(step, 0.0), t, lod).a;
        let west = textureSampleLevel(materials, material_sampler, uv - vec2<f32>(step, 0.0), t, lod).a;
        let north = textureSampleLevel(materials, material_sampler, uv + vec2<f32>(0.0, step), t, lod).a;
        let south = textureSampleLevel(materials, material_sampler, uv - vec2<f32>(0.0, step), t, lod).a;
        let run_m = 2.0 * step * detail.material_tile_m;
        out.slope = wb * detail.max_relief_m * vec2<f32>(east - west, north - south) / run_m;
    }
    return out;
}

fn terrain_color(in: TerrainOut) -> vec4<f32> {
    // Sampled and differentiated in uniform control flow, chosen after.
    let texel = textureSample(ground_page, ground_sampler, in.uv, max(in.layer, 0)).rgb;
    let density = density_color(in.uv);
    let px_m = max(length(dpdx(in.rel)), length(dpdy(in.rel)));
    let mode = u32(frame.fog.z + 0.5);
    let textured = in.layer >= 0 && mode != 4u;
    let albedo = select(in.albedo, texel, textured);
    if (mode == 2u) {
        return vec4<f32>(select(vec3<f32>(0.5), density, textured), 1.0);
    }
    if (mode == 3u) {
        return vec4<f32>(albedo, 1.0);
    }
    // Textured: the material's own detail and relief; legend colours: procedural grain.
    var factor = 1.0;
    var normal = in.normal;
    if (textured) {
        let d = material_detail(in.rel, max(px_m, 1e-6));
        factor = d.factor;
        // The surface z = f(x, y) + h(x, y): its normal is along (-f_x - h_x, -f_y - h_y, 1),
        // and n / n.z is (-f_x, -f_y, 1).
        let n = normalize(in.normal);
        normal = n / max(n.z, 0.2) - vec3<f32>(d.slope, 0.0);
    } else {
        factor = fine_detail(in.rel, max(px_m, 1e-6));
    }
    let detailed = albedo * factor;
    let light = grid_light(in.light_node, in.light_more, in.local, 0.0);
    return lit_color(VertexOut(in.clip, in.rel, normal, detailed, in.fade, light));
}

// Nodes in a cross-fade: dithered.
@fragment
fn fs_main(in: TerrainOut) -> @location(0) vec4<f32> {
    // Sampled before the dither test (derivatives in uniform control flow).
    let color = terrain_color(in);
    if (!in_dither(in.clip.xy, in.fade)) {
        discard;
    }
    return color;
}

// Nodes drawn alone at their place (dither interval [0, 1)): no `discard`, same pixels.
@fragment
fn fs_solid(in: TerrainOut) -> @location(0) vec4<f32> {
    return terrain_color(in);
}

// The GPU-ratio diagnostic (`ViewOptions::flat_terrain`): the same draws with the reference's
// flat colour, dithered like `fs_main` for nodes in a cross-fade.
@fragment
fn fs_flat(in: TerrainOut) -> @location(0) vec4<f32> {
    if (!in_dither(in.clip.xy, in.fade)) {
        discard;
    }
    return vec4<f32>(0.5, 0.5, 0.5, 1.0);
}

@fragment
fn fs_flat_solid() -> @location(0) vec4<f32> {
    return vec4<f32>(0.5, 0.5, 0.5, 1.0);
}
