//! Node bounds known so far, shared by the jobs (which measure and add them) and handed on to
//! the streamer's own copy for selection.

use super::records::Records;
use crate::surface::World;
use crate::terrain::bounds::{self, NodeBounds};
use crate::terrain::quadtree::{NodeKey, QuadTree};
use crate::terrain::select::WalkBounds;
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

/// The frame thread's copy of the known bounds, for the selections: bounds in the order they
/// arrived (a node's siblings and children are measured together, so a walk reading a split
/// node's four children reads neighbouring records) behind a small index (about 16 bytes a
/// node), and each node's links to its children's records, so a selection walk finds a
/// node's children without probing the index (four scattered reads a split node; after the
/// frame thread was idle they are cache misses). Bounds are only added: a node's bounds never
/// change. The records never move and their memory is made resident off the frame thread
/// ([`Records`]).
#[derive(Debug)]
pub(super) struct KnownBounds {
    index: Index,
    records: Records<Record>,
}

/// Shards of the key index, so that growing rehashes one shard (about a sixteenth of the
/// keys) at a time: one map of 28,672 keys took 0.85 ms to grow within a frame, twice that at
/// twice the keys (micro-benchmark, release build, this project's 2-core VM). Keys spread
/// evenly (the low bits of the column and the row), so the shards reach their sizes to grow
/// at different times.
const INDEX_SHARDS: usize = 16;

#[derive(Debug)]
struct Index([FxHashMap<NodeKey, u32>; INDEX_SHARDS]);

impl Index {
    fn with_capacity(nodes: usize) -> Self {
        Self(std::array::from_fn(|_| {
            FxHashMap::with_capacity_and_hasher(
                nodes.div_ceil(INDEX_SHARDS),
                rustc_hash::FxBuildHasher,
            )
        }))
    }

    fn shard(key: NodeKey) -> usize {
        ((key.ix ^ key.iy.rotate_left(2)) as usize) % INDEX_SHARDS
    }

    fn get(&self, key: &NodeKey) -> Option<&u32> {
        self.0[Self::shard(*key)].get(key)
    }

    fn entry(&mut self, key: NodeKey) -> std::collections::hash_map::Entry<'_, NodeKey, u32> {
        self.0[Self::shard(key)].entry(key)
    }
}

/// A known node's bounds and, in [`NodeKey::children`] order, its children's records
/// ([`NO_RECORD`] where not known).
#[derive(Debug, Clone, Copy)]
struct Record {
    bounds: NodeBounds,
    children: [u32; 4],
}

/// A child link to a node whose bounds are not known.
const NO_RECORD: u32 = u32::MAX;

/// A node's bounds as [`KnownBounds`] lends them to a selection walk, with their record (the
/// walk takes its children from there).
#[derive(Debug, Clone, Copy)]
pub(super) struct KnownRef<'a> {
    record: u32,
    bounds: &'a NodeBounds,
}

impl std::borrow::Borrow<NodeBounds> for KnownRef<'_> {
    fn borrow(&self) -> &NodeBounds {
        self.bounds
    }
}

impl<'a> WalkBounds for &'a KnownBounds {
    type Found = KnownRef<'a>;

    fn get(&mut self, key: NodeKey) -> Option<KnownRef<'a>> {
        let known: &'a KnownBounds = self;
        known.find(key)
    }

    fn child(&mut self, parent: &KnownRef<'a>, child: NodeKey) -> Option<KnownRef<'a>> {
        let known: &'a KnownBounds = self;
        let record = known.records.get(parent.record as usize).children[child.child_slot()];
        (record != NO_RECORD).then(|| known.lend(record))
    }
}

impl KnownBounds {
    /// Room for `nodes` in the index from the start (growing it rehashes a shard within one
    /// frame).
    pub(super) fn with_capacity(nodes: usize) -> Self {
        Self {
            index: Index::with_capacity(nodes),
            records: Records::new(Record {
                bounds: NodeBounds::exact(0.0, 0.0),
                children: [NO_RECORD; 4],
            }),
        }
    }

