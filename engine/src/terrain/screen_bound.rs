//! How far an error in metres can move a point on the screen: the pixel metric with the stretch
//! a flat screen gives a displacement off its axis.
//!
//! # Derivation
//!
//! Take the camera's right, up and forward unit vectors `r`, `u`, `f` and a point `X` with
//! camera coordinates `(a, b, z) = ((X - eye)·r, (X - eye)·u, (X - eye)·f)`. A flat screen
//! shows it at `s = K (a / z, b / z)` pixels from the centre, with
//! `K = viewport_height_px / (2 tan(fovy / 2))`. With `x = a / z`, `y = b / z` (so
//! `x² + y² = tan²θ`, θ the angle between `X - eye` and the view axis), moving `X` by `δ` moves
//! its image by
//!
//! ```text
//! ds = (K / z) (δ·r - x δ·f,  δ·u - y δ·f).
//! ```
//!
//! - A **vertical** displacement `δ = e ẑ` (what a terrain block's error is: the mesh above or
//!   below the surface at the same x, y) gives `|ds| = (K e / z) g(x, y)` with
//!   `g(x, y) = |(ẑ·r - (ẑ·f) x, ẑ·u - (ẑ·f) y)|`. With `z = D / sqrt(1 + x² + y²)` (`D` the
//!   point's distance from the eye): `|ds| = K e g(x, y) sqrt(1 + x² + y²) / D`. Looking level
//!   (`ẑ·f = 0`) this is the tangential `1 / cosθ`; looking straight down it is the radial
//!   `sinθ / cos²θ` (nothing at the centre, where the displacement is along the axis); looking
//!   down at an angle it is smaller below the centre than above it.
//! - A displacement of **any** direction and length `e` (the matrix above has singular values
//!   1 and `sqrt(1 + x² + y²) = 1 / cosθ`) gives `|ds| <= K e (1 + x² + y²) / D`.
//!
//! The error on the screen is the length of the image of the segment from the true surface point
//! to the drawn one, both inside the block's box; only its part on the screen counts (the
//! measure clips it to the view frustum). Integrating `|ds|` along that part gives
//! `e K stretch / D_min`, with `D_min` the box's distance and `stretch` the largest of
//! `g sqrt(1 + x² + y²)` (vertical) or `1 + x² + y²` (any direction) over the screen
//! positions `(x, y)` of the box's points on the screen. Written with the depth instead,
//! `|ds| = (K e / z) g` (vertical) and `<= (K e / z) sqrt(1 + x² + y²)` (any), so with `z_min`
//! the box's least depth (at a corner; at least the near plane's on the screen) the stretch is
//! also at most `g D_min / z_min`, resp. `sqrt(1 + x² + y²) D_min / z_min`; the smaller of the
//! two forms holds. (The first is tighter for a box that reaches beside the eye, whose nearest
//! depth is off the screen; the second for most others.)
//!
//! Those positions: for a box wholly in front of the eye, each camera coordinate `a`, `b`, `z`
//! ranges over an interval (linear in the point: its ends are at corners), so `x = a / z` and
//! `y = b / z` lie in the products of those intervals with the one of `1 / z`: a rectangle; the
//! screen is the rectangle `|x| <= tan(fovy / 2) aspect`, `|y| <= tan(fovy / 2)`; a box
//! reaching the eye's plane may cover the whole screen. Over the
//! intersection of the two rectangles, `g` and `sqrt(1 + x² + y²)` are convex (norms of affine
//! maps), so each is largest at one of its corners, and the stretch is at most the product of
//! the two largest. A box off the screen (in a guard band) takes the stretch of the screen's
//! border nearest to it, so the guard band splits as the screen's edge would.
//!
//! The bound depends on the view direction, so turning the camera can change the selection: a
//! node near the screen's centre may need to split when a turn takes it towards an edge (a
//! rotation-invariant choice would have to use the corner's stretch everywhere, up to
//! `1 / cos²θcorner`: 2.4 at 60 degrees 16:9). The streamer prepares nodes at a lower threshold
//! than it draws them (`split_factor` against `show_factor`), which covers the stretch a turn
//! within its guard band adds.

use crate::camera::Camera;
use glam::DVec3;

/// A camera's pixel bound: what an error in metres can become on its screen, from a box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScreenBound {
    pub eye_m: DVec3,
    right: DVec3,
    up: DVec3,
    forward: DVec3,
    k_px: f64,
    /// Half-extents of the screen in tangent units: `tan(fovy / 2) aspect`, `tan(fovy / 2)`.
    half_tan: [f64; 2],
    /// World up in the camera's axes: `ẑ·r`, `ẑ·u`, `ẑ·f`.
    z_cam: DVec3,
    /// The near plane's depth: no point on the screen is nearer.
    near_m: f64,
    /// The on-axis model: every stretch is 1.
    on_axis: bool,
    /// The largest stretch of any box (the whole screen's, distance form).
    most: Stretch,
}

