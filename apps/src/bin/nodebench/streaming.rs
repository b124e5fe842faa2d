//! Section `streaming`: real-time flights through the streaming system (latency, cancelled
//! jobs, pop debt, bookkeeping per frame).

use crate::open_world;
use crate::pilots::{Pilot, PilotChoice};
use crate::report::{Report, bar};
use crate::span::Span;
use anyhow::{Result, bail};
use engine::camera::Camera;
use engine::ground::content::NodeGround;
use engine::lighting::content::{LightingContent, NodeLight};
use engine::render::Gpu;
use engine::render::terrain::TerrainNodeGpu;
use engine::stream::Streamer;
use engine::surface::World;
use engine::viewer::Viewer;
use std::time::Instant;

/// A closed loop over the map at `above_m` over the ground (or the water), flown at
/// `speed_m_s`: the camera `t_s` seconds into the flight.
pub(crate) fn loop_camera(
    world: &World,
    (speed_m_s, above_m): (f64, f64),
    t_s: f64,
    viewport_px: [u32; 2],
) -> Camera {
    let o = world.origin_m();
    let s = world.size_m();
    let (cx, cy) = (o[0] + 0.5 * s[0], o[1] + 0.5 * s[1]);
    let (rx, ry) = (0.32 * s[0], 0.28 * s[1]);
    let circumference = std::f64::consts::TAU * f64::midpoint(rx * rx, ry * ry).sqrt();
    let a = std::f64::consts::TAU * (t_s * speed_m_s / circumference);
    let (x, y) = (cx + rx * a.cos(), cy + ry * a.sin());
    let z = world.height_m(x, y).max(world.map.manifest.water_level_m) + above_m;
    let tangent = glam::DVec3::new(-rx * a.sin(), ry * a.cos(), 0.0).normalize();
    let dir = (tangent + glam::DVec3::new(0.0, 0.0, -0.25)).normalize();
    let pos = glam::DVec3::new(x, y, z);
    Camera::look_at(pos, pos + dir, 60f64.to_radians(), viewport_px)
}

/// Flights: (speed m/s, height above the ground m). The last is a jet.
pub(crate) const FLIGHTS: [(f64, f64); 4] =
    [(50.0, 40.0), (150.0, 40.0), (300.0, 40.0), (1000.0, 1000.0)];

/// The pilots that hide their future fly from this speed on (m/s).
const HIDDEN_FROM_M_S: f64 = 150.0;

/// The seed of the hidden pilots' manoeuvres (every run flies the same paths).
const PILOT_SEED: u64 = 1;

/// A flight's streaming: the streamer alone, or with a GPU the viewer's streaming with every
/// renderer's upload hook (ground textures rendered under the per-frame GPU budget), nothing
/// drawn.
enum Flight<'g> {
    Cpu(Box<Streamer>),
    Gpu(&'g Gpu, Box<Viewer>),
}

impl<'g> Flight<'g> {
    /// The flight's streaming of `world` with `kinds`, through the viewer where there is a GPU.
    fn new(
        world: engine::surface::World,
        settings: engine::stream::StreamSettings,
        kinds: &[engine::kinds::Registration],
        gpu: Option<&'g Gpu>,
    ) -> Self {
        match gpu {
            Some(g) => Flight::Gpu(
                g,
                Box::new(Viewer::with_kinds(
                    g,
                    wgpu::TextureFormat::Rgba8UnormSrgb,
                    world,
                    settings,
                    kinds,
                )),
            ),
            None => Flight::Cpu(Box::new(Streamer::new(
                world,
                settings,
                kinds
                    .iter()
                    .map(|k| std::sync::Arc::clone(&k.kind))
                    .collect(),
            ))),
        }
    }

    fn streamer(&self) -> &Streamer {
        match self {
            Flight::Cpu(s) => s,
            Flight::Gpu(_, v) => &v.streamer,
        }
    }

    fn streamer_mut(&mut self) -> &mut Streamer {
        match self {
            Flight::Cpu(s) => s,
            Flight::Gpu(_, v) => &mut v.streamer,
        }
    }

    /// Streams until `cam`'s view is ready (at most `timeout_s`) and, with `future` (the path
    /// ahead, as in [`Streamer::update_along`]), what the prefetch along it requests, as for
    /// a camera already in flight; without, as for a camera at rest. Then waits until the
    /// light grids of the nodes it draws are computed (the other live grids, of resident nodes
    /// not drawn, go on in the background during the flight); on timeout, what it still
    /// waited on.
    fn settle(
        &mut self,
        cam: &Camera,
        future: Option<&[(f64, Camera)]>,
        timeout_s: f64,
    ) -> Result<(), String> {
        let ready = self.settle_streaming(cam, future, timeout_s);
        if let Some(l) = self.streamer().shared.kind::<LightingContent>() {
            l.wait_drawn_lit();
        }
        ready
    }

