//! Streaming: turning each frame's wanted node set into prioritized, cancellable, phased
//! background jobs, keeping prepared nodes in an LRU cache under a memory budget, and deciding
//! what is drawn (with cross-fades) so that nothing is ever missing from the screen.
//!
//! - **Phases are data.** A job runs the [`Phase`] list in order. CPU phases run on worker
//!   threads; GPU phases are handed back to the owner (render) thread and run there under a
//!   per-frame budget ([`Streamer::run_gpu_phases`]). New content (vegetation, light grids) is a
//!   new phase, not a new scheduler.
//! - **Priority** is larger nodes first, then nearer to the camera. Pending requests sit in one
//!   bucket per level; the distance is computed when a job is dispatched, so priorities follow
//!   the camera without rebuilding a queue.
//! - **Cancellation**: a request that is no longer wanted is removed from its bucket if still
//!   queued; if running, its flag is set and the worker stops at the next phase boundary,
//!   releasing its tiles; if waiting for its GPU phase, it is dropped. Every result carries
//!   (key, generation); results of an older generation are discarded, so a cancelled job's late
//!   result is never shown.
//! - **Replacement**: a node is replaced by its children only when every child that is needed
//!   (overlaps the map and is wanted or has wanted descendants) is ready; going back up works
//!   the same way. Changes cross-fade over [`StreamSettings::fade_s`]. Each drawn node gets a
//!   dither interval `[lo, hi)`: a pixel with ordered-dither value `d` is drawn by the node whose
//!   interval contains `d`. The intervals of the nodes covering a point partition [0, 1), so the
//!   parent and its children never both draw a pixel and never both skip it (complementary
//!   patterns, no sorting).
//! - Selection during streaming uses only bounds already known: a node whose bounds are unknown
//!   is wanted (its job measures them) but not descended into until they are.

use crate::bounds::{self, NodeBounds};
use crate::mesh::{self, NodeMesh};
use crate::quadtree::{NodeKey, QuadTree};
use crate::select::Camera;
use crate::tiles::{Tile, TileCache, TileKey};
use crate::world::World;
use crossbeam_channel::{Receiver, Sender};
use rustc_hash::{FxHashMap, FxHashSet};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;

/// Where a phase runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PhaseKind {
    Cpu,
    Gpu,
}

/// One step of preparing a node.
#[derive(Clone, Copy)]
pub struct Phase {
    pub name: &'static str,
    pub kind: PhaseKind,
    pub run: fn(&Shared, &mut NodeWork),
}

impl std::fmt::Debug for Phase {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} ({:?})", self.name, self.kind)
    }
}

/// Everything phases may read, shared by all threads.
#[derive(Debug)]
pub struct Shared {
    pub world: World,
    pub tree: QuadTree,
    pub bounds: BoundsStore,
    pub tiles: Mutex<TileCache>,
    /// Vegetation placement (built once from the map).
    pub placer: crate::vegetation::Placer,
    /// How much vegetation blocks lines of sight.
    pub canopy: crate::vegetation::Canopy,
}

/// Node bounds known so far, shared by selection (reads) and jobs (writes).
#[derive(Debug, Default)]
pub struct BoundsStore {
    map: Mutex<FxHashMap<NodeKey, NodeBounds>>,
}

impl BoundsStore {
    pub fn peek(&self, key: NodeKey) -> Option<NodeBounds> {
        self.map
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .get(&key)
            .copied()
    }

    /// The node's bounds, measured outside the lock when unknown (after its parent's).
    pub fn get(&self, world: &World, tree: &QuadTree, key: NodeKey) -> NodeBounds {
        if let Some(b) = self.peek(key) {
            return b;
        }
        let parent = key.parent().map(|p| self.get(world, tree, p));
        let b = bounds::monotone(bounds::measure(world, tree, key), parent);
        self.map
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .insert(key, b);
        b
    }

    pub fn len(&self) -> usize {
        self.map
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A node's content while it is being prepared, and once prepared.
#[derive(Debug, Default)]
pub struct NodeWork {
    pub key: Option<NodeKey>,
    pub bounds: Option<NodeBounds>,
    /// Tiles held by this job (released when the job ends, finished or cancelled).
    pub tiles: Vec<(TileKey, Arc<Tile>)>,
    pub terrain: Option<NodeMesh>,
    /// The node's vegetation instances (grouped for drawing).
    pub vegetation: Option<crate::vegetation::NodeVegetation>,
    /// Set by the GPU upload phase: bytes that went to the GPU.
    pub uploaded_bytes: usize,
    /// The node's GPU objects, set by the renderer's upload hook, dropped with the node.
    pub gpu: GpuSlot,
}

/// GPU objects of one node, of a type only the renderer knows (this module stays free of wgpu).
#[derive(Default)]
pub struct GpuSlot(pub Option<Box<dyn std::any::Any + Send + Sync>>);

impl std::fmt::Debug for GpuSlot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.0.is_some() {
            "GpuSlot(set)"
        } else {
            "GpuSlot(empty)"
        })
    }
}

