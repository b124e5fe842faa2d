//! The viewer's prefetch along a known path (`Viewer::path_ahead`, what the flyover sets for
//! its automatic and replayed flights): frames drawn at rest with the path ahead set make the
//! path's end resident, frames without it do not.

use engine::camera::Camera;
use engine::render::{COLOR_FORMAT, Target};
use engine::stream::predict::PREDICT_HORIZONS_S;
use engine::viewer::Viewer;
use glam::DVec3;
use tests::gpu::{device, frame, settle, tiny_viewer};
use tests::terrain::tiny_world;

const SIZE_PX: [u32; 2] = [160, 90];
const TAU_PX: f64 = 1.0;

/// A camera of a flight across the tiny map, `t` from 0 to 1.
fn flight_at(t: f64) -> Camera {
    thread_local! {
        static WORLD: engine::surface::world::World = tiny_world();
    }
    let (x, y) = (60.0 + 390.0 * t, 80.0 + 300.0 * t);
    let p = DVec3::new(x, y, WORLD.with(|w| w.height_m(x, y)) + 30.0);
    let yaw: f64 = 0.6 + t;
    let dir = DVec3::new(yaw.cos() * 0.8, yaw.sin() * 0.8, -0.6);
    Camera::look_at(p, p + dir, 60f64.to_radians(), SIZE_PX)
}

/// Nodes wanted at `far` that `v` does not hold.
fn missing_at(v: &Viewer, far: &Camera) -> usize {
    let s = &v.streamer;
    let wanted = s.select_wanted(far, s.settings.tau_px * s.settings.split_factor);
    assert!(!wanted.is_empty());
    wanted.iter().filter(|k| s.resident(**k).is_none()).count()
}

#[test]
fn frames_with_the_path_ahead_set_prefetch_along_it_and_use_it_once() {
    let Some(g) = device() else { return };
    let target = Target::new(&g.device, SIZE_PX, COLOR_FORMAT);
    let here = flight_at(0.0);
    // The path ahead: the same flight, far on (the camera itself stays at its start, so a
    // velocity-based prediction would predict nothing).
    let future: Vec<(f64, Camera)> = (1..)
        .zip(PREDICT_HORIZONS_S)
        .map(|(i, h)| (h, flight_at(0.25 * f64::from(i))))
        .collect();
    let far = future[future.len() - 1].1;

    let mut with_path = tiny_viewer(&g, TAU_PX);
    // Settled: quiet (no job in flight, no request left for a later frame, no pop debt) for as
    // many frames in a row as the prefetch has parts plus one. A frame recomputes one part
    // with the bounds known by then, so nodes whose bounds the last jobs brought are asked for
    // only when their part's turn comes (the deeper selection of the on-screen bound needs more
    // of these rounds), and a frame whose worker held the job queue leaves its requests to the
    // next one.
    let quiet_needed = PREDICT_HORIZONS_S.len() + 2;
    let (mut quiet, mut settled) = (0, false);
    for _ in 0..20_000 {
        with_path.path_ahead.clone_from(&future);
        let deferred = with_path.streamer.stats.requests_deferred;
        let st = frame(&g, &mut with_path, &target, &here, 0.05);
        assert!(
            with_path.path_ahead.is_empty(),
            "a frame left the path ahead set for the next one"
        );
        let calm = with_path.streamer.in_flight() == 0
            && st.pop_debt_nodes == 0
            && with_path.streamer.stats.requests_deferred == deferred;
        quiet = if calm { quiet + 1 } else { 0 };
        if quiet >= quiet_needed {
            settled = true;
            break;
        }
        std::thread::yield_now();
    }
    assert!(settled, "the view with the path ahead did not settle");
    assert_eq!(
        missing_at(&with_path, &far),
        0,
        "nodes wanted at the path's end are not resident after frames along it"
    );

    let mut without = tiny_viewer(&g, TAU_PX);
    settle(&g, &mut without, &target, &here);
    assert!(
        missing_at(&without, &far) > 0,
        "the path's end was resident without the path too: this test shows nothing"
    );
}
