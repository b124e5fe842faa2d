//! The camera: an f64 perspective camera (z up), its frustum, and the projection constant `K`
//! of the pixel-error metric (`px = err_m * K / dist_m`).

use glam::{DMat4, DVec3};

/// A perspective camera in f64 world space (z up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub position_m: DVec3,
    /// Unit view direction.
    pub forward: DVec3,
    /// Unit up direction, orthogonal to `forward`.
    pub up: DVec3,
    pub fovy_rad: f64,
    pub viewport_px: [u32; 2],
    pub near_m: f64,
}

impl Camera {
    /// A camera at `position_m` looking at `target_m`, world z up.
    pub fn look_at(
        position_m: DVec3,
        target_m: DVec3,
        fovy_rad: f64,
        viewport_px: [u32; 2],
    ) -> Self {
        let forward = (target_m - position_m).normalize_or(DVec3::Y);
        let side = forward.cross(DVec3::Z);
        let side = if side.length_squared() < 1e-12 {
            DVec3::X
        } else {
            side.normalize()
        };
        let up = side.cross(forward).normalize();
        Self {
            position_m,
            forward,
            up,
            fovy_rad,
            viewport_px,
            near_m: 0.1,
        }
    }

    pub fn right(&self) -> DVec3 {
        self.forward.cross(self.up)
    }

    pub fn aspect(&self) -> f64 {
        f64::from(self.viewport_px[0]) / f64::from(self.viewport_px[1].max(1))
    }

    /// Pixels per (metre / metre of distance): `viewport_height / (2 tan(fovy / 2))`.
    pub fn k_px(&self) -> f64 {
        f64::from(self.viewport_px[1]) / (2.0 * (self.fovy_rad * 0.5).tan())
    }

    /// Clip space from camera-relative world space (a point minus [`Self::position_m`]): the
    /// view rotation and a reversed-Z perspective with an infinite far plane (WebGPU: NDC z in
    /// [0, 1], y up), the matrix the renderer draws with (it builds the same in f32).
    pub fn clip_from_rel(&self) -> DMat4 {
        let view = glam::dcamera::rh::view::look_to_mat4(DVec3::ZERO, self.forward, self.up);
        let proj = glam::dcamera::rh::proj::directx::perspective_infinite_reverse(
            self.fovy_rad,
            self.aspect(),
            self.near_m,
        );
        proj * view
    }

    /// The frustum planes (inward unit normals through the camera, plus the near plane).
    pub fn frustum(&self) -> Frustum {
        self.frustum_widened(1.0)
    }

    /// The frustum with the tangents of its half-angles scaled by `factor` (a guard band
    /// around the view for `factor > 1`).
    pub fn frustum_widened(&self, factor: f64) -> Frustum {
        let (f, r, u) = (self.forward, self.right(), self.up);
        let ty = (self.fovy_rad * 0.5).tan() * factor;
        let tx = ty * self.aspect();
        Frustum {
            apex_m: self.position_m,
            normals: [
                (f * tx + r).normalize(),
                (f * tx - r).normalize(),
                (f * ty + u).normalize(),
                (f * ty - u).normalize(),
                f,
            ],
            near_m: self.near_m,
        }
    }
}

/// Four side planes through the apex and a near plane; the far plane is at infinity.
#[derive(Debug, Clone, Copy)]
pub struct Frustum {
    pub apex_m: DVec3,
    pub normals: [DVec3; 5],
    pub near_m: f64,
}

/// A set of a frustum's planes, bit `i` for plane `i` ([`Frustum::classify_aabb`]).
pub type Planes = u8;

/// All five planes of a [`Frustum`].
pub const ALL_PLANES: Planes = 0b1_1111;

impl Frustum {
    /// False only when the box is certainly outside.
    pub fn intersects_aabb(&self, min: DVec3, max: DVec3) -> bool {
        self.classify_aabb(min, max, ALL_PLANES).is_some()
    }

