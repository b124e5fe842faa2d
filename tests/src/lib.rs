//! End-to-end test crate: worldgen -> map folder -> engine. Shared helpers for the tests in
//! `tests/tests/`.

pub mod gltf_fixture;
pub mod mutate;
pub mod readers;

use std::path::{Path, PathBuf};

/// The workspace root (the folder holding `Cargo.toml`, `maps/`, `shaders/`).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

/// `tests/data` in the repository: the real elevation data and meshes the tests read (see its
/// README for where each file comes from and under which terms it is shared).
pub fn test_data_dir() -> PathBuf {
    workspace_root().join("tests").join("data")
}

/// True when running under CI (`CI` set to anything but empty/"false"/"0").
pub fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| !v.is_empty() && v != "false" && v != "0")
}

/// Where skipped tests write their reason (one line each); `tests/run.sh` prints the file in
/// its summary, since the test runner hides a passing test's output.
pub fn skips_file() -> PathBuf {
    std::env::var_os("TESTS_SKIPS_FILE").map_or_else(
        || workspace_root().join("target").join("test-skips.txt"),
        PathBuf::from,
    )
}

/// Records that the calling test skipped its checks, and why (printed and appended to
/// [`skips_file`]). Callers fail instead of skipping in CI.
pub fn skip(test: &str, why: &str) {
    use std::io::Write as _;
    println!("skipping {test}: {why}");
    let line = format!("{test}: {why}\n");
    let appended = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(skips_file())
        .and_then(|mut f| f.write_all(line.as_bytes()));
    if let Err(e) = appended {
        println!(
            "(could not record the skip in {}: {e})",
            skips_file().display()
        );
    }
}

/// Path of a file in [`test_data_dir`]. The files are committed, so a missing one fails the
/// calling test with the path it looked for (a clone without them is broken, not a reason to skip).
pub fn test_data(rel: &str) -> PathBuf {
    let p = test_data_dir().join(rel);
    assert!(
        p.is_file(),
        "test data {} is missing: it is committed under tests/data",
        p.display()
    );
    p
}

/// The committed tiny test map.
pub fn tiny_map_dir() -> PathBuf {
    workspace_root().join("maps").join("tiny")
}

/// Parameters that produced the committed tiny map (see maps/README.md).
pub fn tiny_map_params() -> worldgen::generate::GenerateParams {
    worldgen::generate::GenerateParams {
        name: "tiny".into(),
        seed: 7,
        size_m: 512.0,
        spacing_m: 4.0,
        threads: 0,
    }
}

/// Parameters of the 2 km map the ground-patch tests use.
pub fn patches_map_params() -> worldgen::generate::GenerateParams {
    worldgen::generate::GenerateParams {
        name: "patches".into(),
        seed: 16,
        size_m: 2048.0,
        spacing_m: 4.0,
        threads: 0,
    }
}

/// A map generated in memory (no progress output).
pub fn generated(p: &worldgen::generate::GenerateParams) -> worldgen::Map {
    worldgen::generate::generate(p, &worldgen::progress::Silent, &mut Vec::new()).expect("generate")
}

/// `map` with its heights and ground types served page by page ([`worldgen::map::MapRaster::Paged`])
/// from page files of `page_side` written as `dir/heights.pages` and `dir/ground.pages`, through
/// `paging`'s cache.
pub fn with_paged_layers(
    mut map: worldgen::Map,
    dir: &Path,
    page_side: u32,
    paging: &worldgen::pages::Paging,
) -> worldgen::Map {
    use worldgen::pages::{CacheSample, PageFile, PagedRaster, bake};
    fn paged<T: CacheSample + std::fmt::Debug>(
        raster: &worldgen::map::MapRaster<T>,
        path: &Path,
        page_side: u32,
        paging: &worldgen::pages::Paging,
    ) -> worldgen::map::MapRaster<T> {
        let grid = raster.grid().expect("the layer in memory");
        bake::write_grid(path, grid, page_side, raster.key()).expect("write the pages");
        let file = PageFile::open(path).expect("open the pages");
        worldgen::map::MapRaster::Paged(PagedRaster::new(paging, file, T::zero()).expect("pages"))
    }
    map.heights = paged(&map.heights, &dir.join("heights.pages"), page_side, paging);
    map.ground = paged(&map.ground, &dir.join("ground.pages"), page_side, paging);
    map
}

