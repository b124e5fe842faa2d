//! Paged map layers: what the page cache serves equals the map's own layers sample for sample,
//! before and after eviction; a bake split into shares and subsets in any order writes the same
//! bytes as one bake; damaged, truncated and missing page files give errors that name the file
//! and the page, and the other pages still read.

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use std::path::Path;
use tests::tiny_map_dir;
use worldgen::Map;
use worldgen::pages::bake::{self, PageSet, Raster};
use worldgen::pages::{PageCache, PageError, PageFile};
use worldgen::progress::Silent;

/// Page side for the tests: small, so the 129-sample tiny map has many pages and ragged edges.
const SIDE: u32 = 16;

fn baked_tiny(into: &Path) -> Map {
    let map = Map::load(&tiny_map_dir()).expect("tiny map");
    bake::bake(&map, into, SIDE, &PageSet::All, &Silent).expect("bake");
    bake::finish(&map, into, &Silent).expect("finish");
    map
}

/// A copy of the tiny map in `into/map`, baked in its own folder (its files beside its pages),
/// and the map.
fn baked_copy_of_tiny(into: &Path) -> (std::path::PathBuf, Map) {
    let dir = into.join("map");
    tests::copy_dir(&tiny_map_dir(), &dir);
    let map = Map::load(&dir).expect("tiny map");
    bake::bake(&map, &dir, SIDE, &PageSet::All, &Silent).expect("bake");
    bake::finish(&map, &dir, &Silent).expect("finish");
    (dir, map)
}

/// Compares a region served by the cache with the same samples of the layer itself.
fn check_region(
    cache: &PageCache,
    layer: worldgen::pages::LayerId,
    raster: Raster<'_>,
    r: [u32; 4],
) {
    let [x0, y0, w, h] = r;
    match raster {
        Raster::F32(g) => {
            let got = cache.region::<f32>(layer, x0, y0, w, h).expect("region");
            for y in 0..h as usize {
                for x in 0..w as usize {
                    let want = g.get(x0 as usize + x, y0 as usize + y);
                    assert_eq!(
                        got.get(x, y).to_bits(),
                        want.to_bits(),
                        "sample ({x}, {y}) of {r:?}"
                    );
                }
            }
        }
        Raster::U8(g) => {
            let got = cache.region::<u8>(layer, x0, y0, w, h).expect("region");
            for y in 0..h as usize {
                for x in 0..w as usize {
                    assert_eq!(
                        got.get(x, y),
                        g.get(x0 as usize + x, y0 as usize + y),
                        "sample ({x}, {y}) of {r:?}"
                    );
                }
            }
        }
    }
}

fn random_region(rng: &mut SmallRng, w: u32, h: u32) -> [u32; 4] {
    let x0 = rng.random_range(0..w);
    let y0 = rng.random_range(0..h);
    let rw = rng.random_range(1..=(w - x0).min(3 * SIDE));
    let rh = rng.random_range(1..=(h - y0).min(3 * SIDE));
    [x0, y0, rw, rh]
}

#[test]
fn paged_layers_equal_the_map_layers_before_and_after_eviction() {
    let tmp = tempfile::tempdir().unwrap();
    let map = baked_tiny(tmp.path());
    let page_bytes = (SIDE * SIDE * 4) as usize;
    // A budget of three f32 pages: far less than a layer, so requests evict all the time.
    let cache = PageCache::new(3 * page_bytes);
    let mut rng = SmallRng::seed_from_u64(81);
    let mut layers = Vec::new();
    for (name, raster) in bake::rasters(&map).expect("heights in memory") {
        let file = PageFile::open(&bake::page_file_path(tmp.path(), &name)).expect("open");
        let (w, h) = (file.layout().width, file.layout().height);
        let id = cache.add(file);
        check_region(&cache, id, raster, [0, 0, w, h]);
        layers.push((id, raster, w, h));
    }
    let first = cache.stats();
    for _ in 0..400 {
        let (id, raster, w, h) = layers[rng.random_range(0..layers.len())];
        check_region(&cache, id, raster, random_region(&mut rng, w, h));
    }
    let s = cache.stats();
    assert!(
        s.evictions > 0 && s.page_ins > first.page_ins,
        "pages were not evicted and read again: {s:?}"
    );
    assert!(
        s.peak_resident_bytes <= 3 * page_bytes,
        "resident beyond the budget: {s:?}"
    );
    assert_eq!(s.failures, 0);
}

