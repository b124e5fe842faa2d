//! The pixel bound on the screen: a cliff in each corner of wide screens, measured through the
//! camera's matrices (engine::measure), against the selection's bound (engine::terrain::select).

use engine::camera::Camera;
use engine::measure::{self, ScreenRegion};
use engine::surface::world::World;
use engine::terrain::bounds::BoundsCache;
use engine::terrain::quadtree::QuadTree;
use engine::terrain::select::{SelectParams, select};
use engine::terrain::tiles::TileCache;
use glam::DVec3;
use tests::terrain::{build_selection, cliff_world, tree_of};

/// The x of the cliff face in the cliff world (100 m up between the samples at 156 and 160 m).
const CLIFF_X_M: f64 = 158.0;

/// A camera whose view puts the cliff's top edge at `at_y_m` near the screen corner
/// (`sx`, `sy` = ±1: right/left, top/bottom), 90 % of the way from the centre to the corner, seen
/// from `dist_m` away on the low side of the cliff.
fn corner_camera(
    world: &World,
    fovy_deg: f64,
    viewport: [u32; 2],
    (sx, sy): (f64, f64),
    at_y_m: f64,
    dist_m: f64,
) -> Camera {
    let top = DVec3::new(CLIFF_X_M, at_y_m, world.height_m(CLIFF_X_M + 2.0, at_y_m));
    // Looking across the cliff (east, turned away from the corner's side so the cliff stays in
    // view) and down for a top corner, level for a bottom one.
    let yaw = sx * 0.35;
    let pitch: f64 = if sy > 0.0 { -0.55 } else { -0.05 };
    let fwd = DVec3::new(
        yaw.cos() * pitch.cos(),
        yaw.sin() * pitch.cos(),
        pitch.sin(),
    );
    let probe = Camera::look_at(DVec3::ZERO, fwd, fovy_deg.to_radians(), viewport);
    let ty = (probe.fovy_rad * 0.5).tan();
    let tx = ty * probe.aspect();
    let ray =
        (probe.forward - 0.9 * sx * tx * probe.right() + 0.9 * sy * ty * probe.up).normalize();
    let eye = top - ray * dist_m;
    Camera::look_at(eye, eye + fwd, probe.fovy_rad, viewport)
}

/// The on-screen error of a selection: the largest over dense samples of its meshes, and by
/// screen region.
fn on_screen_error(
    world: &World,
    tree: &QuadTree,
    cache: &mut BoundsCache,
    tiles: &mut TileCache,
    cam: &Camera,
    params: SelectParams,
) -> (measure::ViewError, u32) {
    let sel = select(world, tree, cache, cam, params);
    let meshes = build_selection(world, tree, cache, tiles, &sel);
    let samples: Vec<_> = sel
        .nodes
        .iter()
        .filter(|s| s.error_px <= params.tau_px)
        .map(|s| measure::node_error_samples(world, tree, &meshes[&s.key], 4))
        .collect();
    let refs: Vec<_> = samples.iter().collect();
    (
        measure::view_max_error_px(&refs, cam, true),
        sel.over_tau_at_finest,
    )
}