    fn lend(&self, record: u32) -> KnownRef<'_> {
        KnownRef {
            record,
            bounds: &self.records.get(record as usize).bounds,
        }
    }

    /// The node's bounds and record, looked up by key.
    fn find(&self, key: NodeKey) -> Option<KnownRef<'_>> {
        self.index.get(&key).map(|&record| self.lend(record))
    }

    /// Adds bounds not known yet (the first bounds given for a node stay), linked to the
    /// known records of its parent and children.
    pub(super) fn extend(&mut self, fresh: impl IntoIterator<Item = (NodeKey, NodeBounds)>) {
        for (key, b) in fresh {
            let std::collections::hash_map::Entry::Vacant(e) = self.index.entry(key) else {
                continue;
            };
            let record = u32::try_from(self.records.len())
                .ok()
                .filter(|&r| r != NO_RECORD)
                .expect("fewer than 2^32 - 1 known nodes");
            e.insert(record);
            let children = key
                .children()
                .map(|c| self.index.get(&c).copied().unwrap_or(NO_RECORD));
            self.records.push(Record {
                bounds: b,
                children,
            });
            if let Some(&parent) = key.parent().and_then(|p| self.index.get(&p)) {
                self.records.get_mut(parent as usize).children[key.child_slot()] = record;
            }
        }
    }

    #[cfg(test)]
    pub(super) fn len(&self) -> usize {
        self.records.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_bounds_keep_the_first_given_and_find_each_node() {
        let key = |ix| NodeKey {
            level: 3,
            ix,
            iy: 1,
        };
        let mut known = KnownBounds::with_capacity(2);
        known.extend([
            (key(0), NodeBounds::exact(0.0, 1.0)),
            (key(1), NodeBounds::exact(2.0, 3.0)),
        ]);
        known.extend([
            (key(1), NodeBounds::exact(5.0, 6.0)),
            (key(2), NodeBounds::exact(7.0, 9.0)),
        ]);
        assert_eq!(known.len(), 3);
        assert_eq!(known.find(key(0)).map(|b| b.bounds.z_max_m), Some(1.0));
        assert_eq!(
            known.find(key(1)).map(|b| b.bounds.z_min_m),
            Some(2.0),
            "the first bounds stay"
        );
        assert_eq!(known.find(key(2)).map(|b| b.bounds.z_min_m), Some(7.0));
        assert!(known.find(key(3)).is_none());
    }

    /// The keys of a square of nodes, of a strip one node wide, and of a node's descendants
    /// spread over every shard: none holds more than twice its share.
    #[test]
    fn index_shards_share_the_keys_evenly() {
        let square = (0..64u32).flat_map(|ix| (0..64).map(move |iy| (12u8, ix + 100, iy + 37)));
        let strip = (0..4096u32).map(|ix| (14u8, ix, 5));
        let below = (0u8..6).flat_map(|d| {
            let n = 1u32 << d;
            (0..n).flat_map(move |ix| (0..n).map(move |iy| (9 + d, 40 * n + ix, 21 * n + iy)))
        });
        let sets: [Vec<(u8, u32, u32)>; 3] = [square.collect(), strip.collect(), below.collect()];
        for keys in sets {
            let mut per_shard = [0usize; INDEX_SHARDS];
            for &(level, ix, iy) in &keys {
                per_shard[Index::shard(NodeKey { level, ix, iy })] += 1;
            }
            let share = keys.len() / INDEX_SHARDS;
            assert!(
                per_shard.iter().all(|&n| n > 0 && n <= 2 * share),
                "{} keys: {per_shard:?}",
                keys.len()
            );
        }
    }

    /// A walk following the child links reaches the same records as lookups by key, whatever
    /// order the nodes arrived in (parents first, children first, or mixed), and no record
    /// where a child is not known.
    #[test]
    fn child_links_find_what_the_index_finds_in_any_arrival_order() {
        let root = NodeKey::ROOT;
        let mut keys = vec![root];
        keys.extend(root.children());
        keys.extend(root.children()[1].children());
        // Two of the last child's children: the others stay unknown.
        keys.extend(&root.children()[3].children()[..2]);
        let orders = [
            keys.clone(),
            keys.iter().rev().copied().collect(),
            keys[5..]
                .iter()
                .chain(&keys[..5])
                .copied()
                .collect::<Vec<_>>(),
        ];
        for order in orders {
            let mut known = KnownBounds::with_capacity(4);
            for (n, &k) in order.iter().enumerate() {
                let z = n as f64;
                known.extend([(k, NodeBounds::exact(z, z + 1.0))]);
            }
            let mut source = &known;
            let mut linked = 0;
            for &k in &keys {
                let parent = source.find(k).expect("every key was added");
                assert_eq!(Some(&parent.record), known.index.get(&k));
                assert_eq!(
                    *parent.bounds,
                    known.records.get(parent.record as usize).bounds
                );
                for c in k.children() {
                    let found = source.child(&parent, c).map(|r| r.record);
                    assert_eq!(found, known.index.get(&c).copied(), "{k:?} -> {c:?}");
                    linked += usize::from(found.is_some());
                }
            }
            assert_eq!(
                linked,
                keys.len() - 1,
                "every key but the root is a linked child"
            );
        }
    }
}
