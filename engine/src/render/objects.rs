//! The objects renderer: progressive meshes (one vertex buffer per model, wedges in level order)
//! drawn per instance with an index list kept at the level the pixel metric chooses
//! ([`crate::objects::lod`]), edited level by level on the CPU ([`PmInstance`]) and rewritten
//! on the GPU only when the level changes. One draw per visible instance. A model with an
//! `MSFT_lod` chain has a vertex buffer per chain level; an instance that moves to another chain
//! level starts a new index list there (no geomorph across chain levels: they share no vertices).

use super::Gpu;
use super::frame::{
    DrawStats, FrameResources, PipelineSpec, pipeline, storage_entry, uniform_entry,
};
use super::lighting::light_entry;
use super::scene::{FrameDraws, NodeRenderer};
use crate::objects::content::{NodeObjects, ObjectsContent};
use crate::objects::lod::{Choice, choose};
use crate::objects::set::{ObjectSet, PmModel, model_to_world};
use crate::stream::Shared;
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
    index_count: u32,
    full_triangles: u32,
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
    /// Per model, per chain option (0 the base).
    vertex_buffers: Vec<Vec<wgpu::Buffer>>,
    draw_layout: wgpu::BindGroupLayout,
    morph_layout: wgpu::BindGroupLayout,
    /// Bound for instances that are not morphing (the shader reads nothing from it).
    no_morph: wgpu::BindGroup,
    draw_buffer: wgpu::Buffer,
    draw_group: wgpu::BindGroup,
    draw_capacity: u64,
    instances: HashMap<u32, InstanceGpu>,
    items: Vec<DrawItem>,
    frame_no: u64,
    pub stats: ObjectStats,
}

/// The WGSL of this renderer.
pub fn shader_source() -> String {
    super::shader::assemble("objects", "")
}

fn draw_group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    buffer: &wgpu::Buffer,
) -> wgpu::BindGroup {
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("object draws"),
        layout,
        entries: &[wgpu::BindGroupEntry {
            binding: 0,
            resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer,
                offset: 0,
                size: wgpu::BufferSize::new(std::mem::size_of::<DrawUniform>() as u64),
            }),
        }],
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
            entries: &[uniform_entry(0, true, wgpu::ShaderStages::VERTEX)],
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
        let attrs = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3];
        let buffers = [Some(wgpu::VertexBufferLayout {
            array_stride: 24,
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
        let pipeline = pipeline(device, &module, &layout, &spec);
        let vertex_buffers = set
            .models
            .iter()
            .map(|model| {
                (0..=model.chain.len())
                    .map(|option| {
                        let m = model.option(option);
                        let mut data: Vec<f32> = Vec::with_capacity(m.pm.wedge_position.len() * 6);
                        for (w, &p) in m.pm.wedge_position.iter().enumerate() {
                            data.extend_from_slice(&m.pm.positions[p as usize]);
                            data.extend_from_slice(&m.normals[w]);
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
        let draw_group = draw_group(device, &draw_layout, &draw_buffer);
        ObjectsRenderer {
            set,
            pipeline,
            vertex_buffers,
            draw_layout,
            morph_layout,
            no_morph,
            draw_buffer,
            draw_group,
            draw_capacity,
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
            .filter_map(|i| Some((i.instance, self.instances[&i.instance].morph?.t)))
            .collect()
    }

    /// The level each drawn instance showed last frame (tests and statistics).
    pub fn levels(&self) -> Vec<(u32, usize)> {
        let mut v: Vec<(u32, usize)> = self
            .items
            .iter()
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

    fn prepare(&mut self, gpu: &Gpu, _frame: &mut FrameResources, draws: &FrameDraws<'_>) {
        self.frame_no += 1;
        self.items.clear();
        self.stats = ObjectStats::default();
        let camera = draws.camera;
        let k_px = camera.k_px();
        let settings = draws.view.pm_lod;
        let mut uniforms: Vec<DrawUniform> = Vec::new();
        for node in draws.drawn {
            let Some(objects) = node.work.get::<NodeObjects>() else {
                continue;
            };
            // Objects are lit by the drawing node's light grid (sky and sun visibility).
            let light = light_entry(draws.tree, node.work);
            let corner = draws.tree.rect(node.key).min;
            for &id in &objects.instances {
                let inst = &self.set.instances[id as usize];
                let model = &self.set.models[inst.model as usize];
                let (c, r) = self.set.sphere(inst);
                if !draws
                    .frustum
                    .intersects_aabb(c - DVec3::splat(r), c + DVec3::splat(r))
                {
                    continue;
                }
                let distance_m = (c - camera.position_m).length() - r;
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
                    [0.62, 0.58, 0.52]
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
                });
                self.items.push(DrawItem {
                    instance: id,
                    model: inst.model,
                    option: choice.option,
                    index_count: indices.len() as u32,
                    full_triangles: full as u32,
                });
                self.stats.instances_drawn += 1;
                self.stats.triangles += indices.len() as u64 / 3;
                self.stats.full_triangles += full as u64;
            }
        }
        let frame_no = self.frame_no;
        self.instances
            .retain(|_, i| frame_no.saturating_sub(i.last_frame) < KEEP_FRAMES);
        if uniforms.is_empty() {
            return;
        }
        if uniforms.len() as u64 > self.draw_capacity {
            self.draw_capacity = (uniforms.len() as u64).next_power_of_two();
            self.draw_buffer = draw_buffer(&gpu.device, self.draw_capacity);
            self.draw_group = draw_group(&gpu.device, &self.draw_layout, &self.draw_buffer);
        }
        let mut bytes = vec![0u8; uniforms.len() * DRAW_STRIDE as usize];
        for (k, u) in uniforms.iter().enumerate() {
            let at = k * DRAW_STRIDE as usize;
            bytes[at..at + std::mem::size_of::<DrawUniform>()]
                .copy_from_slice(bytemuck::bytes_of(u));
        }
        gpu.queue.write_buffer(&self.draw_buffer, 0, &bytes);
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
        pass.set_pipeline(&self.pipeline);
        for (k, item) in self.items.iter().enumerate() {
            let Some(inst) = self.instances.get(&item.instance) else {
                continue;
            };
            pass.set_bind_group(2, &self.draw_group, &[(k as u64 * DRAW_STRIDE) as u32]);
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
