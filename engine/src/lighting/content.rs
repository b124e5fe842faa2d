//! Light grids as a node-content kind. Phase `light grid` (cheap): a node finer than
//! [`grid_level`] is shaded by the grid of its ancestor at that level, a node at that level or
//! coarser by its own; the phase finds that [`SharedGrid`] (or registers it) and stores it as
//! the node's [`NodeLight`]. Every node holding a grid keeps it alive; the last one evicted
//! frees it.
//!
//! **Computing** a grid takes about 0.1 - 0.3 s, a hundred times a node's other preparation, so
//! node jobs never wait for it: background threads (as many as the node workers by default), on
//! Linux under the OS's idle policy so that they never take a core from a node worker or the
//! frame thread ([`crate::stream::idle_priority`]), compute the grids that are missing or were
//! lit for another sun. Each takes next a grid that shades a node the last frame drew
//! ([`ContentKind::observe_drawn`]) or one of their coarser ancestors (it shades them until
//! theirs arrive), and among those, or when there are none, the one nearest to the camera
//! (distance to the grid's square; coarser first at equal distance: the coarse grids around the
//! camera come first). Resident nodes that are not drawn (ancestors, prefetched nodes) hold
//! nearly twice as many grids as the drawn ones. Until its grid arrives a node is shaded by its
//! nearest drawn-through ancestor's computed grid (`render::lighting`), fully lit without one;
//! [`SharedGrid::version`] tells the renderer when to upload. **Relighting** after a sun change
//! ([`LightingContent::set_sun`]) is the same work less the sky, which no sun changes
//! ([`LightGrid::relit`]): every live grid is stale, nearest first, and no frame waits for it.

use super::grid::{COLUMNS, LAYERS, LightGrid, Sun, grid_level};
use super::sky_pages::{SKY_PAGES_DIR, SkyPages};
use crate::stream::{ContentKind, NodeWork, Payload, Phase, Shared};
use crate::surface::World;
use crate::terrain::quadtree::{NodeKey, QuadTree};
use crate::vegetation::canopy::Canopy;
use glam::DVec2;
use rustc_hash::{FxHashMap, FxHashSet};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, Weak};

/// Bytes of one grid on the GPU (four bytes a sample, `render::light_pool`), counted in the
/// node-cache budget by the node that owns the grid.
pub const GRID_GPU_BYTES: usize = COLUMNS * COLUMNS * LAYERS * 4;

/// Keys kept by [`LightingContent::computed_keys`].
pub const LOG_LEN: usize = 4096;

/// One grid shared by the nodes it shades.
#[derive(Debug)]
pub struct SharedGrid {
    pub key: NodeKey,
    /// The current grid (None until the first computation is done).
    grid: Mutex<Option<Arc<LightGrid>>>,
    /// A light thread is computing it (changed under the threads' state lock).
    computing: std::sync::atomic::AtomicBool,
    /// Bumped each time a grid is stored (first computation and every relight).
    version: AtomicU64,
}

impl SharedGrid {
    /// The current grid, None before the first computation.
    pub fn grid(&self) -> Option<Arc<LightGrid>> {
        self.grid.lock().expect("grid lock").clone()
    }

    /// How many times a grid was stored: a renderer uploads again when it changes.
    pub fn version(&self) -> u64 {
        self.version.load(Ordering::Acquire)
    }

    fn store(&self, grid: LightGrid) {
        *self.grid.lock().expect("grid lock") = Some(Arc::new(grid));
        self.version.fetch_add(1, Ordering::AcqRel);
    }

    /// Whether the grid is missing or lit for another sun than `sun`.
    fn stale(&self, sun: Sun) -> bool {
        self.grid
            .lock()
            .expect("grid lock")
            .as_ref()
            .is_none_or(|g| g.sun_dir != sun)
    }
}

/// The lighting kind's payload of a node: the grid that shades it.
#[derive(Debug, Clone)]
pub struct NodeLight {
    pub grid: Arc<SharedGrid>,
    /// Whether the grid is this node's own (its bytes count here, once).
    pub owns: bool,
}

impl Payload for NodeLight {
    fn bytes(&self) -> usize {
        if self.owns { GRID_GPU_BYTES } else { 0 }
    }
}

/// The light threads' state.
#[derive(Debug, Default)]
struct ThreadState {
    started: bool,
    stop: bool,
    /// Threads computing a grid now.
    busy: usize,
    /// Nothing stale is left and no thread is computing (set by the threads, cleared by every
    /// new request).
    idle: bool,
}

