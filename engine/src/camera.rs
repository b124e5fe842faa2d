//! The camera: an f64 perspective camera (z up), its frustum, and the projection constant `K`
//! of the pixel-error metric (`px = err_m * K / dist_m`).

use glam::DVec3;

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

impl Frustum {
    /// False only when the box is certainly outside.
    pub fn intersects_aabb(&self, min: DVec3, max: DVec3) -> bool {
        let (lo, hi) = (min - self.apex_m, max - self.apex_m);
        for (i, n) in self.normals.iter().enumerate() {
            // The box corner furthest along n.
            let p = DVec3::new(
                if n.x >= 0.0 { hi.x } else { lo.x },
                if n.y >= 0.0 { hi.y } else { lo.y },
                if n.z >= 0.0 { hi.z } else { lo.z },
            );
            let offset = if i == 4 { self.near_m } else { 0.0 };
            if n.dot(p) < offset {
                return false;
            }
        }
        true
    }
}

/// Distance from `p` to the nearest point of the box (0 inside).
pub fn distance_to_aabb(p: DVec3, min: DVec3, max: DVec3) -> f64 {
    (p.clamp(min, max) - p).length()
}
