//! Section `textures` (when an adapter exists): the ground texture of every node of the
//! flight's sample rendered offscreen one at a time: the CPU time to gather its decal pieces
//! and to record its pass, its GPU time from timestamp queries (where the adapter has them),
//! bytes per node, and segments drawn per node. Node textures are not yet part of streaming (no
//! pool, not sampled by the terrain), so there are no streaming rows with textures on and off.

use crate::report::{Report, bar};
use engine::ground::decal_index::DecalIndex;
use engine::ground::layout::SIDE;
use engine::ground::pieces::node_decals;
use engine::render::ground::{GROUND_TEXTURE_FORMAT, GroundTexturer};
use engine::render::{Gpu, GpuTimer, Target};
use engine::surface::World;
use engine::terrain::quadtree::QuadTree;
use std::time::Instant;

pub(crate) fn section_textures(
    gpu: &Gpu,
    adapter: &str,
    world: &World,
    tree: &QuadTree,
    cams: &[engine::camera::Camera],
    r: &mut Report,
    quick: bool,
) {
    let keys = crate::terrain::flight_nodes(
        world,
        tree,
        &cams[..cams.len().min(if quick { 2 } else { 16 })],
        if quick { 24 } else { 240 },
    );
    let t_setup = Instant::now();
    let texturer = GroundTexturer::new(gpu, world);
    let index = DecalIndex::new(&world.map.decals, world.origin_m(), world.size_m());
    let setup_ms = t_setup.elapsed().as_secs_f64() * 1e3;
    let target = Target::new(&gpu.device, [SIDE, SIDE], GROUND_TEXTURE_FORMAT);
    let mut timer = GpuTimer::new(gpu);
    let (mut t_pieces, mut t_encode, mut t_gpu, mut segments) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let b = bar(keys.len() as u64, "ground textures");
    for &key in &keys {
        let t0 = Instant::now();
        let pieces = node_decals(&world.map.decals, &index, tree, key);
        let t1 = Instant::now();
        let mut enc = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        let timed = timer.as_ref().is_some_and(|t| t.begin(&mut enc));
        texturer.record(
            gpu,
            &mut enc,
            &target.color_view,
            tree,
            key,
            &pieces,
            &world.map.decals,
        );
        if timed && let Some(t) = &timer {
            t.end(&mut enc);
        }
        let cmd = enc.finish();
        let t2 = Instant::now();
        gpu.queue.submit([cmd]);
        if let Some(t) = timer.as_mut() {
            t.after_submit();
            let _ = gpu.device.poll(wgpu::PollType::wait_indefinitely());
            t.harvest(gpu);
            if let Some(ms) = t.last_ms.take() {
                t_gpu.push(ms * 1e-3);
            }
        }
        t_pieces.push((t1 - t0).as_secs_f64());
        t_encode.push((t2 - t1).as_secs_f64());
        segments.push(pieces.segments.len() as f64);
        b.inc(1);
    }
    b.finish_and_clear();
    let params = format!(
        "{} nodes from the flight at tau 2, {SIDE} x {SIDE} texels, {adapter}",
        keys.len()
    );
    r.add(
        "textures",
        "set-up: materials and ground layer uploaded, decal index",
        setup_ms,
        "ms",
        &params,
    );
    r.timings("textures", "node decal pieces (CPU)", t_pieces, &params);
    r.timings(
        "textures",
        "node texture pass recorded (CPU)",
        t_encode,
        &params,
    );
    if t_gpu.is_empty() {
        eprintln!("textures: the adapter has no timestamp queries, GPU time rows left out");
    } else {
        r.timings(
            "textures",
            "node texture pass (GPU, timestamp queries)",
            t_gpu,
            &params,
        );
    }
    r.add(
        "textures",
        "bytes per node texture",
        f64::from(SIDE * SIDE * 4),
        "bytes",
        &format!("{params}, RGBA8 sRGB, no mips yet: the layout's size, not a measurement"),
    );
    segments.sort_by(f64::total_cmp);
    for (name, q) in [("p50", 0.5), ("max", 1.0)] {
        r.add(
            "textures",
            &format!("road and path segments per node {name}"),
            apps::percentile(&segments, q),
            "segments",
            &params,
        );
    }
}
