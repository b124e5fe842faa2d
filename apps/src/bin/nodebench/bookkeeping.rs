//! Section `bookkeeping`: the streamer's per-frame update on settled views, with the workers
//! idle, so the rows show the update's own cost without the noise of a flight. Three rows per
//! flight: back to back (caches warm, a floor), after writing 32 MiB (the data caches cold),
//! and after sleeping a 60 Hz frame's gap (the frame thread idle, as in a flight: on a virtual
//! machine the core may run other guests meanwhile, and the same update costs about twice to
//! three times as much; the `streaming` section's bookkeeping rows are of that kind).

use crate::open_world;
use crate::report::{Report, bar};
use crate::span::Span;
use crate::streaming::{FLIGHTS, P50_P99, loop_camera};
use anyhow::{Result, bail};
use engine::lighting::content::LightingContent;
use engine::stream::{StreamSettings, Streamer};
use std::time::Instant;

/// Bytes written between updates for the cold-cache rows: more than this machine's caches
/// (L2 2 MiB per core, L3 32 MiB shared).
const SWEEP_BYTES: usize = 32 << 20;

/// The frame thread's sleep before the after-idle rows: a 60 Hz frame less the update.
const IDLE: std::time::Duration = std::time::Duration::from_millis(15);

/// Views per flight (evenly spaced in time over the first `VIEW_SPAN_S` seconds).
const VIEWS: usize = 4;
const VIEW_SPAN_S: f64 = 12.0;

pub(crate) fn section_bookkeeping(
    world_path: &std::path::Path,
    r: &mut Report,
    quick: bool,
    workers: usize,
    viewport_px: [u32; 2],
) -> Result<()> {
    let dt = 1.0 / 60.0;
    let frames = if quick { 21 } else { 360 };
    let tau = 2.0;
    let flights: Vec<(f64, f64)> = if quick {
        vec![FLIGHTS[2]]
    } else {
        FLIGHTS.to_vec()
    };
    for flight in flights {
        let (speed, above) = flight;
        let world = open_world(world_path)?;
        // Light grids off: settling would wait for hundreds of grids, and the update's cost
        // does not depend on them (their threads would be idle while measured anyway).
        let kinds = engine::kinds::registered(&world)
            .iter()
            .filter(|k| k.kind.name() != LightingContent::NAME)
            .map(|k| std::sync::Arc::clone(&k.kind))
            .collect();
        let settings = StreamSettings {
            tau_px: tau,
            ..StreamSettings::default()
        }
        .with_workers(workers);
        let mut s = Streamer::new(world, settings, kinds);
        let (mut wall, mut on_cpu, mut selection) = (Vec::new(), Vec::new(), Vec::new());
        let (mut cold, mut cold_selection) = (Vec::new(), Vec::new());
        let (mut idle, mut idle_selection) = (Vec::new(), Vec::new());
        // Written between updates to evict the caches, as a frame's uploads and drawing do.
        let mut sweep = vec![0u8; SWEEP_BYTES];
        let b = bar((VIEWS * frames) as u64, &format!("bookkeeping {speed} m/s"));
        for v in 0..VIEWS {
            let t_s = VIEW_SPAN_S * v as f64 / VIEWS as f64;
            let world = &s.shared.world;
            let cam = loop_camera(world, flight, t_s, viewport_px);
            // The path ahead as a flight predicts it, so every prefetch part is computed.
            let future =
                engine::stream::predict::along(t_s, |t| loop_camera(world, flight, t, viewport_px));
            // Settle with the path ahead prefetched too.
            let t0 = Instant::now();
            loop {
                s.update_along(&cam, dt, &future);
                s.run_gpu_phases();
                if s.in_flight() == 0 && s.needed().iter().all(|k| s.is_ready(k)) {
                    break;
                }
                if t0.elapsed().as_secs_f64() > 300.0 {
                    bail!("bookkeeping at {speed} m/s: view {v} did not settle within 300 s");
                }
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
            for f in 0..frames {
                // In turn: back to back, after a sweep of the caches, after an idle gap.
                let case = f % 3;
                if case == 1 {
                    for (i, v) in sweep.iter_mut().enumerate().step_by(64) {
                        *v = v.wrapping_add(i as u8);
                    }
                    std::hint::black_box(&mut sweep);
                } else if case == 2 {
                    std::thread::sleep(IDLE);
                }
                let t = Span::start();
                s.update_along(&cam, dt, &future);
                let span = t.stop();
                let selections_s = s.stats.last_update.selections_s();
                match case {
                    0 => {
                        wall.push(span.wall_s);
                        on_cpu.extend(span.on_cpu_s);
                        selection.push(selections_s);
                    }
                    1 => {
                        cold.push(span.wall_s);
                        cold_selection.push(selections_s);
                    }
                    _ => {
                        idle.push(span.wall_s);
                        idle_selection.push(selections_s);
                    }
                }
                b.inc(1);
            }
        }
        b.finish_and_clear();
        let params = format!(
            "{speed} m/s at {above} m: {VIEWS} settled views of the streaming flight, \
             {frames} updates each with its predicted path (one prefetch part computed again \
             per update; in turn back to back, after writing 32 MiB (the cold rows) and after \
             sleeping {idle_ms} ms (the idle rows)), tau {tau} px, light grids off, workers idle",
            idle_ms = IDLE.as_millis()
        );
        for (name, times) in [
            ("streaming update per frame, caches warm", wall),
            (
                "streaming update per frame, caches warm, on-CPU time",
                on_cpu,
            ),
            ("  of which the selections", selection),
            (
                "streaming update per frame, caches cold (after writing 32 MiB)",
                cold,
            ),
            ("  of which the selections", cold_selection),
            (
                "streaming update per frame, after the frame thread slept (idle)",
                idle,
            ),
            ("  of which the selections", idle_selection),
        ] {
            r.quantiles("bookkeeping", times, &P50_P99, &params, |q| {
                format!("{name} {q}")
            });
        }
    }
    Ok(())
}