#[test]
fn a_bake_in_shares_and_subsets_in_any_order_writes_the_same_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let whole = tmp.path().join("whole");
    let split = tmp.path().join("split");
    let map = baked_tiny(&whole);
    // Some pages first, then the shares out of order, overlapping what is already baked.
    bake::bake(
        &map,
        &split,
        SIDE,
        &PageSet::Indices(vec![40, 3, 17]),
        &Silent,
    )
    .unwrap();
    bake::bake(
        &map,
        &split,
        SIDE,
        &PageSet::Share { part: 2, count: 3 },
        &Silent,
    )
    .unwrap();
    let missing = bake::missing_pages(&map, &split).unwrap();
    assert!(
        !missing.is_empty(),
        "two thirds of the pages cannot cover every layer"
    );
    // Finishing too early fails, names a missing page and moves nothing into place.
    let err = bake::finish(&map, &split, &Silent).expect_err("incomplete bake finished");
    assert!(matches!(err, PageError::NotBaked { .. }), "{err}");
    assert!(
        err.to_string().contains(".partial") && err.to_string().contains("page ("),
        "{err}"
    );
    for (name, _) in bake::rasters(&map).expect("heights in memory") {
        assert!(
            !bake::page_file_path(&split, &name).exists(),
            "{name} moved into place early"
        );
    }
    for part in [0, 1] {
        let share = PageSet::Share { part, count: 3 };
        bake::bake(&map, &split, SIDE, &share, &Silent).unwrap();
    }
    assert!(bake::missing_pages(&map, &split).unwrap().is_empty());
    assert_eq!(
        bake::finish(&map, &split, &Silent).unwrap(),
        bake::rasters(&map).expect("heights in memory").len()
    );
    let (a, b) = (bake::pages_dir(&whole), bake::pages_dir(&split));
    let names = tests::files_under(&a);
    assert_eq!(names, tests::files_under(&b), "different files");
    // The layers, the binary decal and tree lists and the record of sources.
    assert_eq!(
        names.len(),
        bake::rasters(&map).expect("heights in memory").len() + 3
    );
    for n in &names {
        assert!(
            std::fs::read(a.join(n)).unwrap() == std::fs::read(b.join(n)).unwrap(),
            "{n:?} differs"
        );
    }
}

