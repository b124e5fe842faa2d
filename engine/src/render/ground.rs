//! The GPU part of a node's ground texture: renders the texels of a node's layout
//! ([`crate::ground::layout`]) into a colour target (the terrain renderer's pool layer for the
//! node) — each texel's ground type, resolved by the node's CPU phase
//! ([`crate::ground::types`]), shaded with the type's material ([`crate::ground::materials`], with CPU-made mips), then the node's closed
//! decal areas (fields, dirt, rock patches: each its box, an inside test and a soft edge) and
//! its road and path segments ([`crate::ground::pieces`]) with soft edges, each a quad around
//! its segment, blended in file order (areas before segments); then its mip levels, all of a
//! batch's textures in one compute pass (`record_mips`). The materials' detail height rides
//! in their alpha channel, which this pass ignores: the terrain shader bumps the ground's
//! normal with it near the camera (`render::ground_detail`).
//!
//! Nodes recorded between two submissions share one set of buffers: each node's uniforms sit
//! at a 256-byte dynamic offset, its segments and areas are instance ranges of the batch's
//! lists, its texels' types a range of the batch's type words, and [`GroundTexturer::submit`]
//! writes the batch once before submitting (a node texture creates no buffer, bind group or
//! view; the pool keeps each layer's views).

use super::Gpu;
use super::frame::{sampler_entry, texture_entry};
use super::ground_pool::LayerMips;
use crate::ground::content::NodeGround;
use crate::ground::layout::{SIDE, lattice_index, texel_m};
use crate::ground::material_layers::{self, MaterialLayers};
use crate::ground::materials::{MATERIAL_TEXELS, MATERIAL_TILE_M};
use crate::ground::pieces::NodeDecals;
use crate::ground::types::{TexelCells, TypeForm};
use crate::surface::World;
use crate::terrain::quadtree::{NodeKey, QuadTree};
use wgpu::util::DeviceExt;
use worldgen::map::DecalKind;

/// Format node ground textures are rendered into and sampled through (shaded in linear light,
/// stored sRGB).
pub const GROUND_TEXTURE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
/// Format of the pool's texture pages: the same bytes as [`GROUND_TEXTURE_FORMAT`] (pages are
/// viewed through it), but one that compute shaders can write: the mip pass writes the sRGB
/// encoding itself through views of this format.
pub const GROUND_PAGE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
/// Texels a side of level 0 one workgroup of the mip pass reduces (`cs_mips`: 16 x 16
/// invocations, one level-1 texel each, then levels 2 and 3 from the workgroup's memory).
const MIP_BLOCK: u32 = 32;
const _: () = assert!(
    crate::ground::layout::MIP_LEVELS == 4 && SIDE.is_multiple_of(MIP_BLOCK),
    "cs_mips writes levels 1 - 3 of whole 32 x 32 blocks"
);
/// Linear albedo of roads (asphalt) and paths (dirt).
const ROAD_LINEAR: [f32; 3] = [0.045, 0.045, 0.05];
const PATH_LINEAR: [f32; 3] = [0.26, 0.17, 0.09];
/// Linear albedo of the closed areas: rock patches, bare earth, and a field's two row tones.
const ROCK_PATCH_LINEAR: [f32; 3] = [0.21, 0.2, 0.19];
const DIRT_PATCH_LINEAR: [f32; 3] = [0.2, 0.13, 0.075];
const FIELD_LOW_LINEAR: [f32; 3] = [0.2, 0.13, 0.06];
const FIELD_HIGH_LINEAR: [f32; 3] = [0.36, 0.3, 0.08];

/// The assembled shader source.
pub fn shader_source() -> String {
    let v = |c: [f32; 3]| format!("vec3<f32>({:?}, {:?}, {:?})", c[0], c[1], c[2]);
    super::shader::assemble(
        "ground",
        &[
            format!("const SIDE: u32 = {SIDE}u;"),
            format!("const ROAD_COLOR: vec3<f32> = {};", v(ROAD_LINEAR)),
            format!("const PATH_COLOR: vec3<f32> = {};", v(PATH_LINEAR)),
            format!(
                "const ROCK_PATCH_COLOR: vec3<f32> = {};",
                v(ROCK_PATCH_LINEAR)
            ),
            format!(
                "const DIRT_PATCH_COLOR: vec3<f32> = {};",
                v(DIRT_PATCH_LINEAR)
            ),
            format!(
                "const FIELD_LOW_COLOR: vec3<f32> = {};",
                v(FIELD_LOW_LINEAR)
            ),
            format!(
                "const FIELD_HIGH_COLOR: vec3<f32> = {};",
                v(FIELD_HIGH_LINEAR)
            ),
        ]
        .join("\n"),
    )
}