impl GpuSlot {
    /// The stored object if it is a `T`.
    pub fn get<T: 'static>(&self) -> Option<&T> {
        self.0.as_ref().and_then(|b| b.downcast_ref::<T>())
    }
}

impl NodeWork {
    fn key(&self) -> NodeKey {
        self.key.unwrap_or(NodeKey::ROOT)
    }

    /// Bytes this node keeps resident (CPU copy of its GPU data).
    pub fn bytes(&self) -> usize {
        self.terrain.as_ref().map_or(0, NodeMesh::gpu_bytes)
            + self
                .vegetation
                .as_ref()
                .map_or(0, crate::vegetation::NodeVegetation::gpu_bytes)
    }
}

fn phase_bounds(s: &Shared, w: &mut NodeWork) {
    w.bounds = Some(s.bounds.get(&s.world, &s.tree, w.key()));
}

fn phase_tiles(s: &Shared, w: &mut NodeWork) {
    let Some(tk) = mesh::source_tile(&s.world, &s.tree, w.key()) else {
        return;
    };
    let resident = s
        .tiles
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .try_acquire(tk);
    // Generate outside the lock; if another job made it meanwhile, theirs is kept.
    let tile = resident.unwrap_or_else(|| {
        let t = Arc::new(Tile::generate(&s.world, tk));
        s.tiles
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .insert_acquired(t)
    });
    w.tiles.push((tk, tile));
}

fn phase_terrain_mesh(s: &Shared, w: &mut NodeWork) {
    let key = w.key();
    let tile = w.tiles.first().map(|(_, t)| Arc::clone(t));
    // Skirt depths need the bounds of coarser neighbours: measured (and stored) on demand.
    let mesh = mesh::build(
        &s.world,
        &s.tree,
        &mut |k| s.bounds.get(&s.world, &s.tree, k),
        key,
        tile.as_deref(),
    );
    w.terrain = Some(mesh);
}

fn phase_vegetation(s: &Shared, w: &mut NodeWork) {
    w.vegetation = Some(crate::vegetation::node_vegetation(
        &s.world,
        &s.placer,
        &s.tree,
        w.key(),
    ));
}

fn phase_release_tiles(s: &Shared, w: &mut NodeWork) {
    release_tiles(s, w);
}

fn release_tiles(s: &Shared, w: &mut NodeWork) {
    if w.tiles.is_empty() {
        return;
    }
    let mut tiles = s.tiles.lock().unwrap_or_else(PoisonError::into_inner);
    for (k, _) in w.tiles.drain(..) {
        tiles.release(k);
    }
}

fn phase_upload(_s: &Shared, w: &mut NodeWork) {
    // The renderer replaces this phase with a real upload; headless, it only accounts bytes.
    w.uploaded_bytes = w.bytes();
}

/// The node pipeline: bounds -> tiles -> terrain mesh -> vegetation -> release tiles -> GPU
/// upload.
pub fn terrain_phases() -> Vec<Phase> {
    vec![
        Phase {
            name: "bounds",
            kind: PhaseKind::Cpu,
            run: phase_bounds,
        },
        Phase {
            name: "tiles",
            kind: PhaseKind::Cpu,
            run: phase_tiles,
        },
        Phase {
            name: "terrain mesh",
            kind: PhaseKind::Cpu,
            run: phase_terrain_mesh,
        },
        Phase {
            name: "vegetation",
            kind: PhaseKind::Cpu,
            run: phase_vegetation,
        },
        Phase {
            name: "release tiles",
            kind: PhaseKind::Cpu,
            run: phase_release_tiles,
        },
        Phase {
            name: "gpu upload",
            kind: PhaseKind::Gpu,
            run: phase_upload,
        },
    ]
}

