//! Streaming: turning each frame's wanted node set into prioritized, cancellable, phased
//! background jobs, keeping prepared nodes in an LRU cache under a memory budget, and deciding
//! what is drawn (with cross-fades) so that nothing is ever missing from the screen.
//!
//! - **Content kinds are plug-ins** ([`content`]). A job runs the phases of every registered
//!   [`ContentKind`] in order, between the core phases `bounds` (first) and `release tiles` and
//!   `gpu upload` (last). CPU phases run on worker threads; GPU phases are handed back to the
//!   owner (render) thread and run there under a per-frame budget
//!   ([`Streamer::run_gpu_phases`]). New content is a new kind, not a new scheduler.
//!
//! Files: [`content`] (kinds, payloads, node work), `bounds_store` (bounds known so far),
//! `needed` (the nodes a selection needs, held as its split nodes),
//! `jobs` (requests, workers, cancellation, GPU phases), `queue` (pending jobs by priority),
//! `display` (fades and the draw list), `residency` (LRU eviction under the budget,
//! statistics), `dropper` (frees evicted nodes off the frame thread).
//! - **Priority** is time to need first ([`predict`]: needed now, then needed by the predicted
//!   camera 0.4, 1 and 2 s ahead, then the lower-tau prefetch around the camera), then larger
//!   nodes first, then nearer to the camera. Pending jobs sit in a queue shared with the
//!   workers (`queue`), one bucket per class and level; a free worker takes the best job, the
//!   distance computed at that moment, so priorities follow the camera without rebuilding a
//!   queue and workers never wait for a hand-off.
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

pub mod bounds_store;
pub mod content;
mod display;
mod dropper;
mod jobs;
mod needed;
mod pop_debt;
pub use jobs::{idle_priority, lower_priority};
pub use needed::{DisplayNodes, NeededSet};
pub mod predict;
mod queue;
mod records;
mod residency;

pub use bounds_store::BoundsStore;
pub use content::{ContentKind, GpuSlots, NodeWork, Payload, Phase, PhaseFn, PhaseKind};
pub use display::DrawNode;
pub use pop_debt::PopDebtWindow;

use crate::camera::Camera;
use crate::surface::World;
use crate::terrain::bounds::NodeBounds;
use crate::terrain::quadtree::{NodeKey, QuadTree, ancestor_set};
use crate::terrain::select::Reached;
use crate::terrain::tiles::TileCache;
use crossbeam_channel::Receiver;
use jobs::{JobResult, Request, RequestState};
use queue::JobQueue;
use rustc_hash::{FxHashMap, FxHashSet};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// The tangents of the wanted selection's frustum half-angles over the view's (see
/// [`Streamer::select_wanted`]).
pub const GUARD_BAND: f64 = 1.15;

/// Node bounds the streamer's copy has room for from the start (about 7 MiB): a flight's
/// first seconds add thousands, and growing copies them all within one frame.
const KNOWN_CAPACITY: usize = 1 << 14;

/// Everything phases may read, shared by all threads.
#[derive(Debug)]
pub struct Shared {
    /// The world, shared (not copied) with every kind that keeps it, such as the light threads.
    pub world: Arc<World>,
    pub tree: QuadTree,
    pub bounds: BoundsStore,
    pub tiles: Mutex<TileCache>,
    /// The registered content kinds, in phase order.
    pub kinds: Vec<Arc<dyn ContentKind>>,
}

impl Shared {
    /// The registered kind of type `T`.
    pub fn kind<T: ContentKind>(&self) -> Option<&T> {
        self.kinds
            .iter()
            .find_map(|k| (k.as_ref() as &dyn std::any::Any).downcast_ref::<T>())
    }
}

