//! Renderer tests on the Vulkan software adapter (lavapipe): shader validation, a golden image,
//! reversed-Z depth precision, and no leaked pixels (holes) from 50 cameras, during fades too.

use engine::camera::Camera;
use engine::render::frame::ViewOptions;
use engine::render::scene::{DrawnNode, FrameDraws, Scene, UploadEncoder};
use engine::render::terrain::TerrainRenderer;
use engine::render::{COLOR_FORMAT, Target};
use engine::stream::NodeWork;
use engine::terrain::bounds::NodeBounds;
use engine::terrain::mesh::NodeMesh;
use engine::terrain::quadtree::{NodeKey, QuadTree};
use glam::DVec3;
use tests::gpu::{device, frame, settle, tiny_viewer};
use tests::terrain::tiny_world;
use worldgen::noise::unit3;

/// Every renderer's assembled shader (generated constants + prelude + its file) parses and
/// validates, and every `.wgsl` file in `shaders/` is one of them (none escapes validation).
#[test]
fn every_assembled_shader_parses_and_validates_with_naga() {
    let sources = engine::render::shader_sources();
    for (name, src) in &sources {
        let module = naga::front::wgsl::parse_str(src)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(src)));
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::default(),
        )
        .validate(&module)
        .unwrap_or_else(|e| panic!("{name}: {e:?}"));
    }
    let dir = tests::workspace_root().join("shaders");
    let mut files = 0;
    for entry in std::fs::read_dir(&dir).expect("shaders/ exists") {
        let p = entry.expect("readable entry").path();
        let is_wgsl = p
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("wgsl"));
        // `prelude.inc.wgsl` is included, not assembled on its own.
        let stem = p.file_stem().and_then(|n| n.to_str()).unwrap_or_default();
        if !is_wgsl || std::path::Path::new(stem).extension().is_some() {
            continue;
        }
        assert!(
            sources.iter().any(|(n, _)| *n == stem),
            "{} is not assembled by any renderer",
            p.display()
        );
        files += 1;
    }
    assert_eq!(
        files,
        sources.len(),
        "renderer sources and shader files differ"
    );
}

fn golden_camera() -> Camera {
    let w = tiny_world();
    let p = DVec3::new(120.0, 90.0, w.height_m(120.0, 90.0) + 60.0);
    Camera::look_at(
        p,
        DVec3::new(300.0, 330.0, w.height_m(300.0, 330.0)),
        60f64.to_radians(),
        [160, 90],
    )
}

/// The golden camera's view at another viewport size.
fn golden_view(size: [u32; 2]) -> Camera {
    let cam = golden_camera();
    Camera::look_at(
        cam.position_m,
        cam.position_m + cam.forward,
        cam.fovy_rad,
        size,
    )
}

fn load_png(path: &std::path::Path) -> Option<(Vec<u8>, [u32; 2])> {
    let f = std::fs::File::open(path).ok()?;
    let mut r = png::Decoder::new(std::io::BufReader::new(f))
        .read_info()
        .ok()?;
    let mut buf = vec![0; r.output_buffer_size()?];
    let info = r.next_frame(&mut buf).ok()?;
    buf.truncate(info.buffer_size());
    Some((buf, [info.width, info.height]))
}