    fn settle_streaming(
        &mut self,
        cam: &Camera,
        future: Option<&[(f64, Camera)]>,
        timeout_s: f64,
    ) -> Result<(), String> {
        let dt_s = 1.0 / 60.0;
        match self {
            Flight::Cpu(s) => {
                let settled = match future {
                    Some(f) => s.settle_along(cam, f, timeout_s),
                    None => s.settle(cam, timeout_s),
                };
                if settled {
                    Ok(())
                } else {
                    Err(format!("{} requests in flight", s.in_flight()))
                }
            }
            Flight::Gpu(gpu, v) => {
                let start = Instant::now();
                while !match future {
                    Some(f) => v.stream_only_along(gpu, cam, dt_s, f),
                    None => v.stream_only(gpu, cam, dt_s),
                } {
                    if start.elapsed().as_secs_f64() > timeout_s {
                        return Err(v.outstanding().to_string());
                    }
                    std::thread::yield_now();
                }
                Ok(())
            }
        }
    }

    /// One frame's streaming: the update along the known path (`future`), or without one
    /// extrapolating the camera's velocity as for a pilot by hand; then the GPU phases.
    /// Returns the time of each.
    fn frame(&mut self, cam: &Camera, dt_s: f64, future: Option<&[(f64, Camera)]>) -> [Span; 2] {
        let t = Span::start();
        match future {
            Some(f) => self.streamer_mut().update_along(cam, dt_s, f),
            None => self.streamer_mut().update(cam, dt_s),
        }
        let update = t.stop();
        let t = Span::start();
        match self {
            Flight::Cpu(s) => {
                s.run_gpu_phases();
            }
            Flight::Gpu(gpu, v) => v.upload_and_finish(gpu),
        }
        [update, t.stop()]
    }
}

/// How a flight's warm start leaves the streamer.
#[derive(Clone, Copy, PartialEq)]
enum WarmStart {
    /// As for a camera already in flight: what the prefetch along the path's next seconds
    /// requests is resident too.
    InFlight,
    /// As for a camera at rest about to start: the flight's first frames measure the
    /// start-up, the path's prefetch all requested at once.
    AtRest,
}

/// One streaming run.
#[derive(Clone, Copy)]
struct Run {
    /// (speed m/s, height above the ground m), one of [`FLIGHTS`].
    flight: (f64, f64),
    workers: usize,
    textures: bool,
    lighting: bool,
    towns: bool,
    start: WarmStart,
    /// A pilot whose future the streamer cannot read; none: the loop, its path known.
    pilot: Option<Pilot>,
}

impl Run {
    /// Everything on, warm start in flight.
    fn all_on(flight: (f64, f64), workers: usize) -> Self {
        Run {
            flight,
            workers,
            textures: true,
            lighting: true,
            towns: true,
            start: WarmStart::InFlight,
            pilot: None,
        }
    }

    /// Of `pilots` (none named: all): with the known path, every flight with each of
    /// `worker_counts` and ground textures, light grids and the map's houses on; when no pilot
    /// is named, with 1 worker also the same from rest, ground textures off with light grids
    /// on and off, and (on a map with `houses`) the houses off. Then each hidden pilot at the
    /// flights from [`HIDDEN_FROM_M_S`] with each of `worker_counts`, everything on, and at
    /// 300 m/s with 1 worker also with ground textures and light grids off (what the geometry
    /// alone asks of the worker).
    fn all(worker_counts: &[usize], houses: usize, pilots: &[PilotChoice]) -> Vec<Run> {
        let flies = |p: PilotChoice| pilots.is_empty() || pilots.contains(&p);
        let variants = pilots.is_empty();
        let hidden = Pilot::ALL
            .into_iter()
            .filter(|&p| flies(PilotChoice::Hidden(p)))
            .flat_map(|pilot| {
                FLIGHTS
                    .iter()
                    .filter(|f| f.0 >= HIDDEN_FROM_M_S)
                    .flat_map(move |&f| {
                        let geometry_only = Run {
                            pilot: Some(pilot),
                            textures: false,
                            lighting: false,
                            ..Run::all_on(f, 1)
                        };
                        worker_counts
                            .iter()
                            .map(move |&w| Run {
                                pilot: Some(pilot),
                                ..Run::all_on(f, w)
                            })
                            .chain((f.0 == 300.0).then_some(geometry_only))
                    })
            });
        FLIGHTS
            .iter()
            .filter(|_| flies(PilotChoice::Known))
            .flat_map(|&f| {
                let one = Run::all_on(f, 1);
                let others = [
                    Run {
                        start: WarmStart::AtRest,
                        ..one
                    },
                    Run {
                        textures: false,
                        ..one
                    },
                    Run {
                        textures: false,
                        lighting: false,
                        ..one
                    },
                ]
                .into_iter()
                .chain((houses > 0).then_some(Run {
                    towns: false,
                    ..one
                }))
                .filter(move |_| variants);
                worker_counts
                    .iter()
                    .map(move |&w| Run::all_on(f, w))
                    .chain(others)
            })
            .chain(hidden)
            .collect()
    }

