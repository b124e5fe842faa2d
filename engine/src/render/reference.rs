//! A same-run reference for GPU timings: the frame's terrain triangles drawn as one indexed
//! draw with a flat shader (positions made camera-relative on the CPU with the same f32 sums
//! the terrain shader does), into a target of its own, timed with timestamp queries like the
//! frame pass. `frame pass / reference` says how close to the adapter's limit the frame draws;
//! an absolute time only means something per adapter.

use super::Gpu;
use super::frame::{FrameResources, PipelineSpec, node_offset_m, pipeline};
use super::target::Target;
use super::timer::GpuTimer;
use crate::camera::Camera;
use crate::terrain::mesh::NodeMesh;
use wgpu::util::DeviceExt;

/// The assembled shader source (prelude + `reference.wgsl`).
pub fn shader_source() -> String {
    super::shader::assemble("reference", "")
}

/// The reference draw, its target and its timer.
pub struct TerrainReference {
    pipeline: wgpu::RenderPipeline,
    target: Option<Target>,
    timer: Option<GpuTimer>,
    /// Triangles of the last recorded reference.
    pub triangles: u64,
}

impl std::fmt::Debug for TerrainReference {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "TerrainReference({} triangles)", self.triangles)
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

impl TerrainReference {
    /// None when the device has no timestamp queries (nothing to compare then).
    pub fn new(gpu: &Gpu, frame: &FrameResources) -> Option<Self> {
        let timer = GpuTimer::new(gpu)?;
        let module = super::shader::module(&gpu.device, "reference", &shader_source());
        let layout = frame.pipeline_layout(&gpu.device, "reference pipeline layout", false, &[]);
        let buffers = [Some(LAYOUT)];
        let spec = PipelineSpec::triangles(
            "reference",
            "vs_reference",
            "fs_reference",
            &buffers,
            frame.color_format,
        );
        Some(Self {
            pipeline: pipeline(&gpu.device, &module, &layout, &spec),
            target: None,
            timer: Some(timer),
            triangles: 0,
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

    /// Records the reference of `meshes` seen by `cam` into `encoder` (after the frame's pass,
    /// whose frame uniforms it reuses), into its own `size` target.
    pub fn record(
        &mut self,
        gpu: &Gpu,
        frame: &FrameResources,
        encoder: &mut wgpu::CommandEncoder,
        size: [u32; 2],
        cam: &Camera,
        meshes: &[(&NodeMesh, u8)],
    ) {
        if let Some(t) = self.timer.as_mut() {
            t.harvest(gpu);
        }
        let mut positions: Vec<[f32; 3]> = Vec::new();
        let mut indices: Vec<u32> = Vec::new();
        for &(m, decimation) in meshes {
            let drawn = m.drawn_indices(decimation);
            let o = node_offset_m(m.origin_m, cam.position_m);
            let base = positions.len() as u32;
            positions.extend(
                m.positions
                    .iter()
                    .map(|p| [p[0] + o[0], p[1] + o[1], p[2] + o[2]]),
            );
            indices.extend(drawn.iter().map(|i| i + base));
        }
        self.triangles = indices.len() as u64 / 3;
        if indices.is_empty() {
            return;
        }
        let device = &gpu.device;
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
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &frame.group, &[]);
            pass.set_vertex_buffer(0, vb.slice(..));
            pass.set_index_buffer(ib.slice(..), wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..indices.len() as u32, 0, 0..1);
        }
        if timed && let Some(t) = &self.timer {
            t.end(encoder);
        }
    }

    /// Call after submitting the encoder given to [`Self::record`].
    pub fn after_submit(&self) {
        if let Some(t) = &self.timer {
            t.after_submit();
        }
    }
}
