//! Plain structs shared by every renderer, each mirroring a WGSL struct of
//! `shaders/prelude.inc.wgsl` field by field (std140-compatible: only vec4 and mat4x4 members in
//! uniforms). Renderer-specific structs live with their renderer.

use bytemuck::{Pod, Zeroable};

/// Mirrors `Frame`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct FrameUniforms {
    pub clip_from_rel: [[f32; 4]; 4],
    pub rel_from_clip: [[f32; 4]; 4],
    pub sun_dir: [f32; 4],
    pub sun_color: [f32; 4],
    pub sky_zenith: [f32; 4],
    pub sky_horizon: [f32; 4],
    /// x: fog density per metre, y: largest fog amount, z: debug mode ([`super::frame::ViewOptions::debug_mode`]), w: unused.
    pub fog: [f32; 4],
    /// xy: the camera's position modulo [`super::frame::DETAIL_PERIOD_M`] (world positions of
    /// nearby pixels, for the ground's fine detail, without f32 cancellation); zw: unused.
    pub camera_wrap: [f32; 4],
}

/// Mirrors `Node`: one row of a renderer's node table (a storage array of this frame's rows,
/// found by the draw's instance index or through the instance's `entry`, see
/// `render::node_table`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub struct NodeEntry {
    /// xyz: node origin minus camera (m); w: dither interval start.
    pub offset_lo: [f32; 4],
    /// x: dither interval end, y: quad-tree level, zw: the renderer's own (terrain: ground
    /// texture layer or -1, texture coordinates per metre).
    pub hi_level: [f32; 4],
    /// The node's light grid ([`super::light_pool::LightLease::entry`]): x its tile in the pool
    /// or -1, y columns per metre, zw the node's south-west corner in the grid's columns.
    pub light: [f32; 4],
    /// xy: more of the renderer's own (terrain: the node's south-west corner in metres from
    /// that of the node whose ground texture it shows: 0 for its own, more for an ancestor's
    /// while its own is not made yet); z: the node's sides toward a coarser light grid
    /// (`lighting::seams::SideSteps`), w: its width in its grid's columns.
    pub more: [f32; 4],
}

/// Mirrors `VertexIn` (28 bytes): plant-shape vertices (terrain vertices are two streams of
/// their own, `render::terrain`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct MeshVertex {
    /// Unit shape coordinates.
    pub position: [f32; 3],
    pub normal: [f32; 3],
    /// The part (0 trunk, 1 foliage).
    pub tag: u32,
}

impl MeshVertex {
    /// The vertex buffer layout (locations 0, 1, 2).
    pub const LAYOUT: wgpu::VertexBufferLayout<'static> = wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<Self>() as u64,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Uint32],
    };
}

const _: () = assert!(std::mem::size_of::<NodeEntry>() == 64);
const _: () = assert!(std::mem::size_of::<MeshVertex>() == 28);
const _: () = assert!(std::mem::size_of::<FrameUniforms>() == 2 * 64 + 6 * 16);
