//! Interpolating grid samples at f64 world positions.
//!
//! A layer's sample (i, j) sits at `origin + (i, j) * spacing`. Positions outside the grid are
//! clamped to its border (the value at the nearest edge point), which is what terrain code wants
//! at map borders and corners.

use crate::Grid;

/// Where a grid lies in the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridPlacement {
    /// World position (m) of sample (0, 0), the south-west corner.
    pub origin_m: [f64; 2],
    /// Distance (m) between neighbouring samples, the same in x and y.
    pub spacing_m: f64,
}

impl GridPlacement {
    /// Continuous grid coordinates of a world position, clamped into [0, w-1] x [0, h-1].
    #[inline]
    fn grid_coords(&self, width: usize, height: usize, x_m: f64, y_m: f64) -> (f64, f64) {
        let gx = ((x_m - self.origin_m[0]) / self.spacing_m).clamp(0.0, (width - 1) as f64);
        let gy = ((y_m - self.origin_m[1]) / self.spacing_m).clamp(0.0, (height - 1) as f64);
        // A NaN position (never produced by valid callers) samples the corner rather than panicking.
        (
            if gx.is_nan() { 0.0 } else { gx },
            if gy.is_nan() { 0.0 } else { gy },
        )
    }
}

/// `x.floor()` without a library call: on baseline x86-64 (no SSE4.1 `roundsd`) `f64::floor` is
/// a call into libm, which profiling showed at 6 % of node bounds time. Exact for `|x| < 2^52`
/// (where every f64 with a fraction converts to i64 exactly); the surface's grid and noise
/// coordinates are far smaller. NaN gives 0.
#[inline]
pub fn floor_small(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x { t - 1.0 } else { t }
}

/// Bilinear interpolation (C0) at a world position.
pub fn bilinear(grid: &Grid<f32>, at: GridPlacement, x_m: f64, y_m: f64) -> f64 {
    let (gx, gy) = at.grid_coords(grid.width(), grid.height(), x_m, y_m);
    let (x0, y0) = (floor_small(gx), floor_small(gy));
    let (fx, fy) = (gx - x0, gy - y0);
    let (ix, iy) = (x0 as i64, y0 as i64);
    let (w, h) = (grid.width() as i64, grid.height() as i64);
    if ix + 1 < w && iy + 1 < h {
        // Interior (grid_coords already clamped below at 0): no index clamping needed.
        let i = (iy * w + ix) as usize;
        let d = grid.data();
        let (s00, s10, s01, s11) = (
            f64::from(d[i]),
            f64::from(d[i + 1]),
            f64::from(d[i + w as usize]),
            f64::from(d[i + w as usize + 1]),
        );
        let a = s00 + fx * (s10 - s00);
        let b = s01 + fx * (s11 - s01);
        return a + fy * (b - a);
    }
    let s = |dx: i64, dy: i64| f64::from(grid.get_clamped(ix + dx, iy + dy));
    let a = s(0, 0) + fx * (s(1, 0) - s(0, 0));
    let b = s(0, 1) + fx * (s(1, 1) - s(0, 1));
    a + fy * (b - a)
}

/// Catmull-Rom weights for the four samples around a fractional position t in [0, 1).
#[inline]
pub fn catmull_rom_weights(t: f64) -> [f64; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    [
        0.5 * (-t3 + 2.0 * t2 - t),
        0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
        0.5 * (-3.0 * t3 + 4.0 * t2 + t),
        0.5 * (t3 - t2),
    ]
}

/// Bicubic (Catmull-Rom, C1) interpolation at a world position. It passes through every sample;
/// it may overshoot between samples by a fraction of the neighbouring differences.
pub fn bicubic(grid: &Grid<f32>, at: GridPlacement, x_m: f64, y_m: f64) -> f64 {
    let (gx, gy) = at.grid_coords(grid.width(), grid.height(), x_m, y_m);
    let (x0, y0) = (floor_small(gx), floor_small(gy));
    let (wx, wy) = (catmull_rom_weights(gx - x0), catmull_rom_weights(gy - y0));
    let (ix, iy) = (x0 as i64, y0 as i64);
    let (w, h) = (grid.width() as i64, grid.height() as i64);
    if ix >= 1 && iy >= 1 && ix + 2 < w && iy + 2 < h {
        // Interior: the 4x4 stencil needs no clamping.
        let data = grid.data();
        let mut sum = 0.0;
        for (j, wyj) in wy.iter().enumerate() {
            let row = &data[((iy - 1 + j as i64) * w + ix - 1) as usize..][..4];
            sum += wyj
                * (wx[0] * f64::from(row[0])
                    + wx[1] * f64::from(row[1])
                    + wx[2] * f64::from(row[2])
                    + wx[3] * f64::from(row[3]));
        }
        return sum;
    }
    let mut sum = 0.0;
    for (j, wyj) in wy.iter().enumerate() {
        let mut row = 0.0;
        for (i, wxi) in wx.iter().enumerate() {
            row += wxi * f64::from(grid.get_clamped(ix + i as i64 - 1, iy + j as i64 - 1));
        }
        sum += wyj * row;
    }
    sum
}

