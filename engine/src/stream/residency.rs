//! Residency: which prepared nodes stay (pinned or recently used) under the memory budget, and
//! the statistics of the cache and the job queue.

use super::Streamer;
use super::jobs::RequestState;
use super::predict::PREFETCH_PARTS;
use crate::camera::Camera;
use crate::terrain::quadtree::NodeKey;
use rustc_hash::FxHashSet;
use std::sync::PoisonError;
use std::time::Instant;

/// Eviction goes down to the budget less 1/`EVICTION_SLACK` of it (16 MiB of the default
/// 512 MiB), so that the pass over the resident nodes (2,000 - 5,000 in a 300 m/s flight; about
/// 0.2 ms a pass on the 2-core VM) runs once per 16 MiB of new nodes instead of in
/// every update and every call of the GPU phases that finished a node.
const EVICTION_SLACK: usize = 32;

impl Streamer {
    /// Resident nodes that must stay: needed, prefetched, drawn, or in a fade.
    pub(super) fn pinned(&self) -> FxHashSet<NodeKey> {
        let mut p = self.needed.to_set();
        p.extend(super::predict::entries(&self.prefetch_parts).map(|(_, k)| k));
        p.extend(self.drawn.iter().map(|d| d.key));
        p.extend(self.split.keys().copied());
        p
    }

    /// Bytes of the resident nodes that cannot be evicted now (needed, prefetched, drawn or
    /// in a fade): counted when asked, not every frame.
    pub fn pinned_bytes(&self) -> usize {
        self.pinned()
            .iter()
            .filter_map(|k| self.resident.get(k))
            .map(|r| r.bytes)
            .sum()
    }

    /// Whether `k` is one of [`Self::pinned`] (needed, prefetched, in a fade or drawn), asked
    /// without building that set.
    fn is_pinned(&self, k: &NodeKey) -> bool {
        self.needed.contains(k)
            || self.prefetched(k)
            || self.split.contains_key(k)
            || self.drawn.iter().any(|d| d.key == *k)
    }

    /// Counts `bytes` that a renderer allocated for resident node `key` after the node became
    /// resident (its ground texture, made when the display first needs the node) in the node's
    /// bytes and the cache budget; nothing when `key` is not resident (its GPU objects, the
    /// texture with them, went when it did).
    pub fn charge(&mut self, key: NodeKey, bytes: usize) {
        if let Some(r) = self.resident.get_mut(&key) {
            r.bytes += bytes;
            self.resident_bytes += bytes;
        }
    }

    /// Drops the least recently used prepared nodes that are not pinned once over the memory
    /// budget, down to [`EVICTION_SLACK`] under it (no pinned node goes), so that the pass
    /// over the resident nodes runs once per few megabytes of new nodes, not in every frame of
    /// a flight. Pinned nodes alone may exceed the budget; then nothing else is kept. Within
    /// the budget it costs nothing. Freeing the nodes' memory is left to the dropping thread.
    pub(super) fn evict(&mut self) {
        let budget = self.settings.cache_budget_bytes;
        if self.resident_bytes <= budget {
            return;
        }
        let low_water = budget - budget / EVICTION_SLACK;
        // Every held node is marked used in this frame first: the needed ones are (by this
        // frame's update), so the prefetched, drawn and fading ones are marked here, one
        // lookup each. Then a node not marked in this frame is free without a lookup, and of
        // the marked ones only those that became resident in this frame (marked when they
        // arrived, held or not) are checked. Checking every unmarked node instead took a
        // needed, a fade and a lookup per prefetch part for each of the many free ones.
        let frame = self.frame;
        let held = super::predict::entries(&self.prefetch_parts)
            .map(|(_, k)| k)
            .chain(self.drawn.iter().map(|d| d.key))
            .chain(self.split.keys().copied());
        for k in held {
            if let Some(r) = self.resident.get_mut(&k) {
                r.last_used_frame = frame;
            }
        }
        let free = |k: &NodeKey, r: &super::Resident| {
            r.last_used_frame < frame || (r.ready_frame == frame && !self.is_pinned(k))
        };
        // Least recently used first (ties by key); a heap, as a pass evicts few of many.
        let mut candidates: std::collections::BinaryHeap<_> = self
            .resident
            .iter()
            .filter(|(k, r)| free(k, r))
            .map(|(k, r)| std::cmp::Reverse((r.last_used_frame, *k)))
            .collect();
        // What the marks stand for, checked against the sets themselves in debug builds (the
        // tests' builds): no pinned node is a candidate.
        #[cfg(debug_assertions)]
        let pinned = self.pinned();
        while self.resident_bytes > low_water {
            let Some(std::cmp::Reverse((_, k))) = candidates.pop() else {
                break;
            };
            #[cfg(debug_assertions)]
            assert!(!pinned.contains(&k), "eviction chose pinned node {k:?}");
            if let Some(r) = self.resident.remove(&k) {
                self.resident_bytes -= r.bytes;
                self.dropper.drop_node(r.work);
                self.stats.evicted += 1;
            }
        }
    }

