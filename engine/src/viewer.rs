//! The frame loop shared by the windowed and headless viewer and the GPU tests: streaming
//! update, GPU phases (uploads through the registered node renderers), draw list, rendering.

use crate::camera::Camera;
use crate::kinds::Registration;
use crate::lighting::Sun;
use crate::lighting::content::LightingContent;
use crate::render::frame::{DrawStats, ViewOptions};
use crate::render::lighting::LightingRenderer;
use crate::render::reference::{FrameContent, GpuReference};
use crate::render::scene::{DrawnNode, FrameDraws, RenderTimes, Scene, UploadEncoder};
use crate::render::sky::{BoundsLines, SkyRenderer};
use crate::render::terrain::TerrainRenderer;
use crate::render::vegetation::VegetationRenderer;
use crate::render::{Gpu, GpuTimer};
use crate::stream::{StreamSettings, Streamer};
use crate::surface::World;
use crate::terrain::quadtree::{NodeKey, unique_ancestors};
use glam::DVec3;
use std::sync::Arc;
use std::time::Instant;

/// The work a view still waits on before it is settled (all zero).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Outstanding {
    pub requests_in_flight: usize,
    /// Nodes the display wants that a coarser ancestor still stands in for.
    pub wanted_not_drawn: usize,
    /// Node ground textures queued and not made yet.
    pub textures_pending: usize,
}

impl Outstanding {
    pub fn is_settled(&self) -> bool {
        *self == Self::default()
    }
}

impl std::fmt::Display for Outstanding {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} requests in flight, {} wanted nodes not drawn, {} ground textures pending",
            self.requests_in_flight, self.wanted_not_drawn, self.textures_pending
        )
    }
}