    /// The registered content kinds of `world`, less those this run turns off.
    fn kinds(&self, world: &World) -> Vec<engine::kinds::Registration> {
        let mut kinds = engine::kinds::registered(world);
        if !self.textures {
            kinds.retain(|k| k.kind.name() != engine::ground::content::GroundContent::NAME);
        }
        if !self.lighting {
            kinds.retain(|k| k.kind.name() != LightingContent::NAME);
        }
        if !self.towns {
            kinds.retain(|k| k.kind.name() != engine::objects::content::ObjectsContent::NAME);
        }
        kinds
    }

    /// The rows' parameters: the flight of `seconds` at `tau_px` on a map with `houses`,
    /// streamed by `workers`, and the adapter that renders the ground textures.
    fn params(
        &self,
        (seconds, tau_px): (f64, f64),
        workers: usize,
        houses: usize,
        adapter: Option<&str>,
    ) -> String {
        let (speed, above) = self.flight;
        let horizons_s = engine::stream::predict::PREDICT_HORIZONS_S;
        let pilot = self.pilot.map_or(String::new(), |p| {
            format!(
                "hidden-future pilot {}, seed {PILOT_SEED}: the streamer sees each camera as it \
                 comes and extrapolates its velocity; ",
                p.describe()
            )
        });
        format!(
            "{pilot}{speed} m/s at {above} m, {seconds} s at 60 Hz, tau {tau_px} px, warm start \
             {}, {} worker(s), houses {}, light grids {}, ground textures {}",
            match (self.start, self.pilot) {
                (WarmStart::AtRest, _) => "at rest (the start-up measured)".to_string(),
                (WarmStart::InFlight, None) => format!(
                    "in flight (what the prefetch along the path's next {} s requests resident)",
                    horizons_s[horizons_s.len() - 1]
                ),
                (WarmStart::InFlight, Some(_)) => "in flight (what extrapolating the first \
                                                    frame's velocity requests resident)"
                    .to_string(),
            },
            workers,
            if !self.towns {
                "off".to_string()
            } else if houses == 0 {
                "none on this map".to_string()
            } else {
                format!("on ({houses})")
            },
            if self.lighting { "on" } else { "off" },
            match (self.textures, adapter) {
                (false, _) => "off".to_string(),
                (true, Some(adapter)) => format!(
                    "on (rendered on {adapter} under the per-frame GPU budget; uploads of every \
                     kind, nothing drawn)"
                ),
                (true, None) => "on (no GPU adapter: CPU side only, the decal pieces; no \
                                 texture is made or counted in the cache budget)"
                    .to_string(),
            }
        )
    }
}

