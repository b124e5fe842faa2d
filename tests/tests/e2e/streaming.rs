//! Streaming: determinism across worker counts and request orders, cancellation under a burst
//! of teleports, late results discarded, and a draw list that always covers the map exactly
//! once per pixel (complementary cross-fades, nothing missing).

use engine::camera::Camera;
use engine::kinds::content_kinds;
use engine::stream::{NodeWork, Phase, PhaseKind, Shared, StreamSettings, Streamer, node_phases};
use engine::terrain::bounds::BoundsCache;
use engine::terrain::mesh::NodeMesh;
use engine::terrain::quadtree::NodeKey;
use engine::terrain::tiles::TileCache;
use engine::vegetation::NodeVegetation;
use glam::DVec3;
use std::collections::HashMap;
use std::sync::{Arc, Condvar, Mutex};
use tests::terrain::{build_mesh, tiny_world, tree_of};
use worldgen::noise::unit3;

/// A streamer of the tiny map with every registered content kind.
fn streamer(settings: StreamSettings) -> Streamer {
    let world = tiny_world();
    let kinds = content_kinds(&world);
    Streamer::new(world, settings, kinds)
}

fn settings(workers: usize) -> StreamSettings {
    StreamSettings {
        workers,
        fade_s: 0.1,
        tau_px: 0.5,
        ..StreamSettings::default()
    }
}

/// A camera `above` metres over the tiny map's ground at (x, y), looking along `yaw` and down.
fn cam_at(x: f64, y: f64, above: f64, yaw: f64) -> Camera {
    thread_local! {
        static WORLD: engine::surface::world::World = tiny_world();
    }
    let ground = WORLD.with(|w| w.height_m(x, y));
    let p = DVec3::new(x, y, ground + above);
    let dir = DVec3::new(yaw.cos() * 0.8, yaw.sin() * 0.8, -0.6);
    Camera::look_at(p, p + dir, 60f64.to_radians(), [640, 360])
}

fn flight(i: usize) -> Camera {
    let t = i as f64 / 40.0;
    cam_at(60.0 + 390.0 * t, 80.0 + 300.0 * t, 40.0 - 25.0 * t, 0.6 + t)
}

/// Checks that at `n` points of the map the drawn nodes' dither intervals tile [0, 1).
fn assert_draw_list_partitions(s: &Streamer, seed: u64, n: i64) {
    let tree = *s.tree();
    let list = s.draw_list();
    assert!(!list.is_empty());
    for i in 0..n {
        let x = tree.origin_m[0] + tree.map_size_m[0] * unit3(seed, i, 0);
        let y = tree.origin_m[1] + tree.map_size_m[1] * unit3(seed, i, 1);
        let mut iv: Vec<(f32, f32)> = list
            .iter()
            .filter(|d| {
                let r = tree.rect(d.key);
                x >= r.min[0] && x < r.max[0] && y >= r.min[1] && y < r.max[1]
            })
            .map(|d| (d.dither_lo, d.dither_hi))
            .collect();
        iv.sort_by(|a, b| a.0.total_cmp(&b.0));
        assert!(!iv.is_empty(), "point ({x}, {y}) is drawn by no node");
        assert_eq!(
            iv[0].0, 0.0,
            "point ({x}, {y}): coverage starts at {}",
            iv[0].0
        );
        for w in iv.windows(2) {
            assert!(
                (w[0].1 - w[1].0).abs() < 1e-6,
                "point ({x}, {y}): intervals {iv:?} overlap or leave a gap"
            );
        }
        assert!(
            (iv[iv.len() - 1].1 - 1.0).abs() < 1e-6,
            "point ({x}, {y}): coverage ends at {iv:?}"
        );
    }
}

