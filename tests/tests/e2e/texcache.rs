//! The texture cache: the mip level it picks against a brute-force projection of
//! texels through an independently built view-projection matrix, and the slot pool through a
//! 10,000-frame teleport storm checked by a mirror of the GPU that applies its plans op by op.

use engine::camera::Camera;
use engine::texcache::mip::{needed_level, px_per_m};
use engine::texcache::pool::{Op, PoolSettings, SlotId, TextureId, TexturePool, slot_bytes};
use glam::{DMat4, DVec3, DVec4};
use std::collections::HashMap;
use worldgen::noise::unit3;

/// A counter-based random stream (the worldgen hash), so every case is reproducible.
struct Stream {
    seed: u64,
    n: i64,
}

impl Stream {
    fn new(seed: u64) -> Self {
        Stream { seed, n: 0 }
    }
    fn next(&mut self) -> f64 {
        self.n += 1;
        unit3(self.seed, self.n, 0)
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
    fn unit_vector(&mut self) -> DVec3 {
        loop {
            let v = DVec3::new(
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
            );
            let l = v.length();
            if l > 0.1 && l <= 1.0 {
                return v / l;
            }
        }
    }
}

/// Pixel coordinates of `p` through glam's view and projection matrices and the viewport
/// transform; `None` behind the near plane.
fn project(camera: &Camera, view_proj: &DMat4, p: DVec3) -> Option<[f64; 2]> {
    if (p - camera.position_m).dot(camera.forward) < camera.near_m {
        return None;
    }
    let c = *view_proj * p.extend(1.0);
    let (w, h) = (
        f64::from(camera.viewport_px[0]),
        f64::from(camera.viewport_px[1]),
    );
    Some([(c.x / c.w + 1.0) * 0.5 * w, (1.0 - c.y / c.w) * 0.5 * h])
}

/// An OpenGL-style right-handed view and perspective projection (far plane at 10,000 km), built
/// here from the camera's frame rather than taken from the engine.
fn view_projection(camera: &Camera) -> DMat4 {
    let (f, u, e) = (camera.forward, camera.up, camera.position_m);
    let r = f.cross(u);
    let view = DMat4::from_cols(
        DVec4::new(r.x, u.x, -f.x, 0.0),
        DVec4::new(r.y, u.y, -f.y, 0.0),
        DVec4::new(r.z, u.z, -f.z, 0.0),
        DVec4::new(-r.dot(e), -u.dot(e), f.dot(e), 1.0),
    );
    let fy = 1.0 / (camera.fovy_rad * 0.5).tan();
    let aspect = f64::from(camera.viewport_px[0]) / f64::from(camera.viewport_px[1]);
    let (n, far) = (camera.near_m, 1e7);
    let proj = DMat4::from_cols(
        DVec4::new(fy / aspect, 0.0, 0.0, 0.0),
        DVec4::new(0.0, fy, 0.0, 0.0),
        DVec4::new(0.0, 0.0, (far + n) / (n - far), -1.0),
        DVec4::new(0.0, 0.0, 2.0 * far * n / (n - far), 0.0),
    );
    proj * view
}

/// The largest on-screen length, in pixels, of a one-metre texel edge found by projecting short
/// segments in 96 directions at points sampled on and in the ball (those on screen).
fn brute_px_per_m(camera: &Camera, centre: DVec3, radius: f64, rng: &mut Stream) -> Option<f64> {
    let view_proj = view_projection(camera);
    let directions: Vec<DVec3> = (0..96).map(|_| rng.unit_vector()).collect();
    let (w, h) = (
        f64::from(camera.viewport_px[0]),
        f64::from(camera.viewport_px[1]),
    );
    let mut best: Option<f64> = None;
    for s in 0..1500 {
        let dir = rng.unit_vector();
        // Half on the surface (where the maximum is), half inside.
        let r = if s % 2 == 0 {
            radius
        } else {
            radius * rng.next().cbrt()
        };
        let p = centre + dir * r;
        let Some(a) = project(camera, &view_proj, p) else {
            continue;
        };
        if !(0.0..=w).contains(&a[0]) || !(0.0..=h).contains(&a[1]) {
            continue;
        }
        let step = 1e-5 * (p - camera.position_m).length();
        for d in &directions {
            let Some(b) = project(camera, &view_proj, p + *d * step) else {
                continue;
            };
            let px = (b[0] - a[0]).hypot(b[1] - a[1]) / step;
            best = Some(best.map_or(px, |x: f64| x.max(px)));
        }
    }
    best
}

/// The coarsest level with no texel over a pixel, by trying every level from the coarsest.
fn brute_level(texel_m: f64, px_per_m: f64, coarsest: u32) -> u32 {
    (0..=coarsest)
        .rev()
        .find(|&k| texel_m * f64::from(1u32 << k) * px_per_m <= 1.0)
        .unwrap_or(0)
}

#[test]
fn picked_mip_is_never_coarser_and_mostly_equal_to_a_brute_force_projection() {
    let mut rng = Stream::new(19);
    let (mut cases, mut equal, mut finer) = (0, 0, 0);
    let mut worst_ratio: f64 = 0.0;
    while cases < 400 {
        let eye = DVec3::new(
            rng.range(-50.0, 50.0),
            rng.range(-50.0, 50.0),
            rng.range(1.0, 80.0),
        );
        let target = eye + rng.unit_vector() * 10.0;
        let viewport = [[1280, 720], [800, 800], [640, 1136]][cases % 3];
        let fovy = rng.range(0.6, 1.3);
        let camera = Camera::look_at(eye, target, fovy, viewport);
        // An object somewhere around the view (some partly off screen), 2 m to 3 km away.
        let distance = 2.0f64.powf(rng.range(1.0, 11.5));
        let off = (camera.right() * rng.range(-1.0, 1.0) + camera.up * rng.range(-0.7, 0.7))
            * (fovy * 0.5).tan();
        let centre = eye + (camera.forward + off).normalize() * distance;
        let radius = rng.range(0.05, 0.45) * distance;
        let Some(brute) = brute_px_per_m(&camera, centre, radius, &mut rng) else {
            continue;
        };
        let bound = px_per_m(&camera, centre, radius).expect("in front");
        assert!(
            bound >= brute * (1.0 - 1e-9),
            "case {cases}: the bound {bound} px/m is below a projected texel {brute} px/m"
        );
        worst_ratio = worst_ratio.max(bound / brute);
        for texel_mm in [1.0, 4.0, 20.0] {
            let texel_m = texel_mm * 1e-3 * rng.range(0.8, 1.25);
            let picked = needed_level(&camera, centre, radius, texel_m, 9).expect("in front");
            let reference = brute_level(texel_m, brute, 9);
            assert!(
                picked <= reference,
                "case {cases}: level {picked} is coarser than the brute-force {reference}"
            );
            assert!(
                reference - picked <= 1,
                "case {cases}: level {picked}, brute force {reference}"
            );
            equal += usize::from(picked == reference);
            finer += usize::from(picked < reference);
        }
        cases += 1;
    }
    let share = equal as f64 / (equal + finer) as f64;
    eprintln!(
        "mip level vs brute force: {equal} equal, {finer} one finer ({:.1} % equal); bound / brute px per m at most {worst_ratio:.3}",
        share * 100.0
    );
    // The bound is within 3 % of the exact maximum over a ball wholly on screen (looser where
    // the screen's edges cut it), and the brute force samples from below: 96.1 % of the picks
    // are equal with this seed (90.2 % with the earlier bound that paired the nearest depth
    // with the widest offset).
    assert!(
        share >= 0.93,
        "only {:.1} % of the levels equal the brute force",
        share * 100.0
    );
}

/// The GPU side as plain data: slots alive and what each holds.
#[derive(Default)]
struct Mirror {
    slots: HashMap<SlotId, Option<(TextureId, u32)>>,
    bytes: u64,
    peak_bytes: u64,
}

impl Mirror {
    fn apply(&mut self, pool: &TexturePool, ops: &[Op], edges: &[u32]) {
        let s = *pool.settings();
        for op in ops {
            match *op {
                Op::Destroy(slot) => {
                    assert!(
                        self.slots.remove(&slot).is_some(),
                        "destroying {slot:?}, not alive"
                    );
                    self.bytes -= slot_bytes(slot.edge_log2, s.bytes_per_texel);
                }
                Op::Create(slot) => {
                    assert!(
                        self.slots.insert(slot, None).is_none(),
                        "creating {slot:?} twice"
                    );
                    self.bytes += slot_bytes(slot.edge_log2, s.bytes_per_texel);
                }
                Op::Upload {
                    texture,
                    level,
                    slot,
                } => {
                    let held = self
                        .slots
                        .get_mut(&slot)
                        .expect("uploading into a slot not alive");
                    assert_eq!(
                        edges[texture as usize] - level,
                        slot.edge_log2,
                        "level and slot sizes differ"
                    );
                    *held = Some((texture, level));
                }
            }
            // Memory only grows within the budget (after a budget cut it may start above).
            if matches!(op, Op::Create(_)) {
                assert!(
                    self.bytes <= s.budget_bytes,
                    "a slot made: {} bytes alive over the budget of {}",
                    self.bytes,
                    s.budget_bytes
                );
            }
            self.peak_bytes = self.peak_bytes.max(self.bytes);
        }
        assert!(
            self.bytes <= s.budget_bytes,
            "after the plan {} bytes alive over the budget of {}",
            self.bytes,
            s.budget_bytes
        );
    }

