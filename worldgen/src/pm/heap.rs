//! The collapse order's priority queue: one entry per position, its cheapest collapse and that
//! collapse's key, in an indexed binary min-heap updated in place.

use std::cmp::Ordering;

/// Priority key: tier (0 normal, then `TIER_FEATURE` and `TIER_FLIP` of the builder), then cost,
/// then the removed end's cornerness.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Key {
    pub(super) tier: u8,
    pub(super) cost: f64,
    pub(super) tie: f64,
}

impl Key {
    pub(super) fn cmp_key(&self, o: &Self) -> Ordering {
        self.tier
            .cmp(&o.tier)
            .then(self.cost.total_cmp(&o.cost))
            .then(self.tie.total_cmp(&o.tie))
    }
}

/// One heap entry: a position, its best collapse target and that collapse's key.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct HeapEntry {
    pub(super) key: Key,
    pub(super) pos: u32,
    pub(super) target: u32,
}

/// An indexed binary min-heap of positions by their best collapse: one entry per position,
/// updated in place (no stale entries to skip). Entries hold their keys, so sifting reads the
/// heap array only (and `orig` on equal keys).
pub(super) struct PosHeap<'a> {
    heap: Vec<HeapEntry>,
    slot: Vec<u32>,
    /// Input index of every position: equal keys go to the lower one (deterministic, and
    /// independent of the renumbering).
    orig: &'a [u32],
}

const NO_SLOT: u32 = u32::MAX;

impl<'a> PosHeap<'a> {
    pub(super) fn new(orig: &'a [u32]) -> Self {
        PosHeap {
            heap: Vec::with_capacity(orig.len()),
            slot: vec![NO_SLOT; orig.len()],
            orig,
        }
    }

    /// Heap order: key, then the lower input position (one entry per position, so this is a
    /// strict order and the pops do not depend on the heap's layout).
    fn less(&self, a: &HeapEntry, b: &HeapEntry) -> bool {
        match a.key.cmp_key(&b.key) {
            Ordering::Less => true,
            Ordering::Greater => false,
            Ordering::Equal => self.orig[a.pos as usize] < self.orig[b.pos as usize],
        }
    }

    fn place(&mut self, i: usize, e: HeapEntry) {
        self.slot[e.pos as usize] = i as u32;
        self.heap[i] = e;
    }

    /// Puts `e` into the hole at `i`, moving parents down while `e` is less.
    fn up(&mut self, mut i: usize, e: HeapEntry) {
        while i > 0 {
            let parent = (i - 1) / 2;
            if !self.less(&e, &self.heap[parent]) {
                break;
            }
            self.place(i, self.heap[parent]);
            i = parent;
        }
        self.place(i, e);
    }

    /// The lesser of entry `i`'s children, if it has any.
    fn lesser_child(&self, i: usize) -> Option<usize> {
        let (l, n) = (2 * i + 1, self.heap.len());
        if l >= n {
            None
        } else if l + 1 < n && self.less(&self.heap[l + 1], &self.heap[l]) {
            Some(l + 1)
        } else {
            Some(l)
        }
    }

    /// Puts `e` into the hole at `i`, moving the lesser child up while it is less than `e`.
    fn down(&mut self, mut i: usize, e: HeapEntry) {
        while let Some(m) = self.lesser_child(i) {
            if !self.less(&self.heap[m], &e) {
                break;
            }
            self.place(i, self.heap[m]);
            i = m;
        }
        self.place(i, e);
    }

    /// Inserts or updates position `p`'s entry (nothing moves when it is unchanged).
    pub(super) fn set(&mut self, p: u32, key: Key, target: u32) {
        let entry = HeapEntry {
            key,
            pos: p,
            target,
        };
        let s = self.slot[p as usize];
        if s == NO_SLOT {
            self.heap.push(entry);
            self.up(self.heap.len() - 1, entry);
        } else {
            let i = s as usize;
            let old = self.heap[i];
            if old == entry {
                return;
            }
            if self.less(&entry, &old) {
                self.up(i, entry);
            } else {
                self.down(i, entry);
            }
        }
    }

    pub(super) fn remove(&mut self, p: u32) {
        let s = self.slot[p as usize];
        if s == NO_SLOT {
            return;
        }
        self.slot[p as usize] = NO_SLOT;
        let i = s as usize;
        let last = self.heap.pop().expect("a slotted entry is in the heap");
        if i == self.heap.len() {
            return;
        }
        if i > 0 && self.less(&last, &self.heap[(i - 1) / 2]) {
            self.up(i, last);
            return;
        }
        // Floyd's order: the hole goes down to a leaf along the lesser children (one
        // comparison a level), then the last entry, which came from the bottom, rises.
        let mut hole = i;
        while let Some(m) = self.lesser_child(hole) {
            self.place(hole, self.heap[m]);
            hole = m;
        }
        self.up(hole, last);
    }

    pub(super) fn entry(&self, p: u32) -> Option<&HeapEntry> {
        let s = self.slot[p as usize];
        (s != NO_SLOT).then(|| &self.heap[s as usize])
    }

    pub(super) fn peek(&self) -> Option<(u32, Key, u32)> {
        let e = self.heap.first()?;
        Some((e.pos, e.key, e.target))
    }
}