pub(crate) fn section_streaming(
    world_path: &std::path::Path,
    r: &mut Report,
    quick: bool,
    workers: usize,
    viewport_px: [u32; 2],
    gpu: Option<(&Gpu, &str)>,
    speeds: &[f64],
    pilots: &[PilotChoice],
) -> Result<()> {
    use engine::stream::StreamSettings;
    let dt = 1.0 / 60.0;
    let seconds = if quick { 2.0 } else { 12.0 };
    let frames = (seconds / dt) as usize;
    let tau = 2.0;
    let worker_counts: Vec<usize> = if workers > 1 {
        vec![1, workers]
    } else {
        vec![1]
    };
    for busy in [0].into_iter().chain(worker_counts.iter().copied()) {
        scheduling_noise(r, frames, dt, busy);
    }
    let houses = open_world(world_path)?.map.buildings.len();
    let flown = |run: &Run| speeds.is_empty() || speeds.contains(&run.flight.0);
    for run in Run::all(&worker_counts, houses, pilots)
        .into_iter()
        .filter(flown)
    {
        let Run {
            flight,
            workers,
            lighting,
            start: warm_start,
            ..
        } = run;
        let speed = flight.0;
        let world = open_world(world_path)?;
        let (warm_cam, cams, future) = flight_cameras(&world, &run, frames, dt, viewport_px);
        let settings = StreamSettings {
            tau_px: tau,
            ..StreamSettings::default()
        }
        .with_workers(workers);
        let kinds = run.kinds(&world);
        let mut flight_run = Flight::new(world, settings, &kinds, gpu.map(|(g, _)| g));
        // Warm start at the first camera, as after loading: in flight along the path, or at
        // rest.
        // In flight: the known path's first look ahead, or for a hidden pilot what its first
        // frame's velocity extrapolates.
        let warm_ahead = match &future {
            Some(future) => future[0].clone(),
            None => engine::stream::predict::extrapolate(
                &warm_cam,
                (cams[0].position_m - warm_cam.position_m) / dt,
            ),
        };
        let path_ahead = (warm_start == WarmStart::InFlight).then_some(warm_ahead.as_slice());
        if let Err(left) = flight_run.settle(&warm_cam, path_ahead, 600.0) {
            bail!("streaming at {speed} m/s: the warm start did not settle within 600 s ({left})");
        }
        flight_run.streamer_mut().take_latencies();
        let s = flight_run.streamer();
        let c0 = s.stats.cancelled_queued + s.stats.cancelled_running + s.stats.cancelled_gpu;
        let evicted0 = s.stats.evicted;
        let deferred0 = s.stats.requests_deferred;
        let budget_bytes = s.settings.cache_budget_bytes;
        let b = bar(frames as u64, &format!("streaming {speed} m/s"));
        let (mut debt_frames, mut worst_excess, mut frame_times) =
            (0usize, 0.0f64, Vec::with_capacity(frames));
        let mut stages = Vec::with_capacity(frames);
        // Light debt: frames with a visible drawn node whose light grid is not computed yet
        // (drawn fully lit), and the share of such nodes over all frames; texture debt: the
        // same for nodes whose own ground texture is not made yet (they show an ancestor's).
        let (mut unlit_frames, mut unlit_nodes, mut lit_checked) = (0usize, 0usize, 0usize);
        // Of those, the ones no computed ancestor's grid shades either (drawn fully lit).
        let (mut fully_lit_frames, mut fully_lit_nodes) = (0usize, 0usize);
        let (mut bare_frames, mut bare_nodes, mut textured_checked) = (0usize, 0usize, 0usize);
        // Residency: frames whose pinned nodes (needed, prefetched, drawn, in a fade) alone
        // exceed the cache budget, where nothing else stays and a node leaving the pinned sets
        // is evicted at once.
        let (mut over_budget_frames, mut pinned_peak_bytes) = (0usize, 0usize);
        // The camera moves by the flight's clock (frame f shows the camera at f dt); a frame
        // that starts more than a frame after its time is late, and the flight's real length
        // is reported beside the one it says.
        let mut late_frames = 0usize;
        let start = Instant::now();
        for (f, cam) in cams.iter().enumerate() {
            late_frames += usize::from(start.elapsed().as_secs_f64() > (f + 1) as f64 * dt);
            frame_times.push(flight_run.frame(cam, dt, future.as_ref().map(|p| p[f].as_slice())));
            let s = flight_run.streamer();
            stages.push(s.stats.last_update);
            let debts = frame_debts(s, cam, tau);
            lit_checked += debts.lit_checked;
            if debts.excess_px > 0.0 {
                debt_frames += 1;
                worst_excess = worst_excess.max(debts.excess_px);
            }
            unlit_frames += usize::from(debts.unlit > 0);
            unlit_nodes += debts.unlit;
            fully_lit_frames += usize::from(debts.fully_lit > 0);
            fully_lit_nodes += debts.fully_lit;
            textured_checked += debts.textured_checked;
            bare_frames += usize::from(debts.without_texture > 0);
            bare_nodes += debts.without_texture;
            let pinned_bytes = s.pinned_bytes();
            over_budget_frames += usize::from(pinned_bytes > budget_bytes);
            pinned_peak_bytes = pinned_peak_bytes.max(pinned_bytes);
            b.inc(1);
            // Real time: frame f ends at (f + 1) * dt.
            let due = (f + 1) as f64 * dt;
            let now = start.elapsed().as_secs_f64();
            if now < due {
                std::thread::sleep(std::time::Duration::from_secs_f64(due - now));
            }
        }
        b.finish_and_clear();
        let clock = Clock {
            planned_s: frames as f64 * dt,
            real_s: start.elapsed().as_secs_f64(),
            late_frames,
            frames,
        };
        let s = flight_run.streamer_mut();
        let cancelled =
            s.stats.cancelled_queued + s.stats.cancelled_running + s.stats.cancelled_gpu - c0;
        let params = clock.mark(&run.params(
            (seconds, tau),
            s.settings.workers,
            houses,
            gpu.map(|(_, adapter)| adapter),
        ));
        clock.report(r, &params);
        let outcome = FlightOutcome {
            requests_deferred: s.stats.requests_deferred - deferred0,
            latencies: s.take_latencies(),
            cancelled,
            debt_share: debt_frames as f64 / frames as f64,
            worst_excess_px: worst_excess,
            frame_times,
            stages,
            light_debt: lighting.then(|| {
                [
                    unlit_frames as f64 / frames as f64,
                    unlit_nodes as f64 / lit_checked.max(1) as f64,
                    fully_lit_frames as f64 / frames as f64,
                    fully_lit_nodes as f64 / lit_checked.max(1) as f64,
                ]
            }),
            texture_debt: (run.textures && gpu.is_some()).then(|| {
                (
                    bare_frames as f64 / frames as f64,
                    bare_nodes as f64 / textured_checked.max(1) as f64,
                )
            }),
            residency: Residency {
                budget_bytes,
                over_budget_share: over_budget_frames as f64 / frames as f64,
                pinned_peak_bytes,
                evicted: s.stats.evicted - evicted0,
            },
        };
        outcome.report(r, &params);
    }
    Ok(())
}

