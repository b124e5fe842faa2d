//! The terrain renderer: long-lived pipelines (terrain fill, terrain wireframe, sky, debug
//! lines), per-node GPU buffers, per-frame uniforms.

use super::gpu_data::{
    FrameUniforms, NODE_UNIFORM_STRIDE, NodeUniforms, PlantInstance, TerrainVertex,
};
use super::{DEPTH_FORMAT, Gpu};
use crate::bounds::NodeBounds;
use crate::mesh::NodeMesh;
use crate::plants::{self, PlantMeshes, Shape};
use crate::quadtree::{NodeKey, QuadTree};
use crate::select::Camera;
use crate::vegetation::{NodeVegetation, Representation};
use bytemuck::Zeroable;
use glam::{DVec3, Vec3};
use wgpu::util::DeviceExt;

/// The terrain shader source, embedded (release builds use only this copy).
pub const TERRAIN_WGSL: &str = include_str!("../../../shaders/terrain.wgsl");

/// The shader text: in debug builds the file on disk when present (edit and rerun without a
/// rebuild), else the embedded copy.
fn shader_source() -> std::borrow::Cow<'static, str> {
    #[cfg(debug_assertions)]
    {
        let p = concat!(env!("CARGO_MANIFEST_DIR"), "/../shaders/terrain.wgsl");
        if let Ok(s) = std::fs::read_to_string(p) {
            return s.into();
        }
    }
    TERRAIN_WGSL.into()
}

/// One node's buffers on the GPU.
pub struct TerrainNodeGpu {
    pub key: NodeKey,
    pub origin_m: [f64; 2],
    pub bounds: NodeBounds,
    /// World-space box of the node.
    pub aabb_m: (DVec3, DVec3),
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    index_count: u32,
    pub bytes: usize,
    /// The node's vegetation instances, when it has any.
    pub plants: Option<PlantsGpu>,
}

/// One instance group of a node on the GPU.
#[derive(Debug, Clone, Copy)]
struct PlantGroupGpu {
    first: u32,
    count: u32,
    shape: Shape,
    kind: PlantDraw,
    /// Drawn the same way at every finer level: drawn through the node's splits.
    kept: bool,
}

/// How a group is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PlantDraw {
    Mesh,
    Billboard,
    /// Cluster quads sampling the node's impostor texture.
    Impostor,
}

/// Group billboards: clusters per node side (an 8 x 8 grid) and the tile size of a cluster in the
/// node's impostor texture.
const CLUSTERS_PER_SIDE: u32 = 8;
const IMPOSTOR_TILE_PX: u32 = 32;
const IMPOSTOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

/// Mirrors `Cluster` in `terrain.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ClusterUniform {
    centre_bottom_half: [f32; 4],
    height: [f32; 4],
}

/// A node's vegetation instances (one buffer, groups are ranges of it).
pub struct PlantsGpu {
    instances: wgpu::Buffer,
    /// The node's group-billboard texture (8 x 8 cluster tiles), when it has group members.
    impostors: Option<wgpu::BindGroup>,
    groups: Vec<PlantGroupGpu>,
    /// World-space box of the items (ground to tree tops).
    pub aabb_m: (DVec3, DVec3),
    pub bytes: usize,
    low_detail: bool,
}

impl std::fmt::Debug for PlantsGpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "PlantsGpu({} groups, {} bytes)",
            self.groups.len(),
            self.bytes
        )
    }
}

impl std::fmt::Debug for TerrainNodeGpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "TerrainNodeGpu({:?}, {} bytes)", self.key, self.bytes)
    }
}

impl TerrainNodeGpu {
    pub fn triangles(&self) -> u32 {
        self.index_count / 3
    }
}

/// Debug views and per-view switches.
#[derive(Debug, Clone, Copy, PartialEq)]
#[allow(
    clippy::struct_excessive_bools,
    reason = "independent on/off switches of the viewer's panel"
)]
pub struct ViewOptions {
    pub wireframe: bool,
    pub color_by_level: bool,
    pub show_bounds: bool,
    /// Draw the sky gradient (off: the clear colour shows wherever nothing was drawn).
    pub sky: bool,
    /// Clear colour (linear RGBA) behind everything.
    pub clear: [f64; 4],
    /// Distance fog: density per metre and largest amount (depth cueing, never hiding).
    pub fog_per_m: f32,
    pub fog_max: f32,
    /// Draw vegetation.
    pub plants: bool,
}

impl Default for ViewOptions {
    fn default() -> Self {
        Self {
            wireframe: false,
            color_by_level: false,
            show_bounds: false,
            sky: true,
            clear: [0.0, 0.0, 0.0, 1.0],
            fog_per_m: 1.0 / 25_000.0,
            fog_max: 0.35,
            plants: true,
        }
    }
}

/// One node to draw and its dither interval.
#[derive(Debug, Clone, Copy)]
pub struct Draw<'a> {
    pub node: &'a TerrainNodeGpu,
    pub dither_lo: f32,
    pub dither_hi: f32,
}

