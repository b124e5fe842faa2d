//! The objects renderer: progressive meshes (one vertex buffer per model, wedges in level order)
//! drawn per instance with an index list kept at the level the pixel metric chooses
//! ([`crate::objects::lod`]), edited level by level on the CPU ([`PmInstance`]) and rewritten
//! on the GPU only when the level changes. One draw per visible instance. A model with an
//! `MSFT_lod` chain has a vertex buffer per chain level; an instance that moves to another chain
//! level starts a new index list there (no geomorph across chain levels: they share no vertices).

use super::Gpu;
use super::frame::{
    DrawStats, FrameResources, PipelineSpec, pipeline, sampler_entry, storage_entry, texture_entry,
    uniform_entry,
};
use super::lighting::light_entry;
use super::scene::{FrameDraws, NodeRenderer};
use super::texture_pool::GpuTexturePool;
use crate::objects::content::{NodeObjects, ObjectsContent};
use crate::objects::hlod;
use crate::objects::lod::{Choice, choose};
use crate::objects::set::{ObjectSet, PLAIN_ALBEDO, PmModel, ROOF_NORMAL_UP, model_to_world};
use crate::objects::texturing;
use crate::stream::Shared;
use crate::texcache::pool::{PoolSettings, SlotId, TexturePool};
use glam::{DMat4, DVec3};
use std::collections::HashMap;
use std::sync::Arc;
use wgpu::util::DeviceExt;
use worldgen::pm::PmInstance;

/// Bytes of one draw's uniform block, padded to the dynamic-offset alignment.
const DRAW_STRIDE: u64 = 256;
/// Frames an instance's index list survives without being drawn.
const KEEP_FRAMES: u64 = 600;

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

struct InstanceGpu {
    /// The chain option drawn (0: the base progressive mesh).
    option: usize,
    lod: PmInstance,
    indices: wgpu::Buffer,
    uploaded_level: usize,
    last_frame: u64,
    morph: Option<Morph>,
    /// Per-wedge "collapse onto" positions and their bind group (made on the first morph).
    morph_to: Option<(wgpu::Buffer, wgpu::BindGroup)>,
}

impl InstanceGpu {
    /// Moves the instance towards `level`: at once, or by a geomorph of `morph_s` seconds
    /// (advanced by `dt_s`); rewrites the GPU index list when the shown level changed (returns
    /// whether it did).
    fn update_level(
        &mut self,
        gpu: &Gpu,
        model: &PmModel,
        level: usize,
        morph_s: f64,
        dt_s: f64,
        morph_layout: &wgpu::BindGroupLayout,
    ) -> bool {
        let pm = &model.pm;
        // Advance a geomorph; a finished shrink switches to its coarser list.
        if let Some(m) = self.morph.as_mut() {
            m.t += (dt_s / morph_s.max(1e-9)) as f32;
            if m.t >= 1.0 || morph_s <= 0.0 {
                if !m.refine {
                    self.lod.set_level(pm, &model.edits, m.target);
                }
                self.morph = None;
            }
        }
        if self.morph.is_none() && level != self.lod.level() {
            if morph_s > 0.0 {
                let refine = level > self.lod.level();
                let coarse = level.min(self.lod.level());
                let lo = pm.wedges_at(coarse) as u32;
                let hi = pm.wedges_at(level.max(self.lod.level())) as u32;
                let (buffer, _) = self.morph_to.get_or_insert_with(|| {
                    let b = gpu.device.create_buffer(&wgpu::BufferDescriptor {
                        label: Some("object morph targets"),
                        size: (pm.wedge_position.len().max(1) * 32) as u64,
                        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                        mapped_at_creation: false,
                    });
                    let g = morph_group(&gpu.device, morph_layout, &b);
                    (b, g)
                });
                let to: Vec<[f32; 4]> = (lo..hi)
                    .flat_map(|w0| {
                        let w = pm.live_wedge(w0, lo);
                        let q = pm.positions[pm.wedge_position[w as usize] as usize];
                        let n = model.normals[w as usize];
                        [[q[0], q[1], q[2], 1.0], [n[0], n[1], n[2], 0.0]]
                    })
                    .collect();
                if !to.is_empty() {
                    gpu.queue
                        .write_buffer(buffer, u64::from(lo) * 32, bytemuck::cast_slice(&to));
                }
                if refine {
                    self.lod.set_level(pm, &model.edits, level);
                }
                self.morph = Some(Morph {
                    lo,
                    hi,
                    t: 0.0,
                    refine,
                    target: level,
                });
            } else {
                self.lod.set_level(pm, &model.edits, level);
            }
        }
        let shown = self.lod.level();
        if self.uploaded_level == shown {
            return false;
        }
        let indices = self.lod.indices();
        if !indices.is_empty() {
            gpu.queue
                .write_buffer(&self.indices, 0, bytemuck::cast_slice(indices));
        }
        self.uploaded_level = shown;
        true
    }
}