/// Per resident node: the mesh hash (vertices, normals, ground types, indices) and a hash of
/// everything its jobs produced (the mesh, its bounds and skirt depths, the vegetation groups
/// and clusters).
fn hashes(s: &Streamer) -> HashMap<NodeKey, (u64, u64)> {
    use std::hash::{Hash, Hasher};
    s.resident_keys()
        .into_iter()
        .filter_map(|k| {
            let w = &s.resident(k)?.work;
            let m = w.get::<NodeMesh>()?;
            let mut h = std::collections::hash_map::DefaultHasher::new();
            m.content_hash().hash(&mut h);
            let b = w.bounds?;
            for v in [
                b.z_min_m,
                b.z_max_m,
                b.error_m,
                b.mesh_error_m,
                b.descendants_error_m,
            ]
            .into_iter()
            .chain(m.skirt_bottom_m)
            {
                v.to_bits().hash(&mut h);
            }
            let veg = w.get::<NodeVegetation>()?;
            format!("{:?}", veg.groups).hash(&mut h);
            format!("{:?}", veg.clusters).hash(&mut h);
            Some((k, (m.content_hash(), h.finish())))
        })
        .collect()
}

#[test]
fn node_contents_do_not_depend_on_worker_count_or_request_order() {
    let mut results = Vec::new();
    for workers in [1, 4] {
        let mut s = streamer(settings(workers));
        for i in 0..40 {
            s.update(&flight(i), 1.0 / 60.0);
            s.run_gpu_phases();
        }
        assert!(
            s.settle(&flight(40), 120.0),
            "{workers} workers did not settle"
        );
        results.push(hashes(&s));
    }
    let common: Vec<NodeKey> = results[0]
        .keys()
        .filter(|k| results[1].contains_key(k))
        .copied()
        .collect();
    assert!(common.len() > 30, "only {} nodes in common", common.len());
    for k in &common {
        assert_eq!(
            results[0][k], results[1][k],
            "{k:?} differs between 1 and 4 workers"
        );
    }
    // Direct builds in a shuffled order give the same bytes.
    let world = tiny_world();
    let tree = tree_of(&world);
    let mut order = common.clone();
    order.sort_by_key(|k| {
        worldgen::noise::hash3(
            99,
            i64::from(k.ix) * 64 + i64::from(k.iy),
            i64::from(k.level),
        )
    });
    let mut cache = BoundsCache::new();
    let mut tiles = TileCache::new();
    for k in order {
        assert_eq!(
            build_mesh(&world, &tree, &mut cache, &mut tiles, k).content_hash(),
            results[0][&k].0,
            "{k:?}"
        );
    }
}

/// A content kind written only here: its payload is the node's vertex count, which it reads
/// from the terrain payload made by the kind registered before it.
#[derive(Debug)]
struct VertexCount;

#[derive(Debug)]
struct VertexCountPayload(usize);

impl engine::stream::Payload for VertexCountPayload {
    fn bytes(&self) -> usize {
        1000
    }
}

impl engine::stream::ContentKind for VertexCount {
    fn name(&self) -> &'static str {
        "vertex count"
    }

    fn phases(self: Arc<Self>) -> Vec<Phase> {
        vec![Phase::cpu("count", |_: &Shared, w: &mut NodeWork| {
            let n = w.get::<NodeMesh>().map_or(0, |m| m.positions.len());
            w.put(VertexCountPayload(n));
        })]
    }
}

/// Adding a content kind is one registration: the streamer runs its phase for every node after
/// the kinds before it, keeps its payload with the node and counts its bytes in the budget.
#[test]
fn a_new_content_kind_plugs_in_with_one_registration() {
    let world = tiny_world();
    let mut kinds = content_kinds(&world);
    kinds.push(Arc::new(VertexCount));
    let mut s = Streamer::new(world, settings(2), kinds);
    assert!(s.settle(&cam_at(200.0, 200.0, 30.0, 1.0), 120.0));
    let keys = s.resident_keys();
    assert!(keys.len() > 10, "only {} nodes resident", keys.len());
    for k in &keys {
        let w = &s.resident(*k).expect("resident").work;
        let mesh = w.get::<NodeMesh>().expect("terrain payload");
        let count = w
            .get::<VertexCountPayload>()
            .expect("the new kind's payload");
        assert_eq!(count.0, mesh.positions.len(), "{k:?}");
        assert!(
            w.bytes() >= mesh.gpu_bytes() + 1000,
            "{k:?}: payload bytes not counted"
        );
    }
    assert!(s.shared.kind::<VertexCount>().is_some());
}

