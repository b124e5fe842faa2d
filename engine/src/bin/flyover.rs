//! The flyover viewer: a window with the streamed terrain and an egui panel (detail level,
//! workers, memory budget, debug views, live statistics), or, with `--headless` or when no
//! display is available, an offscreen run that writes PNG frames and per-frame statistics.

use anyhow::{Context, Result, bail};
use clap::Parser;
use engine::app::{CameraPath, DEFAULT_MAP, FrameStats, PathKey, Viewer, auto_flyover, open_world};
use engine::render::{COLOR_FORMAT, Gpu, Target, write_png};
use engine::select::Camera;
use engine::stream::StreamSettings;
use glam::DVec3;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

#[derive(Parser, Debug, Clone)]
#[command(
    name = "flyover",
    about = "Fly over a map with streamed quad-tree terrain",
    long_about = "Fly over a map with streamed quad-tree terrain.\n\n\
        Window controls: the automatic flyover runs until you press a movement key or Space; \
        then W/A/S/D move, Q/E go down/up, hold the right mouse button and move to look, the \
        wheel changes speed, Space toggles the automatic flyover, F12 writes a screenshot, R \
        starts/stops recording a camera path (written to --record), Esc quits.\n\n\
        Without a display (no DISPLAY or WAYLAND_DISPLAY) it runs --headless instead."
)]
struct Cli {
    /// Map folder. The default map is generated there on first run when missing.
    #[arg(long, default_value = DEFAULT_MAP)]
    map: PathBuf,
    /// Render offscreen: write PNG frames and a JSON of per-frame statistics into --out.
    #[arg(long)]
    headless: bool,
    /// Frames to render (headless), at --fps steps of simulated time.
    #[arg(long, default_value_t = 600)]
    frames: u64,
    /// Simulated frames per second (headless) for the camera clock.
    #[arg(long, default_value_t = 30.0)]
    fps: f64,
    /// Output folder for frames, statistics and screenshots.
    #[arg(long, default_value = "out/flyover")]
    out: PathBuf,
    /// Write every Nth frame as PNG (headless).
    #[arg(long, default_value_t = 30)]
    every: u64,
    /// Replay this camera path file (see --record) instead of the automatic flyover.
    #[arg(long)]
    path: Option<PathBuf>,
    /// Where R (in the window) records a camera path.
    #[arg(long, default_value = "out/flyover/camera-path.txt")]
    record: PathBuf,
    /// Viewport size WxH in pixels.
    #[arg(long, default_value = "1280x720", value_parser = parse_size)]
    size: [u32; 2],
    /// Detail level: the largest projected geometric error in pixels.
    #[arg(long, default_value_t = 2.0)]
    tau: f64,
    /// Worker threads for node generation (default: cores - 1).
    #[arg(long)]
    workers: Option<usize>,
    /// Memory budget of the node cache in MiB.
    #[arg(long, default_value_t = 512)]
    budget_mib: usize,
    /// Split as if vegetation hid nothing (by default nodes whose view from a camera inside the
    /// canopy is blocked by dense vegetation split less).
    #[arg(long)]
    no_vegetation_occlusion: bool,
    /// Duration of the automatic flyover in seconds.
    #[arg(long, default_value_t = 40.0)]
    duration_s: f64,
    /// Window: write live statistics (JSON, overwritten each frame) to this file.
    #[arg(long)]
    stats_file: Option<PathBuf>,
    /// Window: quit after this many seconds.
    #[arg(long)]
    exit_after_s: Option<f64>,
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

fn settings(cli: &Cli) -> StreamSettings {
    let mut s = StreamSettings {
        tau_px: cli.tau,
        cache_budget_bytes: cli.budget_mib << 20,
        vegetation_occlusion: !cli.no_vegetation_occlusion,
        ..StreamSettings::default()
    };
    if let Some(w) = cli.workers {
        s.workers = w.max(1);
        s.max_in_flight = s.workers + 1;
    }
    s
}

/// The camera at time `t_s`: the replayed path, or the automatic flyover.
fn scripted_camera(
    cli: &Cli,
    path: Option<&CameraPath>,
    world: &engine::world::World,
    t_s: f64,
    viewport: [u32; 2],
) -> Camera {
    match path {
        Some(p) => p.at(t_s, viewport),
        None => auto_flyover(world, t_s / cli.duration_s, viewport),
    }
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn p95(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[(v.len() * 95 / 100).min(v.len() - 1)]
}

fn run_headless(cli: &Cli) -> Result<()> {
    let world = open_world(&cli.map, &worldgen::progress::Silent)
        .with_context(|| format!("opening map {}", cli.map.display()))?;
    let path = cli.path.as_deref().map(CameraPath::load).transpose()?;
    let gpu = Gpu::new_headless()?;
    eprintln!("headless on {}", gpu.adapter_name());
    std::fs::create_dir_all(&cli.out).with_context(|| format!("creating {}", cli.out.display()))?;
    let target = Target::new(&gpu.device, cli.size, COLOR_FORMAT);
    let mut viewer = Viewer::new(&gpu, COLOR_FORMAT, world, settings(cli));
    let bar = indicatif::ProgressBar::new(cli.frames);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} frames ({eta})")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    bar.set_message("rendering");
    let dt = 1.0 / cli.fps;
    let mut all: Vec<FrameStats> = Vec::new();
    let mut written = Vec::new();
    for f in 0..cli.frames {
        let t_s = f as f64 * dt;
        let cam = scripted_camera(
            cli,
            path.as_ref(),
            &viewer.streamer.shared.world,
            t_s,
            cli.size,
        );
        let mut enc = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("headless frame"),
            });
        let mut st = viewer.frame(
            &gpu,
            &mut enc,
            &target.color_view,
            &target.depth_view,
            &cam,
            dt,
        );
        let t0 = Instant::now();
        gpu.queue.submit([enc.finish()]);
        viewer.after_submit();
        gpu.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| anyhow::anyhow!("waiting for the GPU: {e}"))?;
        st.gpu_wait_ms = t0.elapsed().as_secs_f64() * 1e3;
        st.t_s = t_s;
        if cli.every > 0 && (f % cli.every == 0 || f + 1 == cli.frames) {
            let png = cli.out.join(format!("frame_{f:05}.png"));
            write_png(&png, target.size, &target.read_rgba(&gpu)?)?;
            written.push(png);
        }
        all.push(st);
        bar.inc(1);
    }
    bar.finish_and_clear();
    let col = |f: fn(&FrameStats) -> f64| all.iter().map(f).collect::<Vec<f64>>();
    let rows: [(&str, Vec<f64>); 13] = [
        (
            "streaming update (selection + bookkeeping)",
            col(|s| s.update_ms),
        ),
        ("  of which selection", col(|s| s.selection_ms)),
        ("GPU uploads", col(|s| s.upload_ms)),
        ("encode", col(|s| s.encode_ms)),
        ("GPU wait", col(|s| s.gpu_wait_ms)),
        (
            "GPU terrain pass (timestamp queries, when supported)",
            all.iter().filter_map(|s| s.gpu_terrain_ms).collect(),
        ),
        (
            "CPU frame (update + uploads + encode)",
            col(|s| s.cpu_frame_ms),
        ),
        ("triangles", col(|s| s.triangles as f64)),
        ("draw calls", col(|s| f64::from(s.draw_calls))),
        (
            "vegetation instances (meshes + billboards)",
            col(|s| s.plant_instances as f64),
        ),
        (
            "  of which group billboards (cluster quads)",
            col(|s| s.group_billboards as f64),
        ),
        (
            "vegetation draw calls",
            col(|s| f64::from(s.plant_draw_calls)),
        ),
        (
            "vegetation mesh triangles",
            col(|s| s.plant_triangles as f64),
        ),
    ];
    println!(
        "flyover --headless: {} frames at {}x{} on {}\n",
        all.len(),
        cli.size[0],
        cli.size[1],
        gpu.adapter_name()
    );
    println!("| per frame | median | p95 | max |\n|---|---:|---:|---:|");
    let mut summary = serde_json::Map::new();
    for (name, mut v) in rows {
        let max = v.iter().copied().fold(0.0, f64::max);
        let (m, p) = (median(&mut v), p95(&mut v));
        println!("| {name} | {m:.2} | {p:.2} | {max:.2} |");
        summary.insert(
            name.to_string(),
            serde_json::json!({"median": m, "p95": p, "max": max}),
        );
    }
    let json = cli.out.join("stats.json");
    let doc = serde_json::json!({
        "adapter": gpu.adapter_name(),
        "size": cli.size,
        "tau_px": cli.tau,
        "summary": summary,
        "frames": all,
    });
    std::fs::write(&json, serde_json::to_string_pretty(&doc)?)
        .with_context(|| format!("writing {}", json.display()))?;
    println!(
        "\n{} PNG frames in {}, statistics in {}",
        written.len(),
        cli.out.display(),
        json.display()
    );
    Ok(())
}

