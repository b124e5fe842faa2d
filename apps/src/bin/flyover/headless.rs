//! Headless runs: offscreen frames along the automatic flyover (or a replayed path), PNG frames
//! every `--every` frames, a table of per-frame times and `stats.json`.

use crate::{Cli, make_viewer, scripted_camera};
use anyhow::{Context, Result};
use apps::{open_world, percentile};
use engine::flight::CameraPath;
use engine::render::{COLOR_FORMAT, Gpu, Target, write_png};
use engine::viewer::FrameStats;
use std::time::Instant;

pub(crate) fn run_headless(cli: &Cli) -> Result<()> {
    let load = Instant::now();
    let world = open_world(&cli.map, &worldgen::progress::Bars::new(false))
        .with_context(|| format!("opening map {}", cli.map.display()))?;
    let map_load_s = load.elapsed().as_secs_f64();
    let mut world_memory: Vec<(&str, usize)> = world.memory_bytes();
    // A baked map's paged max-pyramids: their cache and faults, reported at the end.
    // And its decal field read tile by tile (a clone shares the tiles and their cache).
    let paged = (
        world.page_cache.clone(),
        world.page_faults.clone(),
        world.decals.clone(),
    );
    let flight = Instant::now();
    let rss_mib_now = || worldgen::progress::rss_bytes().map(|b| b as f64 / f64::from(1 << 20));
    let after_load_rss_mib = rss_mib_now();
    let path = cli.path.as_deref().map(CameraPath::load).transpose()?;
    let gpu = Gpu::new_headless()?;
    print_setup(cli, &gpu);
    std::fs::create_dir_all(&cli.out).with_context(|| format!("creating {}", cli.out.display()))?;
    let target = Target::new(&gpu.device, cli.size, COLOR_FORMAT);
    let start = scripted_camera(cli, path.as_ref(), &world, 0.0, cli.size, cli.fov_deg);
    let after_gpu_rss_mib = rss_mib_now();
    let after_gpu_s = load.elapsed().as_secs_f64();
    let mut viewer = make_viewer(cli, &gpu, COLOR_FORMAT, world, &start)?;
    let after_viewer_rss_mib = rss_mib_now();
    let after_viewer_s = load.elapsed().as_secs_f64();
    // What the vegetation kind holds of the map's whole area.
    let vegetation = viewer
        .streamer
        .shared
        .kind::<engine::vegetation::content::VegetationContent>();
    if let Some(v) = vegetation {
        world_memory.push((
            "vegetation canopy (large trees' grid and occupancy bits, for lines of sight and \
             light; its density layers are the map's)",
            v.canopy.bytes(),
        ));
    }
    viewer.view.merged_draws = !cli.per_item_draws;
    viewer.view.flat_terrain = cli.flat_terrain;
    if cli.gpu_reference {
        // The reference draws terrain and plants, not houses.
        viewer.view.objects = false;
        if !viewer.enable_gpu_reference(&gpu, cli.size) {
            eprintln!("--gpu-reference: this adapter has no timestamp queries; no reference");
        }
    }
    if cli.warm_start {
        warm_start(cli, path.as_ref(), &gpu, &mut viewer)?;
    }
    // Seconds from the start of the open to the end of the first frame that drew terrain.
    let mut first_world_frame_s = None;
    if cli.wait_first_world {
        let t = wait_first_world(cli, path.as_ref(), &gpu, &target, &mut viewer, load)?;
        eprintln!("the first frame showing the world came {t:.2} s after the open began");
        first_world_frame_s = Some(t);
    }
    let bar = indicatif::ProgressBar::new(cli.frames);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} frames ({eta})")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    bar.set_message("rendering");
    let dt = 1.0 / cli.fps;
    let mut all: Vec<FrameStats> = Vec::new();
    let mut written = Vec::new();
    for f in 0..cli.frames {
        let t_s = f as f64 * dt;
        let world = &viewer.streamer.shared.world;
        let cam = scripted_camera(cli, path.as_ref(), world, t_s, cli.size, cli.fov_deg);
        // The flight is scripted: prefetch follows its path, not the camera's velocity.
        viewer.path_ahead = engine::stream::predict::along(t_s, |t| {
            scripted_camera(cli, path.as_ref(), world, t, cli.size, cli.fov_deg)
        });
        let mut st = viewer
            .render_offscreen(&gpu, &target, &cam, dt)
            .map_err(|e| anyhow::anyhow!(e))?;
        st.t_s = t_s;
        if first_world_frame_s.is_none() && st.drawn_nodes > 0 {
            first_world_frame_s = Some(load.elapsed().as_secs_f64());
        }
        if cli.every > 0 && (f % cli.every == 0 || f + 1 == cli.frames) {
            let png = cli.out.join(format!("frame_{f:05}.png"));
            write_png(&png, target.size, &target.read_rgba(&gpu)?)?;
            written.push(png);
        }
        all.push(st);
        bar.inc(1);
    }
    bar.finish_and_clear();
    println!(
        "flyover --headless: {} frames at {}x{} on {}\n",
        all.len(),
        cli.size[0],
        cli.size[1],
        gpu.adapter_name()
    );
    let summary = print_table(&all, &gpu.adapter_name());
    let peak_rss_mib = worldgen::progress::peak_rss_bytes().map(|b| b as f64 / f64::from(1 << 20));
    let rss_mib = rss_mib_now();
    let open = OpenReport {
        map_load_s,
        first_world_frame_s,
        after_gpu_s,
        after_viewer_s,
        rss_mib: [after_load_rss_mib, after_gpu_rss_mib, after_viewer_rss_mib],
    };
    open.print(&world_memory, rss_mib, peak_rss_mib);
    let mib = |b: usize| b as f64 / f64::from(1 << 20);
    let world_memory_mib: serde_json::Map<String, serde_json::Value> = world_memory
        .iter()
        .map(|(what, b)| ((*what).to_string(), serde_json::json!(mib(*b))))
        .collect();
    let world_bytes: usize = world_memory.iter().map(|(_, b)| b).sum();
    let resident = resident_breakdown(&gpu, &viewer, world_bytes);
    let secs = flight.elapsed().as_secs_f64();
    let (page_cache, page_faults, decals) = paged;
    let pages = page_cache.map(|c| page_report(&c, secs, &page_faults));
    let decal_tiles = decals.tile_stats().map(|s| decal_tile_report(&s, secs));
    let json = cli.out.join("stats.json");
    let doc = serde_json::json!({
        "world_memory_mib": world_memory_mib,
        "end_resident_mib": resident,
        "adapter": gpu.adapter_name(),
        "size": cli.size,
        "tau_px": cli.tau,
        "fov_deg": cli.fov_deg,
        "map_load_s": map_load_s,
        "first_world_frame_s": first_world_frame_s,
        "page_cache": pages,
        "decal_tiles": decal_tiles,
        "page_faults": page_faults.list(),
        "peak_rss_mib": peak_rss_mib,
        "end_rss_mib": rss_mib,
        "after_load_rss_mib": after_load_rss_mib,
        "after_gpu_rss_mib": after_gpu_rss_mib,
        "after_viewer_rss_mib": after_viewer_rss_mib,
        "after_gpu_s": after_gpu_s,
        "after_viewer_s": after_viewer_s,
        "summary": summary,
        "frames": all,
    });
    std::fs::write(&json, serde_json::to_string_pretty(&doc)?)
        .with_context(|| format!("writing {}", json.display()))?;
    println!(
        "\n{} PNG frames in {}, statistics in {}",
        written.len(),
        cli.out.display(),
        json.display()
    );
    Ok(())
}