/// The tiny map from a fixed camera after streaming settles, against `tests/golden/tiny.png`.
/// Tolerance (software rasterizers differ in the last bits, drivers in rounding): mean absolute
/// channel difference <= 1.5 / 255 and at most 0.5% of pixels with any channel off by > 24.
/// `UPDATE_GOLDEN=1` rewrites the reference (refused in CI).
#[test]
fn golden_image_of_the_tiny_map() {
    let Some(g) = device() else { return };
    let cam = golden_camera();
    let target = Target::new(&g.device, cam.viewport_px, COLOR_FORMAT);
    let mut v = tiny_viewer(&g, 1.0);
    settle(&g, &mut v, &target, &cam);
    let got = target.read_rgba(&g).expect("readback");
    let path = tests::workspace_root().join("tests/golden/tiny.png");
    if std::env::var_os("UPDATE_GOLDEN").is_some() {
        // A reference rewritten by the run that checks it proves nothing.
        assert!(
            !tests::in_ci(),
            "UPDATE_GOLDEN is set in CI: refusing to rewrite the reference instead of checking it"
        );
        std::fs::create_dir_all(path.parent().expect("has a parent")).expect("mkdir");
        engine::render::write_png(&path, cam.viewport_px, &got).expect("write golden");
        println!("wrote {}", path.display());
        return;
    }
    let (want, size) =
        load_png(&path).unwrap_or_else(|| panic!("{} missing or unreadable", path.display()));
    assert_eq!(size, cam.viewport_px);
    let (mut sum, mut bad) = (0u64, 0usize);
    for (a, b) in got.chunks_exact(4).zip(want.chunks_exact(4)) {
        let d: Vec<u8> = (0..3).map(|i| a[i].abs_diff(b[i])).collect();
        sum += d.iter().map(|&x| u64::from(x)).sum::<u64>();
        if d.iter().any(|&x| x > 24) {
            bad += 1;
        }
    }
    let pixels = (size[0] * size[1]) as usize;
    let mean = sum as f64 / (pixels * 3) as f64;
    println!("golden: mean difference {mean:.3} / 255, {bad} pixels off by > 24");
    assert!(mean <= 1.5, "mean channel difference {mean} / 255");
    assert!(
        bad * 200 <= pixels,
        "{bad} of {pixels} pixels differ by more than 24"
    );
    // Not a blank picture: sky and terrain both present.
    let distinct: std::collections::HashSet<[u8; 3]> = got
        .chunks_exact(4)
        .map(|p| [p[0] / 8, p[1] / 8, p[2] / 8])
        .collect();
    assert!(
        distinct.len() > 50,
        "only {} distinct colours",
        distinct.len()
    );
}

/// A flat square node mesh `size_m` wide at height `z_m`, ground type `ground` everywhere.
fn quad(key: NodeKey, origin_m: [f64; 2], size_m: f32, z_m: f32, ground: u8) -> NodeMesh {
    NodeMesh {
        key,
        origin_m,
        positions: vec![
            [0.0, 0.0, z_m],
            [size_m, 0.0, z_m],
            [0.0, size_m, z_m],
            [size_m, size_m, z_m],
        ],
        shading: vec![engine::terrain::mesh::pack_shading([0.0, 0.0, 1.0], ground); 4],
        indices: vec![0, 1, 3, 0, 3, 2].into(),
        surface_index_count: 6,
        bounds: NodeBounds::exact(f64::from(z_m), f64::from(z_m)),
        skirt_bottom_m: [f64::from(z_m); 4],
        decimation: 0,
    }
}

/// The tiny map moved 10^7 m from the origin renders like the original from the same relative
/// camera (lavapipe): node geometry reaches the GPU camera-relative, so nothing shakes or
/// tears far out. Same tolerance as the golden image.
#[test]
fn a_world_ten_thousand_km_out_renders_like_the_original() {
    let Some(g) = device() else { return };
    let near_cam = golden_camera();
    let mut images = Vec::new();
    for offset in [0.0, 1.0e7] {
        let world = tests::terrain::shifted(&tiny_world(), offset, -offset);
        let mut cam = near_cam;
        cam.position_m += DVec3::new(offset, -offset, 0.0);
        let target = Target::new(&g.device, cam.viewport_px, COLOR_FORMAT);
        let mut v = tests::gpu::viewer(&g, world, 1.0);
        settle(&g, &mut v, &target, &cam);
        images.push(target.read_rgba(&g).expect("readback"));
    }
    let (mut sum, mut bad) = (0u64, 0usize);
    for (a, b) in images[0].chunks_exact(4).zip(images[1].chunks_exact(4)) {
        let d: Vec<u8> = (0..3).map(|i| a[i].abs_diff(b[i])).collect();
        sum += d.iter().map(|&x| u64::from(x)).sum::<u64>();
        bad += usize::from(d.iter().any(|&x| x > 24));
    }
    let n = images[0].len() / 4;
    let mean = sum as f64 / (3 * n) as f64;
    assert!(
        mean <= 1.5 && bad * 200 <= n,
        "far world differs: mean {mean:.2}/255, {bad} of {n} pixels off by > 24"
    );
}

