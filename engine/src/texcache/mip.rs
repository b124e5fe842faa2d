//! The mip level a texture needs on an object this frame.
//!
//! Seed 000 keeps one **MipMapFactor per texture per object**: the longest edge, in metres, of
//! one full-resolution texel anywhere on the object ([`texel_m`], from the mesh's positions and
//! UVs; an instance scales it). A texel of level `k` is `2^k` times longer. The GPU's isotropic
//! mip selection never draws a texel smaller than a pixel along its shortest on-screen axis, so
//! holding the coarsest level whose *longest* on-screen texel edge is at most one pixel is
//! pessimistic: the GPU never wants a finer level than the one resident.
//!
//! **On-screen length.** A point at camera-space depth `z` and lateral offset `s` projects with
//! the Jacobian of `K (x/z, y/z)` (`K` = [`Camera::k_px`], square pixels), whose largest singular
//! value is `K sqrt(z^2 + s^2) / z^2`: a segment of length `l` there is at most
//! `l K sqrt(z^2 + s^2) / z^2` pixels long, more so nearer and further off the axis. Over the
//! object's bounding ball (centre depth `c_z`, lateral `c_s`, radius `r`), the visible points
//! have depths in `[max(c_z - r, near), c_z + r]`; [`px_per_m`] cuts that range into slices
//! whose far depth is at most 1 % beyond their near depth `a`, and in a slice `[a, b]` bounds
//! every visible point by `sqrt(b^2 + S^2) / a^2`, where `S` is the widest lateral offset of the
//! ball at a depth of the slice (`c_s` plus the cross-section radius nearest `c_z`), cut on
//! each screen axis at `b` times the tangent of the half field of view (nothing wider is on
//! screen). The
//! largest slice bound is a proven upper bound of the stretch over the ball; for a ball wholly
//! on screen it exceeds the exact maximum by at most the slice ratio cubed (3 %), where the
//! screen's edges cut the ball the two axes are cut separately and it can be looser. The level
//! is the largest `k` keeping `texel_m 2^k` times it at most one pixel ([`needed_level`]);
//! tests compare it with a brute-force projection of texels over the ball.
//!
//! [`Camera::k_px`]: crate::camera::Camera::k_px

use crate::camera::Camera;
use glam::DVec3;

/// Far over near depth of one slice of [`px_per_m`]: the bound exceeds the exact maximum by at
/// most this cubed.
const SLICE_RATIO: f64 = 1.01;

/// Upper bound of the on-screen length in pixels of a one-metre segment anywhere in the ball
/// (`centre_m`, `radius_m`) that is in front of the near plane and on screen (the module's
/// slices); `None` when the whole ball is behind the near plane.
pub fn px_per_m(camera: &Camera, centre_m: DVec3, radius_m: f64) -> Option<f64> {
    let rel = centre_m - camera.position_m;
    let depth_m = rel.dot(camera.forward);
    let radius_m = radius_m.max(0.0);
    let far_m = depth_m + radius_m;
    // Slices grow from the near plane: it must be positive, and the depths finite.
    let near_plane_m = camera.near_m.max(1e-6);
    if !far_m.is_finite() || far_m < near_plane_m {
        return None;
    }
    let lateral_m = (rel - camera.forward * depth_m).length();
    // The centre across and up the view, and the half extents of the view per metre of depth.
    let (across_m, up_m) = (rel.dot(camera.right()).abs(), rel.dot(camera.up).abs());
    let half_y = (camera.fovy_rad * 0.5).tan();
    let half_x = half_y * camera.aspect();
    // An upper bound of the lateral offset of a visible point of the ball at depths in
    // [a, b]: the cross-section radius there is at most `r_ab`, and on screen the point is
    // within `half_x b` across and `half_y b` up.
    let widest_m = |a: f64, b: f64| {
        let dz = depth_m.clamp(a, b) - depth_m;
        let r_ab = (radius_m * radius_m - dz * dz).max(0.0).sqrt();
        let x = (across_m + r_ab).min(half_x * b);
        let y = (up_m + r_ab).min(half_y * b);
        (lateral_m + r_ab).min(x.hypot(y))
    };
    let mut near = (depth_m - radius_m).max(near_plane_m);
    let mut stretch: f64 = 0.0;
    loop {
        let far = (near * SLICE_RATIO).min(far_m).max(near);
        let s = widest_m(near, far);
        stretch = stretch.max((far * far + s * s).sqrt() / (near * near));
        if far >= far_m {
            break;
        }
        near = far;
    }
    Some(camera.k_px() * stretch)
}