/// How the map's open went: seconds from its start, and resident memory (MiB) after loading
/// the map, opening the GPU and making the viewer.
struct OpenReport {
    map_load_s: f64,
    first_world_frame_s: Option<f64>,
    after_gpu_s: f64,
    after_viewer_s: f64,
    rss_mib: [Option<f64>; 3],
}

impl OpenReport {
    /// Prints the open's times, the world's parts in memory and the resident memory at the
    /// end (`rss_mib`) and peak.
    fn print(&self, world_memory: &[(&str, usize)], rss_mib: Option<f64>, peak: Option<f64>) {
        let show = |m: Option<f64>| {
            m.map_or_else(|| "not reported".to_string(), |m| format!("{m:.0} MiB"))
        };
        println!(
            "\nmap opened in {:.2} s (load, validation, error grids); resident memory {} at the \
             end, {} at the peak",
            self.map_load_s,
            show(rss_mib),
            show(peak)
        );
        match self.first_world_frame_s {
            Some(t) => {
                println!("the first frame showing the world ended {t:.2} s after the open began");
            }
            None => println!("no frame of the run showed the world (terrain)"),
        }
        let mib = |b: usize| b as f64 / f64::from(1 << 20);
        let parts: Vec<String> = world_memory
            .iter()
            .map(|(what, b)| format!("{what} {:.0} MiB", mib(*b)))
            .collect();
        println!("world in memory: {}", parts.join(", "));
        let [load, gpu, viewer] = self.rss_mib.map(show);
        println!(
            "resident memory after loading the map {load}, after opening the GPU {gpu} ({:.2} s \
             after the open began), after making the viewer and its renderers {viewer} ({:.2} s)",
            self.after_gpu_s, self.after_viewer_s
        );
    }
}

