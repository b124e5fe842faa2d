//! Support for the binaries: opening (or generating) a map, the automatic flyover, camera path
//! files, and the frame loop shared by the windowed and headless viewer.

use crate::quadtree::NodeKey;
use crate::render::Gpu;
use crate::render::terrain::{Draw, DrawStats, TerrainNodeGpu, TerrainRenderer, ViewOptions};
use crate::select::Camera;
use crate::stream::{GpuSlot, StreamSettings, Streamer, terrain_phases};
use crate::world::World;
use glam::DVec3;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The map folder used when none is given.
pub const DEFAULT_MAP: &str = "maps/default";

#[derive(Debug, thiserror::Error)]
pub enum AppError {
    #[error("{0}")]
    Map(#[from] worldgen::MapError),
    #[error("generating the default map: {0}")]
    Generate(String),
    #[error("camera path {path}, line {line}: {problem}")]
    PathLine {
        path: PathBuf,
        line: usize,
        problem: String,
    },
    #[error("camera path {path}: {reason}")]
    PathFile { path: PathBuf, reason: String },
}

/// Opens the map at `dir`; the default map folder is generated first when it is missing, and
/// generated again when it was written by an older version of the map format (it is ours to
/// regenerate; any other map gets the version error).
pub fn open_world(
    dir: &Path,
    progress: &dyn worldgen::progress::Progress,
) -> Result<World, AppError> {
    let is_default = dir == Path::new(DEFAULT_MAP);
    let generate = |why: &str| -> Result<(), AppError> {
        eprintln!("{DEFAULT_MAP} {why}: generating the default map (8 km, seed 1, ~10 s) ...");
        let map = worldgen::generate::generate(
            &worldgen::generate::GenerateParams::default(),
            progress,
            &mut Vec::new(),
        )
        .map_err(|e| AppError::Generate(e.to_string()))?;
        map.write(dir)?;
        Ok(())
    };
    if is_default && !dir.join("map.toml").exists() {
        generate("not found")?;
    }
    match worldgen::Map::load(dir) {
        Err(worldgen::MapError::UnknownVersion {
            found, supported, ..
        }) if is_default && found < i64::from(supported) => {
            generate("is from an older map format")?;
            Ok(World::new(worldgen::Map::load(dir)?))
        }
        r => Ok(World::new(r?)),
    }
}

/// The automatic flyover: a low valley flight (25 m above the ground) for the first half, then
/// a climb to a high overview of the whole map. `t` in [0, 1].
pub fn auto_flyover(world: &World, t: f64, viewport_px: [u32; 2]) -> Camera {
    let o = world.origin_m();
    let s = world.size_m();
    let t = t.clamp(0.0, 1.0);
    let path = |t: f64| {
        [
            o[0] + s[0] * (0.15 + 0.6 * t),
            o[1] + s[1] * (0.25 + 0.45 * t + 0.05 * (t * 9.0).sin()),
        ]
    };
    // Height over the ground smoothed along the path, so the camera does not jitter over bumps.
    let ground = (0..9)
        .map(|i| {
            let p = path(t + (f64::from(i) - 4.0) * 0.004);
            world.height_m(p[0], p[1])
        })
        .fold(f64::NEG_INFINITY, f64::max);
    let climb = ((t - 0.5) / 0.5).clamp(0.0, 1.0);
    let above = 25.0 + climb * climb * 0.6 * s[0].max(s[1]);
    let p = path(t);
    let pos = DVec3::new(p[0], p[1], ground + above);
    let ahead = DVec3::new(s[0] * 0.6, s[1] * 0.45, 0.0).normalize();
    let pitch: f64 = -0.1;
    let low = DVec3::new(ahead.x * pitch.cos(), ahead.y * pitch.cos(), pitch.sin());
    // While climbing, turn from straight ahead to the map's centre, so the end is an overview.
    let centre = DVec3::new(
        o[0] + s[0] * 0.5,
        o[1] + s[1] * 0.5,
        world.height_m(o[0] + s[0] * 0.5, o[1] + s[1] * 0.5),
    );
    let w = climb * climb * (3.0 - 2.0 * climb);
    let dir = low
        .lerp((centre - pos).normalize_or(low), w)
        .normalize_or(low);
    Camera::look_at(pos, pos + dir, 60f64.to_radians(), viewport_px)
}

/// One key of a camera path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathKey {
    pub t_s: f64,
    pub position_m: DVec3,
    pub forward: DVec3,
}

