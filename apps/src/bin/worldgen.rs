//! `worldgen`: generate, import, bake and check maps; build progressive meshes.

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::time::Instant;
use worldgen::Map;
use worldgen::generate::GenerateParams;
use worldgen::progress::{Bars, Progress, StepTime};

/// Map tools for the terrain streaming engine.
///
/// A map is a folder: `map.toml` (manifest: format "tvs-map" version 3, world size, origin, seed,
/// layer files), `heights.exr` (f32 metres), `ground.png` (indexed ground types), one
/// `density_<species>.png` per vegetation species, `trees.csv`, `decals.toml`, `buildings.csv`
/// and `poisson.csv` (the ranked, periodic Poisson-disc tile that places vegetation). All
/// outputs are deterministic: the same inputs give the same bytes.
#[derive(Parser)]
#[command(name = "worldgen", version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Hide progress bars (they are hidden automatically when stderr is not a terminal).
    #[arg(long, global = true)]
    quiet: bool,
}

#[derive(Subcommand)]
enum Command {
    /// Generate a procedural map: fBm + ridged noise, hydraulic and thermal erosion, ground
    /// types from slope/height/moisture, species densities, large trees, roads between towns
    /// (least-cost paths over slope) and footpaths. Prints the time of every step.
    Generate {
        /// Random seed; the same seed and size always give the same bytes.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// World side in metres (square map); a multiple of twice the spacing.
        #[arg(long, default_value_t = 8192.0)]
        size: f64,
        /// Height sample spacing in metres.
        #[arg(long, default_value_t = 4.0)]
        spacing: f64,
        /// Output map folder (replaced atomically if it exists).
        #[arg(long, default_value = "maps/default")]
        out: PathBuf,
        /// Map name written to the manifest (defaults to the folder name).
        #[arg(long)]
        name: Option<String>,
        /// Worker threads for the parallel steps (0 = all cores). Does not change the output.
        #[arg(long, default_value_t = 0)]
        threads: usize,
    },
    /// Import real elevation data: GeoTIFF (.tif/.tiff: one band of 8/16/32-bit integers or
    /// 32/64-bit floats, strips or tiles, uncompressed/LZW/Deflate/PackBits; pixel size and
    /// position from ModelPixelScale + ModelTiepoint or ModelTransformation, projected metres or
    /// feet, or geographic degrees converted at the centre latitude; GDAL nodata = void), SRTM
    /// .hgt (1201² or 3601², void = -32768), 8/16-bit grayscale PNG (with --spacing-m and
    /// --vertical-scale-m) or single-channel EXR (with --spacing-m; NaN = void). Voids are
    /// filled from neighbours and counted; ground types, densities and trees are derived from
    /// slope and height. A projected GeoTIFF keeps its position as the map's origin. Several
    /// files are joined into one map (a mosaic), in any order: projected GeoTIFFs of one sample
    /// lattice by their positions, or SRTM tiles of one resolution by the positions in their
    /// names; where they overlap the first file given keeps its samples, and what no file covers
    /// is filled like a void.
    ImportDem {
        /// The elevation file, or several GeoTIFF files or SRTM tiles to join (a mosaic).
        #[arg(required = true, num_args = 1..)]
        files: Vec<PathBuf>,
        /// Output map folder.
        #[arg(long)]
        out: PathBuf,
        /// Distance between source samples in metres (PNG, EXR and GeoTIFF without
        /// georeferencing; derived for .hgt and georeferenced GeoTIFF).
        #[arg(long)]
        spacing_m: Option<f64>,
        /// Metres per PNG or GeoTIFF unit (e.g. 0.1 for the Puget Sound height field); a
        /// GeoTIFF's VerticalUnitsGeoKey (feet) is applied on top.
        #[arg(long, default_value_t = 1.0)]
        vertical_scale_m: f64,
        /// Latitude of the south edge of a .hgt tile whose name does not carry it.
        #[arg(long)]
        latitude_deg: Option<f64>,
        /// Height of the water surface in metres (sea level for SRTM).
        #[arg(long, default_value_t = 0.0)]
        water_level_m: f64,
        /// Snow from this height up, in metres.
        #[arg(long, default_value_t = 1800.0)]
        snow_line_m: f64,
        /// Map name (defaults to the file name).
        #[arg(long)]
        name: Option<String>,
        #[arg(long, default_value_t = 0)]
        threads: usize,
    },
    /// Bake a map's raster layers (heights, ground types, densities) into page files under
    /// `<map>/pages/`: fixed square pages, each with its own checksum, read through a page
    /// cache; and, when the bake finishes, what the engine derives from the map: the
    /// max-pyramids of its bounds and the ground amplitude grid (`pages/derived/*.pages`), the
    /// decal field by 64 m tile (`pages/derived/decals.tiles`, read tile by tile at run time)
    /// and the surface error grids with the 32 m nodes' bounds (`pages/derived/surface_error.*`,
    /// read page by page), so that no open of the map computes them (half a minute on the 8 km
    /// map); and the decal list in binary with the record of the files the bake read, so that
    /// an open reads the pages instead of decoding the files. A page depends only on its layer and its index, so the bake can be
    /// split into shares run in any order, on any machines that share the folder
    /// (`--share 0/4` ... `--share 3/4`, then `--finish`); the result is the same bytes.
    /// Without `--share`, `--pages` or `--finish` it bakes every page and finishes. Finishing
    /// checks every page and only then moves the files into place: an interrupted bake leaves
    /// only hidden `.partial` files.
    Bake {
        /// The map folder.
        dir: PathBuf,
        /// Samples per page side.
        #[arg(long, default_value_t = worldgen::pages::DEFAULT_PAGE_SIDE)]
        page_side: u32,
        /// Bake one share of the pages: `K/N` takes the pages whose index modulo N is K.
        #[arg(long, conflicts_with = "pages")]
        share: Option<String>,
        /// Bake these page indices: a comma-separated list of indices and ranges (`0-15,40`).
        #[arg(long)]
        pages: Option<String>,
        /// Only finish: check every page of the partial files and move them into place.
        #[arg(long, conflicts_with_all = ["share", "pages"])]
        finish: bool,
    },
    /// Validate a map folder and print a summary; exit code 0 when valid, 1 with the error.
    /// A baked map's page files are read whole and every page's checksum checked, and so are
    /// its derived files, each checked to be baked for this map and this engine.
    Check {
        /// The map folder.
        dir: PathBuf,
    },
    /// Build a progressive mesh from an OBJ or glTF mesh: half-edge collapses down to one
    /// vertex, the measured error bound of every level, written as a versioned `.pm` file.
    /// Prints the build times and the error at a few triangle counts.
    Pm {
        /// The input mesh (.obj, .gltf, .glb).
        input: PathBuf,
        /// Output `.pm` file.
        #[arg(long)]
        out: PathBuf,
        /// Collapse cost: `longest-edge` (the seed's: the longest edge of the vanishing
        /// triangles, corners survive), `quadric` (Garland-Heckbert with border and seam
        /// planes) or `melax`.
        #[arg(long, default_value = "quadric")]
        cost: String,
        /// Spacing of the error samples on the full mesh, as a fraction of its diagonal. The
        /// stored error bound includes the samples' covering radius (spacing / sqrt 3).
        #[arg(long, default_value_t = 0.005)]
        sample_fraction: f64,
    },
    /// Write a procedural building as an OBJ mesh (Y-up, metres): storeys with window and door
    /// insets, a gable or hip roof, a chimney; closed, with facade UVs split at the corners.
    /// Use it as a model: `worldgen pm house.obj --out house.pm`, `flyover --object house.obj`.
    Building {
        /// Output `.obj` file.
        #[arg(long)]
        out: PathBuf,
        /// Roof shape: `gable` or `hip`.
        #[arg(long, default_value = "gable")]
        roof: String,
        /// Footprint side in metres, 3 to 200 (the ridge runs along the longer side).
        #[arg(long, default_value_t = 10.0)]
        width_m: f64,
        /// The other footprint side in metres, 3 to 200.
        #[arg(long, default_value_t = 8.0)]
        depth_m: f64,
        /// Storeys, 1 to 40 (windows on every storey, a door on the front's ground floor).
        #[arg(long, default_value_t = 2)]
        storeys: u32,
        /// Height of a storey in metres, 2.4 to 6.
        #[arg(long, default_value_t = 3.0)]
        storey_m: f64,
        /// Roof pitch in degrees, 5 to 60.
        #[arg(long, default_value_t = 35.0)]
        roof_pitch_deg: f64,
        /// Varies window spacing and size and the chimney's place.
        #[arg(long, default_value_t = 1)]
        seed: u64,
    },
}

