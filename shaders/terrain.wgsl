// Terrain nodes: camera-relative positions, reversed-Z, sun + sky ambient shading, ground-type
// colours, distance fog, screen-door dither cross-fades between levels (see the prelude).

// Linear colour per ground type (the map's legend); `GROUND_TYPES` comes from the renderer.
@group(2) @binding(0) var<uniform> ground_colors: array<vec4<f32>, GROUND_TYPES>;

// The draw's first instance is the node's slot in the node table.
@vertex
fn vs_main(v: VertexIn, @builtin(instance_index) slot: u32) -> VertexOut {
    let node = nodes[slot];
    var out: VertexOut;
    let rel = v.position + node.offset_lo.xyz;
    out.clip = frame.clip_from_rel * vec4<f32>(rel, 1.0);
    out.rel = rel;
    out.normal = v.normal;
    out.albedo = ground_colors[min(v.tag, GROUND_TYPES - 1u)].rgb;
    out.fade = node_fade(node);
    return out;
}

// Nodes in a cross-fade: dithered.
@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    return lit_pixel(in);
}

// Nodes drawn alone at their place (dither interval [0, 1)): no `discard`, same pixels.
@fragment
fn fs_solid(in: VertexOut) -> @location(0) vec4<f32> {
    return lit_color(in);
}
