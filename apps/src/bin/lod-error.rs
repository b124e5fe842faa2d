//! `lod-error`: the LOD error table of a progressive mesh, a mesh or an artist LOD chain (seed
//! 001's LOD error tool). For each level: vertices, triangles and the measured two-sided
//! Hausdorff distance to the full model (and, for a PM, its stored bound next to it); a log-log
//! plot of error against triangles for each cost.

use anyhow::{Context, Result, bail};
use apps::plot::{Curve, write_loglog};
use clap::Parser;
use std::path::{Path, PathBuf};
use worldgen::pm::gltf_input;
use worldgen::pm::measure::{Soup, hausdorff, level_soup, mesh_soup};
use worldgen::pm::{CostKind, PmMesh, TriMesh, file, load_mesh};

/// Print the LOD error table of a `.pm` file, or of an `.obj` / `.gltf` / `.glb` model built
/// with every collapse cost (and its MSFT_lod chain, if it has one), and plot error against
/// triangles. Errors are measured: grid samples on both surfaces, every sample's exact distance
/// to the other surface, the larger of the two directions (model units and % of the diagonal).
#[derive(Parser)]
#[command(name = "lod-error", version, about, long_about)]
struct Cli {
    /// A `.pm` file or a model (`.obj`, `.gltf`, `.glb`).
    input: PathBuf,
    /// Write the plot (PNG) here.
    #[arg(long, default_value = "target/lod-error.png")]
    plot: PathBuf,
    /// Measurement sample spacing as a fraction of the diagonal.
    #[arg(long, default_value_t = 0.002)]
    measure_fraction: f64,
    /// Error-bound sample spacing for models built here (see `worldgen pm`).
    #[arg(long, default_value_t = 0.005)]
    sample_fraction: f64,
}

const SHARES: [f64; 8] = [1.0, 0.5, 0.25, 0.1, 0.03, 0.01, 0.003, 0.001];

fn diagonal(s: &Soup) -> f64 {
    let mut lo = glam::DVec3::splat(f64::INFINITY);
    let mut hi = -lo;
    for t in s {
        for v in t {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
    }
    (hi - lo).length()
}

/// Rows for a PM at the shares of its triangles; returns the plot curves (measured, stored).
fn pm_table(pm: &PmMesh, label: &str, spacing_fraction: f64) -> (Curve, Curve) {
    let full = level_soup(pm, pm.level_count());
    let diag = diagonal(&full).max(f64::MIN_POSITIVE);
    let total = pm.triangles.len();
    let mut measured = Curve {
        label: format!("{label}, measured"),
        points: Vec::new(),
    };
    let mut stored = Curve {
        label: format!("{label}, stored bound"),
        points: Vec::new(),
    };
    println!(
        "\n{label}\n\n| vertices | wedges | triangles | share | stored bound | measured | measured / diagonal |\n|---:|---:|---:|---:|---:|---:|---:|"
    );
    let mut last = usize::MAX;
    for share in SHARES {
        let target = (total as f64 * share).round() as usize;
        let p = pm.finest_with_at_most(target.max(1));
        if p == last {
            continue;
        }
        last = p;
        let level = pm.levels[p - 1];
        let m = hausdorff(&full, &level_soup(pm, p), diag * spacing_fraction);
        println!(
            "| {p} | {} | {} | {:.1} % | {:.4e} | {m:.4e} | {:.3} % |",
            level.wedges,
            level.triangles,
            100.0 * level.triangles as f64 / total.max(1) as f64,
            level.error,
            100.0 * m / diag
        );
        if level.triangles > 0 {
            measured.points.push((level.triangles as f64, m / diag));
            stored
                .points
                .push((level.triangles as f64, level.error as f64 / diag));
        }
    }
    (measured, stored)
}

fn run(cli: &Cli) -> Result<()> {
    if !(cli.measure_fraction > 0.0 && cli.measure_fraction <= 0.1) {
        bail!(
            "--measure-fraction {}: expected a number in (0, 0.1]",
            cli.measure_fraction
        );
    }
    let ext = cli
        .input
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let mut curves = Vec::new();
    if ext == "pm" {
        let pm = file::read(&cli.input)?;
        println!(
            "{}: progressive mesh, cost {}, {} levels, {} triangles",
            cli.input.display(),
            pm.cost.name(),
            pm.level_count(),
            pm.triangles.len()
        );
        let (m, s) = pm_table(&pm, pm.cost.name(), cli.measure_fraction);
        curves.push(m);
        curves.push(s);
    } else {
        let (mesh, weld) = load_mesh(&cli.input)?;
        println!(
            "{}: {} triangles ({} dropped at welding), {} positions",
            cli.input.display(),
            mesh.triangles.len(),
            weld.degenerate_dropped + weld.duplicates_dropped,
            mesh.positions.len()
        );
        for cost in CostKind::ALL {
            let (pm, times) = PmMesh::build(&mesh, cost, cli.sample_fraction, &mut |_, _, _| {});
            let (m, _) = pm_table(
                &pm,
                &format!(
                    "{} (order {:.2} s, bounds {:.2} s)",
                    cost.name(),
                    times.collapse_s,
                    times.error_s
                ),
                cli.measure_fraction,
            );
            curves.push(m);
        }
        if matches!(ext.as_str(), "gltf" | "glb") {
            curves.extend(chain_table(&cli.input, &mesh, cli.measure_fraction)?);
        }
    }
    let shown: Vec<&Curve> = curves.iter().collect();
    let title = format!(
        "{}: error against triangles",
        cli.input
            .file_name()
            .map_or(String::new(), |n| n.to_string_lossy().into_owned())
    );
    write_loglog(&cli.plot, &title, "Hausdorff distance / diagonal", &shown)
        .with_context(|| format!("writing {}", cli.plot.display()))?;
    println!("\nplot: {}", cli.plot.display());
    Ok(())
}

/// The MSFT_lod chain of a glTF model: each level's measured error against the base.
fn chain_table(path: &Path, base: &TriMesh, fraction: f64) -> Result<Option<Curve>> {
    let model = gltf_input::load(path)?;
    if model.levels.len() < 2 {
        println!("\n(no MSFT_lod chain in {})", path.display());
        return Ok(None);
    }
    let full = mesh_soup(base);
    let diag = diagonal(&full).max(f64::MIN_POSITIVE);
    let mut curve = Curve {
        label: "MSFT_lod chain".into(),
        points: Vec::new(),
    };
    println!(
        "\nMSFT_lod chain\n\n| level | vertices | triangles | measured | measured / diagonal |\n|---|---:|---:|---:|---:|"
    );
    for (name, tris) in &model.levels {
        let (mesh, _) = TriMesh::weld(tris);
        let m = hausdorff(&full, &mesh_soup(&mesh), diag * fraction);
        println!(
            "| {name} | {} | {} | {m:.4e} | {:.3} % |",
            mesh.positions.len(),
            mesh.triangles.len(),
            100.0 * m / diag
        );
        curve.points.push((mesh.triangles.len() as f64, m / diag));
    }
    Ok(Some(curve))
}

fn main() -> std::process::ExitCode {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    match run(&Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
