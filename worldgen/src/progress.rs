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

/// indicatif bars on stderr for the library's long steps (the CLIs'); hidden ones report
/// nothing, and indicatif draws nothing where stderr is not a terminal.
pub struct Bars {
    bar: std::sync::Mutex<Option<indicatif::ProgressBar>>,
    hidden: bool,
}

impl Bars {
    pub fn new(hidden: bool) -> Self {
        Self {
            bar: std::sync::Mutex::new(None),
            hidden,
        }
    }

    /// Moves the current step's bar to `done` units (for steps that report positions).
    pub fn set_position(&self, done: u64) {
        if let Ok(slot) = self.bar.lock()
            && let Some(b) = slot.as_ref()
        {
            b.set_position(done);
        }
    }
}

impl Progress for Bars {
    fn begin(&self, step: &str, total: u64) {
        if self.hidden {
            return;
        }
        let bar = indicatif::ProgressBar::new(total);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{msg:28} [{bar:36}] {percent:>3}% {elapsed_precise} ETA {eta}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
        );
        bar.set_message(step.to_string());
        if let Ok(mut slot) = self.bar.lock() {
            *slot = Some(bar);
        }
    }
    fn advance(&self, n: u64) {
        if let Ok(slot) = self.bar.lock()
            && let Some(b) = slot.as_ref()
        {
            b.inc(n);
        }
    }
    fn end(&self) {
        if let Ok(mut slot) = self.bar.lock()
            && let Some(b) = slot.take()
        {
            b.finish_and_clear();
        }
    }
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

/// The process's resident memory by kind of mapping (Linux `/proc/self/smaps`): where a growth of
/// [`rss_bytes`] lives.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RssParts {
    /// The main thread's malloc heap (the `[heap]` mapping).
    pub main_heap_bytes: u64,
    /// Every other anonymous page: other threads' malloc arenas, large allocations mapped on
    /// their own, thread stacks, the GPU driver's own mappings.
    pub other_anonymous_bytes: u64,
    /// Pages backed by files or shared memory: the code of the program and its libraries,
    /// mapped files.
    pub file_bytes: u64,
}

/// [`RssParts`] now, None where `/proc/self/smaps` cannot be read.
pub fn rss_parts() -> Option<RssParts> {
    let smaps = std::fs::read_to_string("/proc/self/smaps").ok()?;
    Some(parse_smaps(&smaps))
}

/// Sums the `Rss:` and `Anonymous:` fields of each mapping in an smaps listing by kind. Field
/// lines start with a name ending in ':'; every other line starts a mapping (address range,
/// permissions, offset, device, inode, then the path, if any).
fn parse_smaps(smaps: &str) -> RssParts {
    const KIB: u64 = 1024;
    let mut parts = RssParts::default();
    let mut in_heap = false;
    let mut mapping_rss = 0u64;
    for line in smaps.lines() {
        let mut words = line.split_whitespace();
        let Some(first) = words.next() else {
            continue;
        };
        if !first.ends_with(':') {
            in_heap = line.split_whitespace().nth(5) == Some("[heap]");
            mapping_rss = 0;
            continue;
        }
        let Some(kib) = words.next().and_then(|w| w.parse::<u64>().ok()) else {
            continue;
        };
        match first {
            "Rss:" => {
                mapping_rss = kib * KIB;
                if in_heap {
                    parts.main_heap_bytes += mapping_rss;
                }
            }
            "Anonymous:" if !in_heap => {
                parts.other_anonymous_bytes += kib * KIB;
                parts.file_bytes += mapping_rss.saturating_sub(kib * KIB);
            }
            _ => {}
        }
    }
    parts
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smaps_listing_is_split_into_main_heap_anonymous_and_file_pages() {
        let smaps = "\
55d0c0a00000-55d0c0c00000 rw-p 00000000 00:00 0                          [heap]
Size:               2048 kB
Rss:                1500 kB
Anonymous:          1500 kB
VmFlags: rd wr mr mw me ac
7f0000000000-7f0004000000 rw-p 00000000 00:00 0
Rss:                 300 kB
Anonymous:           300 kB
7f1000000000-7f1000100000 r-xp 00000000 08:01 1234                       /usr/lib/libfoo.so
Rss:                 800 kB
Anonymous:            40 kB
";
        assert_eq!(
            parse_smaps(smaps),
            RssParts {
                main_heap_bytes: 1500 * 1024,
                other_anonymous_bytes: 340 * 1024,
                file_bytes: 760 * 1024,
            }
        );
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn the_parts_add_up_to_the_resident_set_and_see_a_touched_allocation() {
        let total = |p: RssParts| p.main_heap_bytes + p.other_anonymous_bytes + p.file_bytes;
        // Other tests of this process allocate and free meanwhile: the checks must hold in one of
        // three tries.
        let mut tries = Vec::new();
        for _ in 0..3 {
            let before = rss_parts().expect("smaps readable on Linux");
            let rss = rss_bytes().expect("VmRSS on Linux");
            // 64 MiB in one allocation is mapped on its own (far above malloc's mmap threshold)
            // and counts as other anonymous memory once touched (filled with ones here).
            let block = vec![1u8; 64 << 20];
            let after = rss_parts().expect("smaps readable");
            assert!(block.iter().step_by(4096).all(|&b| b == 1));
            let grown = after.other_anonymous_bytes as i64 - before.other_anonymous_bytes as i64;
            let sums_up = total(before).abs_diff(rss) < rss / 10 + (4 << 20);
            if sums_up && grown >= 60 << 20 {
                return;
            }
            tries.push((before, rss, grown));
        }
        panic!("parts against VmRSS, and other anonymous growth: {tries:?}");
    }
}
