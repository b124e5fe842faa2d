//! Which decals reach a rectangle, without a scan of all of them: a uniform grid of buckets over
//! the map, each holding the decals whose reach box (the bounding box of the centre line or
//! outline, widened by the decal's reach, [`crate::surface::decals::decal_reach_m`]) overlaps it.
//! A query reads the buckets under the rectangle and keeps the decals whose box overlaps it, in
//! file order (the order decals are drawn in).
//!
//! The boxes are supersets of where a decal changes anything, so a query never misses a decal
//! that touches the rectangle; it may return one whose box overlaps but whose shape does not
//! (drawing it there changes no texel).

use worldgen::map::Decal;

/// Bucket side (m): a 16 m tile's query reads one to four buckets, a large node's a few hundred.
pub const BUCKET_M: f64 = 64.0;

/// Axis-aligned rectangle `[min, max]` in world metres.
pub type Box2 = ([f64; 2], [f64; 2]);

/// The decals of a map in buckets (see the module docs).
#[derive(Debug, Clone)]
pub struct DecalIndex {
    origin_m: [f64; 2],
    cols: usize,
    rows: usize,
    /// Per bucket (row-major from the south-west), decal indices in ascending order.
    buckets: Vec<Vec<u32>>,
    /// Per decal, its reach box.
    boxes: Vec<Box2>,
}

/// Whether two boxes overlap (touching counts).
pub fn overlaps(a: &Box2, b: &Box2) -> bool {
    a.0[0] <= b.1[0] && b.0[0] <= a.1[0] && a.0[1] <= b.1[1] && b.0[1] <= a.1[1]
}

impl DecalIndex {
    /// Indexes `decals` over the map at `origin_m` of `size_m`. Decals reaching outside the map
    /// go into the border buckets; decals with no points are never returned.
    pub fn new(decals: &[Decal], origin_m: [f64; 2], size_m: [f64; 2]) -> Self {
        let count = |len: f64| ((len / BUCKET_M).ceil() as usize).max(1);
        let (cols, rows) = (count(size_m[0]), count(size_m[1]));
        let mut buckets = vec![Vec::new(); cols * rows];
        let mut boxes = Vec::with_capacity(decals.len());
        for (i, d) in decals.iter().enumerate() {
            let (lo, hi) = reach_box(d);
            boxes.push((lo, hi));
            if d.points.is_empty() {
                continue;
            }
            let ((c0, c1), (r0, r1)) = (
                Self::span(lo[0], hi[0], origin_m[0], cols),
                Self::span(lo[1], hi[1], origin_m[1], rows),
            );
            for r in r0..=r1 {
                for c in c0..=c1 {
                    buckets[r * cols + c].push(i as u32);
                }
            }
        }
        Self {
            origin_m,
            cols,
            rows,
            buckets,
            boxes,
        }
    }

    /// The buckets `[lo, hi]` covers along one axis, clamped to the grid.
    fn span(lo: f64, hi: f64, origin: f64, n: usize) -> (usize, usize) {
        let at = |v: f64| (((v - origin) / BUCKET_M).floor().max(0.0) as usize).min(n - 1);
        (at(lo), at(hi))
    }

    /// The decals whose reach box overlaps the rectangle `[min_m, max_m]`, ascending (file
    /// order).
    pub fn query(&self, min_m: [f64; 2], max_m: [f64; 2]) -> Vec<u32> {
        let rect = (min_m, max_m);
        let ((c0, c1), (r0, r1)) = (
            Self::span(min_m[0], max_m[0], self.origin_m[0], self.cols),
            Self::span(min_m[1], max_m[1], self.origin_m[1], self.rows),
        );
        let mut out: Vec<u32> = (r0..=r1)
            .flat_map(|r| (c0..=c1).map(move |c| r * self.cols + c))
            .flat_map(|b| self.buckets[b].iter().copied())
            .filter(|&i| overlaps(&self.boxes[i as usize], &rect))
            .collect();
        out.sort_unstable();
        out.dedup();
        out
    }

    /// Number of decals indexed.
    pub fn len(&self) -> usize {
        self.boxes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.boxes.is_empty()
    }

    /// Bucket entries in all (a measure of the index's size).
    pub fn entries(&self) -> usize {
        self.buckets.iter().map(Vec::len).sum()
    }
}

/// A decal's reach box: the bounding box of its points widened by its reach (empty, min above
/// max, for a decal without points).
pub fn reach_box(d: &Decal) -> Box2 {
    let r = crate::surface::decals::decal_reach_m(d);
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in &d.points {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k] - r);
            hi[k] = hi[k].max(p[k] + r);
        }
    }
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use worldgen::noise::unit3;

    /// Every decal that comes within its reach of the rectangle's area (distance from a sample
    /// of its shape, brute force over all decals) is returned, and nothing is returned whose
    /// box misses the rectangle; on random rectangles from tile to map size, some off the map.
    #[test]
    fn queries_equal_a_scan_of_all_decals() {
        let map = crate::test_maps::tiny_map();
        let (o, s) = (map.manifest.origin_m, map.manifest.size_m);
        let decals = &map.decals;
        assert!(decals.len() >= 3, "the tiny map has decals");
        let index = DecalIndex::new(decals, o, s);
        assert_eq!(index.len(), decals.len());
        let mut non_empty = 0;
        for i in 0..4000i64 {
            let size = [4.0, 16.0, 64.0, 200.0, 600.0][(i % 5) as usize];
            let min = [
                o[0] - 100.0 + (s[0] + 200.0) * unit3(7, i, 0),
                o[1] - 100.0 + (s[1] + 200.0) * unit3(7, i, 1),
            ];
            let max = [min[0] + size, min[1] + size * 0.5];
            let got = index.query(min, max);
            // The scan: every decal's box.
            let want: Vec<u32> = decals
                .iter()
                .enumerate()
                .filter(|(_, d)| !d.points.is_empty() && overlaps(&reach_box(d), &(min, max)))
                .map(|(i, _)| i as u32)
                .collect();
            assert_eq!(got, want, "rectangle {min:?} .. {max:?}");
            non_empty += usize::from(!got.is_empty());
        }
        assert!(non_empty > 400, "only {non_empty} queries met a decal");
    }

    /// A decal's surface effect (the displacement field `E`) is zero at every lattice sample
    /// farther than its reach from the returned decals: no decal that changes the ground in a
    /// rectangle is missing from the query.
    #[test]
    fn no_decal_that_shapes_a_rectangle_is_missing() {
        let map = crate::test_maps::tiny_map();
        let (o, s) = (map.manifest.origin_m, map.manifest.size_m);
        let index = DecalIndex::new(&map.decals, o, s);
        let world = crate::surface::World::new(map);
        let mut shaped = 0;
        for i in 0..300i64 {
            let min = [
                o[0] + (s[0] - 16.0) * unit3(9, i, 0),
                o[1] + (s[1] - 16.0) * unit3(9, i, 1),
            ];
            let max = [min[0] + 16.0, min[1] + 16.0];
            if !index.query(min, max).is_empty() {
                continue;
            }
            for j in 0..=32 {
                for k in 0..=32 {
                    let (x, y) = (min[0] + f64::from(k) * 0.5, min[1] + f64::from(j) * 0.5);
                    assert_eq!(
                        world.decals.offset_m(x, y),
                        0.0,
                        "decal offset at ({x}, {y}) but the query found no decal"
                    );
                    shaped += 1;
                }
            }
        }
        assert!(shaped > 0);
    }
}
