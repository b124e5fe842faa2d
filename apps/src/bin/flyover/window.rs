//! The windowed viewer (winit 0.30 + egui 0.37): window, input, frame loop, screenshots.

use crate::panel::{Ui, panel};
use crate::{Cli, make_viewer, scripted_camera};
use anyhow::{Context, Result, bail};
use apps::open_world;
use engine::camera::Camera;
use engine::flight::{CameraPath, PathKey};
use engine::render::{Gpu, Target, write_png};
use engine::viewer::{FrameStats, Viewer};
use glam::DVec3;
use std::sync::Arc;
use std::time::Instant;
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

/// The panel's pop debt covers this many seconds of frames.
const POP_DEBT_WINDOW_S: f64 = 5.0;

pub fn run(cli: &Cli) -> Result<()> {
    // Open the map before the window, so a map error is reported plainly.
    let world = open_world(&cli.map, &worldgen::progress::Bars::new(false))
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
    /// Pop debt of the last seconds, for the panel, on the frames' clock.
    pop_debt: engine::stream::PopDebtWindow,
    clock_s: f64,
    recording: Option<CameraPath>,
    screenshot: bool,
    screenshots: u32,
    faults: Faults,
}

/// What keeps the viewer from drawing a frame.
struct Faults {
    /// The window has no area (minimised): no frame is drawn until it has one again.
    minimised: bool,
    /// Set by the device's lost callback and by its uncaptured-error handler: the viewer exits
    /// with this message at the next frame (it does not recreate a lost device).
    gpu_failure: Arc<std::sync::Mutex<Option<String>>>,
    /// `--debug-lose-device-after-s` has destroyed the device.
    device_destroyed: bool,
}

/// Whether to draw this frame: an error when the GPU failed, false while minimised or right
/// after the test hook destroyed the device.
fn may_draw(st: &mut State, cli: &Cli) -> Result<bool> {
    let f = &mut st.faults;
    if let Some(failure) = f
        .gpu_failure
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .clone()
    {
        bail!(
            "{failure}; the viewer does not recreate its GPU device, so it stops here (restart \
             it; a driver update or a smaller --budget-mib may help)"
        );
    }
    if let Some(after_s) = cli.debug_lose_device_after_s
        && !f.device_destroyed
        && st.started.elapsed().as_secs_f64() > after_s
    {
        // Test hook: lose the device the way a driver reset would, then let wgpu report it.
        f.device_destroyed = true;
        st.gpu.device.destroy();
        let _ = st.gpu.device.poll(wgpu::PollType::Poll);
        return Ok(false);
    }
    Ok(!f.minimised)
}

/// Whether a window of this size can be drawn into (a minimised window reports 0x0).
fn drawable(size: winit::dpi::PhysicalSize<u32>) -> bool {
    size.width > 0 && size.height > 0
}

/// Records device loss and uncaptured GPU errors (the default handler panics) into `failure`.
fn watch_gpu(gpu: &Gpu, failure: &Arc<std::sync::Mutex<Option<String>>>) {
    let f = Arc::clone(failure);
    gpu.device.set_device_lost_callback(move |reason, message| {
        let mut slot = f.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        slot.get_or_insert(format!("the GPU device was lost ({reason:?}: {message})"));
    });
    let f = Arc::clone(failure);
    gpu.device
        .on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            let mut slot = f.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            slot.get_or_insert(format!("GPU error: {e}"));
        }));
}