/// Per-node uniforms (mirrors `GroundNode` in `ground.wgsl`).
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct GroundNodeUniform {
    first: [i32; 2],
    material_anchor: [f32; 2],
    material_step: f32,
    material_lod: f32,
    segment_count: u32,
    texel_m: f32,
    /// The node's first word in the batch's type words (four types a word), and what they
    /// hold: 0 each texel's type, 1 the cells the texels reach ([`TypeForm`]).
    types_first: u32,
    types_form: u32,
    /// Ground-cell coordinates of lattice index (0, 0)'s corner ([`TexelCells`]).
    ground_anchor: [f32; 2],
    /// The reached cells: the first, how many a side, and the map's cells a side.
    window_first: [i32; 2],
    window_side: [i32; 2],
    map_cells: [i32; 2],
    /// Texel size in ground cells.
    ground_step: f32,
    pad: f32,
}

/// One segment (mirrors `Segment` in `ground.wgsl`), in texel-lattice units of its level.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct GpuSegment {
    a: [f32; 2],
    b: [f32; 2],
    half_width: f32,
    falloff: f32,
    kind: u32,
    pad: u32,
}

/// One closed area (mirrors `Area` in `ground.wgsl`), in texel-lattice units of its level.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct GpuArea {
    lo: [f32; 2],
    hi: [f32; 2],
    first: u32,
    count: u32,
    half_width: f32,
    falloff: f32,
    kind: u32,
    pad: u32,
    rows: [f32; 2],
}

/// The area kind numbers of `ground.wgsl` (segments use 0 road, 1 path).
fn area_kind(kind: DecalKind) -> u32 {
    match kind {
        // A building pad shows as bare, trodden earth around the house.
        DecalKind::Dirt | DecalKind::Pad => 4,
        DecalKind::RockPatch => 2,
        DecalKind::Field => 3,
        // `pieces::node_decals` lists only area kinds as areas.
        DecalKind::Road | DecalKind::Path => unreachable!("a road or path is never an area"),
    }
}

/// The ground-texture pipeline and the map data it reads.
pub struct GroundTexturer {
    /// A node's texels, from each texel's type or from the cells its texels reach.
    pipeline: wgpu::RenderPipeline,
    /// Road and path segments as quads, blended over the ground in file order.
    segments: wgpu::RenderPipeline,
    /// Closed areas as their boxes, blended over the ground in file order (before segments).
    areas: wgpu::RenderPipeline,
    /// Mip levels 1 - 3 of a node texture from its level 0 (box filter in linear light).
    mips: wgpu::ComputePipeline,
    mips_layout: wgpu::BindGroupLayout,
    layout: wgpu::BindGroupLayout,
    materials: wgpu::TextureView,
    sampler: wgpu::Sampler,
    types: u32,
    map_origin_m: [f64; 2],
    ground_spacing_m: f64,
    /// The node data of the passes recorded since the last [`Self::submit`] (behind a lock so
    /// that recording takes `&self`; one thread records at a time in practice).
    pending: std::sync::Mutex<Pending>,
}

/// Node data waiting for the next submission.
struct Pending {
    /// The nodes recorded since the last submission: their uniforms, segments, areas and
    /// outline points, written to `buffers` just before it.
    batch: Batch,
    buffers: BatchBuffers,
    /// Earlier, smaller buffers still read by recorded passes (after a batch outgrew them),
    /// with the data to write to them; cleared on submit.
    outgrown: Vec<(BatchBuffers, Batch)>,
}

/// Bytes between two nodes' uniforms (the dynamic-offset alignment every adapter accepts).
const UNIFORM_STRIDE: usize = 256;

/// A batch's node data on the CPU. Segment and area indices are the batch's, so a node draws
/// its instances `first .. first + count` (no per-node buffer).
#[derive(Default)]
struct Batch {
    uniforms: Vec<u8>,
    segments: Vec<GpuSegment>,
    areas: Vec<GpuArea>,
    points: Vec<[f32; 2]>,
    /// The nodes' ground types ([`crate::ground::types::NodeTypes::append_words`]).
    types: Vec<u32>,
}

