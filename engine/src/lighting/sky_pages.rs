//! The static part of light grids kept with the map: one page per light-grid node (at
//! [`super::grid::grid_level`] and every coarser level) holding the grid's sky visibility,
//! which depends on the terrain's horizons and the canopy but on no sun. A grid made with its
//! page ([`LightGrid::relit`]'s path: the page is the sky an earlier computation of the node
//! found) skips the horizons of every direction but the sun's and the canopy's sky rays, which
//! are most of a grid's time; only the sun's horizon and canopy ray and the ground's bounce are
//! marched.
//!
//! Pages are derived data, baked the first time a node's grid is computed ([`SkyPages::grid`])
//! or for the whole map ahead of time ([`SkyPages::bake`]), and never trusted blindly: a page is used only when its key matches the
//! map and the lighting it was computed with, it belongs to the node asked for, and its payload
//! matches its checksum; otherwise it is refused (logged with its file and the reason) and the
//! grid computed in full, which writes the page again. The key hashes the surface
//! ([`crate::surface::map_error_cache::surface_key`]: heights, ground, amplitudes, seed,
//! placement, decals, the surface function), the canopy (its layer tops and extinction at fixed
//! points) and the grid's constants, so a changed map or a changed computation invalidates
//! every page.
//!
//! Layout (little-endian), one file per node, `<dir>/<level>/<ix>_<iy>.sky`: magic
//! `TVS-SKYP`, format version u32, key u64, level u8, ix u32, iy u32, payload checksum u64, then
//! the payload: the grid's sky bytes, `[layer][row][col]`.

use super::grid::{self, COLUMNS, LAYERS, LightGrid, Sun};
use crate::surface::World;
use crate::surface::map_error_cache::surface_key;
use crate::terrain::quadtree::{NodeKey, QuadTree};
use crate::vegetation::canopy::Canopy;
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};

/// The folder of a map's sky pages in its derived folder ([`World::derived_dir`]).
pub const SKY_PAGES_DIR: &str = ".sky_pages";

const MAGIC: &[u8; 8] = b"TVS-SKYP";
const FORMAT_VERSION: u32 = 1;
/// Bumped whenever the sky's computation changes (part of every page's key).
const SKY_METHOD_VERSION: u64 = 1;
const HEADER_BYTES: usize = 8 + 4 + 8 + 1 + 4 + 4 + 8;
/// Bytes of a page's payload.
pub const PAYLOAD_BYTES: usize = LAYERS * COLUMNS * COLUMNS;

/// Why a page was not used.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum PageRefused {
    #[error("no page yet")]
    Missing,
    #[error("cannot read the page: {0}")]
    Io(String),
    #[error("not a sky page of this version (magic, version or size)")]
    Format,
    #[error("computed from another map, canopy or lighting version (key)")]
    Stale,
    #[error("holds another node's sky (node)")]
    WrongNode,
    #[error("its content does not match its checksum (damaged or edited)")]
    Damaged,
}

/// The sky pages of one map in one folder.
#[derive(Debug, Clone)]
pub struct SkyPages {
    dir: PathBuf,
    key: u64,
}

/// The key of the sky computed on `world` under `canopy` (see the module docs).
pub fn sky_key(world: &World, canopy: &Canopy) -> u64 {
    let mut h = std::hash::DefaultHasher::new();
    surface_key(world, SKY_METHOD_VERSION).hash(&mut h);
    for t in grid::layer_heights_m(canopy) {
        t.to_bits().hash(&mut h);
    }
    canopy.top_m.to_bits().hash(&mut h);
    let (o, s) = (world.origin_m(), world.size_m());
    for i in 0..1024i64 {
        let x = o[0] + s[0] * worldgen::noise::unit3(0x5C7, i, 0);
        let y = o[1] + s[1] * worldgen::noise::unit3(0x5C7, i, 1);
        let above = canopy.top_m * worldgen::noise::unit3(0x5C7, i, 2);
        canopy.extinction_per_m(x, y, above).to_bits().hash(&mut h);
    }
    (
        COLUMNS,
        LAYERS,
        grid::HORIZON_AZIMUTHS,
        grid::CANOPY_AZIMUTHS,
        grid::SKY_BANDS,
        grid::CANOPY_STEPS,
    )
        .hash(&mut h);
    for v in [
        grid::GRID_SIDE_M,
        grid::GROUND_LAYER_M,
        grid::HORIZON_REACH_M,
        grid::NEAR_SPACING_M,
        grid::NEAR_MARGIN_M,
    ] {
        v.to_bits().hash(&mut h);
    }
    h.finish()
}