const PATH_MAGIC: &str = "tvs-camera-path 1";

/// A recorded camera path: text, one key per line (`t_s x y z forward_x forward_y forward_z`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CameraPath {
    pub keys: Vec<PathKey>,
}

impl CameraPath {
    pub fn load(path: &Path) -> Result<Self, AppError> {
        let text = std::fs::read_to_string(path).map_err(|e| AppError::PathFile {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        let bad = |line: usize, problem: String| AppError::PathLine {
            path: path.to_path_buf(),
            line,
            problem,
        };
        let mut lines = text.lines().enumerate();
        match lines.next() {
            Some((_, l)) if l.trim() == PATH_MAGIC => {}
            _ => return Err(bad(1, format!("expected the first line {PATH_MAGIC:?}"))),
        }
        let mut keys: Vec<PathKey> = Vec::new();
        for (i, l) in lines {
            let l = l.trim();
            if l.is_empty() || l.starts_with('#') {
                continue;
            }
            let v: Vec<f64> = l
                .split_whitespace()
                .map(str::parse)
                .collect::<Result<_, _>>()
                .map_err(|e| bad(i + 1, format!("not a number: {e}")))?;
            if v.len() != 7 || v.iter().any(|x| !x.is_finite()) {
                return Err(bad(
                    i + 1,
                    format!("expected 7 finite numbers (t_s x y z fx fy fz), got {l:?}"),
                ));
            }
            let forward = DVec3::new(v[4], v[5], v[6]);
            if forward.length() < 1e-9 {
                return Err(bad(i + 1, "forward direction is zero".into()));
            }
            if keys.last().is_some_and(|k| v[0] <= k.t_s) {
                return Err(bad(i + 1, format!("time {} s does not increase", v[0])));
            }
            keys.push(PathKey {
                t_s: v[0],
                position_m: DVec3::new(v[1], v[2], v[3]),
                forward: forward.normalize(),
            });
        }
        if keys.is_empty() {
            return Err(AppError::PathFile {
                path: path.to_path_buf(),
                reason: "no keys".into(),
            });
        }
        Ok(Self { keys })
    }

    pub fn save(&self, path: &Path) -> Result<(), AppError> {
        let mut s = format!("{PATH_MAGIC}\n# t_s x_m y_m z_m forward_x forward_y forward_z\n");
        for k in &self.keys {
            let (p, f) = (k.position_m, k.forward);
            let _ = writeln!(
                s,
                "{:.4} {:.4} {:.4} {:.4} {:.6} {:.6} {:.6}",
                k.t_s, p.x, p.y, p.z, f.x, f.y, f.z
            );
        }
        std::fs::write(path, s).map_err(|e| AppError::PathFile {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })
    }

    pub fn duration_s(&self) -> f64 {
        self.keys.last().map_or(0.0, |k| k.t_s)
    }

    /// The camera at time `t_s` (linear between keys, clamped at the ends).
    pub fn at(&self, t_s: f64, viewport_px: [u32; 2]) -> Camera {
        let i = self.keys.partition_point(|k| k.t_s <= t_s);
        let (a, b) = (
            self.keys[i.saturating_sub(1)],
            self.keys[i.min(self.keys.len() - 1)],
        );
        let f = if b.t_s > a.t_s {
            ((t_s - a.t_s) / (b.t_s - a.t_s)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let pos = a.position_m.lerp(b.position_m, f);
        let fwd = a.forward.lerp(b.forward, f).normalize_or(a.forward);
        Camera::look_at(pos, pos + fwd, 60f64.to_radians(), viewport_px)
    }
}

/// Timings of one frame (ms) and what it drew.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct FrameStats {
    pub frame: u64,
    pub t_s: f64,
    /// Streaming update: selection, cancellation, requests, dispatch, fades.
    pub update_ms: f64,
    /// GPU phases (node buffer uploads) under their budget.
    pub upload_ms: f64,
    /// Building the draw list and recording the command buffer.
    pub encode_ms: f64,
    /// Waiting for the GPU to finish the frame (headless; windowed, the present waits).
    pub gpu_wait_ms: f64,
    /// GPU time of the terrain pass from timestamp queries (a recent frame's), when supported.
    pub gpu_terrain_ms: Option<f64>,
    /// Of `update_ms`: the selection of wanted nodes.
    pub selection_ms: f64,
    pub cpu_frame_ms: f64,
    pub draw_calls: u32,
    pub triangles: u64,
    /// Vegetation instances drawn (meshes and billboards), their draw calls, mesh triangles.
    pub plant_instances: u64,
    pub plant_draw_calls: u32,
    pub plant_triangles: u64,
    /// Of the vegetation instances: group-billboard quads (one per cluster of items).
    pub group_billboards: u64,
    pub drawn_nodes: usize,
    pub nodes_per_level: Vec<usize>,
    pub jobs_queued: usize,
    pub jobs_running: usize,
    pub jobs_waiting_gpu: usize,
    pub jobs_cancelled_total: u64,
    pub tiles_bytes: usize,
    pub node_buffers_bytes: usize,
    pub cache_bytes: usize,
    /// Wanted nodes not yet shown (a coarser ancestor stands in for them).
    pub pop_debt_nodes: usize,
}

/// Streaming + terrain rendering for one world: what one frame of the viewer does.
pub struct Viewer {
    pub streamer: Streamer,
    pub renderer: TerrainRenderer,
    pub view: ViewOptions,
    /// Debug: when set, selection uses this camera while rendering follows the live one.
    pub frozen: Option<Camera>,
    timer: Option<crate::render::GpuTimer>,
    frame: u64,
}

impl std::fmt::Debug for Viewer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Viewer(frame {})", self.frame)
    }
}

impl Viewer {
    pub fn new(
        gpu: &Gpu,
        color_format: wgpu::TextureFormat,
        world: World,
        settings: StreamSettings,
    ) -> Self {
        let legend: Vec<[u8; 3]> = world
            .map
            .manifest
            .ground
            .legend
            .iter()
            .map(|g| g.color)
            .collect();
        let streamer = Streamer::new(world, settings, terrain_phases());
        let mut renderer = TerrainRenderer::new(gpu, color_format, &legend);
        let names: Vec<String> = streamer
            .shared
            .placer
            .species
            .iter()
            .map(|s| s.name.clone())
            .collect();
        renderer.set_plant_looks(gpu, &names);
        Self {
            streamer,
            renderer,
            view: ViewOptions::default(),
            frozen: None,
            timer: crate::render::GpuTimer::new(gpu),
            frame: 0,
        }
    }