/// Frames of the flight's first view, drawn until one shows terrain: the seconds from `open`
/// (the start of the map's open) to the end of that frame. An error after 60 s.
fn wait_first_world(
    cli: &Cli,
    path: Option<&CameraPath>,
    gpu: &Gpu,
    target: &Target,
    viewer: &mut engine::viewer::Viewer,
    open: Instant,
) -> Result<f64> {
    let world = &viewer.streamer.shared.world;
    let cam = scripted_camera(cli, path, world, 0.0, cli.size, cli.fov_deg);
    let waited = Instant::now();
    loop {
        let st = viewer
            .render_offscreen(gpu, target, &cam, 1.0 / cli.fps)
            .map_err(|e| anyhow::anyhow!(e))?;
        if st.drawn_nodes > 0 {
            return Ok(open.elapsed().as_secs_f64());
        }
        if waited.elapsed().as_secs_f64() > 60.0 {
            anyhow::bail!(
                "--wait-first-world: no frame showed the world within 60 s ({})",
                viewer.outstanding()
            );
        }
        std::thread::yield_now();
    }
}

/// The page cache of a baked map's max-pyramids over a run of `secs`: printed, and as JSON.
fn page_report(
    c: &worldgen::pages::PageCache,
    secs: f64,
    faults: &engine::surface::levels::PageFaults,
) -> serde_json::Value {
    let mib = |b: usize| b as f64 / f64::from(1 << 20);
    let s = c.stats();
    println!(
        "pages of the heights, ground types, max-pyramids and surface error grids: {} page-ins ({:.1} per second), {} hits, {} evictions, {:.0} MiB \
         resident at the peak of a {:.0} MiB budget, {} page faults",
        s.page_ins,
        s.page_ins as f64 / secs,
        s.hits,
        s.evictions,
        mib(s.peak_resident_bytes),
        mib(c.budget_bytes()),
        faults.list().len()
    );
    for fault in faults.list() {
        println!("page fault: {fault}");
    }
    serde_json::json!({
        "page_ins": s.page_ins,
        "page_ins_per_s": s.page_ins as f64 / secs,
        "hits": s.hits,
        "evictions": s.evictions,
        "peak_resident_mib": mib(s.peak_resident_bytes),
        "budget_mib": mib(c.budget_bytes()),
    })
}

/// The adapter, the draw path and the light the run uses (stderr).
fn print_setup(cli: &Cli, gpu: &Gpu) {
    eprintln!(
        "headless on {} ({} draws, ground textures filtered with anisotropy {}x), sun azimuth \
         {} deg, elevation {} deg{}{}",
        gpu.adapter_name(),
        if cli.per_item_draws {
            "per-item"
        } else if gpu.multi_draw {
            "merged, multi-draw indirect"
        } else {
            "merged batches as plain loops: no multi-draw indirect on this adapter"
        },
        gpu.anisotropy,
        cli.sun_azimuth_deg,
        cli.sun_elevation_deg,
        if cli.no_lighting {
            ", no light grids"
        } else {
            ""
        },
        if cli.flat_terrain {
            ", terrain with a flat fragment shader (diagnostic)"
        } else {
            ""
        }
    );
}