fn checksum(payload: &[u8]) -> u64 {
    let mut h = std::hash::DefaultHasher::new();
    payload.hash(&mut h);
    h.finish()
}

impl SkyPages {
    /// The pages of `world` under `canopy` in `dir` (created when the first page is written).
    pub fn new(dir: &Path, world: &World, canopy: &Canopy) -> Self {
        Self {
            dir: dir.to_path_buf(),
            key: sky_key(world, canopy),
        }
    }

    /// The file of node `key`'s page.
    pub fn path(&self, key: NodeKey) -> PathBuf {
        self.dir
            .join(key.level.to_string())
            .join(format!("{}_{}.sky", key.ix, key.iy))
    }

    /// Node `key`'s sky, from its page.
    pub fn read(&self, key: NodeKey) -> Result<Vec<u8>, PageRefused> {
        let bytes = std::fs::read(self.path(key)).map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => PageRefused::Missing,
            _ => PageRefused::Io(e.to_string()),
        })?;
        if bytes.len() != HEADER_BYTES + PAYLOAD_BYTES
            || &bytes[..8] != MAGIC
            || u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes")) != FORMAT_VERSION
        {
            return Err(PageRefused::Format);
        }
        if u64::from_le_bytes(bytes[12..20].try_into().expect("8 bytes")) != self.key {
            return Err(PageRefused::Stale);
        }
        let node = NodeKey {
            level: bytes[20],
            ix: u32::from_le_bytes(bytes[21..25].try_into().expect("4 bytes")),
            iy: u32::from_le_bytes(bytes[25..29].try_into().expect("4 bytes")),
        };
        if node != key {
            return Err(PageRefused::WrongNode);
        }
        let payload = &bytes[HEADER_BYTES..];
        if u64::from_le_bytes(bytes[29..37].try_into().expect("8 bytes")) != checksum(payload) {
            return Err(PageRefused::Damaged);
        }
        Ok(payload.to_vec())
    }

    /// Writes `grid`'s sky as its node's page.
    pub fn write(&self, grid: &LightGrid) -> std::io::Result<()> {
        self.write_sky(grid.key, &grid.sky)
    }

    /// Writes `sky` as node `key`'s page (through a temporary file, so a reader never sees a
    /// half-written page).
    fn write_sky(&self, key: NodeKey, sky: &[u8]) -> std::io::Result<()> {
        let path = self.path(key);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent)?;
        }
        let mut bytes = Vec::with_capacity(HEADER_BYTES + PAYLOAD_BYTES);
        bytes.extend_from_slice(MAGIC);
        bytes.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        bytes.extend_from_slice(&self.key.to_le_bytes());
        bytes.push(key.level);
        bytes.extend_from_slice(&key.ix.to_le_bytes());
        bytes.extend_from_slice(&key.iy.to_le_bytes());
        bytes.extend_from_slice(&checksum(sky).to_le_bytes());
        bytes.extend_from_slice(sky);
        let tmp = path.with_extension(format!("partial{}", std::process::id()));
        std::fs::write(&tmp, &bytes)?;
        std::fs::rename(&tmp, &path)
    }

    /// Node `key`'s grid for `sun`: from its page when one is usable, else computed in full and
    /// its page written. A refused page is logged (its file and why); a page that cannot be
    /// written is logged too, and the grid is returned either way.
    pub fn grid(
        &self,
        (world, canopy, tree): (&World, &Canopy, &QuadTree),
        key: NodeKey,
        sun: Sun,
    ) -> LightGrid {
        match self.read(key) {
            Ok(sky) => return LightGrid::with_sky(world, canopy, tree, key, sun, &sky),
            Err(PageRefused::Missing) => {}
            Err(why) => log::warn!(
                "{}: sky page not used ({why}); computing the grid in full",
                self.path(key).display()
            ),
        }
        let grid = LightGrid::compute(world, canopy, tree, key, sun);
        if let Err(e) = self.write(&grid) {
            log::warn!("{}: cannot write ({e})", self.path(key).display());
        }
        grid
    }
}

