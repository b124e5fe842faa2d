//! Node bounds known so far, shared by the jobs (which measure and add them) and handed on to
//! the streamer's own copy for selection.

use crate::surface::World;
use crate::terrain::bounds::{self, NodeBounds};
use crate::terrain::quadtree::{NodeKey, QuadTree};
use rustc_hash::FxHashMap;
use std::sync::{Mutex, MutexGuard, PoisonError, TryLockError};

/// Node bounds known so far, shared by all threads. The frame thread never walks this map:
/// it takes the bounds added since its last look ([`Self::take_fresh`]) without waiting, so a
/// job adding bounds (or growing the map) never holds up a frame's selection.
#[derive(Debug, Default)]
pub struct BoundsStore {
    known: Mutex<Known>,
}

#[derive(Debug, Default)]
struct Known {
    map: FxHashMap<NodeKey, NodeBounds>,
    /// Added since the last [`BoundsStore::take_fresh`].
    fresh: Vec<(NodeKey, NodeBounds)>,
}

impl BoundsStore {
    fn lock(&self) -> MutexGuard<'_, Known> {
        self.known.lock().unwrap_or_else(PoisonError::into_inner)
    }

    pub fn peek(&self, key: NodeKey) -> Option<NodeBounds> {
        self.lock().map.get(&key).copied()
    }

    /// The bounds added since the last call; `None` (nothing taken, they wait for the next
    /// call) when a job holds the store just now: never waits.
    pub fn take_fresh(&self) -> Option<Vec<(NodeKey, NodeBounds)>> {
        let mut known = match self.known.try_lock() {
            Ok(k) => k,
            Err(TryLockError::Poisoned(p)) => p.into_inner(),
            Err(TryLockError::WouldBlock) => return None,
        };
        Some(std::mem::take(&mut known.fresh))
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
        let mut known = self.lock();
        let Known { map, fresh } = &mut *known;
        for (k, b) in std::iter::once((key, b)).chain(leaves) {
            if let std::collections::hash_map::Entry::Vacant(e) = map.entry(k) {
                e.insert(b);
                fresh.push((k, b));
            }
        }
        b
    }

    pub fn len(&self) -> usize {
        self.lock().map.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}
