//! `headline`: writes README.md's table of headline figures from the benchmark documents under
//! docs/benchmarks/ (see `apps::headline`). With `--check` it writes nothing and fails when the
//! README's table differs.

use clap::Parser;
use std::path::PathBuf;
use std::process::ExitCode;

/// Writes README.md's headline figures from the benchmark documents (docs/benchmarks/*.md, each
/// written by one nodebench run), between the README's two marker lines.
#[derive(Parser)]
#[command(version)]
struct Cli {
    /// The repository root (where README.md and docs/ are).
    #[arg(long, default_value = ".")]
    root: PathBuf,
    /// Only check: fail (exit status 1) when README.md's table is not the generated one.
    #[arg(long)]
    check: bool,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let readme_path = cli.root.join("README.md");
    let result = std::fs::read_to_string(&readme_path)
        .map_err(|e| format!("{}: cannot read: {e}", readme_path.display()))
        .and_then(|readme| {
            let table = apps::headline::table(&cli.root)?;
            let new = apps::headline::with_table(&readme, &table)
                .map_err(|e| format!("{}: {e}", readme_path.display()))?;
            if new == readme {
                println!(
                    "{}: the headline table is up to date",
                    readme_path.display()
                );
            } else if cli.check {
                return Err(format!(
                    "{}: the headline table is stale; run `cargo run -p apps --bin headline`",
                    readme_path.display()
                ));
            } else {
                // Written beside it and renamed over it, so a failed write loses nothing.
                let tmp = readme_path.with_extension("md.tmp");
                std::fs::write(&tmp, new)
                    .and_then(|()| std::fs::rename(&tmp, &readme_path))
                    .map_err(|e| format!("{}: cannot write: {e}", readme_path.display()))?;
                println!("{}: headline table written", readme_path.display());
            }
            Ok(())
        });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("headline: {e}");
            ExitCode::FAILURE
        }
    }
}