/// The phases of a node job: `bounds`, then every kind's CPU phases in registration order, then
/// `release tiles` and the `gpu upload` phase (whose work the owner supplies, see
/// [`Streamer::run_gpu_phases_with`]).
pub fn node_phases(kinds: &[Arc<dyn ContentKind>]) -> Vec<Phase> {
    let mut phases = vec![Phase::cpu("bounds", |s: &Shared, w: &mut NodeWork| {
        w.bounds = Some(s.bounds.get(&s.world, &s.tree, w.key));
    })];
    for k in kinds {
        phases.extend(Arc::clone(k).phases());
    }
    phases.push(Phase::cpu("release tiles", jobs::release_tiles));
    phases.push(Phase::gpu("gpu upload", |_: &Shared, w: &mut NodeWork| {
        // Headless this only accounts bytes; a renderer's upload hook replaces the figure.
        w.uploaded_bytes = w.bytes();
    }));
    phases
}

/// Streaming settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamSettings {
    /// Split less where vegetation blocks the view (see `vegetation::Canopy`).
    pub vegetation_occlusion: bool,
    /// Worker threads (at least 1).
    pub workers: usize,
    /// Memory budget for prepared nodes kept resident (bytes).
    pub cache_budget_bytes: usize,
    /// GPU phases per frame: time and bytes budgets (at least one phase runs per frame). The
    /// time is the frame thread's time in the phases plus the GPU time their recorded work is
    /// expected to take (`NodeWork::gpu_estimate_s`). The viewer raises the time budget to a
    /// quarter of the time between frames when frames are slower than that.
    pub gpu_budget_s: f64,
    pub gpu_budget_bytes: usize,
    /// Cross-fade duration.
    pub fade_s: f64,
    /// The user's detail level: largest projected error (px) to show.
    pub tau_px: f64,
    /// Nodes whose error passes `split_factor * tau` are needed split: their children are
    /// requested (first class), so they are ready before the error reaches tau.
    pub split_factor: f64,
    /// A drawn node is replaced by its children (a cross-fade) once its error passes
    /// `show_factor * tau` (at least `split_factor`); the fade speeds up to end before the
    /// error reaches tau (`display`). Between the two factors children are ready but not yet
    /// drawn, so the frame draws the triangles of a selection near tau.
    pub show_factor: f64,
    /// Nodes down to `prefetch_factor * tau` are prepared ahead (lower priority, not shown
    /// until needed), so they are ready when the camera gets there.
    pub prefetch_factor: f64,
    /// Debug: show every node at this level (no pixel-error test), like seed 003's MLFIX.
    pub fixed_level: Option<u8>,
    /// Draw grid meshes through every 2nd or 4th vertex where the ancestor meshes that shows
    /// stay within `split_factor * tau` (`terrain::select::decimation`).
    pub decimate: bool,
}

impl StreamSettings {
    /// These settings with `workers` worker threads.
    #[must_use]
    pub fn with_workers(mut self, workers: usize) -> Self {
        self.workers = workers.max(1);
        self
    }
}

impl Default for StreamSettings {
    fn default() -> Self {
        let cores = std::thread::available_parallelism().map_or(2, std::num::NonZeroUsize::get);
        Self {
            workers: (cores - 1).max(1),
            cache_budget_bytes: 512 << 20,
            gpu_budget_s: 0.004,
            gpu_budget_bytes: 32 << 20,
            fade_s: 0.2,
            tau_px: 2.0,
            split_factor: 0.6,
            show_factor: 0.8,
            prefetch_factor: 0.5,
            fixed_level: None,
            vegetation_occlusion: false,
            decimate: true,
        }
    }
}

