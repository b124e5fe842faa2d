//! A short soak: the viewer flies the automatic flight in loops on the tiny map for
//! 20 s, sampled every second; afterwards, settled on one view, no job, cancellation or tile is
//! left over, the cache is within its budget, and the samples carry the GPU memory counters.
//! The 30-minute soak is `nodebench --only soak --soak-minutes 30` (docs/guides/soak.md).

use engine::soak::{SoakParams, run};
use engine::stream::{MAX_LATENCIES_KEPT, StreamSettings};
use std::time::Duration;

#[test]
fn a_short_soak_leaks_no_job_or_tile_and_stays_in_budget() {
    let Some(g) = tests::gpu::device() else {
        return;
    };
    let budget = 96 << 20;
    let params = SoakParams {
        duration: Duration::from_secs(20),
        lap_s: 8.0,
        size_px: [320, 180],
        settings: StreamSettings {
            workers: 1,
            cache_budget_bytes: budget,
            ..StreamSettings::default()
        },
    };
    let mut seen = 0;
    let report = run(&g, tests::terrain::tiny_world(), &params, |_| seen += 1).expect("soak");
    let n = report.samples.len();
    assert_eq!(seen, n);
    assert!((20..=22).contains(&n), "{n} samples in 20 s");
    let last = report.samples.last().unwrap();
    assert!(last.frames > 20, "only {} frames", last.frames);
    // The counters are live: GPU buffers and textures exist and are counted.
    assert!(
        report
            .samples
            .iter()
            .all(|s| s.gpu_buffer_bytes > 0 && s.gpu_texture_bytes > 0 && s.gpu_buffers > 0),
        "{:?}",
        report.samples[0]
    );
    assert!(report.samples.iter().all(|s| s.rss_bytes.is_some()
        && s.rss_main_heap_bytes.is_some()
        && s.rss_other_anonymous_bytes.is_some()
        && s.rss_file_bytes.is_some()));
    assert!(
        report
            .samples
            .iter()
            .all(|s| s.latencies_kept <= MAX_LATENCIES_KEPT)
    );
    let e = &report.end;
    assert!(e.settled, "{e:?}");
    assert!(e.jobs_requested > 0, "{e:?}");
    assert_eq!(
        (e.jobs_in_flight, e.cancels_outstanding, e.tiles_held),
        (0, 0, 0),
        "left over after the soak: {e:?}"
    );
    assert!(e.cache_bytes <= e.cache_budget_bytes, "{e:?}");
}
