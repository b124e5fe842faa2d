//! Section `textures` (when an adapter exists): the ground texture of every node of the
//! flight's sample rendered offscreen one at a time: the CPU time to gather its decal pieces
//! and resolve its texels' ground types, and to record its pass, its GPU time from timestamp queries (where the adapter has them),
//! bytes per node (the texture's, and the types' the node holds on the CPU), and segments drawn
//! per node; then the automatic flight through the viewer
//! with ground textures: texels per pixel on ground pixels (read back from the texel-density
//! view) and pool layers in use.

use crate::report::{Report, bar};
use engine::color::srgb_to_linear;
use engine::ground::content::NodeGround;
use engine::ground::content::TEXTURE_BYTES;
use engine::ground::decal_index::DecalIndex;
use engine::ground::layout::{MIP_LEVELS, SIDE};
use engine::render::frame::{GroundView, texels_per_pixel_of};
use engine::render::ground::GroundTexturer;
use engine::render::ground_pool::GroundPool;
use engine::render::terrain::TerrainNodeGpu;
use engine::render::{Gpu, GpuTimer};
use engine::surface::World;
use engine::terrain::quadtree::QuadTree;
use engine::viewer::Viewer;
use std::time::Instant;

pub(crate) fn section_textures(
    gpu: &Gpu,
    adapter: &str,
    world_path: &std::path::Path,
    world: &World,
    tree: &QuadTree,
    cams: &[engine::camera::Camera],
    r: &mut Report,
    quick: bool,
) -> anyhow::Result<()> {
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
    let mut pool = GroundPool::new(1, texturer.mip_layout());
    let Some(slot) = pool.lease(&gpu.device) else {
        anyhow::bail!("textures: the pool gave no layer");
    };
    let mut timer = GpuTimer::new(gpu);
    let (mut t_pieces, mut t_encode, mut t_submit, mut t_gpu, mut segments) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut type_bytes = Vec::new();
    let b = bar(keys.len() as u64, "ground textures");
    for &key in &keys {
        let t0 = Instant::now();
        let pieces = NodeGround::new(world, &index, tree, key);
        let t1 = Instant::now();
        let mut enc = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        let timed = timer.as_ref().is_some_and(|t| t.begin(&mut enc));
        texturer.record(
            gpu,
            &mut enc,
            &slot.view,
            tree,
            key,
            &pieces,
            &world.map.decals,
        );
        texturer.record_mips(&mut enc, std::slice::from_ref(&slot.mips));
        if timed && let Some(t) = &timer {
            t.end(&mut enc);
        }
        let t2 = Instant::now();
        texturer.submit(gpu, enc);
        let t3 = Instant::now();
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
        t_submit.push((t3 - t2).as_secs_f64());
        segments.push(pieces.decals.segments.len() as f64);
        type_bytes.push(pieces.types.bytes() as f64);
        b.inc(1);
    }
    b.finish_and_clear();
    let params = format!(
        "{} nodes from the flight at tau 2, {SIDE} x {SIDE} texels and {} smaller mip levels, {adapter}",
        keys.len(),
        MIP_LEVELS - 1,
    );
    r.add(
        "textures",
        "set-up: materials uploaded, decal index",
        setup_ms,
        "ms",
        &params,
    );
    r.timings(
        "textures",
        "node decal pieces and texel ground types (CPU)",
        t_pieces,
        &params,
    );
    r.timings(
        "textures",
        "node texture passes recorded (CPU)",
        t_encode,
        &params,
    );
    r.timings(
        "textures",
        "node data written and passes submitted (CPU)",
        t_submit,
        &params,
    );
    if t_gpu.is_empty() {
        eprintln!("textures: the adapter has no timestamp queries, GPU time rows left out");
    } else {
        r.timings(
            "textures",
            "node texture passes (GPU, timestamp queries)",
            t_gpu,
            &params,
        );
    }
    r.add(
        "textures",
        "bytes per node texture",
        TEXTURE_BYTES as f64,
        "bytes",
        &format!("{params}, RGBA8 sRGB: the layout's size, not a measurement"),
    );
    let types_params = format!("{params}; a plain list would hold {} bytes", SIDE * SIDE);
    for (what, mut values, unit, params) in [
        (
            "road and path segments per node",
            segments,
            "segments",
            &params,
        ),
        (
            "texel ground types held per node (runs of one type)",
            type_bytes,
            "bytes",
            &types_params,
        ),
    ] {
        values.sort_by(f64::total_cmp);
        for (name, q) in [("p50", 0.5), ("max", 1.0)] {
            let value = apps::percentile(&values, q);
            r.add("textures", &format!("{what} {name}"), value, unit, params);
        }
    }
    flight_texels(gpu, adapter, world_path, r, quick)
}