/// The decal tiles of a baked map read over a run of `secs`: printed, and as JSON.
fn decal_tile_report(s: &engine::surface::decal_bake::TileStats, secs: f64) -> serde_json::Value {
    let mib = |b: usize| b as f64 / f64::from(1 << 20);
    println!(
        "decal tiles: {} tile-ins ({:.1} per second), {} hits, {} evictions, {:.1} MiB resident \
         at the peak",
        s.tile_ins,
        s.tile_ins as f64 / secs,
        s.hits,
        s.evictions,
        mib(s.peak_resident_bytes)
    );
    serde_json::json!({
        "tile_ins": s.tile_ins,
        "tile_ins_per_s": s.tile_ins as f64 / secs,
        "hits": s.hits,
        "evictions": s.evictions,
        "peak_resident_mib": mib(s.peak_resident_bytes),
    })
}

/// Where the resident memory is at the end (Linux): by kind of mapping, and how much of it the
/// world, the GPU objects alive (on a CPU adapter, whose "GPU" memory is RAM), the
/// prepared-node cache (the CPU copies of the nodes' GPU data) and file-backed pages account
/// for. Printed; returned in MiB for `stats.json` (null where `/proc/self/smaps` is missing).
fn resident_breakdown(
    gpu: &Gpu,
    viewer: &engine::viewer::Viewer,
    world_bytes: usize,
) -> serde_json::Value {
    let Some(parts) = worldgen::progress::rss_parts() else {
        return serde_json::Value::Null;
    };
    let mib = |b: u64| b as f64 / f64::from(1 << 20);
    let counters = gpu.device.get_internal_counters();
    let gpu_alive = counters.hal.buffer_memory.read() + counters.hal.texture_memory.read();
    let cpu_adapter = engine::render::is_cpu_adapter(&gpu.adapter);
    let gpu_in_ram = if cpu_adapter {
        u64::try_from(gpu_alive).unwrap_or(0)
    } else {
        0
    };
    let cache = viewer.streamer.stats.resident_bytes as u64;
    let total = parts.main_heap_bytes + parts.other_anonymous_bytes + parts.file_bytes;
    let known = world_bytes as u64 + gpu_in_ram + cache + parts.file_bytes;
    let rest = total.saturating_sub(known);
    println!(
        "resident at the end by mapping: {:.0} MiB main-thread heap, {:.0} MiB other anonymous \
         memory (other threads' heaps, large blocks, the driver's), {:.0} MiB file-backed",
        mib(parts.main_heap_bytes),
        mib(parts.other_anonymous_bytes),
        mib(parts.file_bytes)
    );
    println!(
        "of the {:.0} MiB: world {:.0}, GPU buffers and textures alive {:.0}{}, prepared-node \
         cache {:.0}, file-backed {:.0}; not accounted for {:.0} MiB",
        mib(total),
        mib(world_bytes as u64),
        mib(gpu_in_ram),
        if cpu_adapter {
            " (a CPU adapter: in RAM)"
        } else {
            " (on the GPU, not counted)"
        },
        mib(cache),
        mib(parts.file_bytes),
        mib(rest)
    );
    serde_json::json!({
        "main_heap": mib(parts.main_heap_bytes),
        "other_anonymous": mib(parts.other_anonymous_bytes),
        "file_backed": mib(parts.file_bytes),
        "world": mib(world_bytes as u64),
        "gpu_alive_in_ram": mib(gpu_in_ram),
        "prepared_node_cache": mib(cache),
        "not_accounted_for": mib(rest),
    })
}

/// The encode's parts per renderer (in drawing order, named as in the first frame) that spent
/// time: the deferred GPU work, then prepare.
fn renderer_rows(all: &[FrameStats]) -> Vec<(String, Vec<f64>)> {
    let mut rows = Vec::new();
    let Some(first) = all.first() else {
        return rows;
    };
    for (p, (phase, names)) in first.render.phases().into_iter().enumerate() {
        for (k, &(name, _)) in names.iter().enumerate() {
            let v: Vec<f64> = all
                .iter()
                .filter_map(|s| s.render.phases()[p].1.get(k).map(|&(_, ms)| ms))
                .collect();
            if v.iter().any(|&ms| ms >= 0.01) {
                rows.push((format!("  of which {phase}: {name}"), v));
            }
        }
    }
    rows
}