/// A prepared node.
#[derive(Debug)]
pub struct Resident {
    /// Boxed: the resident map moves only pointers when it grows.
    pub work: Box<NodeWork>,
    /// The last frame that needed, prefetched, drew or faded the node (held nodes are marked
    /// in the frames that evict), or the frame it became resident.
    pub last_used_frame: u64,
    /// The frame it became resident.
    pub ready_frame: u64,
    /// `work.bytes()`, taken when the node became resident (payloads do not change after),
    /// plus what renderers made for it later ([`Streamer::charge`]).
    pub bytes: usize,
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
    /// Updates that left their cancels and requests to the next update because a worker held
    /// the job queue (the frame thread never waits on a worker).
    pub requests_deferred: u64,
    pub evicted: u64,
    pub queued: usize,
    pub running: usize,
    pub waiting_gpu: usize,
    pub resident: usize,
    pub resident_bytes: usize,
    pub wanted: usize,
    pub drawn: usize,
    /// Latencies of the jobs completed since the last `take_latencies` (at most
    /// [`MAX_LATENCIES_KEPT`]: the oldest half goes when it is full, so a viewer that never
    /// reads them does not grow).
    pub latencies: Vec<JobLatency>,
    /// Where the last update's time went.
    pub last_update: UpdateStages,
}

/// The parts of one [`Streamer::update_along`], in seconds of wall-clock time, in order.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct UpdateStages {
    /// The content kinds' camera and draw-list hooks.
    pub kinds_s: f64,
    /// Taking the workers' results (finished nodes become resident) and the bounds they
    /// measured.
    pub results_s: f64,
    /// The display selection, its ancestors and the needed set.
    pub selection_s: f64,
    /// The prefetch selections along the predicted path and their classes.
    pub prefetch_s: f64,
    /// Cancelling stale requests, making and promoting requests.
    pub requests_s: f64,
    /// Advancing the fades and making the draw list.
    pub display_s: f64,
    /// Eviction under the cache budget and the statistics.
    pub residency_s: f64,
}

impl UpdateStages {
    /// Names of the stages, in the order of [`Self::seconds`].
    pub const NAMES: [&'static str; 7] = [
        "kinds' hooks",
        "worker results",
        "display selection",
        "prefetch selections",
        "requests",
        "fades and draw list",
        "eviction and statistics",
    ];

    /// The time of the update's selections (the display set and the prefetch parts).
    pub fn selections_s(&self) -> f64 {
        self.selection_s + self.prefetch_s
    }

    /// The stages' times, in the order of [`Self::NAMES`].
    pub fn seconds(&self) -> [f64; 7] {
        [
            self.kinds_s,
            self.results_s,
            self.selection_s,
            self.prefetch_s,
            self.requests_s,
            self.display_s,
            self.residency_s,
        ]
    }
}

/// Most job latencies [`StreamStats::latencies`] keeps unread (about 1.5 MiB).
pub const MAX_LATENCIES_KEPT: usize = 65_536;

/// How long a completed job took.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JobLatency {
    /// From the request (for display or for prefetch) to ready (s).
    pub request_to_ready_s: f64,
    /// From the moment the node was first needed for display (requested or promoted to the
    /// display class) to ready (s); `None` for a prefetched node ready before it was needed.
    pub need_to_ready_s: Option<f64>,
    /// The frame thread's time in the node's GPU phases, the renderers' upload hooks included
    /// (s); not the deferred work those hooks leave for the end of the frame (ground textures,
    /// impostor bakes).
    pub gpu_phases_s: f64,
}