/// Streaming settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamSettings {
    /// Split less where vegetation blocks the view (see `vegetation::Canopy`).
    pub vegetation_occlusion: bool,
    /// Worker threads (at least 1).
    pub workers: usize,
    /// Most jobs handed to workers at once (queued there or running).
    pub max_in_flight: usize,
    /// Memory budget for prepared nodes kept resident (bytes).
    pub cache_budget_bytes: usize,
    /// GPU phases per frame: time and bytes budgets (at least one phase runs per frame).
    pub gpu_budget_s: f64,
    pub gpu_budget_bytes: usize,
    /// Cross-fade duration.
    pub fade_s: f64,
    /// The user's detail level: largest projected error (px) to show.
    pub tau_px: f64,
    /// Nodes are split for display when their error passes `split_factor * tau`, so a fade
    /// finishes before the error reaches tau.
    pub split_factor: f64,
    /// Nodes down to `prefetch_factor * tau` are prepared ahead (lower priority, not shown
    /// until needed), so they are ready when the camera gets there.
    pub prefetch_factor: f64,
    /// Debug: show every node at this level (no pixel-error test), like seed 003's MLFIX.
    pub fixed_level: Option<u8>,
}

impl Default for StreamSettings {
    fn default() -> Self {
        let cores = std::thread::available_parallelism().map_or(2, std::num::NonZeroUsize::get);
        Self {
            workers: (cores - 1).max(1),
            // A shallow hand-off: jobs handed to workers run in FIFO order, so a deep backlog
            // would make urgent display jobs wait behind prefetch.
            max_in_flight: (cores - 1).max(1) + 1,
            cache_budget_bytes: 512 << 20,
            gpu_budget_s: 0.004,
            gpu_budget_bytes: 32 << 20,
            fade_s: 0.2,
            tau_px: 2.0,
            split_factor: 0.6,
            prefetch_factor: 0.5,
            fixed_level: None,
            vegetation_occlusion: false,
        }
    }
}

/// What a worker sends back.
enum JobResult {
    /// CPU phases done; the next phase index (a GPU phase) or `phases.len()` when complete.
    Done {
        key: NodeKey,
        generation: u64,
        work: Box<NodeWork>,
        next_phase: usize,
    },
    Cancelled,
}

struct JobMsg {
    key: NodeKey,
    generation: u64,
    cancel: Arc<AtomicBool>,
    start_phase: usize,
    work: Box<NodeWork>,
}

/// A request's state on the owner thread.
enum RequestState {
    Queued,
    Running {
        cancel: Arc<AtomicBool>,
    },
    WaitingGpu {
        work: Box<NodeWork>,
        next_phase: usize,
    },
}

struct Request {
    generation: u64,
    state: RequestState,
    requested_at: Instant,
    /// 0: needed for display; 1: prefetch.
    class: usize,
}

/// A prepared node.
#[derive(Debug)]
pub struct Resident {
    pub work: NodeWork,
    pub last_used_frame: u64,
}

/// One node to draw this frame, with its dither interval (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DrawNode {
    pub key: NodeKey,
    pub dither_lo: f32,
    pub dither_hi: f32,
}

/// Counters and per-frame statistics.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StreamStats {
    pub requested: u64,
    pub completed: u64,
    pub cancelled_queued: u64,
    pub cancelled_running: u64,
    pub cancelled_gpu: u64,
    pub late_results_discarded: u64,
    /// Running jobs that stopped at a phase boundary after being cancelled.
    pub cancels_acknowledged: u64,
    pub evicted: u64,
    pub queued: usize,
    pub running: usize,
    pub waiting_gpu: usize,
    pub resident: usize,
    pub resident_bytes: usize,
    /// Bytes of resident nodes that cannot be evicted now (needed, drawn or fading).
    pub pinned_bytes: usize,
    pub wanted: usize,
    pub drawn: usize,
    /// Request-to-ready latencies (s) of jobs completed since the last `take_latencies`.
    pub latencies_s: Vec<f64>,
    /// Time of the last update's two selections (display and prefetch sets).
    pub last_selection_s: f64,
}

/// The streaming system. Owned by one thread (the render thread); workers run CPU phases.
pub struct Streamer {
    pub shared: Arc<Shared>,
    pub settings: StreamSettings,
    phases: Arc<Vec<Phase>>,
    to_workers: Option<Sender<JobMsg>>,
    from_workers: Receiver<JobResult>,
    workers: Vec<std::thread::JoinHandle<()>>,
    requests: FxHashMap<NodeKey, Request>,
    /// Pending (queued) requests per priority class (display, prefetch) and level.
    buckets: [Vec<Vec<NodeKey>>; 2],
    next_generation: u64,
    resident: FxHashMap<NodeKey, Resident>,
    wanted: FxHashSet<NodeKey>,
    /// Nodes needed for display (wanted, ancestors, children of ancestors) and for prefetch.
    needed: FxHashSet<NodeKey>,
    /// Ancestors of wanted nodes: the nodes that are to be replaced by their children.
    to_split: FxHashSet<NodeKey>,
    prefetch: FxHashSet<NodeKey>,
    /// This frame's draw list, computed once after the fades advance.
    drawn: Vec<DrawNode>,
    /// Split state per node: 0 = the node is drawn, 1 = its children are; in between, fading.
    split: FxHashMap<NodeKey, f32>,
    frame: u64,
    camera: Option<Camera>,
    pub stats: StreamStats,
}

