//! The README's table of headline figures, generated from the benchmark documents under
//! `docs/benchmarks/` (each written by one nodebench run): every figure is a row picked by its
//! section, metric and parameters, shown with the document it comes from. `headline` writes
//! the table into README.md between two marker lines; a unit test checks that the README's
//! table is what the documents give, so neither can change without the other.

use std::fmt::Write as _;
use std::path::Path;

/// The line before the generated table in README.md.
pub const BEGIN: &str = "<!-- headline figures: generated from docs/benchmarks by `cargo run -p apps --bin headline`; edits here are overwritten -->";
/// The line after it.
pub const END: &str = "<!-- end of headline figures -->";

/// One figure: its label in the README, the benchmark document (under `docs/benchmarks/`) and
/// the row: section, metric, and text every matching row's parameters contain.
struct Figure {
    label: &'static str,
    doc: &'static str,
    section: &'static str,
    metric: &'static str,
    params: &'static [&'static str],
}

const STREAMING_300: &[&str] = &[
    "300 m/s at 40 m",
    "warm start in flight",
    "1 worker(s)",
    "houses on",
    "light grids on",
    "ground textures on",
];

const FIGURES: &[Figure] = &[
    Figure {
        label: "on-screen max terrain error at τ = 2 px, 60° 16:9 (measured)",
        doc: "pixel-error.md",
        section: "error",
        metric: "grid on-screen measured max error",
        params: &["tau 2 px, 60° 16:9"],
    },
    Figure {
        label: "the same at 90° 21:9",
        doc: "pixel-error.md",
        section: "error",
        metric: "grid on-screen measured max error",
        params: &["tau 2 px, 90° 21:9"],
    },
    Figure {
        label: "terrain triangles per frame at τ = 2 px, 1280x720",
        doc: "pixel-error.md",
        section: "selection",
        metric: "triangles per frame",
        params: &["tau 2 px, 60° 16:9"],
    },
    Figure {
        label: "selection per frame, p50",
        doc: "pixel-error.md",
        section: "selection",
        metric: "selection per frame (bounds cached) p50",
        params: &["tau 2 px, 60° 16:9"],
    },
    Figure {
        label: "node preparation (all CPU phases), p50",
        doc: "benchmarks.md",
        section: "terrain",
        metric: "node preparation, all CPU phases, p50",
        params: &[],
    },
    Figure {
        label: "node preparation (all CPU phases), p99",
        doc: "benchmarks.md",
        section: "terrain",
        metric: "node preparation, all CPU phases, p99",
        params: &[],
    },
    Figure {
        label: "pop debt at 300 m/s, 1 worker, everything on",
        doc: "benchmarks.md",
        section: "streaming",
        metric: "pop debt (frames with a drawn node over tau)",
        params: STREAMING_300,
    },
    Figure {
        label: "request-to-ready p99 at 300 m/s, 1 worker, everything on",
        doc: "benchmarks.md",
        section: "streaming",
        metric: "request-to-ready latency p99",
        params: STREAMING_300,
    },
    Figure {
        label: "draw calls per frame (terrain, vegetation, houses), 720p",
        doc: "benchmarks.md",
        section: "gpu",
        metric: "draw calls per frame (terrain + vegetation + houses), median",
        params: &["1280x720"],
    },
    Figure {
        label: "terrain triangles saved behind vegetation at eye height (opt-in rule)",
        doc: "vegetation.md",
        section: "vegetation",
        metric: "occlusion, rendered: terrain triangles saved",
        params: &["tau 2 px"],
    },
    Figure {
        label: "… and the terrain error it shows (τ = 2 px)",
        doc: "vegetation.md",
        section: "vegetation",
        metric: "occlusion, rendered: on-screen max error shown, with the rule",
        params: &["tau 2 px"],
    },
    Figure {
        label: "worst image error of a vegetation switch at τ = 2 px (group billboard -> billboard)",
        doc: "vegetation.md",
        section: "vegetation",
        metric: "switch image error, group billboard -> billboard: max",
        params: &["tau 2 px"],
    },
    Figure {
        label: "worst house image error at τ = 2 px (town orbit at 400 m, near a corner)",
        doc: "buildings.md",
        section: "buildings",
        metric: "house image error at 400 m, near its corner: max",
        params: &["tau 2 px"],
    },
    Figure {
        label: "32 km map after `worldgen bake`: from the open to the first frame showing it",
        doc: "worlds.md",
        section: "worlds",
        metric: "flyover 32768 m, first open: from the open to the first frame showing the world",
        params: &[],
    },
    Figure {
        label: "32 km world held in memory during the flight (pages cached apart, 128 MiB)",
        doc: "worlds.md",
        section: "worlds",
        metric: "flyover 32768 m, first open: world held whole in memory",
        params: &[],
    },
];

/// The table rows of a benchmark document: (section, metric, value, unit, parameters).
fn rows(text: &str) -> Vec<[&str; 5]> {
    text.lines()
        .filter_map(|l| {
            let f: Vec<&str> = l.strip_prefix('|')?.strip_suffix('|')?.split('|').collect();
            let f: Vec<&str> = f.iter().map(|s| s.trim()).collect();
            (f.len() == 5).then(|| [f[0], f[1], f[2], f[3], f[4]])
        })
        .collect()
}

/// The generated table (Markdown, without the markers) from the documents under
/// `<root>/docs/benchmarks/`; an error names the document and the figure it lacks.
pub fn table(root: &Path) -> Result<String, String> {
    let mut out = String::from("| figure | value | from |\n|---|---:|---|\n");
    for f in FIGURES {
        let path = root.join("docs/benchmarks").join(f.doc);
        let text = std::fs::read_to_string(&path)
            .map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
        let row = rows(&text)
            .into_iter()
            .find(|r| {
                r[0] == f.section && r[1] == f.metric && f.params.iter().all(|p| r[4].contains(p))
            })
            .ok_or_else(|| {
                format!(
                    "{}: no row {} | {} with parameters {:?} (for the README figure {:?})",
                    path.display(),
                    f.section,
                    f.metric,
                    f.params,
                    f.label
                )
            })?;
        let _ = writeln!(
            out,
            "| {} | {} {} | [{}](docs/benchmarks/{}) |",
            f.label, row[2], row[3], f.doc, f.doc
        );
    }
    Ok(out)
}

/// `readme` with the text between its marker lines replaced by `table`; an error when the
/// markers are missing.
pub fn with_table(readme: &str, table: &str) -> Result<String, String> {
    let begin = readme
        .find(BEGIN)
        .ok_or_else(|| format!("README.md has no line {BEGIN:?}"))?;
    let end = readme
        .find(END)
        .filter(|&e| e > begin)
        .ok_or_else(|| format!("README.md has no line {END:?} after the first marker"))?;
    Ok(format!(
        "{}{BEGIN}\n{table}{}",
        &readme[..begin],
        &readme[end..]
    ))
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    /// The README's headline table is the one the committed benchmark documents give.
    #[test]
    fn readme_table_is_generated_from_the_benchmark_documents() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let readme = std::fs::read_to_string(root.join("README.md")).expect("README.md");
        let table = super::table(&root).expect("every figure has its row");
        assert_eq!(
            super::with_table(&readme, &table).expect("markers"),
            readme,
            "README.md's headline table is stale: run `cargo run -p apps --bin headline`"
        );
    }
}
