//! Spans of the frame thread's time: the wall clock and where it went, as far as the platform
//! reports it: on-CPU time, and on Linux the time the thread was ready to run but waited for a
//! core (its run-queue delay, `/proc/thread-self/schedstat`). The wall clock less both is time
//! the thread slept (a lock, a page brought in) or its virtual CPU was not running.

use std::time::Instant;

/// A span of the frame thread's time.
#[derive(Clone, Copy)]
#[allow(clippy::struct_field_names)] // the names carry their unit, seconds
pub(crate) struct Span {
    pub(crate) wall_s: f64,
    pub(crate) on_cpu_s: Option<f64>,
    /// Ready to run, waiting for a core (another thread had it).
    pub(crate) run_queue_s: Option<f64>,
}

/// A span being timed (a copy times the same span: each `stop` reads it up to then).
#[derive(Clone, Copy)]
pub(crate) struct SpanStart {
    wall: Instant,
    on_cpu: Option<cpu_time::ThreadTime>,
    run_delay_ns: Option<u64>,
}

impl Span {
    pub(crate) fn start() -> SpanStart {
        // The wall clock is read first and last, around the other two: a thread is running
        // when it reads them, so the on-CPU time and the waits counted between its reads lie
        // within the wall clock's span, and together never exceed it. (Read outside, a wait
        // just before the span or just after it counted, and the parts could pass the wall
        // clock by a time slice.)
        let wall = Instant::now();
        let run_delay_ns = run_delay_ns();
        SpanStart {
            on_cpu: cpu_time::ThreadTime::try_now().ok(),
            wall,
            run_delay_ns,
        }
    }
}

impl SpanStart {
    pub(crate) fn stop(self) -> Span {
        let on_cpu_s = self
            .on_cpu
            .and_then(|t| t.try_elapsed().ok())
            .map(|d| d.as_secs_f64());
        let run_queue_s = self
            .run_delay_ns
            .zip(run_delay_ns())
            .map(|(a, b)| b.saturating_sub(a) as f64 * 1e-9);
        let wall_s = self.wall.elapsed().as_secs_f64();
        Span {
            wall_s,
            on_cpu_s,
            run_queue_s,
        }
    }
}

/// The calling thread's total time spent waiting on a run queue, ns: the second field of
/// `/proc/thread-self/schedstat` (proc(5)); `None` where there is no such file.
fn run_delay_ns() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    text.split_whitespace().nth(1)?.parse().ok()
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};

    fn spin(seconds: f64) {
        let t = Instant::now();
        while t.elapsed().as_secs_f64() < seconds {
            std::hint::spin_loop();
        }
    }

    /// A thread among three busy threads per core waits on the run queue for most of its wall
    /// clock, and for longer than it did before they started; on-CPU and waiting together
    /// stay within the wall clock. The span runs in steps of 0.1 s until its wait passes a
    /// quarter of it, within 5 s: the busy threads take the cores at the scheduler's pace (a
    /// fixed 0.2 s span once waited only 28 ms, in one full test run).
    #[test]
    fn a_thread_among_busy_threads_waits_on_the_run_queue() {
        assert!(run_delay_ns().is_some(), "no schedstat on this Linux");
        let q = |s: Span| s.run_queue_s.expect("run-queue figure");
        let before = Span::start();
        spin(0.05);
        let before = before.stop();
        let stop = Arc::new(AtomicBool::new(false));
        let cores = std::thread::available_parallelism().map_or(2, usize::from);
        let busy: Vec<_> = (0..3 * cores)
            .map(|_| {
                let stop = Arc::clone(&stop);
                std::thread::spawn(move || {
                    while !stop.load(Ordering::Relaxed) {
                        std::hint::spin_loop();
                    }
                })
            })
            .collect();
        let start = Span::start();
        let deadline = Instant::now() + std::time::Duration::from_secs(5);
        let shared = loop {
            spin(0.1);
            let s = start.stop();
            if q(s) > 0.25 * s.wall_s || Instant::now() > deadline {
                break s;
            }
        };
        stop.store(true, Ordering::Relaxed);
        for b in busy {
            b.join().expect("busy thread");
        }
        // About three quarters of the span waiting (a quarter of a core each).
        assert!(
            q(shared) > 0.25 * shared.wall_s,
            "waited {} s of {} s",
            q(shared),
            shared.wall_s
        );
        assert!(q(before) < q(shared), "{} s before", q(before));
        let parts = shared.on_cpu_s.expect("on-CPU") + q(shared);
        assert!(
            parts <= shared.wall_s * 1.02 + 0.002,
            "on-CPU and waiting {parts} s in a span of {} s",
            shared.wall_s
        );
    }
}