/// The automatic flight through the viewer with ground textures at 720p, tau 2, vegetation off
/// (its pixels would hide the ground), drawn in the texel-density view and read back: texels
/// per pixel on every textured ground pixel, and pool layers held by resident nodes.
fn flight_texels(
    gpu: &Gpu,
    adapter: &str,
    world_path: &std::path::Path,
    r: &mut Report,
    quick: bool,
) -> anyhow::Result<()> {
    let size = if quick { [640, 360] } else { [1280, 720] };
    let frames = if quick { 4 } else { 24 };
    let (mut density, mut layers, mut untextured) = (Vec::new(), Vec::new(), 0usize);
    let setup = |v: &mut Viewer| {
        v.view.plants = false;
        v.view.sky = false;
        v.view.ground_view = GroundView::TexelDensity;
    };
    crate::gpu::fly(gpu, world_path, size, frames, setup, |v, target| {
        let rgba = target.read_rgba(gpu)?;
        for p in rgba.chunks_exact(4) {
            let linear = [0, 1, 2].map(|k| srgb_to_linear(p[k]) as f32);
            match texels_per_pixel_of(linear) {
                Some(t) => density.push(f64::from(t)),
                // Grey: a ground pixel of a node without a texture.
                None if p[0] == p[1] && p[1] == p[2] && p[0] > 0 => untextured += 1,
                None => {}
            }
        }
        let s = &v.streamer;
        let held = s
            .resident_keys()
            .iter()
            .filter_map(|&k| s.resident(k))
            .filter(|res| {
                res.work
                    .gpu
                    .get::<TerrainNodeGpu>()
                    .is_some_and(|t| t.ground_slot().is_some())
            })
            .count();
        layers.push(held as f64);
        Ok(())
    })?;
    let params = format!(
        "{}x{}, tau 2 px, {frames} settled views of the automatic flight, vegetation off, {adapter}",
        size[0], size[1]
    );
    density.sort_by(f64::total_cmp);
    for (name, q) in [("p5", 0.05), ("p50", 0.5), ("p95", 0.95)] {
        r.add(
            "textures",
            &format!("ground-texture texels per pixel on ground pixels {name}"),
            apps::percentile(&density, q),
            "texels/px",
            &format!("{params}; the view encodes 1/16 to 16, clamped"),
        );
    }
    let fine = density.iter().filter(|&&t| t >= 1.0).count();
    r.add(
        "textures",
        "ground pixels whose texel is <= 1 px (texels per pixel >= 1)",
        100.0 * fine as f64 / density.len().max(1) as f64,
        "%",
        &format!("{params}; target >= 95 %"),
    );
    r.add(
        "textures",
        "ground pixels of nodes without a texture",
        100.0 * untextured as f64 / (density.len() + untextured).max(1) as f64,
        "%",
        &params,
    );
    layers.sort_by(f64::total_cmp);
    for (name, q) in [("p50", 0.5), ("max", 1.0)] {
        r.add(
            "textures",
            &format!("pool layers held by resident nodes {name}"),
            apps::percentile(&layers, q),
            "layers",
            &format!("{params}; {TEXTURE_BYTES} bytes each"),
        );
    }
    Ok(())
}