/// Bicubic interpolation limited to the range of the four nearest samples: no overshoot, so a
/// flat area (sea at 0 m) stays exactly flat next to a steep coast. C1 where the limiter is
/// inactive; used for resampling imported elevation data.
pub fn bicubic_limited(grid: &Grid<f32>, at: GridPlacement, x_m: f64, y_m: f64) -> f64 {
    let (gx, gy) = at.grid_coords(grid.width(), grid.height(), x_m, y_m);
    let (ix, iy) = (gx.floor() as i64, gy.floor() as i64);
    let corners = [(0, 0), (1, 0), (0, 1), (1, 1)]
        .map(|(dx, dy)| f64::from(grid.get_clamped(ix + dx, iy + dy)));
    let lo = corners.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = corners.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    bicubic(grid, at, x_m, y_m).clamp(lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_small_equals_floor() {
        for k in -200_000..200_000 {
            let x = f64::from(k) * 0.013_7;
            let whole = f64::from(k);
            for v in [
                x,
                x.next_up(),
                x.next_down(),
                whole,
                whole.next_up(),
                whole.next_down(),
            ] {
                assert_eq!(floor_small(v), v.floor(), "at {v}");
            }
        }
        for v in [
            0.0,
            -0.0,
            -0.5,
            0.5,
            -1.0,
            1.0,
            4.0e15,
            -4.0e15,
            0.999_999_999_999,
        ] {
            assert_eq!(floor_small(v), v.floor(), "at {v}");
        }
    }

    fn ramp() -> (Grid<f32>, GridPlacement) {
        // h = 2x + 3y on a 5x4 grid with 10 m spacing, origin far from zero.
        let mut g = Grid::new(5, 4, 0.0f32);
        for y in 0..4 {
            for x in 0..5 {
                g.set(x, y, (2 * x + 3 * y) as f32);
            }
        }
        (
            g,
            GridPlacement {
                origin_m: [1.0e7, -2.0e6],
                spacing_m: 10.0,
            },
        )
    }

    #[test]
    fn both_interpolators_reproduce_samples_and_planes() {
        let (g, at) = ramp();
        for (x, y) in [
            (0.0, 0.0),
            (13.0, 7.5),
            (25.0, 29.0),
            (40.0, 30.0),
            (5.5, 21.25),
        ] {
            let expected = 2.0 * x / 10.0 + 3.0 * y / 10.0;
            let (wx, wy) = (at.origin_m[0] + x, at.origin_m[1] + y);
            assert!(
                (bilinear(&g, at, wx, wy) - expected).abs() < 1e-9,
                "bilinear at {x},{y}"
            );
            // Catmull-Rom reproduces linear functions exactly away from the border; at the border,
            // clamped indices bend it, so check interior points only.
            if (10.0..=30.0).contains(&x) && (10.0..=20.0).contains(&y) {
                assert!(
                    (bicubic(&g, at, wx, wy) - expected).abs() < 1e-9,
                    "bicubic at {x},{y}"
                );
            }
        }
    }

    #[test]
    fn outside_positions_clamp_to_the_border() {
        let (g, at) = ramp();
        let corner = bilinear(&g, at, at.origin_m[0] - 1e5, at.origin_m[1] - 1e5);
        assert_eq!(corner, 0.0);
        let far = bicubic(&g, at, at.origin_m[0] + 1e5, at.origin_m[1] + 1e5);
        assert!((far - f64::from(2 * 4 + 3 * 3)).abs() < 1e-9);
        assert!(bilinear(&g, at, f64::NAN, f64::NAN).is_finite());
    }

    #[test]
    fn limited_bicubic_keeps_flat_sea_flat_next_to_a_cliff() {
        let mut g = Grid::new(8, 3, 0.0f32);
        for y in 0..3 {
            for x in 4..8 {
                g.set(x, y, 100.0);
            }
        }
        let at = GridPlacement {
            origin_m: [0.0, 0.0],
            spacing_m: 1.0,
        };
        // Plain Catmull-Rom dips below the sea next to the cliff; the limited one does not.
        assert!(bicubic(&g, at, 2.5, 1.0) < 0.0);
        for i in 0..=30 {
            let x = f64::from(i) * 0.1;
            assert_eq!(
                bicubic_limited(&g, at, x, 1.0),
                0.0,
                "sea not flat at x={x}"
            );
        }
    }

    #[test]
    fn bicubic_is_c1_across_cell_borders() {
        let mut g = Grid::new(6, 6, 0.0f32);
        for y in 0..6 {
            for x in 0..6 {
                g.set(x, y, ((x * 7 + y * 13) % 5) as f32);
            }
        }
        let at = GridPlacement {
            origin_m: [0.0, 0.0],
            spacing_m: 1.0,
        };
        let e = 1e-6;
        for &x in &[2.0, 3.0] {
            let left = (bicubic(&g, at, x, 2.5) - bicubic(&g, at, x - e, 2.5)) / e;
            let right = (bicubic(&g, at, x + e, 2.5) - bicubic(&g, at, x, 2.5)) / e;
            assert!(
                (left - right).abs() < 1e-3,
                "slope jumps at x={x}: {left} vs {right}"
            );
        }
    }
}
