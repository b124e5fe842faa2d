//! Interpolating grid samples at f64 world positions.
//!
//! A layer's sample (i, j) sits at `origin + (i, j) * spacing`. Positions outside the grid are
//! clamped to its border (the value at the nearest edge point), which is what terrain code wants
//! at map borders and corners.

use crate::Grid;

/// A raster of f32 samples the bilinear interpolators read: a [`Grid`], or storage of a
/// caller's own that answers sample by sample.
pub trait Samples {
    fn width(&self) -> usize;
    fn height(&self) -> usize;
    /// Sample (`x`, `y`), both in range.
    fn at(&self, x: usize, y: usize) -> f32;
    /// Sample (`x`, `y`) clamped into the raster.
    #[inline]
    fn at_clamped(&self, x: i64, y: i64) -> f32 {
        let xc = x.clamp(0, self.width() as i64 - 1) as usize;
        let yc = y.clamp(0, self.height() as i64 - 1) as usize;
        self.at(xc, yc)
    }
    /// Samples `x..x + 2` by `y..y + 2` (`[row][column]`, south row first), all in range. A
    /// paged raster reads them with one look-up of their page.
    #[inline]
    fn quad(&self, x: usize, y: usize) -> [[f32; 2]; 2] {
        std::array::from_fn(|j| std::array::from_fn(|i| self.at(x + i, y + j)))
    }
    /// Samples `x..x + 4` by `y..y + 4`, as [`Samples::quad`].
    #[inline]
    fn block4(&self, x: usize, y: usize) -> [[f32; 4]; 4] {
        std::array::from_fn(|j| std::array::from_fn(|i| self.at(x + i, y + j)))
    }
}

