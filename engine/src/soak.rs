//! Soak: the viewer flying the automatic flyover path in a loop for a given time, headless,
//! sampling once a second what could grow: resident memory of the process (and where it lives),
//! GPU memory alive
//! (wgpu's own counters of buffer and texture memory), job counts, the prepared-node cache, held
//! tiles, the texture cache and the streamer's latency log. At the end it settles on one view
//! and checks that no job, cancellation or tile is left over. Used by `nodebench --only soak`
//! and `flyover --headless --soak-minutes`.

use crate::camera::Camera;
use crate::render::{COLOR_FORMAT, Gpu, Target};
use crate::stream::StreamSettings;
use crate::surface::World;
use crate::viewer::Viewer;
use std::time::{Duration, Instant};

/// What a soak measures once a second.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct SoakSample {
    pub t_s: f64,
    pub frames: u64,
    /// Resident set of the process (Linux `VmRSS`), None elsewhere.
    pub rss_bytes: Option<u64>,
    /// The same split by kind of mapping (`worldgen::progress::RssParts`): the main thread's
    /// malloc heap, every other anonymous page, pages backed by files.
    pub rss_main_heap_bytes: Option<u64>,
    pub rss_other_anonymous_bytes: Option<u64>,
    pub rss_file_bytes: Option<u64>,
    /// GPU memory held by buffers and textures, and the buffers alive (wgpu's counters; its
    /// Vulkan backend counts destroyed textures but not created ones, so no texture count).
    pub gpu_buffer_bytes: i64,
    pub gpu_texture_bytes: i64,
    pub gpu_buffers: i64,
    pub jobs_queued: usize,
    pub jobs_running: usize,
    pub jobs_waiting_gpu: usize,
    /// Prepared nodes kept and their bytes (budget: `StreamSettings::cache_budget_bytes`).
    pub resident_nodes: usize,
    pub cache_bytes: usize,
    /// Tiles held by running jobs.
    pub tiles_held: usize,
    pub texture_resident_bytes: u64,
    /// Job latencies the streamer keeps for its readers.
    pub latencies_kept: usize,
}

/// After the flight: the viewer settled on the path's start view.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct SoakEnd {
    pub settled: bool,
    pub jobs_in_flight: usize,
    pub cancels_outstanding: u64,
    pub tiles_held: usize,
    pub cache_bytes: usize,
    pub cache_budget_bytes: usize,
    /// Jobs requested and cancelled over the whole soak.
    pub jobs_requested: u64,
    pub jobs_cancelled: u64,
}

/// A whole soak.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct SoakReport {
    pub samples: Vec<SoakSample>,
    pub end: SoakEnd,
}

/// How to soak.
#[derive(Debug, Clone)]
pub struct SoakParams {
    pub duration: Duration,
    /// One lap of the automatic flight takes this long (the camera loops).
    pub lap_s: f64,
    pub size_px: [u32; 2],
    pub settings: StreamSettings,
}

fn sample(viewer: &Viewer, gpu: &Gpu, t_s: f64, frames: u64, texture_bytes: u64) -> SoakSample {
    let counters = gpu.device.get_internal_counters();
    let st = &viewer.streamer.stats;
    let parts = worldgen::progress::rss_parts();
    SoakSample {
        t_s,
        frames,
        rss_bytes: worldgen::progress::rss_bytes(),
        rss_main_heap_bytes: parts.map(|p| p.main_heap_bytes),
        rss_other_anonymous_bytes: parts.map(|p| p.other_anonymous_bytes),
        rss_file_bytes: parts.map(|p| p.file_bytes),
        gpu_buffer_bytes: counters.hal.buffer_memory.read() as i64,
        gpu_texture_bytes: counters.hal.texture_memory.read() as i64,
        gpu_buffers: counters.hal.buffers.read() as i64,
        jobs_queued: st.queued,
        jobs_running: st.running,
        jobs_waiting_gpu: st.waiting_gpu,
        resident_nodes: st.resident,
        cache_bytes: st.resident_bytes,
        tiles_held: viewer.streamer.tiles_resident(),
        texture_resident_bytes: texture_bytes,
        latencies_kept: st.latencies.len(),
    }
}

/// Flies `world` for `p.duration`, calling `each` with every sample (progress), and returns the
/// samples and the end checks.
pub fn run(
    gpu: &Gpu,
    world: World,
    p: &SoakParams,
    mut each: impl FnMut(&SoakSample),
) -> Result<SoakReport, String> {
    let mut viewer = Viewer::new(gpu, COLOR_FORMAT, world, p.settings);
    let target = Target::new(&gpu.device, p.size_px, COLOR_FORMAT);
    let cam_at = |viewer: &Viewer, t: f64| -> Camera {
        crate::flight::auto_flyover(&viewer.streamer.shared.world, t, p.size_px)
    };
    let t0 = Instant::now();
    let mut last = t0;
    let mut next_sample_s = 0.0;
    let mut frames = 0u64;
    let mut texture_bytes = 0u64;
    let mut report = SoakReport::default();
    loop {
        let now = Instant::now();
        let t_s = (now - t0).as_secs_f64();
        if t_s >= next_sample_s {
            let s = sample(&viewer, gpu, t_s, frames, texture_bytes);
            each(&s);
            report.samples.push(s);
            next_sample_s += 1.0;
        }
        if t_s >= p.duration.as_secs_f64() {
            break;
        }
        let cam = cam_at(&viewer, (t_s / p.lap_s).fract());
        let dt = (now - last).as_secs_f64().max(1e-3);
        last = now;
        let st = viewer.render_offscreen(gpu, &target, &cam, dt)?;
        texture_bytes = st.texture_resident_bytes;
        frames += 1;
    }
    let start = cam_at(&viewer, 0.0);
    let settled = viewer.streamer.settle(&start, 300.0);
    let st = &viewer.streamer.stats;
    report.end = SoakEnd {
        settled,
        jobs_in_flight: viewer.streamer.in_flight(),
        cancels_outstanding: viewer.streamer.cancelled_outstanding(),
        tiles_held: viewer.streamer.tiles_resident(),
        cache_bytes: st.resident_bytes,
        cache_budget_bytes: viewer.streamer.settings.cache_budget_bytes,
        jobs_requested: st.requested,
        jobs_cancelled: st.cancelled_queued + st.cancelled_running + st.cancelled_gpu,
    };
    Ok(report)
}

impl SoakReport {
    /// Largest value of `f` over the samples whose time lies in `[from, to)` of the soak's
    /// length (fractions).
    pub fn max_between(&self, from: f64, to: f64, f: impl Fn(&SoakSample) -> f64) -> f64 {
        let end = self.samples.last().map_or(0.0, |s| s.t_s);
        self.samples
            .iter()
            .filter(|s| s.t_s >= from * end && s.t_s < to * end.max(1e-9) + 1e-9)
            .map(f)
            .fold(0.0, f64::max)
    }

    /// Growth of `f`: its maximum over the last third of the soak minus its maximum over the
    /// middle third (the first third is warm-up: caches filling).
    pub fn growth(&self, f: impl Fn(&SoakSample) -> f64 + Copy) -> f64 {
        self.max_between(2.0 / 3.0, 1.0, f) - self.max_between(1.0 / 3.0, 2.0 / 3.0, f)
    }
}