#[test]
fn a_burst_of_teleports_settles_with_nothing_leaked() {
    // The burst and tour below leave more prepared nodes (meshes, vegetation, decal pieces: no
    // ground texture is made without a renderer) than this budget holds, and the last view
    // pins about 29 MiB (a camera flown by hand prefetches the views to either side too; 9 MiB
    // without); the tour has to evict to stay within this.
    let budget = 40 << 20;
    let mut s = streamer(StreamSettings {
        cache_budget_bytes: budget,
        ..settings(3)
    });
    // Start from a settled view, so the burst has a known tree to request and cancel from.
    assert!(s.settle(&cam_at(256.0, 256.0, 20.0, 0.0), 120.0));
    for i in 0..10_000i64 {
        let cam = if i % 500 < 250 {
            // Random teleports.
            cam_at(
                512.0 * unit3(1, i, 0),
                512.0 * unit3(1, i, 1),
                5.0 + 300.0 * unit3(1, i, 2),
                6.3 * unit3(1, i, 3),
            )
        } else {
            // A fast flight (about 2 km/s) back and forth.
            let t = (i % 250) as f64 / 250.0;
            cam_at(
                20.0 + 470.0 * t,
                256.0 + 200.0 * (t * 12.0).sin(),
                15.0,
                0.3,
            )
        };
        s.update(&cam, 1.0 / 60.0);
        if i % 3 == 0 {
            s.run_gpu_phases();
        }
        if i % 97 == 0 && s.is_ready(NodeKey::ROOT) {
            assert_draw_list_partitions(&s, i as u64, 50);
        }
    }
    let stats = s.stats.clone();
    assert!(
        stats.cancelled_queued + stats.cancelled_running + stats.cancelled_gpu > 100,
        "{stats:?}"
    );
    // A slower tour fills the cache past its budget.
    for k in 0..6 {
        let c = cam_at(
            60.0 + 80.0 * f64::from(k),
            450.0 - 70.0 * f64::from(k),
            6.0,
            0.4 * f64::from(k),
        );
        assert!(s.settle(&c, 120.0), "tour stop {k} did not settle");
    }
    let last = cam_at(250.0, 250.0, 30.0, 1.0);
    assert!(
        s.settle(&last, 120.0),
        "did not settle after the burst: {:?}",
        s.stats
    );
    for k in s.wanted() {
        assert!(
            s.is_ready(*k),
            "wanted {k:?} is not resident after settling"
        );
    }
    assert_eq!(s.in_flight(), 0);
    // Every cancelled running job reported back: stopped at a phase boundary or discarded late.
    assert_eq!(s.cancelled_outstanding(), 0);
    assert_eq!(
        s.stats.cancelled_running,
        s.stats.cancels_acknowledged + s.stats.late_results_discarded
    );
    assert_eq!(
        s.tiles_resident(),
        0,
        "tiles still held after every job ended"
    );
    // Within budget, except for nodes that cannot go (needed, drawn, fading).
    assert!(
        s.pinned_bytes() <= budget,
        "this view alone needs {} bytes; pick a larger budget",
        s.pinned_bytes()
    );
    assert!(
        s.stats.resident_bytes <= budget,
        "resident {} bytes over the budget {budget}",
        s.stats.resident_bytes
    );
    assert!(
        s.stats.evicted > 0,
        "the budget never forced an eviction: {:?}",
        s.stats
    );
    assert_draw_list_partitions(&s, 7, 400);
}

/// A gate the test opens and closes: a phase that waits while it is closed, and counts the
/// jobs that reached it.
#[derive(Default)]
struct Gate {
    state: Mutex<(bool, usize)>,
    changed: Condvar,
}

impl Gate {
    fn set_open(&self, open: bool) {
        self.state.lock().expect("gate lock").0 = open;
        self.changed.notify_all();
    }

    /// The phase: counts the arrival, then waits until the gate is open.
    fn pass(&self) {
        let mut st = self.state.lock().expect("gate lock");
        st.1 += 1;
        self.changed.notify_all();
        while !st.0 {
            st = self.changed.wait(st).expect("gate lock");
        }
    }

