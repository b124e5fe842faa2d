// The GPU-timing reference (see render/reference.rs): the terrain's triangles already at
// camera-relative positions, and the vegetation's instances placed from the vegetation's node
// table like its own draws (plant meshes; billboards and cluster quads as whole quads); one
// flat colour, no textures.

@vertex
fn vs_reference(@location(0) rel: vec3<f32>) -> @builtin(position) vec4<f32> {
    return frame.clip_from_rel * vec4<f32>(rel, 1.0);
}

@fragment
fn fs_reference() -> @location(0) vec4<f32> {
    return vec4<f32>(0.5, 0.5, 0.5, 1.0);
}

// One plant shape's triangles per instance, placed like `vs_plant` places them.
@vertex
fn vs_reference_plant(v: VertexIn, inst: PlantInstanceIn) -> @builtin(position) vec4<f32> {
    let node = nodes[row_of_entry[inst.entry]];
    let rel = inst.position + plant_offset(v.position, inst) + node.offset_lo.xyz;
    return frame.clip_from_rel * vec4<f32>(rel, 1.0);
}

// Six vertices per instance: its camera-facing quad, placed like `vs_billboard` places it.
@vertex
fn vs_reference_quad(
    @builtin(vertex_index) i: u32,
    inst: PlantInstanceIn,
) -> @builtin(position) vec4<f32> {
    let base = inst.position + nodes[row_of_entry[inst.entry]].offset_lo.xyz;
    return frame.clip_from_rel * vec4<f32>(quad_rel(base, quad_corner(i), inst), 1.0);
}