/// Prints to stdout, ignoring a closed pipe (`worldgen ... | head` must not panic).
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout().lock(), $($arg)*);
    }};
}

fn print_times(times: &[StepTime], total_s: f64) {
    say!("| step | time (s) |\n|---|---:|");
    for t in times {
        say!("| {} | {:.3} |", t.step, t.duration_s);
    }
    say!("| **total** | **{total_s:.3}** |");
    if let Some(b) = worldgen::progress::peak_rss_bytes() {
        say!(
            "peak resident memory: {:.0} MiB",
            b as f64 / f64::from(1 << 20)
        );
    }
}

fn check(dir: &std::path::Path) -> Result<()> {
    if !dir.join("map.toml").exists() && !dir.is_dir() {
        bail!("{}: no such map folder", dir.display());
    }
    let map = Map::load(dir)?;
    say!(
        "{}: valid map \"{}\" (format {} v{})",
        dir.display(),
        map.manifest.name,
        map.manifest.format,
        map.manifest.version
    );
    say!("{}", map.summary());
    if worldgen::pages::bake::pages_dir(dir).is_dir() {
        let pages = worldgen::pages::bake::verify(&map, dir, &worldgen::progress::Silent)?;
        say!("page files: {pages} pages, every one matches its checksum and this map");
        if worldgen::pages::bake::pages_dir(dir)
            .join("derived")
            .is_dir()
        {
            say!("{}", apps::check_derived(dir).map_err(anyhow::Error::msg)?);
        }
    }
    Ok(())
}

