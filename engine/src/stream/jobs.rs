//! Jobs: requests, the worker threads that run CPU phases, cancellation, result collection and
//! the GPU phases on the owner thread.

use super::queue::{JobQueue, Pending};
use super::{JobLatency, NodeWork, Phase, PhaseKind, Resident, Shared, Streamer};
use crate::terrain::quadtree::NodeKey;
use crossbeam_channel::Sender;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, PoisonError};
use std::time::Instant;

/// What a worker sends back.
pub(super) enum JobResult {
    /// CPU phases done; the next phase index (a GPU phase) or `phases.len()` when complete.
    Done {
        key: NodeKey,
        generation: u64,
        work: Box<NodeWork>,
        next_phase: usize,
    },
    Cancelled,
}

pub(super) struct JobMsg {
    pub(super) key: NodeKey,
    pub(super) generation: u64,
    pub(super) cancel: Arc<AtomicBool>,
    pub(super) start_phase: usize,
    pub(super) work: Box<NodeWork>,
}

/// A request's state on the owner thread.
pub(super) enum RequestState {
    /// In the shared queue or taken by a worker (the owner does not track which: a worker
    /// takes jobs without telling it; cancelling finds out).
    InWorkers { cancel: Arc<AtomicBool> },
    WaitingGpu {
        work: Box<NodeWork>,
        next_phase: usize,
    },
}

pub(super) struct Request {
    pub(super) generation: u64,
    pub(super) state: RequestState,
    pub(super) requested_at: Instant,
    /// When the node was first needed for display (requested in, or promoted to, class 0).
    pub(super) needed_at: Option<Instant>,
    /// Priority class: 0 needed for display, then prefetch by time to need (see
    /// [`super::predict::CLASSES`]).
    pub(super) class: usize,
}

/// Releases the tiles a job holds (a core phase, and on cancellation).
pub(super) fn release_tiles(s: &Shared, w: &mut NodeWork) {
    if w.tiles.is_empty() {
        return;
    }
    let mut tiles = s.tiles.lock().unwrap_or_else(PoisonError::into_inner);
    for (k, _) in w.tiles.drain(..) {
        tiles.release(k);
    }
}

/// Runs the calling (worker) thread below the thread that owns the streamer (the render
/// thread): at the lowest normal priority, and on Linux under the batch policy (no wakeup
/// preemption), so that with as many workers as cores the frame's bookkeeping still gets a
/// core when it needs one. Best effort: a refusal is logged.
pub fn lower_priority() {
    use thread_priority::ThreadPriority;
    #[cfg(target_os = "linux")]
    let result = thread_priority::unix::set_thread_priority_and_policy(
        thread_priority::unix::thread_native_id(),
        ThreadPriority::Min,
        thread_priority::unix::ThreadSchedulePolicy::Normal(
            thread_priority::unix::NormalThreadSchedulePolicy::Batch,
        ),
    );
    #[cfg(not(target_os = "linux"))]
    let result = thread_priority::set_current_thread_priority(ThreadPriority::Min);
    if let Err(e) = result {
        log::warn!("node worker keeps its normal priority: {e:?}");
    }
}

/// Runs the calling thread below the node workers too, for work that no frame waits for (the
/// light grids): on Linux under the idle policy (it gets a core only while no worker or frame
/// thread wants it; at the workers' lowest normal priority it would take half of a shared core
/// from them), elsewhere as [`lower_priority`]. Best effort: a refusal is logged.
pub fn idle_priority() {
    #[cfg(target_os = "linux")]
    {
        let result = thread_priority::unix::set_thread_priority_and_policy(
            thread_priority::unix::thread_native_id(),
            thread_priority::ThreadPriority::Min,
            thread_priority::unix::ThreadSchedulePolicy::Normal(
                thread_priority::unix::NormalThreadSchedulePolicy::Idle,
            ),
        );
        if let Err(e) = result {
            log::warn!("background thread keeps the workers' priority: {e:?}");
            lower_priority();
        }
    }
    #[cfg(not(target_os = "linux"))]
    lower_priority();
}

pub(super) fn worker_loop(
    shared: &Shared,
    phases: &[Phase],
    queue: &JobQueue,
    tx: &Sender<JobResult>,
) {
    lower_priority();
    while let Some(mut job) = queue.take(&shared.tree) {
        let mut i = job.start_phase;
        let mut cancelled = false;
        while i < phases.len() && phases[i].kind == PhaseKind::Cpu {
            if job.cancel.load(Ordering::Acquire) {
                cancelled = true;
                break;
            }
            (phases[i].run)(shared, &mut job.work);
            i += 1;
        }
        let msg = if cancelled {
            release_tiles(shared, &mut job.work);
            JobResult::Cancelled
        } else {
            JobResult::Done {
                key: job.key,
                generation: job.generation,
                work: job.work,
                next_phase: i,
            }
        };
        if tx.send(msg).is_err() {
            break;
        }
    }
}

