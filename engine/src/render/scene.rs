//! Renderers as plug-ins: each [`NodeRenderer`] owns its pipelines and its per-node GPU objects
//! (created by its upload hook in the streaming GPU phase, stored in the node's `GpuSlots`) and
//! records its own draws. A [`Scene`] holds the shared [`FrameResources`] and the renderers in
//! drawing order (sky, then the registered node-content kinds, then debug lines).

use super::Gpu;
use super::frame::{DrawStats, FrameResources, ViewOptions};
use crate::camera::{Camera, Frustum};
use crate::stream::NodeWork;
use crate::terrain::quadtree::{NodeKey, QuadTree};
use std::time::Instant;

/// One drawn node: its prepared content and its dither interval.
#[derive(Debug, Clone, Copy)]
pub struct DrawnNode<'a> {
    pub key: NodeKey,
    pub work: &'a NodeWork,
    pub dither: [f32; 2],
    /// Halvings of the vertex spacing its terrain grid is drawn with (0: every vertex).
    pub decimation: u8,
}

impl<'a> DrawnNode<'a> {
    /// `work`'s node drawn on its own: fully faded in, every vertex (tests and measures that
    /// draw chosen nodes without a streamer).
    pub fn faded_in(work: &'a NodeWork) -> Self {
        Self {
            key: work.key,
            work,
            dither: [0.0, 1.0],
            decimation: 0,
        }
    }
}

/// What a frame draws: the camera, the view options, the drawn nodes and the resident
/// ancestors of drawn nodes (content kept through splits is drawn via them), `ancestors`
/// sorted by key.
#[derive(Debug, Clone, Copy)]
pub struct FrameDraws<'a> {
    pub camera: &'a Camera,
    pub frustum: &'a Frustum,
    pub view: &'a ViewOptions,
    pub tree: &'a QuadTree,
    pub drawn: &'a [DrawnNode<'a>],
    pub ancestors: &'a [DrawnNode<'a>],
    /// Simulated seconds since the previous frame (time-based effects such as geomorphs).
    pub dt_s: f64,
    /// The pixel-error threshold the streamer selects with (objects choose their levels by it).
    pub tau_px: f64,
    /// What is left this frame of the streamer's GPU upload budget in bytes after the nodes'
    /// uploads (the texture cache uploads within it, at least one texture a frame).
    pub upload_bytes_left: usize,
    /// What is left this frame of the streamer's GPU time budget after the nodes' GPU phases
    /// (their frame-thread time and expected GPU time): the texture cache's uploads fit in it
    /// at their measured cost per byte, at least one texture a frame.
    pub upload_time_left_s: f64,
}

/// Bytes of one staging chunk of the node uploads: the chunks are kept and reused once the GPU
/// has copied out of them, so their memory is written warm. As many are made as two frames'
/// uploads fill (a frame's chunks are taken back in the next frame).
pub const STAGING_CHUNK_BYTES: u64 = 1 << 20;

/// A renderer's staging belt for its node uploads (copies recorded into the
/// [`UploadEncoder`]; the renderer's [`NodeRenderer::close_uploads`] recalls and finishes it),
/// with `premade` chunks made, closed and given back: they are free once wgpu maps them again,
/// at the first submission or poll (a chunk made in a frame costs that frame its zero-fill
/// and the first touch of its pages).
pub fn staging_belt(device: &wgpu::Device, premade: usize) -> wgpu::util::StagingBelt {
    let mut belt = wgpu::util::StagingBelt::new(device.clone(), STAGING_CHUNK_BYTES);
    if let (Some(chunk), Some(align)) = (
        wgpu::BufferSize::new(STAGING_CHUNK_BYTES),
        wgpu::BufferSize::new(wgpu::COPY_BUFFER_ALIGNMENT),
    ) {
        for _ in 0..premade {
            // A whole chunk each: every call makes a new one.
            let _ = belt.allocate(chunk, align);
        }
    }
    belt.finish();
    belt.recall();
    belt
}

/// What a renderer's [`NodeRenderer::close_uploads`] does with its [`staging_belt`]: the
/// chunks closed last time (their copies submitted since) return to the belt once the GPU has
/// copied out of them (wgpu maps them again in a later submission's or poll's maintenance);
/// then this frame's are closed.
pub fn close_staging(belt: &mut wgpu::util::StagingBelt) {
    belt.recall();
    belt.finish();
}

/// Where upload hooks record their copies into GPU buffers: the frame's command encoder (the
/// copies are submitted with the frame, before its pass, in one submission), or, for GPU
/// phases run without a frame, an encoder made on first use that the caller submits
/// ([`Self::finish`]) after [`Scene::finish_uploads`] (which closes the uploads' staging).
pub enum UploadEncoder<'a> {
    Frame(&'a mut wgpu::CommandEncoder),
    Own(Option<wgpu::CommandEncoder>),
}