/// `--share K/N` or `--pages LIST` as a page set (all pages without either).
fn page_set(share: Option<&str>, pages: Option<&str>) -> Result<worldgen::pages::bake::PageSet> {
    use worldgen::pages::bake::PageSet;
    if let Some(s) = share {
        let parsed = s.split_once('/').and_then(|(k, n)| {
            Some((k.trim().parse::<u32>().ok()?, n.trim().parse::<u32>().ok()?))
        });
        return match parsed {
            Some((part, count)) if count > 0 && part < count => Ok(PageSet::Share { part, count }),
            _ => bail!("--share {s:?}: expected K/N with 0 <= K < N, e.g. 0/4"),
        };
    }
    let Some(list) = pages else {
        return Ok(PageSet::All);
    };
    let mut out = Vec::new();
    for item in list.split(',') {
        let item = item.trim();
        let bad =
            || anyhow::anyhow!("--pages {list:?}: {item:?} is not an index or a range like 3-9");
        let (a, b) = if let Some((a, b)) = item.split_once('-') {
            (
                a.trim().parse::<u32>().map_err(|_| bad())?,
                b.trim().parse::<u32>().map_err(|_| bad())?,
            )
        } else {
            let i = item.parse::<u32>().map_err(|_| bad())?;
            (i, i)
        };
        if b < a || b - a > 1 << 24 {
            return Err(bad());
        }
        out.extend(a..=b);
    }
    Ok(PageSet::Indices(out))
}

