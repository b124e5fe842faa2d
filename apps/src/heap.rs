//! The binaries' heap on transparent huge pages.
//!
//! Each frame the frame thread reads the state of thousands of resident nodes (their work,
//! GPU slots, bounds, draw records) spread over a heap of hundreds of MiB, after sleeping while
//! the GPU draws; with 4 KiB pages most of those reads also miss the TLB. glibc's malloc backs
//! its heaps with transparent huge pages (2 MiB) when the tunable `glibc.malloc.hugetlb=1` is
//! set, and it reads tunables only when a process starts, from `GLIBC_TUNABLES`. So a binary
//! that starts without it runs itself again with it, once. Measured on the 2-core VM with
//! lavapipe (`flyover --headless --frames 300`, four rounds, each against the binary without
//! it): the frame thread's on-CPU time per frame p50 -4 to -13 %, p95 -7 to -12 %, the
//! streaming update -13 to -22 %, opening the map 3.4 -> 3.0 s; resident memory +12 - 17 MiB
//! of 2.85 GiB (docs/benchmarks/streaming.md).

/// The variable glibc reads its tunables from, and the tunable.
const TUNABLES: &str = "GLIBC_TUNABLES";
const HUGE_PAGES: &str = "glibc.malloc.hugetlb";

/// On Linux, unless `GLIBC_TUNABLES` already names `glibc.malloc.hugetlb` (set it to
/// `glibc.malloc.hugetlb=0` to run on 4 KiB pages), replaces this process by the same binary
/// with the same arguments and `glibc.malloc.hugetlb=1` added to `GLIBC_TUNABLES`. Call it
/// first in `main`, before any thread starts. Other C libraries ignore the variable (the
/// binary then runs once more, as before). When the binary cannot be run again it says so
/// and goes on here.
pub fn rerun_with_huge_pages() {
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::process::CommandExt;
        let current = std::env::var_os(TUNABLES);
        if current
            .as_ref()
            .is_some_and(|v| v.to_string_lossy().contains(HUGE_PAGES))
        {
            return;
        }
        let Ok(exe) = std::env::current_exe() else {
            return;
        };
        let mut value = std::ffi::OsString::new();
        if let Some(v) = current.filter(|v| !v.is_empty()) {
            value.push(v);
            value.push(":");
        }
        value.push(HUGE_PAGES);
        value.push("=1");
        let mut args = std::env::args_os();
        let mut command = std::process::Command::new(exe);
        if let Some(arg0) = args.next() {
            command.arg0(arg0);
        }
        let error = command.args(args).env(TUNABLES, value).exec();
        eprintln!(
            "warning: could not run again with the heap on huge pages ({error}); going on without"
        );
    }
}