/// What the light threads share with the kind.
#[derive(Debug)]
struct Inner {
    /// The streamer's world, attached when the streamer is made (see
    /// [`ContentKind::attach_world`]): shared, never copied (a copy of a 32 km world is 2.8 GB).
    world: std::sync::OnceLock<Arc<World>>,
    /// The sky pages kept in the world's derived folder, if it has one (made by the first
    /// light thread that needs them: their key hashes the whole map).
    pages: std::sync::OnceLock<Option<SkyPages>>,
    /// Where the sky pages are kept when set ([`LightingContent::keep_sky_pages_in`]), instead
    /// of the world's derived folder.
    pages_dir: std::sync::OnceLock<std::path::PathBuf>,
    tree: QuadTree,
    canopy: Arc<Canopy>,
    sun: Mutex<Sun>,
    /// The camera's x and y (m) as `f64` bits: written by the frame thread without waiting
    /// on a light thread (a torn pair between two frames only orders one pick differently).
    camera_xy_m: [AtomicU64; 2],
    /// The grids of the nodes the last frame drew, and those computed before any other. The
    /// frame thread swaps in a new set and the light threads take the current one, each
    /// holding the lock only for that: the frame never waits on a light thread (idle
    /// priority) scanning its grids.
    drawn: Mutex<Arc<DrawnGrids>>,
    grids: Mutex<FxHashMap<NodeKey, Weak<SharedGrid>>>,
    /// Per subscriber ([`LightingContent::grids_stored`]), the keys of the grids stored (first
    /// computations and relights) since it last took them; dropped subscribers are forgotten.
    stored: Mutex<Vec<Weak<Mutex<Vec<NodeKey>>>>>,
    /// The keys picked for computing, in order (the last [`LOG_LEN`]).
    log: Mutex<std::collections::VecDeque<NodeKey>>,
    state: Mutex<ThreadState>,
    /// Wakes the threads (a new grid, a new sun, a grid done).
    wake: Condvar,
    /// Wakes [`LightingContent::wait_idle`].
    idle: Condvar,
}

/// The grids the last frame's drawn nodes need ([`ContentKind::observe_drawn`]).
#[derive(Debug, Default)]
struct DrawnGrids {
    /// The grids that shade the drawn nodes ([`LightGrid::owner`]).
    owners: FxHashSet<NodeKey>,
    /// Those and their coarser ancestors' grids (which shade the drawn nodes until their own
    /// arrive): computed before any other.
    first: FxHashSet<NodeKey>,
}

impl Inner {
    /// Lists `key` for every subscriber still there (after the grid is stored).
    fn announce_stored(&self, key: NodeKey) {
        self.stored
            .lock()
            .expect("stored lock")
            .retain(|list| match list.upgrade() {
                Some(list) => {
                    list.lock().expect("stored lock").push(key);
                    true
                }
                None => false,
            });
    }

    fn sun(&self) -> Sun {
        *self.sun.lock().expect("sun lock")
    }

    /// The live stale grid to compute next: one that shades a drawn node, or would while the
    /// node's own is missing (a coarser ancestor's), before any other; then the nearest to the
    /// camera, coarser first at equal distance (so the coarse grids around the camera come
    /// first and shade everything under them at their columns until the finer grids arrive).
    fn next_stale(&self) -> Option<Arc<SharedGrid>> {
        let sun = self.sun();
        let [x, y] = &self.camera_xy_m;
        let camera = DVec2::new(
            f64::from_bits(x.load(Ordering::Relaxed)),
            f64::from_bits(y.load(Ordering::Relaxed)),
        );
        let drawn = Arc::clone(&self.drawn.lock().expect("drawn lock"));
        let mut grids = self.grids.lock().expect("grids lock");
        grids.retain(|_, g| g.strong_count() > 0);
        let distance = |key: NodeKey| {
            let r = self.tree.rect(key);
            let dx = (r.min[0] - camera.x).max(camera.x - r.max[0]).max(0.0);
            let dy = (r.min[1] - camera.y).max(camera.y - r.max[1]).max(0.0);
            dx.hypot(dy)
        };
        grids
            .values()
            .filter_map(Weak::upgrade)
            .filter(|g| !g.computing.load(Ordering::Acquire) && g.stale(sun))
            .min_by(|a, b| {
                (!drawn.first.contains(&a.key))
                    .cmp(&!drawn.first.contains(&b.key))
                    .then(distance(a.key).total_cmp(&distance(b.key)))
                    .then(a.key.level.cmp(&b.key.level))
                    .then(a.key.cmp(&b.key))
            })
    }

