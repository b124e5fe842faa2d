//! Small geometric kernels on f64 vectors: closest point on a triangle, triangle normals and the
//! barycentric sample grids used by the error measurement.

use glam::DVec3;

/// Converts a stored f32 position to f64.
pub fn v3(p: [f32; 3]) -> DVec3 {
    DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64)
}

/// Squared distance from `p` to the closed triangle `(a, b, c)` (degenerate triangles included:
/// they behave as their longest segment or as a point).
pub fn point_triangle_distance_sq(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let ab = b - a;
    let ac = c - a;
    let n = ab.cross(ac);
    let nn = n.length_squared();
    if nn > 1e-30 * (ab.length_squared() * ac.length_squared()).max(1e-300) {
        // Project onto the plane; inside when all three edge tests agree with the normal.
        let ap = p - a;
        let d = ap.dot(n);
        let q = p - n * (d / nn);
        let inside = (b - a).cross(q - a).dot(n) >= 0.0
            && (c - b).cross(q - b).dot(n) >= 0.0
            && (a - c).cross(q - c).dot(n) >= 0.0;
        if inside {
            return d * d / nn;
        }
    }
    point_segment_distance_sq(p, a, b)
        .min(point_segment_distance_sq(p, b, c))
        .min(point_segment_distance_sq(p, c, a))
}

/// A ball around a triangle (its centroid and the distance to the farthest corner): a cheap
/// lower bound of point-triangle distances, so most exact distances can be skipped.
#[derive(Debug, Clone, Copy)]
pub struct TriangleBall {
    centre: DVec3,
    radius: f64,
}

impl TriangleBall {
    pub fn new(a: DVec3, b: DVec3, c: DVec3) -> Self {
        let centre = (a + b + c) / 3.0;
        let radius = (a - centre)
            .length()
            .max((b - centre).length())
            .max((c - centre).length());
        TriangleBall { centre, radius }
    }

    /// A lower bound of [`point_triangle_distance_sq`] from `p` to the triangle: every point of
    /// the triangle lies in the ball, so the distance is at least `|p - centre| - radius`. The
    /// bound is lowered by a relative 1e-9 so that rounding never lifts it above the exact
    /// distance as computed.
    pub fn lower_bound_sq(&self, p: DVec3) -> f64 {
        let to_centre = (p - self.centre).length();
        let d = to_centre - self.radius - 1e-9 * (to_centre + self.radius);
        if d > 0.0 { d * d } else { 0.0 }
    }
}

/// Squared distance from `p` to the segment `[a, b]`.
pub fn point_segment_distance_sq(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    let ab = b - a;
    let len = ab.length_squared();
    let t = if len > 0.0 {
        ((p - a).dot(ab) / len).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + ab * t - p).length_squared()
}

/// Unnormalised normal (twice the area vector) of a triangle.
pub fn area_normal(a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    (b - a).cross(c - a)
}

/// Grid samples on a triangle: its barycentric lattice with `k` segments per edge, where `k` is
/// the smallest count that keeps every sub-edge at or under `spacing`. Every point of the
/// triangle lies within `covering_radius` of a sample (a sub-triangle's points are within its
/// longest edge / sqrt(3) of one of its corners). Calls `emit` for each sample; returns the
/// covering radius.
pub fn grid_samples(
    a: DVec3,
    b: DVec3,
    c: DVec3,
    spacing: f64,
    mut emit: impl FnMut(DVec3),
) -> f64 {
    let longest = (b - a).length().max((c - b).length()).max((a - c).length());
    let k = if spacing > 0.0 {
        ((longest / spacing).ceil() as usize).clamp(1, 4096)
    } else {
        1
    };
    let kf = k as f64;
    for i in 0..=k {
        for j in 0..=(k - i) {
            let u = i as f64 / kf;
            let v = j as f64 / kf;
            emit(a + (b - a) * u + (c - a) * v);
        }
    }
    longest / kf / 3f64.sqrt()
}
