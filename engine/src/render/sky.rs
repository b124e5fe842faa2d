//! The sky (a full-screen gradient with a sun disc at the far plane, drawn after the opaque node
//! content with an `Equal` depth test, so it shades only the pixels nothing covered) and the
//! node-bounds debug lines (drawn last): frame-level renderers that hold no per-node objects.

use super::Gpu;
use super::frame::{DrawStats, FrameResources, PipelineSpec, depth_state, pipeline};
use super::scene::{FrameDraws, NodeRenderer};
use crate::terrain::mesh::NodeMesh;

/// The assembled shader source (prelude + `sky.wgsl`).
pub fn shader_source() -> String {
    super::shader::assemble("sky", "")
}

fn frame_only_pipeline(
    gpu: &Gpu,
    frame: &FrameResources,
    spec: &PipelineSpec<'_>,
) -> wgpu::RenderPipeline {
    let module = super::shader::module(&gpu.device, "sky", &shader_source());
    let layout = frame.pipeline_layout(&gpu.device, spec.label, false, &[]);
    pipeline(&gpu.device, &module, &layout, spec)
}

/// The sky gradient.
pub struct SkyRenderer {
    sky: wgpu::RenderPipeline,
}

impl SkyRenderer {
    pub fn new(gpu: &Gpu, frame: &FrameResources) -> Self {
        let sky = frame_only_pipeline(
            gpu,
            frame,
            &PipelineSpec {
                // Depth 0 is the cleared far plane: only pixels no geometry wrote pass.
                depth: depth_state(false, wgpu::CompareFunction::Equal),
                ..PipelineSpec::triangles("sky", "vs_sky", "fs_sky", &[], frame.color_format)
            },
        );
        Self { sky }
    }
}

impl NodeRenderer for SkyRenderer {
    fn name(&self) -> &'static str {
        "sky"
    }

    fn prepare(&mut self, _gpu: &Gpu, _frame: &mut FrameResources, _draws: &FrameDraws<'_>) {}

    fn draw(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        _frame: &FrameResources,
        draws: &FrameDraws<'_>,
        _stats: &mut DrawStats,
    ) {
        if draws.view.sky {
            pass.set_pipeline(&self.sky);
            pass.draw(0..3, 0..1);
        }
    }
}

/// Debug: the boxes of the visible terrain nodes as yellow lines.
pub struct BoundsLines {
    lines: wgpu::RenderPipeline,
    buffer: wgpu::Buffer,
    capacity: u64,
    count: u32,
    /// This frame's line vertices (camera-relative box corners).
    vertices: Vec<[f32; 3]>,
}

impl BoundsLines {
    pub fn new(gpu: &Gpu, frame: &FrameResources) -> Self {
        let layout = [Some(wgpu::VertexBufferLayout {
            array_stride: 12,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &wgpu::vertex_attr_array![0 => Float32x3],
        })];
        let lines = frame_only_pipeline(
            gpu,
            frame,
            &PipelineSpec {
                topology: wgpu::PrimitiveTopology::LineList,
                depth: depth_state(false, wgpu::CompareFunction::GreaterEqual),
                ..PipelineSpec::triangles(
                    "node bounds lines",
                    "vs_lines",
                    "fs_lines",
                    &layout,
                    frame.color_format,
                )
            },
        );
        let capacity = 1024;
        Self {
            lines,
            buffer: Self::buffer(&gpu.device, capacity),
            capacity,
            count: 0,
            vertices: Vec::new(),
        }
    }

    fn buffer(device: &wgpu::Device, vertices: u64) -> wgpu::Buffer {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("node bounds lines"),
            size: vertices * 12,
            usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// Collects and uploads this frame's lines (called from `prepare`, before the pass).
    fn collect(&mut self, gpu: &Gpu, draws: &FrameDraws<'_>) {
        self.vertices.clear();
        if draws.view.show_bounds {
            let c = draws.camera.position_m;
            for d in draws.drawn.iter().filter(|d| d.dither[1] > d.dither[0]) {
                let Some(mesh) = d.work.get::<NodeMesh>() else {
                    continue;
                };
                let (lo, hi) = mesh.aabb_m(draws.tree);
                if !draws.frustum.intersects_aabb(lo, hi) {
                    continue;
                }
                let (lo, hi) = (lo - c, hi - c);
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
                    self.vertices.push(corner(a));
                    self.vertices.push(corner(b));
                }
            }
        }
        if self.vertices.len() as u64 > self.capacity {
            self.capacity = (self.vertices.len() as u64).next_power_of_two();
            self.buffer = Self::buffer(&gpu.device, self.capacity);
        }
        if !self.vertices.is_empty() {
            gpu.queue
                .write_buffer(&self.buffer, 0, bytemuck::cast_slice(&self.vertices));
        }
        self.count = self.vertices.len() as u32;
    }
}

impl NodeRenderer for BoundsLines {
    fn name(&self) -> &'static str {
        "bounds lines"
    }

    fn prepare(&mut self, gpu: &Gpu, _frame: &mut FrameResources, draws: &FrameDraws<'_>) {
        self.collect(gpu, draws);
    }

    fn draw(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        _frame: &FrameResources,
        _draws: &FrameDraws<'_>,
        _stats: &mut DrawStats,
    ) {
        if self.count > 0 {
            pass.set_pipeline(&self.lines);
            pass.set_vertex_buffer(0, self.buffer.slice(..));
            pass.draw(0..self.count, 0..1);
        }
    }
}
