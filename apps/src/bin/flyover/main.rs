//! The flyover viewer: a window with the streamed terrain and an egui panel (detail level,
//! workers, memory budget, debug views, live statistics), or, with `--headless` or when no
//! display is available, an offscreen run that writes PNG frames and per-frame statistics.

mod headless;
mod panel;
mod window;

use anyhow::{Context, Result};
use apps::DEFAULT_MAP;
use clap::{CommandFactory, FromArgMatches, Parser};
use engine::camera::Camera;
use engine::flight::{CameraPath, auto_flyover};
use engine::ground::content::GroundContent;
use engine::lighting::Sun;
use engine::lighting::content::LightingContent;
use engine::objects::lod::PmLodSettings;
use engine::render::Gpu;
use engine::render::frame::GroundView;
use engine::stream::StreamSettings;
use engine::surface::World;
use engine::viewer::Viewer;
use std::path::PathBuf;

#[derive(Parser, Debug, Clone)]
#[command(
    name = "flyover",
    about = "Fly over a map with streamed quad-tree terrain",
    long_about = "Fly over a map with streamed quad-tree terrain.\n\n\
        Window controls: the automatic flyover runs until you press a movement key or Space; \
        then W/A/S/D move, Q/E go down/up, hold the right mouse button and move to look, the \
        wheel changes speed, Space toggles the automatic flyover, F12 writes a screenshot, R \
        starts/stops recording a camera path (written to --record), Esc quits.\n\n\
        Without a display (no DISPLAY or WAYLAND_DISPLAY) it runs --headless instead, by default \
        a short run (240 frames of 640x360 covering the whole automatic flight, about a minute \
        on 2 cores with a software adapter) unless --frames, --size or --fps are given."
)]
#[allow(
    clippy::struct_excessive_bools,
    reason = "independent command-line switches"
)]
pub(crate) struct Cli {
    /// Map folder. The default map is generated there on first run when missing.
    #[arg(long, default_value = DEFAULT_MAP)]
    pub(crate) map: PathBuf,
    /// Render offscreen: write PNG frames and a JSON of per-frame statistics into --out.
    #[arg(long)]
    pub(crate) headless: bool,
    /// Frames to render (headless), at --fps steps of simulated time.
    #[arg(long, default_value_t = 600)]
    pub(crate) frames: u64,
    /// Simulated frames per second (headless) for the camera clock.
    #[arg(long, default_value_t = 30.0, value_parser = positive)]
    pub(crate) fps: f64,
    /// Output folder for frames, statistics and screenshots.
    #[arg(long, default_value = "out/flyover")]
    pub(crate) out: PathBuf,
    /// Write every Nth frame as PNG (headless).
    #[arg(long, default_value_t = 30)]
    pub(crate) every: u64,
    /// Replay this camera path file (see --record) instead of the automatic flyover.
    #[arg(long)]
    pub(crate) path: Option<PathBuf>,
    /// Where R (in the window) records a camera path.
    #[arg(long, default_value = "out/flyover/camera-path.txt")]
    pub(crate) record: PathBuf,
    /// Viewport size WxH in pixels.
    #[arg(long, default_value = "1280x720", value_parser = parse_size)]
    pub(crate) size: [u32; 2],
    /// Vertical field of view in degrees (20 to 120); the panel has a slider for it. The
    /// detail level holds on the whole screen at any field of view.
    #[arg(long, default_value_t = 60.0, value_parser = apps::parse_fov_deg)]
    pub(crate) fov_deg: f64,
    /// Detail level: the largest projected geometric error in pixels.
    #[arg(long, default_value_t = 2.0, value_parser = positive)]
    pub(crate) tau: f64,
    /// Worker threads for node generation (default: cores - 1).
    #[arg(long)]
    pub(crate) workers: Option<usize>,
    /// Memory budget of the node cache in MiB.
    #[arg(long, default_value_t = 512)]
    pub(crate) budget_mib: usize,
    /// Split less where dense vegetation blocks the view from a camera inside the canopy: up to
    /// 30 - 43 % fewer terrain triangles at eye height, but the canopy is a density, not the
    /// drawn trees, so terrain error can show through gaps (on the default map's eye-height
    /// views within tau at the default 2 px, 2.3x tau at 0.5 px: docs/guides/pixel-error.md).
    /// Off by default, so tau holds at every pixel.
    #[arg(long)]
    pub(crate) vegetation_occlusion: bool,
    /// Draw every terrain node through all its 33 x 33 vertices (by default a node whose
    /// ancestor's mesh is within the detail level over it is drawn through every 2nd or 4th
    /// vertex: the same surface, up to 16x fewer triangles).
    #[arg(long)]
    pub(crate) no_decimation: bool,
    /// Duration of the automatic flyover in seconds.
    #[arg(long, default_value_t = 40.0, value_parser = positive)]
    pub(crate) duration_s: f64,
    /// Window: write live statistics (JSON, overwritten each frame) to this file.
    #[arg(long)]
    pub(crate) stats_file: Option<PathBuf>,
    /// Window: quit after this many seconds.
    #[arg(long)]
    pub(crate) exit_after_s: Option<f64>,
    /// Window, for tests: destroy the GPU device after this many seconds (as a driver reset
    /// would lose it); the viewer must then exit with a clear message.
    #[arg(long, hide = true)]
    pub(crate) debug_lose_device_after_s: Option<f64>,
    /// Headless: also time a same-run GPU reference each frame (the frame's terrain triangles as
    /// one indexed draw with a flat shader, its plant instances gathered into one instanced draw
    /// per plant mesh and one for all billboard and cluster quads, drawn whole) and report pass
    /// / reference. Turns objects (houses) off for the run, so the pass and the reference draw
    /// the same things (the pass also draws the sky behind them).
    #[arg(long)]
    pub(crate) gpu_reference: bool,
    /// Draw item by item (one draw call per node mesh and node instance group, the fallback
    /// path) instead of one multi-draw per render state and pool page: same pixels, for
    /// comparing the cost of draw calls.
    #[arg(long)]
    pub(crate) per_item_draws: bool,
    /// Headless GPU-ratio diagnostic: draw the terrain's own draws (same batches, skirts and
    /// cross-fade dithers) with a flat fragment shader like the --gpu-reference's, so that the
    /// pass / reference ratio splits into geometry and shading.
    #[arg(long)]
    pub(crate) flat_terrain: bool,
    /// How the ground is shown: lit (default), coloured by ground-texture texels per pixel
    /// (red: a texel covers several pixels, yellow: one, green: a pixel covers several texels;
    /// grey: no texture), or the ground texture alone (no light, no fog).
    #[arg(long, value_enum, default_value_t = GroundViewArg::Shaded)]
    pub(crate) ground_view: GroundViewArg,
    /// Do not make per-node ground textures (the ground is coloured per vertex from the map's
    /// ground types, as before ground textures existed): for comparing cost and looks.
    #[arg(long)]
    pub(crate) no_ground_textures: bool,
    /// The sun's compass azimuth in degrees (0 north, 90 east). The light grids (terrain and
    /// canopy shadows, sky occlusion) are made for it; the panel's sliders change it live.
    #[arg(long, default_value_t = Sun::default().azimuth_deg, value_parser = azimuth)]
    pub(crate) sun_azimuth_deg: f64,
    /// The sun's elevation above the horizon in degrees (-10 to 90; low values give long
    /// shadows, at or below 0 only the sky lights the scene).
    #[arg(long, default_value_t = Sun::default().elevation_deg, value_parser = elevation)]
    pub(crate) sun_elevation_deg: f64,
    /// Do not make light grids: the sun and sky light everything fully, with no shadows or
    /// occlusion (as before light grids existed), for comparing cost and looks.
    #[arg(long)]
    pub(crate) no_lighting: bool,
    /// Leave out the map's houses (its towns), for comparing cost and looks.
    #[arg(long)]
    pub(crate) no_buildings: bool,
    /// Debug view: everything grey, lit by the light grids alone.
    #[arg(long)]
    pub(crate) lighting_only: bool,
    /// Debug view: the light grids' values (red: sky visibility, green: sun visibility, blue:
    /// the ground's bounce).
    #[arg(long)]
    pub(crate) light_values: bool,
    /// Headless: before the first frame, stream its view until ready and its light grids are
    /// computed (pictures of a settled view; the frames' statistics then start warm).
    #[arg(long)]
    pub(crate) warm_start: bool,
    /// Headless: before the flight, draw frames of its first view until one shows the world
    /// (terrain at any level of detail; at most 60 s), and report the time from the start of
    /// the map's open to that frame (`first_world_frame_s` in stats.json), what a user waits
    /// for. Without it the time is reported only if a frame of the flight shows the world.
    #[arg(long)]
    pub(crate) wait_first_world: bool,
    /// Place this model as progressive-mesh objects in the world (repeatable): a `.pm` file
    /// (`worldgen pm`), or an `.obj` / `.gltf` / `.glb` built at start-up with the quadric
    /// cost (a glTF `MSFT_lod` chain's levels too, each with its bounded distance to the base).
    /// Copies stand in a row ahead of the first camera, on the ground; each instance draws the
    /// level (of the base or of a chain level) with the fewest triangles whose error stays
    /// within tau on screen.
    #[arg(long)]
    pub(crate) object: Vec<PathBuf>,
    /// Copies of each --object.
    #[arg(long, default_value_t = 6)]
    pub(crate) object_count: usize,
    /// Size of each copy (its largest extent), metres.
    #[arg(long, default_value_t = 12.0, value_parser = positive)]
    pub(crate) object_size_m: f64,
    /// Progressive meshes: scale of the pixel metric (seed 003's STRENGTH; 2 keeps detail to
    /// half the distance).
    #[arg(long, default_value_t = 1.0, value_parser = positive)]
    pub(crate) pm_strength: f64,
    /// Progressive meshes: fewest vertices drawn (MINVERTS).
    #[arg(long, default_value_t = 4)]
    pub(crate) pm_min_vertices: usize,
    /// Progressive meshes: metres subtracted from the distance before the metric (ZDISP).
    #[arg(long, default_value_t = 0.0)]
    pub(crate) pm_zdisp_m: f64,
    /// Progressive meshes: geomorph over this many seconds when an object's level changes
    /// (MORPH; 0 switches at once).
    #[arg(long, default_value_t = 0.25)]
    pub(crate) pm_morph_s: f64,
    /// Debug: draw every object with this fraction of its vertices (MLFIX), 0 to 1.
    #[arg(long, value_parser = fraction)]
    pub(crate) pm_fixed: Option<f64>,
    /// Debug: colour objects by the share of their vertices drawn (blue coarse .. red full).
    #[arg(long)]
    pub(crate) pm_color_by_lod: bool,
    /// Debug: tint textured objects (houses) by the mip level the texture cache holds for them
    /// (red full resolution, orange, yellow, green, cyan, blue, violet coarser; grey none).
    #[arg(long)]
    pub(crate) texture_mip_view: bool,
    /// Draw every house on its own, also where a node's merged far mesh (HLOD) would do.
    #[arg(long)]
    pub(crate) no_hlod: bool,
    /// Bake the light grids' sky pages of the whole map into its folder (`<map>/.sky_pages`)
    /// on all cores, then exit. The sky is most of a light grid's cost and depends on no sun;
    /// with its page a grid costs about a fifth. Maps of 2 km and more bake a node's page the
    /// first time its grid is made anyway; this bakes them all ahead of time (minutes on the
    /// 8 km map). Pages already there and valid are kept.
    #[arg(long)]
    pub(crate) bake_sky: bool,
}