struct App {
    cli: Cli,
    /// The opened map, moved into the viewer when the window exists.
    world: Option<engine::surface::world::World>,
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
        let gpu_failure = Arc::new(std::sync::Mutex::new(None));
        watch_gpu(&gpu, &gpu_failure);
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
        let depth =
            engine::render::depth_view(&gpu.device, [config.width, config.height], "window depth");
        let world = self
            .world
            .take()
            .context("the window was initialised twice")?;
        let vp = [config.width, config.height];
        let cam = scripted_camera(cli, self.path.as_ref(), &world, 0.0, vp, cli.fov_deg);
        let viewer = make_viewer(cli, &gpu, config.format.add_srgb_suffix(), world, &cam)?;
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
                fov_deg: cli.fov_deg,
                workers: ws.workers,
                budget_mib: cli.budget_mib,
                fixed_level: None,
                frozen: false,
                occlusion: cli.vegetation_occlusion,
                slider_rect: [0.0; 4],
                sun: cli.sun(),
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
            pop_debt: engine::stream::PopDebtWindow::new(POP_DEBT_WINDOW_S),
            clock_s: 0.0,
            recording: None,
            screenshot: false,
            screenshots: 0,
            faults: Faults {
                minimised: !drawable(size),
                gpu_failure,
                device_destroyed: false,
            },
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
                st.faults.minimised = !drawable(size);
                if st.faults.minimised {
                    return;
                }
                st.config.width = size.width;
                st.config.height = size.height;
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
                                        Ok(()) => {
                                            eprintln!("camera path: {}", self.cli.record.display());
                                        }
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
                    st.yaw_pitch.1 = (st.yaw_pitch.1 - (position.y - y0) * 0.003).clamp(-1.5, 1.5);
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
        // A minimised window waits for the event that gives it an area again.
        if let Some(st) = self.state.as_ref().filter(|st| !st.faults.minimised) {
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
    let fovy_rad = st.ui.fov_deg.to_radians();
    st.cam = Camera::look_at(pos, pos + fwd, fovy_rad, st.cam.viewport_px);
}

/// Applies the panel's settings to the streamer (a workers change restarts its threads).
fn apply_panel(st: &mut State) {
    {
        let s = &mut st.viewer.streamer.settings;
        s.tau_px = st.ui.tau;
        s.cache_budget_bytes = st.ui.budget_mib << 20;
        s.fixed_level = st.ui.fixed_level;
        s.vegetation_occlusion = st.ui.occlusion;
    }
    if st.ui.workers != st.viewer.streamer.settings.workers {
        let s = st.viewer.streamer.settings.with_workers(st.ui.workers);
        // Same world (shared, not copied) and content kinds, new worker threads.
        let shared = &st.viewer.streamer.shared;
        let world = shared.world.clone();
        let kinds = shared.kinds.clone();
        st.viewer.streamer = engine::stream::Streamer::new(world, s, kinds);
    }
    if st.ui.sun != st.viewer.view.sun {
        st.viewer.set_sun(st.ui.sun, st.cam.position_m);
    }
    match (st.ui.frozen, st.viewer.frozen) {
        (true, None) => st.viewer.frozen = Some(st.cam),
        (false, Some(_)) => st.viewer.frozen = None,
        _ => {}
    }
}

fn redraw(st: &mut State, cli: &Cli, path: Option<&CameraPath>) -> Result<()> {
    if !may_draw(st, cli)? {
        return Ok(());
    }
    let now = Instant::now();
    let elapsed_s = (now - st.last_frame).as_secs_f64();
    st.frame_ms = st.frame_ms * 0.9 + elapsed_s * 1e3 * 0.1;
    // The simulation step is capped, so a slow frame does not jump the camera.
    let dt = elapsed_s.min(0.1);
    st.last_frame = now;
    let vp = [st.config.width, st.config.height];
    if st.auto {
        st.t_s += dt;
        let world = &st.viewer.streamer.shared.world;
        let fov_deg = st.ui.fov_deg;
        st.cam = scripted_camera(cli, path, world, st.t_s, vp, fov_deg);
        // A scripted flight: prefetch follows its path (free flight extrapolates the velocity).
        st.viewer.path_ahead = engine::stream::predict::along(st.t_s, |t| {
            scripted_camera(cli, path, world, t, vp, fov_deg)
        });
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
    apply_panel(st);
    let frame = match st.surface.get_current_texture() {
        wgpu::CurrentSurfaceTexture::Success(f) | wgpu::CurrentSurfaceTexture::Suboptimal(f) => f,
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
    let mut stats = st
        .viewer
        .frame(&st.gpu, &mut enc, &terrain_view, &st.depth, &st.cam, dt);
    st.clock_s += elapsed_s;
    st.pop_debt.push(st.clock_s, stats.pop_excess_px);
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
    let pages = crate::panel::map_pages(&st.viewer.streamer.shared.world);
    let extra = if pages.is_empty() {
        extra
    } else {
        format!("{extra}\n{pages}")
    };
    let mut output: Option<egui::FullOutput> = None;
    let passes = if st.viewer.streamer.stats.completed == 0 {
        2
    } else {
        1
    };
    for _ in 0..passes {
        let input = st.egui_input.take_egui_input(&st.window);
        let (ui_state, view, gpu, fm) = (&mut st.ui, &mut st.viewer.view, &st.gpu, st.frame_ms);
        let pop_debt = &st.pop_debt;
        let mut out = st.egui_ctx.run_ui(input, |ui| {
            egui::Panel::left("controls").show(ui, |ui| {
                panel(ui, ui_state, view, (&stats, pop_debt), fm, gpu, &extra);
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
    let extra_cmds =
        st.egui_renderer
            .update_buffers(&st.gpu.device, &st.gpu.queue, &mut enc, &prims, &screen);
    draw_ui(&mut enc, &view, &st.egui_renderer, &prims, &screen);
    // The UI's encoding counts in the CPU frame too (one finish for both).
    st.viewer.submit_frame(&st.gpu, extra_cmds, enc, &mut stats);
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
        write_stats_file(p, st, ppp, &stats)?;
    }
    st.last_stats = stats;
    Ok(())
}

/// Writes the frame's statistics and the panel's state to `p` (replaced whole, so a reader never
/// sees half a file).
fn write_stats_file(p: &std::path::Path, st: &State, ppp: f32, stats: &FrameStats) -> Result<()> {
    let doc = serde_json::json!({
        "tau_px": st.ui.tau,
        "fov_deg": st.ui.fov_deg,
        "slider_rect_points": st.ui.slider_rect,
        "pixels_per_point": ppp,
        "screenshots": st.screenshots,
        "pop_debt_last": {
            "window_s": st.pop_debt.window_s(),
            "frames": st.pop_debt.frames(),
            "share": st.pop_debt.share(),
            "worst_px": st.pop_debt.worst_px(),
        },
        "surface_px": [st.config.width, st.config.height],
        "stats": stats,
    });
    let tmp = p.with_extension("tmp");
    std::fs::write(&tmp, serde_json::to_string(&doc)?)?;
    std::fs::rename(&tmp, p)?;
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
    let mut shot = st.viewer.frame(
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
    // Through the viewer, like every frame: its timers' readback follows the submission.
    st.viewer.submit_frame(&st.gpu, [], enc, &mut shot);
    std::fs::create_dir_all(&cli.out)?;
    let p = cli
        .out
        .join(format!("screenshot_{:03}.png", st.screenshots));
    write_png(&p, size, &target.read_rgba(&st.gpu)?)?;
    st.screenshots += 1;
    eprintln!("screenshot: {}", p.display());
    Ok(())
}