/// The streaming system. Owned by one thread (the render thread); workers run CPU phases.
pub struct Streamer {
    pub shared: Arc<Shared>,
    pub settings: StreamSettings,
    phases: Arc<Vec<Phase>>,
    /// Pending jobs per priority class (see [`predict::CLASSES`]) and level; workers take
    /// from it.
    queue: Arc<JobQueue>,
    from_workers: Receiver<JobResult>,
    workers: Vec<std::thread::JoinHandle<()>>,
    /// Frees evicted and discarded nodes off the frame thread (their GPU objects on it).
    dropper: dropper::Dropper,
    requests: FxHashMap<NodeKey, Request>,
    next_generation: u64,
    resident: FxHashMap<NodeKey, Resident>,
    /// The sum of `bytes` over `resident` (kept as nodes enter and leave).
    resident_bytes: usize,
    wanted: FxHashSet<NodeKey>,
    /// The bounds known to the selections: the store's, taken as jobs add them
    /// ([`BoundsStore::take_fresh`]), with room for a flight's first [`KNOWN_CAPACITY`] nodes.
    known: bounds_store::KnownBounds,
    /// Nodes needed for display: the ancestors of wanted nodes (the nodes to be replaced by
    /// their children, [`NeededSet::split`]) and their children.
    needed: NeededSet,
    /// The part of the needed set's split nodes drawn split: nodes over the display threshold
    /// (`show_factor * tau`) and their ancestors.
    show_split: FxHashSet<NodeKey>,
    /// The last frame's `show_split` and `wanted`, reused by the next update.
    spare_sets: [FxHashSet<NodeKey>; 2],
    /// The prefetch set's parts, each refreshed when stale (see [`predict`]); a node is
    /// prefetched when a part holds it and it is not needed now.
    prefetch_parts: Vec<predict::PrefetchPart>,
    /// The prefetch parts computed since the last update that made its requests (bit `i` for
    /// part `i`): only their nodes can be missing (see [`Self::refresh_prefetch`]).
    parts_to_request: u8,
    /// This frame's draw list, computed once after the fades advance.
    drawn: Vec<DrawNode>,
    /// Split state per node: 0 = the node is drawn, 1 = its children are; in between, fading.
    split: FxHashMap<NodeKey, f32>,
    /// Projected error (px) in the last frame of the nodes then fading to their children.
    fade_px: FxHashMap<NodeKey, f64>,
    frame: u64,
    camera: Option<Camera>,
    /// Camera velocity estimated from the last two updates (m/s).
    velocity_m_per_s: glam::DVec3,
    /// The camera's yaw rate, smoothed over the last updates (rad/s; see
    /// [`predict::extrapolate_turning`]).
    yaw_rate_rad_per_s: f64,
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

impl Streamer {
    /// A streamer for `world` preparing the content of every kind in `kinds` (in that order;
    /// see [`node_phases`]).
    pub fn new(
        world: impl Into<Arc<World>>,
        settings: StreamSettings,
        kinds: Vec<Arc<dyn ContentKind>>,
    ) -> Self {
        let phases = node_phases(&kinds);
        Self::with_phases(world, settings, kinds, phases)
    }