impl Streamer {
    /// Queues a job for `key` in priority class `class` (the caller holds the queue's lock and
    /// wakes the workers after its batch).
    pub(super) fn request(&mut self, pending: &mut Pending, key: NodeKey, class: usize) {
        let generation = self.next_generation;
        self.next_generation += 1;
        let cancel = Arc::new(AtomicBool::new(false));
        let now = Instant::now();
        pending.push(
            class,
            JobMsg {
                key,
                generation,
                cancel: Arc::clone(&cancel),
                start_phase: 0,
                work: Box::new(NodeWork::new(key)),
            },
        );
        self.requests.insert(
            key,
            Request {
                generation,
                state: RequestState::InWorkers { cancel },
                requested_at: now,
                needed_at: (class == 0).then_some(now),
                class,
            },
        );
        self.stats.requested += 1;
    }

    /// Cancels `key`'s request (the caller holds the queue's lock): a queued job is removed, a
    /// running one is told to stop at its next phase boundary, one waiting for its GPU phase
    /// is dropped.
    pub(super) fn cancel(&mut self, pending: &mut Pending, key: NodeKey) {
        let Some(req) = self.requests.remove(&key) else {
            return;
        };
        match req.state {
            RequestState::InWorkers { cancel } => {
                if let Some(mut job) = pending.remove(req.class, key) {
                    release_tiles(&self.shared, &mut job.work);
                    self.stats.cancelled_queued += 1;
                } else {
                    cancel.store(true, Ordering::Release);
                    self.stats.cancelled_running += 1;
                }
            }
            RequestState::WaitingGpu { mut work, .. } => {
                release_tiles(&self.shared, &mut work);
                self.dropper.drop_node(work);
                self.stats.cancelled_gpu += 1;
            }
        }
    }

    pub(super) fn collect_results(&mut self) {
        while let Ok(res) = self.from_workers.try_recv() {
            match res {
                JobResult::Cancelled => self.stats.cancels_acknowledged += 1,
                JobResult::Done {
                    key,
                    generation,
                    mut work,
                    next_phase,
                } => {
                    let current = self
                        .requests
                        .get(&key)
                        .is_some_and(|r| r.generation == generation);
                    if !current {
                        // A cancelled (or superseded) job's late result: never shown.
                        release_tiles(&self.shared, &mut work);
                        self.dropper.drop_node(work);
                        self.stats.late_results_discarded += 1;
                        continue;
                    }
                    if next_phase < self.phases.len() {
                        if let Some(r) = self.requests.get_mut(&key) {
                            r.state = RequestState::WaitingGpu { work, next_phase };
                        }
                    } else {
                        self.finish(key, work);
                    }
                }
            }
        }
    }

    pub(super) fn finish(&mut self, key: NodeKey, work: Box<NodeWork>) {
        if let Some(req) = self.requests.remove(&key) {
            // Nobody may read the log (the viewer does not): keep the newest ones only.
            if self.stats.latencies.len() >= super::MAX_LATENCIES_KEPT {
                self.stats.latencies.drain(..super::MAX_LATENCIES_KEPT / 2);
            }
            self.stats.latencies.push(JobLatency {
                request_to_ready_s: req.requested_at.elapsed().as_secs_f64(),
                need_to_ready_s: req.needed_at.map(|t| t.elapsed().as_secs_f64()),
                gpu_phases_s: work.gpu_phases_s,
            });
        }
        self.stats.completed += 1;
        let bytes = work.bytes();
        self.resident_bytes += bytes;
        let old = self.resident.insert(
            key,
            Resident {
                bytes,
                work,
                last_used_frame: self.frame,
                ready_frame: self.frame,
            },
        );
        if let Some(old) = old {
            self.resident_bytes -= old.bytes;
            self.dropper.drop_node(old.work);
        }
    }

    /// Runs waiting GPU phases (coarsest, then oldest first) until the frame's time or byte
    /// budget is spent; at least one per call. Returns the number of phases run.
    pub fn run_gpu_phases(&mut self) -> usize {
        self.run_gpu_phases_with(&mut |_, _| {})
    }

    /// [`Self::run_gpu_phases`] where each GPU phase also calls `upload` (the renderer creates
    /// the node's buffers there and stores them in [`NodeWork::gpu`]).
    pub fn run_gpu_phases_with(&mut self, upload: &mut dyn FnMut(&Shared, &mut NodeWork)) -> usize {
        self.run_gpu_phases_within(self.settings.gpu_budget_s, upload)
    }

