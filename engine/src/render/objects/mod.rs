//! The objects renderer: progressive meshes (the vertices of every model in one buffer, wedges
//! in level order) drawn per instance with an index list kept at the level the pixel metric
//! chooses ([`crate::objects::lod`]), edited level by level on the CPU ([`PmInstance`]) and
//! rewritten on the GPU only when the level changes. A model with an `MSFT_lod` chain has a
//! vertex range per chain level; an instance that moves to another chain level starts a new index
//! list there (no geomorph across chain levels: they share no vertices).
//!
//! Merged draws (seed 002): index lists, geomorph targets and nodes' merged far meshes are
//! ranges in pooled pages ([`PagedBuffer`]); per-draw data is one storage array indexed by the
//! draw's instance index. The draws go through [`Batches`] under a key of pipeline, texture slots
//! and pages, so the frame's houses take one multi-draw per key (a few texture pairs) instead
//! of one draw each.

use super::Gpu;
use super::batches::{Batches, Item};
use super::frame::{
    DrawStats, FrameResources, PipelineSpec, pipeline, sampler_entry, storage_entry, texture_entry,
};
use super::paged_buffer::PagedBuffer;
use super::scene::{FrameDraws, NodeRenderer, UploadEncoder};
use super::suballoc::Lease;
use super::texture_pool::GpuTexturePool;
use crate::objects::content::{NodeObjects, ObjectsContent};
use crate::objects::hlod;
use crate::objects::lod::{self, Choice, choose};
use crate::objects::set::{ObjectSet, PLAIN_ALBEDO, PmModel, ROOF_NORMAL_UP, model_to_world};
use crate::objects::texturing;
use crate::stream::Shared;
use crate::terrain::screen_bound::ScreenBound;
use crate::texcache::pool::{PoolSettings, SlotId, TexturePool};
use glam::{DMat4, DVec3};
use std::collections::HashMap;
use std::sync::Arc;
use wgpu::util::{DeviceExt, DrawIndexedIndirectArgs, DrawIndirectArgs};

mod frame_work;
use worldgen::pm::PmInstance;

/// Frames an instance's index list survives without being drawn.
const KEEP_FRAMES: u64 = 600;
/// Indices in a page of index lists (16 MiB), and pages at most.
const INDEX_PAGE: u32 = 1 << 22;
const INDEX_PAGES: usize = 16;
/// Geomorph targets (two `vec4`s per wedge) in a page (32 MiB, within the default storage
/// binding limit of 128 MiB), and pages at most.
const MORPH_PAGE: u32 = 1 << 21;
const MORPH_PAGES: usize = 8;
/// Vertices of merged far meshes in a page (36 MiB), and pages at most.
const HLOD_PAGE: u32 = 1 << 20;
const HLOD_PAGES: usize = 16;
/// Bytes of a merged far mesh's vertex (position, normal, colour).
const HLOD_VERTEX_BYTES: u64 = 36;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct DrawUniform {
    rel_from_model: [[f32; 4]; 4],
    normal_from_model: [[f32; 4]; 4],
    fade: [f32; 4],
    albedo: [f32; 4],
    morph: [f32; 4],
    light: [f32; 4],
    base_local: [f32; 4],
    base_rel: [f32; 4],
    tex: [f32; 4],
    roof_albedo: [f32; 4],
    /// x: the model's first vertex in the shared vertex buffer; y: the first geomorph target of
    /// the instance in its morph page.
    pool: [u32; 4],
}

/// A geomorph in progress: wedges `lo..hi` move between their own position and that of the
/// wedge they collapse onto at the coarser of the two levels.
#[derive(Debug, Clone, Copy)]
struct Morph {
    lo: u32,
    hi: u32,
    /// Progress, 0 to 1.
    t: f32,
    /// Growing out to a finer level (its list is shown), else shrinking into `target`.
    refine: bool,
    target: usize,
}

/// The pooled pages instances write into.
struct Pools {
    /// Index lists: an instance leases room for its model's full list.
    indices: PagedBuffer,
    /// Per wedge the position and normal it collapses onto (leased on an instance's first
    /// geomorph, two elements per wedge).
    morph: PagedBuffer,
    /// One bind group per morph page.
    morph_groups: Vec<wgpu::BindGroup>,
    morph_layout: wgpu::BindGroupLayout,
}