    /// The statistics after a frame or a GPU phase.
    pub(super) fn refresh_stats(&mut self) {
        let (mut in_workers, mut g) = (0, 0);
        for req in self.requests.values() {
            match req.state {
                RequestState::InWorkers { .. } => in_workers += 1,
                RequestState::WaitingGpu { .. } => g += 1,
            }
        }
        // Jobs a worker took and has not reported yet count as running (cancelled ones are no
        // longer requests).
        let q = self.queue.queued().min(in_workers);
        self.stats.queued = q;
        self.stats.running = in_workers - q;
        self.stats.waiting_gpu = g;
        self.stats.resident = self.resident.len();
        debug_assert_eq!(
            self.resident_bytes,
            self.resident.values().map(|r| r.bytes).sum::<usize>()
        );
        self.stats.resident_bytes = self.resident_bytes;
        self.stats.wanted = self.wanted.len();
        self.stats.drawn = self.drawn.len();
    }

    /// Takes the latencies of the jobs completed since the last call.
    pub fn take_latencies(&mut self) -> Vec<super::JobLatency> {
        std::mem::take(&mut self.stats.latencies)
    }

    /// Keys of all resident nodes.
    pub fn resident_keys(&self) -> Vec<NodeKey> {
        let mut v: Vec<NodeKey> = self.resident.keys().copied().collect();
        v.sort_unstable();
        v
    }

    /// Waits (up to `timeout_s`) until no job is queued, running or waiting for the GPU, every
    /// needed node is resident and no fade is in progress, running GPU phases as they arrive,
    /// for a whole round of prefetch parts (so the prefetch selections use the bounds now
    /// known). Returns false on timeout.
    pub fn settle(&mut self, cam: &Camera, timeout_s: f64) -> bool {
        self.settle_with(timeout_s, |s| s.update(cam, 1.0 / 60.0))
    }

    /// [`Self::settle`] for a camera already in flight along a known path: `future` as in
    /// [`Self::update_along`], so what the prefetch along it requests is resident too (the
    /// state of a flight in progress, not of a camera at rest about to start).
    pub fn settle_along(&mut self, cam: &Camera, future: &[(f64, Camera)], timeout_s: f64) -> bool {
        self.settle_with(timeout_s, |s| s.update_along(cam, 1.0 / 60.0, future))
    }

    fn settle_with(&mut self, timeout_s: f64, mut update: impl FnMut(&mut Self)) -> bool {
        let t0 = Instant::now();
        // Quiet updates in a row: settled after a whole round of prefetch parts (one part's
        // selection is redone per update, with the bounds known by then) asked for nothing.
        let mut quiet = 0;
        loop {
            update(self);
            self.run_gpu_phases();
            let settled = self.requests.is_empty()
                && self.cancelled_outstanding() == 0
                && self.needed.iter().all(|k| self.resident.contains_key(&k))
                && self.split.values().all(|&v| v >= 1.0);
            quiet = if settled { quiet + 1 } else { 0 };
            if quiet >= PREFETCH_PARTS {
                return true;
            }
            if t0.elapsed().as_secs_f64() > timeout_s {
                return false;
            }
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
    }

    /// Nodes needed for display (wanted, ancestors, and children of split ancestors).
    pub fn needed(&self) -> &super::NeededSet {
        &self.needed
    }

    /// Tiles currently held (by running jobs).
    pub fn tiles_resident(&self) -> usize {
        self.shared
            .tiles
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .resident()
    }
}