#[test]
fn damaged_page_files_name_the_file_and_page_and_other_pages_still_read() {
    let tmp = tempfile::tempdir().unwrap();
    let map = baked_tiny(tmp.path());
    let heights = bake::page_file_path(tmp.path(), &map.manifest.heights.file);
    let layout = PageFile::open(&heights).unwrap().layout();
    let stride = layout.page_stride_bytes();
    let (pages_x, pages_y) = (layout.pages_per_row(), layout.page_rows());
    let page_at = |c: u32, r: u32| 64 + u64::from(r * pages_x + c) * stride;

    // A flipped byte inside page (2, 1): that page fails its checksum, its neighbour reads.
    let cache = PageCache::new(1 << 20);
    let mut bytes = std::fs::read(&heights).unwrap();
    bytes[(page_at(2, 1) + 100) as usize] ^= 0x10;
    std::fs::write(&heights, &bytes).unwrap();
    let id = cache.add(PageFile::open(&heights).unwrap());
    let err = cache
        .region::<f32>(id, 2 * SIDE, SIDE, 4, 4)
        .expect_err("damaged page read");
    let text = err.to_string();
    assert!(
        matches!(
            err,
            PageError::Checksum {
                column: 2,
                row: 1,
                ..
            }
        ),
        "{text}"
    );
    assert!(
        text.contains("heights.exr.pages") && text.contains("page (2, 1)"),
        "{text}"
    );
    check_region(
        &cache,
        id,
        Raster::F32(map.heights.grid().expect("heights in memory")),
        [SIDE, SIDE, SIDE, SIDE],
    );
    assert_eq!(cache.stats().failures, 1);

    // Truncated while open: the last page row fails with the file and page named, the first
    // row still reads; opened again, the file is refused whole with its expected length.
    let file = std::fs::OpenOptions::new()
        .write(true)
        .open(&heights)
        .unwrap();
    file.set_len(page_at(0, pages_y - 1) + 10).unwrap();
    let err = cache
        .region::<f32>(id, 0, (pages_y - 1) * SIDE, 1, 1)
        .expect_err("truncated page read");
    assert!(
        matches!(err, PageError::PageIo { column: 0, row, .. } if row == pages_y - 1),
        "{err}"
    );
    assert!(err.to_string().contains("heights.exr.pages"), "{err}");
    check_region(
        &cache,
        id,
        Raster::F32(map.heights.grid().expect("heights in memory")),
        [0, 0, SIDE, 2],
    );
    let err = PageFile::open(&heights).expect_err("truncated file opened");
    assert!(
        matches!(err, PageError::Length { .. }) && err.to_string().contains("truncated"),
        "{err}"
    );

    // Missing, and not a page file at all.
    std::fs::remove_file(&heights).unwrap();
    let err = PageFile::open(&heights).expect_err("missing file opened");
    assert!(
        matches!(err, PageError::Io { .. }) && err.to_string().contains("heights.exr.pages"),
        "{err}"
    );
    let ground = bake::page_file_path(tmp.path(), &map.manifest.ground.file);
    let mut bytes = std::fs::read(&ground).unwrap();
    bytes[9] ^= 1; // the version field: caught by the header checksum
    std::fs::write(&ground, &bytes).unwrap();
    let err = PageFile::open(&ground).expect_err("bad header opened");
    assert!(
        matches!(err, PageError::Header { .. }) && err.to_string().contains("ground.png.pages"),
        "{err}"
    );

    // A region of the wrong sample kind or outside the raster is refused, not served.
    let density = &map.densities[0].spec.file;
    let id = cache.add(PageFile::open(&bake::page_file_path(tmp.path(), density)).unwrap());
    assert!(matches!(
        cache.region::<f32>(id, 0, 0, 1, 1),
        Err(PageError::Request { .. })
    ));
    let w = map.densities[0].density.width() as u32;
    assert!(matches!(
        cache.region::<u8>(id, w - 1, 0, 2, 1),
        Err(PageError::Request { .. })
    ));
}

/// Rewrites `path` with `bytes`, keeping its modification time: a change that only a read of
/// the content can see.
fn rewrite_keeping_time(path: &Path, bytes: &[u8]) {
    let modified = std::fs::metadata(path).unwrap().modified().unwrap();
    std::fs::write(path, bytes).unwrap();
    let file = std::fs::File::options().write(true).open(path).unwrap();
    file.set_modified(modified).unwrap();
}