/// Reversed-Z f32 depth with near = 0.1 m: two large quads 1 cm apart, 5 km below the camera,
/// resolve to the nearer one in every pixel even when the farther one is drawn last.
#[test]
fn depth_resolves_quads_one_centimetre_apart_at_five_kilometres() {
    let Some(g) = device() else { return };
    let size = [128u32, 128];
    // Red (legend 0) is 1 cm above blue (legend 1).
    let (tree, mut scene) = terrain_scene(&g, &[[255, 0, 0], [0, 0, 255]]);
    let key = NodeKey {
        level: 0,
        ix: 0,
        iy: 0,
    };
    let [near_quad, far_quad] = [(0.01, 0), (0.0, 1)].map(|(z_m, ground)| {
        let mut w = NodeWork::new(key);
        w.put(quad(key, [-3000.0, -3000.0], 6000.0, z_m, ground));
        scene.upload(&g, &tree, &mut w);
        w
    });
    // 5 km up, looking straight down (slightly tilted so look_at has an up vector).
    let p = DVec3::new(0.0, 0.0, 5000.0);
    let mut cam = Camera::look_at(p, DVec3::new(0.0, 1.0, 0.0), 40f64.to_radians(), size);
    cam.near_m = 0.1;
    let view = ViewOptions {
        sky: false,
        fog_per_m: 0.0,
        clear: [0.0, 1.0, 0.0, 1.0],
        ..ViewOptions::default()
    };
    let target = Target::new(&g.device, size, COLOR_FORMAT);
    let mut draw =
        |works: &[&NodeWork]| draw_nodes(&g, &mut scene, &tree, &cam, &view, &target, works);
    // Control: the far quad alone shows blue everywhere (the set-up sees it).
    let alone = draw(&[&far_quad]);
    assert!(
        alone.chunks_exact(4).all(|p| p[2] > p[0] && p[1] < 8),
        "far quad alone not blue"
    );
    for order in [[&near_quad, &far_quad], [&far_quad, &near_quad]] {
        let px = draw(&order);
        let wrong = px
            .chunks_exact(4)
            .filter(|p| !(p[0] > p[2] && p[1] < 8))
            .count();
        assert_eq!(
            wrong, 0,
            "{wrong} pixels show the farther quad (or nothing)"
        );
    }
}

/// A 4 km quad tree at the origin and a scene with only a terrain renderer whose legend
/// colours are `legend` (sRGB), for hand-made node meshes.
fn terrain_scene(g: &engine::render::Gpu, legend: &[[u8; 3]]) -> (QuadTree, Scene) {
    let mut scene = Scene::new(g, COLOR_FORMAT);
    let terrain = TerrainRenderer::new(g, &scene.frame, legend);
    scene.push(Box::new(terrain));
    (QuadTree::new([0.0, 0.0], [4096.0, 4096.0]), scene)
}

/// Draws `works` (nodes of `tree`, each at its own place, not fading) with `scene` from `cam`
/// into `target`; returns its pixels.
fn draw_nodes(
    g: &engine::render::Gpu,
    scene: &mut Scene,
    tree: &QuadTree,
    cam: &Camera,
    view: &ViewOptions,
    target: &Target,
    works: &[&NodeWork],
) -> Vec<u8> {
    let frustum = cam.frustum();
    let drawn: Vec<DrawnNode<'_>> = works.iter().map(|w| DrawnNode::faded_in(w)).collect();
    let draws = FrameDraws {
        camera: cam,
        frustum: &frustum,
        view,
        tree,
        drawn: &drawn,
        ancestors: &[],
        dt_s: 0.0,
        tau_px: 2.0,
        upload_bytes_left: usize::MAX,
        upload_time_left_s: f64::INFINITY,
    };
    let mut enc = g
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("test nodes"),
        });
    scene.finish_uploads(g, &mut UploadEncoder::Frame(&mut enc), f64::INFINITY);
    scene.render(g, &mut enc, &target.color_view, &target.depth_view, &draws);
    g.queue.submit([enc.finish()]);
    scene.after_deferred_submit();
    target.read_rgba(g).expect("readback")
}