    /// Every slot alive is free or holds what the pool says a texture is resident at.
    fn check(&self, pool: &TexturePool) {
        let mut claimed = 0;
        let mut seen = HashMap::new();
        for t in 0..pool.texture_count() as TextureId {
            if let Some((slot, level)) = pool.resident(t) {
                assert_eq!(
                    self.slots.get(&slot),
                    Some(&Some((t, level))),
                    "texture {t}"
                );
                assert!(seen.insert(slot, t).is_none(), "{slot:?} held twice");
                claimed += 1;
            }
        }
        let free = pool.free_slots();
        for slot in &free {
            assert!(self.slots.contains_key(slot), "free {slot:?} not alive");
            assert!(!seen.contains_key(slot), "free {slot:?} also held");
        }
        assert_eq!(self.slots.len(), claimed + free.len(), "a slot leaked");
        assert_eq!(self.bytes, pool.allocated_bytes());
    }
}

/// A textured object: its bounding ball and (texture, MipMapFactor) pairs.
struct Object {
    centre: DVec3,
    radius: f64,
    textures: Vec<(TextureId, f64)>,
}

struct Scene {
    objects: Vec<Object>,
    edges: Vec<u32>,
}

fn scene(pool: &mut TexturePool, rng: &mut Stream) -> Scene {
    let mut edges = Vec::new();
    for _ in 0..300 {
        let edge = 6 + (rng.next() * 6.0) as u32;
        pool.add_texture(edge).expect("edge in range");
        edges.push(edge);
    }
    let objects = (0..3000)
        .map(|_| {
            let centre = DVec3::new(
                rng.range(-2000.0, 2000.0),
                rng.range(-2000.0, 2000.0),
                rng.range(0.0, 30.0),
            );
            let radius = rng.range(3.0, 25.0);
            let textures = (0..=(rng.next() * 3.0) as usize)
                .map(|_| {
                    let t = (rng.next() * edges.len() as f64) as usize;
                    // The texture spans the object's size once.
                    (t as TextureId, 2.0 * radius / f64::from(1u32 << edges[t]))
                })
                .collect();
            Object {
                centre,
                radius,
                textures,
            }
        })
        .collect();
    Scene { objects, edges }
}

/// Requests every visible object's textures for `camera`.
/// The objects whose bounding boxes meet the camera's frustum, with their on-screen stretch
/// bound (pixels per metre).
fn visible<'a>(scene: &'a Scene, camera: &Camera) -> Vec<(&'a Object, f64)> {
    let frustum = camera.frustum();
    scene
        .objects
        .iter()
        .filter(|o| {
            let r = DVec3::splat(o.radius);
            frustum.intersects_aabb(o.centre - r, o.centre + r)
        })
        .filter_map(|o| Some((o, px_per_m(camera, o.centre, o.radius)?)))
        .collect()
}