/// Copies every file under folder `from` (subfolders included) into a new folder `to`.
pub fn copy_dir(from: &Path, to: &Path) {
    for rel in files_under(from) {
        let dst = to.join(&rel);
        if let Some(parent) = dst.parent() {
            std::fs::create_dir_all(parent).expect("create copy folder");
        }
        std::fs::copy(from.join(&rel), dst).expect("copy file");
    }
}

/// Every file under `dir` (paths relative to it, sorted), subfolders included.
pub fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).expect("read dir") {
            let p = e.expect("entry").path();
            if p.is_dir() {
                stack.push(p);
            } else if let Ok(rel) = p.strip_prefix(dir) {
                out.push(rel.to_path_buf());
            }
        }
    }
    out.sort();
    out
}

/// FNV-1a over the relative paths and bytes of every file under a folder, in path order.
pub fn hash_dir(dir: &Path) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut feed = |bytes: &[u8]| {
        for &b in bytes {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    };
    for n in files_under(dir) {
        feed(n.as_os_str().as_encoded_bytes());
        feed(&std::fs::read(dir.join(&n)).expect("read file"));
    }
    h
}

/// Terrain test helpers: worlds with hard surfaces, dense error measurement, ray casting.
pub mod terrain {
    use engine::surface::world::World;
    use engine::terrain::mesh::NodeMesh;
    use engine::terrain::quadtree::QuadTree;
    use glam::DVec3;
    use worldgen::Map;

    /// A camera over the map from `(seed, i)`: position in the inner 90%, log-uniform height
    /// above the ground in `[min_above_m, max_above_m]`, any heading, looking down 0.05-1.05 rad.
    pub fn random_camera(
        world: &World,
        seed: u64,
        i: i64,
        min_above_m: f64,
        max_above_m: f64,
        viewport: [u32; 2],
    ) -> engine::camera::Camera {
        let o = world.origin_m();
        let s = world.size_m();
        let x = o[0] + s[0] * (0.05 + 0.9 * worldgen::noise::unit3(seed, i, 0));
        let y = o[1] + s[1] * (0.05 + 0.9 * worldgen::noise::unit3(seed, i, 1));
        // Log-uniform height above the ground.
        let above =
            min_above_m * (max_above_m / min_above_m).powf(worldgen::noise::unit3(seed, i, 2));
        let z = world.height_m(x, y) + above;
        let yaw = std::f64::consts::TAU * worldgen::noise::unit3(seed, i, 3);
        let pitch = -(0.05 + 1.0 * worldgen::noise::unit3(seed, i, 4));
        let dir = DVec3::new(
            yaw.cos() * pitch.cos(),
            yaw.sin() * pitch.cos(),
            pitch.sin(),
        );
        let p = DVec3::new(x, y, z);
        engine::camera::Camera::look_at(p, p + dir, 60f64.to_radians(), viewport)
    }

    /// `map` opened as the stream opens it: the map-error grids and the 32 m nodes' bounds
    /// measured once ([`engine::terrain::precomputed`]), no cache file.
    pub fn world_of(map: Map) -> World {
        engine::terrain::precomputed::open(map, None, &worldgen::progress::Silent)
    }

    /// The committed tiny map as a world.
    pub fn tiny_world() -> World {
        world_of(Map::load(&super::tiny_map_dir()).expect("tiny map loads"))
    }

    /// A generated 2 km map (seed 16, 4 m spacing), large enough to hold every kind of
    /// worldgen's ground patches (fields, dirt, rock outcrops), as a world.
    pub fn patches_world() -> World {
        world_of(super::generated(&super::patches_map_params()))
    }

    /// The tiny map with hard cases burned into its heights: a 100 m vertical cliff (between
    /// two neighbouring samples) across the map, single-sample spikes of +50 m and -30 m, and a
    /// perfectly flat 0 m sea (water ground, so no detail) in the south-east quarter. Heights
    /// and ground share the 4 m spacing in the tiny map.
    pub fn cliff_world() -> World {
        let mut map = Map::load(&super::tiny_map_dir()).expect("tiny map loads");
        let (w, h) = (map.heights.width(), map.heights.height());
        for y in 0..h {
            for x in 0..w {
                let mut z = map.heights.get(x, y);
                if x >= w / 2 && y < h / 2 {
                    z = 0.0;
                    map.ground.grid_mut().expect("ground in memory").set(
                        x,
                        y,
                        worldgen::classify::WATER,
                    );
                } else if x >= 40 {
                    z += 100.0;
                }
                let hg = map.heights.grid_mut().expect("heights in memory");
                hg.set(x, y, z);
            }
        }
        let hg = map.heights.grid_mut().expect("heights in memory");
        hg.set(20, 90, hg.get(20, 90) + 50.0);
        let hg = map.heights.grid_mut().expect("heights in memory");
        hg.set(100, 100, hg.get(100, 100) - 30.0);
        world_of(map)
    }