/// A terrain vertex's normal reaches the shader through its shading word
/// (`terrain::mesh::pack_shading`) facing the right way: flat quads, each with one normal
/// tilted toward one of five azimuths, drawn lit (lighting only: one grey albedo, no fog, no
/// sky, no light grid) under a sun whose azimuth is no multiple of 45 degrees, come out
/// brighter in the order of their normals' cosines with the sun, computed here from the
/// normals before packing. (A decoder that swapped or negated a coordinate reverses it.)
#[test]
fn packed_terrain_normals_face_the_sun_they_were_given() {
    let Some(g) = device() else { return };
    let size = [16u32, 16];
    let (tree, mut scene) = terrain_scene(&g, &[[200, 200, 200]]);
    let sun = engine::lighting::grid::Sun {
        azimuth_deg: 110.0,
        elevation_deg: 40.0,
    };
    let view = ViewOptions {
        sky: false,
        fog_per_m: 0.0,
        lighting_only: true,
        sun,
        ..ViewOptions::default()
    };
    let p = DVec3::new(0.0, 0.0, 100.0);
    let mut cam = Camera::look_at(p, DVec3::new(0.0, 1.0, 0.0), 40f64.to_radians(), size);
    cam.near_m = 0.1;
    let target = Target::new(&g.device, size, COLOR_FORMAT);
    let key = NodeKey::ROOT;
    // Tilted half the sun's elevation: every normal sees the sun, so no cosine is clamped.
    let tilt = (sun.elevation_deg / 2.0).to_radians();
    let mut seen: Vec<(f64, u32)> = [0.0f64, 40.0, 80.0, 120.0, 160.0]
        .iter()
        .map(|off| {
            let a = (sun.azimuth_deg + off).to_radians();
            let n = DVec3::new(a.sin() * tilt.sin(), a.cos() * tilt.sin(), tilt.cos());
            let mut mesh = quad(key, [-3000.0, -3000.0], 6000.0, 0.0, 0);
            mesh.shading = vec![engine::terrain::mesh::pack_shading(n.to_array(), 0); 4];
            let mut w = NodeWork::new(key);
            w.put(mesh);
            scene.upload(&g, &tree, &mut w);
            let px = draw_nodes(&g, &mut scene, &tree, &cam, &view, &target, &[&w]);
            let brightness: u32 = px.chunks_exact(4).map(|p| u32::from(p[1])).sum();
            (n.dot(sun.toward()), brightness)
        })
        .collect();
    seen.sort_by(|a, b| a.0.total_cmp(&b.0));
    println!("cosine with the sun, summed green: {seen:?}");
    for w in seen.windows(2) {
        assert!(
            w[1].1 > w[0].1,
            "a normal nearer the sun drew darker: {seen:?}"
        );
    }
}

/// Renders the terrain over a magenta clear colour (no sky) from 50 cameras aimed at the ground,
/// each after settling and during the cross-fades of a move to the next camera: no pixel whose
/// ray hits the ground may stay magenta.
#[test]
fn no_leaked_pixels_from_fifty_cameras_including_fades() {
    let Some(g) = device() else { return };
    let world = tiny_world();
    let size = [64u32, 36];
    let target = Target::new(&g.device, size, COLOR_FORMAT);
    let mut v = tiny_viewer(&g, 1.0);
    v.view.sky = false;
    v.view.clear = [1.0, 0.0, 1.0, 1.0];
    v.view.fog_per_m = 0.0;
    let cams: Vec<Camera> = (0..50i64)
        .map(|i| {
            let x = 60.0 + 390.0 * unit3(41, i, 0);
            let y = 60.0 + 390.0 * unit3(41, i, 1);
            let above = 3.0 + 80.0 * unit3(41, i, 2);
            let yaw = std::f64::consts::TAU * unit3(41, i, 3);
            let pitch = -(0.35 + 0.9 * unit3(41, i, 4));
            let p = DVec3::new(x, y, world.height_m(x, y) + above);
            let d = DVec3::new(
                yaw.cos() * pitch.cos(),
                yaw.sin() * pitch.cos(),
                pitch.sin(),
            );
            Camera::look_at(p, p + d, 60f64.to_radians(), size)
        })
        .collect();
    let magenta = |p: &[u8]| p[0] > 250 && p[1] < 5 && p[2] > 250;
    let (mut checked, mut frames, mut faded_frames) = (0usize, 0usize, 0usize);
    for (i, cam) in cams.iter().enumerate() {
        settle(&g, &mut v, &target, cam);
        let mut check = |v: &engine::viewer::Viewer, cam: &Camera, what: &str| {
            let px = target.read_rgba(&g).expect("readback");
            for py in 0..size[1] {
                for qx in 0..size[0] {
                    let p = &px[((py * size[0] + qx) * 4) as usize..][..4];
                    assert!(
                        !(magenta(p) && tests::ground_hit(&world, cam, qx, py).is_some()),
                        "camera {i} ({what}): leaked pixel at ({qx}, {py}); {} nodes drawn",
                        v.drawn_keys().len()
                    );
                    checked += 1;
                }
            }
        };
        check(&v, cam, "settled");
        frames += 1;
        // Move halfway to the next camera in short frames: fades are under way meanwhile.
        let next = cams[(i + 1) % cams.len()];
        for k in 1..=6 {
            let f = f64::from(k) / 12.0;
            let pos = cam.position_m.lerp(next.position_m, f);
            let fwd = cam.forward.lerp(next.forward, f).normalize();
            let c = Camera::look_at(pos, pos + fwd, cam.fovy_rad, size);
            frame(&g, &mut v, &target, &c, 0.05);
            let fading = v
                .streamer
                .draw_list()
                .iter()
                .any(|d| d.dither_lo > 0.0 || d.dither_hi < 1.0);
            if fading {
                faded_frames += 1;
            }
            check(&v, &c, "moving");
            frames += 1;
        }
    }
    println!("{frames} frames, {checked} pixels checked, {faded_frames} frames with fades");
    assert!(
        faded_frames > 10,
        "only {faded_frames} frames had cross-fades under way"
    );
}

