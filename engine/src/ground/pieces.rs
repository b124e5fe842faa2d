//! The decal pieces a node's ground texture draws (the CPU part of the texture phase, not run by
//! any job yet): the segments of the roads and paths, and the closed areas, that reach the
//! texture's rectangle (the node plus its border texels, [`super::layout`]), in the fixed
//! drawing order (decals in file order, segments along each). Pieces are references into the
//! map's decal list: the texture pass reads the exact world points from there (texel positions
//! must be computed from the same numbers in every node that shares them). A pure function of
//! the map and the node key.

use super::decal_index::{Box2, DecalIndex, overlaps};
use super::layout::{BORDER, texel_m};
use crate::terrain::quadtree::{NodeKey, QuadTree};
use worldgen::map::Decal;

/// One segment of an open decal (road, path): the decal's index in the map's decal list and
/// the index of the segment's first point in its points.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SegmentRef {
    pub decal: u32,
    pub point: u32,
}

/// What a node's texture draws of the map's decals.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct NodeDecals {
    pub segments: Vec<SegmentRef>,
    /// Closed decals (rock patches), by index in the decal list.
    pub areas: Vec<u32>,
}

/// The rectangle a node's texture covers (world m): the node widened by its border texels.
pub fn texture_rect_m(tree: &QuadTree, key: NodeKey) -> Box2 {
    let r = tree.rect(key);
    let b = f64::from(BORDER) * texel_m(tree, key.level);
    ([r.min[0] - b, r.min[1] - b], [r.max[0] + b, r.max[1] + b])
}

/// The box of segment `a`-`b` widened by `reach`.
fn segment_box(a: [f64; 3], b: [f64; 3], reach: f64) -> Box2 {
    (
        [a[0].min(b[0]) - reach, a[1].min(b[1]) - reach],
        [a[0].max(b[0]) + reach, a[1].max(b[1]) + reach],
    )
}

/// The decal pieces of node `key` (see the module docs).
pub fn node_decals(
    decals: &[Decal],
    index: &DecalIndex,
    tree: &QuadTree,
    key: NodeKey,
) -> NodeDecals {
    let rect = texture_rect_m(tree, key);
    let mut out = NodeDecals::default();
    for i in index.query(rect.0, rect.1) {
        let d = &decals[i as usize];
        if d.kind.is_area() {
            out.areas.push(i);
            continue;
        }
        let reach = crate::surface::decals::decal_reach_m(d);
        for (k, w) in d.points.windows(2).enumerate() {
            if overlaps(&segment_box(w[0], w[1], reach), &rect) {
                out.segments.push(SegmentRef {
                    decal: i,
                    point: k as u32,
                });
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use worldgen::noise::unit3;

    /// On random nodes of every level of the tiny map: the pieces are exactly the segments (by a
    /// scan of every decal's every segment) and closed decals whose widened box reaches the
    /// texture rectangle, in file and segment order.
    #[test]
    fn pieces_equal_a_scan_of_every_segment() {
        let map = crate::test_maps::tiny_map();
        let (o, s) = (map.manifest.origin_m, map.manifest.size_m);
        let tree = QuadTree::new(o, s);
        let index = DecalIndex::new(&map.decals, o, s);
        let mut seen = 0;
        for i in 0..600i64 {
            let level = (i % i64::from(tree.max_level + 1)) as u8;
            let x = o[0] + s[0] * unit3(11, i, 0);
            let y = o[1] + s[1] * unit3(11, i, 1);
            let key = tree.key_at(level, x, y).expect("inside the map");
            let got = node_decals(&map.decals, &index, &tree, key);
            let rect = texture_rect_m(&tree, key);
            let mut want = NodeDecals::default();
            for (di, d) in map.decals.iter().enumerate() {
                let di = di as u32;
                if d.closed {
                    if overlaps(&super::super::decal_index::reach_box(d), &rect) {
                        want.areas.push(di);
                    }
                    continue;
                }
                let reach = crate::surface::decals::decal_reach_m(d);
                for (si, w) in d.points.windows(2).enumerate() {
                    if overlaps(&segment_box(w[0], w[1], reach), &rect) {
                        want.segments.push(SegmentRef {
                            decal: di,
                            point: si as u32,
                        });
                    }
                }
            }
            assert_eq!(got, want, "node {key:?}");
            seen += got.segments.len() + got.areas.len();
        }
        assert!(seen > 500, "only {seen} pieces met");
    }
}