impl Batch {
    fn clear(&mut self) {
        self.uniforms.clear();
        self.segments.clear();
        self.areas.clear();
        self.points.clear();
        self.types.clear();
    }
}

/// The GPU buffers of a batch and the bind group over them, with their capacities (elements).
struct BatchBuffers {
    uniforms: wgpu::Buffer,
    segments: wgpu::Buffer,
    areas: wgpu::Buffer,
    points: wgpu::Buffer,
    types: wgpu::Buffer,
    group: wgpu::BindGroup,
    nodes: usize,
    segment_capacity: usize,
    area_capacity: usize,
    point_capacity: usize,
    type_capacity: usize,
}

impl std::fmt::Debug for GroundTexturer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "GroundTexturer({} types)", self.types)
    }
}

/// The legend's materials as one layer each of a mipmapped sRGB array (a flat grey one for an
/// empty legend), and the layer count.
fn materials_view(gpu: &Gpu, world: &World) -> (wgpu::TextureView, u32) {
    let MaterialLayers {
        layers: types,
        bytes,
    } = material_layers::for_world(world);
    let view = gpu
        .device
        .create_texture_with_data(
            &gpu.queue,
            &wgpu::TextureDescriptor {
                label: Some("ground materials"),
                size: wgpu::Extent3d {
                    width: MATERIAL_TEXELS,
                    height: MATERIAL_TEXELS,
                    depth_or_array_layers: types,
                },
                mip_level_count: MATERIAL_TEXELS.ilog2() + 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rgba8UnormSrgb,
                usage: wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            &bytes,
        )
        .create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
    (view, types)
}

impl GroundTexturer {
    /// Uploads the legend's materials.
    pub fn new(gpu: &Gpu, world: &World) -> Self {
        let device = &gpu.device;
        let map = &world.map;
        let (materials, types) = materials_view(gpu, world);
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("ground material sampler"),
            address_mode_u: wgpu::AddressMode::Repeat,
            address_mode_v: wgpu::AddressMode::Repeat,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            ..Default::default()
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("ground texture layout"),
            entries: &[
                super::frame::uniform_entry(0, true, wgpu::ShaderStages::VERTEX_FRAGMENT),
                storage_entry(1),
                texture_entry(2, wgpu::TextureViewDimension::D2Array),
                sampler_entry(3),
                storage_entry(4),
                storage_entry(5),
                storage_entry(6),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("ground texture pipeline layout"),
            bind_group_layouts: &[None, None, Some(&layout)],
            immediate_size: 0,
        });
        let level = |binding: u32| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::WriteOnly,
                format: GROUND_PAGE_FORMAT,
                view_dimension: wgpu::TextureViewDimension::D2,
            },
            count: None,
        };
        let mips_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("ground mip layout"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                level(1),
                level(2),
                level(3),
            ],
        });
        let module = super::shader::module(device, "ground", &shader_source());
        let mips = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("ground texture mips"),
            layout: Some(
                &device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                    label: Some("ground mip pipeline layout"),
                    bind_group_layouts: &[None, None, None, Some(&mips_layout)],
                    immediate_size: 0,
                }),
            ),
            module: &module,
            entry_point: Some("cs_mips"),
            compilation_options: wgpu::PipelineCompilationOptions::default(),
            cache: None,
        });
        let make = |label: &str, vs: &str, fs: &str, blend: Option<wgpu::BlendState>| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(&pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some(vs),
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                    buffers: &[],
                },
                primitive: wgpu::PrimitiveState::default(),
                depth_stencil: None,
                multisample: wgpu::MultisampleState::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some(fs),
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format: GROUND_TEXTURE_FORMAT,
                        blend,
                        write_mask: wgpu::ColorWrites::COLOR,
                    })],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let pipeline = make("ground texture", "vs_fill", "fs_texel", None);
        let segments = make(
            "ground texture segments",
            "vs_segment",
            "fs_segment",
            Some(wgpu::BlendState::ALPHA_BLENDING),
        );
        let areas = make(
            "ground texture areas",
            "vs_area",
            "fs_area",
            Some(wgpu::BlendState::ALPHA_BLENDING),
        );
        let buffers = BatchBuffers::new(
            device,
            &layout,
            &materials,
            &sampler,
            [64, 4096, 1024, 8192, 64 * (SIDE * SIDE / 4) as usize],
        );
        Self {
            pipeline,
            segments,
            areas,
            mips,
            mips_layout,
            layout,
            materials,
            sampler,
            types,
            map_origin_m: map.manifest.origin_m,
            ground_spacing_m: map.manifest.ground.spacing_m,
            pending: std::sync::Mutex::new(Pending {
                batch: Batch::default(),
                buffers,
                outgrown: Vec::new(),
            }),
        }
    }

    /// What the terrain's detail below the finest texel samples: the materials array and the
    /// number of ground types.
    pub fn detail_sources(&self) -> (wgpu::TextureView, u32) {
        (self.materials.clone(), self.types)
    }

    /// The layout of the mip pass's bindings: what [`super::ground_pool::GroundPool`] binds
    /// each layer's levels with ([`LayerMips`]).
    pub fn mip_layout(&self) -> &wgpu::BindGroupLayout {
        &self.mips_layout
    }

    /// [`Self::write_recorded`], then submits `enc` (which holds those recordings).
    pub fn submit(&self, gpu: &Gpu, enc: wgpu::CommandEncoder) {
        self.write_recorded(gpu);
        gpu.queue.submit([enc.finish()]);
    }

    /// Writes the node data of everything recorded since the last call to the GPU: call it
    /// before the encoders [`Self::record`] wrote to are submitted.
    pub fn write_recorded(&self, gpu: &Gpu) {
        let mut guard = self
            .pending
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let p = &mut *guard;
        for (buffers, batch) in p.outgrown.drain(..) {
            buffers.write(&gpu.queue, &batch);
        }
        p.buffers.write(&gpu.queue, &p.batch);
        p.batch.clear();
    }

    /// Records the mip levels of the node textures in `layers` (their level 0 recorded before,
    /// into `enc`), all in one compute pass: a level-k texel is the mean of the `4^k` level-0
    /// texels under it, in linear light. Texel blocks never straddle a node edge (node sides
    /// are `TEXELS` texels, a multiple of `2^(levels - 1)`), so neighbours' shared border
    /// texels stay equal at every level. One pass for a batch, not a render pass per level
    /// and texture: each pass costs the frame thread more to encode than its texels cost.
    pub fn record_mips(&self, enc: &mut wgpu::CommandEncoder, layers: &[LayerMips]) {
        if layers.is_empty() {
            return;
        }
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("ground texture mips"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.mips);
        let blocks = SIDE / MIP_BLOCK;
        for layer in layers {
            pass.set_bind_group(3, &layer.0, &[]);
            pass.dispatch_workgroups(blocks, blocks, 1);
        }
    }

    /// Records the texels of node `key` into `target` (a `SIDE x SIDE` view in
    /// [`GROUND_TEXTURE_FORMAT`]): `ground`'s texel types, then its decal pieces drawn from the
    /// map's `decal_list`.
    pub fn record(
        &self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        target: &wgpu::TextureView,
        tree: &QuadTree,
        key: NodeKey,
        ground: &NodeGround,
        decal_list: &[worldgen::map::Decal],
    ) {
        let decals = &ground.decals;
        let t = texel_m(tree, key.level);
        let root = tree.rect(NodeKey::ROOT).min;
        // Lattice units of the level: (world - root) / t, in f64, then f32 (the same numbers
        // in every node).
        let lattice = |p: [f64; 3]| [((p[0] - root[0]) / t) as f32, ((p[1] - root[1]) / t) as f32];
        let segments: Vec<GpuSegment> = decals
            .segments
            .iter()
            .map(|s| {
                let d = &decal_list[s.decal as usize];
                let (a, b) = (d.points[s.point as usize], d.points[s.point as usize + 1]);
                GpuSegment {
                    a: lattice(a),
                    b: lattice(b),
                    half_width: (0.5 * f64::from(d.width_m) / t) as f32,
                    falloff: (f64::from(d.falloff_m) / t) as f32,
                    kind: u32::from(d.kind == DecalKind::Path),
                    pad: 0,
                }
            })
            .collect();
        let (areas, points) = gpu_areas(decals, decal_list, &lattice, t);
        let cells = TexelCells::new(tree, key, self.map_origin_m, self.ground_spacing_m);
        let material_m = MATERIAL_TILE_M;
        let corner = |o: f64, r: f64, unit: f64| (r - o) / unit;
        let mut uniform = GroundNodeUniform {
            first: lattice_index(key, 0, 0).map(|v| v as i32),
            material_step: (t / material_m) as f32,
            material_anchor: [
                corner(self.map_origin_m[0], root[0], material_m).rem_euclid(1.0) as f32,
                corner(self.map_origin_m[1], root[1], material_m).rem_euclid(1.0) as f32,
            ],
            material_lod: (t / (material_m / f64::from(MATERIAL_TEXELS)))
                .log2()
                .max(0.0) as f32,
            segment_count: segments.len() as u32,
            texel_m: t as f32,
            types_first: 0,
            types_form: 0,
            ground_anchor: cells.anchor,
            window_first: [0; 2],
            window_side: [1; 2],
            map_cells: [1; 2],
            ground_step: cells.step,
            pad: 0.0,
        };
        if let TypeForm::Cells { first, side, map } = ground.types.form {
            uniform.types_form = 1;
            uniform.window_first = first;
            uniform.window_side = side.map(|v| v as i32);
            uniform.map_cells = map;
        }
        let mut guard = self
            .pending
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let p = &mut *guard;
        let need = [
            p.batch.uniforms.len() / UNIFORM_STRIDE + 1,
            p.batch.segments.len() + segments.len(),
            p.batch.areas.len() + areas.len(),
            p.batch.points.len() + points.len(),
            p.batch.types.len() + ground.types.words(),
        ];

        if !p.buffers.holds(need) {
            // The passes recorded so far read the current buffers: keep them with their data
            // until the submission, and go on in buffers twice the size this node needs.
            let have = p.buffers.capacity();
            let bigger = BatchBuffers::new(
                &gpu.device,
                &self.layout,
                &self.materials,
                &self.sampler,
                std::array::from_fn(|i| (2 * need[i]).max(have[i])),
            );
            let old = std::mem::replace(&mut p.buffers, bigger);
            p.outgrown.push((old, std::mem::take(&mut p.batch)));
        }
        let b = &mut p.batch;
        let offset = b.uniforms.len();
        uniform.types_first = b.types.len() as u32;
        ground.types.append_words(&mut b.types);
        b.uniforms.extend_from_slice(bytemuck::bytes_of(&uniform));
        b.uniforms.resize(offset + UNIFORM_STRIDE, 0);
        let first_segment = b.segments.len() as u32;
        b.segments.extend_from_slice(&segments);
        let first_area = b.areas.len() as u32;
        let first_point = b.points.len() as u32;
        b.areas.extend(areas.iter().map(|a| GpuArea {
            first: a.first + first_point,
            ..*a
        }));
        b.points.extend_from_slice(&points);
        let mut pass = clear_pass(enc, target, "ground texture");
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(2, &p.buffers.group, &[offset as u32]);
        pass.draw(0..3, 0..1);
        if !areas.is_empty() {
            pass.set_pipeline(&self.areas);
            pass.draw(0..6, first_area..first_area + areas.len() as u32);
        }
        if !segments.is_empty() {
            pass.set_pipeline(&self.segments);
            pass.draw(0..6, first_segment..first_segment + segments.len() as u32);
        }
    }
}