/// An open of a baked map reads its raster layers from their pages and its decal and tree
/// lists from their binary copies while the map's files hold what was baked, and decodes the
/// files themselves once they change or a page is damaged. That the bake is what is read is
/// shown by damaging the heights image and the lists behind an unchanged length and time:
/// decoding them would fail, yet the open gives the map as baked.
#[test]
fn a_baked_map_opens_from_its_pages_while_its_files_are_as_baked() {
    let tmp = tempfile::tempdir().unwrap();
    let (dir, map) = baked_copy_of_tiny(tmp.path());
    let exr = dir.join(&map.manifest.heights.file);
    let decals = dir.join(&map.manifest.decals.file);
    let trees = dir.join(&map.manifest.trees.file);
    let (exr_bytes, decal_bytes, tree_bytes) = (
        std::fs::read(&exr).unwrap(),
        std::fs::read(&decals).unwrap(),
        std::fs::read(&trees).unwrap(),
    );
    assert!(!map.trees.is_empty(), "the tiny map has large trees");
    let scrambled = |b: &[u8]| -> Vec<u8> {
        let mut out = b.to_vec();
        let mid = out.len() / 2;
        for v in &mut out[mid - 40..mid + 40] {
            *v ^= 0x5A;
        }
        out
    };

    // Damaged behind the same length and time: both are read from the bake.
    rewrite_keeping_time(&exr, &scrambled(&exr_bytes));
    rewrite_keeping_time(&decals, &scrambled(&decal_bytes));
    rewrite_keeping_time(&trees, &scrambled(&tree_bytes));
    assert!(
        worldgen::map::layers::read_heights(&dir, &map.manifest).is_err()
            && worldgen::map::lists::read_decals(&decals, &map.manifest).is_err()
            && worldgen::map::lists::read_trees(&trees, &map.manifest).is_err(),
        "the damage must be visible to a decode"
    );
    assert!(
        Map::load(&dir).expect("opened from the bake") == map,
        "the open from the bake differs from the map"
    );

    // The same bytes with a new time (a copy): the content is read once, matches, and the new
    // time is remembered for the next open.
    std::fs::write(&exr, &exr_bytes).unwrap();
    std::fs::write(&decals, &decal_bytes).unwrap();
    std::fs::write(&trees, &tree_bytes).unwrap();
    let checked = dir.join(worldgen::pages::sources::CHECKED_FILE);
    let before = std::fs::read_to_string(&checked).unwrap();
    assert!(Map::load(&dir).unwrap() == map);
    let after = std::fs::read_to_string(&checked).unwrap();
    assert_ne!(before, after, "the new times are remembered");
    rewrite_keeping_time(&exr, &scrambled(&exr_bytes));
    assert!(
        Map::load(&dir).unwrap() == map,
        "a remembered time is trusted without reading the file"
    );
    std::fs::write(&exr, &exr_bytes).unwrap();

    // A damaged page: the layer is decoded from its own file instead, the same map.
    let page_file = bake::page_file_path(&dir, &map.manifest.heights.file);
    let mut pages = std::fs::read(&page_file).unwrap();
    pages[100] ^= 1;
    std::fs::write(&page_file, &pages).unwrap();
    assert!(Map::load(&dir).unwrap() == map);

    // Changed heights: the stale pages are not used; the open gives the new heights.
    let mut changed = map.heights.grid().expect("heights in memory").clone();
    changed.set(7, 9, changed.get(7, 9) + 1.5);
    worldgen::map::layers::write_heights(&exr, &changed).unwrap();
    let reopened = Map::load(&dir).unwrap();
    assert_eq!(reopened.heights.get(7, 9), map.heights.get(7, 9) + 1.5);
    assert!(reopened.decals == map.decals);
}

/// The binary tree list is checked against the manifest like the CSV: with the species its
/// trees use no longer named in map.toml, the open of the baked map fails naming the list and
/// the tree, as the open of the unbaked map fails naming its line.
#[test]
fn a_baked_tree_list_is_checked_against_the_manifest() {
    let tmp = tempfile::tempdir().unwrap();
    let (dir, map) = baked_copy_of_tiny(tmp.path());
    let first = map
        .trees
        .iter()
        .position(|t| t.species == 1)
        .expect("a tree of species 1");
    let toml = dir.join("map.toml");
    let text = std::fs::read_to_string(&toml).unwrap();
    let start = text.find("tree_species = [").expect("the species list");
    let end = start + text[start..].find(']').expect("the list's end") + 1;
    let one_species = format!(
        "{}tree_species = [\"pine\"]{}",
        &text[..start],
        &text[end..]
    );
    std::fs::write(&toml, one_species).unwrap();
    let refused = |what: &str| match Map::load(&dir) {
        Ok(_) => panic!("{what}: the map opened with species 1 not named"),
        Err(e) => e.to_string(),
    };
    let msg = refused("baked");
    for w in ["trees.csv", &format!("tree[{first}]"), "species 1"] {
        assert!(msg.contains(w), "error lacks {w:?}: {msg}");
    }
    std::fs::remove_dir_all(bake::pages_dir(&dir)).unwrap();
    let msg = refused("unbaked");
    for w in ["trees.csv", "line ", "species 1"] {
        assert!(msg.contains(w), "error lacks {w:?}: {msg}");
    }
}