fn fraction(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if (0.0..=1.0).contains(&v) => Ok(v),
        Ok(v) => Err(format!("{v} must be between 0 and 1")),
        Err(e) => Err(format!("{s:?} is not a number: {e}")),
    }
}

impl Cli {
    /// The sun of --sun-azimuth-deg and --sun-elevation-deg.
    pub(crate) fn sun(&self) -> Sun {
        Sun {
            azimuth_deg: self.sun_azimuth_deg,
            elevation_deg: self.sun_elevation_deg,
        }
    }
}

fn azimuth(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v.rem_euclid(360.0)),
        Ok(v) => Err(format!("{v} must be a finite number of degrees")),
        Err(e) => Err(format!("{s:?} is not a number: {e}")),
    }
}

fn elevation(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if (-10.0..=90.0).contains(&v) => Ok(v),
        Ok(v) => Err(format!("{v} must be between -10 and 90 degrees")),
        Err(e) => Err(format!("{s:?} is not a number: {e}")),
    }
}

/// `--ground-view` values.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum GroundViewArg {
    Shaded,
    TexelDensity,
    TextureOnly,
}

impl From<GroundViewArg> for GroundView {
    fn from(v: GroundViewArg) -> Self {
        match v {
            GroundViewArg::Shaded => GroundView::Shaded,
            GroundViewArg::TexelDensity => GroundView::TexelDensity,
            GroundViewArg::TextureOnly => GroundView::TextureOnly,
        }
    }
}