/// A known path: per frame, the path ahead (see [`engine::stream::predict::along`]).
type PathAhead = Vec<Vec<(f64, Camera)>>;

/// The cameras of `run`'s flight: the warm start's, then one per frame; with the path ahead
/// of each frame when it is known. The replayed loop's path is known: prefetch follows it. A
/// hidden pilot's cameras come one a frame, after the warm start at its first.
fn flight_cameras(
    world: &World,
    run: &Run,
    frames: usize,
    dt: f64,
    viewport_px: [u32; 2],
) -> (Camera, Vec<Camera>, Option<PathAhead>) {
    let flight = run.flight;
    match run.pilot {
        None => {
            let cams: Vec<Camera> = (0..frames)
                .map(|f| loop_camera(world, flight, f as f64 * dt, viewport_px))
                .collect();
            let future: PathAhead = (0..frames)
                .map(|f| {
                    engine::stream::predict::along(f as f64 * dt, |t_s| {
                        loop_camera(world, flight, t_s, viewport_px)
                    })
                })
                .collect();
            (cams[0], cams, Some(future))
        }
        Some(pilot) => {
            let mut cams = crate::pilots::fly(
                world,
                pilot,
                flight,
                frames + 1,
                dt,
                viewport_px,
                PILOT_SEED,
            );
            let first = cams.remove(0);
            (first, cams, None)
        }
    }
}

/// One frame's debts over its visible drawn nodes.
#[derive(Default)]
struct FrameDebts {
    /// The largest excess over tau (pop debt when above 0).
    excess_px: f64,
    /// Nodes with a light grid, how many of them still lack it, and how many of those no
    /// resident ancestor's computed grid shades (drawn fully lit).
    lit_checked: usize,
    unlit: usize,
    fully_lit: usize,
    /// Nodes with a ground texture, and how many of them do not have their own made yet.
    textured_checked: usize,
    without_texture: usize,
}

/// One frame's debts (see [`FrameDebts`]).
fn frame_debts(s: &Streamer, cam: &Camera, tau: f64) -> FrameDebts {
    // Pop debt as the viewer's panel counts it; light and texture debt over the same visible
    // drawn nodes' content.
    let visible = s.visible_drawn(cam, tau);
    let mut out = FrameDebts {
        excess_px: s.excess_over_tau_px(cam, tau, &visible),
        ..FrameDebts::default()
    };
    for d in &visible {
        let Some(res) = s.resident(d.key) else {
            continue; // not resident: nothing drawn
        };
        if let Some(l) = res.work.get::<NodeLight>() {
            out.lit_checked += 1;
            if l.grid.grid().is_none() {
                out.unlit += 1;
                let ancestor_lit = d.key.ancestors().any(|a| {
                    s.resident(a)
                        .and_then(|r| r.work.get::<NodeLight>())
                        .is_some_and(|l| l.grid.grid().is_some())
                });
                out.fully_lit += usize::from(!ancestor_lit);
            }
        }
        if res.work.get::<NodeGround>().is_some() {
            out.textured_checked += 1;
            let own = res.work.gpu.get::<TerrainNodeGpu>();
            out.without_texture += usize::from(own.is_none_or(|t| t.ground_slot().is_none()));
        }
    }
    out
}

/// The machine's own scheduling noise, next to the bookkeeping rows: a fixed amount of
/// single-threaded work (about 1 ms, calibrated first) per 60 Hz frame while `busy` other
/// threads compute without pause (as node workers do in a flight), at their lowest priority.
/// What its p99 adds over its p50 is what the operating system (and, in a virtual machine, the
/// host) adds to any per-frame time here; bookkeeping percentiles are no better than that.
fn scheduling_noise(r: &mut Report, frames: usize, dt: f64, busy: usize) {
    let work = |n: u64| {
        let mut x = 0u64;
        for i in 0..n {
            x = x.wrapping_add(i ^ (x >> 3));
        }
        std::hint::black_box(x)
    };
    let t = Instant::now();
    work(1_000_000);
    let per_ms = (1_000_000.0 / (t.elapsed().as_secs_f64() * 1e3)) as u64;
    let stop = std::sync::atomic::AtomicBool::new(false);
    let mut times = Vec::with_capacity(frames);
    std::thread::scope(|scope| {
        for _ in 0..busy {
            scope.spawn(|| {
                engine::stream::lower_priority();
                while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                    work(per_ms / 10);
                }
            });
        }
        let start = Instant::now();
        for f in 0..frames {
            let t = Instant::now();
            work(per_ms);
            times.push(t.elapsed().as_secs_f64());
            let due = (f + 1) as f64 * dt;
            let now = start.elapsed().as_secs_f64();
            if now < due {
                std::thread::sleep(std::time::Duration::from_secs_f64(due - now));
            }
        }
        stop.store(true, std::sync::atomic::Ordering::Relaxed);
    });
    let params = format!(
        "fixed ~1 ms of work per frame, {frames} frames at 60 Hz, {busy} busy low-priority thread(s)"
    );
    r.quantiles("streaming", times, &P50_P99, &params, |q| {
        format!("scheduling noise reference {q}")
    });
}