    /// The box against the planes in `planes` (the others are taken as passed): `None` when it
    /// is certainly outside one of them, else the planes among them it is not wholly inside.
    /// A box inside a plane has every box within it inside too, so a hierarchy tests a child
    /// box only against the planes its parent box crossed (none: no test at all).
    pub fn classify_aabb(&self, min: DVec3, max: DVec3, planes: Planes) -> Option<Planes> {
        let (lo, hi) = (min - self.apex_m, max - self.apex_m);
        let mut crossed = planes;
        for (i, n) in self.normals.iter().enumerate() {
            let bit = 1 << i;
            if planes & bit == 0 {
                continue;
            }
            // The box corners furthest along n and furthest against it.
            let (far, near) = (
                DVec3::new(
                    if n.x >= 0.0 { hi.x } else { lo.x },
                    if n.y >= 0.0 { hi.y } else { lo.y },
                    if n.z >= 0.0 { hi.z } else { lo.z },
                ),
                DVec3::new(
                    if n.x >= 0.0 { lo.x } else { hi.x },
                    if n.y >= 0.0 { lo.y } else { hi.y },
                    if n.z >= 0.0 { lo.z } else { hi.z },
                ),
            );
            let offset = if i == 4 { self.near_m } else { 0.0 };
            if n.dot(far) < offset {
                return None;
            }
            if n.dot(near) >= offset {
                crossed &= !bit;
            }
        }
        Some(crossed)
    }
}

/// Distance from `p` to the nearest point of the box (0 inside).
pub fn distance_to_aabb(p: DVec3, min: DVec3, max: DVec3) -> f64 {
    (p.clamp(min, max) - p).length()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Boxes around a camera looking down at an angle, from a fixed sequence of numbers in
    /// [0, 1) (a multiplicative congruential generator: enough to spread boxes about).
    fn boxes(n: usize) -> Vec<(DVec3, DVec3)> {
        let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
        let mut unit = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        (0..n)
            .map(|_| {
                let c = DVec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5) * 400.0;
                let half = DVec3::new(unit(), unit(), unit()) * 60.0;
                (c - half, c + half)
            })
            .collect()
    }

    /// Classifying against all planes culls exactly what the plain test culls; a box within
    /// another is outside whenever the test against the planes the outer one crosses says so,
    /// and never wrongly: the result with the inherited planes equals the result with all.
    #[test]
    fn boxes_within_a_box_need_only_the_planes_it_crosses() {
        let cam = Camera::look_at(
            DVec3::new(0.0, 0.0, 50.0),
            DVec3::new(100.0, 30.0, 0.0),
            1.0,
            [640, 360],
        );
        let f = cam.frustum_widened(1.15);
        let (mut inside, mut crossing, mut outside) = (0, 0, 0);
        for (lo, hi) in boxes(4000) {
            let all = f.classify_aabb(lo, hi, ALL_PLANES);
            let plain = f.intersects_aabb(lo, hi);
            assert_eq!(all.is_some(), plain);
            match all {
                None => outside += 1,
                Some(0) => inside += 1,
                Some(_) => crossing += 1,
            }
            let Some(crossed) = all else { continue };
            // Eight sub-boxes (octants) and one thin slab in the middle.
            let mid = 0.5 * (lo + hi);
            let mut subs: Vec<(DVec3, DVec3)> = (0..8)
                .map(|o| {
                    let pick = |bit: usize, a: f64, m: f64, b: f64| {
                        if o & bit == 0 { (a, m) } else { (m, b) }
                    };
                    let (x0, x1) = pick(1, lo.x, mid.x, hi.x);
                    let (y0, y1) = pick(2, lo.y, mid.y, hi.y);
                    let (z0, z1) = pick(4, lo.z, mid.z, hi.z);
                    (DVec3::new(x0, y0, z0), DVec3::new(x1, y1, z1))
                })
                .collect();
            subs.push((DVec3::new(lo.x, lo.y, mid.z), DVec3::new(hi.x, hi.y, mid.z)));
            for (slo, shi) in subs {
                let inherited = f.classify_aabb(slo, shi, crossed);
                let full = f.classify_aabb(slo, shi, ALL_PLANES);
                assert_eq!(inherited.is_some(), full.is_some(), "{slo} {shi}");
                if let (Some(i), Some(a)) = (inherited, full) {
                    assert_eq!(i, a, "the planes a sub-box crosses");
                }
            }
        }
        assert!(
            inside > 100 && crossing > 100 && outside > 100,
            "{inside} {crossing} {outside}"
        );
    }
}