fn bake(
    dir: &std::path::Path,
    page_side: u32,
    share: Option<&str>,
    pages: Option<&str>,
    finish_only: bool,
    bars: &Bars,
) -> Result<()> {
    use worldgen::pages::bake;
    let set = page_set(share, pages)?;
    let t0 = Instant::now();
    let map = Map::load(dir)?;
    if !finish_only {
        let report = bake::bake(&map, dir, page_side, &set, bars)?;
        say!(
            "baked {} pages ({:.1} MiB) of {} in {:.2} s",
            report.pages_written,
            report.bytes_written as f64 / f64::from(1 << 20),
            dir.display(),
            t0.elapsed().as_secs_f64()
        );
    }
    if finish_only || set == bake::PageSet::All {
        let missing = bake::missing_pages(&map, dir)?;
        if !missing.is_empty() {
            for (layer, pages) in &missing {
                say!(
                    "{layer}: {} pages not baked yet (first: {})",
                    pages.len(),
                    pages[0]
                );
            }
            bail!(
                "{}: the bake is not complete; bake the missing pages, then `worldgen bake --finish`",
                dir.display()
            );
        }
        let n = bake::finish(&map, dir, bars)?;
        say!(
            "finished {n} page files in {} ({:.2} s)",
            bake::pages_dir(dir).display(),
            t0.elapsed().as_secs_f64()
        );
        let t1 = Instant::now();
        let computed = apps::bake_derived(map, dir, bars).with_context(|| {
            format!(
                "writing the derived data of {}",
                bake::pages_dir(dir).join("derived").display()
            )
        })?;
        if computed {
            say!(
                "max-pyramids, coarse height levels, ground amplitude, decal tiles, surface error grids and 32 m node bounds: baked ({:.2} s)",
                t1.elapsed().as_secs_f64()
            );
        } else {
            say!(
                "max-pyramids, coarse height levels, ground amplitude and decal tiles: baked; surface error grids and 32 m node bounds: already baked for this map"
            );
        }
    }
    if let Some(b) = worldgen::progress::peak_rss_bytes() {
        say!(
            "peak resident memory: {:.0} MiB",
            b as f64 / f64::from(1 << 20)
        );
    }
    Ok(())
}

fn write_map(map: &Map, out: &std::path::Path, times: &mut Vec<StepTime>) -> Result<()> {
    worldgen::progress::timed(times, "write map files", || map.write(out))
        .with_context(|| format!("writing map to {}", out.display()))
}

fn build_pm(
    input: &std::path::Path,
    out: &std::path::Path,
    cost: &str,
    sample_fraction: f64,
    bars: &Bars,
) -> Result<()> {
    use worldgen::pm::{CostKind, PmMesh, file, load_mesh};
    let Some(kind) = CostKind::from_name(cost) else {
        bail!("--cost {cost:?}: expected longest-edge, quadric or melax");
    };
    if !(sample_fraction > 0.0 && sample_fraction <= 0.1) {
        bail!("--sample-fraction {sample_fraction}: expected a number in (0, 0.1]");
    }
    let t0 = Instant::now();
    let (mesh, weld) = load_mesh(input)?;
    let load_s = t0.elapsed().as_secs_f64();
    let mut current = String::new();
    let (pm, times) = PmMesh::build(&mesh, kind, sample_fraction, &mut |part, done, total| {
        if part != current {
            if !current.is_empty() {
                bars.end();
            }
            bars.begin(part, total as u64);
            current = part.to_string();
        }
        bars.set_position(done as u64);
    });
    bars.end();
    file::write(&pm, out)?;
    let bytes = std::fs::metadata(out).map_or(0, |m| m.len());
    say!(
        "{} -> {}: {} triangles ({} input, {} degenerate and {} duplicate dropped), {} positions, {} wedges, cost {}",
        input.display(),
        out.display(),
        mesh.triangles.len(),
        weld.input_triangles,
        weld.degenerate_dropped,
        weld.duplicates_dropped,
        mesh.positions.len(),
        mesh.wedge_position.len(),
        kind.name()
    );
    say!(
        "| part | time (s) |\n|---|---:|\n| read + weld | {load_s:.3} |\n| collapse order | {:.3} |\n| error bounds | {:.3} |\n| layout | {:.3} |",
        times.collapse_s,
        times.error_s,
        times.assemble_s
    );
    say!(
        "collapse order: {:.2} M input triangles/s; file {} bytes ({:.1} bytes per triangle)",
        mesh.triangles.len() as f64 / times.collapse_s.max(1e-9) / 1e6,
        bytes,
        bytes as f64 / mesh.triangles.len().max(1) as f64
    );
    let diag = mesh.diagonal();
    say!(
        "| triangles | share | positions | error bound | error / diagonal |\n|---:|---:|---:|---:|---:|"
    );
    let full = pm.triangles.len();
    for share in [1.0, 0.5, 0.1, 0.01, 0.001] {
        let target = (full as f64 * share).round() as usize;
        // The coarsest level that still draws at least `target` triangles.
        let p = pm
            .levels
            .iter()
            .position(|l| l.triangles as usize >= target)
            .map_or(pm.level_count(), |i| i + 1);
        let l = pm.levels[p - 1];
        say!(
            "| {} | {:.1} % | {p} | {:.4e} | {:.3e} |",
            l.triangles,
            100.0 * l.triangles as f64 / full.max(1) as f64,
            l.error,
            l.error / diag
        );
    }
    Ok(())
}

