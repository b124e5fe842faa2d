//! Section `gpu` (when an adapter exists): the automatic flight rendered offscreen through the
//! viewer, the frame pass timed with timestamp queries next to a same-run reference (the
//! frame's terrain triangles as one indexed draw with a flat shader), and again with the
//! terrain's own draws given a flat fragment shader, which splits the ratio into geometry
//! (draws, skirts, cross-fade dithers) and shading. Absolute times only mean something per
//! adapter, so the rows name it and the ratio is the figure to compare.

use crate::open_world;
use crate::report::{Report, bar};
use anyhow::Result;
use engine::render::{COLOR_FORMAT, Gpu, Target};
use engine::stream::StreamSettings;
use engine::viewer::{FrameStats, Viewer};

/// The adapter's name, or None when there is none (the section is then left out).
pub(crate) fn adapter() -> Option<(Gpu, String)> {
    let gpu = Gpu::new_headless().ok()?;
    let name = gpu.adapter_name();
    Some((gpu, name))
}

pub(crate) fn section_gpu(
    gpu: &Gpu,
    adapter: &str,
    world_path: &std::path::Path,
    r: &mut Report,
    quick: bool,
) -> Result<()> {
    let heights: &[u32] = if quick { &[360] } else { &[720, 1440] };
    let frames = if quick { 6 } else { 24 };
    for &h in heights {
        let size = [h * 16 / 9, h];
        // Everything (draw counts); vegetation without houses and the terrain alone (the two
        // ratios: the reference draws terrain and plants, not houses); the terrain alone with a
        // flat fragment shader (the ratio's geometry part: same draws, skirts and dithers, no
        // shading).
        let runs = [
            (true, true, false, "vegetation and houses on"),
            (true, false, false, "vegetation on, houses off"),
            (false, false, false, "vegetation and houses off"),
            (
                false,
                false,
                true,
                "vegetation and houses off, terrain with a flat fragment shader",
            ),
        ];
        for (plants, objects, flat, what) in runs {
            let setup = |v: &mut Viewer| {
                v.view.plants = plants;
                v.view.objects = objects;
                v.view.flat_terrain = flat;
                if !objects {
                    v.enable_gpu_reference(gpu, size);
                }
            };
            let stats = fly(gpu, world_path, size, frames, setup, |_, _| Ok(()))?;
            let median = |f: &dyn Fn(&FrameStats) -> Option<f64>| {
                let mut v: Vec<f64> = stats.iter().filter_map(f).collect();
                v.sort_by(f64::total_cmp);
                (!v.is_empty()).then(|| apps::percentile(&v, 0.5))
            };
            let params = format!(
                "{}x{}, tau 2 px, {what}, {frames} frames of the automatic flight, {adapter}",
                size[0], size[1],
            );
            let times = [
                (
                    "frame pass (timestamp queries), median",
                    median(&|s| s.gpu_terrain_ms),
                    "ms",
                ),
                (
                    if plants {
                        "reference: one terrain draw + instanced plant draws, median"
                    } else {
                        "one-draw terrain reference, median"
                    },
                    median(&|s| s.gpu_reference_ms),
                    "ms",
                ),
            ];
            let counts = [
                (
                    "draw calls per frame (terrain + vegetation), median",
                    median(&|s| Some(f64::from(s.draw_calls + s.plant_draw_calls))),
                    "draws",
                ),
                (
                    "draw calls per frame (houses and merged far meshes), median",
                    median(&|s| Some(f64::from(s.object_draw_calls))),
                    "draws",
                ),
                (
                    "draw calls per frame (terrain + vegetation + houses), median",
                    median(&|s| {
                        Some(f64::from(
                            s.draw_calls + s.plant_draw_calls + s.object_draw_calls,
                        ))
                    }),
                    "draws",
                ),
                (
                    "items per frame (node meshes + node instance groups), median",
                    median(&|s| Some(f64::from(s.items + s.plant_items))),
                    "items",
                ),
                (
                    "house items per frame (houses + merged far meshes), median",
                    median(&|s| Some(f64::from(s.object_items))),
                    "items",
                ),
                (
                    "terrain triangles per frame, median",
                    median(&|s| Some(s.triangles as f64)),
                    "triangles",
                ),
            ];
            // The flat run adds its times and ratio only (its draws are the shaded run's).
            let counts = if flat { &[][..] } else { &counts[..] };
            for &(what, value, unit) in times.iter().chain(counts) {
                if let Some(v) = value {
                    r.add("gpu", what, v, unit, &params);
                }
            }
            if !objects
                && let (Some(pass), Some(reference)) = (
                    median(&|s| s.gpu_terrain_ms),
                    median(&|s| s.gpu_reference_ms),
                )
            {
                r.add(
                    "gpu",
                    match (plants, flat) {
                        (true, _) => "frame pass / reference, terrain and vegetation",
                        (false, true) => {
                            "frame pass with flat terrain shading / one-draw reference"
                        }
                        (false, false) => "frame pass / one-draw reference",
                    },
                    pass / reference,
                    "ratio",
                    &params,
                );
            }
        }
    }
    Ok(())
}

/// Renders `frames` frames spread over the automatic flight through a viewer set up by `setup`,
/// each view streamed until settled first, calls `each` after each measured frame has been
/// drawn, and returns the measured frames' statistics.
pub(crate) fn fly(
    gpu: &Gpu,
    world_path: &std::path::Path,
    size: [u32; 2],
    frames: usize,
    setup: impl FnOnce(&mut Viewer),
    mut each: impl FnMut(&Viewer, &Target) -> Result<()>,
) -> Result<Vec<FrameStats>> {
    let world = open_world(world_path)?;
    let settings = StreamSettings {
        tau_px: 2.0,
        ..StreamSettings::default()
    };
    let mut viewer = Viewer::new(gpu, COLOR_FORMAT, world, settings);
    setup(&mut viewer);
    let target = Target::new(&gpu.device, size, COLOR_FORMAT);
    let dt = 1.0 / 30.0;
    let b = bar(frames as u64, &format!("gpu {}x{}", size[0], size[1]));
    let mut out = Vec::with_capacity(frames);
    // Each measured view is streamed until settled first, so the frame draws what the view
    // needs.
    for f in 0..frames {
        let t = (f as f64 + 0.5) / frames as f64;
        let cam = engine::flight::auto_flyover(&viewer.streamer.shared.world, t, size);
        let start = std::time::Instant::now();
        while !viewer.stream_only(gpu, &cam, 0.1) && start.elapsed().as_secs_f64() < 120.0 {
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        // Three frames of the same view: timestamp results arrive a frame late, so the last
        // frame's statistics hold a settled frame's times.
        let mut last = None;
        for _ in 0..3 {
            let st = viewer
                .render_offscreen(gpu, &target, &cam, dt)
                .map_err(|e| anyhow::anyhow!(e))?;
            last = Some(st);
        }
        each(&viewer, &target)?;
        out.extend(last);
        b.inc(1);
    }
    b.finish_and_clear();
    Ok(out)
}