/// What one streaming flight measured.
struct FlightOutcome {
    latencies: Vec<engine::stream::JobLatency>,
    cancelled: u64,
    /// Updates that left their requests to the next one (a worker held the job queue).
    requests_deferred: u64,
    /// Share of frames with pop debt.
    debt_share: f64,
    worst_excess_px: f64,
    /// Per frame: the streamer's update (the bookkeeping) and the GPU phases.
    frame_times: Vec<[Span; 2]>,
    /// Per frame: where the update's time went.
    stages: Vec<engine::stream::UpdateStages>,
    /// With light grids: the share of frames with a visible drawn node still without its grid,
    /// and the share of visible drawn nodes (over all frames) without it; then the same for
    /// nodes that no resident ancestor's computed grid shades either (drawn fully lit).
    light_debt: Option<[f64; 4]>,
    /// With ground textures rendered: the same for nodes whose own texture is not made yet
    /// (drawn with their nearest resident ancestor's).
    texture_debt: Option<(f64, f64)>,
    residency: Residency,
}

/// A flight against its clock: how long it says it lasts, how long it took, and the frames that
/// started more than a frame after their time.
struct Clock {
    planned_s: f64,
    real_s: f64,
    late_frames: usize,
    frames: usize,
}

impl Clock {
    /// The real length over which a flight counts as having run slower than it says.
    const SLOW_FACTOR: f64 = 1.05;

    /// `params`, marked when the flight ran slower than it says (every row of it then shows).
    fn mark(&self, params: &str) -> String {
        if self.real_s > self.planned_s * Self::SLOW_FACTOR {
            format!(
                "{params}; RAN SLOW: {:.1} s for {:.1} s, {} of {} frames late",
                self.real_s, self.planned_s, self.late_frames, self.frames
            )
        } else {
            params.to_string()
        }
    }

    fn report(&self, r: &mut Report, params: &str) {
        r.add(
            "streaming",
            "flight's real duration",
            self.real_s,
            "s",
            &format!("{params}; the flight says {:.1} s", self.planned_s),
        );
        r.add(
            "streaming",
            "frames started more than a frame late",
            self.late_frames as f64 / self.frames.max(1) as f64 * 100.0,
            "%",
            params,
        );
    }
}

/// The node cache over one flight.
struct Residency {
    budget_bytes: usize,
    /// Share of frames whose pinned nodes alone exceed the budget.
    over_budget_share: f64,
    /// The largest bytes of pinned resident nodes after a frame.
    pinned_peak_bytes: usize,
    /// Nodes evicted during the flight.
    evicted: u64,
}

impl FlightOutcome {
    /// The job and update counts of the flight: `completed` jobs, `needed` of them for
    /// display before they were ready.
    fn report_counts(&self, completed: usize, needed: usize, r: &mut Report, params: &str) {
        r.add(
            "streaming",
            "jobs completed",
            completed as f64,
            "jobs",
            params,
        );
        r.add(
            "streaming",
            "jobs needed for display before they were ready",
            needed as f64,
            "jobs",
            params,
        );
        r.add(
            "streaming",
            "jobs cancelled",
            self.cancelled as f64,
            "jobs",
            params,
        );
        r.add(
            "streaming",
            "updates that left their requests to the next update",
            self.requests_deferred as f64,
            "updates",
            &format!(
                "{params}; a worker held the job queue, and the frame thread does not wait for it"
            ),
        );
    }

