//! The job queue the owner thread and the workers share: pending node jobs in one bucket per
//! priority class and level. A worker that is free takes the best job itself (lowest class,
//! then coarsest level, then nearest to the camera's last position), so workers never wait
//! for the next frame's hand-off and an urgent job never waits behind jobs handed out before
//! it was requested.
//!
//! (The queue replaced a hand-off of a fixed number of jobs per frame: with one worker it
//! capped throughput at five jobs a frame, 300 jobs/s, while the worker idled.)

use super::jobs::JobMsg;
use crate::terrain::quadtree::{NodeKey, QuadTree};
use glam::DVec3;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError, TryLockError};

/// Pending jobs and the camera position that orders them.
pub(super) struct Pending {
    /// `buckets[class][level]`.
    buckets: Vec<Vec<Vec<JobMsg>>>,
    camera_m: Option<DVec3>,
    /// The number of jobs in the buckets: changed under the lock, readable without it
    /// ([`JobQueue::queued`]).
    len: Arc<AtomicUsize>,
    closed: bool,
}

impl Pending {
    pub(super) fn push(&mut self, class: usize, job: JobMsg) {
        self.buckets[class][usize::from(job.key.level)].push(job);
        self.len.fetch_add(1, Ordering::Relaxed);
    }

    /// Removes `key`'s job from class `class`; `None` when it is not queued there (a worker
    /// took it).
    pub(super) fn remove(&mut self, class: usize, key: NodeKey) -> Option<JobMsg> {
        let bucket = &mut self.buckets[class][usize::from(key.level)];
        let i = bucket.iter().position(|j| j.key == key)?;
        self.len.fetch_sub(1, Ordering::Relaxed);
        Some(bucket.swap_remove(i))
    }

    /// Moves `key`'s job from class `from` to class `to` if it is still queued.
    pub(super) fn promote(&mut self, key: NodeKey, from: usize, to: usize) {
        if let Some(job) = self.remove(from, key) {
            self.push(to, job);
        }
    }

    pub(super) fn set_camera(&mut self, position_m: DVec3) {
        self.camera_m = Some(position_m);
    }

    /// Takes the best job: first non-empty bucket in (class, level) order, the job nearest to
    /// the camera in it (ties by key, so the order does not depend on push order).
    fn take_best(&mut self, tree: &QuadTree) -> Option<JobMsg> {
        let camera_m = self.camera_m;
        let bucket = self.buckets.iter_mut().flatten().find(|b| !b.is_empty())?;
        let i = match camera_m {
            Some(p) => {
                let dist = |k: NodeKey| {
                    let r = tree.rect(k);
                    let c = DVec3::new(
                        (r.min[0] + r.max[0]) * 0.5,
                        (r.min[1] + r.max[1]) * 0.5,
                        p.z,
                    );
                    (c - p).length_squared()
                };
                (0..bucket.len())
                    .min_by(|&a, &b| {
                        let (ka, kb) = (bucket[a].key, bucket[b].key);
                        dist(ka).total_cmp(&dist(kb)).then(ka.cmp(&kb))
                    })
                    .unwrap_or(0)
            }
            None => (0..bucket.len())
                .min_by_key(|&i| bucket[i].key)
                .unwrap_or(0),
        };
        self.len.fetch_sub(1, Ordering::Relaxed);
        Some(bucket.swap_remove(i))
    }
}

/// [`Pending`] behind a lock, with a condition variable that wakes idle workers.
pub(super) struct JobQueue {
    pending: Mutex<Pending>,
    /// [`Pending`]'s count of its jobs.
    queued: Arc<AtomicUsize>,
    wake: Condvar,
}

impl JobQueue {
    pub(super) fn new(classes: usize, levels: usize) -> Self {
        let queued = Arc::new(AtomicUsize::new(0));
        Self {
            pending: Mutex::new(Pending {
                buckets: (0..classes)
                    .map(|_| (0..levels).map(|_| Vec::new()).collect())
                    .collect(),
                camera_m: None,
                len: Arc::clone(&queued),
                closed: false,
            }),
            queued,
            wake: Condvar::new(),
        }
    }

    /// The number of pending jobs, without taking the lock (statistics).
    pub(super) fn queued(&self) -> usize {
        self.queued.load(Ordering::Relaxed)
    }

    /// The pending jobs, locked (the owner batches its changes under one lock; call
    /// [`Self::wake_workers`] after pushing).
    pub(super) fn lock(&self) -> MutexGuard<'_, Pending> {
        self.pending.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The pending jobs, or None while another thread holds them. For the frame thread: a
    /// worker runs at the lowest priority, and one holding the lock can be off its core for a
    /// scheduler tick or more while higher-priority threads run.
    pub(super) fn try_lock(&self) -> Option<MutexGuard<'_, Pending>> {
        match self.pending.try_lock() {
            Ok(p) => Some(p),
            Err(TryLockError::Poisoned(p)) => Some(p.into_inner()),
            Err(TryLockError::WouldBlock) => None,
        }
    }

    pub(super) fn wake_workers(&self) {
        self.wake.notify_all();
    }

    /// Workers stop taking jobs; [`Self::take`] returns `None` from now on.
    pub(super) fn close(&self) {
        self.lock().closed = true;
        self.wake.notify_all();
    }

    /// A worker's wait for its next job: the best pending one, or `None` once closed.
    pub(super) fn take(&self, tree: &QuadTree) -> Option<JobMsg> {
        let mut p = self.lock();
        loop {
            if p.closed {
                return None;
            }
            if let Some(job) = p.take_best(tree) {
                return Some(job);
            }
            p = self.wake.wait(p).unwrap_or_else(PoisonError::into_inner);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stream::NodeWork;
    use std::sync::Arc;
    use std::sync::atomic::AtomicBool;

    fn job(key: NodeKey) -> JobMsg {
        JobMsg {
            key,
            generation: 1,
            cancel: Arc::new(AtomicBool::new(false)),
            start_phase: 0,
            work: Box::new(NodeWork::new(key)),
        }
    }

    /// Jobs come out by class, then level, then distance to the camera; removed and promoted
    /// jobs follow their new place; a closed queue returns nothing.
    #[test]
    fn takes_by_class_then_level_then_distance() {
        let tree = QuadTree::new([0.0, 0.0], [1024.0, 1024.0]);
        let q = JobQueue::new(3, usize::from(tree.max_level) + 1);
        let root = NodeKey::ROOT;
        let [a, b, c, d] = root.children();
        let near_grandchild = a.children()[0];
        {
            let mut p = q.lock();
            // The camera over child `d`'s far corner.
            let r = tree.rect(d);
            p.set_camera(DVec3::new(r.max[0], r.max[1], 50.0));
            p.push(2, job(root));
            p.push(1, job(a));
            p.push(1, job(near_grandchild));
            p.push(1, job(d));
            p.push(1, job(b));
            p.push(2, job(c));
            assert_eq!(q.queued(), 6);
            // `c` moves up to class 0; `b` is cancelled while queued.
            p.promote(c, 2, 0);
            assert!(p.remove(1, b).is_some());
            assert!(p.remove(1, b).is_none());
        }
        let order: Vec<NodeKey> = (0..5).map(|_| q.take(&tree).unwrap().key).collect();
        assert_eq!(order, vec![c, d, a, near_grandchild, root]);
        assert_eq!(q.queued(), 0);
        q.lock().push(0, job(a));
        q.close();
        assert!(q.take(&tree).is_none());
    }
}