/// The viewer for `cli`: every registered content kind (less ground textures with
/// `--no-ground-textures`, less light grids with `--no-lighting`, less the map's houses with
/// `--no-buildings`, plus the `--object` models),
/// the ground view of `--ground-view`, the sun of `--sun-*`. `start` is the first camera (the
/// objects stand ahead of it).
pub(crate) fn make_viewer(
    cli: &Cli,
    gpu: &Gpu,
    format: wgpu::TextureFormat,
    world: World,
    start: &Camera,
) -> anyhow::Result<Viewer> {
    let mut kinds = engine::kinds::registered(&world);
    if cli.no_ground_textures {
        kinds.retain(|k| k.kind.name() != GroundContent::NAME);
    }
    if cli.no_lighting {
        kinds.retain(|k| k.kind.name() != LightingContent::NAME);
    }
    if cli.no_buildings || !cli.object.is_empty() {
        kinds.retain(|k| k.kind.name() != engine::objects::content::ObjectsContent::NAME);
    }
    if !cli.object.is_empty() {
        kinds.push(objects_registration(cli, &world, start)?);
    }
    let mut viewer =
        Viewer::with_kinds_from(gpu, format, world, settings(cli), &kinds, Some(start));
    viewer.view.ground_view = cli.ground_view.into();
    viewer.view.lighting_only = cli.lighting_only;
    viewer.view.light_values = cli.light_values;
    viewer.view.pm_lod = PmLodSettings {
        strength: cli.pm_strength,
        min_vertices: cli.pm_min_vertices,
        z_disp_m: cli.pm_zdisp_m,
        fixed_fraction: cli.pm_fixed,
        morph_s: cli.pm_morph_s.max(0.0),
    };
    viewer.view.pm_color_by_lod = cli.pm_color_by_lod;
    viewer.view.texture_mip_view = cli.texture_mip_view;
    viewer.view.hlod = !cli.no_hlod;
    viewer.set_sun(cli.sun(), glam::DVec3::ZERO);
    Ok(viewer)
}