impl std::fmt::Debug for Streamer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Streamer")
            .field("settings", &self.settings)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

fn worker_loop(shared: &Shared, phases: &[Phase], rx: &Receiver<JobMsg>, tx: &Sender<JobResult>) {
    while let Ok(mut job) = rx.recv() {
        let mut i = job.start_phase;
        let mut cancelled = false;
        while i < phases.len() && phases[i].kind == PhaseKind::Cpu {
            if job.cancel.load(Ordering::Acquire) {
                cancelled = true;
                break;
            }
            (phases[i].run)(shared, &mut job.work);
            i += 1;
        }
        let msg = if cancelled {
            release_tiles(shared, &mut job.work);
            JobResult::Cancelled
        } else {
            JobResult::Done {
                key: job.key,
                generation: job.generation,
                work: job.work,
                next_phase: i,
            }
        };
        if tx.send(msg).is_err() {
            break;
        }
    }
}

impl Streamer {
    pub fn new(world: World, settings: StreamSettings, phases: Vec<Phase>) -> Self {
        let tree = QuadTree::new(world.origin_m(), world.size_m());
        let placer = crate::vegetation::Placer::new(&world);
        let canopy = crate::vegetation::Canopy::new(&world, &placer);
        let shared = Arc::new(Shared {
            canopy,
            world,
            tree,
            bounds: BoundsStore::default(),
            tiles: Mutex::new(TileCache::new()),
            placer,
        });
        let phases = Arc::new(phases);
        let (to_workers, rx) = crossbeam_channel::unbounded::<JobMsg>();
        let (tx, from_workers) = crossbeam_channel::unbounded::<JobResult>();
        let workers = (0..settings.workers.max(1))
            .map(|i| {
                let (s, p, r, t) = (
                    Arc::clone(&shared),
                    Arc::clone(&phases),
                    rx.clone(),
                    tx.clone(),
                );
                std::thread::Builder::new()
                    .name(format!("node-worker-{i}"))
                    .spawn(move || worker_loop(&s, &p, &r, &t))
                    .map_err(|e| log::error!("cannot start worker thread: {e}"))
                    .ok()
            })
            .collect::<Vec<_>>()
            .into_iter()
            .flatten()
            .collect();
        let levels = usize::from(tree.max_level) + 1;
        Self {
            shared,
            settings,
            phases,
            to_workers: Some(to_workers),
            from_workers,
            workers,
            requests: FxHashMap::default(),
            buckets: [vec![Vec::new(); levels], vec![Vec::new(); levels]],
            next_generation: 1,
            resident: FxHashMap::default(),
            wanted: FxHashSet::default(),
            needed: FxHashSet::default(),
            to_split: FxHashSet::default(),
            prefetch: FxHashSet::default(),
            split: FxHashMap::default(),
            drawn: Vec::new(),
            frame: 0,
            camera: None,
            stats: StreamStats::default(),
        }
    }

    pub fn tree(&self) -> &QuadTree {
        &self.shared.tree
    }

    pub fn resident(&self, key: NodeKey) -> Option<&Resident> {
        self.resident.get(&key)
    }

    pub fn is_ready(&self, key: NodeKey) -> bool {
        self.resident.contains_key(&key)
    }

    pub fn wanted(&self) -> &FxHashSet<NodeKey> {
        &self.wanted
    }

    pub fn in_flight(&self) -> usize {
        self.requests.len()
    }

    /// The wanted set for a camera at threshold `tau_px`, using only bounds already known (see
    /// the module docs).
    pub fn select_wanted(&self, cam: &Camera, tau_px: f64) -> FxHashSet<NodeKey> {
        let sel = crate::select::traverse(
            &self.shared.tree,
            cam,
            true,
            |key| self.shared.bounds.peek(key),
            |key: NodeKey, b: &NodeBounds, dist, px| match self.settings.fixed_level {
                Some(level) => key.level < level,
                None if self.settings.vegetation_occlusion && px > tau_px => {
                    let s = &self.shared;
                    px * s.canopy.error_factor(
                        &s.world,
                        cam.position_m,
                        s.tree.rect(key),
                        b.z_max_m,
                        dist,
                    ) > tau_px
                }
                None => px > tau_px,
            },
        );
        sel.nodes
            .iter()
            .map(|n| n.key)
            .chain(sel.unknown_bounds)
            .collect()
    }