impl Samples for Grid<f32> {
    #[inline]
    fn width(&self) -> usize {
        Grid::width(self)
    }
    #[inline]
    fn height(&self) -> usize {
        Grid::height(self)
    }
    #[inline]
    fn at(&self, x: usize, y: usize) -> f32 {
        self.data()[y * Grid::width(self) + x]
    }
}

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
        (
            self.axis_coord(0, width, x_m),
            self.axis_coord(1, height, y_m),
        )
    }

    /// One axis of [`Self::grid_coords`]: the continuous coordinate along `axis` (0 = x,
    /// 1 = y) of a world coordinate, clamped into [0, len - 1].
    #[inline]
    fn axis_coord(&self, axis: usize, len: usize, v_m: f64) -> f64 {
        let g = ((v_m - self.origin_m[axis]) / self.spacing_m).clamp(0.0, (len - 1) as f64);
        // A NaN position (never produced by valid callers) samples the corner rather than panicking.
        if g.is_nan() { 0.0 } else { g }
    }

    /// Per world coordinate along `axis`: the sample index below it and the fraction past it.
    fn axis_cells(&self, axis: usize, len: usize, coords_m: &[f64]) -> Vec<(i64, f64)> {
        coords_m
            .iter()
            .map(|&v| {
                let g = self.axis_coord(axis, len, v);
                let g0 = floor_small(g);
                (g0 as i64, g - g0)
            })
            .collect()
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
pub fn bilinear<S: Samples + ?Sized>(grid: &S, at: GridPlacement, x_m: f64, y_m: f64) -> f64 {
    let (gx, gy) = at.grid_coords(grid.width(), grid.height(), x_m, y_m);
    let (x0, y0) = (floor_small(gx), floor_small(gy));
    let (fx, fy) = (gx - x0, gy - y0);
    let (ix, iy) = (x0 as i64, y0 as i64);
    let (w, h) = (grid.width() as i64, grid.height() as i64);
    if ix + 1 < w && iy + 1 < h {
        // Interior (grid_coords already clamped below at 0): no index clamping needed.
        let [[s00, s10], [s01, s11]] = grid
            .quad(ix as usize, iy as usize)
            .map(|r| r.map(f64::from));
        let a = s00 + fx * (s10 - s00);
        let b = s01 + fx * (s11 - s01);
        return a + fy * (b - a);
    }
    let s = |dx: i64, dy: i64| f64::from(grid.at_clamped(ix + dx, iy + dy));
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
pub fn bicubic<S: Samples + ?Sized>(grid: &S, at: GridPlacement, x_m: f64, y_m: f64) -> f64 {
    let (gx, gy) = at.grid_coords(grid.width(), grid.height(), x_m, y_m);
    let (x0, y0) = (floor_small(gx), floor_small(gy));
    let (wx, wy) = (catmull_rom_weights(gx - x0), catmull_rom_weights(gy - y0));
    let (ix, iy) = (x0 as i64, y0 as i64);
    let (w, h) = (grid.width() as i64, grid.height() as i64);
    if gx == x0 && gy == y0 {
        // On a sample: the weights are (0, 1, 0, 0) along both axes, so the sum is the sample
        // itself, which is read alone (a coarse lattice reads no neighbours).
        return f64::from(grid.at_clamped(ix, iy));
    }
    if ix >= 1 && iy >= 1 && ix + 2 < w && iy + 2 < h {
        // Interior: the 4x4 stencil needs no clamping.
        let block = grid.block4(ix as usize - 1, iy as usize - 1);
        let mut sum = 0.0;
        for (row, wyj) in block.iter().zip(&wy) {
            let s = |i: usize| f64::from(row[i]);
            sum += wyj * (wx[0] * s(0) + wx[1] * s(1) + wx[2] * s(2) + wx[3] * s(3));
        }
        return sum;
    }
    let mut sum = 0.0;
    for (j, wyj) in wy.iter().enumerate() {
        let mut row = 0.0;
        for (i, wxi) in wx.iter().enumerate() {
            row += wxi * f64::from(grid.at_clamped(ix + i as i64 - 1, iy + j as i64 - 1));
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

/// The distinct indices that stencils of `len` consecutive indices starting at `starts` read,
/// sorted, and per stencil the position of its first index there (the others follow it:
/// consecutive integers stay neighbours in the sorted list). Lattice evaluations work on these
/// compact lists, so a sparse lattice (a coarse node over a fine grid) costs what it reads.
pub fn stencil_indices(starts: &[i64], len: i64) -> (Vec<i64>, Vec<usize>) {
    let mut all: Vec<i64> = starts
        .iter()
        .flat_map(|&s| (0..len).map(move |d| s + d))
        .collect();
    all.sort_unstable();
    all.dedup();
    let at = starts
        .iter()
        .map(|s| all.binary_search(s).unwrap_or_default())
        .collect();
    (all, at)
}

/// [`bilinear`] at every point of the lattice `xs` x `ys` (row-major, one row per `ys` entry),
/// equal to it point by point: each grid row the lattice touches is interpolated along x once
/// per column, then each point blends two such values (the same operations in the same order).
pub fn bilinear_lattice<S: Samples + ?Sized>(
    grid: &S,
    at: GridPlacement,
    xs: &[f64],
    ys: &[f64],
) -> Vec<f64> {
    let cols = at.axis_cells(0, grid.width(), xs);
    let rows = at.axis_cells(1, grid.height(), ys);
    let starts: Vec<i64> = rows.iter().map(|r| r.0).collect();
    let (grid_rows, first) = stencil_indices(&starts, 2);
    let n = xs.len();
    let mut along_x = Vec::with_capacity(grid_rows.len() * n);
    for &gy in &grid_rows {
        along_x.extend(cols.iter().map(|&(ix, fx)| {
            let (s0, s1) = (
                f64::from(grid.at_clamped(ix, gy)),
                f64::from(grid.at_clamped(ix + 1, gy)),
            );
            s0 + fx * (s1 - s0)
        }));
    }
    let mut out = Vec::with_capacity(n * ys.len());
    for (&(_, fy), &r) in rows.iter().zip(&first) {
        let (below, above) = (&along_x[r * n..][..n], &along_x[(r + 1) * n..][..n]);
        out.extend(below.iter().zip(above).map(|(&a, &b)| a + fy * (b - a)));
    }
    out
}

/// [`bicubic`] at every point of the lattice `xs` x `ys` (row-major), equal to it point by
/// point: each grid row the stencils touch is filtered along x once per column (the column's
/// weights computed once), then each point sums four such values with its row's weights.
pub fn bicubic_lattice<S: Samples + ?Sized>(
    grid: &S,
    at: GridPlacement,
    xs: &[f64],
    ys: &[f64],
) -> Vec<f64> {
    let weights = |cells: Vec<(i64, f64)>| -> Vec<(i64, [f64; 4])> {
        cells
            .into_iter()
            .map(|(i, f)| (i, catmull_rom_weights(f)))
            .collect()
    };
    let cols = weights(at.axis_cells(0, grid.width(), xs));
    let rows = weights(at.axis_cells(1, grid.height(), ys));
    let starts: Vec<i64> = rows.iter().map(|r| r.0 - 1).collect();
    let (grid_rows, first) = stencil_indices(&starts, 4);
    let n = xs.len();
    let mut along_x = Vec::with_capacity(grid_rows.len() * n);
    for &gy in &grid_rows {
        along_x.extend(cols.iter().map(|(ix, wx)| {
            let s = |d: i64| f64::from(grid.at_clamped(ix + d - 1, gy));
            // On a sample column the weights are (0, 1, 0, 0): the sample alone.
            if *wx == ON_SAMPLE {
                s(1)
            } else {
                wx[0] * s(0) + wx[1] * s(1) + wx[2] * s(2) + wx[3] * s(3)
            }
        }));
    }
    let mut out = Vec::with_capacity(n * ys.len());
    for ((_, wy), &r) in rows.iter().zip(&first) {
        if *wy == ON_SAMPLE {
            out.extend_from_slice(&along_x[(r + 1) * n..][..n]);
            continue;
        }
        for i in 0..n {
            let mut sum = 0.0;
            for (j, wyj) in wy.iter().enumerate() {
                sum += wyj * along_x[(r + j) * n + i];
            }
            out.push(sum);
        }
    }
    out
}

/// The Catmull-Rom weights at fraction 0 (a position on a sample), which pick the sample.
const ON_SAMPLE: [f64; 4] = [0.0, 1.0, 0.0, 0.0];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lattice_sampling_equals_point_sampling_inside_and_outside_the_grid() {
        let mut g = Grid::new(13, 9, 0.0f32);
        for y in 0..9 {
            for x in 0..13 {
                g.set(
                    x,
                    y,
                    (crate::noise::unit3(3, x as i64, y as i64) * 50.0 - 10.0) as f32,
                );
            }
        }
        let at = GridPlacement {
            origin_m: [100.0, -20.0],
            spacing_m: 4.0,
        };
        // Beyond every border, on sample positions and between them, unsorted rows.
        let xs: Vec<f64> = (0..71).map(|i| 91.0 + f64::from(i) * 0.93).collect();
        let ys: Vec<f64> = (0..31)
            .map(|j| 25.0 - f64::from(j * 7 % 31) * 1.75)
            .collect();
        let (lin, cub) = (
            bilinear_lattice(&g, at, &xs, &ys),
            bicubic_lattice(&g, at, &xs, &ys),
        );
        for (j, &y) in ys.iter().enumerate() {
            for (i, &x) in xs.iter().enumerate() {
                let k = j * xs.len() + i;
                assert_eq!(lin[k], bilinear(&g, at, x, y), "bilinear at ({x}, {y})");
                assert_eq!(cub[k], bicubic(&g, at, x, y), "bicubic at ({x}, {y})");
            }
        }
    }

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