    /// Waits (event-driven, no sleeps) until `n` jobs in total have reached the gate.
    fn wait_for_arrivals(&self, n: usize) {
        let st = self.state.lock().expect("gate lock");
        let (st, timeout) = self
            .changed
            .wait_timeout_while(st, std::time::Duration::from_mins(2), |st| st.1 < n)
            .expect("gate lock");
        assert!(!timeout.timed_out(), "only {} jobs reached the gate", st.1);
    }
}

/// Opens the gate when dropped: a failing assertion while jobs are held must fail the test,
/// not leave the workers (and the streamer's drop, which joins them) waiting forever.
struct OpenOnDrop(Arc<Gate>);

impl Drop for OpenOnDrop {
    fn drop(&mut self) {
        self.0.set_open(true);
    }
}

/// A job held in its last CPU phase while it is cancelled still delivers its result, late; the
/// result is discarded. The test holds jobs in a gate phase (inserted before the GPU phase)
/// until they are cancelled, so the order of events is fixed, not raced with sleeps.
#[test]
fn late_results_of_cancelled_jobs_are_discarded() {
    let world = tiny_world();
    let kinds = content_kinds(&world);
    let mut phases = node_phases(&kinds);
    let upload = phases.pop().expect("the GPU phase");
    assert_eq!(upload.kind, PhaseKind::Gpu);
    let gate = Arc::new(Gate::default());
    gate.set_open(true);
    let g = Arc::clone(&gate);
    phases.push(Phase::cpu("gate", move |_: &Shared, _: &mut NodeWork| {
        g.pass();
    }));
    phases.push(upload);
    let mut s = Streamer::with_phases(world, settings(2), kinds, phases);
    // Dropped before `s` (locals drop in reverse order).
    let _open_on_drop = OpenOnDrop(Arc::clone(&gate));
    let a = cam_at(100.0, 100.0, 20.0, 0.5);
    let b = cam_at(450.0, 450.0, 20.0, 3.5);
    assert!(s.settle(&a, 120.0));
    let mut arrived = gate.state.lock().expect("gate lock").1;
    for _ in 0..3 {
        // Start B's jobs and hold them in the gate, turn back to A (B's jobs are cancelled while
        // held), then let them finish.
        gate.set_open(false);
        s.update(&b, 1.0 / 60.0);
        arrived += 1;
        gate.wait_for_arrivals(arrived);
        s.update(&a, 1.0 / 60.0);
        assert!(s.stats.cancelled_running > 0, "no held job was cancelled");
        gate.set_open(true);
        assert!(s.settle(&a, 120.0));
        arrived = gate.state.lock().expect("gate lock").1;
    }
    assert!(s.settle(&a, 120.0));
    assert!(
        s.stats.late_results_discarded > 0,
        "no late result was produced: {:?}",
        s.stats
    );
    // Nothing drawn is stale: every drawn node is resident and matches a fresh build.
    let world = tiny_world();
    let tree = tree_of(&world);
    let mut cache = BoundsCache::new();
    let mut tiles = TileCache::new();
    for d in s.draw_list() {
        let r = s.resident(d.key).expect("drawn nodes are resident");
        let m = r.work.get::<NodeMesh>().expect("terrain");
        assert_eq!(
            m.content_hash(),
            build_mesh(&world, &tree, &mut cache, &mut tiles, d.key).content_hash()
        );
    }
}