    /// Every ancestor of the nodes in `wanted`.
    fn ancestors_of(wanted: &FxHashSet<NodeKey>) -> FxHashSet<NodeKey> {
        let mut ancestors = FxHashSet::default();
        for &k in wanted {
            let mut a = k.parent();
            while let Some(n) = a {
                if !ancestors.insert(n) {
                    break;
                }
                a = n.parent();
            }
        }
        ancestors
    }

    /// The nodes needed to show `wanted` given its `ancestors`: the wanted nodes, the ancestors,
    /// and every child of an ancestor (a node is only replaced by all four children, so the
    /// drawn set always covers the whole map, culled parts included).
    fn needed_for(
        &self,
        wanted: &FxHashSet<NodeKey>,
        ancestors: &FxHashSet<NodeKey>,
    ) -> FxHashSet<NodeKey> {
        let mut out: FxHashSet<NodeKey> = wanted.clone();
        for &a in ancestors {
            out.insert(a);
            out.extend(
                a.children()
                    .into_iter()
                    .filter(|c| self.shared.tree.overlaps_map(*c)),
            );
        }
        out
    }

    /// One frame: new wanted set from the camera, cancel what is no longer needed, request what
    /// is missing, collect worker results, dispatch jobs by priority, advance fades.
    pub fn update(&mut self, cam: &Camera, dt_s: f64) {
        self.frame += 1;
        self.camera = Some(*cam);
        self.collect_results();
        let tau = self.settings.tau_px;
        let t_select = Instant::now();
        self.wanted = self.select_wanted(cam, tau * self.settings.split_factor);
        // Everything on the path from the root to a wanted node is needed too (ancestors are
        // what is shown until the wanted nodes are ready).
        self.to_split = Self::ancestors_of(&self.wanted);
        self.needed = self.needed_for(&self.wanted, &self.to_split);
        let prefetch_wanted = self.select_wanted(cam, tau * self.settings.prefetch_factor);
        self.stats.last_selection_s = t_select.elapsed().as_secs_f64();
        let prefetch_ancestors = Self::ancestors_of(&prefetch_wanted);
        self.prefetch = self.needed_for(&prefetch_wanted, &prefetch_ancestors);
        self.prefetch.retain(|k| !self.needed.contains(k));
        // Cancel requests no longer needed or prefetched.
        let stale: Vec<NodeKey> = self
            .requests
            .keys()
            .filter(|k| !self.needed.contains(k) && !self.prefetch.contains(k))
            .copied()
            .collect();
        for k in stale {
            self.cancel(k);
        }
        // Request what is missing: display first, then prefetch; promote prefetch requests that
        // became needed for display.
        for class in 0..2 {
            let set = if class == 0 {
                &self.needed
            } else {
                &self.prefetch
            };
            let mut missing: Vec<NodeKey> = set
                .iter()
                .filter(|k| !self.resident.contains_key(k))
                .copied()
                .collect();
            missing.sort_unstable();
            for k in missing {
                match self.requests.get_mut(&k) {
                    None => self.request(k, class),
                    Some(r) if r.class > class => {
                        r.class = class;
                        if matches!(r.state, RequestState::Queued) {
                            let level = usize::from(k.level);
                            self.buckets[1][level].retain(|&q| q != k);
                            self.buckets[class][level].push(k);
                        }
                    }
                    Some(_) => {}
                }
            }
        }
        let frame = self.frame;
        for k in self.needed.iter().chain(&self.prefetch) {
            if let Some(r) = self.resident.get_mut(k) {
                r.last_used_frame = frame;
            }
        }
        self.dispatch();
        self.advance_fades(dt_s);
        self.drawn = self.compute_draw_list();
        self.evict();
        self.refresh_stats();
    }

    fn request(&mut self, key: NodeKey, class: usize) {
        let generation = self.next_generation;
        self.next_generation += 1;
        let state = RequestState::Queued;
        self.requests.insert(
            key,
            Request {
                generation,
                state,
                requested_at: Instant::now(),
                class,
            },
        );
        self.buckets[class][usize::from(key.level)].push(key);
        self.stats.requested += 1;
    }

    fn cancel(&mut self, key: NodeKey) {
        let Some(req) = self.requests.remove(&key) else {
            return;
        };
        match req.state {
            RequestState::Queued => {
                self.buckets[req.class][usize::from(key.level)].retain(|&k| k != key);
                self.stats.cancelled_queued += 1;
            }
            RequestState::Running { cancel } => {
                cancel.store(true, Ordering::Release);
                self.stats.cancelled_running += 1;
            }
            RequestState::WaitingGpu { mut work, .. } => {
                release_tiles(&self.shared, &mut work);
                self.stats.cancelled_gpu += 1;
            }
        }
    }