    fn report(self, r: &mut Report, params: &str) {
        let mut request: Vec<f64> = self
            .latencies
            .iter()
            .map(|l| l.request_to_ready_s)
            .collect();
        let mut need: Vec<f64> = self
            .latencies
            .iter()
            .filter_map(|l| l.need_to_ready_s)
            .collect();
        request.sort_by(f64::total_cmp);
        need.sort_by(f64::total_cmp);
        for (name, p) in [("p50", 0.5), ("p95", 0.95), ("p99", 0.99)] {
            r.add(
                "streaming",
                &format!("request-to-ready latency {name}"),
                apps::percentile(&request, p) * 1e3,
                "ms",
                &format!("{params}; every job, prefetch included"),
            );
        }
        for (name, p) in [("p50", 0.5), ("p95", 0.95), ("p99", 0.99)] {
            r.add(
                "streaming",
                &format!("need-to-ready latency {name}"),
                if need.is_empty() {
                    0.0
                } else {
                    apps::percentile(&need, p) * 1e3
                },
                "ms",
                &format!(
                    "{params}; from the frame a node was first needed for display to ready, the {} jobs needed before they were ready",
                    need.len()
                ),
            );
        }
        let mut gpu_phases: Vec<f64> = self.latencies.iter().map(|l| l.gpu_phases_s).collect();
        gpu_phases.sort_by(f64::total_cmp);
        for (name, p) in [("p50", 0.5), ("p99", 0.99)] {
            r.add(
                "streaming",
                &format!("GPU phases per node {name}"),
                apps::percentile(&gpu_phases, p) * 1e6,
                "µs",
                &format!(
                    "{params}; the frame thread's time in a node's GPU phases and upload hooks, \
                     {} nodes; not the deferred work (ground textures, impostor bakes)",
                    gpu_phases.len()
                ),
            );
        }
        self.report_counts(request.len(), need.len(), r, params);
        r.add(
            "streaming",
            "pop debt (frames with a drawn node over tau)",
            100.0 * self.debt_share,
            "%",
            params,
        );
        if let Some([frames, nodes, fully_lit_frames, fully_lit_nodes]) = self.light_debt {
            r.add(
                "streaming",
                "light debt (frames with a drawn node still without its light grid)",
                100.0 * frames,
                "%",
                params,
            );
            r.add(
                "streaming",
                "drawn nodes without their light grid (share over all frames)",
                100.0 * nodes,
                "%",
                params,
            );
            let params = format!(
                "{params}; a node without its own grid is shaded by its nearest resident \
                 ancestor's computed grid, if any"
            );
            r.add(
                "streaming",
                "frames with a drawn node fully lit (neither its grid nor an ancestor's computed)",
                100.0 * fully_lit_frames,
                "%",
                &params,
            );
            r.add(
                "streaming",
                "drawn nodes fully lit (share over all frames)",
                100.0 * fully_lit_nodes,
                "%",
                &params,
            );
        }
        if let Some((frames, nodes)) = self.texture_debt {
            let params = format!("{params}; such a node shows its nearest ancestor's texture");
            r.add(
                "streaming",
                "texture debt (frames with a drawn node still without its own ground texture)",
                100.0 * frames,
                "%",
                &params,
            );
            r.add(
                "streaming",
                "drawn nodes without their own ground texture (share over all frames)",
                100.0 * nodes,
                "%",
                &params,
            );
        }
        r.add(
            "streaming",
            "worst excess over tau",
            self.worst_excess_px,
            "px",
            params,
        );
        let c = &self.residency;
        let budget = format!("{params}; node-cache budget {} MiB", c.budget_bytes >> 20);
        r.add(
            "streaming",
            "frames whose pinned nodes exceed the cache budget",
            100.0 * c.over_budget_share,
            "%",
            &format!(
                "{budget}; pinned: needed, prefetched, drawn or in a fade; over the budget \
                 nothing else stays, and a node leaving those sets is evicted at once"
            ),
        );
        r.add(
            "streaming",
            "pinned bytes, largest after a frame",
            c.pinned_peak_bytes as f64 / f64::from(1u32 << 20),
            "MiB",
            &budget,
        );
        r.add(
            "streaming",
            "nodes evicted",
            c.evicted as f64,
            "nodes",
            &budget,
        );
        report_frame_times(&self.frame_times, &self.stages, r, params);
    }
}

/// The slowest 1 % of `items` (at least one of a non-empty list) by `seconds`, slowest first.
fn slowest_percent<T>(items: &[T], seconds: impl Fn(&T) -> f64) -> Vec<&T> {
    let mut slowest: Vec<&T> = items.iter().collect();
    slowest.sort_by(|a, b| seconds(b).total_cmp(&seconds(a)));
    slowest.truncate(items.len().div_ceil(100));
    slowest
}

/// The rows of where the update's time goes: each stage's p99, and its mean over the slowest
/// 1 % of updates (what the bookkeeping p99 is made of).
fn report_stages(stages: &[engine::stream::UpdateStages], r: &mut Report, params: &str) {
    if stages.is_empty() {
        return;
    }
    let slowest = slowest_percent(stages, |s| s.seconds().iter().sum::<f64>());
    let slow_params = format!(
        "{params}; mean over the slowest 1 % of updates ({} frames), wall clock",
        slowest.len()
    );
    for (i, name) in engine::stream::UpdateStages::NAMES.iter().enumerate() {
        let times = stages.iter().map(|s| s.seconds()[i]).collect();
        r.quantiles("streaming", times, &[0.5, 0.99], params, |q| {
            format!("update stage {name} {q}")
        });
        let mean = slowest.iter().map(|s| s.seconds()[i]).sum::<f64>() / slowest.len() as f64;
        r.add(
            "streaming",
            &format!("update stage {name} in the slowest updates"),
            mean * 1e6,
            "µs",
            &slow_params,
        );
    }
}