/// The table's rows of the frame thread's parts (update, uploads, encode, finish, submit).
fn frame_part_rows(all: &[FrameStats]) -> Vec<(String, Vec<f64>)> {
    let col = |f: fn(&FrameStats) -> f64| all.iter().map(f).collect::<Vec<f64>>();
    let mut rows: Vec<(String, Vec<f64>)> = vec![
        (
            "streaming update (selection + bookkeeping)".into(),
            col(|s| s.update_ms),
        ),
        ("  of which selection".into(), col(|s| s.selection_ms)),
    ];
    for (i, name) in engine::stream::UpdateStages::NAMES.iter().enumerate() {
        let stage: Vec<f64> = all.iter().map(|s| s.update_stages_ms[i]).collect();
        rows.push((format!("  stage: {name}"), stage));
    }
    rows.extend([
        ("GPU uploads".into(), col(|s| s.upload_ms)),
        ("encode".into(), col(|s| s.encode_ms)),
        ("  of which the draw list".into(), col(|s| s.draw_list_ms)),
    ]);
    rows.extend(renderer_rows(all));
    rows.extend([
        (
            "  of which recording the pass".into(),
            col(|s| s.render.record_ms),
        ),
        (
            "finishing the frame's commands (wgpu encodes the pass there)".into(),
            col(|s| s.finish_ms),
        ),
        (
            "submitting them (on a software adapter: waits for earlier submissions to run)".into(),
            col(|s| s.submit_ms),
        ),
    ]);
    rows
}

