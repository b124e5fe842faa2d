//! A dense, row-major 2-D grid of samples with row 0 at the south edge.

/// A `width` x `height` grid of samples, row-major, row 0 = south (smallest y).
#[derive(Clone, Debug, PartialEq)]
pub struct Grid<T> {
    width: usize,
    height: usize,
    data: Vec<T>,
}

impl<T: Copy> Grid<T> {
    /// A grid filled with `fill`.
    pub fn new(width: usize, height: usize, fill: T) -> Self {
        Self {
            width,
            height,
            data: vec![fill; width * height],
        }
    }

    /// Wraps `data` (row 0 = south); `None` when the length does not match.
    pub fn from_vec(width: usize, height: usize, data: Vec<T>) -> Option<Self> {
        (data.len() == width * height).then_some(Self {
            width,
            height,
            data,
        })
    }

    /// Wraps rows given north-up (as stored in image files): the first row becomes the top row.
    pub fn from_north_up(width: usize, height: usize, data_north_up: &[T]) -> Option<Self> {
        if data_north_up.len() != width * height {
            return None;
        }
        let mut data = Vec::with_capacity(width * height);
        for row in data_north_up.chunks_exact(width.max(1)).rev() {
            data.extend_from_slice(row);
        }
        Some(Self {
            width,
            height,
            data,
        })
    }

    /// The samples with the northmost row first (image order).
    pub fn to_north_up(&self) -> Vec<T> {
        let mut out = Vec::with_capacity(self.data.len());
        for row in self.data.chunks_exact(self.width.max(1)).rev() {
            out.extend_from_slice(row);
        }
        out
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    pub fn data(&self) -> &[T] {
        &self.data
    }

    pub fn data_mut(&mut self) -> &mut [T] {
        &mut self.data
    }

    #[inline]
    pub fn get(&self, x: usize, y: usize) -> T {
        self.data[y * self.width + x]
    }

    #[inline]
    pub fn set(&mut self, x: usize, y: usize, value: T) {
        self.data[y * self.width + x] = value;
    }

    /// The sample at (x, y) with both indices clamped into the grid.
    #[inline]
    pub fn get_clamped(&self, x: i64, y: i64) -> T {
        let xc = x.clamp(0, self.width as i64 - 1) as usize;
        let yc = y.clamp(0, self.height as i64 - 1) as usize;
        self.data[yc * self.width + xc]
    }

    /// A new grid of the same size with `f` applied to each sample.
    pub fn map<U: Copy>(&self, f: impl Fn(T) -> U) -> Grid<U> {
        Grid {
            width: self.width,
            height: self.height,
            data: self.data.iter().map(|&v| f(v)).collect(),
        }
    }
}

impl Grid<f32> {
    /// (min, max) over all samples; (0, 0) for an empty grid.
    pub fn min_max(&self) -> (f32, f32) {
        if self.data.is_empty() {
            return (0.0, 0.0);
        }
        self.data
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn north_up_round_trip_flips_rows() {
        let g = Grid::from_vec(2, 3, vec![0, 1, 2, 3, 4, 5]).unwrap();
        let n = g.to_north_up();
        assert_eq!(n, vec![4, 5, 2, 3, 0, 1]);
        assert_eq!(Grid::from_north_up(2, 3, &n).unwrap(), g);
        assert!(Grid::<u8>::from_vec(2, 2, vec![0; 3]).is_none());
    }

    #[test]
    fn clamped_access_stays_inside() {
        let g = Grid::from_vec(2, 2, vec![1, 2, 3, 4]).unwrap();
        assert_eq!(g.get_clamped(-5, -5), 1);
        assert_eq!(g.get_clamped(9, 9), 4);
        assert_eq!(g.get_clamped(1, 0), 2);
    }
}