/// The rows of a flight's per-frame times: the update (bookkeeping), the GPU phases and both,
/// then where the update's time went (`stages`).
fn report_frame_times(
    frame_times: &[[Span; 2]],
    stages: &[engine::stream::UpdateStages],
    r: &mut Report,
    params: &str,
) {
    let spans = [
        (
            "bookkeeping per frame (the streamer's update)",
            frame_times.iter().map(|[u, _]| *u).collect::<Vec<_>>(),
        ),
        (
            "GPU phases per frame (uploads under the GPU budget)",
            frame_times.iter().map(|[_, g]| *g).collect(),
        ),
        (
            "update + GPU phases per frame",
            frame_times
                .iter()
                .map(|[u, g]| Span {
                    wall_s: u.wall_s + g.wall_s,
                    on_cpu_s: u.on_cpu_s.zip(g.on_cpu_s).map(|(a, b)| a + b),
                    run_queue_s: u.run_queue_s.zip(g.run_queue_s).map(|(a, b)| a + b),
                })
                .collect(),
        ),
    ];
    let on_cpu_params = format!(
        "{params}; the wall-clock row less the time the OS gave other threads (with as many \
         workers as cores, a worker can hold the frame thread's core for a scheduler tick)"
    );
    let run_queue_params = format!(
        "{params}; the time in the span the frame thread was ready to run but another thread \
         had its core (Linux run-queue delay)"
    );
    for (i, (name, spans)) in spans.into_iter().enumerate() {
        let wall = spans.iter().map(|s| s.wall_s).collect();
        r.quantiles("streaming", wall, &P50_P99, params, |q| {
            format!("{name} {q}")
        });
        let on_cpu = spans.iter().filter_map(|s| s.on_cpu_s).collect();
        r.quantiles("streaming", on_cpu, &P50_P99, &on_cpu_params, |q| {
            format!("{name} {q}, on-CPU time of the frame thread")
        });
        if i == 0 {
            let waits: Vec<f64> = spans.iter().filter_map(|s| s.run_queue_s).collect();
            r.quantiles("streaming", waits, &P50_P99, &run_queue_params, |q| {
                format!("{name} {q}, waiting for a core")
            });
            report_slowest_spans(&spans, name, r, params);
        }
    }
    report_stages(stages, r, params);
}

/// Where the slowest 1 % of `spans` (by wall clock) went, on average: on the CPU, waiting for
/// a core, and the rest (asleep on a lock or a page, or the virtual CPU not running).
fn report_slowest_spans(spans: &[Span], name: &str, r: &mut Report, params: &str) {
    if spans
        .iter()
        .any(|s| s.on_cpu_s.is_none() || s.run_queue_s.is_none())
    {
        return;
    }
    let slowest = slowest_percent(spans, |s| s.wall_s);
    if slowest.is_empty() {
        return;
    }
    let n = slowest.len() as f64;
    let mean = |f: &dyn Fn(&Span) -> f64| slowest.iter().map(|s| f(s)).sum::<f64>() / n;
    let on_cpu = mean(&|s| s.on_cpu_s.unwrap_or(0.0));
    let waiting = mean(&|s| s.run_queue_s.unwrap_or(0.0));
    let wall = mean(&|s| s.wall_s);
    let slow_params = format!(
        "{params}; mean over the slowest 1 % of frames by wall clock ({} frames); the rest is \
         the wall clock less the other two (asleep: a lock, a page fault; or the virtual CPU \
         not running)",
        slowest.len()
    );
    for (part, value) in [
        ("wall clock", wall),
        ("on the CPU", on_cpu),
        ("waiting for a core", waiting),
        ("the rest", (wall - on_cpu - waiting).max(0.0)),
    ] {
        r.add(
            "streaming",
            &format!("{name} in the slowest frames: {part}"),
            value * 1e6,
            "µs",
            &slow_params,
        );
    }
}

/// The quantiles of the per-frame rows.
pub(crate) const P50_P99: [f64; 2] = [0.5, 0.99];

#[cfg(test)]
mod clock_tests {
    use super::Clock;

    /// A flight that took more than 5 % longer than it says is marked in every row's params,
    /// with its real length and its late frames; one on time is not.
    #[test]
    fn a_flight_that_ran_slow_is_marked() {
        let clock = |real_s: f64, late_frames: usize| Clock {
            planned_s: 12.0,
            real_s,
            late_frames,
            frames: 720,
        };
        assert_eq!(clock(12.3, 2).mark("300 m/s"), "300 m/s");
        let slow = clock(14.2, 131).mark("300 m/s");
        assert!(
            slow.contains("RAN SLOW: 14.2 s for 12.0 s, 131 of 720 frames late"),
            "{slow}"
        );
    }
}