/// Timings of one frame (ms) and what it drew.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct FrameStats {
    pub frame: u64,
    pub t_s: f64,
    /// Streaming update: selection, cancellation, requests, dispatch, fades.
    pub update_ms: f64,
    /// GPU phases (node buffer uploads) under their budget.
    pub upload_ms: f64,
    /// Building the draw list and recording the command buffer.
    pub encode_ms: f64,
    /// Of `encode_ms`: building the draw list (drawn nodes and their resident ancestors).
    pub draw_list_ms: f64,
    /// Of `encode_ms`: the scene's parts (deferred GPU work, each renderer's prepare,
    /// recording the pass).
    pub render: RenderTimes,
    /// Waiting for the GPU to finish the frame (headless; windowed, the present waits).
    pub gpu_wait_ms: f64,
    /// GPU time of the frame pass (sky, terrain, vegetation) from timestamp queries (a recent
    /// frame's), when supported.
    pub gpu_terrain_ms: Option<f64>,
    /// GPU time of the same-run reference (the frame's terrain triangles as one draw with a
    /// flat shader, see `render::reference`), when enabled and supported.
    pub gpu_reference_ms: Option<f64>,
    /// Triangles of that reference.
    pub reference_triangles: u64,
    /// Of `update_ms`: the selection of wanted nodes.
    pub selection_ms: f64,
    /// Of `update_ms`: its stages, in the order of `stream::UpdateStages::NAMES`.
    pub update_stages_ms: [f64; crate::stream::UpdateStages::NAMES.len()],
    /// Finishing the frame's command buffer ([`Viewer::submit_frame`]; wgpu encodes the
    /// recorded passes and copies there). Of `cpu_frame_ms`.
    pub finish_ms: f64,
    /// Submitting it, wall clock (wgpu also frees the commands of finished submissions there).
    /// Not in `cpu_frame_ms`: on a software adapter the submission waits for the work
    /// submitted before it. Its on-CPU time is in `cpu_frame_on_cpu_ms`.
    pub submit_ms: f64,
    /// Wall-clock time of update, uploads, encode and the frame's finish.
    pub cpu_frame_ms: f64,
    /// The frame thread's own CPU time from the frame's start through its submission (the
    /// time the OS gave other threads meanwhile left out), when the platform reports it.
    pub cpu_frame_on_cpu_ms: Option<f64>,
    /// Terrain draw calls recorded (a multi-draw counts once) and the node meshes they draw.
    pub draw_calls: u32,
    pub items: u32,
    pub triangles: u64,
    /// Vegetation instances drawn (meshes and billboards), draw calls recorded, the node
    /// instance groups they draw, mesh triangles.
    pub plant_instances: u64,
    pub plant_draw_calls: u32,
    pub plant_items: u32,
    pub plant_triangles: u64,
    /// Progressive-mesh objects: items drawn (instances and merged far meshes), their draw
    /// calls, triangles drawn and the triangles they would have at full detail.
    pub object_items: u32,
    pub object_draw_calls: u32,
    pub object_triangles: u64,
    pub object_full_triangles: u64,
    /// Objects drawn from an artist (`MSFT_lod`) chain level instead of the base mesh.
    pub object_chain_draws: u32,
    /// Of the object draws: merged far meshes of a node's houses (HLOD).
    pub object_hlod_draws: u32,
    /// The texture cache: resident bytes, bytes at full resolution of the drawn textures,
    /// misses (drawn textures with nothing resident), uploads and their bytes this frame.
    pub texture_resident_bytes: u64,
    pub texture_full_bytes: u64,
    pub texture_misses: u32,
    /// Drawn textures resident coarser than they need (a texel may be over a pixel).
    pub texture_coarser: u32,
    pub texture_uploads: u32,
    pub texture_upload_bytes: u64,
    /// Of the vegetation instances: group-billboard quads (one per cluster of items).
    pub group_billboards: u64,
    pub drawn_nodes: usize,
    pub nodes_per_level: Vec<usize>,
    pub jobs_queued: usize,
    pub jobs_running: usize,
    pub jobs_waiting_gpu: usize,
    pub jobs_cancelled_total: u64,
    pub tiles_bytes: usize,
    pub node_buffers_bytes: usize,
    pub cache_bytes: usize,
    /// Nodes the display wants not yet shown (a coarser ancestor stands in for them).
    pub pop_debt_nodes: usize,
    /// The largest excess over tau of a visible drawn node's projected error, px: above 0 the
    /// frame has pop debt (see [`crate::stream::Streamer::drawn_excess_over_tau_px`]; the
    /// selection's camera, measured after the CPU frame's timing).
    pub pop_excess_px: f64,
    /// Drawn nodes whose light grid has not arrived yet and that no ancestor's grid shades
    /// (drawn fully lit); 0 without light grids.
    pub unlit_nodes: usize,
    /// Drawn nodes whose own light grid has not arrived yet, shaded by an ancestor's coarser
    /// grid.
    pub coarse_lit_nodes: usize,
    /// Drawn nodes whose own ground texture is not made yet, showing an ancestor's; and those
    /// showing none (legend colours). 0 without ground textures.
    pub borrowed_textures: usize,
    pub untextured_nodes: usize,
    /// Layers of the ground-texture pool leased (one per node with its own texture) and bytes
    /// of the pool's pages made so far; 0 without ground textures.
    pub ground_layers_in_use: usize,
    pub ground_pool_bytes: usize,
}

impl FrameStats {
    /// GPU frame pass over the same-run reference, when both timers reported (they report the
    /// same earlier frame).
    pub fn pass_over_reference(&self) -> Option<f64> {
        Some(self.gpu_terrain_ms? / self.gpu_reference_ms.filter(|&r| r > 0.0)?)
    }
}

/// Streaming + rendering for one world: what one frame of the viewer does.
pub struct Viewer {
    pub streamer: Streamer,
    pub scene: Scene,
    pub view: ViewOptions,
    /// Debug: when set, selection uses this camera while rendering follows the live one.
    pub frozen: Option<Camera>,
    /// The camera's path ahead when the owner knows it (an automatic or replayed flight):
    /// (seconds ahead, camera) as in [`crate::stream::Streamer::update_along`], see
    /// [`crate::stream::predict::along`]. The next [`Self::frame`] prefetches along it and
    /// empties it; when empty, the prefetch extrapolates the camera's velocity.
    pub path_ahead: Vec<(f64, Camera)>,
    timer: Option<GpuTimer>,
    reference: Option<GpuReference>,
    reference_size: [u32; 2],
    frame: u64,
    /// When the previous frame started (its interval sets this frame's GPU budget).
    last_frame_start: Option<Instant>,
}