    /// Runs the streaming update and GPU uploads, then records the terrain into `encoder`.
    /// Returns the frame's statistics (GPU wait not included).
    pub fn frame(
        &mut self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        cam: &Camera,
        dt_s: f64,
    ) -> FrameStats {
        let t0 = Instant::now();
        let select_cam = self.frozen.unwrap_or(*cam);
        self.streamer.update(&select_cam, dt_s);
        let t1 = Instant::now();
        let device = &gpu.device;
        let renderer = &self.renderer;
        self.streamer.run_gpu_phases_with(&mut |shared, work| {
            if let Some(mesh) = &work.terrain {
                let mut node = TerrainRenderer::upload(device, &shared.tree, mesh);
                if let Some(v) = &work.vegetation {
                    node.plants = renderer.upload_plants(gpu, &shared.tree, mesh.key, v);
                }
                work.uploaded_bytes = node.bytes + node.plants.as_ref().map_or(0, |p| p.bytes);
                work.gpu = GpuSlot(Some(Box::new(node)));
            }
        });
        let t2 = Instant::now();
        let draws: Vec<Draw<'_>> = self
            .streamer
            .draw_list()
            .iter()
            .filter_map(|d| {
                let node = self
                    .streamer
                    .resident(d.key)?
                    .work
                    .gpu
                    .get::<TerrainNodeGpu>()?;
                Some(Draw {
                    node,
                    dither_lo: d.dither_lo,
                    dither_hi: d.dither_hi,
                })
            })
            .collect();
        if let Some(t) = self.timer.as_mut() {
            t.harvest(gpu);
        }
        let timed = self.timer.as_ref().is_some_and(|t| t.begin(encoder));
        // Ancestors of drawn nodes draw their kept vegetation (resident: the draw list is
        // walked down from the root through them).
        let mut ancestors: Vec<NodeKey> = Vec::new();
        for d in &draws {
            let mut k = d.node.key;
            while let Some(p) = k.parent() {
                ancestors.push(p);
                k = p;
            }
        }
        ancestors.sort_unstable();
        ancestors.dedup();
        let kept: Vec<&TerrainNodeGpu> = ancestors
            .iter()
            .filter_map(|&k| self.streamer.resident(k)?.work.gpu.get::<TerrainNodeGpu>())
            .collect();
        let drawn: DrawStats = self
            .renderer
            .render(gpu, encoder, color, depth, cam, &draws, &kept, &self.view);
        if timed && let Some(t) = &self.timer {
            t.end(encoder);
        }
        let mut per_level = vec![0usize; usize::from(self.streamer.tree().max_level) + 1];
        for d in &draws {
            per_level[usize::from(d.node.key.level)] += 1;
        }
        let node_bytes: usize = draws
            .iter()
            .map(|d| d.node.bytes + d.node.plants.as_ref().map_or(0, |p| p.bytes))
            .sum();
        let t3 = Instant::now();
        let st = &self.streamer.stats;
        let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
        let drawn_set: rustc_hash::FxHashSet<NodeKey> =
            self.streamer.draw_list().iter().map(|d| d.key).collect();
        let wanted_missing = self
            .streamer
            .wanted()
            .iter()
            .filter(|k| !drawn_set.contains(k))
            .count();
        self.frame += 1;
        FrameStats {
            frame: self.frame,
            t_s: 0.0,
            update_ms: ms(t0, t1),
            upload_ms: ms(t1, t2),
            encode_ms: ms(t2, t3),
            gpu_wait_ms: 0.0,
            gpu_terrain_ms: self.timer.as_ref().and_then(|t| t.last_ms),
            selection_ms: st.last_selection_s * 1e3,
            cpu_frame_ms: ms(t0, t3),
            draw_calls: drawn.draw_calls,
            triangles: drawn.triangles,
            plant_instances: drawn.plant_instances,
            plant_draw_calls: drawn.plant_draw_calls,
            plant_triangles: drawn.plant_triangles,
            group_billboards: drawn.group_billboards,
            drawn_nodes: draws.len(),
            nodes_per_level: per_level,
            jobs_queued: st.queued,
            jobs_running: st.running,
            jobs_waiting_gpu: st.waiting_gpu,
            jobs_cancelled_total: st.cancelled_queued + st.cancelled_running + st.cancelled_gpu,
            tiles_bytes: self.streamer.shared.tiles.lock().map_or(0, |t| t.bytes()),
            node_buffers_bytes: node_bytes,
            cache_bytes: st.resident_bytes,
            pop_debt_nodes: wanted_missing,
        }
    }

    /// Call after submitting the encoder given to [`Self::frame`] (starts the timestamp
    /// readback).
    pub fn after_submit(&self) {
        if let Some(t) = &self.timer {
            t.after_submit();
        }
    }

    /// Keys of the nodes drawn last frame.
    pub fn drawn_keys(&self) -> Vec<NodeKey> {
        self.streamer.draw_list().iter().map(|d| d.key).collect()
    }
}
