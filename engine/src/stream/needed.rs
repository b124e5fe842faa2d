//! The nodes needed to show a selection, held as the selection's split nodes.

use crate::terrain::quadtree::{NodeKey, QuadTree};
use rustc_hash::FxHashSet;

/// The nodes needed to show a selection: its split nodes (the strict ancestors of the nodes
/// it selected), every child on the map of a split node (a node is only replaced by all four
/// children, so the drawn set covers the whole map, culled parts included; the selected nodes
/// are among them), and the root alone when the selection is the root.
///
/// Only the split nodes are stored: a node is needed when it or its parent is split. Building
/// the set costs no hash insert beyond the split nodes' (the children were four in five of
/// the inserts of a frame's needed set); asking costs at most two lookups.
#[derive(Debug, Clone)]
pub struct NeededSet {
    split: FxHashSet<NodeKey>,
    /// The root selected alone (nothing split).
    root_alone: bool,
    tree: QuadTree,
}

impl NeededSet {
    /// Nothing needed (nothing selected).
    pub fn empty(tree: QuadTree) -> Self {
        Self {
            split: FxHashSet::default(),
            root_alone: false,
            tree,
        }
    }

    /// The set for a selection whose split nodes are `split` (every strict ancestor of a
    /// selected node); `any_selected` says whether it selected anything (with nothing split,
    /// the root).
    pub fn new(tree: QuadTree, split: FxHashSet<NodeKey>, any_selected: bool) -> Self {
        let root_alone = split.is_empty() && any_selected;
        Self {
            split,
            root_alone,
            tree,
        }
    }

    /// The split nodes: those the display replaces by their children.
    pub fn split(&self) -> &FxHashSet<NodeKey> {
        &self.split
    }

    pub fn contains(&self, key: &NodeKey) -> bool {
        match key.parent() {
            // The root is split whenever anything is.
            None => !self.is_empty(),
            Some(p) => {
                self.split.contains(key)
                    || (self.tree.overlaps_map(*key) && self.split.contains(&p))
            }
        }
    }

    pub fn is_empty(&self) -> bool {
        !self.root_alone && self.split.is_empty()
    }

    /// Every needed node once, in no particular order: the root, then the children of each
    /// split node (every split node but the root is the child of a split node).
    pub fn iter(&self) -> impl Iterator<Item = NodeKey> + '_ {
        let root = (!self.is_empty()).then_some(NodeKey::ROOT);
        root.into_iter().chain(self.split.iter().flat_map(move |a| {
            a.children()
                .into_iter()
                .filter(move |c| self.tree.overlaps_map(*c))
        }))
    }

    /// The needed nodes as a set of their own.
    pub fn to_set(&self) -> FxHashSet<NodeKey> {
        let mut out = FxHashSet::with_capacity_and_hasher(
            5 * self.split.len() + 1,
            rustc_hash::FxBuildHasher,
        );
        out.extend(self.iter());
        out
    }
}

/// The nodes the display needs or draws (a drawn node that is no longer needed is still on
/// screen): what the ground textures are made for.
#[derive(Debug, Clone)]
pub struct DisplayNodes {
    pub(super) needed: NeededSet,
    pub(super) drawn: FxHashSet<NodeKey>,
}

impl DisplayNodes {
    pub fn contains(&self, key: &NodeKey) -> bool {
        self.needed.contains(key) || self.drawn.contains(key)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::quadtree::ancestor_set;

    /// The set asked and listed agrees with the set built out in full (wanted, ancestors and
    /// the ancestors' children on the map) on a map whose tree has children off the map.
    #[test]
    fn the_needed_set_is_the_split_nodes_their_children_and_nothing_else() {
        // 300 x 200 m: the right and top parts of the tree lie off the map.
        let tree = QuadTree::new([10.0, -20.0], [300.0, 200.0]);
        let leaf = |level: u8, fx: f64, fy: f64| {
            let n = 1u32 << level;
            NodeKey {
                level,
                ix: (fx * f64::from(n)) as u32,
                iy: (fy * f64::from(n)) as u32,
            }
        };
        let selections: Vec<Vec<NodeKey>> = vec![
            vec![],
            vec![NodeKey::ROOT],
            vec![leaf(3, 0.1, 0.1), leaf(5, 0.2, 0.3), leaf(2, 0.6, 0.1)],
            vec![leaf(4, 0.9, 0.9), leaf(4, 0.05, 0.6), leaf(1, 0.1, 0.1)],
        ];
        for wanted in selections {
            // Selections reach only nodes on the map.
            let wanted: Vec<NodeKey> = wanted
                .into_iter()
                .filter(|k| tree.overlaps_map(*k))
                .collect();
            let split = ancestor_set(wanted.iter().copied());
            let mut full: FxHashSet<NodeKey> = wanted.iter().copied().collect();
            for &a in &split {
                full.insert(a);
                full.extend(a.children().into_iter().filter(|c| tree.overlaps_map(*c)));
            }
            let set = NeededSet::new(tree, split.clone(), !wanted.is_empty());
            let listed: Vec<NodeKey> = set.iter().collect();
            assert_eq!(
                listed.len(),
                full.len(),
                "each node listed once: {wanted:?}"
            );
            assert_eq!(set.to_set(), full, "{wanted:?}");
            assert_eq!(set.is_empty(), full.is_empty());
            // Every node of the tree down to level 6 asked.
            for level in 0..=6u8 {
                let n = 1u32 << level;
                for iy in 0..n {
                    for ix in 0..n {
                        let k = NodeKey { level, ix, iy };
                        assert_eq!(set.contains(&k), full.contains(&k), "{k:?} for {wanted:?}");
                    }
                }
            }
        }
    }
}