impl BatchBuffers {
    /// Buffers for `[nodes, segments, areas, points, type words]` and their bind group.
    fn new(
        device: &wgpu::Device,
        layout: &wgpu::BindGroupLayout,
        materials: &wgpu::TextureView,
        sampler: &wgpu::Sampler,
        [nodes, segments, areas, points, type_words]: [usize; 5],
    ) -> Self {
        let buffer = |label: &str, bytes: usize, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes.max(64) as u64,
                usage: usage | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let storage = wgpu::BufferUsages::STORAGE;
        let uniforms = buffer(
            "ground node uniforms",
            nodes * UNIFORM_STRIDE,
            wgpu::BufferUsages::UNIFORM,
        );
        let segment_buffer = buffer(
            "ground segments",
            segments * std::mem::size_of::<GpuSegment>(),
            storage,
        );
        let area_buffer = buffer(
            "ground areas",
            areas * std::mem::size_of::<GpuArea>(),
            storage,
        );
        let point_buffer = buffer(
            "ground area points",
            points * std::mem::size_of::<[f32; 2]>(),
            storage,
        );
        let type_buffer = buffer(
            "ground texel types",
            type_words * std::mem::size_of::<u32>(),
            storage,
        );
        let group =
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("ground nodes"),
                layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer: &uniforms,
                            offset: 0,
                            size: wgpu::BufferSize::new(
                                std::mem::size_of::<GroundNodeUniform>() as u64
                            ),
                        }),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: type_buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: wgpu::BindingResource::TextureView(materials),
                    },
                    wgpu::BindGroupEntry {
                        binding: 3,
                        resource: wgpu::BindingResource::Sampler(sampler),
                    },
                    wgpu::BindGroupEntry {
                        binding: 4,
                        resource: segment_buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 5,
                        resource: area_buffer.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 6,
                        resource: point_buffer.as_entire_binding(),
                    },
                ],
            });
        Self {
            uniforms,
            segments: segment_buffer,
            areas: area_buffer,
            points: point_buffer,
            types: type_buffer,
            group,
            nodes,
            segment_capacity: segments,
            area_capacity: areas,
            point_capacity: points,
            type_capacity: type_words,
        }
    }

    /// `[nodes, segments, areas, points, type words]` they hold.
    fn capacity(&self) -> [usize; 5] {
        [
            self.nodes,
            self.segment_capacity,
            self.area_capacity,
            self.point_capacity,
            self.type_capacity,
        ]
    }

    /// Whether `[nodes, segments, areas, points, type words]` fit.
    fn holds(&self, [nodes, segments, areas, points, type_words]: [usize; 5]) -> bool {
        nodes <= self.nodes
            && segments <= self.segment_capacity
            && areas <= self.area_capacity
            && points <= self.point_capacity
            && type_words <= self.type_capacity
    }

    /// Queues `batch` into these buffers (written before the next submission's commands).
    fn write(&self, queue: &wgpu::Queue, batch: &Batch) {
        let put = |buffer: &wgpu::Buffer, bytes: &[u8]| {
            if !bytes.is_empty() {
                queue.write_buffer(buffer, 0, bytes);
            }
        };
        put(&self.uniforms, &batch.uniforms);
        put(&self.segments, bytemuck::cast_slice(&batch.segments));
        put(&self.areas, bytemuck::cast_slice(&batch.areas));
        put(&self.points, bytemuck::cast_slice(&batch.points));
        put(&self.types, bytemuck::cast_slice(&batch.types));
    }
}

