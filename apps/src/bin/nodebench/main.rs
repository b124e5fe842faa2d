//! `nodebench`: the headless node-generation benchmark. Prints Markdown tables, optionally writes
//! JSON rows and a speed-against-error plot. See `--help`. One file per section.

mod bookkeeping;
mod buildings;
mod error;
mod gpu;
mod house_image;
mod lighting;
mod pilots;
mod plot;
mod pm;
mod report;
mod selection;
mod soak;
mod span;
mod streaming;
mod switches;
mod terrain;
mod textures;
mod tiles;
mod vegetation;
mod worlds;

use anyhow::{Context, Result, bail};
use clap::Parser;
use engine::measure;
use engine::surface::World;
use engine::terrain::quadtree::QuadTree;
use report::Report;
use std::path::PathBuf;
use std::time::Instant;

const SECTIONS: [&str; 14] = [
    "tiles",
    "terrain",
    "selection",
    "error",
    "vegetation",
    "lighting",
    "pm",
    "buildings",
    "streaming",
    "bookkeeping",
    "gpu",
    "textures",
    "soak",
    "worlds",
];

/// Node-generation benchmark: speed of every CPU phase and speed against measured error.
///
/// Sections: `tiles` (16 m tile generation), `terrain` (node bounds, grid mesh, TIN mesh),
/// `selection` (per-frame quad-tree selection along a flight), `error` (triangles against
/// measured on-screen pixel error for tau in {0.5, 1, 2, 4, 8}, for the grid, the TIN and a
/// CDLOD-style distance selection tuned to the same measured error), `vegetation` (kept points per
/// second of the ranked Poisson tile against Bridson sampling from the `fast_poisson` crate,
/// vegetation phase time per node, instances and draw calls per frame on the flight, the
/// image error of each representation switch on frames drawn with an adapter),
/// `lighting` (light grids: sky and sun visibility against a ray-marched reference, computation
/// time and bytes per grid in full and from its sky page, lighting the flight's grids the first
/// time, again from their sky pages and after a sun change), `pm` (progressive
/// meshes on the shared meshes: build throughput of each cost and of meshoptimizer, measured
/// error at 50/10/1/0.1 % of the triangles, index rebuild rates, bytes per triangle), `buildings`
/// (towns: generation time, houses per node, house triangles at tau 2 against full detail, the
/// texture cache's resident bytes against full resolution and its misses, on the benchmark
/// flight and an orbit of the largest town, the houses' image error against full detail on
/// frames drawn with an adapter), `streaming`
/// (real-time
/// flights at 50, 150 and 300 m/s at 40 m and 1000 m/s at 1000 m through the streaming system,
/// with 1 and N workers, prefetch along the known path; then pilots whose future the
/// streamer cannot read (turning, climbing, reversing; `--pilots`) at 150, 300 and 1000 m/s:
/// request-to-ready latency, cancelled jobs, pop debt, bookkeeping per frame), `bookkeeping` (the streamer's update per frame on
/// settled views of those flights, workers idle: its own cost without a flight's scheduling
/// noise), `gpu` (when an adapter exists: the automatic flight
/// rendered offscreen at 720p and 1440p, the frame pass timed with timestamp queries next to a
/// same-run one-draw terrain reference, draw calls), `textures` (when an adapter exists: one
/// ground texture per sampled node, CPU and GPU time, bytes), `soak` (when an adapter exists:
/// the automatic flight in laps for `--soak-minutes`, resident and GPU memory, caches, jobs and
/// tiles sampled every second; their growth, and what is left over at the end), `worlds` (only
/// when named in --only: `worldgen generate`, `worldgen bake` and `flyover --headless` at each
/// of `--world-sizes`, as child processes: step times, peak memory, bytes on disk, load and
/// selection time). Per-item times are on one
/// core (p50/p95/p99/max); throughput is given for 1 and N worker threads.
#[derive(Parser)]
#[command(name = "nodebench", version, about, long_about)]
struct Cli {
    /// Map folder (the default map is generated there on first use if missing).
    #[arg(long, default_value = "maps/default")]
    map: PathBuf,
    /// Run only these sections (comma-separated): tiles, terrain, selection, error, vegetation,
    /// lighting, pm, buildings, streaming, bookkeeping, gpu, textures, soak, worlds (worlds runs
    /// only when named here).
    #[arg(long, value_delimiter = ',')]
    only: Vec<String>,
    /// A few seconds in total: fewer items, cameras and thresholds (used by the test script).
    #[arg(long)]
    quick: bool,
    /// Write the rows as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Write the benchmark document (Markdown: command, machine, every row of this run) here,
    /// e.g. docs/benchmarks/benchmarks.md. Until it is written at the end, the rows so far are
    /// kept after every section in `<name>.partial.md` beside it (e.g.
    /// docs/benchmarks/benchmarks.partial.md, removed when the document is written), so a run
    /// that fails late loses nothing.
    #[arg(long)]
    doc: Option<PathBuf>,
    /// Write the speed-against-error plot (PNG) here.
    #[arg(long, default_value = "target/nodebench/speed_vs_error.png")]
    plot: PathBuf,
    /// Folder of the OBJ meshes for section pm.
    #[arg(long, default_value = "tests/data/meshes")]
    meshes: PathBuf,
    /// Write the progressive-mesh error plot (PNG, the bunny) here.
    #[arg(long, default_value = "target/nodebench/pm_error.png")]
    pm_plot: PathBuf,
    /// Worker threads for the throughput rows (default: all cores).
    #[arg(long)]
    workers: Option<usize>,
    /// Section worlds: the map sides to generate and fly, metres (comma-separated; default
    /// 2048, 8192, 32768, and with --quick 2048 only).
    #[arg(long, value_delimiter = ',')]
    world_sizes: Vec<f64>,
    /// Section worlds: where its maps go (gigabytes for 32 km).
    #[arg(long, default_value = "target/nodebench/worlds")]
    worlds_scratch: PathBuf,
    /// Section streaming: only the flights at these speeds, m/s (comma-separated; default
    /// all). For comparing one flight's rows quickly; a benchmark document has them all.
    #[arg(long, value_delimiter = ',')]
    speeds: Vec<f64>,
    /// Section streaming: which pilots fly (comma-separated; default all): `known` (the
    /// replayed loop, prefetch along its known path) and the pilots whose future the streamer
    /// cannot read, which it gets one frame at a time and must extrapolate: `turning` (30-120°
    /// turns every 2-6 s), `climbing` (climbs and dives), `reversing` (stops, turns round,
    /// flies back). The hidden pilots fly at 150, 300 and 1,000 m/s. Naming pilots makes a
    /// comparison run: the known loop then flies with everything on only (not also from rest
    /// or with a kind turned off).
    #[arg(long, value_delimiter = ',', value_parser = pilots::parse_choice)]
    pilots: Vec<pilots::PilotChoice>,
    /// Sections streaming and bookkeeping light grids from the map's baked sky pages
    /// (`<map>/.sky_pages`, written by `flyover --bake-sky` or by a viewer's earlier visits), as
    /// the viewer does; without it every grid is computed in full (rows that do not depend on
    /// what earlier runs left in the map folder). Section lighting measures pages on its own.
    #[arg(long)]
    sky_pages: bool,
    /// Length of the soak section in minutes (--quick: a quarter of a minute).
    #[arg(long, default_value_t = 30.0)]
    soak_minutes: f64,
    /// Viewport height in pixels for selection and error (the width follows the aspect).
    #[arg(long, default_value_t = 720)]
    viewport_height: u32,
    /// Sections selection and error: the vertical field of view in degrees (20 to 120). Without
    /// it and --aspect, they run at 60 degrees 16:9 and again at 90 degrees 21:9.
    #[arg(long, value_parser = apps::parse_fov_deg)]
    fov_deg: Option<f64>,
    /// Sections selection and error: the screen's aspect, W:H such as 16:9 or 21:9.
    #[arg(long, value_parser = apps::parse_aspect)]
    aspect: Option<f64>,
    /// Sections selection and error: measure on these cameras instead of the benchmark flight,
    /// a camera path as `flyover --record` writes it (each line one camera, all of them used).
    #[arg(long)]
    cameras: Option<PathBuf>,
}