/// How much a box's errors may be stretched on the screen, relative to the on-axis metric at
/// the box's distance ([`ScreenBound::stretch`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stretch {
    /// For a vertical displacement.
    pub vertical: f64,
    /// For a displacement of any direction.
    pub any: f64,
}

impl Stretch {
    /// No stretch: the on-axis model's everywhere.
    pub const NONE: Self = Self {
        vertical: 1.0,
        any: 1.0,
    };
}

impl ScreenBound {
    /// The bound on `cam`'s screen, off-axis stretch included.
    pub fn new(cam: &Camera) -> Self {
        let ty = (cam.fovy_rad * 0.5).tan();
        let right = cam.right();
        let mut bound = Self {
            eye_m: cam.position_m,
            right,
            up: cam.up,
            forward: cam.forward,
            k_px: cam.k_px(),
            half_tan: [ty * cam.aspect(), ty],
            z_cam: DVec3::new(right.z, cam.up.z, cam.forward.z),
            near_m: cam.near_m,
            on_axis: false,
            most: Stretch::NONE,
        };
        // The stretch over the whole screen: a box around the eye may show anywhere on it.
        let eye = bound.eye_m;
        bound.most = bound.stretch(eye - DVec3::ONE, eye + DVec3::ONE, 0.0);
        bound
    }

    /// The largest stretch of an error anywhere on the screen: at least [`Self::stretch`] of
    /// any box.
    pub fn most_stretch(&self) -> Stretch {
        self.most
    }

    /// The on-axis model `error_m * K / dist_m` for `cam` (every stretch 1): exact at the
    /// screen's centre only, exceeded off axis. Kept to measure what the stretch costs.
    pub fn on_axis(cam: &Camera) -> Self {
        Self {
            on_axis: true,
            most: Stretch::NONE,
            ..Self::new(cam)
        }
    }

    /// Pixels per (metre / metre of distance) on the view axis: `K`.
    pub fn k_px(&self) -> f64 {
        self.k_px
    }

