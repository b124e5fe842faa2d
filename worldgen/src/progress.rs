//! Progress reporting for long steps, decoupled from the terminal so the library stays quiet in
//! tests and the CLI can show indicatif bars.

/// Receives progress of long steps. Implementations must be cheap and thread-safe.
pub trait Progress: Sync {
    /// A step named `step` starts, with `total` units of work.
    fn begin(&self, step: &str, total: u64);
    /// `n` more units of the current step are done.
    fn advance(&self, n: u64);
    /// The current step is finished.
    fn end(&self);
}

/// Reports nothing.
#[derive(Debug, Default, Clone, Copy)]
pub struct Silent;

impl Progress for Silent {
    fn begin(&self, _step: &str, _total: u64) {}
    fn advance(&self, _n: u64) {}
    fn end(&self) {}
}

/// Wall time of one named step.
#[derive(Debug, Clone)]
pub struct StepTime {
    pub step: String,
    pub duration_s: f64,
}

/// Runs `f` as a named step, timing it and recording the time into `times`.
pub fn timed<R>(times: &mut Vec<StepTime>, step: &str, f: impl FnOnce() -> R) -> R {
    let t0 = std::time::Instant::now();
    let r = f();
    times.push(StepTime {
        step: step.to_string(),
        duration_s: t0.elapsed().as_secs_f64(),
    });
    log::info!("{step}: {:.3} s", t0.elapsed().as_secs_f64());
    r
}

/// The process's peak resident memory so far (Linux `VmHWM`), None where it is not reported.
pub fn peak_rss_bytes() -> Option<u64> {
    status_kib("VmHWM:").map(|k| k * 1024)
}

/// The process's resident memory now (Linux `VmRSS`), None where it is not reported.
pub fn rss_bytes() -> Option<u64> {
    status_kib("VmRSS:").map(|k| k * 1024)
}

fn status_kib(field: &str) -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with(field))?;
    line.split_whitespace().nth(1)?.parse().ok()
}
