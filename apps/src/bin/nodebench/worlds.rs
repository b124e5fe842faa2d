//! Section `worlds` (only with `--only worlds`: minutes to hours, gigabytes of scratch maps):
//! how cost grows with the world. For each side in `--world-sizes` it runs the `worldgen` binary
//! beside this one (`generate --size S`, 4 m spacing, then `bake`) and then `flyover --headless`
//! on the map, each as its own process, and reads back what they print: time per generation
//! step, the bake's time and peak memory, bytes on disk, the map's load time, the time from the
//! open to the first frame that shows the world, memory during the flight, and the per-frame
//! selection time.

use crate::report::Report;
use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// A binary built beside this one (`cargo build --release -p apps`).
fn sibling(name: &str) -> Result<PathBuf> {
    let me = std::env::current_exe().context("locating nodebench")?;
    let p = me.with_file_name(name);
    if !p.exists() {
        bail!(
            "section worlds needs the {name} binary beside nodebench ({}); build it with \
             `cargo build --release -p apps`",
            p.display()
        );
    }
    Ok(p)
}

fn run(cmd: &mut Command, what: &str) -> Result<String> {
    let out = cmd.output().with_context(|| format!("starting {what}"))?;
    if !out.status.success() {
        bail!(
            "{what} failed ({}):\n{}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The number after `prefix` on the line that starts with it.
fn number_after(text: &str, prefix: &str) -> Option<f64> {
    let line = text.lines().find(|l| l.trim_start().starts_with(prefix))?;
    line.trim_start()[prefix.len()..]
        .split_whitespace()
        .next()?
        .trim_end_matches(',')
        .parse()
        .ok()
}

fn dir_bytes(dir: &Path) -> u64 {
    std::fs::read_dir(dir).map_or(0, |entries| {
        entries
            .filter_map(Result::ok)
            .map(|e| {
                let p = e.path();
                if p.is_dir() {
                    dir_bytes(&p)
                } else {
                    e.metadata().map_or(0, |m| m.len())
                }
            })
            .sum()
    })
}

/// `warm_map` (the benchmark's map, small) is flown for one frame before each map's first open
/// ([`warm_up`]).
pub(crate) fn section_worlds(
    sizes_m: &[f64],
    warm_map: &Path,
    scratch: &Path,
    r: &mut Report,
) -> Result<()> {
    let worldgen = sibling("worldgen")?;
    let flyover = sibling("flyover")?;
    std::fs::create_dir_all(scratch).with_context(|| format!("creating {}", scratch.display()))?;
    for &size in sizes_m {
        // Sides are powers of two in metres: name them so (8192 m, not "8.2 km").
        let km = format!("{size:.0} m");
        let map = scratch.join(format!("world_{size:.0}m"));
        let p = format!("{km} square, 4 m spacing, seed 1, {}", map.display());
        eprintln!("worlds: generating {km}");
        let t0 = Instant::now();
        let out = run(
            Command::new(&worldgen)
                .args(["generate", "--seed", "1", "--spacing", "4", "--size"])
                .arg(format!("{size}"))
                .arg("--out")
                .arg(&map),
            "worldgen generate",
        )?;
        let wall_s = t0.elapsed().as_secs_f64();
        // The step table: `| step | seconds |`.
        for line in out
            .lines()
            .filter(|l| l.starts_with("| ") && !l.contains("---"))
        {
            let cells: Vec<&str> = line.trim_matches('|').split('|').map(str::trim).collect();
            if let [step, secs] = cells[..]
                && let Ok(v) = secs.trim_matches('*').parse::<f64>()
                && step != "step"
            {
                r.add(
                    "worlds",
                    &format!("generate {km}: {}", step.trim_matches('*')),
                    v,
                    "s",
                    &p,
                );
            }
        }
        r.add(
            "worlds",
            &format!("generate {km}: wall time"),
            wall_s,
            "s",
            &p,
        );
        if let Some(m) = number_after(&out, "peak resident memory:") {
            r.add(
                "worlds",
                &format!("generate {km}: peak resident memory"),
                m,
                "MiB",
                &p,
            );
        }
        r.add(
            "worlds",
            &format!("{km} map on disk"),
            dir_bytes(&map) as f64 / f64::from(1 << 20),
            "MiB",
            &p,
        );
        bake(&worldgen, &map, &km, &p, r)?;
        warm_up(&flyover, warm_map, scratch, &km, r)?;
        // The bake wrote the surface error grids: the first open after it reads them, like
        // every later one.
        for open in ["first open", "second open"] {
            fly_once(&flyover, &map, scratch, size, &km, open, &p, r)?;
        }
    }
    Ok(())
}

/// `worldgen bake` of `map`: its wall time, peak memory and the pages' bytes on disk.
fn bake(worldgen: &Path, map: &Path, km: &str, p: &str, r: &mut Report) -> Result<()> {
    eprintln!("worlds: baking {km}");
    let t0 = Instant::now();
    let out = run(
        Command::new(worldgen).args(["bake", "--quiet"]).arg(map),
        "worldgen bake",
    )?;
    let name = |what: &str| format!("bake {km}: {what}");
    r.add(
        "worlds",
        &name("wall time"),
        t0.elapsed().as_secs_f64(),
        "s",
        p,
    );
    let derived = "max-pyramids, coarse height levels, ground amplitude, decal tiles, surface error grids and 32 m node bounds";
    if let Some(v) = number_after(&out, &format!("{derived}: baked (")) {
        r.add("worlds", &name(derived), v, "s", p);
    }
    if let Some(m) = number_after(&out, "peak resident memory:") {
        r.add("worlds", &name("peak resident memory"), m, "MiB", p);
    }
    let pages = worldgen::pages::bake::pages_dir(map);
    r.add(
        "worlds",
        &name("page files on disk"),
        dir_bytes(&pages) as f64 / f64::from(1 << 20),
        "MiB",
        p,
    );
    Ok(())
}

/// `flyover --headless --wait-first-world` on `map` for `frames` frames of the automatic
/// flight (one per second of its 40 s, 640x360, no images) into `out`: its stats.json.
fn fly_headless(flyover: &Path, map: &Path, out: &Path, frames: u32) -> Result<serde_json::Value> {
    run(
        Command::new(flyover)
            .args(["--headless", "--wait-first-world", "--frames"])
            .arg(frames.to_string())
            .args([
                "--every",
                "0",
                "--size",
                "640x360",
                "--duration-s",
                "40",
                "--map",
            ])
            .arg(map)
            .arg("--out")
            .arg(out),
        "flyover --headless",
    )?;
    let path = out.join("stats.json");
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    Ok(serde_json::from_str(&text)?)
}

/// One frame of `flyover --headless` on `warm_map` right before a map's first open, so that
/// the first open measures the map and not the program's start: this machine drops files it
/// has not read for a few minutes from its cache (with most of its memory free), so after a
/// generation and bake the viewer's binary and the software GPU driver's libraries are read
/// from disk again, which adds about two seconds to whatever open comes first. That start is
/// reported as its own row (the warm-up's open to its first frame).
fn warm_up(
    flyover: &Path,
    warm_map: &Path,
    scratch: &Path,
    km: &str,
    r: &mut Report,
) -> Result<()> {
    eprintln!("worlds: starting the viewer once on {}", warm_map.display());
    let stats = fly_headless(flyover, warm_map, &scratch.join("fly_warm_up"), 1)?;
    if let Some(v) = stats["first_world_frame_s"].as_f64() {
        r.add(
            "worlds",
            &format!(
                "after the bake of {km}: the viewer's first start (on {}), from the open to \
                 the first frame showing the world",
                warm_map.display()
            ),
            v,
            "s",
            "flyover --headless --wait-first-world --frames 1, 640x360: the program and \
             driver files read from disk after minutes unused; the map's first open below \
             comes after it",
        );
    }
    Ok(())
}

/// One `flyover --headless` run on `map`: its load time, peak memory and selection time.
#[allow(clippy::too_many_arguments)]
fn fly_once(
    flyover: &Path,
    map: &Path,
    scratch: &Path,
    size: f64,
    km: &str,
    open: &str,
    p: &str,
    r: &mut Report,
) -> Result<()> {
    eprintln!("worlds: flying {km} ({open})");
    let stats = fly_headless(flyover, map, &scratch.join(format!("fly_{size:.0}m")), 40)?;
    let fp = format!(
        "{p}; flyover --headless --wait-first-world ({open} of the map; the flight starts \
         once a frame shows the world), 40 frames of the automatic flight, 640x360"
    );
    if let Some(v) = stats["map_load_s"].as_f64() {
        r.add(
            "worlds",
            &format!("flyover {km}, {open}: map load"),
            v,
            "s",
            &fp,
        );
    }
    if let Some(v) = stats["first_world_frame_s"].as_f64() {
        r.add(
            "worlds",
            &format!("flyover {km}, {open}: from the open to the first frame showing the world"),
            v,
            "s",
            &fp,
        );
    }
    if let Some(v) = stats["peak_rss_mib"].as_f64() {
        r.add(
            "worlds",
            &format!("flyover {km}, {open}: peak resident memory"),
            v,
            "MiB",
            &fp,
        );
    }
    // The world's parts held whole, without the pages and tiles resident in its caches,
    // which are reported at their peak under their budgets.
    if let Some(parts) = stats["world_memory_mib"].as_object() {
        let whole: f64 = parts
            .iter()
            .filter(|(what, _)| !what.contains("resident"))
            .filter_map(|(_, v)| v.as_f64())
            .sum();
        let name = format!("flyover {km}, {open}: world held whole in memory");
        r.add("worlds", &name, whole, "MiB", &fp);
    }
    let caches = ["page_cache", "decal_tiles"].map(|c| stats[c]["peak_resident_mib"].as_f64());
    if caches.iter().any(Option::is_some) {
        let name = format!(
            "flyover {km}, {open}: page and decal tile caches resident at their peaks (128 MiB budget each)"
        );
        r.add("worlds", &name, caches.iter().flatten().sum(), "MiB", &fp);
    }
    let mut sel: Vec<f64> = stats["frames"]
        .as_array()
        .map(|f| {
            f.iter()
                .filter_map(|s| s["selection_ms"].as_f64())
                .collect()
        })
        .unwrap_or_default();
    sel.sort_by(f64::total_cmp);
    if !sel.is_empty() {
        r.add(
            "worlds",
            &format!("flyover {km}, {open}: selection per frame, median"),
            apps::percentile(&sel, 0.5),
            "ms",
            &fp,
        );
    }
    Ok(())
}
