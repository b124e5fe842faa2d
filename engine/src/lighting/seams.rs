//! Where a drawn node's light grid meets a coarser one. A node at [`grid_level`] or coarser is
//! shaded by its own grid, a finer node by its ancestor's at that level; so two drawn
//! neighbours of different levels may sample grids of different column spacings, and their
//! interpolations differ along the shared side (at the finer grid's columns between the coarser
//! grid's ones). Every column of a coarse grid holds the bytes of the finer grids' column at the
//! same place (`grid` module docs), so the finer node can match the coarser one exactly on
//! their side by reading its own grid at every `step`-th column only ("decimated" along the
//! side), and blend back to its full grid within one such step from the side. On the node's
//! other sides the decimated reading equals the full one (they lie on coarse columns), so a
//! same-level neighbour that does not blend still matches: no step anywhere.
//!
//! [`coarser_sides`] finds, per drawn node, the sides across which a drawn node uses a coarser
//! grid, as a [`SideSteps`] code the shaders read (`node_light` in the prelude).

use super::grid::{COLUMNS, grid_level};
use crate::terrain::quadtree::{NodeKey, QuadTree, Side, ancestor_set};
use rustc_hash::{FxHashMap, FxHashSet};

/// Per side (west, east, south, north: bits 0-2, 3-5, 6-8, 9-11) the log2 of the step, in the
/// node's grid columns, between the columns its coarser neighbour across that side has: 0 where
/// that neighbour's grid is not coarser.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SideSteps(pub u16);

impl SideSteps {
    /// The log2 step across `side`.
    pub fn log2_step(self, side: Side) -> u8 {
        ((self.0 >> (3 * side_index(side))) & 7) as u8
    }

    fn with(self, side: Side, log2_step: u8) -> Self {
        let shift = 3 * side_index(side);
        Self((self.0 & !(7 << shift)) | (u16::from(log2_step.min(7)) << shift))
    }
}

fn side_index(side: Side) -> u16 {
    match side {
        Side::West => 0,
        Side::East => 1,
        Side::South => 2,
        Side::North => 3,
    }
}

/// The level of the grid that shades a node of `level` (its own, or its ancestor's at
/// [`grid_level`]).
fn grid_owner_level(level: u8, grid_level: u8) -> u8 {
    level.min(grid_level)
}

/// Columns of its grid a node of `level` spans (the grid's [`COLUMNS`] - 1 at [`grid_level`]
/// and coarser, half as many per finer level, at least one).
pub fn node_columns(level: u8, grid_level: u8) -> u32 {
    let cols = (COLUMNS - 1) as u32;
    cols >> level
        .saturating_sub(grid_level)
        .min(cols.trailing_zeros() as u8)
}

/// The sides of every drawn node (`drawn`, fading ones included) whose drawn neighbour across
/// them uses a coarser grid; nodes without such a side are left out. Where a cross-fade draws
/// both a coarser node and its finer children across a side, the side does not blend (the
/// finer ones are the ones that stay).
pub fn coarser_sides(tree: &QuadTree, drawn: &[NodeKey]) -> FxHashMap<NodeKey, SideSteps> {
    let gl = grid_level(tree);
    let set: FxHashSet<NodeKey> = drawn.iter().copied().collect();
    // Strict ancestors of drawn nodes: across a side where one of these lies at the node's own
    // level, the drawn neighbours are finer.
    let covered = ancestor_set(drawn.iter().copied());
    let mut out = FxHashMap::default();
    for &k in drawn {
        let own = grid_owner_level(k.level, gl);
        if own == 0 {
            continue;
        }
        let mut steps = SideSteps::default();
        for side in Side::ALL {
            let Some(n) = tree.neighbour_across(k, side, k.level) else {
                continue;
            };
            if set.contains(&n) || covered.contains(&n) {
                continue;
            }
            for level in (0..k.level).rev() {
                let Some(a) = tree.neighbour_across(k, side, level) else {
                    break;
                };
                if a == k.ancestor_at(level) {
                    break;
                }
                if set.contains(&a) {
                    let theirs = grid_owner_level(a.level, gl);
                    if theirs < own {
                        let max_log2 = node_columns(k.level, gl).trailing_zeros() as u8;
                        steps = steps.with(side, (own - theirs).min(max_log2));
                    }
                    break;
                }
            }
        }
        if steps != SideSteps::default() {
            out.insert(k, steps);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(level: u8, ix: u32, iy: u32) -> NodeKey {
        NodeKey { level, ix, iy }
    }

    /// A 4 km map: grid level 5 (128 m nodes). Drawn: (5, 2, 2), (5, 3, 2), (5, 3, 3) and
    /// the children of (5, 2, 3) (level 6, shaded by its grid) in the north-west quarter of
    /// (4, 1, 1); its west neighbour (4, 0, 1) and its east one (3, 1, 0), a level coarser
    /// still; the children of its south neighbour (4, 1, 0), whose eastern ones border
    /// (3, 1, 0) too.
    #[test]
    fn sides_toward_coarser_grids_are_found() {
        use Side::{East, North, South, West};
        let tree = QuadTree::new([0.0, 0.0], [4096.0, 4096.0]);
        assert_eq!(grid_level(&tree), 5);
        let mut drawn = vec![
            key(5, 2, 2),
            key(5, 3, 2),
            key(5, 3, 3),
            key(4, 0, 1),
            key(3, 1, 0),
        ];
        drawn.extend(key(5, 2, 3).children());
        drawn.extend(key(4, 1, 0).children());
        let sides = coarser_sides(&tree, &drawn);
        let step = |k: NodeKey, side| sides.get(&k).copied().unwrap_or_default().log2_step(side);
        // Toward (4, 0, 1): one level coarser; toward (3, 1, 0): two.
        assert_eq!(step(key(5, 2, 2), West), 1);
        assert_eq!(step(key(5, 3, 2), East), 2);
        assert_eq!(step(key(5, 3, 3), East), 2);
        // (3, 1, 0) also lies east of (4, 1, 0)'s eastern children.
        assert_eq!(step(key(5, 3, 0), East), 2);
        assert_eq!(step(key(5, 3, 1), East), 2);
        // Finer than the grid level: the step is in the grid's columns (level 5 against 4).
        let c = key(5, 2, 3).children();
        assert_eq!((step(c[0], West), step(c[2], West)), (1, 1));
        // Toward a same-level node, finer nodes, nothing drawn, or a node at the grid level
        // seen from below it: no blend.
        assert_eq!(step(key(5, 2, 2), East), 0);
        assert_eq!(step(key(5, 2, 2), North), 0);
        assert_eq!(step(key(5, 2, 2), South), 0);
        assert_eq!(step(key(5, 3, 3), West), 0);
        assert_eq!(step(key(5, 3, 3), North), 0);
        assert_eq!(step(c[1], East), 0);
        assert_eq!(step(key(5, 2, 1), West), 0);
        // The coarse nodes have no coarser neighbour drawn.
        assert!(!sides.contains_key(&key(4, 0, 1)));
        assert!(!sides.contains_key(&key(3, 1, 0)));
        assert_eq!(sides.len(), 7, "{sides:?}");
    }

    #[test]
    fn node_columns_halve_below_the_grid_level() {
        assert_eq!(node_columns(3, 5), 32);
        assert_eq!(node_columns(5, 5), 32);
        assert_eq!(node_columns(6, 5), 16);
        assert_eq!(node_columns(10, 5), 1);
        assert_eq!(node_columns(12, 5), 1);
    }
}
