//! A grid of values that are zero almost everywhere, held as one bit per sample and the
//! non-zero samples in row order: the large trees' extinction of the canopy
//! ([`super::canopy`]), which on a 32 km map is non-zero at about one 8 m cell in eighty, so
//! 64 MiB as a dense f32 grid and about 3 MiB here.

/// `width x height` f32 samples, zero except where a bit is set.
#[derive(Debug, Clone)]
pub(super) struct SparseGrid {
    width: usize,
    height: usize,
    /// One bit per sample (row after row from the south-west), set where a value is stored.
    bits: Vec<u64>,
    /// Per word of `bits`: how many bits the words before it set (the index of its first
    /// stored value).
    before: Vec<u32>,
    /// The stored values in sample order.
    values: Vec<f32>,
}

impl SparseGrid {
    /// The grid whose sample `i` (row-major) is the sum of the `adds` at `i` in their order,
    /// starting from zero: the same f32 as adding them one by one into a dense grid. Samples
    /// with an add are stored even where the sum is zero.
    pub(super) fn from_adds(width: usize, height: usize, mut adds: Vec<(usize, f32)>) -> Self {
        let samples = width * height;
        assert!(
            adds.iter().all(|&(i, _)| i < samples),
            "an add outside the grid"
        );
        // Stable: the adds at one sample keep their order.
        adds.sort_by_key(|&(i, _)| i);
        let mut bits = vec![0u64; samples.div_ceil(64)];
        let mut values: Vec<f32> = Vec::new();
        let mut last = None;
        for (i, v) in adds {
            if last == Some(i) {
                *values.last_mut().expect("a value at the last sample") += v;
            } else {
                // The dense grid's first add is to zero.
                values.push(0.0 + v);
                bits[i / 64] |= 1 << (i % 64);
                last = Some(i);
            }
        }
        let mut before = Vec::with_capacity(bits.len());
        let mut n = 0u32;
        for w in &bits {
            before.push(n);
            n += w.count_ones();
        }
        Self {
            width,
            height,
            bits,
            before,
            values,
        }
    }

    pub(super) fn width(&self) -> usize {
        self.width
    }

    pub(super) fn height(&self) -> usize {
        self.height
    }

    /// The sample at `(x, y)` (inside the grid).
    #[inline]
    pub(super) fn get(&self, x: usize, y: usize) -> f32 {
        debug_assert!(
            x < self.width && y < self.height,
            "({x}, {y}) outside the grid"
        );
        let i = y * self.width + x;
        let (word, bit) = (i / 64, i % 64);
        let w = self.bits[word];
        if w & (1 << bit) == 0 {
            return 0.0;
        }
        let below = (w & ((1u64 << bit) - 1)).count_ones();
        self.values[(self.before[word] + below) as usize]
    }

    /// Calls `f(x, y, value)` for every stored sample, in row order.
    pub(super) fn for_each_stored(&self, mut f: impl FnMut(usize, usize, f32)) {
        let mut k = 0;
        for (word, &bits) in self.bits.iter().enumerate() {
            let mut rest = bits;
            while rest != 0 {
                let i = word * 64 + rest.trailing_zeros() as usize;
                f(i % self.width, i / self.width, self.values[k]);
                k += 1;
                rest &= rest - 1;
            }
        }
    }

    /// Bytes held (the bits, their counts and the stored values).
    pub(super) fn bytes(&self) -> usize {
        std::mem::size_of_val(self.bits.as_slice())
            + std::mem::size_of_val(self.before.as_slice())
            + std::mem::size_of_val(self.values.as_slice())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Random adds (repeated at some samples, at every corner, across word boundaries, and
    /// one that sums to zero) read back as a dense grid's, bit for bit, everywhere.
    #[test]
    fn equals_a_dense_grid() {
        let (w, h) = (37, 50);
        let mut dense = vec![0.0f32; w * h];
        let mut adds = Vec::new();
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let mut points: Vec<(usize, usize)> = vec![(0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1)];
        for _ in 0..200 {
            points.push(((next() % w as u64) as usize, (next() % h as u64) as usize));
        }
        for (k, &(x, y)) in points.iter().enumerate() {
            for _ in 0..=(k % 3) {
                let v = 0.1 + (next() % 1000) as f32 * 1e-3;
                dense[y * w + x] += v;
                adds.push((y * w + x, v));
            }
        }
        for v in [0.5f32, -0.5] {
            dense[3 * w + 30] += v;
            adds.push((3 * w + 30, v));
        }
        let g = SparseGrid::from_adds(w, h, adds);
        for y in 0..h {
            for x in 0..w {
                assert_eq!(
                    g.get(x, y).to_bits(),
                    dense[y * w + x].to_bits(),
                    "({x}, {y})"
                );
            }
        }
        // The stored samples, visited in row order, are the added ones with their values.
        let mut visited = Vec::new();
        g.for_each_stored(|x, y, v| visited.push((y * w + x, v.to_bits())));
        let mut added: Vec<(usize, u32)> = points
            .iter()
            .chain([&(30, 3)])
            .map(|&(x, y)| (y * w + x, dense[y * w + x].to_bits()))
            .collect();
        added.sort_unstable();
        added.dedup();
        assert_eq!(visited, added);
    }
}
