//! Quad-tree geometry: integer node keys and where nodes lie in the world.
//!
//! The root is a square of side `leaf_size_m * 2^max_level` anchored at the map origin, the
//! smallest such square covering the map. Level `l` has `2^l x 2^l` nodes; `(ix, iy)` counts
//! from the south-west. Every node has the same mesh resolution ([`NODE_QUADS`] quads a side).

use crate::surface::world::Rect;

/// Quads along a node side; every node has the same resolution.
pub const NODE_QUADS: u32 = 32;
/// Side of the finest (leaf) nodes, metres.
pub const LEAF_SIZE_M: f64 = 8.0;

/// A node: level 0 is the root.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct NodeKey {
    pub level: u8,
    pub ix: u32,
    pub iy: u32,
}

impl NodeKey {
    pub const ROOT: Self = Self {
        level: 0,
        ix: 0,
        iy: 0,
    };

    /// The four children, in order SW, SE, NW, NE.
    pub fn children(self) -> [Self; 4] {
        let (l, x, y) = (self.level + 1, self.ix * 2, self.iy * 2);
        [
            Self {
                level: l,
                ix: x,
                iy: y,
            },
            Self {
                level: l,
                ix: x + 1,
                iy: y,
            },
            Self {
                level: l,
                ix: x,
                iy: y + 1,
            },
            Self {
                level: l,
                ix: x + 1,
                iy: y + 1,
            },
        ]
    }

    /// Which of its parent's [`Self::children`] the node is (0 - 3; 0 for the root).
    pub fn child_slot(self) -> usize {
        (self.ix & 1) as usize + 2 * (self.iy & 1) as usize
    }

    pub fn parent(self) -> Option<Self> {
        (self.level > 0).then(|| Self {
            level: self.level - 1,
            ix: self.ix / 2,
            iy: self.iy / 2,
        })
    }

    /// The ancestors, parent first, up to the root.
    pub fn ancestors(self) -> impl Iterator<Item = Self> {
        std::iter::successors(self.parent(), |k| k.parent())
    }

    /// The ancestor at `level` (self when `level == self.level`).
    pub fn ancestor_at(self, level: u8) -> Self {
        debug_assert!(level <= self.level);
        let shift = self.level - level;
        Self {
            level,
            ix: self.ix >> shift,
            iy: self.iy >> shift,
        }
    }
}

/// Which side of a node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    West,
    East,
    South,
    North,
}

impl Side {
    pub const ALL: [Self; 4] = [Self::West, Self::East, Self::South, Self::North];
}

/// Every strict ancestor of any of `keys`. A walk up from a key stops at the first ancestor
/// already found, whose own ancestors are in by then (a frame's nodes share most of theirs).
pub fn ancestor_set(keys: impl IntoIterator<Item = NodeKey>) -> rustc_hash::FxHashSet<NodeKey> {
    let keys = keys.into_iter();
    let mut set = rustc_hash::FxHashSet::default();
    // A quad tree's inner nodes are about a third of its leaves.
    set.reserve(keys.size_hint().0 / 2 + 16);
    for k in keys {
        for a in k.ancestors() {
            if !set.insert(a) {
                break;
            }
        }
    }
    set
}

/// [`ancestor_set`] sorted.
pub fn unique_ancestors(keys: impl IntoIterator<Item = NodeKey>) -> Vec<NodeKey> {
    let mut out: Vec<NodeKey> = ancestor_set(keys).into_iter().collect();
    out.sort_unstable();
    out
}

/// The tree over one map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuadTree {
    /// World position of the root's south-west corner (the map origin).
    pub origin_m: [f64; 2],
    /// Map extent (nodes wholly outside it are never selected).
    pub map_size_m: [f64; 2],
    pub max_level: u8,
}

impl QuadTree {
    /// The smallest tree whose root covers a map of `size_m` at `origin_m`.
    pub fn new(origin_m: [f64; 2], size_m: [f64; 2]) -> Self {
        let side = size_m[0].max(size_m[1]);
        let mut max_level = 0u8;
        while LEAF_SIZE_M * f64::from(1u32 << max_level) < side - 1e-9 && max_level < 24 {
            max_level += 1;
        }
        Self {
            origin_m,
            map_size_m: size_m,
            max_level,
        }
    }

    pub fn node_size_m(&self, level: u8) -> f64 {
        LEAF_SIZE_M * f64::from(1u32 << (self.max_level - level))
    }

    /// Mesh vertex spacing of nodes at `level`.
    pub fn spacing_m(&self, level: u8) -> f64 {
        self.node_size_m(level) / f64::from(NODE_QUADS)
    }

    /// The node's square in world metres.
    pub fn rect(&self, key: NodeKey) -> Rect {
        let s = self.node_size_m(key.level);
        let min = [
            self.origin_m[0] + f64::from(key.ix) * s,
            self.origin_m[1] + f64::from(key.iy) * s,
        ];
        Rect {
            min,
            max: [min[0] + s, min[1] + s],
        }
    }

    /// True when the node overlaps the map (with positive area).
    pub fn overlaps_map(&self, key: NodeKey) -> bool {
        let r = self.rect(key);
        r.min[0] < self.origin_m[0] + self.map_size_m[0]
            && r.min[1] < self.origin_m[1] + self.map_size_m[1]
    }