/// Share of the time between frames the GPU phases may take when frames are slower than the
/// settings' budget assumes (a software adapter at a few frames per second): at 60 Hz it is
/// the settings' 4 ms; at 3 Hz, 83 ms, so streaming keeps up with the frames it gets.
const GPU_BUDGET_FRAME_SHARE: f64 = 0.25;

impl std::fmt::Debug for Viewer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Viewer(frame {})", self.frame)
    }
}

impl Viewer {
    /// Streams `world` with every registered content kind and draws it with their renderers
    /// (sky first, node-bounds lines last) into `color_format`.
    pub fn new(
        gpu: &Gpu,
        color_format: wgpu::TextureFormat,
        world: World,
        settings: StreamSettings,
    ) -> Self {
        let registered = crate::kinds::registered(&world);
        Self::with_kinds(gpu, color_format, world, settings, &registered)
    }

    /// [`Viewer::new`] with these kinds only (e.g. the registered ones less ground textures).
    pub fn with_kinds(
        gpu: &Gpu,
        color_format: wgpu::TextureFormat,
        world: World,
        settings: StreamSettings,
        registered: &[Registration],
    ) -> Self {
        Self::with_kinds_from(gpu, color_format, world, settings, registered, None)
    }

    /// [`Viewer::with_kinds`] that starts streaming the view of `first` (the camera of the
    /// first frame) before it makes the renderers: the workers prepare the first nodes while
    /// this thread compiles the renderers' pipelines and uploads the map's textures, instead
    /// of after (a few tenths of a second sooner to the first picture of a large map).
    pub fn with_kinds_from(
        gpu: &Gpu,
        color_format: wgpu::TextureFormat,
        world: World,
        settings: StreamSettings,
        registered: &[Registration],
        first: Option<&Camera>,
    ) -> Self {
        let kinds = registered.iter().map(|r| Arc::clone(&r.kind)).collect();
        let mut streamer = Streamer::new(world, settings, kinds);
        if let Some(cam) = first {
            streamer.update(cam, 0.0);
        }
        let mut scene = Scene::new(gpu, color_format);
        for factory in registered.iter().filter_map(|r| r.renderer) {
            scene.push(factory(gpu, &scene.frame, &streamer.shared));
        }
        // After the opaque node content: the sky shades only the pixels nothing covered.
        scene.push(Box::new(SkyRenderer::new(gpu, &scene.frame)));
        scene.push(Box::new(BoundsLines::new(gpu, &scene.frame)));
        Self {
            streamer,
            scene,
            view: ViewOptions::default(),
            frozen: None,
            path_ahead: Vec::new(),
            timer: GpuTimer::new(gpu),
            reference: None,
            reference_size: [1, 1],
            frame: 0,
            last_frame_start: None,
        }
    }

    /// Sets the sun: the frame's light direction now, and the light grids (if that kind is
    /// registered) relit in the background, nearest to `camera_m` first; grids made from now on
    /// use it too. Frames never wait for the relight.
    pub fn set_sun(&mut self, sun: Sun, camera_m: DVec3) {
        self.view.sun = sun;
        if let Some(lighting) = self.lighting() {
            lighting.set_camera(camera_m.truncate());
            lighting.set_sun(sun);
        }
    }

    /// The light-grid kind, if registered.
    pub fn lighting(&self) -> Option<&LightingContent> {
        self.streamer.shared.kind::<LightingContent>()
    }