/// A viewer of the tiny map without houses (the reference draws none), sky or fog, cleared
/// to magenta, with plants as `plants`, recording the GPU reference at `size`; None (a
/// recorded skip outside CI, a failure in CI) without timestamp queries.
fn reference_viewer(
    g: &engine::render::Gpu,
    size: [u32; 2],
    plants: bool,
) -> Option<engine::viewer::Viewer> {
    let world = tiny_world();
    let mut kinds = engine::kinds::registered(&world);
    kinds.retain(|k| k.kind.name() != engine::objects::content::ObjectsContent::NAME);
    let mut v = engine::viewer::Viewer::with_kinds(
        g,
        COLOR_FORMAT,
        world,
        engine::stream::StreamSettings {
            workers: 1,
            tau_px: 1.0,
            ..engine::stream::StreamSettings::default()
        },
        &kinds,
    );
    v.view = ViewOptions {
        sky: false,
        fog_per_m: 0.0,
        plants,
        clear: [1.0, 0.0, 1.0, 1.0],
        ..ViewOptions::default()
    };
    if !v.enable_gpu_reference(g, size) {
        assert!(
            !tests::in_ci(),
            "CI's adapter (lavapipe) has timestamp queries"
        );
        tests::skip("gpu reference", "no timestamp queries on this adapter");
        return None;
    }
    Some(v)
}

/// Whether each pixel of `rgba` (a frame cleared to magenta) is covered by something drawn.
fn covered_by_pass(rgba: &[u8]) -> Vec<bool> {
    rgba.chunks(4)
        .map(|p| !(p[0] == 255 && p[1] == 0 && p[2] == 255))
        .collect()
}

/// Pixels covered in `a` but not in `b`.
fn only_in(a: &[bool], b: &[bool]) -> usize {
    a.iter().zip(b).filter(|&(&x, &y)| x && !y).count()
}

/// The viewer's GPU-reference target, read back.
fn reference_pixels(g: &engine::render::Gpu, v: &engine::viewer::Viewer) -> Vec<u8> {
    v.gpu_reference()
        .and_then(|r| r.target())
        .expect("reference target")
        .read_rgba(g)
        .expect("reference pixels")
}

/// Whether each pixel of the reference target's `rgba` is covered (alpha 1).
fn covered_by_reference(rgba: &[u8]) -> Vec<bool> {
    rgba.chunks(4).map(|p| p[3] == 255).collect()
}