impl Pools {
    /// Makes the bind groups of morph pages opened since the last call.
    fn morph_groups(&mut self, device: &wgpu::Device) {
        while self.morph_groups.len() < self.morph.pages().len() {
            let page = &self.morph.pages()[self.morph_groups.len()];
            self.morph_groups
                .push(morph_group(device, &self.morph_layout, page));
        }
    }
}

struct InstanceGpu {
    /// The chain option drawn (0: the base progressive mesh).
    option: usize,
    lod: PmInstance,
    /// Its index list's range (room for the full list).
    indices: Lease,
    uploaded_level: usize,
    last_frame: u64,
    morph: Option<Morph>,
    /// Its geomorph targets' range (leased on the first morph).
    morph_to: Option<Lease>,
}

/// What a run of merged draws shares: pipeline, bind groups and buffers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
struct Key {
    /// A node's merged far mesh (else a progressive-mesh instance).
    hlod: bool,
    /// The slots of the facade and roof textures (None: the white fallback).
    slots: [Option<SlotId>; 2],
    /// The index page (the vertex page, for a merged far mesh).
    page: u32,
    /// The morph page bound (0 for draws that do not morph).
    morph_page: u32,
}

struct DrawItem {
    instance: u32,
    option: usize,
    /// Indices drawn (vertices, for a merged far mesh).
    index_count: u32,
    full_triangles: u32,
    /// Its key (the slots are filled once the frame's texture plan is applied).
    key: Key,
    /// The draw; its first instance is the item's index in the frame's draw data.
    args: Item,
}

/// What an instance shows this frame and where its data is.
struct Shown {
    level: usize,
    index_count: u32,
    /// The draw's geomorph numbers (`DrawUniform::morph`).
    morph: [f32; 4],
    morph_page: u32,
    /// The instance's first geomorph target in its morph page.
    morph_base: u32,
    /// Its index list's page and first index.
    page: u32,
    first_index: u32,
}

/// A node's merged far mesh on the GPU (three vertices a triangle, no index list): its range in
/// the far-mesh vertex pages.
struct HlodGpu {
    vertices: Lease,
}

/// Per-frame statistics of the objects.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ObjectStats {
    pub instances_drawn: u32,
    pub triangles: u64,
    /// Triangles the drawn instances would have at full detail.
    pub full_triangles: u64,
    /// Index lists rewritten this frame (level changes).
    pub level_changes: u32,
    /// Instances not drawn because the index pages were full.
    pub pool_full: u32,
}

pub struct ObjectsRenderer {
    set: Arc<ObjectSet>,
    pipeline: wgpu::RenderPipeline,
    /// Merged far meshes: per-vertex colour, no morph.
    pipeline_hlod: wgpu::RenderPipeline,
    /// The vertices of every model and chain option.
    vertices: wgpu::Buffer,
    /// Per model, per chain option (0 the base): its first vertex in `vertices`.
    base_vertex: Vec<Vec<u32>>,
    pools: Pools,
    /// Vertices of the nodes' merged far meshes.
    hlod_vertices: PagedBuffer,
    draw_layout: wgpu::BindGroupLayout,
    /// The frame's per-draw data (storage array, indexed by instance index).
    draw_buffer: wgpu::Buffer,
    /// Draw groups by the slots of their two textures (remade when slots or the draw buffer
    /// change).
    groups: HashMap<[Option<SlotId>; 2], wgpu::BindGroup>,
    draw_capacity: u64,
    /// The texture cache: its bookkeeping (texture ids are indices into the set's textures),
    /// its slots on the GPU, and per model the MipMapFactor before scale and texture size.
    tex_pool: TexturePool,
    gpu_tex: GpuTexturePool,
    units_per_texture: Vec<[f64; 2]>,
    /// Per texture its mean linear colour (its 1 x 1 level), drawn while none is resident.
    tex_means: Vec<[f32; 3]>,
    instances: HashMap<u32, InstanceGpu>,
    items: Vec<DrawItem>,
    batches: Batches<Key>,
    /// Whether this frame's runs are recorded as multi-draws.
    merged: bool,
    /// Whether a full index pool was reported (once a run).
    warned_pool_full: bool,
    frame_no: u64,
    pub stats: ObjectStats,
}

/// The WGSL of this renderer.
pub fn shader_source() -> String {
    super::shader::assemble(
        "objects",
        &format!(
            "const TEXTURE_TILE_M: f32 = {:?};\nconst ROOF_NORMAL_UP: f32 = {:?};\n",
            worldgen::house_textures::TILE_M as f32,
            ROOF_NORMAL_UP
        ),
    )
}