/// At 90 and 120 degrees, with the cliff in each corner of the screen: the error measured on
/// the screen stays within tau; the same views selected with the on-axis bound (the former
/// metric, which leaves out the off-axis stretch) show more than tau there, so this test fails
/// without the stretch.
#[test]
fn a_cliff_in_each_screen_corner_stays_within_tau_on_the_screen() {
    let world = cliff_world();
    let tree = tree_of(&world);
    let mut cache = BoundsCache::new();
    let mut tiles = TileCache::new();
    let viewport = [320, 180];
    let tau = 2.0;
    let (mut worst, mut worst_on_axis_corner) = (0.0f64, 0.0f64);
    for fovy_deg in [90.0, 120.0] {
        for corner in [(1.0, 1.0), (-1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)] {
            let cam = corner_camera(&world, fovy_deg, viewport, corner, 300.0, 60.0);
            let ground = world.height_m(cam.position_m.x, cam.position_m.y);
            assert!(
                cam.position_m.z > ground + 2.0,
                "{fovy_deg} {corner:?}: the camera is under the ground"
            );
            let p = SelectParams::culled(tau, &tree);
            let (e, over) = on_screen_error(&world, &tree, &mut cache, &mut tiles, &cam, p);
            assert!(
                e.samples > 10_000,
                "{fovy_deg} {corner:?}: {} samples",
                e.samples
            );
            assert!(
                e.max_px <= tau,
                "{fovy_deg} deg, corner {corner:?}: {:.3} px on the screen over tau {tau} \
                 (by region {:?}; {over} finest nodes over tau left out)",
                e.max_px,
                e.region_max_px
            );
            worst = worst.max(e.max_px);
            let axis = SelectParams {
                off_axis: false,
                ..p
            };
            let (a, _) = on_screen_error(&world, &tree, &mut cache, &mut tiles, &cam, axis);
            worst_on_axis_corner =
                worst_on_axis_corner.max(a.region_max_px[ScreenRegion::Corners as usize]);
        }
    }
    println!(
        "largest on-screen error {worst:.3} px; with the on-axis bound {worst_on_axis_corner:.3} \
         px in the corners"
    );
    // The views are hard: the bound is not met by accident far under tau.
    assert!(
        worst > 0.4 * tau,
        "largest on-screen error only {worst:.3} px"
    );
    assert!(
        worst_on_axis_corner > tau,
        "the on-axis bound held in the corners too ({worst_on_axis_corner:.3} px)"
    );
}

/// The crest line of [`ridge_world`] (m east of the origin): a vertex line of every node mesh
/// with a spacing of up to 32 m, and a line of the map's 4 m samples.
const CREST_X_M: f64 = 288.0;

/// The tiny map turned into a ridge along y at [`CREST_X_M`]: heights fall 4 m per metre on
/// both sides (symmetric, so the surface's crest is on that line for every y; steep, so seen
/// nearly along x nothing before or behind the crest rises above it), the crest height waves
/// 12 m over 24 m of y (so a node mesh of 8 m spacing cuts the waves' tops and troughs), water
/// ground everywhere (no procedural detail) and no decals.
fn ridge_world() -> World {
    let mut map = worldgen::Map::load(&tests::tiny_map_dir()).expect("tiny map loads");
    let (w, h) = (map.heights.width(), map.heights.height());
    let spacing = map.manifest.heights.spacing_m;
    for y in 0..h {
        for x in 0..w {
            let (xm, ym) = (x as f64 * spacing, y as f64 * spacing);
            let crest = 150.0 + 12.0 * (std::f64::consts::TAU * ym / 24.0).sin();
            let z = (crest - 4.0 * (xm - CREST_X_M).abs()).max(30.0);
            let hg = map.heights.grid_mut().expect("heights in memory");
            hg.set(x, y, z as f32);
            map.ground
                .grid_mut()
                .expect("ground in memory")
                .set(x, y, worldgen::classify::WATER);
        }
    }
    map.decals.clear();
    tests::terrain::world_of(map)
}

/// The silhouette row (pixels from the top, to the middle of the first covered pixel) of each
/// column of a reference rendering (covered: alpha 1); None for a column with nothing.
fn silhouette_rows(rgba: &[u8], size: [u32; 2]) -> Vec<Option<f64>> {
    (0..size[0] as usize)
        .map(|c| {
            (0..size[1] as usize)
                .find(|&r| rgba[(r * size[0] as usize + c) * 4 + 3] == 255)
                .map(|r| r as f64 + 0.5)
        })
        .collect()
}

/// Renders `mesh` alone with the GPU reference's flat shader at `cam` and returns its pixels.
fn render_alone(
    g: &engine::render::Gpu,
    frame: &engine::render::frame::FrameResources,
    reference: &mut engine::render::reference::GpuReference,
    cam: &Camera,
    mesh: &engine::terrain::mesh::NodeMesh,
) -> Vec<u8> {
    frame.write_uniforms(
        &g.queue,
        cam,
        &engine::render::frame::ViewOptions::default(),
    );
    let mut encoder = g
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("silhouette test"),
        });
    let content = engine::render::reference::FrameContent {
        camera: cam,
        meshes: &[(mesh, 0)],
        plants: None,
    };
    reference.record(g, frame, &mut encoder, cam.viewport_px, &content);
    g.queue.submit([encoder.finish()]);
    reference
        .target()
        .expect("reference target")
        .read_rgba(g)
        .expect("reference pixels")
}