/// The objects kind for `--object`: the models, copies in a row ahead of `start`, with the
/// map's houses unless `--no-buildings`.
fn objects_registration(
    cli: &Cli,
    world: &World,
    start: &Camera,
) -> anyhow::Result<engine::kinds::Registration> {
    use engine::objects::content::ObjectsContent;
    use engine::objects::set::{ObjectSet, PmModel};
    let mut models = Vec::new();
    for p in &cli.object {
        eprintln!("loading object {}", p.display());
        models.push(PmModel::load(p).with_context(|| format!("--object {}", p.display()))?);
    }
    let f = start.forward;
    let dir = if f.x.hypot(f.y) > 1e-6 {
        [f.x, f.y]
    } else {
        [1.0, 0.0]
    };
    let len = dir[0].hypot(dir[1]);
    let ahead_m = 3.0 * cli.object_size_m;
    let from = [
        start.position_m.x + dir[0] / len * ahead_m,
        start.position_m.y + dir[1] / len * ahead_m,
    ];
    let row = ObjectSet::place_row(
        models,
        from,
        dir,
        cli.object_count,
        2.5 * cli.object_size_m,
        cli.object_size_m,
        |x, y| world.height_m(x, y),
    );
    let mut set = if cli.no_buildings {
        ObjectSet::default()
    } else {
        ObjectSet::from_buildings(
            &world.map.buildings,
            &world.map.building_models,
            &world.map.building_textures,
        )
    };
    set.append(row);
    Ok(engine::kinds::Registration {
        kind: std::sync::Arc::new(ObjectsContent {
            set: std::sync::Arc::new(set),
        }),
        renderer: Some(engine::render::objects::ObjectsRenderer::create),
    })
}

/// A finite number above zero (thresholds, rates, durations).
fn positive(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        Ok(v) => Err(format!("{v} must be a finite number above 0")),
        Err(e) => Err(format!("{s:?} is not a number: {e}")),
    }
}

