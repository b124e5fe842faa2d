//! Section `soak` (when an adapter exists): the viewer flies the automatic flight in laps for
//! `--soak-minutes` (30 by default), sampled every second (`engine::soak`). Rows: the largest
//! value of each sampled quantity and its growth (largest over the last third of the run minus
//! largest over the middle third; the first third is warm-up while caches fill), then the end
//! checks after settling on one view: jobs, cancellations and tiles left over, the cache against
//! its budget.

use crate::open_world;
use crate::report::{Report, bar};
use anyhow::{Result, bail};
use engine::soak::{SoakParams, SoakSample, run};
use engine::stream::StreamSettings;
use std::time::Duration;

const MIB: f64 = 1024.0 * 1024.0;

/// A sampled quantity: name, divisor, unit, and how to read it from a sample.
type Metric = (&'static str, f64, &'static str, fn(&SoakSample) -> f64);

pub(crate) fn section_soak(
    gpu: &engine::render::Gpu,
    adapter: &str,
    world_path: &std::path::Path,
    r: &mut Report,
    minutes: f64,
) -> Result<()> {
    let world = open_world(world_path)?;
    let params = SoakParams {
        duration: Duration::from_secs_f64(minutes * 60.0),
        lap_s: 120.0,
        size_px: [640, 360],
        settings: StreamSettings::default(),
    };
    let seconds = params.duration.as_secs();
    let b = bar(seconds, "soak (seconds)");
    let report = run(gpu, world, &params, |s| b.set_position(s.t_s as u64))
        .map_err(|e| anyhow::anyhow!("soak: {e}"))?;
    b.finish_and_clear();
    let Some(last) = report.samples.last() else {
        bail!("soak: no sample");
    };
    let p = format!(
        "{minutes} min of the automatic flight in laps of {} s, {}x{}, tau {} px, {} worker(s), \
         sampled every second, {adapter}",
        params.lap_s,
        params.size_px[0],
        params.size_px[1],
        params.settings.tau_px,
        params.settings.workers
    );
    r.add("soak", "frames rendered", last.frames as f64, "frames", &p);
    r.add(
        "soak",
        "frames per second, mean",
        last.frames as f64 / last.t_s.max(1e-9),
        "fps",
        &p,
    );
    let metrics: [Metric; 12] = [
        ("resident memory (RSS)", MIB, "MiB", |s| {
            s.rss_bytes.unwrap_or(0) as f64
        }),
        ("RSS in the main thread's malloc heap", MIB, "MiB", |s| {
            s.rss_main_heap_bytes.unwrap_or(0) as f64
        }),
        (
            "RSS in other anonymous memory (other threads' heaps, large blocks, driver)",
            MIB,
            "MiB",
            |s| s.rss_other_anonymous_bytes.unwrap_or(0) as f64,
        ),
        (
            "RSS in file-backed pages (code, mapped files)",
            MIB,
            "MiB",
            |s| s.rss_file_bytes.unwrap_or(0) as f64,
        ),
        ("GPU memory alive (buffers + textures)", MIB, "MiB", |s| {
            (s.gpu_buffer_bytes + s.gpu_texture_bytes) as f64
        }),
        ("GPU buffers alive", 1.0, "buffers", |s| {
            s.gpu_buffers as f64
        }),
        ("prepared-node cache", MIB, "MiB", |s| s.cache_bytes as f64),
        ("resident nodes", 1.0, "nodes", |s| s.resident_nodes as f64),
        ("texture cache resident", MIB, "MiB", |s| {
            s.texture_resident_bytes as f64
        }),
        (
            "jobs queued + running + waiting for the GPU",
            1.0,
            "jobs",
            |s| (s.jobs_queued + s.jobs_running + s.jobs_waiting_gpu) as f64,
        ),
        ("tiles held", 1.0, "tiles", |s| s.tiles_held as f64),
        ("job latencies kept", 1.0, "entries", |s| {
            s.latencies_kept as f64
        }),
    ];
    for (name, scale, unit, f) in metrics {
        r.add(
            "soak",
            &format!("{name}, largest"),
            report.max_between(0.0, 1.0, f) / scale,
            unit,
            &p,
        );
        r.add(
            "soak",
            &format!("{name}, growth (last third - middle third)"),
            report.growth(f) / scale,
            unit,
            &p,
        );
    }
    let e = &report.end;
    let end = format!("{p}; then settled on the flight's start view");
    r.add(
        "soak",
        "settled after the flight",
        f64::from(u8::from(e.settled)),
        "yes=1",
        &end,
    );
    r.add(
        "soak",
        "jobs left in flight",
        e.jobs_in_flight as f64,
        "jobs",
        &end,
    );
    r.add(
        "soak",
        "cancellations not acknowledged",
        e.cancels_outstanding as f64,
        "jobs",
        &end,
    );
    r.add(
        "soak",
        "tiles left held",
        e.tiles_held as f64,
        "tiles",
        &end,
    );
    r.add(
        "soak",
        "prepared-node cache / budget",
        e.cache_bytes as f64 / e.cache_budget_bytes.max(1) as f64,
        "ratio",
        &end,
    );
    r.add(
        "soak",
        "jobs requested",
        e.jobs_requested as f64,
        "jobs",
        &end,
    );
    r.add(
        "soak",
        "jobs cancelled",
        e.jobs_cancelled as f64,
        "jobs",
        &end,
    );
    Ok(())
}