    /// A world with its origin moved by (dx, dy) metres.
    pub fn shifted(world: &World, dx: f64, dy: f64) -> World {
        let mut map = world.map.clone();
        map.manifest.origin_m = [map.manifest.origin_m[0] + dx, map.manifest.origin_m[1] + dy];
        for d in &mut map.decals {
            for p in &mut d.points {
                p[0] += dx;
                p[1] += dy;
            }
        }
        for t in &mut map.trees {
            t.x_m += dx;
            t.y_m += dy;
        }
        for b in &mut map.buildings {
            b.x_m += dx;
            b.y_m += dy;
        }
        world_of(map)
    }

    pub fn tree_of(world: &World) -> QuadTree {
        QuadTree::new(world.origin_m(), world.size_m())
    }

    /// Builds a node mesh the way the engine does (tiles for small nodes).
    pub use engine::terrain::mesh::build_with_tiles as build_mesh;

    /// The meshes of every selected node as drawn (each with its decimation), by key.
    pub fn build_selection(
        world: &World,
        tree: &QuadTree,
        cache: &mut engine::terrain::bounds::BoundsCache,
        tiles: &mut engine::terrain::tiles::TileCache,
        sel: &engine::terrain::select::Selection,
    ) -> std::collections::HashMap<engine::terrain::quadtree::NodeKey, NodeMesh> {
        sel.nodes
            .iter()
            .map(|s| {
                let m = build_mesh(world, tree, cache, tiles, s.key);
                let m = if s.decimation > 0 {
                    m.decimated(s.decimation)
                } else {
                    m
                };
                (s.key, m)
            })
            .collect()
    }

    /// The true largest |mesh - surface| of a node, measured on a dense lattice of 10 points
    /// per mesh quad (not aligned with the engine's 4-per-quad check lattice), plus the largest
    /// distance of the surface outside the node's height range.
    pub fn measure_true_error(world: &World, tree: &QuadTree, m: &NodeMesh) -> (f64, f64) {
        engine::measure::true_node_error(world, tree, m, 10)
    }

    /// [`measure_true_error`] per bound block of the node.
    pub fn measure_true_block_errors(
        world: &World,
        tree: &QuadTree,
        m: &NodeMesh,
    ) -> [(f64, f64); engine::terrain::bounds::BLOCKS] {
        engine::measure::true_block_errors(world, tree, m, 10)
    }

    /// Ray / triangle intersection distance (two-sided, Moller-Trumbore), in f64.
    pub fn ray_triangle(o: DVec3, d: DVec3, a: DVec3, b: DVec3, c: DVec3) -> Option<f64> {
        let e1 = b - a;
        let e2 = c - a;
        let p = d.cross(e2);
        let det = e1.dot(p);
        if det.abs() < 1e-12 {
            return None;
        }
        let inv = 1.0 / det;
        let t0 = o - a;
        let u = t0.dot(p) * inv;
        if !(-1e-9..=1.0 + 1e-9).contains(&u) {
            return None;
        }
        let q = t0.cross(e1);
        let v = d.dot(q) * inv;
        if v < -1e-9 || u + v > 1.0 + 1e-9 {
            return None;
        }
        let t = e2.dot(q) * inv;
        (t > 0.0).then_some(t)
    }

    /// Nearest hit of a ray with a node mesh (surface and skirts), world space.
    pub fn ray_mesh(o: DVec3, d: DVec3, m: &NodeMesh) -> Option<f64> {
        let org = DVec3::new(m.origin_m[0], m.origin_m[1], 0.0);
        let v = |i: u32| {
            let p = m.positions[i as usize];
            org + DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))
        };
        let mut best: Option<f64> = None;
        for t in m.indices.chunks_exact(3) {
            if let Some(h) = ray_triangle(o, d, v(t[0]), v(t[1]), v(t[2])) {
                best = Some(best.map_or(h, |b: f64| b.min(h)));
            }
        }
        best
    }
}

