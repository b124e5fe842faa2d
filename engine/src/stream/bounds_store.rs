//! Node bounds known so far, shared by selection (reads) and jobs (writes).

use crate::surface::World;
use crate::terrain::bounds::{self, NodeBounds};
use crate::terrain::quadtree::{NodeKey, QuadTree};
use rustc_hash::FxHashMap;
use std::sync::{Mutex, MutexGuard, PoisonError};

/// Node bounds known so far, shared by selection (reads) and jobs (writes).
#[derive(Debug, Default)]
pub struct BoundsStore {
    map: Mutex<FxHashMap<NodeKey, NodeBounds>>,
}

impl BoundsStore {
    pub fn peek(&self, key: NodeKey) -> Option<NodeBounds> {
        self.map
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .get(&key)
            .copied()
    }

    /// Every bound known now, locked for as long as the guard lives (one lock for a whole
    /// selection instead of one per node; jobs wait to add theirs meanwhile).
    pub fn known(&self) -> MutexGuard<'_, FxHashMap<NodeKey, NodeBounds>> {
        self.map.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The node's bounds, measured outside the lock when unknown (after its parent's; a parent
    /// of leaves stores theirs too, see [`bounds::measure_with_leaves`]).
    pub fn get(&self, world: &World, tree: &QuadTree, key: NodeKey) -> NodeBounds {
        if let Some(b) = self.peek(key) {
            return b;
        }
        let parent = key.parent().map(|p| self.get(world, tree, p));
        // Measuring a parent of leaves stored them too (one lattice for the five nodes).
        if let Some(b) = self.peek(key) {
            return b;
        }
        let (b, leaves) = bounds::measure_stored(world, tree, key, parent);
        let mut map = self.map.lock().unwrap_or_else(PoisonError::into_inner);
        map.insert(key, b);
        for (k, leaf) in leaves {
            map.entry(k).or_insert(leaf);
        }
        b
    }

    pub fn len(&self) -> usize {
        self.map
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}
