//! `apps`: support shared by the binaries `flyover` (the viewer) and `nodebench` (the
//! benchmark): opening (or generating) a map, the one percentile rule their tables use, and
//! their heap on huge pages ([`heap`]); and the README's headline figures ([`headline`]).

use engine::surface::World;
use std::path::Path;

pub mod headline;
pub mod heap;
pub mod plot;

/// The map folder used when none is given.
pub const DEFAULT_MAP: &str = "maps/default";

/// A map that cannot be opened (or generated).
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    #[error("{0}")]
    Map(#[from] worldgen::MapError),
    #[error("generating the default map: {0}")]
    Generate(String),
}

/// Opens the map at `dir`; the default map folder is generated first when it is missing, and
/// generated again when it was written by an older version of the map format (it is ours to
/// regenerate; any other map gets the version error).
pub fn open_world(
    dir: &Path,
    progress: &dyn worldgen::progress::Progress,
) -> Result<World, OpenError> {
    let is_default = dir == Path::new(DEFAULT_MAP);
    let generate = |why: &str| -> Result<(), OpenError> {
        eprintln!(
            "{DEFAULT_MAP} {why}: generating the default map (8 km, seed 1, ~10 s) and baking it (~30 s) ..."
        );
        let map = worldgen::generate::generate(
            &worldgen::generate::GenerateParams::default(),
            progress,
            &mut Vec::new(),
        )
        .map_err(|e| OpenError::Generate(e.to_string()))?;
        map.write(dir)?;
        // Baked like `worldgen bake`: no open of it derives anything.
        let bake = |e: String| OpenError::Generate(format!("baking {}: {e}", dir.display()));
        worldgen::pages::bake::bake_all(&map, dir, progress).map_err(|e| bake(e.to_string()))?;
        bake_derived(map, dir, progress).map_err(|e| bake(e.to_string()))?;
        Ok(())
    };
    if is_default && !dir.join("map.toml").exists() {
        generate("not found")?;
    }
    let t0 = std::time::Instant::now();
    // A baked map serves its heights page by page through the world's page cache.
    let load = || {
        if worldgen::pages::bake::pages_dir(dir)
            .join("derived")
            .is_dir()
        {
            let paging = worldgen::pages::Paging::new(PAGE_CACHE_BUDGET_BYTES);
            worldgen::Map::load_paged(dir, &paging)
        } else {
            worldgen::Map::load(dir)
        }
    };
    match load() {
        Err(worldgen::MapError::UnknownVersion {
            found, supported, ..
        }) if is_default && found < i64::from(supported) => {
            generate("is from an older map format")?;
            Ok(world_of(load()?, dir, progress))
        }
        r => {
            log::info!(
                "map layers and lists read in {:.2} s",
                t0.elapsed().as_secs_f64()
            );
            Ok(world_of(r?, dir, progress))
        }
    }
}

/// The file in a map folder that keeps the surface error grids between runs (derived data:
/// checked against the map on every load, rewritten when it does not match).
pub const SURFACE_ERROR_CACHE: &str = ".surface_error.bin";

/// Maps with at least this many height cells (a 2 km map at 4 m) keep their surface error
/// grids in [`SURFACE_ERROR_CACHE`] and their light grids' sky pages beside it: the 8 km
/// default map has 4 M and computes the grids in about a minute on two cores (most of it the
/// 32 m nodes' bounds, [`engine::terrain::precomputed`]), a 2 km map in seconds; smaller maps
/// compute them in a fraction of a second and are left untouched.
pub const CACHE_MIN_CELLS: usize = 1 << 18;

/// Bytes of height, ground type, max-pyramid and surface error grid pages a baked map keeps resident (the
/// page cache's budget), and, under a budget of their own of the same size, bytes of decal
/// tiles.
pub const PAGE_CACHE_BUDGET_BYTES: usize = 128 << 20;

