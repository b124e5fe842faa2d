//! A file that keeps a map's [`MapErrorPyramid`] between runs: computing it costs seconds on a
//! large map (the finest surface on a 1 m lattice over the whole map), reading it milliseconds.
//!
//! The file is derived data, never trusted blindly: it is used only when its key matches the
//! surface it was computed from and its payload matches its checksum; otherwise the pyramid is
//! computed again (and the file rewritten). The key hashes everything `F` and its region bounds
//! are made of (heights, ground types, amplitudes, seed, placement, decals) and a fingerprint of
//! the surface function itself (`F` and its between-points bound at fixed points), so a changed
//! map or a changed surface definition in the engine both invalidate the file.
//!
//! Layout (little-endian): magic `TVS-SERR`, format version u32, key u64, payload checksum u64,
//! then the payload: origin (2 f64), the finest grid's spacing (f64: half the height spacing, or a
//! quarter with the terrain's measured grid, [`crate::terrain::precomputed`]; version 1 had
//! neither), grid count (u32), and per grid its
//! blocks per row and rows (2 u32) and its blocks (4 f32 each).

use super::map_error::MapErrorPyramid;
use super::world::{Rect, World};
use std::hash::{Hash, Hasher};
use std::path::Path;

const MAGIC: &[u8; 8] = b"TVS-SERR";
const FORMAT_VERSION: u32 = 3;

/// Why a cache file was not used.
#[derive(Debug, thiserror::Error)]
pub enum CacheMiss {
    #[error("no cache file yet")]
    Missing,
    #[error("cannot read the cache file: {0}")]
    Io(std::io::Error),
    #[error("not a surface-error cache file of this version")]
    Format,
    #[error("computed from another map or another surface definition")]
    Stale,
    #[error("its content does not match its checksum (damaged or edited)")]
    Damaged,
}

/// The key of `world`'s surface and of the version of the caller's computation (`method`: how
/// grids finer than the map's own are measured, see [`World::with_error_cache`]): see the module
/// docs.
pub fn surface_key(world: &World, method: u64) -> u64 {
    let mut h = std::hash::DefaultHasher::new();
    FORMAT_VERSION.hash(&mut h);
    method.hash(&mut h);
    let map = &world.map;
    // The heights, the ground types, the legend's amplitudes, the decals and the map's
    // placement, through the keys of what the world derives from them (CRCs already taken).
    world.derived_key().hash(&mut h);
    map.manifest.seed.hash(&mut h);
    for v in map.manifest.origin_m.iter().chain(&map.manifest.size_m) {
        v.to_bits().hash(&mut h);
    }
    let (hs, gs) = world.cell_spacings_m();
    hs.to_bits().hash(&mut h);
    gs.to_bits().hash(&mut h);
    // The surface function: F and the between-points bound at fixed points of a square of at
    // most 256 m in the middle of the map (few pages of a baked map's paged pyramids).
    let (o, s) = (world.origin_m(), world.size_m());
    let side = [s[0].min(256.0), s[1].min(256.0)];
    for i in 0..256i64 {
        let x = o[0] + (s[0] - side[0]) * 0.5 + side[0] * worldgen::noise::unit3(0x5E77, i, 0);
        let y = o[1] + (s[1] - side[1]) * 0.5 + side[1] * worldgen::noise::unit3(0x5E77, i, 1);
        world.height_m(x, y).to_bits().hash(&mut h);
        let cell = Rect {
            min: [x, y],
            max: [x + 0.5, y + 0.5],
        };
        world
            .region_bounds(cell)
            .between_m(0.5)
            .to_bits()
            .hash(&mut h);
    }
    h.finish()
}

fn checksum(payload: &[u8]) -> u64 {
    let mut h = std::hash::DefaultHasher::new();
    payload.hash(&mut h);
    h.finish()
}

/// Reads the pyramid cached for `key` from `path`.
pub fn read(path: &Path, key: u64) -> Result<MapErrorPyramid, CacheMiss> {
    let bytes = std::fs::read(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => CacheMiss::Missing,
        _ => CacheMiss::Io(e),
    })?;
    let header = 8 + 4 + 8 + 8;
    if bytes.len() < header
        || &bytes[..8] != MAGIC
        || u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes")) != FORMAT_VERSION
    {
        return Err(CacheMiss::Format);
    }
    if u64::from_le_bytes(bytes[12..20].try_into().expect("8 bytes")) != key {
        return Err(CacheMiss::Stale);
    }
    let payload = &bytes[header..];
    if u64::from_le_bytes(bytes[20..28].try_into().expect("8 bytes")) != checksum(payload) {
        return Err(CacheMiss::Damaged);
    }
    MapErrorPyramid::from_bytes(payload).ok_or(CacheMiss::Format)
}

/// Writes the pyramid for `key` to `path` (through a temporary file, so a reader never sees a
/// half-written one).
pub fn write(path: &Path, key: u64, pyramid: &MapErrorPyramid) -> std::io::Result<()> {
    let payload = pyramid.to_bytes();
    let mut bytes = Vec::with_capacity(28 + payload.len());
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    bytes.extend_from_slice(&key.to_le_bytes());
    bytes.extend_from_slice(&checksum(&payload).to_le_bytes());
    bytes.extend_from_slice(&payload);
    let tmp = path.with_extension("partial");
    std::fs::write(&tmp, &bytes)?;
    std::fs::rename(&tmp, path)
}