/// A view setting of sections selection and error: its cameras and their name in the rows.
struct ViewSetting {
    label: String,
    cams: Vec<engine::camera::Camera>,
}

/// Sections selection and error (those `want` names) at each view setting; the
/// speed-against-error curve of the first.
fn sections_by_view(
    cli: &Cli,
    world: &World,
    tree: &QuadTree,
    report: &mut Report,
    want: &dyn Fn(&str) -> bool,
) -> Result<Vec<plot::CurvePoint>> {
    let views = view_settings(cli, world)?;
    if want("selection") {
        for v in &views {
            selection::section_selection(world, tree, &v.cams, &v.label, report, cli.quick);
        }
    }
    let mut curve = Vec::new();
    if want("error") {
        for (i, v) in views.iter().enumerate() {
            let extent = if i == 0 {
                error::Extent::WithBaselines
            } else {
                error::Extent::GridOnly
            };
            let c = error::section_error(world, tree, &v.cams, &v.label, extent, report, cli.quick);
            if i == 0 {
                curve = c;
            }
        }
    }
    Ok(curve)
}

/// The view settings sections selection and error run at: the one the command line names, or
/// 60 degrees 16:9 and 90 degrees 21:9 on the benchmark flight (or the --cameras file).
fn view_settings(cli: &Cli, world: &World) -> Result<Vec<ViewSetting>> {
    let vh = cli.viewport_height.max(16);
    let settings: Vec<(f64, f64, &str)> = match (cli.fov_deg, cli.aspect) {
        (None, None) => vec![(60.0, 16.0 / 9.0, "16:9"), (90.0, 21.0 / 9.0, "21:9")],
        (fov, aspect) => vec![(fov.unwrap_or(60.0), aspect.unwrap_or(16.0 / 9.0), "")],
    };
    let path = match &cli.cameras {
        Some(p) => {
            let path = engine::flight::CameraPath::load(p)?;
            if path.keys.is_empty() {
                bail!("{}: the camera path has no cameras", p.display());
            }
            Some(path)
        }
        None => None,
    };
    Ok(settings
        .into_iter()
        .map(|(fov_deg, aspect, name)| {
            let viewport = [((f64::from(vh) * aspect).round() as u32).max(16), vh];
            let mut cams = match &path {
                Some(p) => p
                    .keys
                    .iter()
                    .map(|k| {
                        let at = k.position_m;
                        engine::camera::Camera::look_at(at, at + k.forward, 1.0, viewport)
                    })
                    .collect(),
                None => measure::default_flight(world, if cli.quick { 8 } else { 64 }, viewport),
            };
            for c in &mut cams {
                c.fovy_rad = fov_deg.to_radians();
            }
            let aspect_name = if name.is_empty() {
                format!("{aspect:.3}:1")
            } else {
                name.to_string()
            };
            let source = cli
                .cameras
                .as_ref()
                .map_or(String::new(), |p| format!(", cameras of {}", p.display()));
            ViewSetting {
                label: format!("{fov_deg}° {aspect_name}{source}"),
                cams,
            }
        })
        .collect())
}