/// Bakes what the engine derives from the map in `dir` (`worldgen bake`), so that no open of
/// the map computes it: the max-pyramids of the region bounds and the ground amplitude grid as
/// page files under `pages/derived`, the decal field as a tile file there, the ground
/// materials' texture layers, and the surface error grids with the 32 m nodes' bounds as page
/// files there too (kept when they already hold them for this map and this engine; read from
/// [`SURFACE_ERROR_CACHE`] when it holds them, which is then removed). Returns whether the error grids were computed (false: they
/// were already baked or cached).
pub fn bake_derived(
    map: worldgen::Map,
    dir: &Path,
    progress: &dyn worldgen::progress::Progress,
) -> std::io::Result<bool> {
    use engine::surface::map_error_cache;
    use engine::terrain::precomputed;
    let mut world = World::without_error_grids(map);
    let pages = worldgen::pages::bake::pages_dir(dir);
    world
        .write_derived_pages(&pages, worldgen::pages::DEFAULT_PAGE_SIDE)
        .map_err(std::io::Error::other)?;
    engine::ground::material_layers::write_baked(&world.map, &pages)
        .map_err(std::io::Error::other)?;
    let path = dir.join(SURFACE_ERROR_CACHE);
    let key = map_error_cache::surface_key(&world, precomputed::MEASUREMENT_VERSION);
    let remove_whole_file = || match std::fs::remove_file(&path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
        _ => Ok(()),
    };
    let probe = std::sync::Arc::new(worldgen::pages::PageCache::new(1 << 20));
    let faults = std::sync::Arc::default();
    if engine::surface::map_error::MapErrorPyramid::open_pages(&pages, key, &probe, &faults).is_ok()
    {
        remove_whole_file()?;
        return Ok(false);
    }
    let computed = if let Ok(grids) = map_error_cache::read(&path, key) {
        world.map_error = grids;
        false
    } else {
        precomputed::compute(&mut world, progress);
        true
    };
    world
        .map_error
        .write_pages(&pages, worldgen::pages::DEFAULT_PAGE_SIDE, key)
        .map_err(std::io::Error::other)?;
    // The pages hold the grids now; the whole-map file would only double them on disk.
    remove_whole_file()?;
    Ok(computed)
}

/// Checks what `worldgen bake` derived for the map in `dir` (`worldgen check`): every page of
/// every page file under `pages/derived` matches its checksum, and the viewer's open of the map
/// reads every derived part from the bake (none missing, damaged or baked for another map or
/// engine). Returns a line saying so, or the error naming the file (and page) or the parts.
pub fn check_derived(dir: &Path) -> Result<String, String> {
    use engine::ground::material_layers;
    use engine::surface::map_error::MapErrorPyramid;
    use worldgen::pages::{PageFile, SampleKind};
    let pages = worldgen::pages::bake::pages_dir(dir);
    let derived = pages.join("derived");
    let mut files: Vec<_> = std::fs::read_dir(&derived)
        .map_err(|e| format!("{}: {e}", derived.display()))?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "pages"))
        .collect();
    files.sort();
    let mut page_count = 0u64;
    for path in &files {
        let file = PageFile::open(path).map_err(|e| e.to_string())?;
        let l = file.layout();
        for index in 0..l.page_count() {
            let (column, row) = l.column_row(index);
            match l.kind {
                SampleKind::F32 => file.read_page::<f32>(column, row).map(drop),
                SampleKind::U8 => file.read_page::<u8>(column, row).map(drop),
            }
            .map_err(|e| e.to_string())?;
        }
        page_count += u64::from(l.page_count());
    }
    let paging = worldgen::pages::Paging::new(PAGE_CACHE_BUDGET_BYTES);
    let map = worldgen::Map::load_paged(dir, &paging).map_err(|e| e.to_string())?;
    let mut stale: Vec<&str> = Vec::new();
    if map.heights.paged().is_none() {
        stale.push("heights pages");
    }
    let world = World::paged_without_error_grids(map, &pages, PAGE_CACHE_BUDGET_BYTES);
    stale.extend(&world.computed_at_open);
    let method = engine::terrain::precomputed::MEASUREMENT_VERSION;
    let key = engine::surface::map_error_cache::surface_key(&world, method);
    let faults = std::sync::Arc::default();
    if MapErrorPyramid::open_pages(&pages, key, &paging.cache, &faults).is_err() {
        stale.push("surface error grids");
    }
    let materials = material_layers::baked_path(&pages);
    if material_layers::read_baked(&materials, material_layers::key(&world.map)).is_err() {
        stale.push("ground materials");
    }
    if !stale.is_empty() {
        return Err(format!(
            "{}: derived data missing, damaged or baked for another map or engine: {} (logged above); bake it again with `worldgen bake {} --finish`",
            derived.display(),
            stale.join(", "),
            dir.display()
        ));
    }
    Ok(format!(
        "derived data: {} page files, {page_count} pages, every one matches its checksum; every part baked for this map and this engine",
        files.len()
    ))
}