fn display_available() -> bool {
    std::env::var_os("DISPLAY").is_some_and(|v| !v.is_empty())
        || std::env::var_os("WAYLAND_DISPLAY").is_some_and(|v| !v.is_empty())
}

fn main() -> std::process::ExitCode {
    env_logger::Builder::from_env(
        env_logger::Env::default().default_filter_or("warn,winit=error,egui_wgpu=error"),
    )
    .init();
    let cli = Cli::parse();
    let result = if cli.headless {
        run_headless(&cli)
    } else if !display_available() {
        eprintln!(
            "no display (DISPLAY and WAYLAND_DISPLAY are unset): running headless, frames go to {}",
            cli.out.display()
        );
        run_headless(&cli)
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

mod window {
    //! The windowed viewer (winit 0.30 + egui 0.37).

    use super::{
        Arc, CameraPath, Cli, Context, DVec3, FrameStats, Gpu, Instant, PathKey, Result, Target,
        Viewer, bail, open_world, scripted_camera, settings, write_png,
    };
    use engine::select::Camera;
    use winit::application::ApplicationHandler;
    use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
    use winit::event_loop::{ActiveEventLoop, EventLoop};
    use winit::keyboard::{KeyCode, PhysicalKey};
    use winit::window::{Window, WindowId};

    pub fn run(cli: &Cli) -> Result<()> {
        // Open the map before the window, so a map error is reported plainly.
        let world = open_world(&cli.map, &worldgen::progress::Silent)
            .with_context(|| format!("opening map {}", cli.map.display()))?;
        let path = cli.path.as_deref().map(CameraPath::load).transpose()?;
        let event_loop = EventLoop::new().context("creating the window event loop")?;
        let mut app = App {
            cli: cli.clone(),
            world: Some(world),
            path,
            state: None,
            error: None,
        };
        event_loop
            .run_app(&mut app)
            .context("running the window event loop")?;
        if let Some(e) = app.error {
            return Err(e);
        }
        Ok(())
    }

    struct Ui {
        tau: f64,
        workers: usize,
        budget_mib: usize,
        fixed_level: Option<u8>,
        frozen: bool,
        occlusion: bool,
        slider_rect: [f32; 4],
    }

    struct State {
        window: Arc<Window>,
        surface: wgpu::Surface<'static>,
        config: wgpu::SurfaceConfiguration,
        gpu: Gpu,
        depth: wgpu::TextureView,
        viewer: Viewer,
        egui_ctx: egui::Context,
        egui_input: egui_winit::State,
        egui_renderer: egui_wgpu::Renderer,
        ui: Ui,
        auto: bool,
        cam: Camera,
        speed_m_s: f64,
        keys: rustc_hash::FxHashSet<KeyCode>,
        look: bool,
        last_cursor: Option<(f64, f64)>,
        yaw_pitch: (f64, f64),
        started: Instant,
        last_frame: Instant,
        t_s: f64,
        frame_ms: f64,
        last_stats: FrameStats,
        recording: Option<CameraPath>,
        screenshot: bool,
        screenshots: u32,
    }

    struct App {
        cli: Cli,
        /// The opened map, moved into the viewer when the window exists.
        world: Option<engine::world::World>,
        path: Option<CameraPath>,
        state: Option<State>,
        error: Option<anyhow::Error>,
    }

    impl App {
        fn init(&mut self, el: &ActiveEventLoop) -> Result<State> {
            let cli = &self.cli;
            let attrs = Window::default_attributes()
                .with_title("flyover")
                .with_inner_size(winit::dpi::PhysicalSize::new(cli.size[0], cli.size[1]));
            let window = Arc::new(el.create_window(attrs).context("creating the window")?);
            let instance =
                wgpu::Instance::new(wgpu::InstanceDescriptor::new_with_display_handle_from_env(
                    Box::new(el.owned_display_handle()),
                ));
            let surface = instance
                .create_surface(Arc::clone(&window))
                .context("creating the window surface")?;
            let gpu = Gpu::with_instance(instance, Some(&surface))?;
            let size = window.inner_size();
            let mut config = surface
                .get_default_config(&gpu.adapter, size.width.max(1), size.height.max(1))
                .context("the adapter cannot present to this window")?;
            // egui wants a non-sRGB surface; the terrain draws through an sRGB view of it.
            let caps = surface.get_capabilities(&gpu.adapter);
            if let Some(f) = caps.formats.iter().copied().find(|f| {
                matches!(
                    f,
                    wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Rgba8Unorm
                )
            }) {
                config.format = f;
                config.view_formats = vec![f.add_srgb_suffix()];
            }
            config.present_mode = wgpu::PresentMode::AutoVsync;
            surface.configure(&gpu.device, &config);
            let depth = engine::render::depth_view(
                &gpu.device,
                [config.width, config.height],
                "window depth",
            );
            let world = self
                .world
                .take()
                .context("the window was initialised twice")?;
            let vp = [config.width, config.height];
            let cam = scripted_camera(cli, self.path.as_ref(), &world, 0.0, vp);
            let viewer = Viewer::new(&gpu, config.format.add_srgb_suffix(), world, settings(cli));
            let egui_ctx = egui::Context::default();
            let egui_state = egui_winit::State::new(
                egui_ctx.clone(),
                egui::ViewportId::ROOT,
                &window,
                Some(window.scale_factor() as f32),
                None,
                None,
            );
            let egui_renderer = egui_wgpu::Renderer::new(
                &gpu.device,
                config.format,
                egui_wgpu::RendererOptions::default(),
            );
            let ws = viewer.streamer.settings;
            Ok(State {
                window,
                surface,
                config,
                gpu,
                depth,
                viewer,
                egui_ctx,
                egui_input: egui_state,
                egui_renderer,
                ui: Ui {
                    tau: cli.tau,
                    workers: ws.workers,
                    budget_mib: cli.budget_mib,
                    fixed_level: None,
                    frozen: false,
                    occlusion: !cli.no_vegetation_occlusion,
                    slider_rect: [0.0; 4],
                },
                auto: true,
                yaw_pitch: (cam.forward.y.atan2(cam.forward.x), cam.forward.z.asin()),
                cam,
                speed_m_s: 40.0,
                keys: rustc_hash::FxHashSet::default(),
                look: false,
                last_cursor: None,
                started: Instant::now(),
                last_frame: Instant::now(),
                t_s: 0.0,
                frame_ms: 0.0,
                last_stats: FrameStats::default(),
                recording: None,
                screenshot: false,
                screenshots: 0,
            })
        }
    }

    impl ApplicationHandler for App {
        fn resumed(&mut self, el: &ActiveEventLoop) {
            if self.state.is_some() {
                return;
            }
            match self.init(el) {
                Ok(s) => self.state = Some(s),
                Err(e) => {
                    self.error = Some(e);
                    el.exit();
                }
            }
        }

        fn window_event(&mut self, el: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
            let Some(st) = self.state.as_mut() else {
                return;
            };
            let consumed = st.egui_input.on_window_event(&st.window, &event).consumed;
            match event {
                WindowEvent::CloseRequested => el.exit(),
                WindowEvent::Resized(size) => {
                    st.config.width = size.width.max(1);
                    st.config.height = size.height.max(1);
                    st.surface.configure(&st.gpu.device, &st.config);
                    st.depth = engine::render::depth_view(
                        &st.gpu.device,
                        [st.config.width, st.config.height],
                        "window depth",
                    );
                }
                WindowEvent::KeyboardInput { event, .. } if !consumed => {
                    if let PhysicalKey::Code(code) = event.physical_key {
                        let down = event.state == ElementState::Pressed;
                        if down {
                            st.keys.insert(code);
                        } else {
                            st.keys.remove(&code);
                        }
                        if down && !event.repeat {
                            match code {
                                KeyCode::Escape => el.exit(),
                                KeyCode::Space => st.auto = !st.auto,
                                KeyCode::F12 => st.screenshot = true,
                                KeyCode::KeyR => {
                                    if let Some(p) = st.recording.take() {
                                        if let Some(dir) = self.cli.record.parent() {
                                            let _ = std::fs::create_dir_all(dir);
                                        }
                                        match p.save(&self.cli.record) {
                                            Ok(()) => eprintln!(
                                                "camera path: {}",
                                                self.cli.record.display()
                                            ),
                                            Err(e) => eprintln!("error: {e}"),
                                        }
                                    } else {
                                        st.recording = Some(CameraPath::default());
                                    }
                                }
                                KeyCode::KeyW
                                | KeyCode::KeyA
                                | KeyCode::KeyS
                                | KeyCode::KeyD
                                | KeyCode::KeyQ
                                | KeyCode::KeyE => st.auto = false,
                                _ => {}
                            }
                        }
                    }
                }
                WindowEvent::MouseInput {
                    state,
                    button: MouseButton::Right,
                    ..
                } if !consumed => {
                    st.look = state == ElementState::Pressed;
                    if st.look {
                        st.auto = false;
                    }
                }
                WindowEvent::CursorMoved { position, .. } => {
                    if let Some((x0, y0)) = st.last_cursor
                        && st.look
                    {
                        st.yaw_pitch.0 -= (position.x - x0) * 0.003;
                        st.yaw_pitch.1 =
                            (st.yaw_pitch.1 - (position.y - y0) * 0.003).clamp(-1.5, 1.5);
                    }
                    st.last_cursor = Some((position.x, position.y));
                }
                WindowEvent::MouseWheel { delta, .. } if !consumed => {
                    let lines = match delta {
                        MouseScrollDelta::LineDelta(_, y) => f64::from(y),
                        MouseScrollDelta::PixelDelta(p) => p.y / 40.0,
                    };
                    st.speed_m_s = (st.speed_m_s * 1.25f64.powf(lines)).clamp(1.0, 5000.0);
                }
                WindowEvent::RedrawRequested => {
                    if let Err(e) = redraw(st, &self.cli, self.path.as_ref()) {
                        self.error = Some(e);
                        el.exit();
                    }
                    if self
                        .cli
                        .exit_after_s
                        .is_some_and(|s| st.started.elapsed().as_secs_f64() > s)
                    {
                        el.exit();
                    }
                }
                _ => {}
            }
        }

        fn about_to_wait(&mut self, _el: &ActiveEventLoop) {
            if let Some(st) = &self.state {
                st.window.request_redraw();
            }
        }
    }

    fn free_fly(st: &mut State, dt: f64) {
        let (yaw, pitch) = st.yaw_pitch;
        let fwd = DVec3::new(
            yaw.cos() * pitch.cos(),
            yaw.sin() * pitch.cos(),
            pitch.sin(),
        );
        let right = fwd.cross(DVec3::Z).normalize_or(DVec3::X);
        let mut v = DVec3::ZERO;
        let k = |c: KeyCode| if st.keys.contains(&c) { 1.0 } else { 0.0 };
        v += fwd * (k(KeyCode::KeyW) - k(KeyCode::KeyS));
        v += right * (k(KeyCode::KeyD) - k(KeyCode::KeyA));
        v += DVec3::Z * (k(KeyCode::KeyE) - k(KeyCode::KeyQ));
        let pos = st.cam.position_m + v * st.speed_m_s * dt;
        st.cam = Camera::look_at(pos, pos + fwd, st.cam.fovy_rad, st.cam.viewport_px);
    }

    fn panel(
        ui: &mut egui::Ui,
        st_ui: &mut Ui,
        view: &mut engine::render::terrain::ViewOptions,
        s: &FrameStats,
        frame_ms: f64,
        gpu: &Gpu,
        extra: &str,
    ) {
        ui.heading("Detail");
        let r = ui.add(
            egui::Slider::new(&mut st_ui.tau, 0.5..=16.0)
                .logarithmic(true)
                .text("pixel error τ (px)"),
        );
        st_ui.slider_rect = [r.rect.min.x, r.rect.min.y, r.rect.max.x, r.rect.max.y];
        ui.add(egui::Slider::new(&mut st_ui.workers, 1..=32).text("workers (restarts streaming)"));
        ui.add(egui::Slider::new(&mut st_ui.budget_mib, 32..=8192).text("node cache MiB"));
        ui.separator();
        ui.heading("Debug views");
        let mut fixed = st_ui.fixed_level.is_some();
        if gpu.wireframe {
            ui.checkbox(&mut view.wireframe, "wireframe");
        } else {
            ui.label("wireframe: not supported by this adapter");
        }
        ui.checkbox(&mut view.color_by_level, "colour by level");
        ui.checkbox(&mut view.show_bounds, "node bounds");
        ui.checkbox(&mut view.plants, "vegetation");
        ui.checkbox(&mut st_ui.occlusion, "split less behind dense vegetation");
        ui.checkbox(&mut st_ui.frozen, "freeze culling camera");
        ui.checkbox(&mut fixed, "fixed level");
        if fixed {
            let mut l = st_ui.fixed_level.unwrap_or(6);
            ui.add(egui::Slider::new(&mut l, 0..=12).text("level"));
            st_ui.fixed_level = Some(l);
        } else {
            st_ui.fixed_level = None;
        }
        ui.separator();
        ui.heading("Statistics");
        ui.label(format!(
            "{:.1} fps, frame {frame_ms:.1} ms (CPU: update {:.2}, uploads {:.2}, encode {:.2} ms)",
            1000.0 / frame_ms.max(1e-3),
            s.update_ms,
            s.upload_ms,
            s.encode_ms
        ));
        ui.label(match (gpu.timestamps, s.gpu_terrain_ms) {
            (true, Some(ms)) => format!("GPU: terrain pass {ms:.2} ms (timestamp queries)"),
            (true, None) => "GPU: waiting for the first timestamps".to_string(),
            (false, _) => "GPU time: timestamps not supported by this adapter".to_string(),
        });
        ui.label(format!(
            "triangles {}  draw calls {}  nodes {}",
            s.triangles, s.draw_calls, s.drawn_nodes
        ));
        ui.label(format!(
            "vegetation: {} instances, {} draw calls, {} mesh triangles",
            s.plant_instances, s.plant_draw_calls, s.plant_triangles
        ));
        ui.label(format!("nodes per level {:?}", s.nodes_per_level));
        ui.label(format!(
            "jobs: queued {} running {} waiting GPU {} cancelled {}",
            s.jobs_queued, s.jobs_running, s.jobs_waiting_gpu, s.jobs_cancelled_total
        ));
        ui.label(format!(
            "memory: tiles {:.1} MiB, drawn node buffers {:.1} MiB, node cache {:.1} MiB",
            s.tiles_bytes as f64 / 1_048_576.0,
            s.node_buffers_bytes as f64 / 1_048_576.0,
            s.cache_bytes as f64 / 1_048_576.0
        ));
        ui.label(format!(
            "pop debt: {} wanted nodes not shown yet",
            s.pop_debt_nodes
        ));
        ui.label(extra);
    }

    fn redraw(st: &mut State, cli: &Cli, path: Option<&CameraPath>) -> Result<()> {
        let now = Instant::now();
        let elapsed_s = (now - st.last_frame).as_secs_f64();
        st.frame_ms = st.frame_ms * 0.9 + elapsed_s * 1e3 * 0.1;
        // The simulation step is capped, so a slow frame does not jump the camera.
        let dt = elapsed_s.min(0.1);
        st.last_frame = now;
        let vp = [st.config.width, st.config.height];
        if st.auto {
            st.t_s += dt;
            st.cam = scripted_camera(cli, path, &st.viewer.streamer.shared.world, st.t_s, vp);
            st.yaw_pitch = (
                st.cam.forward.y.atan2(st.cam.forward.x),
                st.cam.forward.z.asin(),
            );
        } else {
            st.cam.viewport_px = vp;
            free_fly(st, dt);
        }
        if let Some(rec) = st.recording.as_mut() {
            let t = rec.keys.last().map_or(0.0, |k| k.t_s + dt.max(1e-3));
            rec.keys.push(PathKey {
                t_s: t,
                position_m: st.cam.position_m,
                forward: st.cam.forward,
            });
        }
        // Apply the panel's settings.
        {
            let s = &mut st.viewer.streamer.settings;
            s.tau_px = st.ui.tau;
            s.cache_budget_bytes = st.ui.budget_mib << 20;
            s.fixed_level = st.ui.fixed_level;
            s.vegetation_occlusion = st.ui.occlusion;
        }
        if st.ui.workers != st.viewer.streamer.settings.workers {
            let mut s = st.viewer.streamer.settings;
            s.workers = st.ui.workers;
            s.max_in_flight = s.workers + 1;
            let world = engine::world::World::new(st.viewer.streamer.shared.world.map.clone());
            st.viewer.streamer =
                engine::stream::Streamer::new(world, s, engine::stream::terrain_phases());
        }
        match (st.ui.frozen, st.viewer.frozen) {
            (true, None) => st.viewer.frozen = Some(st.cam),
            (false, Some(_)) => st.viewer.frozen = None,
            _ => {}
        }
        let frame = match st.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(f)
            | wgpu::CurrentSurfaceTexture::Suboptimal(f) => f,
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => {
                return Ok(());
            }
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                st.surface.configure(&st.gpu.device, &st.config);
                return Ok(());
            }
            wgpu::CurrentSurfaceTexture::Validation => {
                bail!("the window surface failed validation")
            }
        };
        let view = frame
            .texture
            .create_view(&wgpu::TextureViewDescriptor::default());
        let terrain_view = frame.texture.create_view(&wgpu::TextureViewDescriptor {
            format: Some(st.config.format.add_srgb_suffix()),
            ..Default::default()
        });
        let mut enc = st
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("window frame"),
            });
        let stats = st
            .viewer
            .frame(&st.gpu, &mut enc, &terrain_view, &st.depth, &st.cam, dt);
        // The UI: two passes on the first frame (egui lays windows out on the first pass).
        let extra = format!(
            "camera ({:.0}, {:.0}, {:.0}) m, speed {:.0} m/s, {}{}",
            st.cam.position_m.x,
            st.cam.position_m.y,
            st.cam.position_m.z,
            st.speed_m_s,
            if st.auto {
                "automatic flyover"
            } else {
                "free fly"
            },
            if st.recording.is_some() {
                ", recording"
            } else {
                ""
            }
        );
        let mut output: Option<egui::FullOutput> = None;
        let passes = if st.viewer.streamer.stats.completed == 0 {
            2
        } else {
            1
        };
        for _ in 0..passes {
            let input = st.egui_input.take_egui_input(&st.window);
            let (ui_state, view, gpu, fm) = (&mut st.ui, &mut st.viewer.view, &st.gpu, st.frame_ms);
            let mut out = st.egui_ctx.run_ui(input, |ui| {
                egui::Panel::left("controls").show(ui, |ui| {
                    panel(ui, ui_state, view, &stats, fm, gpu, &extra);
                });
            });
            // Texture changes of an earlier pass still have to reach the renderer.
            if let Some(mut prev) = output.take() {
                let mut d = std::mem::take(&mut prev.textures_delta);
                d.append(std::mem::take(&mut out.textures_delta));
                out.textures_delta = d;
            }
            output = Some(out);
        }
        let mut output = output.expect("at least one UI pass ran");
        st.egui_input
            .handle_platform_output(&st.window, output.platform_output);
        let ppp = output.pixels_per_point;
        let prims = st.egui_ctx.tessellate(output.shapes, ppp);
        let screen = egui_wgpu::ScreenDescriptor {
            size_in_pixels: [st.config.width, st.config.height],
            pixels_per_point: ppp,
        };
        let mut textures = std::mem::take(&mut output.textures_delta);
        for (id, deltas) in &textures.set {
            for delta in deltas {
                st.egui_renderer
                    .update_texture(&st.gpu.device, &st.gpu.queue, *id, delta);
            }
        }
        let extra_cmds = st.egui_renderer.update_buffers(
            &st.gpu.device,
            &st.gpu.queue,
            &mut enc,
            &prims,
            &screen,
        );
        draw_ui(&mut enc, &view, &st.egui_renderer, &prims, &screen);
        st.gpu
            .queue
            .submit(extra_cmds.into_iter().chain([enc.finish()]));
        st.viewer.after_submit();
        st.gpu.queue.present(frame);
        for id in &textures.free {
            st.egui_renderer.free_texture(id);
        }
        // Applied above; egui checks that nothing is dropped unapplied.
        textures.clear();
        if st.screenshot {
            st.screenshot = false;
            screenshot(st, cli, &prims, &screen)?;
        }
        if let Some(p) = &cli.stats_file {
            let doc = serde_json::json!({
                "tau_px": st.ui.tau,
                "slider_rect_points": st.ui.slider_rect,
                "pixels_per_point": ppp,
                "screenshots": st.screenshots,
                "stats": stats,
            });
            let tmp = p.with_extension("tmp");
            std::fs::write(&tmp, serde_json::to_string(&doc)?)?;
            std::fs::rename(&tmp, p)?;
        }
        st.last_stats = stats;
        Ok(())
    }

    /// Draws the UI over what `view` already holds.
    fn draw_ui(
        enc: &mut wgpu::CommandEncoder,
        view: &wgpu::TextureView,
        renderer: &egui_wgpu::Renderer,
        prims: &[egui::ClippedPrimitive],
        screen: &egui_wgpu::ScreenDescriptor,
    ) {
        let pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("egui pass"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Load,
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        renderer.render(&mut pass.forget_lifetime(), prims, screen);
    }

    /// Renders the current view again into an offscreen target (a window surface may not be a
    /// copy source) and writes it as PNG.
    fn screenshot(
        st: &mut State,
        cli: &Cli,
        prims: &[egui::ClippedPrimitive],
        screen: &egui_wgpu::ScreenDescriptor,
    ) -> Result<()> {
        let size = [st.config.width, st.config.height];
        let target = Target::with_srgb_view(&st.gpu.device, size, st.config.format);
        let mut enc = st
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("screenshot"),
            });
        st.viewer.frame(
            &st.gpu,
            &mut enc,
            &target.color_view,
            &target.depth_view,
            &st.cam,
            0.0,
        );
        draw_ui(
            &mut enc,
            &target.plain_view,
            &st.egui_renderer,
            prims,
            screen,
        );
        st.gpu.queue.submit([enc.finish()]);
        std::fs::create_dir_all(&cli.out)?;
        let p = cli
            .out
            .join(format!("screenshot_{:03}.png", st.screenshots));
        write_png(&p, size, &target.read_rgba(&st.gpu)?)?;
        st.screenshots += 1;
        eprintln!("screenshot: {}", p.display());
        Ok(())
    }
}