    /// [`Self::run_gpu_phases_with`] under a time budget of `budget_s` this frame instead of
    /// the settings' (the byte budget stays).
    pub fn run_gpu_phases_within(
        &mut self,
        budget_s: f64,
        upload: &mut dyn FnMut(&Shared, &mut NodeWork),
    ) -> usize {
        let t0 = Instant::now();
        let mut bytes = 0usize;
        let mut gpu_s = 0.0;
        let mut order: Vec<(u8, u64, NodeKey)> = self
            .requests
            .iter()
            .filter(|(_, r)| matches!(r.state, RequestState::WaitingGpu { .. }))
            .map(|(k, r)| (k.level, r.generation, *k))
            .collect();
        order.sort_unstable();
        let mut ran = 0;
        for (_, _, key) in order {
            if ran > 0
                && (t0.elapsed().as_secs_f64() + gpu_s >= budget_s
                    || bytes >= self.settings.gpu_budget_bytes)
            {
                break;
            }
            let Some(req) = self.requests.get_mut(&key) else {
                continue;
            };
            let RequestState::WaitingGpu { work, next_phase } = &mut req.state else {
                continue;
            };
            let mut w = std::mem::replace(work, Box::new(NodeWork::new(key)));
            let mut i = *next_phase;
            let t = Instant::now();
            while i < self.phases.len() && self.phases[i].kind == PhaseKind::Gpu {
                (self.phases[i].run)(&self.shared, &mut w);
                upload(&self.shared, &mut w);
                i += 1;
            }
            w.gpu_phases_s += t.elapsed().as_secs_f64();
            bytes += w.uploaded_bytes;
            gpu_s += w.gpu_estimate_s;
            ran += 1;
            if i >= self.phases.len() {
                self.finish(key, w);
            } else {
                // More CPU phases follow: back to the workers, in the request's class.
                let cancel = Arc::new(AtomicBool::new(false));
                let (generation, class) = (req.generation, req.class);
                req.state = RequestState::InWorkers {
                    cancel: Arc::clone(&cancel),
                };
                self.queue.lock().push(
                    class,
                    JobMsg {
                        key,
                        generation,
                        cancel,
                        start_phase: i,
                        work: w,
                    },
                );
                self.queue.wake_workers();
            }
        }
        // Finished nodes change the draw list only when the root first becomes ready (splits
        // wait for fades, which advance in `update`).
        if self.drawn.is_empty() && self.resident.contains_key(&NodeKey::ROOT) {
            self.advance_fades_and_draw(None);
        }
        // Finished nodes add bytes: keep the cache within its budget here too, not only in
        // `update` (otherwise the budget holds only until the next GPU phase).
        self.evict();
        self.refresh_stats();
        ran
    }

    /// Cancelled running jobs whose worker has not reported back yet (it will: with an
    /// acknowledgement at the next phase boundary, or a late result that is discarded).
    pub fn cancelled_outstanding(&self) -> u64 {
        self.stats.cancelled_running
            - self.stats.cancels_acknowledged
            - self.stats.late_results_discarded
    }
}

impl Drop for Streamer {
    fn drop(&mut self) {
        // Cancel everything, close the channel, and join the workers.
        for req in self.requests.values() {
            if let RequestState::InWorkers { cancel } = &req.state {
                cancel.store(true, Ordering::Release);
            }
        }
        self.queue.close();
        for w in self.workers.drain(..) {
            let _ = w.join();
        }
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    /// The calling thread's scheduling policy, field 41 of `/proc/thread-self/stat`
    /// (proc(5)); fields are counted after the command name, which may hold spaces.
    fn policy_of_this_thread() -> u32 {
        let stat = std::fs::read_to_string("/proc/thread-self/stat").expect("proc stat");
        let after_name = &stat[stat.rfind(')').expect("name") + 1..];
        let fields: Vec<&str> = after_name.split_whitespace().collect();
        fields[41 - 3].parse().expect("policy")
    }

    #[test]
    fn light_work_runs_below_the_node_workers() {
        const SCHED_BATCH: u32 = 3;
        const SCHED_IDLE: u32 = 5;
        let worker = std::thread::spawn(|| {
            super::lower_priority();
            policy_of_this_thread()
        });
        let light = std::thread::spawn(|| {
            super::idle_priority();
            policy_of_this_thread()
        });
        assert_eq!(worker.join().expect("worker"), SCHED_BATCH);
        assert_eq!(light.join().expect("light"), SCHED_IDLE);
    }
}