/// The GPU-timing reference draws exactly the frame's terrain: on a settled view without sky,
/// fog, vegetation or houses, the pixels the terrain pass covers (anything but the magenta
/// clear colour) are the pixels the one-draw reference covers (alpha 1), so `pass / reference`
/// compares the same triangles; and the terrain's draws with the flat diagnostic shader
/// (`ViewOptions::flat_terrain`) cover them too, in the reference's colour.
#[test]
fn the_gpu_reference_covers_the_same_pixels_as_the_terrain_pass() {
    let Some(g) = device() else { return };
    let size = [320u32, 180];
    let Some(mut v) = reference_viewer(&g, size, false) else {
        return;
    };
    let target = Target::new(&g.device, size, COLOR_FORMAT);
    let cam = golden_view(size);
    let st = settle(&g, &mut v, &target, &cam);
    assert!(st.triangles > 1000, "{st:?}");
    // Grid meshes draw the index lists each mesh page keeps once, the reference each node's
    // own triangles from the CPU: the view draws both full and decimated grids.
    let decimated = v
        .streamer
        .draw_list()
        .iter()
        .filter(|d| d.decimation > 0)
        .count();
    assert!(
        decimated > 0 && decimated < v.streamer.draw_list().len(),
        "{decimated} of {} drawn nodes decimated",
        v.streamer.draw_list().len()
    );
    let by_pass = covered_by_pass(&target.read_rgba(&g).expect("frame pixels"));
    let reference = reference_pixels(&g, &v);
    let by_reference = covered_by_reference(&reference);
    let covered = by_pass.iter().filter(|&&c| c).count();
    let differ = by_pass
        .iter()
        .zip(&by_reference)
        .filter(|(p, r)| p != r)
        .count();
    assert!(
        covered > 1000,
        "the view shows too little terrain: {covered} pixels"
    );
    assert_eq!(differ, 0, "{differ} of {covered} covered pixels differ");
    // The ratio's diagnostic: the terrain's own draws with the flat shader cover the same
    // pixels in the reference's flat colour (dt 0: nothing fades between the two frames).
    v.view.flat_terrain = true;
    frame(&g, &mut v, &target, &cam, 0.0);
    let flat = target.read_rgba(&g).expect("flat pixels");
    let grey = reference
        .chunks(4)
        .find(|r| r[3] == 255)
        .map(|r| [r[0], r[1], r[2]])
        .expect("a covered reference pixel");
    let mut wrong = 0usize;
    for ((f, &in_pass), &in_flat) in flat.chunks(4).zip(&by_pass).zip(&covered_by_pass(&flat)) {
        // Grey where the shaded pass drew, the clear colour elsewhere.
        wrong += usize::from(if in_pass { f[..3] != grey } else { in_flat });
    }
    assert_eq!(
        wrong, 0,
        "{wrong} pixels differ from the flat pass's expected picture"
    );
}

/// The GPU reference draws the frame's vegetation too: on a settled view with plants (no sky,
/// fog or houses) it gathers exactly the plant instances the frame drew, covers every pixel
/// the frame covers (plant meshes with their own triangles; billboards and cluster quads as
/// whole quads, so it may cover more), and covers pixels that the terrain alone leaves open.
#[test]
fn the_gpu_reference_draws_the_frames_plant_instances() {
    let Some(g) = device() else { return };
    let size = [320u32, 180];
    let Some(mut v) = reference_viewer(&g, size, true) else {
        return;
    };
    let target = Target::new(&g.device, size, COLOR_FORMAT);
    // Low over the ground, looking a little up: plants stand against the cleared sky.
    let eye = golden_view(size);
    let fwd = DVec3::new(eye.forward.x, eye.forward.y, 0.05).normalize();
    let pos = eye.position_m - DVec3::new(0.0, 0.0, 0.5 * eye.position_m.z.min(60.0));
    let cam = Camera::look_at(pos, pos + fwd, eye.fovy_rad, size);
    let st = settle(&g, &mut v, &target, &cam);
    assert!(st.plant_instances > 100, "{st:?}");
    let r = v.gpu_reference().expect("reference");
    assert_eq!(
        r.plant_instances, st.plant_instances,
        "the reference gathered other instances than the frame drew"
    );
    let by_pass = covered_by_pass(&target.read_rgba(&g).expect("frame pixels"));
    let with_plants = covered_by_reference(&reference_pixels(&g, &v));
    let missed = only_in(&by_pass, &with_plants);
    assert_eq!(
        missed, 0,
        "{missed} pixels the frame covers are not in the reference"
    );
    // The same view without plants (dt 0: nothing fades): the reference loses the plants.
    v.view.plants = false;
    frame(&g, &mut v, &target, &cam, 0.0);
    assert_eq!(v.gpu_reference().expect("reference").plant_instances, 0);
    let terrain_only = covered_by_reference(&reference_pixels(&g, &v));
    let lost = only_in(&terrain_only, &with_plants);
    let plants_only = only_in(&with_plants, &terrain_only);
    assert_eq!(lost, 0, "{lost} terrain pixels are not covered with plants");
    assert!(
        plants_only > 50,
        "plants add only {plants_only} pixels to the reference"
    );
}