    /// The node at `level` containing world point (x, y), if inside the root.
    pub fn key_at(&self, level: u8, x_m: f64, y_m: f64) -> Option<NodeKey> {
        let s = self.node_size_m(level);
        let fx = ((x_m - self.origin_m[0]) / s).floor();
        let fy = ((y_m - self.origin_m[1]) / s).floor();
        let n = f64::from(1u32 << level);
        (fx >= 0.0 && fy >= 0.0 && fx < n && fy < n).then_some(NodeKey {
            level,
            ix: fx as u32,
            iy: fy as u32,
        })
    }

    /// The node at coarser `level` across `side` of `key` (it contains the whole of that side's
    /// outer neighbourhood, since coarser node borders nest). None at the root's border.
    pub fn neighbour_across(&self, key: NodeKey, side: Side, level: u8) -> Option<NodeKey> {
        let r = self.rect(key);
        let (cx, cy) = ((r.min[0] + r.max[0]) * 0.5, (r.min[1] + r.max[1]) * 0.5);
        let eps = self.node_size_m(self.max_level) * 0.25;
        let (x, y) = match side {
            Side::West => (r.min[0] - eps, cy),
            Side::East => (r.max[0] + eps, cy),
            Side::South => (cx, r.min[1] - eps),
            Side::North => (cx, r.max[1] + eps),
        };
        self.key_at(level, x, y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// worldgen resamples imported maps to this tree's mesh spacings (so their nodes read their
    /// bounds from the map-error grids): its base spacing is the leaves' quad.
    #[test]
    fn worldgen_imports_on_the_trees_mesh_spacings() {
        assert_eq!(
            worldgen::dem::NODE_SPACING_BASE_M,
            LEAF_SIZE_M / f64::from(NODE_QUADS)
        );
        for (finest, expected) in [
            (2.0, 2.0),
            (4.0, 4.0),
            (49.76, 32.0),
            (3.048, 2.0),
            (0.3, 0.25),
        ] {
            assert_eq!(
                worldgen::dem::import_spacing_m(finest),
                expected,
                "{finest}"
            );
        }
    }

    #[test]
    fn a_child_knows_its_slot_among_its_parents_children() {
        for parent in [
            NodeKey::ROOT,
            NodeKey {
                level: 5,
                ix: 13,
                iy: 6,
            },
        ] {
            for (slot, c) in parent.children().into_iter().enumerate() {
                assert_eq!(c.child_slot(), slot, "{c:?}");
                assert_eq!(c.parent(), Some(parent));
            }
        }
    }

    /// The same set as every key's ancestors collected, sorted and deduplicated, for keys
    /// that share ancestors, nest in each other and repeat.
    #[test]
    fn unique_ancestors_are_every_ancestor_once() {
        let mut keys = Vec::new();
        let mut state = 12345u64;
        for _ in 0..400 {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            let level = (state >> 60) as u8 % 11;
            let side = 1u32 << level;
            let ix = ((state >> 20) as u32) % side;
            let iy = ((state >> 40) as u32) % side;
            keys.push(NodeKey { level, ix, iy });
        }
        keys.push(keys[7]);
        let mut naive: Vec<NodeKey> = keys.iter().flat_map(|k| k.ancestors()).collect();
        naive.sort_unstable();
        naive.dedup();
        assert!(naive.len() > 100);
        assert_eq!(unique_ancestors(keys.iter().copied()), naive);
    }

    #[test]
    fn default_map_has_eleven_levels_with_8m_leaves() {
        let t = QuadTree::new([0.0, 0.0], [8192.0, 8192.0]);
        assert_eq!(t.max_level, 10);
        assert_eq!(t.node_size_m(10), 8.0);
        assert_eq!(t.spacing_m(10), 0.25);
        assert_eq!(t.node_size_m(0), 8192.0);
    }

    #[test]
    fn keys_nest_and_neighbours_are_found() {
        let t = QuadTree::new([1.0e7, -3.0], [512.0, 300.0]);
        assert_eq!(t.max_level, 6);
        let k = NodeKey {
            level: 6,
            ix: 17,
            iy: 9,
        };
        for c in (NodeKey {
            level: 5,
            ix: 8,
            iy: 4,
        })
        .children()
        {
            assert_eq!(
                c.parent(),
                Some(NodeKey {
                    level: 5,
                    ix: 8,
                    iy: 4
                })
            );
        }
        assert_eq!(
            k.ancestor_at(4),
            NodeKey {
                level: 4,
                ix: 4,
                iy: 2
            }
        );
        assert_eq!(
            t.neighbour_across(k, Side::West, 6),
            Some(NodeKey {
                level: 6,
                ix: 16,
                iy: 9
            })
        );
        assert_eq!(
            t.neighbour_across(k, Side::North, 3),
            Some(NodeKey {
                level: 3,
                ix: 2,
                iy: 1
            })
        );
        assert_eq!(
            t.neighbour_across(
                NodeKey {
                    level: 6,
                    ix: 0,
                    iy: 0
                },
                Side::South,
                2
            ),
            None
        );
        // Rows above 300 m are outside this map.
        assert!(!t.overlaps_map(NodeKey {
            level: 6,
            ix: 0,
            iy: 40
        }));
        assert!(t.overlaps_map(NodeKey {
            level: 6,
            ix: 0,
            iy: 37
        }));
    }
}