    fn run(&self) {
        crate::stream::idle_priority();
        // Threads start only once a world is attached.
        let Some(world) = self.world.get() else {
            return;
        };
        loop {
            let next = {
                let mut state = self.state.lock().expect("state lock");
                loop {
                    if state.stop {
                        return;
                    }
                    if let Some(g) = self.next_stale() {
                        g.computing.store(true, Ordering::Release);
                        state.busy += 1;
                        // Logged in the order picked (nearest first), under the state lock.
                        let mut log = self.log.lock().expect("log lock");
                        if log.len() == LOG_LEN {
                            log.pop_front();
                        }
                        log.push_back(g.key);
                        drop(log);
                        state.idle = false;
                        break g;
                    }
                    if state.busy == 0 {
                        state.idle = true;
                        self.idle.notify_all();
                    }
                    state = self.wake.wait(state).expect("state lock");
                }
            };
            let sun = self.sun();
            // A relight keeps the grid's sky (no sun changes it); a first computation takes it
            // from the node's sky page where the map keeps them.
            let pages = self.pages.get_or_init(|| {
                let dir = self
                    .pages_dir
                    .get()
                    .cloned()
                    .or_else(|| world.derived_dir.as_ref().map(|d| d.join(SKY_PAGES_DIR)));
                dir.map(|dir| SkyPages::new(&dir, world, &self.canopy))
            });
            let grid = match (next.grid(), pages) {
                (Some(earlier), _) => earlier.relit(world, &self.canopy, &self.tree, sun),
                (None, Some(pages)) => pages.grid((world, &self.canopy, &self.tree), next.key, sun),
                (None, None) => LightGrid::compute(world, &self.canopy, &self.tree, next.key, sun),
            };
            next.store(grid);
            self.announce_stored(next.key);
            let mut state = self.state.lock().expect("state lock");
            next.computing.store(false, Ordering::Release);
            state.busy -= 1;
            // The others may wait for this one to decide they are idle, and
            // [`LightingContent::wait_drawn_lit`] for this grid.
            self.wake.notify_all();
            self.idle.notify_all();
        }
    }

    /// Whether every grid that shades a drawn node is computed for the current sun.
    fn drawn_lit(&self) -> bool {
        let sun = self.sun();
        let drawn = Arc::clone(&self.drawn.lock().expect("drawn lock"));
        let grids = self.grids.lock().expect("grids lock");
        drawn.owners.iter().all(|k| {
            grids
                .get(k)
                .and_then(Weak::upgrade)
                .is_none_or(|g| !g.stale(sun))
        })
    }

    /// Tells the thread there may be work.
    fn poke(&self) {
        self.state.lock().expect("state lock").idle = false;
        self.wake.notify_all();
    }
}

/// One subscriber's keys of the grids stored (first computations and relights) since it last
/// took them: a grid's new [`SharedGrid::version`] is visible once its key is listed.
#[derive(Debug)]
pub struct GridsStored(Arc<Mutex<Vec<NodeKey>>>);

impl GridsStored {
    /// The keys listed since the last call (a grid stored twice meanwhile is listed twice).
    pub fn take(&self) -> Vec<NodeKey> {
        std::mem::take(&mut *self.0.lock().expect("stored lock"))
    }
}

/// The light-grid kind (phase `light grid`; payload [`NodeLight`]).
#[derive(Debug)]
pub struct LightingContent {
    inner: Arc<Inner>,
    /// Light threads to start (on the first grid).
    threads: usize,
    handles: Mutex<Vec<std::thread::JoinHandle<()>>>,
}

/// The default number of light threads: as many as the default node workers.
pub fn default_light_threads() -> usize {
    crate::stream::StreamSettings::default().workers
}

impl Drop for LightingContent {
    fn drop(&mut self) {
        self.inner.state.lock().expect("state lock").stop = true;
        self.inner.wake.notify_all();
        for t in self.handles.lock().expect("threads lock").drain(..) {
            let _ = t.join();
        }
    }
}

impl LightingContent {
    /// The kind's registered name.
    pub const NAME: &'static str = "lighting";

    /// The kind for `world` (its quad tree; the light threads compute on the world the streamer
    /// attaches, see [`ContentKind::attach_world`]), lit through `canopy` (the vegetation
    /// kind's), with `sun`, and [`default_light_threads`] threads.
    pub fn new(world: &World, canopy: Arc<Canopy>, sun: Sun) -> Self {
        Self::with_threads(world, canopy, sun, default_light_threads())
    }