impl UploadEncoder<'_> {
    /// The encoder to record into.
    pub fn get(&mut self, device: &wgpu::Device) -> &mut wgpu::CommandEncoder {
        match self {
            Self::Frame(e) => e,
            Self::Own(e) => e.get_or_insert_with(|| {
                device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("node uploads"),
                })
            }),
        }
    }

    /// Submits what was recorded into an own encoder (the frame's is submitted with the
    /// frame); true when it submitted.
    pub fn finish(self, queue: &wgpu::Queue) -> bool {
        if let Self::Own(Some(e)) = self {
            queue.submit([e.finish()]);
            return true;
        }
        false
    }
}

/// The GPU side of one kind of thing drawn.
pub trait NodeRenderer: std::any::Any {
    fn name(&self) -> &'static str;

    /// The GPU phase of a prepared node: create this renderer's objects from the node's payload
    /// (store them with `work.gpu.put`, record copies into `copies`) and return the bytes
    /// uploaded. Default: nothing.
    fn upload(
        &mut self,
        _gpu: &Gpu,
        _frame: &FrameResources,
        _tree: &QuadTree,
        _work: &mut NodeWork,
        _copies: &mut UploadEncoder<'_>,
    ) -> usize {
        0
    }

    /// After a frame's GPU phases, before the encoder their copies went into is submitted:
    /// close the staging memory the upload hooks wrote (it is reused once the GPU has copied
    /// out of it). Default: nothing.
    fn close_uploads(&mut self) {}

    /// Record into `deferred` the work a renderer defers to here (node ground textures, the
    /// impostor bakes its uploads asked for) within `time_left_s` (what the nodes' GPU phases
    /// left of the frame's budget), counting both the GPU time and the frame thread's time it
    /// expects the work to take, at least one item. Every renderer records into the same
    /// encoder ([`Scene::finish_uploads`]; a frame's own, so the work is submitted with the
    /// frame; then [`Self::after_deferred_submit`]). Returns the GPU time it expects the recorded work to
    /// take, less what upload hooks already charged the budget (`NodeWork::gpu_estimate_s`) for
    /// work whose frame-thread time was measured here: the caller counts this call's wall time
    /// apart. A frame calls it before any renderer's `prepare`, its work recorded before the
    /// frame's pass, so everything the pass samples is drawn before it.
    fn finish_uploads(
        &mut self,
        _gpu: &Gpu,
        _deferred: &mut UploadEncoder<'_>,
        _time_left_s: f64,
    ) -> f64 {
        0.0
    }

    /// After the submission of what `finish_uploads` recorded (e.g. to read back its
    /// timestamps). Default: nothing.
    fn after_deferred_submit(&mut self) {}

    /// Before the pass: choose this frame's draws, set their node-table entries and upload the
    /// frame's batches.
    fn prepare(&mut self, gpu: &Gpu, frame: &mut FrameResources, draws: &FrameDraws<'_>);

    /// Inside the frame's pass (group 0 bound): record the draws chosen by `prepare`.
    fn draw(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        frame: &FrameResources,
        draws: &FrameDraws<'_>,
        stats: &mut DrawStats,
    );
}

/// Where the frame thread's time went in [`Scene::finish_uploads`] and [`Scene::render`] (wall
/// clock, ms), per renderer by name in drawing order: the work deferred to the frame
/// (`finish_uploads`: node ground textures, impostor bakes; benchmarks that submit it apart add
/// the submission), `prepare`; and recording the pass.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct RenderTimes {
    pub deferred_ms: Vec<(&'static str, f64)>,
    pub prepare_ms: Vec<(&'static str, f64)>,
    pub record_ms: f64,
}

impl RenderTimes {
    /// The per-renderer phases, named: the deferred GPU work, then prepare.
    pub fn phases(&self) -> [(&'static str, &[(&'static str, f64)]); 2] {
        [
            ("deferred GPU work (finish_uploads)", &self.deferred_ms),
            ("prepare", &self.prepare_ms),
        ]
    }
}

/// The frame resources and the renderers, in drawing order.
pub struct Scene {
    pub frame: FrameResources,
    renderers: Vec<Box<dyn NodeRenderer>>,
    /// The last [`Self::render`]'s times.
    pub last_times: RenderTimes,
}

impl std::fmt::Debug for Scene {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let names: Vec<&str> = self.renderers.iter().map(|r| r.name()).collect();
        write!(f, "Scene({names:?})")
    }
}