    /// Hands queued jobs to workers: coarsest level first, then nearest to the camera.
    fn dispatch(&mut self) {
        let running = self
            .requests
            .values()
            .filter(|r| matches!(r.state, RequestState::Running { .. }))
            .count();
        let mut free = self.settings.max_in_flight.saturating_sub(running);
        let cam_pos = self.camera.map(|c| c.position_m);
        let tree = self.shared.tree;
        let levels = self.buckets[0].len();
        for (class, level) in (0..2).flat_map(|c| (0..levels).map(move |l| (c, l))) {
            while free > 0 && !self.buckets[class][level].is_empty() {
                let bucket = &mut self.buckets[class][level];
                let idx = match cam_pos {
                    Some(p) => {
                        let dist = |k: &NodeKey| {
                            let r = tree.rect(*k);
                            let c = glam::DVec3::new(
                                (r.min[0] + r.max[0]) * 0.5,
                                (r.min[1] + r.max[1]) * 0.5,
                                p.z,
                            );
                            (c - p).length_squared()
                        };
                        (0..bucket.len())
                            .min_by(|&a, &b| {
                                dist(&bucket[a])
                                    .total_cmp(&dist(&bucket[b]))
                                    .then(bucket[a].cmp(&bucket[b]))
                            })
                            .unwrap_or(0)
                    }
                    None => 0,
                };
                let key = bucket.swap_remove(idx);
                let Some(req) = self.requests.get_mut(&key) else {
                    continue;
                };
                let cancel = Arc::new(AtomicBool::new(false));
                let msg = JobMsg {
                    key,
                    generation: req.generation,
                    cancel: Arc::clone(&cancel),
                    start_phase: 0,
                    work: Box::new(NodeWork {
                        key: Some(key),
                        ..NodeWork::default()
                    }),
                };
                req.state = RequestState::Running { cancel };
                if let Some(tx) = &self.to_workers
                    && tx.send(msg).is_err()
                {
                    log::error!("node workers have stopped");
                }
                free -= 1;
            }
        }
    }

    fn collect_results(&mut self) {
        while let Ok(res) = self.from_workers.try_recv() {
            match res {
                JobResult::Cancelled => self.stats.cancels_acknowledged += 1,
                JobResult::Done {
                    key,
                    generation,
                    mut work,
                    next_phase,
                } => {
                    let current = self
                        .requests
                        .get(&key)
                        .is_some_and(|r| r.generation == generation);
                    if !current {
                        // A cancelled (or superseded) job's late result: never shown.
                        release_tiles(&self.shared, &mut work);
                        self.stats.late_results_discarded += 1;
                        continue;
                    }
                    if next_phase < self.phases.len() {
                        if let Some(r) = self.requests.get_mut(&key) {
                            r.state = RequestState::WaitingGpu { work, next_phase };
                        }
                    } else {
                        self.finish(key, *work);
                    }
                }
            }
        }
    }

    fn finish(&mut self, key: NodeKey, work: NodeWork) {
        if let Some(req) = self.requests.remove(&key) {
            self.stats
                .latencies_s
                .push(req.requested_at.elapsed().as_secs_f64());
        }
        self.stats.completed += 1;
        self.resident.insert(
            key,
            Resident {
                work,
                last_used_frame: self.frame,
            },
        );
    }

    /// Runs waiting GPU phases (coarsest, then oldest first) until the frame's time or byte
    /// budget is spent; at least one per call. Returns the number of phases run.
    pub fn run_gpu_phases(&mut self) -> usize {
        self.run_gpu_phases_with(&mut |_, _| {})
    }