/// Unit direction of the ray through the centre of pixel (`px`, `py`) of `cam` (row 0 at the
/// top), as the renderer's projection places it.
pub fn pixel_ray(cam: &engine::camera::Camera, px: u32, py: u32) -> glam::DVec3 {
    let [w, h] = cam.viewport_px;
    let ty = (cam.fovy_rad * 0.5).tan();
    let sx = ((f64::from(px) + 0.5) / f64::from(w) * 2.0 - 1.0) * ty * cam.aspect();
    let sy = (1.0 - (f64::from(py) + 0.5) / f64::from(h) * 2.0) * ty;
    (cam.forward + cam.right() * sx + cam.up * sy).normalize()
}

/// Where the ray through pixel (`px`, `py`) first meets the map's finest surface, if it does
/// more than 2 m inside the map's border (ray-marched with steps no longer than half the
/// height above the surface, so the point is within 5 cm above it).
pub fn ground_hit(
    world: &engine::surface::World,
    cam: &engine::camera::Camera,
    px: u32,
    py: u32,
) -> Option<glam::DVec3> {
    let dir = pixel_ray(cam, px, py);
    let (o, s) = (world.origin_m(), world.size_m());
    let mut t = 0.0;
    for _ in 0..4000 {
        let p = cam.position_m + dir * t;
        // A few metres of margin inside the border: the skirts there may be seen edge-on.
        if p.x < o[0] + 2.0
            || p.y < o[1] + 2.0
            || p.x > o[0] + s[0] - 2.0
            || p.y > o[1] + s[1] - 2.0
        {
            return None;
        }
        let above = p.z - world.height_m(p.x, p.y);
        if above <= 0.0 {
            return Some(p);
        }
        t += (above * 0.5).max(0.05);
    }
    None
}

/// GPU helpers: a headless device (lavapipe here and in CI) and a settled viewer.
pub mod gpu {
    use engine::camera::Camera;
    use engine::render::{COLOR_FORMAT, Gpu, Target};
    use engine::stream::StreamSettings;
    use engine::viewer::{FrameStats, Viewer};

    /// A headless GPU device, or None with a printed reason outside CI. In CI a missing adapter
    /// fails the test (the test script installs lavapipe).
    pub fn device() -> Option<Gpu> {
        match Gpu::new_headless() {
            Ok(g) => Some(g),
            Err(e) => {
                assert!(
                    !super::in_ci(),
                    "CI must have a GPU adapter (lavapipe): {e}"
                );
                super::skip("GPU test", &e.to_string());
                None
            }
        }
    }

    /// A device with multi-draw indirect and a first instance (merged draws), or None after
    /// recording why `test` skips; CI's adapter (lavapipe) has it, so CI fails instead.
    pub fn multi_draw_device(test: &str) -> Option<Gpu> {
        let g = device()?;
        if !g.multi_draw {
            assert!(
                !super::in_ci(),
                "CI's adapter (lavapipe) has multi-draw indirect with a first instance"
            );
            super::skip(test, "no multi-draw indirect on this adapter");
            return None;
        }
        Some(g)
    }

    /// A viewer of `world` at threshold `tau_px`, one worker.
    pub fn viewer(g: &Gpu, world: engine::surface::World, tau_px: f64) -> Viewer {
        Viewer::new(
            g,
            COLOR_FORMAT,
            world,
            StreamSettings {
                workers: 1,
                tau_px,
                ..StreamSettings::default()
            },
        )
    }

    /// A viewer of the tiny map at threshold `tau_px`, one worker.
    pub fn tiny_viewer(g: &Gpu, tau_px: f64) -> Viewer {
        viewer(g, super::terrain::tiny_world(), tau_px)
    }

    /// Renders one frame into `target` and waits for the GPU.
    pub fn frame(g: &Gpu, v: &mut Viewer, target: &Target, cam: &Camera, dt_s: f64) -> FrameStats {
        v.render_offscreen(g, target, cam, dt_s)
            .expect("GPU finishes the frame")
    }

    /// Renders frames until every wanted node is shown, no job is left and every node texture
    /// is made, then a few more so fades end. Returns the last frame's statistics.
    pub fn settle(g: &Gpu, v: &mut Viewer, target: &Target, cam: &Camera) -> FrameStats {
        for _ in 0..20_000 {
            let st = frame(g, v, target, cam, 0.05);
            if v.streamer.in_flight() == 0 && st.pop_debt_nodes == 0 && v.textures_pending() == 0 {
                // Light grids are computed in the background: every frame from here draws with
                // all the grids its nodes hold (wait for that event, then draw).
                let mut last = st;
                for _ in 0..10 {
                    if let Some(l) = v.lighting() {
                        l.wait_idle();
                    }
                    last = frame(g, v, target, cam, 0.1);
                }
                return last;
            }
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        panic!("the viewer did not settle");
    }
}
