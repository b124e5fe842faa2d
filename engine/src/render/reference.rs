//! A same-run reference for GPU timings: the frame's terrain triangles drawn as one indexed
//! draw with a flat shader (positions made camera-relative on the CPU with the same f32 sums
//! the terrain shader does), and the frame's vegetation instances gathered into one instance
//! buffer and drawn with the same flat shader: one instanced draw per plant mesh and one for
//! every billboard and cluster quad (a whole quad each: the reference samples no texture, so
//! it covers more pixels than the frame's alpha-tested quads). Into a target of its own, timed
//! with timestamp queries like the frame pass. `frame pass / reference` says how close to the
//! adapter's limit the frame draws; an absolute time only means something per adapter.

use super::Gpu;
use super::frame::{FrameResources, PipelineSpec, node_offset_m, pipeline};
use super::gpu_data::MeshVertex;
use super::target::Target;
use super::timer::GpuTimer;
use super::vegetation::{InstanceRun, PlantInstance, VegetationRenderer};
use crate::camera::Camera;
use crate::terrain::mesh::NodeMesh;
use wgpu::util::DeviceExt;

/// The assembled shader source (prelude + `reference.wgsl`).
pub fn shader_source() -> String {
    super::shader::assemble("reference", "")
}

/// The reference draws, their target and timer.
pub struct GpuReference {
    pipeline: wgpu::RenderPipeline,
    plant_pipeline: wgpu::RenderPipeline,
    quad_pipeline: wgpu::RenderPipeline,
    /// The frame's plant instances, gathered (grown when needed).
    instances: Option<wgpu::Buffer>,
    target: Option<Target>,
    timer: Option<GpuTimer>,
    /// Terrain triangles of the last recorded reference.
    pub triangles: u64,
    /// Plant instances of the last recorded reference (meshes, billboards, cluster quads).
    pub plant_instances: u64,
}

impl std::fmt::Debug for GpuReference {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "GpuReference({} triangles, {} plant instances)",
            self.triangles, self.plant_instances
        )
    }
}

/// What a frame drew, for its reference: the camera, the terrain meshes (each with its
/// decimation) and the vegetation renderer after its `prepare` (None: no vegetation).
#[derive(Clone, Copy)]
pub struct FrameContent<'a> {
    pub camera: &'a Camera,
    pub meshes: &'a [(&'a NodeMesh, u8)],
    pub plants: Option<&'a VegetationRenderer>,
}

const INSTANCE_BYTES: u64 = std::mem::size_of::<PlantInstance>() as u64;

/// The frame's vegetation as the reference draws it: the gathered instances' copies (source
/// page, first instance, count, in gathered order) and its draws, one per plant mesh (first
/// index, index count, base vertex; its instances) and one for the quads.
#[derive(Debug, Default)]
struct PlantPlan {
    copies: Vec<(u32, u32, u32)>,
    meshes: Vec<((u32, u32, i32), std::ops::Range<u32>)>,
    quads: std::ops::Range<u32>,
}

impl PlantPlan {
    /// Gathers `runs` by mesh, the quads last.
    fn new(runs: impl Iterator<Item = InstanceRun>) -> Self {
        let mut runs: Vec<InstanceRun> = runs.filter(|r| r.count > 0).collect();
        // Quads (None) sort first with `Option`'s order: put them last.
        runs.sort_by_key(|r| (r.mesh.is_none(), r.mesh));
        let mut plan = Self::default();
        let mut at = 0u32;
        for r in &runs {
            // A node's groups are adjacent in its page: one copy for a run of them.
            match plan.copies.last_mut() {
                Some((page, first, count)) if *page == r.page && *first + *count == r.first => {
                    *count += r.count;
                }
                _ => plan.copies.push((r.page, r.first, r.count)),
            }
            let range = at..at + r.count;
            at += r.count;
            match r.mesh {
                Some(mesh) => match plan.meshes.last_mut() {
                    Some((m, instances)) if *m == mesh => instances.end = range.end,
                    _ => plan.meshes.push((mesh, range)),
                },
                None if plan.quads.is_empty() => plan.quads = range,
                None => plan.quads.end = range.end,
            }
        }
        plan
    }

    fn instances(&self) -> u32 {
        self.copies.iter().map(|c| c.2).sum()
    }
}

/// Vertex layout: a camera-relative position.
const LAYOUT: wgpu::VertexBufferLayout<'static> = wgpu::VertexBufferLayout {
    array_stride: 12,
    step_mode: wgpu::VertexStepMode::Vertex,
    attributes: &[wgpu::VertexAttribute {
        format: wgpu::VertexFormat::Float32x3,
        offset: 0,
        shader_location: 0,
    }],
};

impl GpuReference {
    /// None when the device has no timestamp queries (nothing to compare then).
    pub fn new(gpu: &Gpu, frame: &FrameResources) -> Option<Self> {
        let timer = GpuTimer::new(gpu)?;
        let module = super::shader::module(&gpu.device, "reference", &shader_source());
        let layout = frame.pipeline_layout(&gpu.device, "reference pipeline layout", false, &[]);
        let plant_layout =
            frame.pipeline_layout(&gpu.device, "reference plant pipeline layout", true, &[]);
        let make = |layout: &wgpu::PipelineLayout,
                    label: &str,
                    vs: &str,
                    buffers: &[Option<wgpu::VertexBufferLayout<'_>>]| {
            let spec =
                PipelineSpec::triangles(label, vs, "fs_reference", buffers, frame.color_format);
            pipeline(&gpu.device, &module, layout, &spec)
        };
        Some(Self {
            pipeline: make(&layout, "reference", "vs_reference", &[Some(LAYOUT)]),
            plant_pipeline: make(
                &plant_layout,
                "reference plants",
                "vs_reference_plant",
                &[Some(MeshVertex::LAYOUT), Some(PlantInstance::LAYOUT)],
            ),
            quad_pipeline: make(
                &plant_layout,
                "reference quads",
                "vs_reference_quad",
                &[Some(PlantInstance::LAYOUT)],
            ),
            instances: None,
            target: None,
            timer: Some(timer),
            triangles: 0,
            plant_instances: 0,
        })
    }