impl Scene {
    /// A scene drawing into `color_format`, with no renderers yet.
    pub fn new(gpu: &Gpu, color_format: wgpu::TextureFormat) -> Self {
        Self {
            frame: FrameResources::new(&gpu.device, color_format),
            renderers: Vec::new(),
            last_times: RenderTimes::default(),
        }
    }

    /// Appends a renderer (drawn after the ones before it).
    pub fn push(&mut self, renderer: Box<dyn NodeRenderer>) {
        self.renderers.push(renderer);
    }

    /// The renderer of type `T`, if the scene has one (statistics and tests).
    pub fn renderer<T: NodeRenderer>(&self) -> Option<&T> {
        self.renderers
            .iter()
            .find_map(|r| (r.as_ref() as &dyn std::any::Any).downcast_ref::<T>())
    }

    /// The renderer of type `T`, mutable, if the scene has one.
    pub fn renderer_mut<T: NodeRenderer>(&mut self) -> Option<&mut T> {
        self.renderers
            .iter_mut()
            .find_map(|r| (r.as_mut() as &mut dyn std::any::Any).downcast_mut::<T>())
    }

    /// Closes the staging memory the frame's upload hooks wrote (every renderer's
    /// [`NodeRenderer::close_uploads`]), then records every renderer's deferred work into
    /// `deferred` within `time_left_s` of the frame's budget; returns the time left: less the
    /// GPU time the work is expected to take and the frame-thread time it took. The caller
    /// submits `deferred` (a frame records into its own encoder, which holds the uploads'
    /// copies too, before the frame's pass) and then calls [`Self::after_deferred_submit`].
    pub fn finish_uploads(
        &mut self,
        gpu: &Gpu,
        deferred: &mut UploadEncoder<'_>,
        mut time_left_s: f64,
    ) -> f64 {
        self.close_uploads();
        self.last_times.deferred_ms.clear();
        for r in &mut self.renderers {
            let t = Instant::now();
            time_left_s -= r.finish_uploads(gpu, deferred, time_left_s);
            let took_s = t.elapsed().as_secs_f64();
            time_left_s -= took_s;
            self.last_times.deferred_ms.push((r.name(), took_s * 1e3));
        }
        time_left_s
    }

    /// Every renderer's [`NodeRenderer::after_deferred_submit`]: call once the encoder given
    /// to [`Self::finish_uploads`] was submitted.
    pub fn after_deferred_submit(&mut self) {
        for r in &mut self.renderers {
            r.after_deferred_submit();
        }
    }

    /// The GPU phase of a node: every renderer's upload hook, their copies recorded into
    /// `copies`. Returns the bytes uploaded. [`Self::finish_uploads`] follows a frame's GPU
    /// phases (it closes their staging memory), before `copies` is submitted.
    pub fn upload_into(
        &mut self,
        gpu: &Gpu,
        tree: &QuadTree,
        work: &mut NodeWork,
        copies: &mut UploadEncoder<'_>,
    ) -> usize {
        let frame = &self.frame;
        self.renderers
            .iter_mut()
            .map(|r| r.upload(gpu, frame, tree, work, copies))
            .sum()
    }

    /// [`Self::upload_into`] one node on its own, its copies submitted at once.
    pub fn upload(&mut self, gpu: &Gpu, tree: &QuadTree, work: &mut NodeWork) -> usize {
        let mut copies = UploadEncoder::Own(None);
        let bytes = self.upload_into(gpu, tree, work, &mut copies);
        self.close_uploads();
        copies.finish(&gpu.queue);
        bytes
    }

    /// Every renderer's [`NodeRenderer::close_uploads`].
    fn close_uploads(&mut self) {
        for r in &mut self.renderers {
            r.close_uploads();
        }
    }

    /// Records the frame into `encoder`: one pass cleared to the view's colour and far depth,
    /// every renderer in order. The frame's uploads and deferred work
    /// ([`Self::finish_uploads`]) are recorded first.
    pub fn render(
        &mut self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        draws: &FrameDraws<'_>,
    ) -> DrawStats {
        self.frame.begin(&gpu.queue, draws.camera, draws.view);
        self.last_times.prepare_ms.clear();
        for r in &mut self.renderers {
            let t = Instant::now();
            r.prepare(gpu, &mut self.frame, draws);
            self.last_times.prepare_ms.push((r.name(), ms_since(t)));
        }
        let t_record = Instant::now();
        let [r, g, b, a] = draws.view.clear;
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("frame pass"),
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
        pass.set_bind_group(0, &self.frame.group, &[]);
        let mut stats = DrawStats::default();
        for r in &self.renderers {
            r.draw(&mut pass, &self.frame, draws, &mut stats);
        }
        drop(pass);
        self.last_times.record_ms = ms_since(t_record);
        stats
    }
}

/// Milliseconds since `t`.
fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}