fn request_view(pool: &mut TexturePool, scene: &Scene, camera: &Camera) {
    for (o, ppm) in visible(scene, camera) {
        let area_px = (o.radius * ppm).powi(2);
        for &(t, texel_m) in &o.textures {
            let level = needed_level(camera, o.centre, o.radius, texel_m, pool.coarsest_level(t))
                .unwrap_or(0);
            pool.request(t, level, area_px);
        }
    }
}

fn teleport(rng: &mut Stream) -> Camera {
    let eye = DVec3::new(
        rng.range(-2100.0, 2100.0),
        rng.range(-2100.0, 2100.0),
        rng.range(2.0, 300.0),
    );
    let mut dir = rng.unit_vector();
    dir.z = -dir.z.abs() * 0.5;
    Camera::look_at(eye, eye + dir, 1.0, [1280, 720])
}

#[test]
fn teleport_storm_stays_in_budget_and_leaks_no_slot() {
    let settings = PoolSettings {
        budget_bytes: 24 << 20,
        upload_bytes_per_frame: 2 << 20,
        ..PoolSettings::default()
    };
    let mut pool = TexturePool::new(settings);
    let mut rng = Stream::new(7);
    let scene = scene(&mut pool, &mut rng);
    let mut mirror = Mirror::default();
    let mut camera = teleport(&mut rng);
    let (mut over_budget_frames, mut misses, mut drawn) = (0, 0, 0);
    for frame in 0..10_000 {
        // Teleport a third of the frames, else fly on.
        if rng.next() < 0.33 {
            camera = teleport(&mut rng);
        } else {
            let eye = camera.position_m + camera.forward * 40.0;
            camera = Camera::look_at(eye, eye + camera.forward, 1.0, [1280, 720]);
        }
        // A budget cut and a restore in the middle.
        match frame {
            4000 => pool.set_budget(6 << 20),
            6000 => pool.set_budget(settings.budget_bytes),
            _ => {}
        }
        request_view(&mut pool, &scene, &camera);
        let plan = pool.end_frame();
        mirror.apply(&pool, &plan.ops, &scene.edges);
        mirror.check(&pool);
        let s = pool.stats();
        over_budget_frames += usize::from(s.needed_bytes > pool.settings().budget_bytes);
        misses += s.misses;
        drawn += s.drawn;
    }
    eprintln!(
        "storm: peak {} KiB alive of a {} KiB budget; frames needing more than the budget {over_budget_frames}; misses {misses} of {drawn} drawn textures",
        mirror.peak_bytes >> 10,
        settings.budget_bytes >> 10
    );
    assert!(
        mirror.peak_bytes > settings.budget_bytes / 2,
        "the storm never filled the pool"
    );
    // Nothing drawn and no budget: every slot goes.
    pool.set_budget(0);
    let plan = pool.end_frame();
    mirror.apply(&pool, &plan.ops, &scene.edges);
    mirror.check(&pool);
    assert!(mirror.slots.is_empty(), "{} slots left", mirror.slots.len());
}