/// Pixels (RGBA8) that differ between two pictures of the same size.
fn differing_pixels(a: &[u8], b: &[u8]) -> usize {
    a.chunks(4).zip(b.chunks(4)).filter(|(p, q)| p != q).count()
}

/// Merged draws (seed 002: node geometry suballocated from shared pages, one multi-draw per
/// render state and page) draw exactly the pixels of per-item draws (one draw call per node mesh
/// and per node instance group, the fallback path), terrain and vegetation with group
/// billboards, from two settled cameras; and they merge: far fewer draw calls than items.
#[test]
fn merged_draws_draw_exactly_the_pixels_of_per_item_draws() {
    let Some(g) = tests::gpu::multi_draw_device("merged draws") else {
        return;
    };
    let size = [320u32, 180];
    let near = golden_view(size);
    let low = Camera::look_at(
        near.position_m - DVec3::new(0.0, 0.0, 45.0),
        near.position_m + near.forward * 100.0 - DVec3::new(0.0, 0.0, 45.0),
        near.fovy_rad,
        size,
    );
    let mut v = tiny_viewer(&g, 1.0);
    let target = Target::new(&g.device, size, COLOR_FORMAT);
    for cam in [near, low] {
        settle(&g, &mut v, &target, &cam);
        let mut images = Vec::new();
        for merged in [true, false] {
            v.view.merged_draws = merged;
            // dt 0: no fade advances between the two pictures (nothing is in flight).
            let st = frame(&g, &mut v, &target, &cam, 0.0);
            images.push(target.read_rgba(&g).expect("readback"));
            let (calls, items) = (
                st.draw_calls + st.plant_draw_calls,
                st.items + st.plant_items,
            );
            println!("merged {merged}: {calls} draw calls for {items} items");
            assert!(st.items > 20 && st.plant_items > 20, "{st:?}");
            assert!(
                st.group_billboards > 0,
                "no group billboards in view: {st:?}"
            );
            if merged {
                assert!(calls * 5 <= items, "{calls} calls for {items} items");
            } else {
                assert_eq!(calls, items, "the fallback draws item by item");
            }
        }
        let differ = differing_pixels(&images[0], &images[1]);
        assert_eq!(
            differ, 0,
            "{differ} pixels differ between merged and per-item draws"
        );
    }
}

/// Impostor bakes submitted together (their clusters and members in buffers shared by the
/// submission, each bake at its own offsets) bake the textures of bakes submitted one by one:
/// the same settled view of the tiny map's group billboards has the same pixels when every
/// frame uploads all the nodes that are ready (several bakes a submission) and when each frame
/// uploads one (a byte budget of 1: one bake a submission).
#[test]
fn impostor_bakes_submitted_together_bake_what_single_bakes_do() {
    use engine::render::vegetation::VegetationRenderer;
    let Some(g) = device() else {
        return;
    };
    let size = [320u32, 180];
    let cam = golden_view(size);
    let target = Target::new(&g.device, size, COLOR_FORMAT);
    let mut pictures = Vec::new();
    for one_a_frame in [false, true] {
        let mut v = tiny_viewer(&g, 1.0);
        if one_a_frame {
            v.streamer.settings.gpu_budget_bytes = 1;
        }
        let st = settle(&g, &mut v, &target, &cam);
        assert!(
            st.group_billboards > 0,
            "no group billboards in view: {st:?}"
        );
        let together = v
            .scene
            .renderer::<VegetationRenderer>()
            .expect("a vegetation renderer")
            .most_bakes_submitted_together();
        println!("one node a frame {one_a_frame}: at most {together} bakes a submission");
        if one_a_frame {
            assert_eq!(
                together, 1,
                "one upload a frame bakes one node a submission"
            );
        } else {
            assert!(
                together >= 2,
                "bakes were never submitted together ({together})"
            );
        }
        pictures.push(target.read_rgba(&g).expect("readback"));
    }
    let differ = differing_pixels(&pictures[0], &pictures[1]);
    assert_eq!(
        differ, 0,
        "{differ} pixels differ between bakes submitted together and one by one"
    );
}