/// What one frame drew.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DrawStats {
    pub draw_calls: u32,
    pub triangles: u64,
    pub culled: u32,
    /// Vegetation: instances drawn (meshes and billboards), their draw calls and mesh triangles.
    pub plant_instances: u64,
    pub plant_draw_calls: u32,
    pub plant_triangles: u64,
    /// Of the instances: group-billboard quads (each stands for a cluster of items).
    pub group_billboards: u64,
}

pub struct TerrainRenderer {
    fill: wgpu::RenderPipeline,
    wire: Option<wgpu::RenderPipeline>,
    sky: wgpu::RenderPipeline,
    lines: wgpu::RenderPipeline,
    frame_buffer: wgpu::Buffer,
    frame_group: wgpu::BindGroup,
    node_layout: wgpu::BindGroupLayout,
    node_buffer: wgpu::Buffer,
    node_group: wgpu::BindGroup,
    node_capacity: u64,
    line_buffer: wgpu::Buffer,
    line_capacity: u64,
    plant_mesh: wgpu::RenderPipeline,
    billboard: wgpu::RenderPipeline,
    plant_vertices: wgpu::Buffer,
    plant_indices: wgpu::Buffer,
    plant_meshes: PlantMeshes,
    looks_buffer: wgpu::Buffer,
    /// Shape per look index (species).
    shapes: Vec<Shape>,
    bake: wgpu::RenderPipeline,
    atlas_view: wgpu::TextureView,
    atlas_group: wgpu::BindGroup,
    atlas_layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    group_bake: wgpu::RenderPipeline,
    cluster_layout: wgpu::BindGroupLayout,
    impostor: wgpu::RenderPipeline,
}

/// Billboard atlas: one tile per look, `ATLAS_TILE_PX` each, linear colour + coverage.
const ATLAS_TILES: u32 = 16;
const ATLAS_TILE_PX: [u32; 2] = [64, 128];
const ATLAS_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

impl std::fmt::Debug for TerrainRenderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "TerrainRenderer({} node slots)", self.node_capacity)
    }
}

/// A bake pass: colour cleared to transparent, reversed-Z depth cleared to 0 (far).
fn bake_pass<'e>(
    enc: &'e mut wgpu::CommandEncoder,
    label: &str,
    color: &wgpu::TextureView,
    depth: &wgpu::TextureView,
) -> wgpu::RenderPass<'e> {
    enc.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: color,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations {
                load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                store: wgpu::StoreOp::Store,
            },
        })],
        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
            view: depth,
            depth_ops: Some(wgpu::Operations {
                load: wgpu::LoadOp::Clear(0.0),
                store: wgpu::StoreOp::Discard,
            }),
            stencil_ops: None,
        }),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

fn srgb_to_linear(c: u8) -> f32 {
    let c = f32::from(c) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

fn node_group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    buffer: &wgpu::Buffer,
) -> wgpu::BindGroup {
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("terrain node uniforms"),
        layout,
        entries: &[wgpu::BindGroupEntry {
            binding: 0,
            resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer,
                offset: 0,
                size: wgpu::BufferSize::new(std::mem::size_of::<NodeUniforms>() as u64),
            }),
        }],
    })
}