/// The draw uniforms with a facade and a roof texture view.
fn draw_group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    buffer: &wgpu::Buffer,
    views: [&wgpu::TextureView; 2],
    sampler: &wgpu::Sampler,
) -> wgpu::BindGroup {
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("object draws"),
        layout,
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: buffer.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: wgpu::BindingResource::TextureView(views[0]),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: wgpu::BindingResource::TextureView(views[1]),
            },
            wgpu::BindGroupEntry {
                binding: 3,
                resource: wgpu::BindingResource::Sampler(sampler),
            },
        ],
    })
}

fn morph_group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    buffer: &wgpu::Buffer,
) -> wgpu::BindGroup {
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("object morph"),
        layout,
        entries: &[wgpu::BindGroupEntry {
            binding: 0,
            resource: buffer.as_entire_binding(),
        }],
    })
}

fn draw_buffer(device: &wgpu::Device, draws: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("object draw data"),
        size: draws.max(1) * std::mem::size_of::<DrawUniform>() as u64,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

impl ObjectsRenderer {
    /// The renderer of the registered objects kind (a renderer drawing nothing without one).
    pub fn create(gpu: &Gpu, frame: &FrameResources, shared: &Shared) -> Box<dyn NodeRenderer> {
        let set = shared
            .kind::<ObjectsContent>()
            .map_or_else(|| Arc::new(ObjectSet::default()), |k| Arc::clone(&k.set));
        Box::new(Self::new(gpu, frame, set))
    }

    pub fn new(gpu: &Gpu, frame: &FrameResources, set: Arc<ObjectSet>) -> Self {
        let device = &gpu.device;
        let module = super::shader::module(device, "objects", &shader_source());
        let draw_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("object draw layout"),
            entries: &[
                storage_entry(0, wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT),
                texture_entry(1, wgpu::TextureViewDimension::D2),
                texture_entry(2, wgpu::TextureViewDimension::D2),
                sampler_entry(3),
            ],
        });
        let morph_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("object morph layout"),
            entries: &[storage_entry(0, wgpu::ShaderStages::VERTEX)],
        });
        let layout = frame.pipeline_layout(
            device,
            "objects pipeline layout",
            false,
            &[Some(&draw_layout), Some(&morph_layout)],
        );
        let attrs = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x2];
        let buffers = [Some(wgpu::VertexBufferLayout {
            array_stride: 32,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &attrs,
        })];
        let spec = PipelineSpec::triangles(
            "objects",
            "vs_main",
            "fs_main",
            &buffers,
            frame.color_format,
        );
        let pipeline_objects = pipeline(device, &module, &layout, &spec);
        let hlod_attrs = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x3];
        let hlod_buffers = [Some(wgpu::VertexBufferLayout {
            array_stride: HLOD_VERTEX_BYTES,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &hlod_attrs,
        })];
        let hlod_spec = PipelineSpec::triangles(
            "objects hlod",
            "vs_hlod",
            "fs_main",
            &hlod_buffers,
            frame.color_format,
        );
        let pipeline_hlod = pipeline(device, &module, &layout, &hlod_spec);
        // Every model's and chain option's wedges, one after the other.
        let mut data: Vec<f32> = Vec::new();
        let base_vertex = set
            .models
            .iter()
            .map(|model| {
                (0..=model.chain.len())
                    .map(|option| {
                        let base = (data.len() / 8) as u32;
                        let m = model.option(option);
                        for (w, &p) in m.pm.wedge_position.iter().enumerate() {
                            data.extend_from_slice(&m.pm.positions[p as usize]);
                            data.extend_from_slice(&m.normals[w]);
                            data.extend_from_slice(&m.pm.uvs.get(w).copied().unwrap_or([0.0; 2]));
                        }
                        base
                    })
                    .collect()
            })
            .collect();
        data.resize(data.len().max(8), 0.0);
        let vertices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("object vertices"),
            contents: bytemuck::cast_slice(&data),
            usage: wgpu::BufferUsages::VERTEX,
        });
        let mut pools = Pools {
            indices: PagedBuffer::new(
                "object index lists",
                wgpu::BufferUsages::INDEX,
                4,
                INDEX_PAGE,
                INDEX_PAGES,
            ),
            morph: PagedBuffer::new(
                "object morph targets",
                wgpu::BufferUsages::STORAGE,
                16,
                MORPH_PAGE,
                MORPH_PAGES,
            ),
            morph_groups: Vec::new(),
            morph_layout,
        };
        // Morph page 0 is bound for draws that do not morph.
        pools.morph.open_pages(device);
        pools.morph_groups(device);
        let draw_capacity = 64;
        let draw_buffer = draw_buffer(device, draw_capacity);
        let mut tex_pool = TexturePool::new(PoolSettings::default());
        let tex_means = texturing::register(&mut tex_pool, &set);
        let units_per_texture = set
            .models
            .iter()
            .map(texturing::units_per_texture)
            .collect();
        ObjectsRenderer {
            set,
            pipeline: pipeline_objects,
            pipeline_hlod,
            vertices,
            base_vertex,
            pools,
            hlod_vertices: PagedBuffer::new(
                "object far meshes",
                wgpu::BufferUsages::VERTEX,
                HLOD_VERTEX_BYTES,
                HLOD_PAGE,
                HLOD_PAGES,
            ),
            draw_layout,
            draw_buffer,
            groups: HashMap::new(),
            draw_capacity,
            tex_pool,
            gpu_tex: GpuTexturePool::new(gpu),
            units_per_texture,
            tex_means,
            instances: HashMap::new(),
            items: Vec::new(),
            batches: Batches::new(),
            merged: false,
            warned_pool_full: false,
            frame_no: 0,
            stats: ObjectStats::default(),
        }
    }

    /// The geomorph progress (0 to 1) of each drawn instance that is morphing.
    pub fn morphs(&self) -> Vec<(u32, f32)> {
        self.items
            .iter()
            .filter(|i| !i.key.hlod)
            .filter_map(|i| Some((i.instance, self.instances[&i.instance].morph?.t)))
            .collect()
    }

    /// The level each drawn instance showed last frame (tests and statistics).
    pub fn levels(&self) -> Vec<(u32, usize)> {
        let mut v: Vec<(u32, usize)> = self
            .items
            .iter()
            .filter(|i| !i.key.hlod)
            .map(|i| (i.instance, self.instances[&i.instance].lod.level()))
            .collect();
        v.sort_unstable();
        v
    }

    /// The chain option and level each drawn instance showed last frame.
    pub fn choices(&self) -> Vec<(u32, Choice)> {
        let mut v: Vec<(u32, Choice)> = self
            .items
            .iter()
            .filter(|i| !i.key.hlod)
            .map(|i| {
                let inst = &self.instances[&i.instance];
                (
                    i.instance,
                    Choice {
                        option: inst.option,
                        level: inst.lod.level(),
                    },
                )
            })
            .collect();
        v.sort_unstable_by_key(|&(i, _)| i);
        v
    }
}