impl World {
    /// `world` (without error grids) with the map-error grids read from `cache_file` when it
    /// holds them for this surface and this `method` (the version of `compute`), else computed
    /// by `compute` and written there (a write failure is logged, not fatal).
    pub fn with_error_cache(
        mut world: World,
        cache_file: &Path,
        method: u64,
        compute: impl FnOnce(&mut World),
    ) -> Self {
        let t0 = std::time::Instant::now();
        let key = surface_key(&world, method);
        let t1 = std::time::Instant::now();
        if let (Some(dir), Some(cache)) = (&world.pages_dir, &world.page_cache) {
            let faults = &world.page_faults;
            match MapErrorPyramid::open_pages(dir, key, cache, faults) {
                Ok(p) => {
                    log::info!(
                        "surface error grids: key {:.2} s, {} paged grids opened in {:.2} s",
                        (t1 - t0).as_secs_f64(),
                        p.level_count(),
                        t1.elapsed().as_secs_f64()
                    );
                    world.map_error = p;
                    return world;
                }
                Err(e) => log::warn!(
                    "{e}; the surface error grids are read from {} or computed",
                    cache_file.display()
                ),
            }
        }
        match read(cache_file, key) {
            Ok(p) => {
                world.map_error = p;
                log::info!(
                    "surface error grids: key {:.2} s, read {:.2} s",
                    (t1 - t0).as_secs_f64(),
                    t1.elapsed().as_secs_f64()
                );
            }
            Err(why) => {
                if !matches!(why, CacheMiss::Missing) {
                    log::warn!(
                        "{}: not used ({why}); computing the surface error grids again",
                        cache_file.display()
                    );
                }
                compute(&mut world);
                if let Err(e) = write(cache_file, key, &world.map_error) {
                    log::warn!("{}: cannot write ({e})", cache_file.display());
                }
            }
        }
        world
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::precomputed::{self, MEASUREMENT_VERSION};
    use crate::test_maps::tiny_map;
    use worldgen::progress::Silent;

    /// The world as the stream opens it (the map's grids and the terrain's measured finest grid),
    /// with `cache` when given.
    fn opened(map: worldgen::Map, cache: Option<&Path>) -> World {
        precomputed::open(map, cache, &Silent)
    }

    fn temp_file(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("tvs-serr-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        dir.join("cache.bin")
    }

    #[test]
    fn the_cache_is_written_read_back_and_equals_a_fresh_computation() {
        let path = temp_file("roundtrip");
        let fresh = opened(tiny_map(), None);
        let first = opened(tiny_map(), Some(&path));
        assert_eq!(first.map_error.to_bytes(), fresh.map_error.to_bytes());
        let key = surface_key(&fresh, MEASUREMENT_VERSION);
        let read_back = read(&path, key).expect("valid cache file");
        assert_eq!(read_back.to_bytes(), fresh.map_error.to_bytes());
        // The map's own grids and the terrain's measured grid of a quarter height spacing.
        assert!(read_back.level_count() > World::new(tiny_map()).map_error.level_count());
        assert_eq!(read_back.finest_spacing_m(), 1.0);
        // Another measurement version does not use the file.
        assert!(matches!(
            read(&path, surface_key(&fresh, MEASUREMENT_VERSION + 1)),
            Err(CacheMiss::Stale)
        ));
        let _ = std::fs::remove_dir_all(path.parent().expect("dir"));
    }

    /// A file edited after writing (a stored bound lowered) is refused, recomputed and
    /// rewritten; a file computed from other heights is refused as stale.
    #[test]
    fn tampered_or_stale_cache_files_are_refused_and_recomputed() {
        let path = temp_file("tamper");
        let fresh = opened(tiny_map(), None);
        let key = surface_key(&fresh, MEASUREMENT_VERSION);
        write(&path, key, &fresh.map_error).expect("write");
        // Lower one stored error bound (the last f32 of the file, a finer-grid error).
        let mut bytes = std::fs::read(&path).expect("read");
        let n = bytes.len();
        let v = f32::from_le_bytes(bytes[n - 4..].try_into().expect("4 bytes"));
        assert!(v > 0.0, "the edited bound must change: {v}");
        bytes[n - 4..].copy_from_slice(&(v * 0.5).to_le_bytes());
        std::fs::write(&path, &bytes).expect("write tampered");
        assert!(matches!(read(&path, key), Err(CacheMiss::Damaged)));
        let reopened = opened(tiny_map(), Some(&path));
        assert_eq!(reopened.map_error.to_bytes(), fresh.map_error.to_bytes());
        assert!(read(&path, key).is_ok(), "the file was rewritten");
        // Other heights: the key differs, the file is stale for that map.
        let mut changed = tiny_map();
        let hg = changed.heights.grid_mut().expect("heights in memory");
        hg.set(10, 10, hg.get(10, 10) + 1.0);
        let changed_world = opened(changed.clone(), None);
        let changed_key = surface_key(&changed_world, MEASUREMENT_VERSION);
        assert_ne!(changed_key, key);
        assert!(matches!(read(&path, changed_key), Err(CacheMiss::Stale)));
        let reopened = opened(changed, Some(&path));
        assert_eq!(
            reopened.map_error.to_bytes(),
            changed_world.map_error.to_bytes()
        );
        // Truncated and foreign files are refused too.
        std::fs::write(&path, b"TVS-SERR").expect("write short");
        assert!(matches!(read(&path, key), Err(CacheMiss::Format)));
        let _ = std::fs::remove_dir_all(path.parent().expect("dir"));
    }
}