/// The on-screen measure against a rendered reference: a node's mesh and the true surface
/// (densely tessellated: 0.25 m) are rendered on the GPU at 16 times a 320 x 180 view's
/// resolution, looking level across a ridge whose crest waves between the mesh's vertices; in
/// every column of the middle 40 % (where the view is nearly along x, so the silhouette is the
/// crest line, seen from below it) the two silhouettes lie apart by what the measure says the
/// true and the drawn crest point lie apart on the 320 x 180 screen, within 0.25 px.
#[test]
fn the_on_screen_measure_matches_rendered_ridge_silhouettes() {
    let Some(g) = tests::gpu::device() else {
        return;
    };
    let world = ridge_world();
    let tree = tree_of(&world);
    let mut cache = BoundsCache::new();
    let mut tiles = TileCache::new();
    // The 256 m node over the crest: 8 m between vertices.
    let key = tree
        .key_at(1, CREST_X_M + 1.0, 384.0)
        .expect("node on the map");
    let mesh = tests::terrain::build_mesh(&world, &tree, &mut cache, &mut tiles, key);
    let r = tree.rect(key);
    // The true surface over a strip around the crest, 0.25 m between vertices.
    let step_m = 0.25;
    let (nx, ny) = (129usize, ((r.max[1] - r.min[1]) / step_m) as usize + 1);
    let x_start = CREST_X_M - 16.0;
    let mut positions = Vec::with_capacity(nx * ny);
    for j in 0..ny {
        for i in 0..nx {
            let (x, y) = (x_start + i as f64 * step_m, r.min[1] + j as f64 * step_m);
            let z = world.height_m(x, y);
            positions.push([(x - r.min[0]) as f32, (y - r.min[1]) as f32, z as f32]);
        }
    }
    let mut indices = Vec::new();
    for j in 0..ny - 1 {
        for i in 0..nx - 1 {
            let a = (j * nx + i) as u32;
            let (b, c, d) = (a + 1, a + nx as u32, a + nx as u32 + 1);
            indices.extend([a, b, d, a, d, c]);
        }
    }
    let dense = engine::terrain::mesh::NodeMesh {
        shading: vec![0; positions.len()],
        positions,
        surface_index_count: indices.len() as u32,
        indices: indices.into(),
        ..mesh.clone()
    };
    // Looking level along +x from 200 m before the crest, 10 m below its mean height.
    let base = [320u32, 180];
    let scale = 16u32;
    let eye = DVec3::new(CREST_X_M - 200.0, 384.0, 140.0);
    let view = |size: [u32; 2]| Camera::look_at(eye, eye + DVec3::X, 60f64.to_radians(), size);
    let (cam, cam_hi) = (view(base), view([base[0] * scale, base[1] * scale]));
    let frame = engine::render::frame::FrameResources::new(&g.device, engine::render::COLOR_FORMAT);
    let Some(mut reference) = engine::render::reference::GpuReference::new(&g, &frame) else {
        // The reference's flat pipeline comes with its timer: none without timestamp queries.
        assert!(!tests::in_ci(), "CI's adapter has timestamp queries");
        tests::skip(
            "the_on_screen_measure_matches_rendered_ridge_silhouettes",
            "the adapter has no timestamp queries, so no GPU reference to render with",
        );
        return;
    };
    let drawn = silhouette_rows(
        &render_alone(&g, &frame, &mut reference, &cam_hi, &mesh),
        cam_hi.viewport_px,
    );
    let truth = silhouette_rows(
        &render_alone(&g, &frame, &mut reference, &cam_hi, &dense),
        cam_hi.viewport_px,
    );
    let screen = measure::ScreenProjection::new(&cam);
    let surface = engine::terrain::mesh_surface::MeshSurface::new(&mesh, &tree);
    let ty = (cam_hi.fovy_rad * 0.5).tan();
    let tx = ty * cam_hi.aspect();
    let (mut checked, mut worst, mut largest) = (0usize, 0.0f64, 0.0f64);
    for (c, (d, t)) in drawn.iter().zip(&truth).enumerate() {
        let (Some(d), Some(t)) = (d, t) else { continue };
        // The crest point this column sees: its ray meets the crest's vertical plane there
        // (looking along +x, the right is -y).
        let across = 2.0 * (c as f64 + 0.5) / f64::from(cam_hi.viewport_px[0]) - 1.0;
        let xc = across * tx;
        let y = eye.y - xc * (CREST_X_M - eye.x);
        if across.abs() > 0.4 || y < r.min[1] + 4.0 || y > r.max[1] - 4.0 {
            continue;
        }
        let true_crest = DVec3::new(CREST_X_M, y, world.height_m(CREST_X_M, y));
        let drawn_crest = DVec3::new(CREST_X_M, y, surface.height_at(CREST_X_M, y));
        let Some((measured_px, _)) = screen.segment_px(true_crest, drawn_crest) else {
            continue;
        };
        let rendered_px = (d - t).abs() / f64::from(scale);
        worst = worst.max((rendered_px - measured_px).abs());
        largest = largest.max(measured_px);
        checked += 1;
    }
    println!(
        "{checked} columns: silhouettes and measure differ by up to {worst:.3} px; \
         largest measured {largest:.3} px"
    );
    assert!(checked > 900, "{checked} columns checked");
    assert!(
        largest > 1.0,
        "the ridge's largest error is only {largest:.3} px"
    );
    assert!(
        worst <= 0.25,
        "the measure and the rendered silhouettes differ by up to {worst:.3} px"
    );
}