/// The affine model-to-world map of an instance as a matrix (f64).
fn world_from_model(set: &ObjectSet, instance: u32) -> DMat4 {
    let inst = &set.instances[instance as usize];
    let model = &set.models[inst.model as usize];
    let o = model_to_world(DVec3::ZERO, inst, model);
    let x = model_to_world(DVec3::X, inst, model) - o;
    let y = model_to_world(DVec3::Y, inst, model) - o;
    let z = model_to_world(DVec3::Z, inst, model) - o;
    DMat4::from_cols(x.extend(0.0), y.extend(0.0), z.extend(0.0), o.extend(1.0))
}

impl NodeRenderer for ObjectsRenderer {
    fn name(&self) -> &'static str {
        "objects"
    }

    /// A node's merged far mesh, when it has one, goes to the GPU with the node.
    fn upload(
        &mut self,
        gpu: &Gpu,
        _frame: &FrameResources,
        _tree: &crate::terrain::quadtree::QuadTree,
        work: &mut crate::stream::NodeWork,
        _copies: &mut UploadEncoder<'_>,
    ) -> usize {
        let Some(h) = work.get::<NodeObjects>().and_then(|o| o.hlod.as_ref()) else {
            return 0;
        };
        let Some(vertices) = self
            .hlod_vertices
            .lease(&gpu.device, h.vertices.len() as u32)
        else {
            log::warn!(
                "object far-mesh pages full: node {:?} draws its houses one by one",
                work.key
            );
            return 0;
        };
        self.hlod_vertices
            .write(&gpu.queue, &vertices, 0, bytemuck::cast_slice(&h.vertices));
        let bytes = std::mem::size_of_val(h.vertices.as_slice());
        work.gpu.put(HlodGpu { vertices });
        bytes
    }

    fn prepare(&mut self, gpu: &Gpu, frame: &mut FrameResources, draws: &FrameDraws<'_>) {
        self.frame_no += 1;
        self.items.clear();
        self.stats = ObjectStats::default();
        // Objects off (the GPU reference's runs): nothing drawn; instances and textures stay as
        // they are until objects are drawn again.
        if !draws.view.objects {
            return;
        }
        let camera = draws.camera;
        // The pixel metric on the screen: an object's error may move its image by up to the
        // stretch of its box's place on the screen (as a terrain block's).
        let screen = ScreenBound::new(camera);
        let settings = draws.view.pm_lod;
        let mut uniforms: Vec<DrawUniform> = Vec::new();
        // The instances and models (a second handle, so the texture cache can be asked while
        // they are borrowed).
        let set = Arc::clone(&self.set);
        for (node_index, node) in draws.drawn.iter().enumerate() {
            let Some(objects) = node.work.get::<NodeObjects>() else {
                continue;
            };
            // Objects are lit by the drawing node's light grid (sky and sun visibility).
            let light = frame.light.drawn_entry(node_index, node.key).grid;
            if self.hlod_item(draws, &screen, node_index, objects, light, &mut uniforms) {
                continue;
            }
            let corner = draws.tree.rect(node.key).min;
            for &id in &objects.instances {
                let inst = &set.instances[id as usize];
                let model = &set.models[inst.model as usize];
                let (c, r) = set.sphere(inst);
                if !draws
                    .frustum
                    .intersects_aabb(c - DVec3::splat(r), c + DVec3::splat(r))
                {
                    continue;
                }
                let (distance_m, k_on_screen_px) = lod::on_screen(&screen, c, r);
                texturing::request_instance(
                    &mut self.tex_pool,
                    &set,
                    &self.units_per_texture,
                    camera,
                    id,
                    (c, r),
                );
                let choice = choose(
                    model,
                    &settings,
                    draws.tau_px,
                    distance_m,
                    k_on_screen_px,
                    inst.scale,
                );
                let full = model.pm.triangles.len();
                let drawn_model = model.option(choice.option);
                let Some(shown) = self.update_instance(gpu, draws, id, drawn_model, choice) else {
                    continue;
                };
                let Shown {
                    level: shown,
                    index_count,
                    morph,
                    morph_page,
                    morph_base,
                    page,
                    first_index,
                } = shown;
                if index_count == 0 {
                    continue;
                }
                let base_vertex = self.base_vertex[inst.model as usize][choice.option];
                let world = world_from_model(&self.set, id);
                let mut rel = world;
                rel.w_axis -= camera.position_m.extend(0.0);
                let lin = glam::DMat3::from_mat4(world);
                let normal = DMat4::from_mat3(lin.inverse().transpose());
                // Share of the base model's positions (a chain level counts its own).
                let share = shown as f32 / model.pm.level_count().max(1) as f32;
                let by_lod = draws.view.pm_color_by_lod;
                let albedo = if by_lod {
                    lod_color(share)
                } else {
                    PLAIN_ALBEDO
                };
                let k = uniforms.len() as u32;
                uniforms.push(DrawUniform {
                    rel_from_model: rel.as_mat4().to_cols_array_2d(),
                    normal_from_model: normal.as_mat4().to_cols_array_2d(),
                    fade: [
                        node.dither[0],
                        node.dither[1],
                        f32::from(node.key.level),
                        f32::from(u8::from(by_lod)),
                    ],
                    albedo: [albedo[0], albedo[1], albedo[2], 1.0],
                    morph,
                    light,
                    base_local: [
                        (inst.position_m.x - corner[0]) as f32,
                        (inst.position_m.y - corner[1]) as f32,
                        0.0,
                        0.0,
                    ],
                    base_rel: (inst.position_m - camera.position_m)
                        .as_vec3()
                        .extend(0.0)
                        .to_array(),
                    // Filled in once this frame's texture plan is applied.
                    tex: [-1.0, -1.0, 0.0, 0.0],
                    roof_albedo: [albedo[0], albedo[1], albedo[2], 1.0],
                    pool: [base_vertex, morph_base, 0, 0],
                });
                self.items.push(DrawItem {
                    instance: id,
                    option: choice.option,
                    index_count,
                    full_triangles: full as u32,
                    key: Key {
                        hlod: false,
                        slots: [None; 2],
                        page,
                        morph_page,
                    },
                    args: Item::Indexed(DrawIndexedIndirectArgs {
                        index_count,
                        instance_count: 1,
                        first_index,
                        base_vertex: base_vertex as i32,
                        first_instance: k,
                    }),
                });
                self.stats.instances_drawn += 1;
                self.stats.triangles += u64::from(index_count / 3);
                self.stats.full_triangles += full as u64;
            }
        }
        if self.stats.pool_full > 0 && !self.warned_pool_full {
            log::warn!(
                "object index pages full ({INDEX_PAGES} pages of {INDEX_PAGE} indices): {} \
                 instances not drawn this frame",
                self.stats.pool_full
            );
            self.warned_pool_full = true;
        }
        let frame_no = self.frame_no;
        self.instances
            .retain(|_, i| frame_no.saturating_sub(i.last_frame) < KEEP_FRAMES);
        self.texture_plan(gpu, draws, &mut uniforms);
        self.write_uniforms(gpu, &uniforms);
        self.batches.clear();
        for item in &self.items {
            self.batches.push(item.key, item.args);
        }
        self.batches.upload(gpu);
        self.merged = draws.view.multi_draw(gpu);
    }

    fn draw(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        _frame: &FrameResources,
        _draws: &FrameDraws<'_>,
        stats: &mut DrawStats,
    ) {
        if self.items.is_empty() {
            return;
        }
        for item in &self.items {
            stats.object_items += 1;
            stats.object_hlod_draws += u32::from(item.key.hlod);
            stats.object_triangles += u64::from(item.index_count / 3);
            stats.object_full_triangles += u64::from(item.full_triangles);
            stats.object_chain_draws += u32::from(item.option > 0);
        }
        for run in self.batches.runs() {
            let key = run.key;
            let (Some(group), Some(morph)) = (
                self.groups.get(&key.slots),
                self.pools.morph_groups.get(key.morph_page as usize),
            ) else {
                continue;
            };
            if key.hlod {
                let Some(vertices) = self.hlod_vertices.pages().get(key.page as usize) else {
                    continue;
                };
                pass.set_pipeline(&self.pipeline_hlod);
                pass.set_vertex_buffer(0, vertices.slice(..));
            } else {
                let Some(indices) = self.pools.indices.pages().get(key.page as usize) else {
                    continue;
                };
                pass.set_pipeline(&self.pipeline);
                pass.set_vertex_buffer(0, self.vertices.slice(..));
                pass.set_index_buffer(indices.slice(..), wgpu::IndexFormat::Uint32);
            }
            pass.set_bind_group(2, group, &[]);
            pass.set_bind_group(3, morph, &[]);
            stats.object_draw_calls += self.batches.record(pass, run, self.merged);
        }
        let t = self.tex_pool.stats();
        stats.texture_resident_bytes += t.resident_bytes;
        stats.texture_full_bytes += t.full_resolution_bytes;
        stats.texture_misses += t.misses as u32;
        stats.texture_coarser += t.coarser_than_needed as u32;
        stats.texture_uploads += t.uploads as u32;
        stats.texture_upload_bytes += t.upload_bytes;
    }
}

/// Colour of a level drawing `share` of the positions: blue (coarse) through green to red (full).
fn lod_color(share: f32) -> [f32; 3] {
    let t = share.clamp(0.0, 1.0).sqrt();
    if t < 0.5 {
        let u = t * 2.0;
        [0.1, 0.2 + 0.7 * u, 0.9 - 0.6 * u]
    } else {
        let u = (t - 0.5) * 2.0;
        [0.1 + 0.8 * u, 0.9 - 0.6 * u, 0.3 - 0.2 * u]
    }
}

#[cfg(test)]
mod tests {
    /// The per-draw struct has no padding: two 4 x 4 matrices and nine 16-byte vectors, the
    /// array stride WGSL gives `Draw` (that the shader reads it right is what the merged-draw
    /// pixel tests and the object tests show).
    #[test]
    fn draw_data_has_no_padding() {
        assert_eq!(std::mem::size_of::<super::DrawUniform>(), 2 * 64 + 9 * 16);
    }
}