    /// Runs the streaming update and GPU uploads, then records the frame into `encoder`.
    /// Returns the frame's statistics (GPU wait not included). The uploads' copies and the
    /// renderers' deferred work (ground textures, impostor bakes) are recorded into `encoder`
    /// too, before the frame's pass: submit it with [`Self::submit_frame`] (the nodes uploaded
    /// in this frame count as on the GPU from now on, and the renderers read back their
    /// timings).
    pub fn frame(
        &mut self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        cam: &Camera,
        dt_s: f64,
    ) -> FrameStats {
        let t0 = Instant::now();
        let on_cpu0 = cpu_time::ThreadTime::try_now().ok();
        let interval_s = self
            .last_frame_start
            .replace(t0)
            .map_or(0.0, |t| (t0 - t).as_secs_f64());
        let budget_s = self
            .streamer
            .settings
            .gpu_budget_s
            .max(GPU_BUDGET_FRAME_SHARE * interval_s);
        // The textures the last frame made, in the budget before this update evicts.
        self.charge_made_textures();
        let ahead = std::mem::take(&mut self.path_ahead);
        match self.frozen {
            // A frozen selection has no path ahead.
            Some(frozen) => self.streamer.update(&frozen, dt_s),
            None if !ahead.is_empty() => self.streamer.update_along(cam, dt_s, &ahead),
            None => self.streamer.update(cam, dt_s),
        }
        self.show_textures_of_display();
        let t1 = Instant::now();
        let (uploaded, expected_gpu_s) =
            self.upload(gpu, budget_s, &mut UploadEncoder::Frame(encoder));
        let t2 = Instant::now();
        // The deferred work goes into the frame's encoder, before the frame's pass: one
        // submission a frame.
        let upload_time_left_s = self.scene.finish_uploads(
            gpu,
            &mut UploadEncoder::Frame(encoder),
            budget_s - (t2 - t1).as_secs_f64() - expected_gpu_s,
        );
        let t_deferred = Instant::now();
        let (drawn, ancestors) = drawn_nodes(&self.streamer);
        let t_draw_list = Instant::now();
        if let Some(t) = self.timer.as_mut() {
            t.harvest(gpu);
        }
        let timed = self.timer.as_ref().is_some_and(|t| t.begin(encoder));
        let frustum = cam.frustum();
        let draws = FrameDraws {
            camera: cam,
            frustum: &frustum,
            view: &self.view,
            tree: self.streamer.tree(),
            drawn: &drawn,
            ancestors: &ancestors,
            dt_s,
            tau_px: self.streamer.settings.tau_px,
            upload_bytes_left: self
                .streamer
                .settings
                .gpu_budget_bytes
                .saturating_sub(uploaded),
            upload_time_left_s,
        };
        let stats: DrawStats = self.scene.render(gpu, encoder, color, depth, &draws);
        if timed && let Some(t) = &self.timer {
            t.end(encoder);
        }
        if let Some(r) = self.reference.as_mut() {
            record_reference(r, gpu, &self.scene, encoder, self.reference_size, &draws);
        }
        let mut per_level = vec![0usize; usize::from(self.streamer.tree().max_level) + 1];
        for d in &drawn {
            per_level[usize::from(d.key.level)] += 1;
        }
        let node_bytes: usize = drawn.iter().map(|d| d.work.uploaded_bytes).sum();
        let t3 = Instant::now();
        let on_cpu = on_cpu0.and_then(|t| t.try_elapsed().ok());
        let st = &self.streamer.stats;
        let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
        let wanted_missing = self.wanted_not_drawn();
        let pop_excess_px = self.streamer.drawn_excess_over_tau_px(
            self.frozen.as_ref().unwrap_or(cam),
            self.streamer.settings.tau_px,
        );
        let terrain = self.scene.renderer::<TerrainRenderer>();
        let ground_pool = terrain.map_or((0, 0), TerrainRenderer::ground_pool_use);
        self.frame += 1;
        FrameStats {
            frame: self.frame,
            t_s: 0.0,
            update_ms: ms(t0, t1),
            upload_ms: ms(t1, t2),
            encode_ms: ms(t2, t3),
            draw_list_ms: ms(t_deferred, t_draw_list),
            render: self.scene.last_times.clone(),
            gpu_wait_ms: 0.0,
            gpu_terrain_ms: self.timer.as_ref().and_then(|t| t.last_ms),
            gpu_reference_ms: self.reference.as_ref().and_then(GpuReference::last_ms),
            reference_triangles: self.reference.as_ref().map_or(0, |r| r.triangles),
            selection_ms: st.last_update.selections_s() * 1e3,
            update_stages_ms: st.last_update.seconds().map(|s| s * 1e3),
            finish_ms: 0.0,
            submit_ms: 0.0,
            cpu_frame_ms: ms(t0, t3),
            cpu_frame_on_cpu_ms: on_cpu.map(|d| d.as_secs_f64() * 1e3),
            draw_calls: stats.draw_calls,
            items: stats.items,
            triangles: stats.triangles,
            plant_instances: stats.plant_instances,
            plant_draw_calls: stats.plant_draw_calls,
            plant_items: stats.plant_items,
            plant_triangles: stats.plant_triangles,
            object_items: stats.object_items,
            object_draw_calls: stats.object_draw_calls,
            object_triangles: stats.object_triangles,
            object_full_triangles: stats.object_full_triangles,
            object_chain_draws: stats.object_chain_draws,
            object_hlod_draws: stats.object_hlod_draws,
            texture_resident_bytes: stats.texture_resident_bytes,
            texture_full_bytes: stats.texture_full_bytes,
            texture_misses: stats.texture_misses,
            texture_coarser: stats.texture_coarser,
            texture_uploads: stats.texture_uploads,
            texture_upload_bytes: stats.texture_upload_bytes,
            group_billboards: stats.group_billboards,
            drawn_nodes: drawn.len(),
            nodes_per_level: per_level,
            jobs_queued: st.queued,
            jobs_running: st.running,
            jobs_waiting_gpu: st.waiting_gpu,
            jobs_cancelled_total: st.cancelled_queued + st.cancelled_running + st.cancelled_gpu,
            tiles_bytes: self.streamer.shared.tiles.lock().map_or(0, |t| t.bytes()),
            node_buffers_bytes: node_bytes,
            cache_bytes: st.resident_bytes,
            pop_debt_nodes: wanted_missing,
            pop_excess_px,
            unlit_nodes: self
                .scene
                .renderer::<LightingRenderer>()
                .map_or(0, |r| r.unlit_drawn),
            coarse_lit_nodes: self
                .scene
                .renderer::<LightingRenderer>()
                .map_or(0, |r| r.coarse_lit_drawn),
            borrowed_textures: terrain.map_or(0, |t| t.borrowed_textures),
            untextured_nodes: terrain.map_or(0, |t| t.untextured),
            ground_layers_in_use: ground_pool.0,
            ground_pool_bytes: ground_pool.1,
        }
    }

