//! A max-mipmap over a per-cell grid: level k holds the max over 2^k x 2^k cells. Its levels
//! are in memory, or paged when the map was baked ([`super::levels`]).

use super::levels::Level;

#[derive(Debug, Clone)]
pub(crate) struct MaxPyramid {
    pub(crate) levels: Vec<Level>,
}

impl MaxPyramid {
    /// Bytes of the levels held in memory.
    pub(crate) fn bytes(&self) -> usize {
        self.levels.iter().map(Level::bytes).sum()
    }

    /// The pyramid of `base`, every level in memory.
    pub(crate) fn new(base: worldgen::Grid<f32>) -> Self {
        let mut levels = vec![base];
        while let Some(prev) = levels.last() {
            if prev.width() == 1 && prev.height() == 1 {
                break;
            }
            let (w, h) = (prev.width().div_ceil(2), prev.height().div_ceil(2));
            let mut next = worldgen::Grid::new(w, h, 0.0f32);
            for y in 0..h {
                for x in 0..w {
                    let m = prev
                        .get(2 * x, 2 * y)
                        .max(prev.get_clamped(2 * x as i64 + 1, 2 * y as i64))
                        .max(prev.get_clamped(2 * x as i64, 2 * y as i64 + 1))
                        .max(prev.get_clamped(2 * x as i64 + 1, 2 * y as i64 + 1));
                    next.set(x, y, m);
                }
            }
            levels.push(next);
        }
        Self {
            levels: levels.into_iter().map(Level::Memory).collect(),
        }
    }

    pub(crate) fn width(&self) -> usize {
        self.levels[0].width()
    }

    pub(crate) fn height(&self) -> usize {
        self.levels[0].height()
    }

    /// Max over cells [x0, x1] x [y0, y1] (inclusive), possibly over a few more cells around
    /// (still an upper bound), in at most 9 lookups.
    pub(crate) fn max_in(&self, x0: usize, x1: usize, y0: usize, y1: usize) -> f32 {
        let span = (x1 - x0 + 1).max(y1 - y0 + 1);
        let k = (usize::BITS - 1 - span.leading_zeros()) as usize;
        let k = k.min(self.levels.len() - 1);
        let g = &self.levels[k];
        let mut m = 0.0f32;
        for y in (y0 >> k)..=(y1 >> k).min(g.height() - 1) {
            for x in (x0 >> k)..=(x1 >> k).min(g.width() - 1) {
                m = m.max(g.get(x, y));
            }
        }
        m
    }
}