pub(crate) fn open_world(path: &std::path::Path) -> Result<World> {
    // The viewer's: generates the default map when missing or from an older map format.
    apps::open_world(path, &worldgen::progress::Bars::new(false))
        .with_context(|| format!("opening map {}", path.display()))
}

/// The map of `cli`, as the sections use it: without the sky pages a viewer keeps in the map
/// folder unless `--sky-pages` asks for them (the rows then do not depend on earlier runs);
/// section lighting measures pages on its own.
fn open_for_sections(cli: &Cli) -> Result<World> {
    let mut world = open_world(&cli.map)?;
    if cli.sky_pages {
        let dir = cli.map.join(engine::lighting::sky_pages::SKY_PAGES_DIR);
        if !dir.is_dir() {
            bail!(
                "--sky-pages: {} has no sky pages; bake them with `flyover --map {} --bake-sky`",
                cli.map.display(),
                cli.map.display()
            );
        }
        world.derived_dir = Some(cli.map.clone());
    } else {
        world.derived_dir = None;
    }
    Ok(world)
}

fn run(cli: &Cli) -> Result<()> {
    for s in &cli.only {
        if !SECTIONS.contains(&s.as_str()) {
            bail!("unknown section {s:?}; choose from {}", SECTIONS.join(", "));
        }
    }
    let want = |s: &str| cli.only.is_empty() || cli.only.iter().any(|o| o == s);
    let world_sizes_m = world_sizes_m(cli)?;
    let workers = cli
        .workers
        .unwrap_or_else(|| {
            std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
        })
        .max(1);
    // Shared with the light threads of section lighting (never copied).
    let world = std::sync::Arc::new(open_for_sections(cli)?);
    let tree = QuadTree::new(world.origin_m(), world.size_m());
    let vh = cli.viewport_height.max(16);
    let cams = measure::default_flight(&world, if cli.quick { 8 } else { 64 }, [vh * 16 / 9, vh]);
    if terrain::flight_nodes(&world, &tree, &cams, 1).is_empty() {
        bail!(
            "{}: the benchmark flight selects no node of this map, so there is nothing to measure",
            cli.map.display()
        );
    }
    let mut report = Report { rows: Vec::new() };
    let t0 = Instant::now();
    // With --doc: the rows so far go to `<doc>.partial.md` after every section, so a run that
    // fails or is stopped an hour in still leaves what it measured; removed once the document
    // itself is written.
    let partial = cli.doc.as_ref().map(|p| p.with_extension("partial.md"));
    let checkpoint = |report: &Report, section: &str, adapter: Option<&str>| -> Result<()> {
        let Some(p) = &partial else { return Ok(()) };
        let summary = format!(
            "**Incomplete**: the rows of a nodebench run up to section {section}, {:.1} s in; \
             it failed, was stopped or is still running. Not the benchmark document.",
            t0.elapsed().as_secs_f64()
        );
        let machine = report::machine_block(workers, adapter);
        write_file(p, &report.document(&command_line(), &summary, &machine))
    };
    if want("tiles") {
        tiles::section_tiles(&world, &mut report, cli.quick, workers);
        checkpoint(&report, "tiles", None)?;
    }
    if want("terrain") {
        terrain::section_terrain(&world, &tree, &cams, &mut report, cli.quick, workers);
        checkpoint(&report, "terrain", None)?;
    }
    let mut curve = Vec::new();
    if want("selection") || want("error") {
        curve = sections_by_view(cli, &world, &tree, &mut report, &want)?;
        checkpoint(&report, "error", None)?;
    }
    if want("vegetation") {
        vegetation::section_vegetation(&world, &tree, &cams, &mut report, cli.quick);
        checkpoint(&report, "vegetation", None)?;
    }
    if want("lighting") {
        lighting::section_lighting(&world, &tree, &cams, &mut report, cli.quick, workers);
        checkpoint(&report, "lighting", None)?;
    }
    if want("pm") {
        section_pm_with_plot(cli, &mut report);
        checkpoint(&report, "pm", None)?;
    }
    if want("buildings") {
        buildings::section_buildings(&world, &tree, &cams, &mut report, cli.quick);
        checkpoint(&report, "buildings", None)?;
    }
    // One adapter for the sections that use it (streaming renders ground textures with it).
    let adapter = if want("streaming") || want("gpu") || want("textures") || want("soak") {
        gpu::adapter()
    } else {
        None
    };
    let mut adapter_name = adapter
        .as_ref()
        .filter(|_| want("streaming"))
        .map(|(_, name)| name.clone());
    if want("streaming") {
        streaming::section_streaming(
            &cli.map,
            &mut report,
            cli.quick,
            workers,
            [vh * 16 / 9, vh],
            adapter.as_ref().map(|(g, name)| (g, name.as_str())),
            &cli.speeds,
            &cli.pilots,
        )?;
        checkpoint(&report, "streaming", adapter_name.as_deref())?;
    }
    if want("bookkeeping") {
        bookkeeping::section_bookkeeping(
            &cli.map,
            &mut report,
            cli.quick,
            workers,
            [vh * 16 / 9, vh],
        )?;
        checkpoint(&report, "bookkeeping", adapter_name.as_deref())?;
    }
    if (want("gpu") || want("textures") || want("soak"))
        && let Some(name) = adapter_sections(cli, adapter, &world, &tree, &cams, &mut report)?
    {
        adapter_name = Some(name);
    }
    if want("gpu") || want("textures") || want("soak") {
        checkpoint(&report, "gpu, textures and soak", adapter_name.as_deref())?;
    }
    if cli.only.iter().any(|o| o == "worlds") {
        worlds::section_worlds(&world_sizes_m, &cli.map, &cli.worlds_scratch, &mut report)?;
        checkpoint(&report, "worlds", adapter_name.as_deref())?;
    }
    let summary = format!(
        "nodebench on {} ({} x {} m, {} levels), {} worker(s), {:.1} s{}",
        cli.map.display(),
        world.size_m()[0],
        world.size_m()[1],
        tree.max_level + 1,
        workers,
        t0.elapsed().as_secs_f64(),
        if cli.quick { ", --quick" } else { "" }
    );
    println!("{summary}\n\n{}", report.markdown());
    if !curve.is_empty() {
        match plot::write_plot(&cli.plot, &curve) {
            Ok(()) => println!("\nplot: {}", cli.plot.display()),
            Err(e) => eprintln!("warning: plot not written: {e:#}"),
        }
    }
    let machine = report::machine_block(workers, adapter_name.as_deref());
    if let Some(p) = &cli.doc {
        write_file(p, &report.document(&command_line(), &summary, &machine))?;
        println!("benchmark document: {}", p.display());
        if let Some(partial) = partial.as_ref().filter(|q| q.exists()) {
            std::fs::remove_file(partial)
                .with_context(|| format!("removing {}", partial.display()))?;
        }
    }
    if let Some(p) = &cli.json {
        let doc = serde_json::json!({ "machine": machine, "rows": report.rows });
        write_file(p, &serde_json::to_string_pretty(&doc)?)?;
        println!("json: {}", p.display());
    }
    Ok(())
}