    /// [`Self::new`] with `threads` light threads (at least 1).
    pub fn with_threads(world: &World, canopy: Arc<Canopy>, sun: Sun, threads: usize) -> Self {
        Self {
            inner: Arc::new(Inner {
                world: std::sync::OnceLock::new(),
                pages: std::sync::OnceLock::new(),
                pages_dir: std::sync::OnceLock::new(),
                tree: QuadTree::new(world.origin_m(), world.size_m()),
                canopy,
                sun: Mutex::new(sun),
                camera_xy_m: [AtomicU64::new(0), AtomicU64::new(0)],
                drawn: Mutex::new(Arc::new(DrawnGrids::default())),
                grids: Mutex::new(FxHashMap::default()),
                stored: Mutex::new(Vec::new()),
                log: Mutex::new(std::collections::VecDeque::new()),
                state: Mutex::new(ThreadState::default()),
                wake: Condvar::new(),
                idle: Condvar::new(),
            }),
            threads: threads.max(1),
            handles: Mutex::new(Vec::new()),
        }
    }

    /// Keeps the grids' sky pages in `dir` instead of the world's derived folder (before the
    /// first grid is computed; later calls change nothing).
    pub fn keep_sky_pages_in(&self, dir: &std::path::Path) {
        let _ = self.inner.pages_dir.set(dir.to_path_buf());
    }

    /// The light threads it runs.
    pub fn threads(&self) -> usize {
        self.threads
    }

    /// The sun grids are made for.
    pub fn sun(&self) -> Sun {
        self.inner.sun()
    }

    /// The canopy grids are lit through.
    pub fn canopy(&self) -> &Canopy {
        &self.inner.canopy
    }

    /// A new subscriber to the grids stored from now on: a renderer takes their keys each frame
    /// instead of looking at every grid it holds.
    pub fn grids_stored(&self) -> GridsStored {
        let list = Arc::new(Mutex::new(Vec::new()));
        self.inner
            .stored
            .lock()
            .expect("stored lock")
            .push(Arc::downgrade(&list));
        GridsStored(list)
    }

    /// The keys of the last grids computed (up to [`LOG_LEN`]), oldest first.
    pub fn computed_keys(&self) -> Vec<NodeKey> {
        self.inner
            .log
            .lock()
            .expect("log lock")
            .iter()
            .copied()
            .collect()
    }

    /// Where the camera is (the light threads compute the nearest stale grid next).
    pub fn set_camera(&self, camera_xy_m: DVec2) {
        let [x, y] = &self.inner.camera_xy_m;
        x.store(camera_xy_m.x.to_bits(), Ordering::Relaxed);
        y.store(camera_xy_m.y.to_bits(), Ordering::Relaxed);
    }

    /// Sets a new sun: every live grid is relit in the background, nearest to the camera first,
    /// and grids made from now on use it.
    pub fn set_sun(&self, sun: Sun) {
        *self.inner.sun.lock().expect("sun lock") = sun;
        self.inner.poke();
    }

    /// Waits until every live grid is computed for the current sun (tests and benchmarks wait
    /// on this event, not on time).
    pub fn wait_idle(&self) {
        if !self.inner.state.lock().expect("state lock").started {
            return;
        }
        let mut state = self.inner.state.lock().expect("state lock");
        while !state.idle && !state.stop {
            state = self.inner.idle.wait(state).expect("state lock");
        }
    }

    /// Waits until every grid that shades a node the last frame drew is computed for the
    /// current sun; the other live grids (of nodes kept but not drawn) go on in the background.
    pub fn wait_drawn_lit(&self) {
        if !self.inner.state.lock().expect("state lock").started {
            return;
        }
        let mut state = self.inner.state.lock().expect("state lock");
        while !state.stop && !self.inner.drawn_lit() {
            state = self.inner.idle.wait(state).expect("state lock");
        }
    }

    /// The grid of node `key` (at [`grid_level`] or coarser): the live one, or a new one the
    /// light threads will compute.
    pub fn grid_for(&self, key: NodeKey) -> Arc<SharedGrid> {
        let mut grids = self.inner.grids.lock().expect("grids lock");
        if let Some(g) = grids.get(&key).and_then(Weak::upgrade) {
            return g;
        }
        let g = Arc::new(SharedGrid {
            key,
            computing: std::sync::atomic::AtomicBool::new(false),
            grid: Mutex::new(None),
            version: AtomicU64::new(0),
        });
        grids.insert(key, Arc::downgrade(&g));
        drop(grids);
        self.start_thread();
        self.inner.poke();
        g
    }