    /// Draws one frame of `cam` into `target` (offscreen runs: headless flights, benchmarks,
    /// soaks, tests), submits it and waits for the GPU (`gpu_wait_ms`).
    pub fn render_offscreen(
        &mut self,
        gpu: &Gpu,
        target: &crate::render::Target,
        cam: &Camera,
        dt_s: f64,
    ) -> Result<FrameStats, String> {
        let mut enc = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("offscreen frame"),
            });
        let mut st = self.frame(
            gpu,
            &mut enc,
            &target.color_view,
            &target.depth_view,
            cam,
            dt_s,
        );
        self.submit_frame(gpu, [], enc, &mut st);
        let t0 = Instant::now();
        gpu.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| format!("waiting for the GPU: {e}"))?;
        st.gpu_wait_ms = t0.elapsed().as_secs_f64() * 1e3;
        Ok(st)
    }

    /// Finishes `enc` (the encoder given to [`Self::frame`]) and submits it after `before`
    /// (command buffers that must run first, e.g. a UI's uploads). The finish counts in `st`'s
    /// CPU frame (`finish_ms`, `cpu_frame_ms`); the submission in its on-CPU time only
    /// (`submit_ms` holds its wall-clock time: a software adapter makes it wait for the work
    /// submitted before, GPU time on a hardware one).
    pub fn submit_frame(
        &mut self,
        gpu: &Gpu,
        before: impl IntoIterator<Item = wgpu::CommandBuffer>,
        enc: wgpu::CommandEncoder,
        st: &mut FrameStats,
    ) {
        let t0 = Instant::now();
        let on_cpu0 = cpu_time::ThreadTime::try_now().ok();
        let commands = enc.finish();
        let t1 = Instant::now();
        gpu.queue.submit(before.into_iter().chain([commands]));
        self.after_submit();
        let on_cpu_ms = on_cpu0
            .and_then(|t| t.try_elapsed().ok())
            .map(|d| d.as_secs_f64() * 1e3);
        st.finish_ms = (t1 - t0).as_secs_f64() * 1e3;
        st.submit_ms = t1.elapsed().as_secs_f64() * 1e3;
        st.cpu_frame_ms += st.finish_ms;
        st.cpu_frame_on_cpu_ms = st.cpu_frame_on_cpu_ms.zip(on_cpu_ms).map(|(a, b)| a + b);
    }

    /// Called by [`Self::submit_frame`] after the submission (starts the timestamp readbacks).
    fn after_submit(&mut self) {
        self.scene.after_deferred_submit();
        if let Some(t) = &self.timer {
            t.after_submit();
        }
        if let Some(r) = &self.reference {
            r.after_submit();
        }
    }

    /// From now on every frame also records the same-run GPU reference (see
    /// `render::reference`) at `size`; false when the adapter has no timestamp queries.
    pub fn enable_gpu_reference(&mut self, gpu: &Gpu, size: [u32; 2]) -> bool {
        self.reference = GpuReference::new(gpu, &self.scene.frame);
        self.reference_size = size;
        self.reference.is_some()
    }

    /// The same-run GPU reference, when enabled.
    pub fn gpu_reference(&self) -> Option<&GpuReference> {
        self.reference.as_ref()
    }

    /// Streaming without drawing: the update and GPU uploads of [`Self::frame`] (warm starts of
    /// benchmarks). True when no job is in flight and every wanted node is drawn.
    pub fn stream_only(&mut self, gpu: &Gpu, cam: &Camera, dt_s: f64) -> bool {
        self.streamer.update(cam, dt_s);
        self.upload_and_finish(gpu);
        self.outstanding().is_settled()
    }

    /// [`Self::stream_only`] along a known path (`future` as in
    /// [`crate::stream::Streamer::update_along`]): settled includes what the prefetch along it
    /// requested.
    pub fn stream_only_along(
        &mut self,
        gpu: &Gpu,
        cam: &Camera,
        dt_s: f64,
        future: &[(f64, Camera)],
    ) -> bool {
        self.streamer.update_along(cam, dt_s, future);
        self.upload_and_finish(gpu);
        self.outstanding().is_settled()
    }

    /// What a warm start still waits on (see [`Self::stream_only`]).
    pub fn outstanding(&self) -> Outstanding {
        Outstanding {
            requests_in_flight: self.streamer.in_flight(),
            wanted_not_drawn: self.wanted_not_drawn(),
            textures_pending: self.textures_pending(),
        }
    }

    /// The GPU phases under the frame's budget, then the renderers' deferred work (node
    /// textures, impostor bakes) in what they left of it, both in one submission, as a frame
    /// does them after the streamer's update (benchmarks call the two halves apart to time
    /// them apart).
    pub fn upload_and_finish(&mut self, gpu: &Gpu) {
        let budget_s = self.streamer.settings.gpu_budget_s;
        let t0 = Instant::now();
        let mut encoder = UploadEncoder::Own(None);
        let (_, expected_gpu_s) = self.upload(gpu, budget_s, &mut encoder);
        let left_s = budget_s - t0.elapsed().as_secs_f64() - expected_gpu_s;
        self.show_textures_of_display();
        self.scene.finish_uploads(gpu, &mut encoder, left_s);
        // One submission, as a frame's.
        let t = Instant::now();
        if encoder.finish(&gpu.queue) {
            self.scene.after_deferred_submit();
        }
        self.scene
            .last_times
            .deferred_ms
            .push(("their submission", t.elapsed().as_secs_f64() * 1e3));
        self.charge_made_textures();
    }

    /// Tells the terrain renderer whose ground textures to make: the nodes the display needs
    /// (needed for display, or drawn). A prefetched node's texture waits until then, so
    /// prefetch spends no texture time and no texture memory.
    fn show_textures_of_display(&mut self) {
        let Some(t) = self.scene.renderer_mut::<TerrainRenderer>() else {
            return;
        };
        t.show_textures_of(Some(self.streamer.display_nodes()));
    }

    /// Counts the ground textures made since the last call in their nodes' bytes in the cache
    /// budget (a node evicted meanwhile took its texture with it).
    fn charge_made_textures(&mut self) {
        let Some(t) = self.scene.renderer_mut::<TerrainRenderer>() else {
            return;
        };
        for key in t.take_made_textures() {
            self.streamer
                .charge(key, crate::ground::content::TEXTURE_BYTES);
        }
    }

    /// Node ground textures queued and not made yet (drawn nodes show an ancestor's meanwhile).
    pub fn textures_pending(&self) -> usize {
        self.scene
            .renderer::<TerrainRenderer>()
            .map_or(0, TerrainRenderer::textures_pending)
    }

    /// The streamer's GPU phases under `budget_s`, with every renderer's upload hook (their
    /// copies recorded into `copies`); returns the bytes they uploaded and the GPU time their
    /// recorded work is expected to take.
    fn upload(&mut self, gpu: &Gpu, budget_s: f64, copies: &mut UploadEncoder<'_>) -> (usize, f64) {
        let scene = &mut self.scene;
        let (mut bytes, mut expected_gpu_s) = (0, 0.0);
        self.streamer
            .run_gpu_phases_within(budget_s, &mut |shared, work| {
                let estimate_before_s = work.gpu_estimate_s;
                work.uploaded_bytes = scene.upload_into(gpu, &shared.tree, work, copies);
                bytes += work.uploaded_bytes;
                expected_gpu_s += work.gpu_estimate_s - estimate_before_s;
            });
        (bytes, expected_gpu_s)
    }

    /// Nodes the display wants that are not drawn yet (a coarser ancestor stands in for them):
    /// the pop debt count.
    fn wanted_not_drawn(&self) -> usize {
        let drawn: rustc_hash::FxHashSet<NodeKey> = self
            .streamer
            .draw_list()
            .iter()
            .filter(|d| self.streamer.is_ready(d.key))
            .map(|d| d.key)
            .collect();
        self.streamer
            .shown_wanted()
            .iter()
            .filter(|k| !drawn.contains(k))
            .count()
    }

    /// Keys of the nodes drawn last frame.
    pub fn drawn_keys(&self) -> Vec<NodeKey> {
        self.streamer.draw_list().iter().map(|d| d.key).collect()
    }
}

