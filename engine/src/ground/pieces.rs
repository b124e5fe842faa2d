//! The decal pieces a node's ground texture draws (the CPU part of the texture phase, not run by
//! any job yet): the segments of the roads and paths, and the outlines of the closed areas, that
//! reach the texture's rectangle (the node plus its border texels, [`super::layout`]), in
//! node-local metres, in the fixed drawing order (decals in file order, segments along each).
//! A pure function of the map and the node key.

use super::decal_index::DecalIndex;
use super::layout::{BORDER, texel_m};
use crate::terrain::quadtree::{NodeKey, QuadTree};
use worldgen::map::{Decal, DecalKind};

/// One segment of an open decal (road, path), node-local.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// The decal's index in the map's decal list, and the index of end `a` in its points.
    pub decal: u32,
    pub point: u32,
    pub kind: DecalKind,
    /// Ends (m, relative to the node's south-west corner).
    pub a_m: [f32; 2],
    pub b_m: [f32; 2],
    /// Distance along the decal's centre line at `a` (m): texture coordinates along a road run
    /// on across segments and nodes.
    pub along_m: f32,
    pub half_width_m: f32,
    pub falloff_m: f32,
}

/// One closed decal (rock patch), node-local outline.
#[derive(Debug, Clone, PartialEq)]
pub struct Area {
    pub decal: u32,
    pub kind: DecalKind,
    pub outline_m: Vec<[f32; 2]>,
    pub falloff_m: f32,
}

/// What a node's texture draws of the map's decals.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NodeDecals {
    pub segments: Vec<Segment>,
    pub areas: Vec<Area>,
}

/// The rectangle a node's texture covers (world m): the node widened by its border texels.
pub fn texture_rect_m(tree: &QuadTree, key: NodeKey) -> ([f64; 2], [f64; 2]) {
    let r = tree.rect(key);
    let b = f64::from(BORDER) * texel_m(tree, key.level);
    ([r.min[0] - b, r.min[1] - b], [r.max[0] + b, r.max[1] + b])
}

/// Whether segment `a`-`b` widened by `reach` can touch the rectangle (its widened box does).
fn segment_reaches(a: [f64; 3], b: [f64; 3], reach: f64, rect: &([f64; 2], [f64; 2])) -> bool {
    (0..2).all(|k| a[k].min(b[k]) - reach <= rect.1[k] && a[k].max(b[k]) + reach >= rect.0[k])
}

/// The decal pieces of node `key` (see the module docs).
pub fn node_decals(
    decals: &[Decal],
    index: &DecalIndex,
    tree: &QuadTree,
    key: NodeKey,
) -> NodeDecals {
    let rect = texture_rect_m(tree, key);
    let o = tree.rect(key).min;
    let local = |p: [f64; 3]| [(p[0] - o[0]) as f32, (p[1] - o[1]) as f32];
    let mut out = NodeDecals::default();
    for i in index.query(rect.0, rect.1) {
        let d = &decals[i as usize];
        let reach = crate::surface::decals::decal_reach_m(d);
        if d.closed {
            out.areas.push(Area {
                decal: i,
                kind: d.kind,
                outline_m: d.points.iter().map(|&p| local(p)).collect(),
                falloff_m: d.falloff_m,
            });
            continue;
        }
        let mut along = 0.0f64;
        for (k, w) in d.points.windows(2).enumerate() {
            let (a, b) = (w[0], w[1]);
            if segment_reaches(a, b, reach, &rect) {
                out.segments.push(Segment {
                    decal: i,
                    point: k as u32,
                    kind: d.kind,
                    a_m: local(a),
                    b_m: local(b),
                    along_m: along as f32,
                    half_width_m: 0.5 * d.width_m,
                    falloff_m: d.falloff_m,
                });
            }
            along += (b[0] - a[0]).hypot(b[1] - a[1]);
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
    /// texture rectangle, in file and segment order; node-local ends plus the node's corner
    /// give the map's points back to within f32 rounding; distances along run on.
    #[test]
    fn pieces_equal_a_scan_of_every_segment() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../maps/tiny");
        let map = worldgen::Map::load(&dir).expect("tiny map loads");
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
            let corner = tree.rect(key).min;
            let mut want_segments = Vec::new();
            let mut want_areas = Vec::new();
            for (di, d) in map.decals.iter().enumerate() {
                let reach = crate::surface::decals::decal_reach_m(d);
                if d.closed {
                    let (lo, hi) = super::super::decal_index::reach_box(d);
                    if (0..2).all(|k| lo[k] <= rect.1[k] && hi[k] >= rect.0[k]) {
                        want_areas.push(di as u32);
                    }
                    continue;
                }
                for (si, w) in d.points.windows(2).enumerate() {
                    if segment_reaches(w[0], w[1], reach, &rect) {
                        want_segments.push((di as u32, si));
                    }
                }
            }
            assert_eq!(
                got.areas.iter().map(|a| a.decal).collect::<Vec<_>>(),
                want_areas
            );
            assert_eq!(got.segments.len(), want_segments.len(), "node {key:?}");
            for (g, &(di, si)) in got.segments.iter().zip(&want_segments) {
                assert_eq!((g.decal, g.point as usize), (di, si));
                let d = &map.decals[di as usize];
                let (a, b) = (d.points[si], d.points[si + 1]);
                let tol = |v: f64| 1e-6 * (1.0 + v.abs());
                for k in 0..2 {
                    assert!(
                        (f64::from(g.a_m[k]) + corner[k] - a[k]).abs() <= tol(a[k] - corner[k])
                    );
                    assert!(
                        (f64::from(g.b_m[k]) + corner[k] - b[k]).abs() <= tol(b[k] - corner[k])
                    );
                }
                let along: f64 = d.points[..=si]
                    .windows(2)
                    .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
                    .sum();
                assert!((f64::from(g.along_m) - along).abs() <= 1e-3 * (1.0 + along));
                assert_eq!(g.kind, d.kind);
            }
            seen += got.segments.len() + got.areas.len();
        }
        assert!(seen > 500, "only {seen} pieces met");
    }
}