/// The map sizes of section worlds: `--world-sizes`, or 2048, 8192 and 32768 m (2048 m only
/// under `--quick`); an error names a size outside 256..=65536 m when the section runs.
fn world_sizes_m(cli: &Cli) -> Result<Vec<f64>> {
    let sizes_m: Vec<f64> = match (&cli.world_sizes[..], cli.quick) {
        ([], true) => vec![2048.0],
        ([], false) => vec![2048.0, 8192.0, 32768.0],
        (given, _) => given.to_vec(),
    };
    if cli.only.iter().any(|o| o == "worlds") {
        for &s in &sizes_m {
            if !(s.is_finite() && (256.0..=65_536.0).contains(&s)) {
                bail!("--world-sizes: {s} m is outside 256..=65536 m");
            }
        }
    }
    Ok(sizes_m)
}

/// Section pm, and its error curves for one mesh (the bunny; the cow under `--quick`) plotted
/// to `--pm-plot`; a plot that cannot be written is a warning, not a failed run.
fn section_pm_with_plot(cli: &Cli, report: &mut Report) {
    let curves = pm::section_pm(&cli.meshes, report, cli.quick);
    let mesh = if cli.quick {
        "cow.obj"
    } else {
        "stanford-bunny.obj"
    };
    let shown: Vec<_> = curves.iter().filter(|c| c.label.contains(mesh)).collect();
    let title = format!("{mesh}: measured two-sided error against triangles");
    match apps::plot::write_loglog(
        &cli.pm_plot,
        &title,
        "Hausdorff distance / diagonal",
        &shown,
    ) {
        Ok(()) if !curves.is_empty() => println!("pm plot: {}", cli.pm_plot.display()),
        Ok(()) => {}
        Err(e) => eprintln!("warning: pm plot not written: {e:#}"),
    }
}