/// The coarsest level `k <= coarsest` with `texel_m 2^k px_per_m <= 1` (level 0 when even full
/// resolution has texels over a pixel).
pub fn level_for(texel_m: f64, px_per_m: f64, coarsest: u32) -> u32 {
    let mut level = 0;
    let mut texel_px = texel_m * px_per_m;
    while level < coarsest && texel_px * 2.0 <= 1.0 {
        texel_px *= 2.0;
        level += 1;
    }
    level
}

/// The level a texture with MipMapFactor `texel_m` (metres, instance scale applied) needs on an
/// object bounded by the ball; `None` when the ball is behind the camera.
pub fn needed_level(
    camera: &Camera,
    centre_m: DVec3,
    radius_m: f64,
    texel_m: f64,
    coarsest: u32,
) -> Option<u32> {
    px_per_m(camera, centre_m, radius_m).map(|p| level_for(texel_m, p, coarsest))
}

/// The MipMapFactor of a textured mesh: the longest edge, in the positions' units, of one texel
/// of a `size_texels` texture, over all triangles (the largest singular value of each
/// triangle's map from texel coordinates to positions). Triangles with degenerate UVs are
/// skipped; `None` when none is left.
pub fn texel_m(
    positions: &[[f32; 3]],
    uvs: &[[f32; 2]],
    triangles: &[[u32; 3]],
    size_texels: u32,
) -> Option<f64> {
    let size = f64::from(size_texels);
    let mut longest: Option<f64> = None;
    for t in triangles {
        let p = t.map(|i| DVec3::from(positions[i as usize].map(f64::from)));
        let q = t.map(|i| uvs[i as usize].map(|c| f64::from(c) * size));
        let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
        let (du1, dv1) = (q[1][0] - q[0][0], q[1][1] - q[0][1]);
        let (du2, dv2) = (q[2][0] - q[0][0], q[2][1] - q[0][1]);
        let det = du1 * dv2 - du2 * dv1;
        if det.abs() < 1e-12 {
            continue;
        }
        // Columns of the map texel -> position: dP/du and dP/dv.
        let a = (e1 * dv2 - e2 * dv1) / det;
        let b = (e2 * du1 - e1 * du2) / det;
        // Largest singular value of [a b]: from the 2x2 Gram matrix.
        let (aa, bb, ab) = (a.dot(a), b.dot(b), a.dot(b));
        let half_trace = 0.5 * (aa + bb);
        let root = (0.25 * (aa - bb) * (aa - bb) + ab * ab).sqrt();
        let sigma = (half_trace + root).sqrt();
        longest = Some(longest.map_or(sigma, |l| l.max(sigma)));
    }
    longest
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_square_mapped_once_has_texels_of_side_over_size() {
        let positions = [
            [0.0, 0.0, 0.0],
            [4.0, 0.0, 0.0],
            [4.0, 0.0, 2.0],
            [0.0, 0.0, 2.0],
        ];
        let uvs = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let tris = [[0, 1, 2], [0, 2, 3]];
        // 4 m over 256 texels across, 2 m down: the longest texel edge is 4/256 m.
        let t = texel_m(&positions, &uvs, &tris, 256).unwrap();
        assert!((t - 4.0 / 256.0).abs() < 1e-12, "{t}");
    }

    /// The largest stretch over the visible part of a ball, by scanning its depths finely: at a
    /// depth the ball's cross-section is a disk, the screen a rectangle, and the stretch grows
    /// with the offset from the axis, so its largest value is at an extreme point of their
    /// intersection: on the circle (720 angles), a corner of the rectangle, or where the circle
    /// crosses an edge of the rectangle.
    fn scanned_max(camera: &Camera, centre: DVec3, radius: f64) -> f64 {
        let rel = centre - camera.position_m;
        let (cz, cx, cy) = (
            rel.dot(camera.forward),
            rel.dot(camera.right()),
            rel.dot(camera.up),
        );
        let hy = (camera.fovy_rad * 0.5).tan();
        let hx = hy * camera.aspect();
        let mut best: f64 = 0.0;
        for i in 0..=4000 {
            let z = cz - radius + 2.0 * radius * f64::from(i) / 4000.0;
            if z < camera.near_m {
                continue;
            }
            let rho = (radius * radius - (z - cz) * (z - cz)).max(0.0).sqrt();
            let (wx, wy) = (hx * z, hy * z);
            let mut points: Vec<(f64, f64)> = (0..720)
                .map(|k| {
                    let t = f64::from(k) * std::f64::consts::TAU / 720.0;
                    (cx + rho * t.cos(), cy + rho * t.sin())
                })
                .collect();
            for (sx, sy) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
                points.push((sx * wx, sy * wy));
            }
            for x in [-wx, wx] {
                let d = rho * rho - (x - cx) * (x - cx);
                if d >= 0.0 {
                    points.extend([(x, cy + d.sqrt()), (x, cy - d.sqrt())]);
                }
            }
            for y in [-wy, wy] {
                let d = rho * rho - (y - cy) * (y - cy);
                if d >= 0.0 {
                    points.extend([(cx + d.sqrt(), y), (cx - d.sqrt(), y)]);
                }
            }
            let eps = 1e-9 * (1.0 + z);
            for (x, y) in points {
                let on_screen = x.abs() <= wx + eps && y.abs() <= wy + eps;
                let in_disk = (x - cx).hypot(y - cy) <= rho + eps;
                if on_screen && in_disk {
                    let s2 = x * x + y * y;
                    best = best.max(camera.k_px() * (z * z + s2).sqrt() / (z * z));
                }
            }
        }
        best
    }

    #[test]
    fn the_bound_is_above_the_scanned_maximum_and_within_four_percent_of_it_here() {
        let camera = Camera::look_at(
            DVec3::new(3.0, -2.0, 40.0),
            DVec3::new(20.0, 30.0, 35.0),
            0.9,
            [1280, 720],
        );
        let (right, up, fwd) = (camera.right(), camera.up, camera.forward);
        let mut worst: f64 = 0.0;
        for (i, (along, side, high, share)) in [
            (30.0, 0.0, 0.0, 0.05),
            (30.0, 0.0, 0.0, 0.45),
            (200.0, 60.0, -30.0, 0.2),
            (12.0, -5.0, 4.0, 0.4),
            (800.0, 500.0, 0.0, 0.1),
            (5.0, 0.0, 0.0, 1.5),
        ]
        .into_iter()
        .enumerate()
        {
            let centre = camera.position_m + fwd * along + right * side + up * high;
            let radius = share * along;
            let bound = px_per_m(&camera, centre, radius).expect("in front");
            let scanned = scanned_max(&camera, centre, radius);
            assert!(bound >= scanned, "case {i}: bound {bound} below {scanned}");
            worst = worst.max(bound / scanned);
        }
        assert!(
            worst <= SLICE_RATIO.powi(3) * 1.01,
            "bound / scanned max up to {worst}"
        );
        let behind = camera.position_m - fwd * 10.0;
        assert_eq!(px_per_m(&camera, behind, 5.0), None);
    }

    #[test]
    fn levels_double_with_distance() {
        assert_eq!(level_for(0.01, 100.0, 10), 0);
        assert_eq!(level_for(0.01, 50.0, 10), 1);
        assert_eq!(level_for(0.01, 49.0, 10), 1);
        assert_eq!(level_for(0.01, 25.0, 10), 2);
        assert_eq!(level_for(0.01, 0.001, 3), 3);
    }
}