/// What [`SkyPages::bake`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Baked {
    /// Grid-level pages computed (their grids in full).
    pub computed: usize,
    /// Coarser pages taken from the grid-level ones.
    pub derived: usize,
    /// Pages already there and valid.
    pub kept: usize,
}

impl SkyPages {
    /// Bakes every page of the map ahead of time, on `threads` threads: each grid-level node's
    /// grid computed (its page written) unless its page is there and valid, then every coarser
    /// node's page taken from them (a coarse grid's columns hold the finer grids' bytes, so no
    /// computation). `progress` sees the grid-level nodes. A page that cannot be written stops
    /// the bake with the file and the error.
    pub fn bake(
        &self,
        (world, canopy, tree): (&World, &Canopy, &QuadTree),
        threads: usize,
        progress: &dyn worldgen::progress::Progress,
    ) -> std::io::Result<Baked> {
        let level = grid::grid_level(tree);
        let side = 1u32 << level;
        let nodes: Vec<NodeKey> = (0..side)
            .flat_map(|iy| (0..side).map(move |ix| NodeKey { level, ix, iy }))
            .collect();
        progress.begin("sky pages", nodes.len() as u64);
        let next = std::sync::atomic::AtomicUsize::new(0);
        let failed = std::sync::Mutex::new(None);
        let (computed, kept) = (
            std::sync::atomic::AtomicUsize::new(0),
            std::sync::atomic::AtomicUsize::new(0),
        );
        // Only the sky is kept, and no sun changes it: under a sun below the horizon the grid
        // sends no sun rays and weighs no bounce.
        let night = Sun {
            azimuth_deg: 0.0,
            elevation_deg: -45.0,
        };
        std::thread::scope(|s| {
            for _ in 0..threads.max(1) {
                s.spawn(|| {
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(&key) = nodes.get(i) else { break };
                        if self.read(key).is_ok() {
                            kept.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        } else {
                            let g = LightGrid::compute(world, canopy, tree, key, night);
                            if let Err(e) = self.write(&g) {
                                let why = std::io::Error::new(
                                    e.kind(),
                                    format!("{}: {e}", self.path(key).display()),
                                );
                                *failed.lock().expect("failure lock") = Some(why);
                                next.store(nodes.len(), std::sync::atomic::Ordering::Relaxed);
                            } else {
                                computed.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                            }
                        }
                        progress.advance(1);
                    }
                });
            }
        });
        progress.end();
        if let Some(e) = failed.into_inner().expect("failure lock") {
            return Err(e);
        }
        let mut derived = 0;
        for coarse in (0..level).rev() {
            let n = 1u32 << coarse;
            for iy in 0..n {
                for ix in 0..n {
                    self.derive(
                        tree,
                        NodeKey {
                            level: coarse,
                            ix,
                            iy,
                        },
                    )?;
                    derived += 1;
                }
            }
        }
        Ok(Baked {
            computed: computed.into_inner(),
            derived,
            kept: kept.into_inner(),
        })
    }

    /// Writes the page of coarse node `key` from its grid-level descendants' pages (which must
    /// be there): each of its columns is one of theirs.
    fn derive(&self, tree: &QuadTree, key: NodeKey) -> std::io::Result<()> {
        let level = grid::grid_level(tree);
        let step = 1usize << (level - key.level);
        let per = COLUMNS - 1;
        let last = (1usize << level) - 1;
        let mut sky = vec![0u8; PAYLOAD_BYTES];
        let mut fine: std::collections::HashMap<(usize, usize), Vec<u8>> =
            std::collections::HashMap::new();
        for row in 0..COLUMNS {
            for col in 0..COLUMNS {
                // Global grid-level column indices, then the grid-level node holding them.
                let g = [
                    (key.ix as usize * per + col) * step,
                    (key.iy as usize * per + row) * step,
                ];
                let node = [(g[0] / per).min(last), (g[1] / per).min(last)];
                let local = [g[0] - node[0] * per, g[1] - node[1] * per];
                let page = match fine.entry((node[0], node[1])) {
                    std::collections::hash_map::Entry::Occupied(e) => e.into_mut(),
                    std::collections::hash_map::Entry::Vacant(e) => {
                        let k = NodeKey {
                            level,
                            ix: node[0] as u32,
                            iy: node[1] as u32,
                        };
                        let page = self.read(k).map_err(|why| {
                            std::io::Error::other(format!("{}: {why}", self.path(k).display()))
                        })?;
                        e.insert(page)
                    }
                };
                for l in 0..LAYERS {
                    sky[LightGrid::index(l, row, col)] =
                        page[LightGrid::index(l, local[1], local[0])];
                }
            }
        }
        self.write_sky(key, &sky)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::content::LightingContent;
    use crate::stream::ContentKind;
    use crate::vegetation::Placer;
    use std::sync::Arc;

    fn temp_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("tvs-sky-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    fn tiny() -> (World, Canopy, QuadTree) {
        let world = World::new(crate::test_maps::tiny_map());
        let canopy = Canopy::new(&world, &Placer::new(&world));
        let tree = QuadTree::new(world.origin_m(), world.size_m());
        (world, canopy, tree)
    }

    /// Rewrites the page of `key` with its sky changed by `edit`, re-checksummed (a page that
    /// passes every check but holds another sky).
    fn forge(pages: &SkyPages, key: NodeKey, edit: impl Fn(&mut [u8])) {
        let mut bytes = std::fs::read(pages.path(key)).expect("page");
        edit(&mut bytes[HEADER_BYTES..]);
        let sum = checksum(&bytes[HEADER_BYTES..]);
        bytes[29..37].copy_from_slice(&sum.to_le_bytes());
        std::fs::write(pages.path(key), &bytes).expect("write forged page");
    }

    /// A node's grid made from its page equals the full computation, at the grid level and
    /// coarser; a page edited after writing, one of another node, one from another map and a
    /// truncated one are refused, and the grid is computed in full (and the page rewritten).
    #[test]
    fn grids_from_pages_equal_the_computation_and_bad_pages_are_refused() {
        let (world, canopy, tree) = tiny();
        let dir = temp_dir("refused");
        let pages = SkyPages::new(&dir, &world, &canopy);
        let sun = Sun {
            azimuth_deg: 250.0,
            elevation_deg: 12.0,
        };
        let level = grid::grid_level(&tree);
        let fine = NodeKey {
            level,
            ix: 2,
            iy: 1,
        };
        let coarse = NodeKey {
            level: level - 1,
            ix: 1,
            iy: 0,
        };
        let at = (&world, &canopy, &tree);
        for key in [fine, coarse] {
            let full = LightGrid::compute(&world, &canopy, &tree, key, sun);
            assert_eq!(pages.read(key), Err(PageRefused::Missing));
            assert_eq!(
                pages.grid(at, key, sun),
                full,
                "{key:?}: the baking computation"
            );
            assert_eq!(
                pages.read(key).as_deref(),
                Ok(&full.sky[..]),
                "{key:?}: written"
            );
            assert_eq!(pages.grid(at, key, sun), full, "{key:?}: from the page");
        }
        let full = LightGrid::compute(&world, &canopy, &tree, fine, sun);
        // One sky byte changed after writing.
        let page = pages.path(fine);
        let mut bytes = std::fs::read(&page).expect("page");
        bytes[HEADER_BYTES + 100] ^= 0x10;
        std::fs::write(&page, &bytes).expect("tamper");
        assert_eq!(pages.read(fine), Err(PageRefused::Damaged));
        assert_eq!(pages.grid(at, fine, sun), full);
        assert!(pages.read(fine).is_ok(), "rewritten");
        // Another node's page in this node's file.
        std::fs::copy(pages.path(coarse), &page).expect("copy");
        assert_eq!(pages.read(fine), Err(PageRefused::WrongNode));
        assert_eq!(pages.grid(at, fine, sun), full);
        // Pages of another map (one height raised) are stale for it, and a truncated page is
        // not a page.
        let mut other = crate::test_maps::tiny_map();
        let hg = other.heights.grid_mut().expect("heights in memory");
        hg.set(40, 40, hg.get(40, 40) + 3.0);
        let other_world = World::new(other);
        let other_pages = SkyPages::new(&dir, &other_world, &canopy);
        assert_eq!(other_pages.read(fine), Err(PageRefused::Stale));
        std::fs::write(&page, &bytes[..HEADER_BYTES + 10]).expect("truncate");
        assert_eq!(pages.read(fine), Err(PageRefused::Format));
        assert_eq!(pages.grid(at, fine, sun), full);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// The lighting kind keeps its grids' pages in the folder it is given and makes a grid from
    /// its page when one is there: a forged page (valid, but its sky darkened) shows up in the
    /// grid a new kind makes, and nowhere else.
    #[test]
    fn the_lighting_kind_bakes_pages_and_makes_grids_from_them() {
        let (world, canopy, tree) = tiny();
        let world = Arc::new(world);
        let canopy = Arc::new(canopy);
        let dir = temp_dir("kind");
        let level = grid::grid_level(&tree);
        let keys = [
            NodeKey {
                level,
                ix: 0,
                iy: 0,
            },
            NodeKey {
                level,
                ix: 3,
                iy: 2,
            },
        ];
        let kind = |world: &Arc<World>| {
            let k = LightingContent::with_threads(world, Arc::clone(&canopy), Sun::default(), 1);
            k.keep_sky_pages_in(&dir);
            k.attach_world(world);
            k
        };
        let first = kind(&world);
        let held: Vec<_> = keys.iter().map(|&k| first.grid_for(k)).collect();
        first.wait_idle();
        let pages = SkyPages::new(&dir, &world, &canopy);
        for g in &held {
            let grid = g.grid().expect("computed");
            assert_eq!(pages.read(g.key).as_deref(), Ok(&grid.sky[..]), "baked");
        }
        forge(&pages, keys[1], |sky| sky.iter_mut().for_each(|v| *v /= 2));
        let second = kind(&world);
        let again: Vec<_> = keys.iter().map(|&k| second.grid_for(k)).collect();
        second.wait_idle();
        let (a0, a1) = (again[0].grid().expect("0"), again[1].grid().expect("1"));
        assert_eq!(*a0, *held[0].grid().expect("held 0"), "an honest page");
        let forged = held[1].grid().expect("held 1");
        assert!(a1.sky.iter().zip(&forged.sky).all(|(&a, &f)| a == f / 2));
        assert!(forged.sky.iter().any(|&v| v > 1), "the forged sky differs");
        assert_eq!(
            (a1.sun.clone(), a1.bounce.clone()),
            (forged.sun.clone(), forged.bounce.clone())
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Baking the whole map writes every page, each equal to its grid's sky at every level
    /// (the coarse ones taken from the grid-level ones, no computation); a second bake keeps
    /// them all.
    #[test]
    fn a_baked_map_has_every_page_and_each_is_its_grids_sky() {
        let (world, canopy, tree) = tiny();
        let dir = temp_dir("bake");
        let pages = SkyPages::new(&dir, &world, &canopy);
        let at = (&world, &canopy, &tree);
        let level = grid::grid_level(&tree);
        let baked = pages
            .bake(at, 2, &worldgen::progress::Silent)
            .expect("bake");
        let fine = 1usize << (2 * level);
        let coarse: usize = (0..level).map(|l| 1usize << (2 * l)).sum();
        assert_eq!(
            baked,
            Baked {
                computed: fine,
                derived: coarse,
                kept: 0
            }
        );
        for key in [
            NodeKey {
                level,
                ix: 3,
                iy: 1,
            },
            NodeKey {
                level: level - 1,
                ix: 1,
                iy: 1,
            },
            NodeKey {
                level: 0,
                ix: 0,
                iy: 0,
            },
        ] {
            let full = LightGrid::compute(&world, &canopy, &tree, key, Sun::default());
            assert_eq!(pages.read(key).as_deref(), Ok(&full.sky[..]), "{key:?}");
        }
        let again = pages
            .bake(at, 1, &worldgen::progress::Silent)
            .expect("bake again");
        assert_eq!((again.computed, again.kept), (0, fine));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