    /// The target the last reference was drawn into (flat grey where covered, transparent
    /// elsewhere).
    pub fn target(&self) -> Option<&Target> {
        self.target.as_ref()
    }

    /// The latest reference time (ms), a frame or more late like the frame timer's.
    pub fn last_ms(&self) -> Option<f64> {
        self.timer.as_ref().and_then(|t| t.last_ms)
    }

    /// Records the reference of `content` into `encoder` (after the frame's pass, whose frame
    /// uniforms and vegetation node table it reuses), into its own `size` target.
    pub fn record(
        &mut self,
        gpu: &Gpu,
        frame: &FrameResources,
        encoder: &mut wgpu::CommandEncoder,
        size: [u32; 2],
        content: &FrameContent<'_>,
    ) {
        if let Some(t) = self.timer.as_mut() {
            t.harvest(gpu);
        }
        let mut positions: Vec<[f32; 3]> = Vec::new();
        let mut indices: Vec<u32> = Vec::new();
        for &(m, decimation) in content.meshes {
            let drawn = m.drawn_indices(decimation);
            let o = node_offset_m(m.origin_m, content.camera.position_m);
            let base = positions.len() as u32;
            positions.extend(
                m.positions
                    .iter()
                    .map(|p| [p[0] + o[0], p[1] + o[1], p[2] + o[2]]),
            );
            indices.extend(drawn.iter().map(|i| i + base));
        }
        self.triangles = indices.len() as u64 / 3;
        let plants = content
            .plants
            .map(|v| (v, PlantPlan::new(v.frame_instances())))
            .filter(|(_, plan)| plan.instances() > 0);
        self.plant_instances = plants.as_ref().map_or(0, |(_, p)| u64::from(p.instances()));
        if indices.is_empty() && plants.is_none() {
            return;
        }
        let device = &gpu.device;
        let terrain = (!indices.is_empty()).then(|| {
            let vb = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("reference vertices"),
                contents: bytemuck::cast_slice(&positions),
                usage: wgpu::BufferUsages::VERTEX,
            });
            let ib = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("reference indices"),
                contents: bytemuck::cast_slice(&indices),
                usage: wgpu::BufferUsages::INDEX,
            });
            (vb, ib)
        });
        // Gathering the instances is not part of the timed pass.
        if let Some((v, plan)) = &plants {
            self.gather(device, encoder, v.instance_pages(), plan);
        }
        if self.target.as_ref().is_none_or(|t| t.size != size) {
            self.target = Some(Target::new(device, size, frame.color_format));
        }
        let Some(target) = self.target.as_ref() else {
            return;
        };
        let timed = self.timer.as_ref().is_some_and(|t| t.begin(encoder));
        {
            let mut pass = super::frame::bake_pass(
                encoder,
                "reference pass",
                &[&target.color_view],
                &target.depth_view,
            );
            pass.set_bind_group(0, &frame.group, &[]);
            if let Some((vb, ib)) = &terrain {
                pass.set_pipeline(&self.pipeline);
                pass.set_vertex_buffer(0, vb.slice(..));
                pass.set_index_buffer(ib.slice(..), wgpu::IndexFormat::Uint32);
                pass.draw_indexed(0..indices.len() as u32, 0, 0..1);
            }
            if let Some((v, plan)) = &plants
                && let Some(instances) = &self.instances
            {
                pass.set_bind_group(1, v.node_table(), &[]);
                let (shape_vertices, shape_indices) = v.shape_buffers();
                if !plan.meshes.is_empty() {
                    pass.set_pipeline(&self.plant_pipeline);
                    pass.set_vertex_buffer(0, shape_vertices.slice(..));
                    pass.set_vertex_buffer(1, instances.slice(..));
                    pass.set_index_buffer(shape_indices.slice(..), wgpu::IndexFormat::Uint32);
                    for ((first, count, base_vertex), range) in &plan.meshes {
                        pass.draw_indexed(*first..first + count, *base_vertex, range.clone());
                    }
                }
                if !plan.quads.is_empty() {
                    pass.set_pipeline(&self.quad_pipeline);
                    pass.set_vertex_buffer(0, instances.slice(..));
                    pass.draw(0..6, plan.quads.clone());
                }
            }
        }
        if timed && let Some(t) = &self.timer {
            t.end(encoder);
        }
    }

    /// Copies the plan's instance ranges from the vegetation's `pages`, in order, into the
    /// reference's instance buffer.
    fn gather(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        pages: &[wgpu::Buffer],
        plan: &PlantPlan,
    ) {
        let bytes = u64::from(plan.instances()) * INSTANCE_BYTES;
        if self.instances.as_ref().is_none_or(|b| b.size() < bytes) {
            self.instances = Some(device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("reference plant instances"),
                size: bytes.next_power_of_two(),
                usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }));
        }
        let Some(dst) = &self.instances else { return };
        let mut at = 0;
        for &(page, first, count) in &plan.copies {
            let n = u64::from(count) * INSTANCE_BYTES;
            encoder.copy_buffer_to_buffer(
                &pages[page as usize],
                u64::from(first) * INSTANCE_BYTES,
                dst,
                at,
                n,
            );
            at += n;
        }
    }

    /// Call after submitting the encoder given to [`Self::record`].
    pub fn after_submit(&self) {
        if let Some(t) = &self.timer {
            t.after_submit();
        }
    }
}