fn main() -> std::process::ExitCode {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    let bars = Bars::new(cli.quiet);
    match cli.command {
        Command::Generate {
            seed,
            size,
            spacing,
            out,
            name,
            threads,
        } => {
            let t0 = Instant::now();
            let name = name.unwrap_or_else(|| {
                out.file_name()
                    .map_or("map".into(), |n| n.to_string_lossy().into_owned())
            });
            let params = GenerateParams {
                name,
                seed,
                size_m: size,
                spacing_m: spacing,
                threads,
            };
            let mut times = Vec::new();
            let map = worldgen::generate::generate(&params, &bars, &mut times)?;
            write_map(&map, &out, &mut times)?;
            say!(
                "generated {} ({} m, seed {seed}, {} threads)",
                out.display(),
                size,
                worldgen::par::thread_count(threads)
            );
            print_times(&times, t0.elapsed().as_secs_f64());
            say!("{}", map.summary());
        }
        Command::ImportDem {
            files,
            out,
            spacing_m,
            vertical_scale_m,
            latitude_deg,
            water_level_m,
            snow_line_m,
            name,
            threads,
        } => {
            let t0 = Instant::now();
            let file = files[0].clone();
            let name = name.unwrap_or_else(|| {
                file.file_stem()
                    .map_or("dem".into(), |n| n.to_string_lossy().into_owned())
            });
            let params = worldgen::dem::ImportParams {
                path: file.clone(),
                mosaic: files[1..].to_vec(),
                name,
                spacing_m,
                vertical_scale_m,
                latitude_deg,
                water_level_m,
                snow_line_m,
                threads,
            };
            let mut times = Vec::new();
            let (map, report) = worldgen::dem::import(&params, &mut times)?;
            write_map(&map, &out, &mut times)?;
            let what = if files.len() > 1 {
                format!("{} files ({} ...)", files.len(), file.display())
            } else {
                file.display().to_string()
            };
            say!(
                "imported {what} -> {}: source {}x{} samples at {:.2} x {:.2} m, {} voids filled, resampled to {:.3} m spacing",
                out.display(),
                report.source_samples[0],
                report.source_samples[1],
                report.source_spacing_m[0],
                report.source_spacing_m[1],
                report.voids_filled,
                report.spacing_m
            );
            if !report.georeference.is_empty() {
                say!("placed: {}", report.georeference);
            }
            print_times(&times, t0.elapsed().as_secs_f64());
            say!("{}", map.summary());
        }
        Command::Pm {
            input,
            out,
            cost,
            sample_fraction,
        } => build_pm(&input, &out, &cost, sample_fraction, &bars)?,
        Command::Building {
            out,
            roof,
            width_m,
            depth_m,
            storeys,
            storey_m,
            roof_pitch_deg,
            seed,
        } => {
            use worldgen::building_mesh::{BuildingSpec, Roof, building_mesh};
            let Some(roof) = Roof::from_name(&roof) else {
                bail!("--roof {roof:?}: expected gable or hip");
            };
            let spec = BuildingSpec {
                width_m,
                depth_m,
                storeys,
                storey_m,
                roof,
                roof_pitch_deg,
                seed,
            };
            let mesh = building_mesh(&spec).map_err(|e| anyhow::anyhow!("building: {e}"))?;
            std::fs::write(&out, worldgen::pm::obj::to_text(&mesh.triangles))
                .with_context(|| format!("{}: cannot write", out.display()))?;
            say!(
                "{}: {} roof, {} triangles, enclosed volume {:.1} m3",
                out.display(),
                roof.name(),
                mesh.triangles.len(),
                mesh.volume_m3
            );
        }
        Command::Bake {
            dir,
            page_side,
            share,
            pages,
            finish,
        } => bake(
            &dir,
            page_side,
            share.as_deref(),
            pages.as_deref(),
            finish,
            &bars,
        )?,
        Command::Check { dir } => check(&dir)?,
    }
    Ok(())
}