#[test]
fn never_coarser_than_needed_while_the_budget_allows() {
    let settings = PoolSettings {
        budget_bytes: 1 << 40,
        upload_bytes_per_frame: 1 << 40,
        ..PoolSettings::default()
    };
    let mut pool = TexturePool::new(settings);
    let mut rng = Stream::new(11);
    let scene = scene(&mut pool, &mut rng);
    let mut mirror = Mirror::default();
    for _ in 0..200 {
        let camera = teleport(&mut rng);
        request_view(&mut pool, &scene, &camera);
        // Per texture the finest level any visible object needs (the per-object level is tied
        // to the brute-force projection by the first test; this checks the pool's part).
        let mut need: HashMap<TextureId, u32> = HashMap::new();
        for (o, ppm) in visible(&scene, &camera) {
            for &(t, texel_m) in &o.textures {
                let level = brute_level(texel_m, ppm, pool.coarsest_level(t));
                let e = need.entry(t).or_insert(level);
                *e = (*e).min(level);
            }
        }
        let plan = pool.end_frame();
        mirror.apply(&pool, &plan.ops, &scene.edges);
        mirror.check(&pool);
        assert_eq!(pool.stats().misses, 0);
        for (&t, &level) in &need {
            assert_eq!(pool.resident(t).map(|r| r.1), Some(level), "texture {t}");
        }
    }
}