fn parse_size(s: &str) -> Result<[u32; 2], String> {
    let (w, h) = s
        .split_once('x')
        .ok_or_else(|| format!("expected WxH such as 1280x720, got {s:?}"))?;
    let p = |v: &str| {
        v.parse::<u32>()
            .ok()
            .filter(|&n| (16..=8192).contains(&n))
            .ok_or_else(|| format!("size {v:?} must be a number of pixels in 16..=8192"))
    };
    Ok([p(w)?, p(h)?])
}

pub(crate) fn settings(cli: &Cli) -> StreamSettings {
    let s = StreamSettings {
        tau_px: cli.tau,
        cache_budget_bytes: cli.budget_mib << 20,
        vegetation_occlusion: cli.vegetation_occlusion,
        decimate: !cli.no_decimation,
        ..StreamSettings::default()
    };
    match cli.workers {
        Some(w) => s.with_workers(w),
        None => s,
    }
}

/// The camera at time `t_s`: the replayed path, or the automatic flyover, with a vertical
/// field of view of `fov_deg`.
pub(crate) fn scripted_camera(
    cli: &Cli,
    path: Option<&CameraPath>,
    world: &engine::surface::World,
    t_s: f64,
    viewport: [u32; 2],
    fov_deg: f64,
) -> Camera {
    let mut cam = match path {
        Some(p) => p.at(t_s, viewport),
        None => auto_flyover(world, t_s / cli.duration_s, viewport),
    };
    cam.fovy_rad = fov_deg.to_radians();
    cam
}

/// `--bake-sky`: every sky page of the map, with a progress bar and a summary.
fn bake_sky(cli: &Cli) -> Result<()> {
    let bars = worldgen::progress::Bars::new(false);
    let world = apps::open_world(&cli.map, &bars)
        .with_context(|| format!("opening map {}", cli.map.display()))?;
    let tree = engine::terrain::quadtree::QuadTree::new(world.origin_m(), world.size_m());
    let canopy = engine::vegetation::content::VegetationContent::new(&world).canopy;
    let dir = cli.map.join(engine::lighting::sky_pages::SKY_PAGES_DIR);
    let pages = engine::lighting::sky_pages::SkyPages::new(&dir, &world, &canopy);
    let threads = std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get);
    let t0 = std::time::Instant::now();
    let baked = pages
        .bake((&world, &canopy, &tree), threads, &bars)
        .with_context(|| format!("baking the sky pages into {}", dir.display()))?;
    eprintln!(
        "{}: {} grid-level pages computed, {} kept, {} coarser pages derived in {:.1} s on {threads} \
         thread(s)",
        dir.display(),
        baked.computed,
        baked.kept,
        baked.derived,
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

fn display_available() -> bool {
    std::env::var_os("DISPLAY").is_some_and(|v| !v.is_empty())
        || std::env::var_os("WAYLAND_DISPLAY").is_some_and(|v| !v.is_empty())
}

fn main() -> std::process::ExitCode {
    apps::heap::rerun_with_huge_pages();
    env_logger::Builder::from_env(
        env_logger::Env::default()
            .default_filter_or("warn,winit=error,egui_wgpu=error,wgpu_hal=off"),
    )
    .init();
    let matches = Cli::command().get_matches();
    let mut cli = match Cli::from_arg_matches(&matches) {
        Ok(c) => c,
        Err(e) => e.exit(),
    };
    let result = if cli.bake_sky {
        bake_sky(&cli)
    } else if cli.headless {
        headless::run_headless(&cli)
    } else if !display_available() {
        let defaulted =
            |id: &str| matches.value_source(id) == Some(clap::parser::ValueSource::DefaultValue);
        if defaulted("frames") && defaulted("size") && defaulted("fps") {
            // The whole automatic flight in about a minute on a software adapter.
            cli.frames = 240;
            cli.size = [640, 360];
            cli.fps = 240.0 / cli.duration_s;
            if defaulted("every") {
                cli.every = 24;
            }
        }
        eprintln!(
            "no display (DISPLAY and WAYLAND_DISPLAY are unset): running headless, {} frames of \
             {}x{}, frames go to {}",
            cli.frames,
            cli.size[0],
            cli.size[1],
            cli.out.display()
        );
        headless::run_headless(&cli)
    } else {
        window::run(&cli)
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