impl TerrainRenderer {
    /// Pipelines drawing into `color_format` (an sRGB format) for `legend_srgb` ground colours
    /// (the map's legend, at most 256).
    pub fn new(gpu: &Gpu, color_format: wgpu::TextureFormat, legend_srgb: &[[u8; 3]]) -> Self {
        let device = &gpu.device;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("terrain.wgsl"),
            source: wgpu::ShaderSource::Wgsl(shader_source()),
        });
        let uniform_entry =
            |binding: u32, dynamic: bool, vis: wgpu::ShaderStages| wgpu::BindGroupLayoutEntry {
                binding,
                visibility: vis,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: dynamic,
                    min_binding_size: None,
                },
                count: None,
            };
        let vf = wgpu::ShaderStages::VERTEX_FRAGMENT;
        let frame_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("terrain frame layout"),
            entries: &[
                uniform_entry(0, false, vf),
                uniform_entry(1, false, vf),
                uniform_entry(2, false, vf),
            ],
        });
        let node_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("terrain node layout"),
            entries: &[uniform_entry(0, true, vf)],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("terrain pipeline layout"),
            bind_group_layouts: &[Some(&frame_layout), Some(&node_layout)],
            immediate_size: 0,
        });
        let frame_only = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("sky/lines pipeline layout"),
            bind_group_layouts: &[Some(&frame_layout)],
            immediate_size: 0,
        });
        let vertex_layout = wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<TerrainVertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Uint32],
        };
        let depth = |write: bool, compare: wgpu::CompareFunction| wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(write),
            depth_compare: Some(compare),
            stencil: wgpu::StencilState::default(),
            bias: wgpu::DepthBiasState::default(),
        };
        let target = [Some(wgpu::ColorTargetState {
            format: color_format,
            blend: None,
            write_mask: wgpu::ColorWrites::ALL,
        })];
        let terrain_pipeline = |label: &str, mode: wgpu::PolygonMode| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(&layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs_main"),
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                    buffers: &[Some(vertex_layout.clone())],
                },
                primitive: wgpu::PrimitiveState {
                    topology: wgpu::PrimitiveTopology::TriangleList,
                    cull_mode: None,
                    polygon_mode: mode,
                    ..Default::default()
                },
                depth_stencil: Some(depth(true, wgpu::CompareFunction::Greater)),
                multisample: wgpu::MultisampleState::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs_main"),
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                    targets: &target,
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let fill = terrain_pipeline("terrain fill", wgpu::PolygonMode::Fill);
        let wire = gpu
            .wireframe
            .then(|| terrain_pipeline("terrain wireframe", wgpu::PolygonMode::Line));
        let instance_layout = wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<PlantInstance>() as u64,
            step_mode: wgpu::VertexStepMode::Instance,
            attributes: &wgpu::vertex_attr_array![
                3 => Float32x3, 4 => Float32, 5 => Float32, 6 => Float32, 7 => Uint32
            ],
        };
        let atlas_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("billboard atlas layout"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: true },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
            ],
        });
        let billboard_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("billboard pipeline layout"),
            bind_group_layouts: &[Some(&frame_layout), Some(&node_layout), Some(&atlas_layout)],
            immediate_size: 0,
        });
        // Triangle lists, no culling, reversed-Z depth: plants, billboards and the two bakes
        // (which draw into their own formats).
        let plant_pipeline = |label: &str,
                              vs: &str,
                              fs: &str,
                              buffers: &[Option<wgpu::VertexBufferLayout<'_>>],
                              layout: &wgpu::PipelineLayout,
                              format: wgpu::TextureFormat| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some(vs),
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                    buffers,
                },
                primitive: wgpu::PrimitiveState {
                    topology: wgpu::PrimitiveTopology::TriangleList,
                    cull_mode: None,
                    ..Default::default()
                },
                depth_stencil: Some(depth(true, wgpu::CompareFunction::Greater)),
                multisample: wgpu::MultisampleState::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some(fs),
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format,
                        blend: None,
                        write_mask: wgpu::ColorWrites::ALL,
                    })],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let plant_mesh = plant_pipeline(
            "plant meshes",
            "vs_plant",
            "fs_main",
            &[Some(vertex_layout.clone()), Some(instance_layout.clone())],
            &layout,
            color_format,
        );
        let billboard = plant_pipeline(
            "plant billboards",
            "vs_billboard",
            "fs_billboard",
            &[Some(instance_layout.clone())],
            &billboard_layout,
            color_format,
        );
        let impostor_instance_layout = instance_layout.clone();
        let atlas = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("billboard atlas"),
            size: wgpu::Extent3d {
                width: ATLAS_TILE_PX[0] * ATLAS_TILES,
                height: ATLAS_TILE_PX[1],
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: ATLAS_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        });
        let atlas_view = atlas.create_view(&wgpu::TextureViewDescriptor::default());
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("billboard atlas sampler"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        let atlas_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("billboard atlas group"),
            layout: &atlas_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(&atlas_view),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::Sampler(&sampler),
                },
            ],
        });
        let bake_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("billboard bake layout"),
            bind_group_layouts: &[Some(&frame_layout)],
            immediate_size: 0,
        });
        let bake = plant_pipeline(
            "billboard bake",
            "vs_bake",
            "fs_bake",
            &[Some(vertex_layout.clone()), Some(instance_layout)],
            &bake_layout,
            ATLAS_FORMAT,
        );
        let cluster_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("impostor cluster layout"),
            entries: &[uniform_entry(1, false, wgpu::ShaderStages::VERTEX)],
        });
        let group_bake_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("impostor bake layout"),
            bind_group_layouts: &[
                Some(&frame_layout),
                Some(&cluster_layout),
                Some(&atlas_layout),
            ],
            immediate_size: 0,
        });
        let member_layout = wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<PlantInstance>() as u64,
            step_mode: wgpu::VertexStepMode::Instance,
            attributes: &wgpu::vertex_attr_array![
                3 => Float32x3, 4 => Float32, 5 => Float32, 6 => Float32, 7 => Uint32, 8 => Uint32
            ],
        };
        let group_bake = plant_pipeline(
            "impostor bake",
            "vs_group_bake",
            "fs_group_bake",
            &[Some(member_layout)],
            &group_bake_layout,
            IMPOSTOR_FORMAT,
        );
        let impostor = plant_pipeline(
            "plant group billboards",
            "vs_billboard",
            "fs_impostor",
            &[Some(impostor_instance_layout)],
            &billboard_layout,
            color_format,
        );
        let plant_meshes = PlantMeshes::generate();
        let plant_vertex_data: Vec<TerrainVertex> = plant_meshes
            .vertices
            .iter()
            .map(|v| TerrainVertex {
                position: v.position,
                normal: v.normal,
                ground: v.part,
            })
            .collect();
        let plant_vertices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("plant shape vertices"),
            contents: bytemuck::cast_slice(&plant_vertex_data),
            usage: wgpu::BufferUsages::VERTEX,
        });
        let plant_indices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("plant shape indices"),
            contents: bytemuck::cast_slice(&plant_meshes.indices),
            usage: wgpu::BufferUsages::INDEX,
        });
        let looks_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("plant looks"),
            size: 16 * 16,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let simple = |label: &str,
                      vs: &str,
                      fs: &str,
                      topology: wgpu::PrimitiveTopology,
                      buffers: &[Option<wgpu::VertexBufferLayout<'_>>],
                      depth_state: wgpu::DepthStencilState| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(&frame_only),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some(vs),
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                    buffers,
                },
                primitive: wgpu::PrimitiveState {
                    topology,
                    ..Default::default()
                },
                depth_stencil: Some(depth_state),
                multisample: wgpu::MultisampleState::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some(fs),
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                    targets: &target,
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let sky = simple(
            "sky",
            "vs_sky",
            "fs_sky",
            wgpu::PrimitiveTopology::TriangleList,
            &[],
            depth(false, wgpu::CompareFunction::Always),
        );
        let line_layout = wgpu::VertexBufferLayout {
            array_stride: 12,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &wgpu::vertex_attr_array![0 => Float32x3],
        };
        let lines = simple(
            "node bounds lines",
            "vs_lines",
            "fs_lines",
            wgpu::PrimitiveTopology::LineList,
            &[Some(line_layout)],
            depth(false, wgpu::CompareFunction::GreaterEqual),
        );
        let frame_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("terrain frame uniforms"),
            size: std::mem::size_of::<FrameUniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut colors = vec![[0.5f32, 0.5, 0.5, 1.0]; 256];
        for (c, l) in colors.iter_mut().zip(legend_srgb) {
            *c = [
                srgb_to_linear(l[0]),
                srgb_to_linear(l[1]),
                srgb_to_linear(l[2]),
                1.0,
            ];
        }
        let colors_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("ground colours"),
            contents: bytemuck::cast_slice(&colors),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let frame_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("terrain frame group"),
            layout: &frame_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: frame_buffer.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: colors_buffer.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: looks_buffer.as_entire_binding(),
                },
            ],
        });
        let node_capacity = 256;
        let node_buffer = Self::node_buffer(device, node_capacity);
        let node_group = node_group(device, &node_layout, &node_buffer);
        let line_capacity = 1024;
        let line_buffer = Self::line_buffer(device, line_capacity);
        Self {
            fill,
            wire,
            sky,
            lines,
            frame_buffer,
            frame_group,
            node_layout,
            node_buffer,
            node_group,
            node_capacity,
            line_buffer,
            line_capacity,
            plant_mesh,
            billboard,
            plant_vertices,
            plant_indices,
            plant_meshes,
            looks_buffer,
            shapes: Vec::new(),
            bake,
            atlas_view,
            atlas_group,
            atlas_layout,
            sampler,
            group_bake,
            cluster_layout,
            impostor,
        }
    }

    /// Sets the shape and colour of each vegetation species (look index = species index, at
    /// most 16), from the species names.
    pub fn set_plant_looks(&mut self, gpu: &Gpu, species_names: &[String]) {
        let mut data = [[0.3f32, 0.45, 0.2, 2.0]; 16];
        self.shapes.clear();
        for (i, name) in species_names.iter().take(16).enumerate() {
            let (shape, c) = plants::look(name);
            data[i] = [
                srgb_to_linear(c[0]),
                srgb_to_linear(c[1]),
                srgb_to_linear(c[2]),
                shape as u32 as f32,
            ];
            self.shapes.push(shape);
        }
        gpu.queue
            .write_buffer(&self.looks_buffer, 0, bytemuck::cast_slice(&data));
        self.bake_billboards(gpu);
    }

    /// Renders every look's billboard image from its high-detail mesh into the atlas (seen
    /// from the south, lit by the frame's sun and sky).
    fn bake_billboards(&self, gpu: &Gpu) {
        let device = &gpu.device;
        let cam = Camera::look_at(DVec3::ZERO, DVec3::new(0.0, 1.0, 0.0), 1.0, [64, 64]);
        gpu.queue.write_buffer(
            &self.frame_buffer,
            0,
            bytemuck::bytes_of(&Self::frame_uniforms(&cam, &ViewOptions::default())),
        );
        let instances: Vec<PlantInstance> = (0..ATLAS_TILES)
            .map(|i| PlantInstance {
                position: [0.0; 3],
                height_m: 1.0,
                radius_m: 1.0,
                yaw_rad: 0.0,
                look: i,
                padding: 0,
            })
            .collect();
        let instance_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("billboard bake instances"),
            contents: bytemuck::cast_slice(&instances),
            usage: wgpu::BufferUsages::VERTEX,
        });
        let depth_view = super::depth_view(
            device,
            [ATLAS_TILE_PX[0] * ATLAS_TILES, ATLAS_TILE_PX[1]],
            "billboard bake depth",
        );
        let mut enc = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("billboard bake"),
        });
        {
            let mut pass = bake_pass(
                &mut enc,
                "billboard bake pass",
                &self.atlas_view,
                &depth_view,
            );
            pass.set_pipeline(&self.bake);
            pass.set_bind_group(0, &self.frame_group, &[]);
            pass.set_vertex_buffer(0, self.plant_vertices.slice(..));
            pass.set_vertex_buffer(1, instance_buffer.slice(..));
            pass.set_index_buffer(self.plant_indices.slice(..), wgpu::IndexFormat::Uint32);
            for (i, shape) in self.shapes.iter().enumerate().take(ATLAS_TILES as usize) {
                let [w, h] = ATLAS_TILE_PX;
                pass.set_viewport((i as u32 * w) as f32, 0.0, w as f32, h as f32, 0.0, 1.0);
                let (first, count, base) = self.plant_meshes.ranges[*shape as usize][0];
                pass.draw_indexed(first..first + count, base, i as u32..i as u32 + 1);
            }
        }
        gpu.queue.submit([enc.finish()]);
    }

    /// Uploads a node's vegetation instances (None when it has none). Group-billboard members
    /// are baked, cluster by cluster, into the node's impostor texture (a render pass submitted
    /// here); the node then draws one quad per cluster instead of its members.
    pub fn upload_plants(
        &self,
        gpu: &Gpu,
        tree: &QuadTree,
        key: NodeKey,
        veg: &NodeVegetation,
    ) -> Option<PlantsGpu> {
        if veg.instances() == 0 {
            return None;
        }
        let device = &gpu.device;
        let rect = tree.rect(key);
        let o = rect.min;
        let side = rect.max[0] - rect.min[0];
        let instance = |it: &crate::vegetation::Item, cluster: u32| PlantInstance {
            position: [
                (it.x_m - o[0]) as f32,
                (it.y_m - o[1]) as f32,
                it.z_m as f32,
            ],
            height_m: it.height_m,
            radius_m: it.radius_m,
            yaw_rad: it.yaw_rad,
            look: u32::from(it.species),
            padding: cluster,
        };
        let mut data: Vec<PlantInstance> = Vec::with_capacity(veg.instances());
        let mut groups = Vec::with_capacity(veg.groups.len());
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        // Group members by cluster: (x range, y range, bottom, top, radius) and the members.
        let n = CLUSTERS_PER_SIDE as usize;
        let mut boxes = vec![
            [
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
                0.0
            ];
            n * n
        ];
        let mut members: Vec<PlantInstance> = Vec::new();
        let mut member_kept = true;
        for g in &veg.groups {
            for it in &g.items {
                let r = f64::from(it.radius_m);
                lo = lo.min(DVec3::new(it.x_m - r, it.y_m - r, it.z_m - 1.0));
                hi = hi.max(DVec3::new(
                    it.x_m + r,
                    it.y_m + r,
                    it.z_m + f64::from(it.height_m),
                ));
            }
            if g.representation == Representation::Group {
                member_kept &= !g.replaced_on_split;
                for it in &g.items {
                    let cell = |v: f64| (((v / side) * n as f64) as usize).min(n - 1);
                    let c = cell(it.y_m - o[1]) * n + cell(it.x_m - o[0]);
                    let b = &mut boxes[c];
                    let r = f64::from(it.radius_m);
                    b[0] = b[0].min(it.x_m - o[0] - r);
                    b[1] = b[1].max(it.x_m - o[0] + r);
                    b[2] = b[2].min(it.y_m - o[1] - r);
                    b[3] = b[3].max(it.y_m - o[1] + r);
                    b[4] = b[4].min(it.z_m);
                    b[5] = b[5].max(it.z_m + f64::from(it.height_m));
                    members.push(instance(it, c as u32));
                }
                continue;
            }
            let first = data.len() as u32;
            data.extend(g.items.iter().map(|it| instance(it, 0)));
            groups.push(PlantGroupGpu {
                first,
                count: g.items.len() as u32,
                shape: self
                    .shapes
                    .get(usize::from(g.species))
                    .copied()
                    .unwrap_or(Shape::Bush),
                kind: if g.representation == Representation::Mesh {
                    PlantDraw::Mesh
                } else {
                    PlantDraw::Billboard
                },
                kept: !g.replaced_on_split,
            });
        }
        let mut impostors = None;
        let mut texture_bytes = 0;
        if !members.is_empty() {
            // Cluster quads: centre, bottom, half width (the wider of the x and y spans, so a
            // turned quad still covers the members), height; `look` = tile index.
            let mut uniforms = [ClusterUniform::zeroed(); 64];
            let first = data.len() as u32;
            for (c, b) in boxes.iter().enumerate() {
                if b[0] > b[1] {
                    continue;
                }
                let centre = [0.5 * (b[0] + b[1]), 0.5 * (b[2] + b[3])];
                let half = 0.5 * (b[1] - b[0]).max(b[3] - b[2]);
                let height = b[5] - b[4];
                uniforms[c] = ClusterUniform {
                    centre_bottom_half: [
                        centre[0] as f32,
                        centre[1] as f32,
                        b[4] as f32,
                        half as f32,
                    ],
                    height: [height as f32, 0.0, 0.0, 0.0],
                };
                data.push(PlantInstance {
                    position: [centre[0] as f32, centre[1] as f32, b[4] as f32],
                    height_m: height as f32,
                    radius_m: half as f32,
                    yaw_rad: 0.0,
                    look: c as u32,
                    padding: 0,
                });
            }
            groups.push(PlantGroupGpu {
                first,
                count: data.len() as u32 - first,
                shape: Shape::Bush,
                kind: PlantDraw::Impostor,
                kept: member_kept,
            });
            let (group, bytes) = self.bake_impostors(gpu, key, &uniforms, &members);
            impostors = Some(group);
            texture_bytes = bytes;
        }
        let instances = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(&format!("node {}/{}/{} plants", key.level, key.ix, key.iy)),
            contents: bytemuck::cast_slice(&data),
            usage: wgpu::BufferUsages::VERTEX,
        });
        Some(PlantsGpu {
            instances,
            impostors,
            groups,
            aabb_m: (lo, hi),
            bytes: data.len() * std::mem::size_of::<PlantInstance>() + texture_bytes,
            low_detail: tree.spacing_m(key.level) >= 1.0,
        })
    }

    /// Renders a node's group members into its impostor texture (one tile per cluster, seen
    /// from the south) and returns the texture's bind group and size in bytes.
    fn bake_impostors(
        &self,
        gpu: &Gpu,
        key: NodeKey,
        clusters: &[ClusterUniform; 64],
        members: &[PlantInstance],
    ) -> (wgpu::BindGroup, usize) {
        let device = &gpu.device;
        let label = format!("node {}/{}/{} impostors", key.level, key.ix, key.iy);
        let px = CLUSTERS_PER_SIDE * IMPOSTOR_TILE_PX;
        let size = wgpu::Extent3d {
            width: px,
            height: px,
            depth_or_array_layers: 1,
        };
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some(&label),
            size,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: IMPOSTOR_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        let depth_view = super::depth_view(device, [px, px], "impostor bake depth");
        let cluster_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("impostor clusters"),
            contents: bytemuck::cast_slice(clusters),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let cluster_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("impostor clusters"),
            layout: &self.cluster_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 1,
                resource: cluster_buffer.as_entire_binding(),
            }],
        });
        let member_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("impostor members"),
            contents: bytemuck::cast_slice(members),
            usage: wgpu::BufferUsages::VERTEX,
        });
        let mut enc = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some(&label),
        });
        {
            let mut pass = bake_pass(&mut enc, "impostor bake pass", &view, &depth_view);
            pass.set_pipeline(&self.group_bake);
            pass.set_bind_group(0, &self.frame_group, &[]);
            pass.set_bind_group(1, &cluster_group, &[]);
            pass.set_bind_group(2, &self.atlas_group, &[]);
            pass.set_vertex_buffer(0, member_buffer.slice(..));
            pass.draw(0..6, 0..members.len() as u32);
        }
        gpu.queue.submit([enc.finish()]);
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(&label),
            layout: &self.atlas_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(&view),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::Sampler(&self.sampler),
                },
            ],
        });
        (group, (px * px * 4) as usize)
    }

    fn node_buffer(device: &wgpu::Device, slots: u64) -> wgpu::Buffer {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("terrain node uniforms"),
            size: slots * NODE_UNIFORM_STRIDE,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    fn line_buffer(device: &wgpu::Device, vertices: u64) -> wgpu::Buffer {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("node bounds lines"),
            size: vertices * 12,
            usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// Uploads one node mesh (vertices relative to its south-west corner, z absolute).
    pub fn upload(device: &wgpu::Device, tree: &QuadTree, mesh: &NodeMesh) -> TerrainNodeGpu {
        let vertices: Vec<TerrainVertex> = mesh
            .positions
            .iter()
            .zip(&mesh.normals)
            .zip(&mesh.ground)
            .map(|((p, n), g)| TerrainVertex {
                position: *p,
                normal: *n,
                ground: u32::from(*g),
            })
            .collect();
        let label = format!("node {}/{}/{}", mesh.key.level, mesh.key.ix, mesh.key.iy);
        let vb = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(&format!("{label} vertices")),
            contents: bytemuck::cast_slice(&vertices),
            usage: wgpu::BufferUsages::VERTEX,
        });
        let ib = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(&format!("{label} indices")),
            contents: bytemuck::cast_slice(&mesh.indices),
            usage: wgpu::BufferUsages::INDEX,
        });
        let size = tree.node_size_m(mesh.key.level);
        // The skirts reach below z_min; the box covers them.
        let skirt_min = mesh
            .skirt_bottom_m
            .iter()
            .copied()
            .fold(mesh.bounds.z_min_m, f64::min);
        TerrainNodeGpu {
            key: mesh.key,
            origin_m: mesh.origin_m,
            bounds: mesh.bounds,
            aabb_m: (
                DVec3::new(mesh.origin_m[0], mesh.origin_m[1], skirt_min),
                DVec3::new(
                    mesh.origin_m[0] + size,
                    mesh.origin_m[1] + size,
                    mesh.bounds.z_max_m,
                ),
            ),
            vertices: vb,
            indices: ib,
            index_count: mesh.indices.len() as u32,
            bytes: vertices.len() * std::mem::size_of::<TerrainVertex>() + mesh.indices.len() * 4,
            plants: None,
        }
    }

    /// Frame uniforms for a camera: the view rotation and an infinite reversed-Z projection.
    pub fn frame_uniforms(cam: &Camera, view: &ViewOptions) -> FrameUniforms {
        let f = cam.forward.as_vec3();
        let u = cam.up.as_vec3();
        let view_m = glam::camera::rh::view::look_to_mat4(Vec3::ZERO, f, u);
        // WebGPU convention: NDC z in [0, 1], y up; reversed-Z with an infinite far plane.
        let proj = glam::camera::rh::proj::directx::perspective_infinite_reverse(
            cam.fovy_rad as f32,
            cam.aspect() as f32,
            cam.near_m as f32,
        );
        let clip_from_rel = proj * view_m;
        let sun = Vec3::new(0.45, 0.3, 0.62).normalize();
        FrameUniforms {
            clip_from_rel: clip_from_rel.to_cols_array_2d(),
            rel_from_clip: clip_from_rel.inverse().to_cols_array_2d(),
            sun_dir: [sun.x, sun.y, sun.z, 0.0],
            sun_color: [1.0, 0.93, 0.82, 0.0],
            sky_zenith: [0.16, 0.32, 0.66, 1.0],
            sky_horizon: [0.62, 0.72, 0.84, 1.0],
            fog: [
                view.fog_per_m,
                view.fog_max,
                if view.color_by_level { 1.0 } else { 0.0 },
                0.0,
            ],
        }
    }

    /// Records the frame: sky, visible nodes (culled by their box), optional bounds lines.
    pub fn render(
        &mut self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        cam: &Camera,
        draws: &[Draw<'_>],
        kept: &[&TerrainNodeGpu],
        view: &ViewOptions,
    ) -> DrawStats {
        let frustum = cam.frustum();
        let visible: Vec<&Draw<'_>> = draws
            .iter()
            .filter(|d| d.dither_hi > d.dither_lo)
            .filter(|d| frustum.intersects_aabb(d.node.aabb_m.0, d.node.aabb_m.1))
            .collect();
        // Vegetation: the drawn nodes' groups with their dither interval (kept groups of a node
        // that is also in `kept` go with it instead), and the kept groups of `kept` nodes (the
        // ancestors of drawn nodes) in full. Uniform slots follow the terrain's.
        let kept_keys: rustc_hash::FxHashSet<NodeKey> = kept.iter().map(|n| n.key).collect();
        let mut plant_slots: Vec<(&TerrainNodeGpu, f32, f32)> = Vec::new();
        // (slot, plants, which groups): 0 all, 1 replaced ones only, 2 kept ones only.
        let mut plant_draws: Vec<(usize, &PlantsGpu, u8)> = Vec::new();
        if view.plants {
            for d in draws.iter().filter(|d| d.dither_hi > d.dither_lo) {
                if let Some(p) = &d.node.plants
                    && frustum.intersects_aabb(p.aabb_m.0, p.aabb_m.1)
                {
                    let which = u8::from(kept_keys.contains(&d.node.key));
                    plant_draws.push((plant_slots.len(), p, which));
                    plant_slots.push((d.node, d.dither_lo, d.dither_hi));
                }
            }
            for n in kept {
                if let Some(p) = &n.plants
                    && p.groups.iter().any(|g| g.kept)
                    && frustum.intersects_aabb(p.aabb_m.0, p.aabb_m.1)
                {
                    plant_draws.push((plant_slots.len(), p, 2));
                    plant_slots.push((n, 0.0, 1.0));
                }
            }
        }
        let mut stats = DrawStats {
            culled: (draws.len() - visible.len()) as u32,
            ..DrawStats::default()
        };
        gpu.queue.write_buffer(
            &self.frame_buffer,
            0,
            bytemuck::bytes_of(&Self::frame_uniforms(cam, view)),
        );
        let needed = ((visible.len() + plant_slots.len()) as u64).max(1);
        if needed > self.node_capacity {
            self.node_capacity = needed.next_power_of_two();
            self.node_buffer = Self::node_buffer(&gpu.device, self.node_capacity);
            self.node_group = node_group(&gpu.device, &self.node_layout, &self.node_buffer);
        }
        let c = cam.position_m;
        let uniforms = |node: &TerrainNodeGpu, lo: f32, hi: f32| {
            let o = node.origin_m;
            NodeUniforms {
                offset_lo: [(o[0] - c.x) as f32, (o[1] - c.y) as f32, (-c.z) as f32, lo],
                hi_level: [hi, f32::from(node.key.level), 0.0, 0.0],
                padding: [[0.0; 4]; 14],
            }
        };
        let nodes: Vec<NodeUniforms> = visible
            .iter()
            .map(|d| uniforms(d.node, d.dither_lo, d.dither_hi))
            .chain(plant_slots.iter().map(|&(n, lo, hi)| uniforms(n, lo, hi)))
            .collect();
        if !nodes.is_empty() {
            gpu.queue
                .write_buffer(&self.node_buffer, 0, bytemuck::cast_slice(&nodes));
        }
        let mut lines: Vec<[f32; 3]> = Vec::new();
        if view.show_bounds {
            for d in &visible {
                let (lo, hi) = (d.node.aabb_m.0 - c, d.node.aabb_m.1 - c);
                let corner = |i: usize| {
                    [
                        if i & 1 == 0 { lo.x } else { hi.x } as f32,
                        if i & 2 == 0 { lo.y } else { hi.y } as f32,
                        if i & 4 == 0 { lo.z } else { hi.z } as f32,
                    ]
                };
                for (a, b) in [
                    (0, 1),
                    (2, 3),
                    (4, 5),
                    (6, 7),
                    (0, 2),
                    (1, 3),
                    (4, 6),
                    (5, 7),
                    (0, 4),
                    (1, 5),
                    (2, 6),
                    (3, 7),
                ] {
                    lines.push(corner(a));
                    lines.push(corner(b));
                }
            }
            if lines.len() as u64 > self.line_capacity {
                self.line_capacity = (lines.len() as u64).next_power_of_two();
                self.line_buffer = Self::line_buffer(&gpu.device, self.line_capacity);
            }
            if !lines.is_empty() {
                gpu.queue
                    .write_buffer(&self.line_buffer, 0, bytemuck::cast_slice(&lines));
            }
        }
        let [r, g, b, a] = view.clear;
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("terrain pass"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: color,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color { r, g, b, a }),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: depth,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(0.0),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_bind_group(0, &self.frame_group, &[]);
        if view.sky {
            pass.set_pipeline(&self.sky);
            pass.draw(0..3, 0..1);
        }
        let pipeline = match (&self.wire, view.wireframe) {
            (Some(w), true) => w,
            _ => &self.fill,
        };
        pass.set_pipeline(pipeline);
        for (i, d) in visible.iter().enumerate() {
            let offset = (i as u64 * NODE_UNIFORM_STRIDE) as u32;
            pass.set_bind_group(1, &self.node_group, &[offset]);
            pass.set_vertex_buffer(0, d.node.vertices.slice(..));
            pass.set_index_buffer(d.node.indices.slice(..), wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..d.node.index_count, 0, 0..1);
            stats.draw_calls += 1;
            stats.triangles += u64::from(d.node.triangles());
        }
        let base_slot = visible.len();
        for (slot, p, which) in plant_draws {
            let offset = ((base_slot + slot) as u64 * NODE_UNIFORM_STRIDE) as u32;
            pass.set_bind_group(1, &self.node_group, &[offset]);
            for g in &p.groups {
                if (which == 1 && g.kept) || (which == 2 && !g.kept) {
                    continue;
                }
                let instances = g.first..g.first + g.count;
                match g.kind {
                    PlantDraw::Billboard => {
                        pass.set_pipeline(&self.billboard);
                        pass.set_bind_group(2, &self.atlas_group, &[]);
                        pass.set_vertex_buffer(0, p.instances.slice(..));
                        pass.draw(0..6, instances);
                    }
                    PlantDraw::Impostor => {
                        let Some(tex) = &p.impostors else { continue };
                        pass.set_pipeline(&self.impostor);
                        pass.set_bind_group(2, tex, &[]);
                        pass.set_vertex_buffer(0, p.instances.slice(..));
                        pass.draw(0..6, instances);
                        stats.group_billboards += u64::from(g.count);
                    }
                    PlantDraw::Mesh => {
                        pass.set_pipeline(&self.plant_mesh);
                        pass.set_vertex_buffer(0, self.plant_vertices.slice(..));
                        pass.set_vertex_buffer(1, p.instances.slice(..));
                        pass.set_index_buffer(
                            self.plant_indices.slice(..),
                            wgpu::IndexFormat::Uint32,
                        );
                        let (first, count, base) =
                            self.plant_meshes.ranges[g.shape as usize][usize::from(p.low_detail)];
                        pass.draw_indexed(first..first + count, base, instances);
                        stats.plant_triangles += u64::from(count / 3) * u64::from(g.count);
                    }
                }
                stats.plant_instances += u64::from(g.count);
                stats.plant_draw_calls += 1;
            }
        }
        if view.show_bounds && !lines.is_empty() {
            pass.set_pipeline(&self.lines);
            pass.set_vertex_buffer(0, self.line_buffer.slice(..));
            pass.draw(0..lines.len() as u32, 0..1);
        }
        stats
    }
}
