//! The highest map sample over a block of samples, in a few lookups: a max-pyramid of the map's
//! heights that starts at 2 x 2 blocks (the samples themselves are the map's grid, not copied).
//! A bilinear height never exceeds its four samples, so the maximum over the samples around a
//! region bounds the map heights read anywhere in it (the light grids' horizon marches skip
//! stretches of a ray that cannot rise above the horizon already found).

use super::levels::Level;
use worldgen::Grid;

/// Max-pyramid of a grid's samples: level `k` holds the maximum over blocks of `2^(k+1)` x
/// `2^(k+1)` samples (clamped at the far borders).
#[derive(Debug, Clone)]
pub struct HeightMax {
    pub(crate) levels: Vec<Level>,
    /// Samples along x and y of the base grid.
    samples: [usize; 2],
}

impl HeightMax {
    /// The pyramid of `heights`.
    pub fn new(heights: &Grid<f32>) -> Self {
        let samples = [heights.width(), heights.height()];
        let halve = |g: &Grid<f32>| {
            let (w, h) = (g.width().div_ceil(2), g.height().div_ceil(2));
            let mut next = Grid::new(w, h, 0.0f32);
            for y in 0..h {
                for x in 0..w {
                    let (x2, y2) = (2 * x as i64, 2 * y as i64);
                    let m = g
                        .get_clamped(x2, y2)
                        .max(g.get_clamped(x2 + 1, y2))
                        .max(g.get_clamped(x2, y2 + 1))
                        .max(g.get_clamped(x2 + 1, y2 + 1));
                    next.set(x, y, m);
                }
            }
            next
        };
        let mut levels = vec![halve(heights)];
        while let Some(last) = levels.last() {
            if last.width() == 1 && last.height() == 1 {
                break;
            }
            let next = halve(last);
            levels.push(next);
        }
        Self {
            levels: levels.into_iter().map(Level::Memory).collect(),
            samples,
        }
    }

    /// The pyramid of a grid of `samples` from its `levels` (as [`Self::new`] makes them).
    pub(crate) fn from_levels(levels: Vec<Level>, samples: [usize; 2]) -> Self {
        Self { levels, samples }
    }

    /// The sizes of the levels of the pyramid of a grid of `samples`.
    pub(crate) fn level_sizes(samples: [usize; 2]) -> Vec<(usize, usize)> {
        super::levels::level_sizes(samples[0].div_ceil(2), samples[1].div_ceil(2))
    }

    /// Bytes held in memory.
    pub fn bytes(&self) -> usize {
        self.levels.iter().map(Level::bytes).sum()
    }

    /// An upper bound of the samples `[x0, x1] x [y0, y1]` (inclusive sample indices, clamped
    /// into the grid; the maximum over a few more samples around, in at most 9 lookups).
    pub fn max_in(&self, x: [i64; 2], y: [i64; 2]) -> f32 {
        let clamp = |v: i64, n: usize| v.clamp(0, n as i64 - 1) as usize;
        let (x0, x1) = (clamp(x[0], self.samples[0]), clamp(x[1], self.samples[0]));
        let (y0, y1) = (clamp(y[0], self.samples[1]), clamp(y[1], self.samples[1]));
        let (x0, x1, y0, y1) = (x0.min(x1), x0.max(x1), y0.min(y1), y0.max(y1));
        let span = (x1 - x0 + 1).max(y1 - y0 + 1);
        // Level k's blocks are 2^(k+1) samples wide: with 2^(k+1) >= span / 2, at most 3 of
        // them cover the span.
        let k = ((usize::BITS - span.leading_zeros()) as usize)
            .saturating_sub(2)
            .min(self.levels.len() - 1);
        let g = &self.levels[k];
        let shift = k + 1;
        let mut m = f32::NEG_INFINITY;
        for by in (y0 >> shift)..=(y1 >> shift).min(g.height() - 1) {
            for bx in (x0 >> shift)..=(x1 >> shift).min(g.width() - 1) {
                m = m.max(g.get(bx, by));
            }
        }
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against the maximum taken sample by sample, over random rectangles of an uneven grid
    /// (odd sizes, so the clamped borders are exercised), partly outside it: never below, and
    /// exact for over a quarter of them (a bound that is not the global maximum).
    #[test]
    fn bounds_every_rectangle_from_above() {
        let (w, h) = (37usize, 29usize);
        let mut g = Grid::new(w, h, 0.0f32);
        for y in 0..h {
            for x in 0..w {
                let v = worldgen::noise::unit3(7, (y * w + x) as i64, 0) as f32;
                g.set(x, y, 300.0 * v - 150.0);
            }
        }
        let p = HeightMax::new(&g);
        let mut tight = 0;
        for q in 0..2000i64 {
            let r = |c: i64, n: usize| -> i64 {
                (worldgen::noise::unit3(9, q, c) * (n as f64 + 8.0)) as i64 - 4
            };
            let (xa, xb, ya, yb) = (r(0, w), r(1, w), r(2, h), r(3, h));
            let clamp = |v: i64, n: usize| v.clamp(0, n as i64 - 1) as usize;
            let mut exact = f32::NEG_INFINITY;
            for y in clamp(ya.min(yb), h)..=clamp(ya.max(yb), h) {
                for x in clamp(xa.min(xb), w)..=clamp(xa.max(xb), w) {
                    exact = exact.max(g.get(x, y));
                }
            }
            let bound = p.max_in([xa, xb], [ya, yb]);
            assert!(bound >= exact, "rectangle {q}: {bound} < {exact}");
            tight += usize::from(bound == exact);
        }
        // Not a constant answer (the global maximum would pass the bound test too).
        assert!(tight > 500, "only {tight} of 2000 bounds were exact");
    }
}