/// Heights served sample by sample from their page file (through the threads' pages at hand
/// and a cache of three pages) equal the map's heights bit for bit, read by several threads in
/// different orders; a damaged page is served as the fill value, reported once with its file
/// and page, and not read again; the other pages still read; a map loaded paged from its bake
/// opens with paged heights equal to the loaded ones.
#[test]
fn paged_heights_equal_the_map_heights_and_a_damaged_page_serves_the_fill() {
    use worldgen::map::Heights;
    use worldgen::pages::{PagedRaster, Paging};
    let tmp = tempfile::tempdir().unwrap();
    let map = baked_tiny(tmp.path());
    let grid = map.heights.grid().expect("heights in memory").clone();
    let path = bake::page_file_path(tmp.path(), &map.manifest.heights.file);
    let page_bytes = (SIDE * SIDE * 4) as usize;
    let paging = Paging::new(3 * page_bytes);
    let paged = PagedRaster::<f32>::new(&paging, PageFile::open(&path).unwrap(), 0.0).unwrap();
    let (w, h) = (grid.width(), grid.height());
    std::thread::scope(|s| {
        for t in 0..3u64 {
            let (paged, grid) = (&paged, &grid);
            s.spawn(move || {
                let mut rng = SmallRng::seed_from_u64(t);
                for _ in 0..40_000 {
                    let (x, y) = (rng.random_range(0..w), rng.random_range(0..h));
                    assert_eq!(paged.get(x, y).to_bits(), grid.get(x, y).to_bits());
                    // A stencil's block: inside one page (one look-up) or across pages.
                    let (x, y) = (rng.random_range(0..w - 3), rng.random_range(0..h - 3));
                    let block = paged.block::<4>(x, y);
                    for (j, row) in block.iter().enumerate() {
                        for (i, v) in row.iter().enumerate() {
                            assert_eq!(v.to_bits(), grid.get(x + i, y + j).to_bits());
                        }
                    }
                }
            });
        }
    });
    let s = paging.cache.stats();
    assert!(
        s.evictions > 0 && s.peak_resident_bytes <= 3 * page_bytes,
        "{s:?}"
    );
    assert!(paging.faults.list().is_empty());

    // Page (2, 1) damaged: a new raster (no page at hand) serves its samples as the fill.
    let layout = PageFile::open(&path).unwrap().layout();
    let offset = worldgen::pages::file::HEADER_BYTES
        + u64::from(layout.index(2, 1)) * layout.page_stride_bytes();
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[offset as usize + 12] ^= 0x10;
    std::fs::write(&path, &bytes).unwrap();
    let paging = Paging::new(3 * page_bytes);
    let paged = PagedRaster::<f32>::new(&paging, PageFile::open(&path).unwrap(), 0.0).unwrap();
    paged.set_fill(1234.5);
    let side = SIDE as usize;
    for y in 0..h {
        for x in 0..w {
            let expected = if (x / side, y / side) == (2, 1) {
                1234.5
            } else {
                grid.get(x, y)
            };
            assert_eq!(paged.get(x, y).to_bits(), expected.to_bits(), "({x}, {y})");
        }
    }
    // Blocks inside and across the damaged page's edges serve the fill at its samples alone.
    for (x, y) in [
        (2 * side + 5, side + 7),
        (2 * side - 2, side - 1),
        (3 * side - 2, 2 * side - 3),
    ] {
        let block = paged.block::<4>(x, y);
        for (j, row) in block.iter().enumerate() {
            for (i, v) in row.iter().enumerate() {
                let (sx, sy) = (x + i, y + j);
                let expected = if (sx / side, sy / side) == (2, 1) {
                    1234.5
                } else {
                    grid.get(sx, sy)
                };
                assert_eq!(v.to_bits(), expected.to_bits(), "({sx}, {sy})");
            }
        }
    }
    let faults = paging.faults.list();
    assert_eq!(faults.len(), 1, "{faults:?}");
    assert!(
        faults[0].contains("heights.exr.pages") && faults[0].contains("page (2, 1)"),
        "{faults:?}"
    );
    assert_eq!(
        paging.cache.stats().failures,
        1,
        "the damaged page was read again"
    );

    // The paged open of a baked copy of the map.
    let dir = tmp.path().join("map");
    tests::copy_dir(&tiny_map_dir(), &dir);
    bake::bake(&map, &dir, SIDE, &PageSet::All, &Silent).unwrap();
    bake::finish(&map, &dir, &Silent).unwrap();
    let opened = Map::load_paged(&dir, &Paging::new(4 * page_bytes)).unwrap();
    let Heights::Paged(p) = &opened.heights else {
        panic!("the heights of a baked map were not paged");
    };
    assert_eq!(p.key(), map.heights.key());
    for y in 0..h {
        for x in 0..w {
            assert_eq!(
                p.get(x, y).to_bits(),
                grid.get(x, y).to_bits(),
                "({x}, {y})"
            );
        }
    }
}