    fn start_thread(&self) {
        let mut state = self.inner.state.lock().expect("state lock");
        if state.started || self.inner.world.get().is_none() {
            return;
        }
        state.started = true;
        let mut handles = self.handles.lock().expect("threads lock");
        for i in 0..self.threads {
            let inner = Arc::clone(&self.inner);
            handles.push(
                std::thread::Builder::new()
                    .name(format!("light grids {i}"))
                    .spawn(move || inner.run())
                    .expect("a light-grid thread starts"),
            );
        }
    }
}

impl ContentKind for LightingContent {
    fn name(&self) -> &'static str {
        Self::NAME
    }

    /// Gives the light threads `world` (the first one given stays). Grids are computed only
    /// once a world is attached.
    fn attach_world(&self, world: &Arc<World>) {
        if self.inner.world.set(Arc::clone(world)).is_ok() {
            self.start_thread();
            self.inner.poke();
        }
    }

    fn observe_camera(&self, camera_m: glam::DVec3) {
        self.set_camera(camera_m.truncate());
    }

    fn observe_drawn(&self, drawn: &[crate::stream::DrawNode]) {
        let tree = &self.inner.tree;
        let owners: FxHashSet<NodeKey> = drawn
            .iter()
            .map(|d| LightGrid::owner(tree, d.key))
            .collect();
        let mut first =
            FxHashSet::with_capacity_and_hasher(2 * owners.len(), rustc_hash::FxBuildHasher);
        for &k in &owners {
            for a in std::iter::once(k).chain(k.ancestors()) {
                if !first.insert(a) {
                    break; // so is the rest of its chain
                }
            }
        }
        let sets = Arc::new(DrawnGrids { owners, first });
        // The old sets go after the lock (a light thread may still hold them).
        let old = std::mem::replace(&mut *self.inner.drawn.lock().expect("drawn lock"), sets);
        drop(old);
    }

    fn phases(self: Arc<Self>) -> Vec<Phase> {
        vec![Phase::cpu(
            "light grid",
            move |s: &Shared, w: &mut NodeWork| {
                let owner = LightGrid::owner(&s.tree, w.key);
                debug_assert!(owner.level <= grid_level(&s.tree));
                let grid = self.grid_for(owner);
                w.put(NodeLight {
                    grid,
                    owns: owner == w.key,
                });
            },
        )]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stream::DrawNode;
    use crate::vegetation::placement::Placer;

    /// The next grid computed is one that shades a drawn node, even when a grid of a node that
    /// is only kept (not drawn) is nearer to the camera; among the drawn ones, the nearest.
    #[test]
    fn grids_of_drawn_nodes_are_computed_first() {
        let world = World::new(crate::test_maps::tiny_map());
        let canopy = Arc::new(Canopy::new(&world, &Placer::new(&world)));
        // No world attached: no light thread starts, so nothing is taken before the test looks.
        let lighting = LightingContent::with_threads(&world, canopy, Sun::default(), 1);
        let tree = QuadTree::new(world.origin_m(), world.size_m());
        let level = grid_level(&tree);
        let key = |ix, iy| NodeKey { level, ix, iy };
        let grids: Vec<Arc<SharedGrid>> = [key(0, 0), key(1, 0), key(3, 3), key(2, 3)]
            .into_iter()
            .map(|k| lighting.grid_for(k))
            .collect();
        let centre = |k: NodeKey| {
            let r = tree.rect(k);
            DVec2::new(0.5 * (r.min[0] + r.max[0]), 0.5 * (r.min[1] + r.max[1]))
        };
        lighting.set_camera(centre(key(0, 0)));
        assert_eq!(lighting.inner.next_stale().map(|g| g.key), Some(key(0, 0)));
        // A node finer than the grid level is shaded by its ancestor's grid.
        let drawn = |k: NodeKey| DrawNode {
            key: k.children()[0],
            dither_lo: 0.0,
            dither_hi: 1.0,
            decimation: 0,
        };
        lighting.observe_drawn(&[drawn(key(3, 3)), drawn(key(2, 3))]);
        assert_eq!(lighting.inner.next_stale().map(|g| g.key), Some(key(2, 3)));
        // A coarser ancestor's grid (it shades them until theirs arrive) counts as theirs:
        // the parent of (3, 3) and (2, 3) is nearer than (2, 3), so it comes first; while
        // nothing is drawn it is farther than (0, 0).
        let coarse = lighting.grid_for(key(3, 3).parent().expect("the grid level is not the root"));
        assert_eq!(lighting.inner.next_stale().map(|g| g.key), Some(coarse.key));
        lighting.observe_drawn(&[]);
        assert_eq!(lighting.inner.next_stale().map(|g| g.key), Some(key(0, 0)));
        drop((grids, coarse));
    }
}