#[test]
fn the_screen_is_covered_exactly_once_in_every_frame_of_a_flight() {
    let mut s = streamer(settings(2));
    let cam_of = |i: usize| {
        let t = i as f64 / 300.0;
        cam_at(
            40.0 + 430.0 * t,
            60.0 + 380.0 * t,
            60.0 * (1.0 - t) + 8.0,
            0.7,
        )
    };
    // Start from a settled view (an event, not a frame count), so every frame is checked.
    assert!(s.settle(&cam_of(0), 120.0), "the first view did not settle");
    let mut checked = 0;
    let mut saw_fade = false;
    for i in 0..300usize {
        let cam = cam_of(i);
        s.update(&cam, 1.0 / 60.0);
        s.run_gpu_phases();
        if s.is_ready(NodeKey::ROOT) {
            assert_draw_list_partitions(&s, i as u64, 60);
            // At rest every drawn interval is [0, 1); a shorter one means a fade in progress.
            saw_fade |= s
                .draw_list()
                .iter()
                .any(|d| d.dither_hi - d.dither_lo < 1.0);
            checked += 1;
        }
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    assert_eq!(checked, 300, "the root was not ready in every frame");
    assert!(saw_fade, "no cross-fade was ever in progress");
}

/// The draw list runs front to back in plan view: along every ray from the camera's ground
/// point, the nodes under the ray come in list order, so a nearer node is drawn before the
/// ground it can hide (the depth test then rejects hidden pixels before they are shaded).
#[test]
fn the_draw_list_runs_front_to_back_along_every_ray_from_the_camera() {
    let mut s = streamer(settings(2));
    let tree = *s.tree();
    for (i, cam) in [
        cam_at(250.0, 240.0, 20.0, 0.3),
        cam_at(30.0, 470.0, 60.0, -0.9),
        cam_at(400.0, 90.0, 5.0, 2.4),
    ]
    .into_iter()
    .enumerate()
    {
        assert!(s.settle(&cam, 120.0), "view {i} did not settle");
        let list = s.draw_list();
        assert!(list.len() > 20, "view {i} drew only {} nodes", list.len());
        let (cx, cy) = (cam.position_m.x, cam.position_m.y);
        let reach_m = tree.map_size_m[0].hypot(tree.map_size_m[1]);
        for ray in 0..180 {
            let a = f64::from(ray) * std::f64::consts::TAU / 180.0 + 0.01;
            // (smallest, largest) list index of the nodes under the last point.
            let mut last: Option<(usize, usize)> = None;
            let mut t_m = 0.0;
            while t_m < reach_m {
                let (x, y) = (cx + a.cos() * t_m, cy + a.sin() * t_m);
                let under: Vec<usize> = list
                    .iter()
                    .enumerate()
                    .filter(|(_, d)| {
                        let r = tree.rect(d.key);
                        x >= r.min[0] && x < r.max[0] && y >= r.min[1] && y < r.max[1]
                    })
                    .map(|(j, _)| j)
                    .collect();
                if let (Some(&lo), Some(&hi)) = (under.iter().min(), under.iter().max()) {
                    if let Some((lo0, hi0)) = last {
                        assert!(
                            lo >= lo0 && hi >= hi0,
                            "view {i}, ray {ray} at {t_m} m: list entries {lo}..={hi} come \
                             before {lo0}..={hi0}, which are nearer the camera"
                        );
                    }
                    last = Some((lo, hi));
                }
                t_m += 1.0;
            }
        }
    }
}

/// Prefetch follows the camera: a camera flying east at 150 m/s gets every node that the
/// camera one second ahead wants requested (or ready) at once, while a still camera at the same
/// spot does not ask for all of them.
#[test]
fn a_moving_camera_prefetches_where_it_is_going() {
    let dt = 1.0 / 60.0;
    let start = cam_at(120.0, 250.0, 15.0, 0.0);
    let moved = |t: f64| {
        let mut a = start;
        a.position_m.x += 150.0 * t;
        a
    };
    let mut moving = streamer(settings(1));
    let mut still = streamer(settings(1));
    // The moving camera's velocity is known after its first step; its prediction 1 s ahead
    // is the camera at 1 s + dt.
    let ahead = moved(1.0 + dt);
    let mut only_ahead: Vec<Vec<NodeKey>> = Vec::new();
    for (s, second) in [(&mut moving, moved(dt)), (&mut still, start)] {
        assert!(s.settle(&start, 120.0));
        let split = s.settings.tau_px * s.settings.split_factor;
        // Bounds are only ever added, so a node wanted now is still wanted after the next
        // update, or an ancestor of wanted nodes, or a child of one: needed either way.
        let now = s.select_wanted(&start, split);
        only_ahead.push(
            s.select_wanted(&ahead, split)
                .difference(&now)
                .copied()
                .collect(),
        );
        s.update(&second, dt);
    }
    let covered = |s: &Streamer, keys: &[NodeKey]| {
        keys.iter()
            .filter(|&&k| s.is_ready(k) || s.is_requested(k))
            .count()
    };
    let (a, b) = (&only_ahead[0], &only_ahead[1]);
    assert!(a.len() > 4, "{} nodes only ahead", a.len());
    assert_eq!(covered(&moving, a), a.len(), "moving camera");
    assert!(
        covered(&still, b) < b.len(),
        "a still camera asks for everything ahead too: the test cannot tell prefetch apart"
    );
}

/// The guard band: after settling, turning the camera by less than the band's margin needs no
/// new node to draw: everything the new exact view's selection reaches at the display threshold
/// has its bounds and is ready at once. (With no guard band, `GUARD_BAND = 1`, this view reaches
/// nodes whose bounds are not even known.) The pixel bound includes the screen's off-axis
/// stretch, which a turn changes, so the request threshold's selection may change when the
/// camera only turns; the display threshold's margin over it covers that.
#[test]
fn turning_within_the_guard_band_needs_no_new_node() {
    // No lower-tau prefetch: only the guard band prepares ground outside the view.
    let mut s = streamer(StreamSettings {
        prefetch_factor: StreamSettings::default().split_factor,
        ..settings(2)
    });
    // Tilted 3 degrees further down: nearer, finer ground comes into view at the bottom.
    let tilted = |pitch_deg: f64| {
        let c = cam_at(200.0, 250.0, 20.0, 0.5);
        let p = pitch_deg.to_radians();
        let dir = DVec3::new(0.5f64.cos() * p.cos(), 0.5f64.sin() * p.cos(), -p.sin());
        Camera::look_at(c.position_m, c.position_m + dir, c.fovy_rad, c.viewport_px)
    };
    let (a, b) = (tilted(37.0), tilted(40.0));
    assert!(s.settle(&a, 120.0));
    let tree = *s.tree();
    let shown = s.settings.tau_px * s.settings.show_factor;
    let exact = |cam: &Camera| {
        engine::terrain::select::traverse(
            &tree,
            cam,
            true,
            |k| s.shared.bounds.peek(k),
            |_, _, _, px| px > shown,
        )
    };
    let after = exact(&b);
    assert!(
        after.unknown_bounds.is_empty(),
        "{:?}",
        after.unknown_bounds
    );
    for n in &after.nodes {
        assert!(s.is_ready(n.key), "{:?} came into view unprepared", n.key);
    }
}

/// A settled view draws the selection at the display threshold (`show_factor * tau`), not at
/// the request threshold (`split_factor * tau`): every node that selection reaches in the
/// guard band is drawn, and none of their descendants, though the finer nodes down to the
/// request threshold are resident (ready for the camera to come closer).
#[test]
fn a_settled_view_draws_the_selection_at_the_display_threshold() {
    let mut s = streamer(settings(2));
    let tree = *s.tree();
    let cam = cam_at(200.0, 250.0, 20.0, 0.5);
    assert!(s.settle(&cam, 120.0), "the view did not settle");
    let select = |factor: f64| {
        let px = s.settings.tau_px * factor;
        engine::terrain::select::traverse_in(
            &tree,
            &cam,
            Some(cam.frustum_widened(engine::stream::GUARD_BAND)),
            |k| s.shared.bounds.peek(k),
            |_, _, _, e| e > px,
        )
    };
    let shown = select(s.settings.show_factor);
    let requested = select(s.settings.split_factor);
    assert!(shown.unknown_bounds.is_empty() && requested.unknown_bounds.is_empty());
    let drawn: std::collections::HashSet<NodeKey> = s.draw_list().iter().map(|d| d.key).collect();
    for n in &shown.nodes {
        assert!(
            drawn.contains(&n.key),
            "{:?} is selected but not drawn",
            n.key
        );
    }
    let finer: Vec<NodeKey> = drawn
        .iter()
        .filter(|k| {
            k.ancestors()
                .any(|a| shown.nodes.iter().any(|n| n.key == a))
        })
        .copied()
        .collect();
    assert!(
        finer.is_empty(),
        "drawn finer than the selection: {finer:?}"
    );
    // Nothing the display wants is missing (no pop debt at rest).
    for k in s.shown_wanted() {
        assert!(
            drawn.contains(&k),
            "{k:?} is wanted by the display but not drawn"
        );
    }
    // The request threshold reaches finer nodes, all of them ready but not drawn.
    let waiting: Vec<NodeKey> = requested
        .nodes
        .iter()
        .map(|n| n.key)
        .filter(|k| !drawn.contains(k))
        .collect();
    assert!(
        waiting.len() > 10,
        "only {} requested nodes are not drawn",
        waiting.len()
    );
    for k in waiting {
        assert!(s.is_ready(k), "{k:?} was requested but is not ready");
    }
}

/// With the whole map out of view nothing is wanted, and the display wants nothing drawn
/// either, so a warm start there settles (nodebench's jet, 1,000 m over the tiny map, looks
/// past it).
#[test]
fn a_view_that_sees_no_map_wants_nothing_drawn() {
    let mut s = streamer(settings(1));
    let tree = *s.tree();
    let p = DVec3::new(tree.origin_m[0] - 2000.0, tree.origin_m[1] - 2000.0, 300.0);
    let cam = Camera::look_at(
        p,
        p + DVec3::new(-1.0, -1.0, 0.0),
        60f64.to_radians(),
        [640, 360],
    );
    assert!(s.settle(&cam, 120.0), "the view did not settle");
    assert!(s.wanted().is_empty(), "wanted {:?}", s.wanted());
    assert_eq!(s.shown_wanted(), Vec::<NodeKey>::new());
}

/// The per-frame GPU budget counts the GPU time the upload hooks expect their work to take
/// (`NodeWork::gpu_estimate_s`, e.g. a ground texture's measured GPU time), not only the frame
/// thread's time: at 1.5 ms a phase a 4 ms budget runs at most three phases a frame, where the
/// same waiting jobs without an estimate all run in one frame.
#[test]
fn the_gpu_budget_counts_the_expected_gpu_time_of_uploads() {
    let mut s = streamer(StreamSettings {
        gpu_budget_s: 4e-3,
        gpu_budget_bytes: usize::MAX,
        ..settings(2)
    });
    let cam = cam_at(256.0, 256.0, 20.0, 0.0);
    // No GPU phase runs yet: every finished job waits for one.
    loop {
        s.update(&cam, 1.0 / 60.0);
        if s.stats.queued + s.stats.running == 0 && s.stats.waiting_gpu > 0 {
            break;
        }
        std::thread::yield_now();
    }
    let waiting = s.stats.waiting_gpu;
    assert!(waiting >= 8, "only {waiting} jobs wait for the GPU");
    let ran = s.run_gpu_phases_with(&mut |_, w| w.gpu_estimate_s = 1.5e-3);
    assert!(
        (1..=3).contains(&ran),
        "{ran} phases of 1.5 ms ran under a 4 ms budget"
    );
    let rest = s.run_gpu_phases_with(&mut |_, w| w.gpu_estimate_s = 0.0);
    assert!(
        rest > 3,
        "without an estimate only {rest} of the {} waiting phases ran",
        waiting - ran
    );
}

/// A warm start in flight (`settle_along` with the path ahead) leaves resident, besides the
/// view, the nodes wanted at the path's farthest predicted camera; a warm start at rest
/// (`settle`) does not, so the comparison shows what the path adds.
#[test]
fn a_warm_start_along_the_path_makes_the_path_ahead_resident() {
    use engine::stream::predict::PREDICT_HORIZONS_S;
    let cam = flight(0);
    let future: Vec<(f64, Camera)> = (1..)
        .zip(PREDICT_HORIZONS_S)
        .map(|(i, h)| (h, flight(10 * i)))
        .collect();
    let far = future[future.len() - 1].1;
    let settings = settings(2);
    let split_px = settings.tau_px * settings.split_factor;
    let missing_at_far = |s: &Streamer| {
        let wanted = s.select_wanted(&far, split_px);
        assert!(!wanted.is_empty());
        wanted.iter().filter(|k| s.resident(**k).is_none()).count()
    };
    let mut along = streamer(settings);
    assert!(along.settle_along(&cam, &future, 120.0), "did not settle");
    assert_eq!(
        missing_at_far(&along),
        0,
        "nodes wanted at the path's end are not resident after a warm start along it"
    );
    let mut rest = streamer(settings);
    assert!(rest.settle(&cam, 120.0), "did not settle at rest");
    assert!(
        missing_at_far(&rest) > 0,
        "the path's end was resident after a warm start at rest too: this test shows nothing"
    );
}