/// Splitting less behind dense vegetation must not show terrain error: at eye height in the
/// 2 km patches map's woods, looking into them, the view is settled with the rule off and on,
/// drawn (terrain and vegetation) on the GPU, and the drawn terrain's error measured on the
/// screen over the samples the frame's depth shows. With the rule on, the drawn meshes' error
/// exceeds tau somewhere (the rule left nodes coarse) yet what the frame shows stays within tau.
/// Measured at tau 1: rule off 433,408 triangles, 0.571 px over all samples; rule on 228,096
/// triangles, 1.382 px over all, 0.500 px shown. The former rule (one line of sight to a node's
/// top centre) showed 1.316 px here.
#[test]
fn splitting_less_behind_vegetation_shows_no_terrain_error() {
    use engine::render::{COLOR_FORMAT, Target};
    use engine::shown_error::{check_viewer, settled_view_error};
    let Some(g) = tests::gpu::device() else {
        return;
    };
    let world = tests::terrain::patches_world();
    let o = world.origin_m();
    let (x0, y0) = (o[0] + 1150.0, o[1] + 1000.0);
    let eye = DVec3::new(x0, y0, world.height_m(x0, y0) + 1.8);
    let yaw = 1.5 * std::f64::consts::PI + 0.3;
    let cam = Camera::look_at(
        eye,
        eye + DVec3::new(yaw.cos(), yaw.sin(), -0.02),
        60f64.to_radians(),
        [640, 360],
    );
    let tau_px = 1.0;
    let target = Target::new(&g.device, cam.viewport_px, COLOR_FORMAT);
    let mut runs = Vec::new();
    for occlusion in [false, true] {
        let mut v = check_viewer(&g, &world, tau_px, 1, occlusion);
        let e = settled_view_error(&g, &mut v, &target, &cam, 600.0).expect("settled view");
        println!(
            "rule {}: {} nodes, {} triangles; max on the screen {:.3} px over all samples, \
             {:.3} px over the {} shown ({} hidden)",
            if occlusion { "on" } else { "off" },
            e.drawn_nodes,
            e.triangles,
            e.all.max_px,
            e.shown.max_px,
            e.shown.samples,
            e.hidden_samples
        );
        runs.push(e);
    }
    let (off, on) = (runs[0], runs[1]);
    assert!(off.all.max_px <= tau_px, "rule off: {:?}", off.all);
    assert!(
        on.triangles < off.triangles && on.all.max_px > tau_px,
        "the view must exercise the rule: {} against {} triangles, {:.3} px",
        on.triangles,
        off.triangles,
        on.all.max_px
    );
    assert!(
        on.shown.max_px <= tau_px,
        "the rule shows {:.3} px of terrain error (tau {tau_px})",
        on.shown.max_px
    );
}
