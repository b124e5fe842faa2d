//! A renumbering of a mesh's positions and triangles for memory locality. The collapse order
//! reads the positions and triangles around one position at a time, jumping across the mesh
//! from one cheapest collapse to the next; its time is spent waiting for those reads. With the
//! positions in Morton (Z-curve) order of their coordinates and the triangles grouped by their
//! lowest renumbered corner, the reads around one position fall on a few cache lines.

/// Both directions of the renumbering of positions and of triangles.
#[derive(Debug, Clone)]
pub struct Renumbering {
    /// The new index of every input position.
    pub pos_new: Vec<u32>,
    /// The input position at every new index.
    pub pos_old: Vec<u32>,
    /// The new index of every input triangle.
    pub tri_new: Vec<u32>,
    /// The input triangle at every new index.
    pub tri_old: Vec<u32>,
}

/// Bits per axis of the Morton code.
const MORTON_BITS: u32 = 10;

/// Spreads the low 10 bits of `x` to every third bit.
fn spread3(x: u32) -> u64 {
    let mut v = u64::from(x) & 0x3ff;
    v = (v | (v << 16)) & 0x0300_00ff;
    v = (v | (v << 8)) & 0x0300_f00f;
    v = (v | (v << 4)) & 0x030c_30c3;
    v = (v | (v << 2)) & 0x0924_9249;
    v
}

/// Positions in Morton order of their coordinates in the bounding box (ties by input index),
/// triangles by their lowest new corner (ties in input order). Deterministic.
pub fn renumbering(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Renumbering {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in positions {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let cells = ((1u32 << MORTON_BITS) - 1) as f32;
    let scale: [f32; 3] = std::array::from_fn(|k| {
        let extent = hi[k] - lo[k];
        if extent > 0.0 { cells / extent } else { 0.0 }
    });
    let mut keys: Vec<u64> = positions
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let code = (0..3).fold(0u64, |code, k| {
                let cell = ((p[k] - lo[k]) * scale[k]).clamp(0.0, cells) as u32;
                code | (spread3(cell) << k)
            });
            (code << 32) | i as u64
        })
        .collect();
    keys.sort_unstable();
    let pos_old: Vec<u32> = keys.iter().map(|&k| k as u32).collect();
    let mut pos_new = vec![0u32; positions.len()];
    for (new, &old) in pos_old.iter().enumerate() {
        pos_new[old as usize] = new as u32;
    }
    // Counting sort of the triangles by their lowest new corner (stable).
    let first: Vec<u32> = triangles
        .iter()
        .map(|t| t.iter().map(|&p| pos_new[p as usize]).min().unwrap_or(0))
        .collect();
    let mut start = vec![0usize; positions.len() + 1];
    for &f in &first {
        start[f as usize + 1] += 1;
    }
    for i in 0..positions.len() {
        start[i + 1] += start[i];
    }
    let mut tri_old = vec![0u32; triangles.len()];
    let mut tri_new = vec![0u32; triangles.len()];
    for (t, &f) in first.iter().enumerate() {
        let slot = &mut start[f as usize];
        tri_old[*slot] = t as u32;
        tri_new[t] = *slot as u32;
        *slot += 1;
    }
    Renumbering {
        pos_new,
        pos_old,
        tri_new,
        tri_old,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_directions_are_inverse_permutations_and_nearby_points_are_near() {
        // A 16 x 16 grid of points, listed row by row, and its triangles.
        let n = 16u32;
        let positions: Vec<[f32; 3]> = (0..n * n)
            .map(|i| [(i % n) as f32, (i / n) as f32, 0.0])
            .collect();
        let mut triangles = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let i = y * n + x;
                triangles.push([i, i + 1, i + n]);
                triangles.push([i + 1, i + n + 1, i + n]);
            }
        }
        let r = renumbering(&positions, &triangles);
        for (old, &new) in r.pos_new.iter().enumerate() {
            assert_eq!(r.pos_old[new as usize] as usize, old);
        }
        for (old, &new) in r.tri_new.iter().enumerate() {
            assert_eq!(r.tri_old[new as usize] as usize, old);
        }
        // Triangles come grouped by their lowest new corner.
        let first = |t: u32| {
            triangles[t as usize]
                .iter()
                .map(|&p| r.pos_new[p as usize])
                .min()
                .unwrap()
        };
        assert!(r.tri_old.windows(2).all(|w| first(w[0]) <= first(w[1])));
        // Morton order: the first 4 new positions are a 2 x 2 block, the first 16 a 4 x 4 one.
        for (count, side) in [(4usize, 2.0f32), (16, 4.0)] {
            for &old in &r.pos_old[..count] {
                let p = positions[old as usize];
                assert!(
                    p[0] < side && p[1] < side,
                    "{p:?} outside the first {count}"
                );
            }
        }
    }
}
