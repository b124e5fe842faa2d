//! The texel layout of a node's ground texture: every node has the same `SIDE x SIDE` texels,
//! the inner `TEXELS x TEXELS` covering the node and a ring of `BORDER` texels on each side
//! covering its neighbours' edges, so bilinear filtering and the first mip levels read the same
//! values on both sides of a node border. Texel size halves per level.
//!
//! Texel centres lie on one lattice per level anchored at the map origin (`origin + (j + 1/2) t`,
//! `j` an integer, `t` the level's texel size), because node sides are whole multiples of `t`:
//! two nodes of a level that share texels share their exact world positions, and a texel that
//! is a pure function of its position is equal in both.

use crate::terrain::quadtree::{NodeKey, QuadTree};

/// Texels per node side, border included (a power of two, for the mip chain).
pub const SIDE: u32 = 256;
/// Border texels on each side: mip levels `0..=3` keep at least one.
pub const BORDER: u32 = 8;
/// Mip levels of a node texture: those that keep at least one border texel.
pub const MIP_LEVELS: u32 = BORDER.ilog2() + 1;
/// Texels across the node itself.
pub const TEXELS: u32 = SIDE - 2 * BORDER;

/// Texel size (m) of nodes of `level`.
pub fn texel_m(tree: &QuadTree, level: u8) -> f64 {
    tree.node_size_m(level) / f64::from(TEXELS)
}

/// The index on its level's lattice (see the module docs) of texel column `i` (0 = the west
/// border's first) of node `key`, and the same for row `j`.
pub fn lattice_index(key: NodeKey, i: u32, j: u32) -> [i64; 2] {
    let base = |k: u32| i64::from(k) * i64::from(TEXELS) - i64::from(BORDER);
    [base(key.ix) + i64::from(i), base(key.iy) + i64::from(j)]
}

/// World position (m) of the centre of texel (`i`, `j`) of node `key` (`i` east, `j` north,
/// from the south-west border texel).
pub fn texel_centre_m(tree: &QuadTree, key: NodeKey, i: u32, j: u32) -> [f64; 2] {
    let t = texel_m(tree, key.level);
    let o = tree.rect(NodeKey::ROOT).min;
    let [a, b] = lattice_index(key, i, j);
    [o[0] + (a as f64 + 0.5) * t, o[1] + (b as f64 + 0.5) * t]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::quadtree::Side;

    /// Neighbours of one level: every texel of one node's border ring that lies over the other
    /// node has the same world centre as that node's texel there, bit for bit; the lattice
    /// indices agree; texel size halves per level.
    #[test]
    fn neighbours_share_border_texel_positions() {
        let tree = QuadTree::new([1000.5, -2000.25], [8192.0, 8192.0]);
        for level in [1u8, 5, 10] {
            assert_eq!(texel_m(&tree, level - 1), 2.0 * texel_m(&tree, level));
            let n = 1u32 << level;
            for (ix, iy) in [(0, 0), (n / 2 - 1, n / 3), (n - 2, n - 1)] {
                let a = NodeKey { level, ix, iy };
                let Some(b) = tree.neighbour_across(a, Side::East, level) else {
                    panic!("{a:?} has an east neighbour");
                };
                assert_eq!(b.ix, a.ix + 1);
                // a's east border columns TEXELS + BORDER .. SIDE lie over b's columns
                // BORDER .. 2 BORDER; b's west border columns 0 .. BORDER over a's last ones.
                for j in 0..SIDE {
                    for k in 0..BORDER {
                        let (ia, ib) = (TEXELS + BORDER + k, BORDER + k);
                        assert_eq!(lattice_index(a, ia, j), lattice_index(b, ib, j));
                        assert_eq!(
                            texel_centre_m(&tree, a, ia, j),
                            texel_centre_m(&tree, b, ib, j)
                        );
                        let (ia, ib) = (TEXELS + k, k);
                        assert_eq!(
                            texel_centre_m(&tree, a, ia, j),
                            texel_centre_m(&tree, b, ib, j)
                        );
                    }
                }
            }
        }
    }

    /// The inner texels tile the node exactly: the first and last inner centres are half a
    /// texel inside its rectangle.
    #[test]
    fn inner_texels_cover_the_node() {
        let tree = QuadTree::new([0.0, 0.0], [8192.0, 8192.0]);
        let key = NodeKey {
            level: 6,
            ix: 17,
            iy: 40,
        };
        let r = tree.rect(key);
        let t = texel_m(&tree, key.level);
        let first = texel_centre_m(&tree, key, BORDER, BORDER);
        let last = texel_centre_m(&tree, key, BORDER + TEXELS - 1, BORDER + TEXELS - 1);
        for a in 0..2 {
            assert!((first[a] - (r.min[a] + 0.5 * t)).abs() < 1e-9);
            assert!((last[a] - (r.max[a] - 0.5 * t)).abs() < 1e-9);
        }
    }
}