    /// [`Self::run_gpu_phases`] where each GPU phase also calls `upload` (the renderer creates
    /// the node's buffers there and stores them in [`NodeWork::gpu`]).
    pub fn run_gpu_phases_with(&mut self, upload: &mut dyn FnMut(&Shared, &mut NodeWork)) -> usize {
        let t0 = Instant::now();
        let mut bytes = 0usize;
        let mut order: Vec<(u8, u64, NodeKey)> = self
            .requests
            .iter()
            .filter(|(_, r)| matches!(r.state, RequestState::WaitingGpu { .. }))
            .map(|(k, r)| (k.level, r.generation, *k))
            .collect();
        order.sort_unstable();
        let mut ran = 0;
        for (_, _, key) in order {
            if ran > 0
                && (t0.elapsed().as_secs_f64() >= self.settings.gpu_budget_s
                    || bytes >= self.settings.gpu_budget_bytes)
            {
                break;
            }
            let Some(req) = self.requests.get_mut(&key) else {
                continue;
            };
            let RequestState::WaitingGpu { work, next_phase } = &mut req.state else {
                continue;
            };
            let mut w = std::mem::take(work);
            let mut i = *next_phase;
            while i < self.phases.len() && self.phases[i].kind == PhaseKind::Gpu {
                (self.phases[i].run)(&self.shared, &mut w);
                upload(&self.shared, &mut w);
                i += 1;
            }
            bytes += w.uploaded_bytes;
            ran += 1;
            if i >= self.phases.len() {
                self.finish(key, *w);
            } else {
                // More CPU phases follow: back to a worker.
                let cancel = Arc::new(AtomicBool::new(false));
                let generation = req.generation;
                req.state = RequestState::Running {
                    cancel: Arc::clone(&cancel),
                };
                if let Some(tx) = &self.to_workers {
                    let _ = tx.send(JobMsg {
                        key,
                        generation,
                        cancel,
                        start_phase: i,
                        work: w,
                    });
                }
            }
        }
        // Finished nodes change the draw list only when the root first becomes ready (splits
        // wait for fades, which advance in `update`).
        if self.drawn.is_empty() && self.resident.contains_key(&NodeKey::ROOT) {
            self.drawn = self.compute_draw_list();
        }
        // Finished nodes add bytes: keep the cache within its budget here too, not only in
        // `update` (otherwise the budget holds only until the next GPU phase).
        if ran > 0 {
            self.evict();
        }
        self.refresh_stats();
        ran
    }

    /// Moves every node's split state towards its target: split when it is an ancestor of
    /// wanted nodes and all its children are ready, merged otherwise (a node merges only once
    /// its children have merged).
    fn advance_fades(&mut self, dt_s: f64) {
        let step = if self.settings.fade_s > 0.0 {
            (dt_s / self.settings.fade_s) as f32
        } else {
            1.0
        };
        let mut stack = vec![NodeKey::ROOT];
        let mut seen: FxHashSet<NodeKey> = FxHashSet::default();
        while let Some(key) = stack.pop() {
            if !self.resident.contains_key(&key) {
                continue;
            }
            seen.insert(key);
            let wants_split = self.to_split.contains(&key) && self.children_drawable(key);
            let s = self.split.get(&key).copied().unwrap_or(0.0);
            // A node may only merge back once its children are no longer split themselves.
            let children_merged = key
                .children()
                .iter()
                .all(|c| self.split.get(c).copied().unwrap_or(0.0) == 0.0);
            let target = if wants_split || !children_merged {
                1.0
            } else {
                0.0
            };
            // Step towards the target (and stay there once reached).
            let ns = if target > s {
                (s + step).min(target)
            } else {
                (s - step).max(target)
            };
            // Children must be resident to show them at all.
            let ns = if ns > 0.0 && !self.children_drawable(key) {
                0.0
            } else {
                ns
            };
            if ns > 0.0 {
                self.split.insert(key, ns);
                stack.extend(key.children());
            } else {
                self.split.remove(&key);
            }
        }
        self.split.retain(|k, _| seen.contains(k));
    }

    fn children_drawable(&self, key: NodeKey) -> bool {
        key.level < self.shared.tree.max_level
            && key
                .children()
                .iter()
                .all(|c| !self.shared.tree.overlaps_map(*c) || self.resident.contains_key(c))
    }

    /// The nodes to draw and their dither intervals. Nothing is missing: the root (once ready)
    /// covers everything not covered by ready descendants.
    pub fn draw_list(&self) -> &[DrawNode] {
        &self.drawn
    }

    /// Walks the resident tree from the root, giving children the lower part of their parent's
    /// dither interval in proportion to its split state.
    fn compute_draw_list(&self) -> Vec<DrawNode> {
        let mut out = Vec::new();
        if !self.resident.contains_key(&NodeKey::ROOT) {
            return out;
        }
        let mut stack = vec![(NodeKey::ROOT, 0.0f32, 1.0f32)];
        while let Some((key, lo, hi)) = stack.pop() {
            if !self.shared.tree.overlaps_map(key) || !self.resident.contains_key(&key) {
                continue;
            }
            let s = self.split.get(&key).copied().unwrap_or(0.0);
            if s <= 0.0 {
                out.push(DrawNode {
                    key,
                    dither_lo: lo,
                    dither_hi: hi,
                });
                continue;
            }
            // Children take [lo, lo + s (hi - lo)); the node keeps the rest.
            let mid = lo + s * (hi - lo);
            if mid < hi {
                out.push(DrawNode {
                    key,
                    dither_lo: mid,
                    dither_hi: hi,
                });
            }
            for c in key.children() {
                stack.push((c, lo, mid));
            }
        }
        out
    }