    /// A streamer running `phases` (normally [`node_phases`] of `kinds`; tests insert their own).
    pub fn with_phases(
        world: impl Into<Arc<World>>,
        settings: StreamSettings,
        kinds: Vec<Arc<dyn ContentKind>>,
        phases: Vec<Phase>,
    ) -> Self {
        let world: Arc<World> = world.into();
        let tree = QuadTree::new(world.origin_m(), world.size_m());
        let shared = Arc::new(Shared {
            world,
            tree,
            bounds: BoundsStore::default(),
            tiles: Mutex::new(TileCache::new()),
            kinds,
        });
        for k in &shared.kinds {
            k.attach_world(&shared.world);
        }
        let phases = Arc::new(phases);
        let levels = usize::from(tree.max_level) + 1;
        let queue = Arc::new(JobQueue::new(predict::CLASSES, levels));
        let (tx, from_workers) = crossbeam_channel::unbounded::<JobResult>();
        let workers = (0..settings.workers.max(1))
            .map(|i| {
                let (s, p, r, t) = (
                    Arc::clone(&shared),
                    Arc::clone(&phases),
                    Arc::clone(&queue),
                    tx.clone(),
                );
                std::thread::Builder::new()
                    .name(format!("node-worker-{i}"))
                    .spawn(move || jobs::worker_loop(&s, &p, &r, &t))
                    .map_err(|e| log::error!("cannot start worker thread: {e}"))
                    .ok()
            })
            .collect::<Vec<_>>()
            .into_iter()
            .flatten()
            .collect();
        Self {
            shared,
            settings,
            phases,
            queue,
            from_workers,
            workers,
            dropper: dropper::Dropper::start(),
            requests: FxHashMap::default(),
            next_generation: 1,
            resident: FxHashMap::default(),
            resident_bytes: 0,
            wanted: FxHashSet::default(),
            known: bounds_store::KnownBounds::with_capacity(KNOWN_CAPACITY),
            needed: NeededSet::empty(tree),
            show_split: FxHashSet::default(),
            spare_sets: Default::default(),
            prefetch_parts: vec![predict::PrefetchPart::default(); predict::PREFETCH_PARTS],
            parts_to_request: 0,
            split: FxHashMap::default(),
            fade_px: FxHashMap::default(),
            drawn: Vec::new(),
            frame: 0,
            camera: None,
            velocity_m_per_s: glam::DVec3::ZERO,
            yaw_rate_rad_per_s: 0.0,
            // The log's whole capacity at once: growing it in the frame thread reallocated
            // ever larger blocks there (and had glibc consolidate its free lists).
            stats: StreamStats {
                latencies: Vec::with_capacity(MAX_LATENCIES_KEPT),
                ..StreamStats::default()
            },
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

    /// Whether a job for the node is pending (queued, running or waiting for its GPU phase).
    pub fn is_requested(&self, key: NodeKey) -> bool {
        self.requests.contains_key(&key)
    }

    /// The nodes selected at the request threshold (`split_factor * tau`).
    pub fn wanted(&self) -> &FxHashSet<NodeKey> {
        &self.wanted
    }

    /// The nodes the display wants drawn: the selection at the display threshold
    /// (`show_factor * tau`), i.e. the children of nodes drawn split that are not drawn split
    /// themselves; the root alone while nothing is drawn split, and nothing while nothing is
    /// wanted (the whole map out of view).
    pub fn shown_wanted(&self) -> Vec<NodeKey> {
        if self.show_split.is_empty() {
            return if self.wanted.is_empty() {
                Vec::new()
            } else {
                vec![NodeKey::ROOT]
            };
        }
        self.show_split
            .iter()
            .flat_map(|k| k.children())
            .filter(|c| !self.show_split.contains(c) && self.shared.tree.overlaps_map(*c))
            .collect()
    }

    pub fn in_flight(&self) -> usize {
        self.requests.len()
    }

    /// The wanted set for a camera at threshold `tau_px`, using only bounds already known (see
    /// the module docs). Blocks are culled by a frustum [`GUARD_BAND`] wider than the view,
    /// so ground about to come into view (the camera turning, or passing a hill) is split
    /// before it shows, instead of appearing coarse and fading to its children on screen.
    pub fn select_wanted(&self, cam: &Camera, tau_px: f64) -> FxHashSet<NodeKey> {
        let mut wanted = FxHashSet::with_capacity_and_hasher(
            self.wanted.len() + self.wanted.len() / 4,
            rustc_hash::FxBuildHasher,
        );
        self.select(cam, tau_px, None, &mut wanted);
        wanted
    }

    /// [`Self::select_wanted`]; with `over` = (set, threshold), also puts each node split
    /// whose error (as the split test sees it) passes the threshold into the set.
    fn select(
        &self,
        cam: &Camera,
        tau_px: f64,
        mut over: Option<(&mut FxHashSet<NodeKey>, f64)>,
        wanted: &mut FxHashSet<NodeKey>,
    ) {
        // Only errors over tau are looked at (the split test, what vegetation lets through
        // of them, and the display threshold over them); without vegetation's share, none
        // over the larger of the two thresholds.
        let ceiling_px = match (self.settings.vegetation_occlusion, &over) {
            (true, _) => f64::INFINITY,
            (false, Some((_, threshold))) => threshold.max(tau_px),
            (false, None) => tau_px,
        };
        crate::terrain::select::walk(
            &self.shared.tree,
            &crate::terrain::select::ScreenBound::new(cam),
            Some(cam.frustum_widened(GUARD_BAND)),
            crate::terrain::select::PxWindow {
                floor_px: tau_px,
                ceiling_px,
            },
            &self.known,
            |key: NodeKey, b: &NodeBounds, dist, px| {
                // The error the split test compares: projected, times what vegetation lets
                // through where that is on; any split node at a fixed level.
                let seen_px = match self.settings.fixed_level {
                    Some(level) => {
                        if key.level < level {
                            f64::INFINITY
                        } else {
                            0.0
                        }
                    }
                    None if self.settings.vegetation_occlusion && px > tau_px => {
                        let s = &self.shared;
                        let rect = s.tree.rect(key);
                        let visibility: f64 = s
                            .kinds
                            .iter()
                            .map(|k| k.visibility(s, cam.position_m, rect, b.z_max_m, dist))
                            .product();
                        px * visibility
                    }
                    None => px,
                };
                let split = seen_px > tau_px;
                if split
                    && let Some((set, threshold)) = over.as_mut()
                    && seen_px > *threshold
                {
                    set.insert(key);
                }
                split
            },
            |reached| {
                wanted.insert(match reached {
                    Reached::Selected { key, .. } | Reached::Unknown(key) => key,
                });
            },
        );
    }

    /// The nodes needed to show the selection `wanted`: its ancestors and their children (see
    /// [`NeededSet`]).
    fn needed_for(&self, wanted: &FxHashSet<NodeKey>) -> NeededSet {
        NeededSet::new(
            self.shared.tree,
            ancestor_set(wanted.iter().copied()),
            !wanted.is_empty(),
        )
    }

    /// One frame: new wanted set from the camera, cancel what is no longer needed, request what
    /// is missing, collect worker results, dispatch jobs by priority, advance fades. Prefetch
    /// follows the camera's current velocity and turn (see [`predict::extrapolate_turning`]).
    pub fn update(&mut self, cam: &Camera, dt_s: f64) {
        if let Some(prev) = self.camera
            && dt_s > 0.0
        {
            self.velocity_m_per_s = (cam.position_m - prev.position_m) / dt_s;
            let measured = predict::yaw_rate_rad_per_s(&prev, cam, dt_s).unwrap_or(0.0);
            self.yaw_rate_rad_per_s =
                predict::smoothed_yaw_rate(self.yaw_rate_rad_per_s, measured, dt_s);
        }
        let future =
            predict::extrapolate_turning(cam, self.velocity_m_per_s, self.yaw_rate_rad_per_s);
        self.update_predicted(cam, dt_s, &future, predict::Guess::Extrapolated);
    }

    /// [`Self::update`] with the camera's predicted path given by the owner: `future` is
    /// (seconds ahead, camera), sorted by time, at most [`predict::PREDICT_HORIZONS_S`]'s
    /// length (e.g. the automatic flight or a replayed path at those times).
    pub fn update_along(&mut self, cam: &Camera, dt_s: f64, future: &[(f64, Camera)]) {
        self.update_predicted(cam, dt_s, future, predict::Guess::Known);
    }

    /// One update with the predicted cameras `future`, known or extrapolated (`guess`: an
    /// extrapolated future also prefetches the views to either side, see [`predict`]).
    fn update_predicted(
        &mut self,
        cam: &Camera,
        dt_s: f64,
        future: &[(f64, Camera)],
        guess: predict::Guess,
    ) {
        let mut lap = Lap::start();
        let mut stages = UpdateStages::default();
        self.frame += 1;
        self.camera = Some(*cam);
        for k in &self.shared.kinds {
            k.observe_camera(cam.position_m);
        }
        stages.kinds_s = lap.next();
        self.collect_results();
        if let Some(fresh) = self.shared.bounds.take_fresh() {
            self.known.extend(fresh);
        }
        stages.results_s = lap.next();
        let tau = self.settings.tau_px;
        // Into the last frame's sets, emptied (their tables kept: no allocation, no fresh
        // pages each frame).
        let [mut shown, mut wanted] = std::mem::take(&mut self.spare_sets).map(|mut set| {
            set.clear();
            set
        });
        let show_px = tau * self.settings.show_factor.max(self.settings.split_factor);
        self.select(
            cam,
            tau * self.settings.split_factor,
            Some((&mut shown, show_px)),
            &mut wanted,
        );
        let last_wanted = std::mem::replace(&mut self.wanted, wanted);
        // Everything on the path from the root to a wanted node is needed too (ancestors are
        // what is shown until the wanted nodes are ready).
        self.needed = self.needed_for(&self.wanted);
        // Drawn split: the nodes over the display threshold with a wanted descendant (a split
        // whose children are all culled wants none) and their ancestors.
        shown.retain(|k| self.needed.split().contains(k));
        let above = ancestor_set(shown.iter().copied());
        shown.extend(above);
        self.spare_sets = [std::mem::replace(&mut self.show_split, shown), last_wanted];
        stages.selection_s = lap.next();
        self.parts_to_request |= self.refresh_prefetch(cam, future, guess);
        stages.prefetch_s = lap.next();
        // Resident nodes needed, or in a part computed again, are marked used this frame
        // (eviction counts on the needed nodes' mark and marks the other pinned nodes itself,
        // then orders the unmarked by their last mark); the others are missing, each in its
        // class (once per part holding it: sorted, the smallest class comes first and is the
        // one requested).
        let frame = self.frame;
        let mut missing: Vec<(usize, NodeKey)> = Vec::new();
        let entries = self.needed.iter().map(|k| (0, k));
        let parts = predict::entries_of(&self.prefetch_parts, self.parts_to_request);
        for (class, k) in entries.chain(parts) {
            match self.resident.get_mut(&k) {
                Some(r) => r.last_used_frame = frame,
                None => missing.push((class, k)),
            }
        }
        // Cancel requests no longer needed or prefetched, request what is missing, promote
        // requests whose time to need came closer: all under the job queue's lock, and only
        // when no worker holds it. Otherwise the next update does it (it finds the same
        // changes, or newer ones).
        let queue = Arc::clone(&self.queue);
        if let Some(mut pending) = queue.try_lock() {
            let stale: Vec<NodeKey> = self
                .requests
                .keys()
                .filter(|k| !self.needed.contains(k) && !self.prefetched(k))
                .copied()
                .collect();
            pending.set_camera(cam.position_m);
            for k in stale {
                self.cancel(&mut pending, k);
            }
            missing.sort_unstable();
            let requested_before = self.stats.requested;
            for (class, k) in missing {
                match self.requests.get_mut(&k) {
                    None => self.request(&mut pending, k, class),
                    Some(r) if r.class > class => {
                        let old = r.class;
                        r.class = class;
                        if class == 0 {
                            r.needed_at = Some(Instant::now());
                        }
                        if matches!(r.state, RequestState::InWorkers { .. }) {
                            pending.promote(k, old, class);
                        }
                    }
                    Some(_) => {}
                }
            }
            drop(pending);
            self.parts_to_request = 0;
            // Only new jobs need a worker woken: a waiting worker found the queue empty, so a
            // promotion has nothing to offer it (a wake-up each frame would cost the frame a
            // system call and an idle worker a trip through the lock).
            if self.stats.requested > requested_before {
                self.queue.wake_workers();
            }
        } else {
            self.stats.requests_deferred += 1;
        }
        stages.requests_s = lap.next();
        self.advance_fades_and_draw(Some(dt_s));
        stages.display_s = lap.next();
        for k in &self.shared.kinds {
            k.observe_drawn(&self.drawn);
        }
        stages.kinds_s += lap.next();
        self.evict();
        self.refresh_stats();
        stages.residency_s = lap.next();
        self.stats.last_update = stages;
    }
}

/// Consecutive spans of wall-clock time.
struct Lap(Instant);

impl Lap {
    fn start() -> Self {
        Self(Instant::now())
    }

    /// Seconds since the start or the previous call.
    fn next(&mut self) -> f64 {
        let now = Instant::now();
        let s = now.duration_since(self.0).as_secs_f64();
        self.0 = now;
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    /// Every node of every prefetch part is ready or requested after each update that made its
    /// requests, although an update only looks at the parts computed since the last such
    /// update, under a cache budget small enough that eviction runs.
    #[test]
    fn every_prefetched_node_is_ready_or_requested_after_each_update() {
        let world = World::new(crate::test_maps::tiny_map());
        let [x0, y0] = world.origin_m();
        let [w, h] = world.size_m();
        let y = y0 + 0.5 * h;
        let settings = StreamSettings {
            cache_budget_bytes: 1 << 20,
            ..StreamSettings::default()
        }
        .with_workers(1);
        let terrain: Arc<dyn ContentKind> = Arc::new(crate::terrain::content::TerrainContent);
        let mut s = Streamer::new(world, settings, vec![terrain]);
        let (positions, speed_m_per_s) = (24, 100.0);
        let mut checked = 0;
        for f in 0..positions {
            // Across the map at 40 m above the ground, looking ahead and down.
            let x = x0 + 0.1 * w + 0.8 * w * f64::from(f) / f64::from(positions);
            let ground = s.shared.world.height_m(x, y);
            let cam = Camera::look_at(
                DVec3::new(x, y, ground + 40.0),
                DVec3::new(x + 200.0, y, ground),
                1.0,
                [640, 360],
            );
            let future = predict::extrapolate(&cam, DVec3::new(speed_m_per_s, 0.0, 0.0));
            // Updates at this camera until its jobs are done.
            let start = Instant::now();
            loop {
                s.update_along(&cam, 1.0 / 60.0, &future);
                s.run_gpu_phases();
                // (When a worker held the queue, the requests wait for the next update.)
                if s.parts_to_request == 0 {
                    for (_, k) in predict::entries(&s.prefetch_parts) {
                        assert!(
                            s.is_ready(k) || s.is_requested(k),
                            "position {f}: prefetched {k:?} neither ready nor requested"
                        );
                        checked += 1;
                    }
                }
                if s.in_flight() == 0 {
                    break;
                }
                assert!(
                    start.elapsed().as_secs() < 120,
                    "position {f} did not settle"
                );
                std::thread::yield_now();
            }
        }
        assert!(checked > 10_000, "only {checked} prefetched nodes checked");
        assert!(s.stats.evicted > 0, "the budget evicted nothing");
    }

    /// While a worker holds the job queue, an update does not wait for it: it leaves its
    /// requests to a later update, which makes them.
    #[test]
    fn an_update_does_not_wait_for_a_worker_holding_the_job_queue() {
        let world = World::new(crate::test_maps::tiny_map());
        let [x0, y0] = world.origin_m();
        let [w, h] = world.size_m();
        let (x, y) = (x0 + 0.5 * w, y0 + 0.5 * h);
        let ground = world.height_m(x, y);
        let cam = Camera::look_at(
            DVec3::new(x, y, ground + 50.0),
            DVec3::new(x + 100.0, y, ground),
            1.0,
            [640, 360],
        );
        let mut s = Streamer::new(world, StreamSettings::default().with_workers(1), Vec::new());
        let queue = Arc::clone(&s.queue);
        std::thread::scope(|scope| {
            // The test thread stands for a worker holding the lock while off its core.
            let held = queue.lock();
            let (done_tx, done_rx) = std::sync::mpsc::channel();
            let streamer = &mut s;
            scope.spawn(move || {
                streamer.update(&cam, 1.0 / 60.0);
                done_tx.send(()).expect("the test waits");
            });
            let done = done_rx.recv_timeout(std::time::Duration::from_mins(1));
            drop(held);
            assert!(done.is_ok(), "the update waited for the job queue's lock");
        });
        assert_eq!(s.stats.requests_deferred, 1);
        assert_eq!(
            s.in_flight(),
            0,
            "nothing requested while the queue was held"
        );
        // A later update makes the requests (the idle worker takes the lock only when woken,
        // so at most a few are deferred while it settles).
        for _ in 0..100 {
            s.update(&cam, 1.0 / 60.0);
            if s.stats.requested > 0 {
                break;
            }
        }
        assert!(s.stats.requested > 0, "no later update requested anything");
    }
}
