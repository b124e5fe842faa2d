//! Bounded structured fuzzing of every reader of untrusted input: thousands of
//! mutated inputs per reader (`tests::mutate`, seeded, so every run checks the same inputs),
//! each read in full. Every input must give either a value or an error that names the file and
//! says more than that; never a panic, never more than a bounded heap peak (counted by this
//! binary's global allocator), never a hang. Long, coverage-guided runs of the same readers:
//! the cargo-fuzz targets in `tests/fuzz/`.
//!
//! Inputs per reader: `FUZZ_CASES` (default 2000).

use peak_alloc::PeakAlloc;
use std::panic::AssertUnwindSafe;
use std::sync::Mutex;
use std::time::{Duration, Instant};
use tests::mutate::Mutator;
use tests::readers::{Fixture, Reader};

#[global_allocator]
static HEAP: PeakAlloc = PeakAlloc;

/// The readers share one allocator counter: one at a time.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// Heap a reader may hold at its peak for one input beyond what the process held before: a
/// fixed allowance plus a small multiple of the input (a parser holds its text and what it
/// parsed; text files are capped by `worldgen::map::limits::MAX_TEXT_FILE_BYTES`). Every size a
/// reader allocates from must be checked against its file or the documented limits first.
fn heap_budget_bytes(input_bytes: usize) -> usize {
    (64 << 20) + 32 * input_bytes
}

/// Far above any real read of these small inputs (milliseconds): only a hang or a runaway loop
/// gets near it.
const HANG: Duration = Duration::from_secs(20);

fn cases() -> usize {
    std::env::var("FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2000)
}

#[derive(Default)]
struct Outcome {
    ok: usize,
    refused: usize,
    failures: Vec<String>,
    max_heap: usize,
    max_time: Duration,
}

fn fuzz(fixture: &Fixture, reader: &Reader, seed: u64) -> Outcome {
    let original = fixture.seed(reader);
    // The seed itself must read: otherwise every mutant fails for the same dull reason.
    fixture
        .run(reader, &original)
        .unwrap_or_else(|e| panic!("{}: the seed file is refused: {e}", reader.name));
    let file_name = reader
        .file
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut mutator = Mutator::new(seed);
    let mut out = Outcome::default();
    for case in 0..cases() {
        let input = mutator.mutate(&original, reader.format);
        HEAP.reset_peak_usage();
        let before = HEAP.current_usage();
        let t0 = Instant::now();
        let result = std::panic::catch_unwind(AssertUnwindSafe(|| fixture.run(reader, &input)));
        let took = t0.elapsed();
        let heap = HEAP.peak_usage().saturating_sub(before);
        out.max_heap = out.max_heap.max(heap);
        out.max_time = out.max_time.max(took);
        let mut fail = |why: String| {
            if out.failures.len() < 5 {
                let keep = format!(
                    "target/fuzz-failure-{}-{case}.bin",
                    reader.name.replace(' ', "_")
                );
                let _ = std::fs::write(tests::workspace_root().join(&keep), &input);
                out.failures.push(format!("case {case} ({keep}): {why}"));
            } else {
                out.failures.push(String::new());
            }
        };
        match result {
            Err(panic) => {
                let msg = panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| (*s).to_string()))
                    .unwrap_or_default();
                fail(format!("panicked: {msg}"));
            }
            Ok(Ok(())) => out.ok += 1,
            Ok(Err(e)) => {
                out.refused += 1;
                let names_file = e.contains(&file_name);
                let says_more = e.len() > e.find(&file_name).unwrap_or(0) + file_name.len() + 8;
                if !(names_file && says_more) {
                    fail(format!(
                        "error does not name {file_name} and the problem: {e}"
                    ));
                }
            }
        }
        if heap > heap_budget_bytes(input.len()) {
            fail(format!(
                "heap peak {} MiB over the budget for a {}-byte input",
                heap >> 20,
                input.len()
            ));
        }
        if took > HANG {
            fail(format!("took {took:?}"));
        }
    }
    // Restore the seed for the next reader.
    fixture.run(reader, &original).ok();
    out
}

fn check(name: &str, seed: u64) {
    let _one = ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let fixture = Fixture::new();
    let reader = fixture.reader(name).expect("reader");
    // Panics are expected to be caught: keep their reports out of the output.
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let out = fuzz(&fixture, reader, seed);
    std::panic::set_hook(hook);
    println!(
        "{name}: {} inputs, {} read, {} refused, heap peak {:.1} MiB, slowest {:.1} ms",
        cases(),
        out.ok,
        out.refused,
        out.max_heap as f64 / f64::from(1 << 20),
        out.max_time.as_secs_f64() * 1e3
    );
    assert!(
        out.failures.is_empty(),
        "{name}: {} of {} mutated inputs failed; first ones:\n{}",
        out.failures.len(),
        cases(),
        out.failures
            .iter()
            .filter(|f| !f.is_empty())
            .cloned()
            .collect::<Vec<_>>()
            .join("\n")
    );
    // The mutator must reach past the first check: some inputs read, many refused.
    assert!(
        out.refused > cases() / 10,
        "{name}: only {} refused",
        out.refused
    );
}

#[test]
fn every_reader_is_listed() {
    let fixture = Fixture::new();
    let names: Vec<&str> = fixture.readers().iter().map(|r| r.name).collect();
    assert_eq!(
        names.len(),
        15,
        "{names:?}: add a test below for each new reader"
    );
    // Each reader has its cargo-fuzz target.
    let targets = tests::workspace_root().join("tests/fuzz/fuzz_targets");
    let mut fuzzed = Vec::new();
    for entry in std::fs::read_dir(&targets).expect("fuzz targets folder") {
        let text = std::fs::read_to_string(entry.expect("entry").path()).expect("target");
        if let Some(at) = text.find("check(\"") {
            let rest = &text[at + 7..];
            fuzzed.push(rest[..rest.find('"').unwrap_or(0)].to_string());
        }
    }
    for name in &names {
        assert!(
            fuzzed.iter().any(|f| f == name),
            "no cargo-fuzz target in {} runs {name:?}",
            targets.display()
        );
    }
}

#[test]
fn fuzz_map_toml() {
    check("map.toml", 1);
}

#[test]
fn fuzz_heights_exr() {
    check("heights EXR", 2);
}

#[test]
fn fuzz_ground_png() {
    check("ground PNG", 3);
}

#[test]
fn fuzz_density_png() {
    check("density PNG", 4);
}

#[test]
fn fuzz_trees_csv() {
    check("trees CSV", 5);
}

#[test]
fn fuzz_decals_toml() {
    check("decals TOML", 6);
}

#[test]
fn fuzz_buildings_csv() {
    check("buildings CSV", 7);
}

#[test]
fn fuzz_poisson_csv() {
    check("poisson CSV", 8);
}

#[test]
fn fuzz_house_pm() {
    check("house PM", 9);
}

#[test]
fn fuzz_house_texture_png() {
    check("house texture PNG", 10);
}

#[test]
fn fuzz_material_png() {
    check("material PNG", 11);
}

#[test]
fn fuzz_camera_path() {
    check("camera path", 12);
}

#[test]
fn fuzz_geotiff() {
    check("GeoTIFF", 13);
}

#[test]
fn fuzz_obj_mesh() {
    check("OBJ mesh", 14);
}

#[test]
fn fuzz_gltf_model() {
    check("glTF model", 15);
}