    /// Resident nodes that must stay: needed, prefetched, drawn, or in a fade.
    fn pinned(&self) -> FxHashSet<NodeKey> {
        let mut p = self.needed.clone();
        p.extend(self.prefetch.iter().copied());
        p.extend(self.drawn.iter().map(|d| d.key));
        p.extend(self.split.keys().copied());
        p
    }

    /// Drops the least recently used prepared nodes that are not pinned while over the memory
    /// budget. Pinned nodes alone may exceed it; then nothing else is kept.
    fn evict(&mut self) {
        let mut bytes: usize = self.resident.values().map(|r| r.work.bytes()).sum();
        if bytes <= self.settings.cache_budget_bytes {
            return;
        }
        let pinned = self.pinned();
        let mut candidates: Vec<(u64, NodeKey)> = self
            .resident
            .iter()
            .filter(|(k, _)| !pinned.contains(k))
            .map(|(k, r)| (r.last_used_frame, *k))
            .collect();
        candidates.sort_unstable();
        for (_, k) in candidates {
            if bytes <= self.settings.cache_budget_bytes {
                break;
            }
            if let Some(r) = self.resident.remove(&k) {
                bytes -= r.work.bytes();
                self.stats.evicted += 1;
            }
        }
    }

    fn refresh_stats(&mut self) {
        let (mut q, mut r, mut g) = (0, 0, 0);
        for req in self.requests.values() {
            match req.state {
                RequestState::Queued => q += 1,
                RequestState::Running { .. } => r += 1,
                RequestState::WaitingGpu { .. } => g += 1,
            }
        }
        self.stats.queued = q;
        self.stats.running = r;
        self.stats.waiting_gpu = g;
        self.stats.resident = self.resident.len();
        self.stats.resident_bytes = self.resident.values().map(|r| r.work.bytes()).sum();
        let pinned = self.pinned();
        self.stats.pinned_bytes = self
            .resident
            .iter()
            .filter(|(k, _)| pinned.contains(k))
            .map(|(_, r)| r.work.bytes())
            .sum();
        self.stats.wanted = self.wanted.len();
        self.stats.drawn = self.drawn.len();
    }

    /// Takes the request-to-ready latencies recorded since the last call.
    pub fn take_latencies(&mut self) -> Vec<f64> {
        std::mem::take(&mut self.stats.latencies_s)
    }

    /// Keys of all resident nodes.
    pub fn resident_keys(&self) -> Vec<NodeKey> {
        let mut v: Vec<NodeKey> = self.resident.keys().copied().collect();
        v.sort_unstable();
        v
    }

    /// Waits (up to `timeout_s`) until no job is queued, running or waiting for the GPU, every
    /// needed node is resident and no fade is in progress, running GPU phases as they arrive.
    /// Returns false on timeout.
    pub fn settle(&mut self, cam: &Camera, timeout_s: f64) -> bool {
        let t0 = Instant::now();
        loop {
            self.update(cam, 1.0 / 60.0);
            self.run_gpu_phases();
            if self.requests.is_empty()
                && self.cancelled_outstanding() == 0
                && self.needed.iter().all(|k| self.resident.contains_key(k))
                && self.split.values().all(|&v| v >= 1.0)
            {
                return true;
            }
            if t0.elapsed().as_secs_f64() > timeout_s {
                return false;
            }
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
    }

    /// Cancelled running jobs whose worker has not reported back yet (it will: with an
    /// acknowledgement at the next phase boundary, or a late result that is discarded).
    pub fn cancelled_outstanding(&self) -> u64 {
        self.stats.cancelled_running
            - self.stats.cancels_acknowledged
            - self.stats.late_results_discarded
    }

    /// Current split (fade) state of a node: 0 drawn itself, 1 replaced by its children.
    pub fn split_state(&self, key: NodeKey) -> f32 {
        self.split.get(&key).copied().unwrap_or(0.0)
    }

    /// Nodes needed for display (wanted, ancestors, and children of split ancestors).
    pub fn needed(&self) -> &FxHashSet<NodeKey> {
        &self.needed
    }

    /// Tiles currently held (by running jobs).
    pub fn tiles_resident(&self) -> usize {
        self.shared
            .tiles
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .resident()
    }
}

impl Drop for Streamer {
    fn drop(&mut self) {
        // Cancel everything, close the channel, and join the workers.
        for req in self.requests.values() {
            if let RequestState::Running { cancel } = &req.state {
                cancel.store(true, Ordering::Release);
            }
        }
        self.to_workers = None;
        for w in self.workers.drain(..) {
            let _ = w.join();
        }
    }
}
