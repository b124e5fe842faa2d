//! Plain structs uploaded to the GPU. Each mirrors a WGSL struct in `shaders/terrain.wgsl`
//! field by field (std140-compatible: only vec4 and mat4x4 members).

use bytemuck::{Pod, Zeroable};

/// Mirrors `Frame` in `terrain.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct FrameUniforms {
    pub clip_from_rel: [[f32; 4]; 4],
    pub rel_from_clip: [[f32; 4]; 4],
    pub sun_dir: [f32; 4],
    pub sun_color: [f32; 4],
    pub sky_zenith: [f32; 4],
    pub sky_horizon: [f32; 4],
    /// x: fog density per metre, y: largest fog amount, z: debug mode, w: unused.
    pub fog: [f32; 4],
}

/// Mirrors `Node` in `terrain.wgsl`; one per draw, at a 256-byte stride (dynamic offset).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct NodeUniforms {
    /// xyz: node origin minus camera (m); w: dither interval start.
    pub offset_lo: [f32; 4],
    /// x: dither interval end, y: quad-tree level.
    pub hi_level: [f32; 4],
    /// Fills the struct to the 256-byte stride.
    pub padding: [[f32; 4]; 14],
}

/// Bytes between two draws' node uniforms (the largest `min_uniform_buffer_offset_alignment`).
pub const NODE_UNIFORM_STRIDE: u64 = 256;

/// Mirrors `VertexIn` in `terrain.wgsl` (28 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct TerrainVertex {
    /// x, y relative to the node's south-west corner; z absolute (m).
    pub position: [f32; 3],
    pub normal: [f32; 3],
    /// Ground-type legend index.
    pub ground: u32,
}

/// Mirrors `PlantIn`'s instance part in `terrain.wgsl` (32 bytes, one per vegetation item).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct PlantInstance {
    /// x, y relative to the node's south-west corner; z absolute ground height (m).
    pub position: [f32; 3],
    pub height_m: f32,
    pub radius_m: f32,
    pub yaw_rad: f32,
    /// Index into the frame's plant looks (shape, colour).
    pub look: u32,
    pub padding: u32,
}

const _: () = assert!(std::mem::size_of::<PlantInstance>() == crate::vegetation::INSTANCE_BYTES);
const _: () = assert!(std::mem::size_of::<NodeUniforms>() as u64 == NODE_UNIFORM_STRIDE);
const _: () = assert!(std::mem::size_of::<TerrainVertex>() == 28);
const _: () = assert!(std::mem::size_of::<FrameUniforms>() == 2 * 64 + 5 * 16);