fn world_of(map: worldgen::Map, dir: &Path, progress: &dyn worldgen::progress::Progress) -> World {
    let cells = (map.heights.width() - 1) * (map.heights.height() - 1);
    // Large maps keep the grids they compute; any map keeps what `worldgen bake` wrote.
    let cache = (cells >= CACHE_MIN_CELLS || dir.join(SURFACE_ERROR_CACHE).is_file())
        .then(|| dir.join(SURFACE_ERROR_CACHE));
    // A baked map's max-pyramids, decal field and amplitude grid are read instead of computed.
    let pages = worldgen::pages::bake::pages_dir(dir);
    let world = if pages.join("derived").is_dir() {
        World::paged_without_error_grids(map, &pages, PAGE_CACHE_BUDGET_BYTES)
    } else {
        World::without_error_grids(map)
    };
    let mut world = engine::terrain::precomputed::open_world(world, cache.as_deref(), progress);
    // The same maps keep the light grids' sky pages (engine::lighting::sky_pages), and any
    // map whose pages were baked (`flyover --bake-sky`).
    if cells >= CACHE_MIN_CELLS
        || dir
            .join(engine::lighting::sky_pages::SKY_PAGES_DIR)
            .is_dir()
    {
        world.derived_dir = Some(dir.to_path_buf());
    }
    world
}

/// The vertical fields of view the apps accept, degrees (the default is 60).
pub const FOV_DEG_RANGE: std::ops::RangeInclusive<f64> = 20.0..=120.0;

/// A vertical field of view in degrees from the command line: a number in [`FOV_DEG_RANGE`].
pub fn parse_fov_deg(s: &str) -> Result<f64, String> {
    let (lo, hi) = (FOV_DEG_RANGE.start(), FOV_DEG_RANGE.end());
    match s.trim().parse::<f64>() {
        Ok(v) if FOV_DEG_RANGE.contains(&v) => Ok(v),
        Ok(v) => Err(format!(
            "the field of view {v} degrees is outside {lo}..={hi} degrees (vertical)"
        )),
        Err(e) => Err(format!(
            "the field of view {s:?} is not a number of degrees ({e}); give {lo}..={hi}"
        )),
    }
}

/// A screen aspect ratio from the command line, `W:H` such as `16:9` or `21:9`: width over
/// height, each a number above 0, the ratio within 1:4..=8:1.
pub fn parse_aspect(s: &str) -> Result<f64, String> {
    let bad = |why: &str| format!("aspect {s:?}: {why}; give W:H such as 16:9 or 21:9");
    let (w, h) = s.split_once(':').ok_or_else(|| bad("no ':'"))?;
    let num = |v: &str| {
        v.trim()
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite() && *x > 0.0)
            .ok_or_else(|| bad(&format!("{v:?} is not a number above 0")))
    };
    let ratio = num(w)? / num(h)?;
    if (0.25..=8.0).contains(&ratio) {
        Ok(ratio)
    } else {
        Err(bad("the ratio must be within 1:4..=8:1"))
    }
}

/// The `p`-quantile (0..=1) of `sorted` (ascending): the element at index `round((n - 1) p)`,
/// so 0 is the minimum, 1 the maximum and 0.5 the median (for an even count, the upper of the
/// two middle elements: `round` goes half away from zero). NaN for an empty slice.
pub fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * p.clamp(0.0, 1.0)).round() as usize;
    sorted[i]
}

#[cfg(test)]
mod tests {
    use super::percentile;

    #[test]
    fn fields_of_view_and_aspects_outside_their_range_are_refused_with_their_name() {
        assert_eq!(super::parse_fov_deg("90"), Ok(90.0));
        for bad in ["0", "200", "nan", "NaN", "inf", "-60", "", "wide"] {
            let e = super::parse_fov_deg(bad).unwrap_err();
            assert!(e.contains("field of view"), "{bad}: {e}");
        }
        assert!((super::parse_aspect("21:9").unwrap() - 21.0 / 9.0).abs() < 1e-12);
        for bad in ["16/9", "0:9", "16:0", "nan:1", "100:1", "x:y"] {
            let e = super::parse_aspect(bad).unwrap_err();
            assert!(e.contains("aspect"), "{bad}: {e}");
        }
    }

    #[test]
    fn percentile_picks_the_nearest_rank() {
        let v: Vec<f64> = (0..=100).map(f64::from).collect();
        assert_eq!(percentile(&v, 0.0), 0.0);
        assert_eq!(percentile(&v, 0.5), 50.0);
        assert_eq!(percentile(&v, 0.95), 95.0);
        assert_eq!(percentile(&v, 0.99), 99.0);
        assert_eq!(percentile(&v, 1.0), 100.0);
        assert_eq!(percentile(&[3.0, 7.0], 0.5), 7.0);
        assert!(percentile(&[], 0.5).is_nan());
    }
}