/// Sections `gpu`, `textures` and `soak` (as `cli` wants them) on the adapter; its name, or
/// None when there is none and no section insists on one.
fn adapter_sections(
    cli: &Cli,
    adapter: Option<(engine::render::Gpu, String)>,
    world: &World,
    tree: &QuadTree,
    cams: &[engine::camera::Camera],
    report: &mut Report,
) -> Result<Option<String>> {
    let want = |s: &str| cli.only.is_empty() || cli.only.iter().any(|o| o == s);
    match adapter {
        Some((g, name)) => {
            if want("gpu") {
                gpu::section_gpu(&g, &name, &cli.map, report, cli.quick)?;
            }
            if want("textures") {
                textures::section_textures(
                    &g, &name, &cli.map, world, tree, cams, report, cli.quick,
                )?;
            }
            if want("soak") {
                let minutes = if cli.quick { 0.25 } else { cli.soak_minutes };
                if !(minutes.is_finite() && minutes > 0.0) {
                    bail!("--soak-minutes {minutes} must be a positive number");
                }
                soak::section_soak(&g, &name, &cli.map, report, minutes)?;
            }
            return Ok(Some(name));
        }
        None if cli
            .only
            .iter()
            .any(|o| o == "gpu" || o == "textures" || o == "soak") =>
        {
            bail!(
                "sections gpu, textures and soak: no GPU adapter (install \
                 mesa-vulkan-drivers for lavapipe)"
            )
        }
        None => eprintln!("no GPU adapter: sections gpu, textures and soak left out"),
    }
    Ok(None)
}

/// This run's command line as the document prints it (the program named `nodebench`).
fn command_line() -> String {
    let args: Vec<String> = std::env::args()
        .enumerate()
        .map(|(i, a)| if i == 0 { "nodebench".to_string() } else { a })
        .collect();
    args.join(" ")
}

/// Writes `text` to `path`, creating its folder.
fn write_file(path: &std::path::Path, text: &str) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

fn main() -> std::process::ExitCode {
    apps::heap::rerun_with_huge_pages();
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    match run(&Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