/// A read-only storage buffer of the ground-texture group, seen by both stages.
fn storage_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only: true },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// A node's closed areas for `ground.wgsl` (lattice units of texel size `t`) and their outline
/// points (each area's `first` counts from the node's first point).
fn gpu_areas(
    decals: &NodeDecals,
    decal_list: &[worldgen::map::Decal],
    lattice: &impl Fn([f64; 3]) -> [f32; 2],
    t: f64,
) -> (Vec<GpuArea>, Vec<[f32; 2]>) {
    let mut points: Vec<[f32; 2]> = Vec::new();
    let areas: Vec<GpuArea> = decals
        .areas
        .iter()
        .map(|&i| {
            let d = &decal_list[i as usize];
            let first = points.len() as u32;
            points.extend(d.points.iter().map(|&p| lattice(p)));
            let outline = &points[first as usize..];
            let half_width = (0.5 * f64::from(d.width_m) / t) as f32;
            let falloff = (f64::from(d.falloff_m) / t) as f32;
            let reach = half_width + falloff + 1.0;
            let (lo, hi) = outline.iter().fold(
                ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]),
                |(lo, hi), p| {
                    (
                        [lo[0].min(p[0]), lo[1].min(p[1])],
                        [hi[0].max(p[0]), hi[1].max(p[1])],
                    )
                },
            );
            let (a, b) = (d.points[0], d.points[1]);
            let edge = [b[0] - a[0], b[1] - a[1]];
            let len = edge[0].hypot(edge[1]).max(1e-9);
            GpuArea {
                lo: [lo[0] - reach, lo[1] - reach],
                hi: [hi[0] + reach, hi[1] + reach],
                first,
                count: d.points.len() as u32,
                half_width,
                falloff,
                kind: area_kind(d.kind),
                pad: 0,
                // Rows run along the first edge: the pattern varies across it.
                rows: [(-edge[1] / len) as f32, (edge[0] / len) as f32],
            }
        })
        .collect();
    (areas, points)
}

/// A render pass into `view` alone, cleared to black first (every texel is then written by the
/// pass).
pub fn clear_pass<'e>(
    enc: &'e mut wgpu::CommandEncoder,
    view: &wgpu::TextureView,
    label: &str,
) -> wgpu::RenderPass<'e> {
    enc.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations {
                load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                store: wgpu::StoreOp::Store,
            },
        })],
        depth_stencil_attachment: None,
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}