/// The frame's drawn nodes (the streamer's draw list, resident) and their resident ancestors,
/// which draw what they keep through splits (the draw list is walked down from the root
/// through them), sorted by key.
fn drawn_nodes(streamer: &Streamer) -> (Vec<DrawnNode<'_>>, Vec<DrawnNode<'_>>) {
    let drawn: Vec<DrawnNode<'_>> = streamer
        .draw_list()
        .iter()
        .filter_map(|d| {
            Some(DrawnNode {
                key: d.key,
                work: &streamer.resident(d.key)?.work,
                dither: [d.dither_lo, d.dither_hi],
                decimation: d.decimation,
            })
        })
        .collect();
    let ancestors = unique_ancestors(drawn.iter().map(|d| d.key))
        .iter()
        .filter_map(|&key| {
            Some(DrawnNode {
                key,
                work: &streamer.resident(key)?.work,
                dither: [0.0, 1.0],
                decimation: 0,
            })
        })
        .collect();
    (drawn, ancestors)
}

/// The GPU reference of a frame: the terrain meshes the terrain renderer draws (in the frustum,
/// with a non-empty dither interval, each with its decimation), as one draw, and the plant
/// instances the vegetation renderer draws.
fn record_reference(
    reference: &mut GpuReference,
    gpu: &Gpu,
    scene: &Scene,
    encoder: &mut wgpu::CommandEncoder,
    size: [u32; 2],
    draws: &FrameDraws<'_>,
) {
    let meshes: Vec<(&crate::terrain::mesh::NodeMesh, u8)> = draws
        .drawn
        .iter()
        .filter(|d| d.dither[1] > d.dither[0])
        .filter_map(|d| {
            Some((
                d.work.get::<crate::terrain::mesh::NodeMesh>()?,
                d.decimation,
            ))
        })
        .filter(|(m, _)| {
            let (lo, hi) = m.aabb_m(draws.tree);
            draws.frustum.intersects_aabb(lo, hi)
        })
        .collect();
    let content = FrameContent {
        camera: draws.camera,
        meshes: &meshes,
        plants: scene.renderer::<VegetationRenderer>(),
    };
    reference.record(gpu, &scene.frame, encoder, size, &content);
}