    /// The largest stretch of an error anywhere in the box `lo..hi`, `dist_m` from the eye (as
    /// [`crate::camera::distance_to_aabb`] finds it), seen on the screen: an error `e` there
    /// shows at most `e K stretch / dist_m` pixels (see the module docs); 1 in the on-axis
    /// model.
    #[inline]
    pub fn stretch(&self, lo: DVec3, hi: DVec3, dist_m: f64) -> Stretch {
        if self.on_axis {
            return Stretch::NONE;
        }
        let (lo, hi) = (lo - self.eye_m, hi - self.eye_m);
        // The range of a camera coordinate over the box: linear in the point, so least and
        // largest at the corners its axis's signs pick.
        let range = |n: DVec3| {
            let pick = |c: f64, l: f64, h: f64| {
                if c >= 0.0 {
                    (l * c, h * c)
                } else {
                    (h * c, l * c)
                }
            };
            let (x, y, z) = (
                pick(n.x, lo.x, hi.x),
                pick(n.y, lo.y, hi.y),
                pick(n.z, lo.z, hi.z),
            );
            (x.0 + y.0 + z.0, x.1 + y.1 + z.1)
        };
        let [tx, ty] = self.half_tan;
        let (z_min, z_max) = range(self.forward);
        let in_front = z_min > 0.0;
        // The box's screen positions (a / z, b / z) lie in the products of its coordinate
        // ranges with the range of 1 / z: a rectangle.
        let rect = if in_front {
            let (near_inv, far_inv) = (1.0 / z_min, 1.0 / z_max);
            let over = |(a0, a1): (f64, f64)| {
                (
                    a0 * if a0 < 0.0 { near_inv } else { far_inv },
                    a1 * if a1 > 0.0 { near_inv } else { far_inv },
                )
            };
            let ((x0, x1), (y0, y1)) = (over(range(self.right)), over(range(self.up)));
            [x0, x1, y0, y1]
        } else {
            [-tx, tx, -ty, ty]
        };
        let [x0, x1, y0, y1] = if in_front {
            [
                rect[0].clamp(-tx, tx),
                rect[1].clamp(-tx, tx),
                rect[2].clamp(-ty, ty),
                rect[3].clamp(-ty, ty),
            ]
        } else {
            [-tx, tx, -ty, ty]
        };
        let z = self.z_cam;
        let (mut g2, mut q) = (0.0f64, 0.0f64);
        for (x, y) in [(x0, y0), (x1, y0), (x0, y1), (x1, y1)] {
            g2 = g2.max((z.x - z.z * x).powi(2) + (z.y - z.z * y).powi(2));
            q = q.max(1.0 + x * x + y * y);
        }
        // The distance form or the depth form (module docs), whichever is smaller; rounded up
        // a little so no stretch is under-estimated.
        let q_sqrt = q.sqrt();
        let by_depth = dist_m / z_min.max(self.near_m);
        let factor = if in_front {
            q_sqrt.min(by_depth)
        } else {
            q_sqrt
        };
        let g = g2.sqrt();
        let up = 1.0 + 8.0 * f64::EPSILON;
        Stretch {
            vertical: g * factor * up,
            any: q_sqrt * factor * up,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The screen position (pixels from the centre) of a world point, straight from the
    /// camera's axes: the projection the derivation differentiates.
    fn image(cam: &Camera, p: DVec3) -> (f64, f64) {
        let v = p - cam.position_m;
        let z = v.dot(cam.forward);
        (
            cam.k_px() * v.dot(cam.right()) / z,
            cam.k_px() * v.dot(cam.up) / z,
        )
    }

    /// Small boxes anywhere on the screens of cameras looking level, down and up: a vertical
    /// displacement inside a box, seen on the screen, never moves further than the bound says,
    /// and an isotropic one likewise; the bound is tight (within 15 %) for the boxes that give
    /// the largest stretch, and the on-axis model is exceeded off axis.
    #[test]
    fn displacements_on_the_screen_stay_within_the_bound() {
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut unit = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut worst_ratio, mut on_axis_exceeded) = (0.0f64, 0usize);
        for pitch_deg in [0.0, -20.0, -60.0, -89.0, 30.0] {
            for fovy_deg in [60.0, 90.0, 120.0] {
                let p = f64::to_radians(pitch_deg);
                let cam = Camera::look_at(
                    DVec3::ZERO,
                    DVec3::new(p.cos(), 0.0, p.sin()),
                    f64::to_radians(fovy_deg),
                    [1280, 540],
                );
                let bound = ScreenBound::new(&cam);
                let axis = ScreenBound::on_axis(&cam);
                let ty = (cam.fovy_rad * 0.5).tan();
                let tx = ty * cam.aspect();
                for _ in 0..4000 {
                    // A point on the screen at distance 50-500 m, a box of 0.1-2 m around it
                    // (away from the screen's border, so the displaced point stays on it).
                    let (x, y) = (
                        (2.0 * unit() - 1.0) * 0.97 * tx,
                        (2.0 * unit() - 1.0) * 0.97 * ty,
                    );
                    let dir = (cam.forward + x * cam.right() + y * cam.up).normalize();
                    let at = dir * (50.0 + 450.0 * unit());
                    let half = DVec3::splat(0.05 + unit());
                    let (lo, hi) = (at - half, at + half);
                    let e = 0.5 * unit() * half.z;
                    let d = crate::camera::distance_to_aabb(cam.position_m, lo, hi);
                    let stretch = bound.stretch(lo, hi, d);
                    let claim = e * bound.k_px() * stretch.vertical / d;
                    let (a, b) = (image(&cam, at), image(&cam, at + DVec3::Z * e));
                    let seen = ((a.0 - b.0).powi(2) + (a.1 - b.1).powi(2)).sqrt();
                    assert!(seen <= claim, "{seen} px over the bound {claim}");
                    worst_ratio = worst_ratio.max(seen / claim);
                    // Any direction: along the view ray's normal that stretches most.
                    let radial = (x * cam.right() + y * cam.up - (x * x + y * y) * cam.forward)
                        .normalize_or(cam.right());
                    let c = image(&cam, at + radial * e);
                    let seen_any = ((a.0 - c.0).powi(2) + (a.1 - c.1).powi(2)).sqrt();
                    let claim_any = e * bound.k_px() * stretch.any / d;
                    assert!(seen_any <= claim_any, "{seen_any} px over {claim_any}");
                    let on_axis = e * axis.k_px() * axis.stretch(lo, hi, d).vertical / d;
                    on_axis_exceeded += usize::from(seen > on_axis * 1.05);
                }
            }
        }
        assert!(worst_ratio > 0.85, "loose: the best case is {worst_ratio}");
        assert!(on_axis_exceeded > 1000, "{on_axis_exceeded}");
    }

    #[test]
    fn the_on_axis_model_is_the_plain_metric() {
        let cam = Camera::look_at(DVec3::ZERO, DVec3::X, 1.0, [640, 480]);
        let axis = ScreenBound::on_axis(&cam);
        // A box near the screen's corner (its centre 35.8 degrees off axis).
        let (lo, hi) = (DVec3::new(19.5, 11.5, -8.5), DVec3::new(20.5, 12.5, -7.5));
        let d = crate::camera::distance_to_aabb(DVec3::ZERO, lo, hi);
        assert_eq!(axis.stretch(lo, hi, d), Stretch::NONE);
        let s = ScreenBound::new(&cam).stretch(lo, hi, d);
        // Looking level, a vertical error is stretched by about 1 / cosθ, any error by about
        // 1 / cos²θ (relative to the box's nearest point, a little less).
        let cos = 20.0 / 24.66;
        assert!(s.vertical > 0.95 / cos && s.vertical < 1.1 / cos, "{s:?}");
        assert!(
            s.any > 0.95 / (cos * cos) && s.any < 1.2 / (cos * cos),
            "{s:?}"
        );
    }
}