/// Prints the per-frame table (median, p95, max of every row) and the GPU ratio; returns the
/// summary for `stats.json`.
fn print_table(all: &[FrameStats], adapter: &str) -> serde_json::Map<String, serde_json::Value> {
    let col = |f: fn(&FrameStats) -> f64| all.iter().map(f).collect::<Vec<f64>>();
    let mut rows = frame_part_rows(all);
    let more: [(&str, Vec<f64>); 28] = [
        (
            "pop debt: excess over tau of the worst visible drawn node, px (0: none over tau)",
            col(|s| s.pop_excess_px),
        ),
        ("GPU wait", col(|s| s.gpu_wait_ms)),
        (
            "GPU frame pass (timestamp queries, when supported)",
            all.iter().filter_map(|s| s.gpu_terrain_ms).collect(),
        ),
        (
            "GPU reference: terrain triangles in one draw, plants instanced (--gpu-reference)",
            all.iter().filter_map(|s| s.gpu_reference_ms).collect(),
        ),
        (
            "CPU frame (update + uploads + encode + finish)",
            col(|s| s.cpu_frame_ms),
        ),
        (
            "  on-CPU time of the frame thread, through the submission (time given to other threads left out)",
            all.iter().filter_map(|s| s.cpu_frame_on_cpu_ms).collect(),
        ),
        ("triangles", col(|s| s.triangles as f64)),
        (
            "terrain draw calls (a multi-draw counts once)",
            col(|s| f64::from(s.draw_calls)),
        ),
        ("terrain items (node meshes)", col(|s| f64::from(s.items))),
        (
            "vegetation instances (meshes + billboards)",
            col(|s| s.plant_instances as f64),
        ),
        (
            "  of which group billboards (cluster quads)",
            col(|s| s.group_billboards as f64),
        ),
        (
            "vegetation draw calls",
            col(|s| f64::from(s.plant_draw_calls)),
        ),
        (
            "vegetation items (node instance groups)",
            col(|s| f64::from(s.plant_items)),
        ),
        (
            "vegetation mesh triangles",
            col(|s| s.plant_triangles as f64),
        ),
        (
            "objects drawn (progressive meshes)",
            col(|s| f64::from(s.object_items)),
        ),
        ("object draw calls", col(|s| f64::from(s.object_draw_calls))),
        (
            "draw calls in total (terrain + vegetation + objects)",
            col(|s| f64::from(s.draw_calls + s.plant_draw_calls + s.object_draw_calls)),
        ),
        (
            "of those: merged far meshes of a node's houses (HLOD)",
            col(|s| f64::from(s.object_hlod_draws)),
        ),
        (
            "object triangles, % of full detail",
            col(|s| 100.0 * s.object_triangles as f64 / s.object_full_triangles.max(1) as f64),
        ),
        (
            "texture cache resident MiB",
            col(|s| s.texture_resident_bytes as f64 / f64::from(1 << 20)),
        ),
        (
            "texture MiB if every drawn texture were full resolution",
            col(|s| s.texture_full_bytes as f64 / f64::from(1 << 20)),
        ),
        (
            "texture cache misses (drawn in the mean colour)",
            col(|s| f64::from(s.texture_misses)),
        ),
        (
            "textures resident coarser than needed",
            col(|s| f64::from(s.texture_coarser)),
        ),
        (
            "drawn nodes shaded by an ancestor's coarser light grid (their own not made yet)",
            col(|s| s.coarse_lit_nodes as f64),
        ),
        (
            "drawn nodes without their light grid or an ancestor's (drawn fully lit)",
            col(|s| s.unlit_nodes as f64),
        ),
        (
            "drawn nodes showing an ancestor's ground texture (their own not made yet)",
            col(|s| s.borrowed_textures as f64),
        ),
        (
            "ground-texture layers in use (one per node with its own texture)",
            col(|s| s.ground_layers_in_use as f64),
        ),
        (
            "ground-texture pool MiB (pages made so far)",
            col(|s| s.ground_pool_bytes as f64 / f64::from(1 << 20)),
        ),
    ];
    rows.extend(more.into_iter().map(|(n, v)| (n.to_string(), v)));
    println!("| per frame | median | p95 | max |\n|---|---:|---:|---:|");
    let mut summary = serde_json::Map::new();
    for (name, mut v) in rows {
        v.sort_by(f64::total_cmp);
        let (m, p, max) = (
            percentile(&v, 0.5),
            percentile(&v, 0.95),
            percentile(&v, 1.0),
        );
        println!("| {name} | {m:.2} | {p:.2} | {max:.2} |");
        summary.insert(
            name.clone(),
            serde_json::json!({"median": m, "p95": p, "max": max}),
        );
    }
    let over = all.iter().filter(|s| s.pop_excess_px > 0.0).count();
    let pop_debt_percent = 100.0 * over as f64 / all.len().max(1) as f64;
    println!(
        "\npop debt: {pop_debt_percent:.1} % of frames show a drawn node over tau ({over} of {})",
        all.len()
    );
    summary.insert(
        "pop_debt_percent".to_string(),
        serde_json::json!(pop_debt_percent),
    );
    // Per frame (both timers report the same earlier frame), over frames that have both.
    let mut ratios: Vec<f64> = all
        .iter()
        .filter_map(FrameStats::pass_over_reference)
        .collect();
    ratios.sort_by(f64::total_cmp);
    let ratio = (!ratios.is_empty()).then(|| percentile(&ratios, 0.5));
    if let Some(r) = ratio {
        println!(
            "\nGPU frame pass / one-draw reference (median of per-frame ratios, same run, \
             {adapter}): {r:.2}"
        );
    }
    summary.insert(
        "gpu_pass_over_reference".to_string(),
        serde_json::json!(ratio),
    );
    summary
}

/// `--warm-start`: streams the first camera's view until it is ready and its light grids are
/// computed (as after loading), before the first frame.
fn warm_start(
    cli: &Cli,
    path: Option<&CameraPath>,
    gpu: &Gpu,
    viewer: &mut engine::viewer::Viewer,
) -> Result<()> {
    let cam = scripted_camera(
        cli,
        path,
        &viewer.streamer.shared.world,
        0.0,
        cli.size,
        cli.fov_deg,
    );
    let start = Instant::now();
    while !viewer.stream_only(gpu, &cam, 1.0 / 60.0) {
        if start.elapsed().as_secs_f64() > 600.0 {
            anyhow::bail!(
                "--warm-start: the first view did not stream within 600 s ({})",
                viewer.outstanding()
            );
        }
        std::thread::yield_now();
    }
    if let Some(l) = viewer.lighting() {
        l.wait_idle();
    }
    eprintln!(
        "warm start: the first view streamed and lit in {:.1} s",
        start.elapsed().as_secs_f64()
    );
    Ok(())
}