struct DrawItem {
    instance: u32,
    model: u32,
    option: usize,
    /// Indices drawn (vertices, for a merged far mesh).
    index_count: u32,
    full_triangles: u32,
    /// The slots of its facade and roof textures (None: the white fallback).
    slots: [Option<SlotId>; 2],
    /// A merged far mesh: the index of its node in the frame's drawn nodes.
    hlod: Option<usize>,
}

/// A node's merged far mesh on the GPU (three vertices a triangle, no index list).
struct HlodGpu {
    vertices: wgpu::Buffer,
    vertex_count: u32,
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
}

pub struct ObjectsRenderer {
    set: Arc<ObjectSet>,
    pipeline: wgpu::RenderPipeline,
    /// Merged far meshes: per-vertex colour, no morph.
    pipeline_hlod: wgpu::RenderPipeline,
    /// Per model, per chain option (0 the base).
    vertex_buffers: Vec<Vec<wgpu::Buffer>>,
    draw_layout: wgpu::BindGroupLayout,
    morph_layout: wgpu::BindGroupLayout,
    /// Bound for instances that are not morphing (the shader reads nothing from it).
    no_morph: wgpu::BindGroup,
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
                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer,
                    offset: 0,
                    size: wgpu::BufferSize::new(std::mem::size_of::<DrawUniform>() as u64),
                }),
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
        label: Some("object draw uniforms"),
        size: draws.max(1) * DRAW_STRIDE,
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
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
                uniform_entry(
                    0,
                    true,
                    wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT,
                ),
                texture_entry(1, wgpu::TextureViewDimension::D2),
                texture_entry(2, wgpu::TextureViewDimension::D2),
                sampler_entry(3),
            ],
        });
        let morph_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("object morph layout"),
            entries: &[storage_entry(0, wgpu::ShaderStages::VERTEX)],
        });
        let no_morph = morph_group(
            device,
            &morph_layout,
            &device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("no morph"),
                size: 16,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            }),
        );
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
            array_stride: 36,
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
        let vertex_buffers = set
            .models
            .iter()
            .map(|model| {
                (0..=model.chain.len())
                    .map(|option| {
                        let m = model.option(option);
                        let mut data: Vec<f32> = Vec::with_capacity(m.pm.wedge_position.len() * 8);
                        for (w, &p) in m.pm.wedge_position.iter().enumerate() {
                            data.extend_from_slice(&m.pm.positions[p as usize]);
                            data.extend_from_slice(&m.normals[w]);
                            data.extend_from_slice(&m.pm.uvs.get(w).copied().unwrap_or([0.0; 2]));
                        }
                        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                            label: Some("object vertices"),
                            contents: bytemuck::cast_slice(&data),
                            usage: wgpu::BufferUsages::VERTEX,
                        })
                    })
                    .collect()
            })
            .collect();
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
            vertex_buffers,
            draw_layout,
            morph_layout,
            no_morph,
            draw_buffer,
            groups: HashMap::new(),
            draw_capacity,
            tex_pool,
            gpu_tex: GpuTexturePool::new(gpu),
            units_per_texture,
            tex_means,
            instances: HashMap::new(),
            items: Vec::new(),
            frame_no: 0,
            stats: ObjectStats::default(),
        }
    }

    /// The geomorph progress (0 to 1) of each drawn instance that is morphing.
    pub fn morphs(&self) -> Vec<(u32, f32)> {
        self.items
            .iter()
            .filter(|i| i.hlod.is_none())
            .filter_map(|i| Some((i.instance, self.instances[&i.instance].morph?.t)))
            .collect()
    }

    /// The level each drawn instance showed last frame (tests and statistics).
    pub fn levels(&self) -> Vec<(u32, usize)> {
        let mut v: Vec<(u32, usize)> = self
            .items
            .iter()
            .filter(|i| i.hlod.is_none())
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
            .filter(|i| i.hlod.is_none())
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
    ) -> usize {
        let Some(h) = work.get::<NodeObjects>().and_then(|o| o.hlod.as_ref()) else {
            return 0;
        };
        let vertices = gpu
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("object hlod vertices"),
                contents: bytemuck::cast_slice(&h.vertices),
                usage: wgpu::BufferUsages::VERTEX,
            });
        let vertex_count = h.vertices.len() as u32;
        let bytes = std::mem::size_of_val(h.vertices.as_slice());
        work.gpu.put(HlodGpu {
            vertices,
            vertex_count,
        });
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
        let k_px = camera.k_px();
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
            let light = light_entry(frame, draws.tree, node.work).grid;
            if self.hlod_item(draws, node_index, objects, light, &mut uniforms) {
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
                let distance_m = (c - camera.position_m).length() - r;
                texturing::request_instance(
                    &mut self.tex_pool,
                    &set,
                    &self.units_per_texture,
                    camera,
                    id,
                    (c, r),
                );
                let choice = choose(model, &settings, draws.tau_px, distance_m, k_px, inst.scale);
                let full = model.pm.triangles.len();
                let drawn_model = model.option(choice.option);
                // A new instance starts at full detail (and geomorphs down when MORPH is on);
                // a switch of chain level starts at the chosen level.
                let new_entry = |level: usize| {
                    let pm = &drawn_model.pm;
                    InstanceGpu {
                        option: choice.option,
                        lod: PmInstance::new(pm, level),
                        indices: gpu.device.create_buffer(&wgpu::BufferDescriptor {
                            label: Some("object indices"),
                            size: (pm.triangles.len() * 12).max(4) as u64,
                            usage: wgpu::BufferUsages::INDEX | wgpu::BufferUsages::COPY_DST,
                            mapped_at_creation: false,
                        }),
                        uploaded_level: 0,
                        last_frame: 0,
                        morph: None,
                        morph_to: None,
                    }
                };
                let entry = self
                    .instances
                    .entry(id)
                    .or_insert_with(|| new_entry(drawn_model.pm.level_count()));
                if entry.option != choice.option {
                    // Another chain level: its own vertices, so a new list (switched at once).
                    *entry = new_entry(choice.level);
                }
                entry.last_frame = self.frame_no;
                let changed = entry.update_level(
                    gpu,
                    drawn_model,
                    choice.level,
                    settings.morph_s,
                    draws.dt_s,
                    &self.morph_layout,
                );
                self.stats.level_changes += u32::from(changed);
                let shown = entry.lod.level();
                let indices = entry.lod.indices();
                let morph = entry.morph.map_or([0.0; 4], |m| {
                    [
                        m.lo as f32,
                        m.hi as f32,
                        m.t.min(1.0),
                        f32::from(u8::from(m.refine)),
                    ]
                });
                if indices.is_empty() {
                    continue;
                }
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
                });
                self.items.push(DrawItem {
                    instance: id,
                    model: inst.model,
                    option: choice.option,
                    index_count: indices.len() as u32,
                    full_triangles: full as u32,
                    slots: [None; 2],
                    hlod: None,
                });
                self.stats.instances_drawn += 1;
                self.stats.triangles += indices.len() as u64 / 3;
                self.stats.full_triangles += full as u64;
            }
        }
        let frame_no = self.frame_no;
        self.instances
            .retain(|_, i| frame_no.saturating_sub(i.last_frame) < KEEP_FRAMES);
        self.texture_plan(gpu, draws, &mut uniforms);
        self.write_uniforms(gpu, &uniforms);
    }

    fn draw(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        _frame: &FrameResources,
        draws: &FrameDraws<'_>,
        stats: &mut DrawStats,
    ) {
        if self.items.is_empty() {
            return;
        }
        for (k, item) in self.items.iter().enumerate() {
            if let Some(node_index) = item.hlod {
                let (Some(mesh), Some(group)) = (
                    draws.drawn[node_index].work.gpu.get::<HlodGpu>(),
                    self.groups.get(&item.slots),
                ) else {
                    continue;
                };
                pass.set_pipeline(&self.pipeline_hlod);
                pass.set_bind_group(2, group, &[(k as u64 * DRAW_STRIDE) as u32]);
                pass.set_bind_group(3, &self.no_morph, &[]);
                pass.set_vertex_buffer(0, mesh.vertices.slice(..));
                pass.draw(0..mesh.vertex_count, 0..1);
                stats.object_draw_calls += 1;
                stats.object_hlod_draws += 1;
                stats.object_triangles += u64::from(mesh.vertex_count / 3);
                stats.object_full_triangles += u64::from(item.full_triangles);
                continue;
            }
            let Some(inst) = self.instances.get(&item.instance) else {
                continue;
            };
            pass.set_pipeline(&self.pipeline);
            let Some(group) = self.groups.get(&item.slots) else {
                continue;
            };
            pass.set_bind_group(2, group, &[(k as u64 * DRAW_STRIDE) as u32]);
            let morph = inst
                .morph_to
                .as_ref()
                .filter(|_| inst.morph.is_some())
                .map_or(&self.no_morph, |(_, g)| g);
            pass.set_bind_group(3, morph, &[]);
            pass.set_vertex_buffer(
                0,
                self.vertex_buffers[item.model as usize][item.option].slice(..),
            );
            pass.set_index_buffer(inst.indices.slice(..), wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..item.index_count, 0, 0..1);
            stats.object_draw_calls += 1;
            stats.object_triangles += u64::from(item.index_count / 3);
            stats.object_full_triangles += u64::from(item.full_triangles);
            stats.object_chain_draws += u32::from(item.option > 0);
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

impl ObjectsRenderer {
    /// Draws node `node_index`'s merged far mesh instead of its houses when it has one on the
    /// GPU, the view allows it and the pixel metric accepts its error ([`hlod::accepts`]).
    fn hlod_item(
        &mut self,
        draws: &FrameDraws<'_>,
        node_index: usize,
        objects: &NodeObjects,
        light: [f32; 4],
        uniforms: &mut Vec<DrawUniform>,
    ) -> bool {
        let node = &draws.drawn[node_index];
        let camera = draws.camera;
        let (Some(h), Some(gpu_mesh)) = (&objects.hlod, node.work.gpu.get::<HlodGpu>()) else {
            return false;
        };
        if !draws.view.hlod
            || !hlod::accepts(
                h,
                &draws.view.pm_lod,
                draws.tau_px,
                camera.position_m,
                camera.k_px(),
            )
        {
            return false;
        }
        if !draws.frustum.intersects_aabb(h.lo_m, h.hi_m) {
            return true;
        }
        let rel = (h.origin_m - camera.position_m).as_vec3();
        uniforms.push(DrawUniform {
            rel_from_model: glam::Mat4::from_translation(rel).to_cols_array_2d(),
            normal_from_model: glam::Mat4::IDENTITY.to_cols_array_2d(),
            fade: [
                node.dither[0],
                node.dither[1],
                f32::from(node.key.level),
                0.0,
            ],
            albedo: [1.0; 4],
            morph: [0.0; 4],
            light,
            base_local: [0.0; 4],
            base_rel: rel.extend(0.0).to_array(),
            // Vertex colours (w = 1), no texture level.
            tex: [-1.0, -1.0, 0.0, 1.0],
            roof_albedo: [1.0; 4],
        });
        self.items.push(DrawItem {
            instance: 0,
            model: 0,
            option: 0,
            index_count: gpu_mesh.vertex_count,
            full_triangles: h.full_triangles as u32,
            slots: [None; 2],
            hlod: Some(node_index),
        });
        self.stats.triangles += u64::from(gpu_mesh.vertex_count / 3);
        self.stats.full_triangles += h.full_triangles as u64;
        true
    }

    /// Ends the texture cache's frame (its uploads within what is left of the streamer's
    /// per-frame upload budgets of bytes and time), applies the plan on the GPU and fills the draws' texture
    /// levels.
    fn texture_plan(&mut self, gpu: &Gpu, draws: &FrameDraws<'_>, uniforms: &mut [DrawUniform]) {
        // Texture uploads share the streamer's per-frame upload budgets, bytes and time, with
        // the nodes'.
        let left = u64::try_from(draws.upload_bytes_left)
            .unwrap_or(u64::MAX)
            .min(
                self.gpu_tex
                    .upload_cost
                    .bytes_within(draws.upload_time_left_s),
            );
        self.tex_pool
            .set_upload_budget(left.min(PoolSettings::default().upload_bytes_per_frame));
        let plan = self.tex_pool.end_frame();
        if self.gpu_tex.apply(gpu, &plan, &self.set.textures) {
            self.groups.clear();
        }
        self.texture_levels(
            uniforms,
            draws.view.texture_mip_view && !draws.view.pm_color_by_lod,
        );
    }

    /// Writes the draw uniforms (growing the buffer when needed) and makes the draw groups.
    fn write_uniforms(&mut self, gpu: &Gpu, uniforms: &[DrawUniform]) {
        if uniforms.is_empty() {
            return;
        }
        if uniforms.len() as u64 > self.draw_capacity {
            self.draw_capacity = (uniforms.len() as u64).next_power_of_two();
            self.draw_buffer = draw_buffer(&gpu.device, self.draw_capacity);
            self.groups.clear();
        }
        self.make_groups(gpu);
        let mut bytes = vec![0u8; uniforms.len() * DRAW_STRIDE as usize];
        for (k, u) in uniforms.iter().enumerate() {
            let at = k * DRAW_STRIDE as usize;
            bytes[at..at + std::mem::size_of::<DrawUniform>()]
                .copy_from_slice(bytemuck::bytes_of(u));
        }
        gpu.queue.write_buffer(&self.draw_buffer, 0, &bytes);
    }

    /// Makes the draw groups this frame's items need (their slots' views, or the fallback).
    fn make_groups(&mut self, gpu: &Gpu) {
        for item in &self.items {
            if self.groups.contains_key(&item.slots) {
                continue;
            }
            let views = item.slots.map(|s| {
                s.and_then(|s| self.gpu_tex.view(s))
                    .unwrap_or(&self.gpu_tex.fallback)
            });
            let group = draw_group(
                &gpu.device,
                &self.draw_layout,
                &self.draw_buffer,
                views,
                &self.gpu_tex.sampler,
            );
            self.groups.insert(item.slots, group);
        }
    }

    /// After the frame's texture plan: each textured draw's resident levels (or -1 and the
    /// textures' mean colours), the debug tint flag, and its slots.
    fn texture_levels(&mut self, uniforms: &mut [DrawUniform], mip_view: bool) {
        for (item, u) in self.items.iter_mut().zip(uniforms.iter_mut()) {
            if item.hlod.is_some() {
                continue;
            }
            let inst = &self.set.instances[item.instance as usize];
            let Some(textures) = inst.textures else {
                continue;
            };
            let resident = textures.map(|t| self.tex_pool.resident(t));
            item.slots = resident.map(|r| r.map(|(slot, _)| slot));
            let level = |k: usize| resident[k].map_or(-1.0, |(_, l)| l as f32);
            u.tex = [level(0), level(1), f32::from(u8::from(mip_view)), 0.0];
            if u.fade[3] < 0.5 {
                let [f, r] = textures.map(|t| self.tex_means[t as usize]);
                u.albedo = [f[0], f[1], f[2], 1.0];
                u.roof_albedo = [r[0], r[1], r[2], 1.0];
            } else {
                // Coloured by LOD: no textures.
                u.tex = [-1.0, -1.0, 0.0, 0.0];
            }
        }
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
    #[test]
    fn draw_uniform_fits_its_stride() {
        assert!(std::mem::size_of::<super::DrawUniform>() as u64 <= super::DRAW_STRIDE);
    }
}
