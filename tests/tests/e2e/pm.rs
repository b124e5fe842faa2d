//! Progressive meshes: hard meshes collapse to one vertex with valid index lists at
//! every level, per-instance edits agree with the one-pass rebuild, the stored error bounds an
//! independent measurement on the shared meshes, files are deterministic and malformed inputs
//! name the file and the problem.

use glam::DVec3;
use std::path::Path;
use worldgen::pm::build::{FLAG_FLIPPED, FLAG_ISOLATED};
use worldgen::pm::measure::level_soup;
use worldgen::pm::mesh::Corner;
use worldgen::pm::{CostKind, PmEdits, PmInstance, PmMesh, TriMesh, file, obj};

fn corner(p: [f32; 3]) -> Corner {
    Corner {
        position: p,
        uv: None,
        normal: None,
    }
}

fn tri(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> [Corner; 3] {
    [corner(a), corner(b), corner(c)]
}

/// A bumpy open grid of `n` x `n` quads (open border on all four sides).
fn grid(n: usize) -> Vec<[Corner; 3]> {
    let h = |i: usize, j: usize| [i as f32, j as f32, ((i * 7 + j * 3) % 5) as f32 * 0.3];
    let mut out = Vec::new();
    for i in 0..n {
        for j in 0..n {
            out.push(tri(h(i, j), h(i + 1, j), h(i + 1, j + 1)));
            out.push(tri(h(i, j), h(i + 1, j + 1), h(i, j + 1)));
        }
    }
    out
}

fn tetrahedron(o: [f32; 3]) -> Vec<[Corner; 3]> {
    let p = |x: f32, y: f32, z: f32| [o[0] + x, o[1] + y, o[2] + z];
    let (a, b, c, d) = (p(0., 0., 0.), p(1., 0., 0.), p(0., 1., 0.), p(0., 0., 1.));
    vec![tri(a, c, b), tri(a, b, d), tri(b, c, d), tri(c, a, d)]
}

/// The hard cases of the issue, by name.
fn hard_meshes() -> Vec<(&'static str, Vec<[Corner; 3]>)> {
    let o = [0.0, 0.0, 0.0];
    let x = [1.0, 0.0, 0.0];
    let y = [0.0, 1.0, 0.0];
    let xy = [1.0, 1.0, 0.0];
    let mut seam = grid(4);
    // Give the left half and right half different UVs: a seam down the middle.
    for t in &mut seam {
        for c in t.iter_mut() {
            let side = if c.position[0] < 2.0 { 0.0 } else { 0.5 };
            c.uv = Some([side + c.position[0] * 0.1, c.position[1] * 0.1]);
        }
    }
    let mut disconnected = tetrahedron([0.0; 3]);
    disconnected.extend(tetrahedron([5.0, 0.0, 0.0]));
    disconnected.extend(tetrahedron([0.0, 9.0, 1.0]));
    disconnected.push(tri([20.0, 0.0, 0.0], [21.0, 0.0, 0.0], [20.0, 1.0, 0.0]));
    vec![
        ("single triangle", vec![tri(o, x, y)]),
        ("two-triangle quad", vec![tri(o, x, xy), tri(o, xy, y)]),
        (
            "non-manifold edge (three triangles on one edge)",
            vec![
                tri(o, x, y),
                tri(x, o, [0.5, -1.0, 0.0]),
                tri(o, x, [0.5, 0.0, 1.0]),
            ],
        ),
        (
            "zero-area and degenerate triangles",
            vec![
                tri(o, x, y),
                tri(o, x, [2.0, 0.0, 0.0]),
                tri(o, o, x),
                tri(x, xy, y),
            ],
        ),
        (
            "duplicate triangles and vertices",
            vec![
                tri(o, x, y),
                tri(o, x, y),
                tri(x, y, o),
                tri(y, x, xy),
                tri(y, x, xy),
            ],
        ),
        ("disconnected parts", disconnected),
        ("open borders", grid(6)),
        ("UV seam", seam),
    ]
}

fn positions_of(pm: &PmMesh, indices: &[u32]) -> Vec<[u32; 3]> {
    indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]].map(|w| pm.wedge_position[w as usize]))
        .collect()
}

fn normal(pm: &PmMesh, t: [u32; 3]) -> DVec3 {
    let p = t.map(|i| {
        let q = pm.positions[i as usize];
        DVec3::new(q[0] as f64, q[1] as f64, q[2] as f64)
    });
    (p[1] - p[0]).cross(p[2] - p[0])
}

/// Every level of `pm`: indices in range and drawing no degenerate triangle; between
/// neighbouring levels, a collapse not flagged as flipping turns no surviving triangle over.
pub(crate) fn check_levels(name: &str, pm: &PmMesh) {
    pm.validate()
        .unwrap_or_else(|(f, m)| panic!("{name}: invalid PM: {f}: {m}"));
    assert_eq!(pm.triangles_at(1), 0, "{name}: level 1 draws nothing");
    let mut idx = Vec::new();
    let mut prev: Option<Vec<[u32; 3]>> = None;
    for p in (1..=pm.level_count()).rev() {
        pm.indices_at(p, &mut idx);
        assert_eq!(idx.len(), pm.triangles_at(p) * 3);
        let live = pm.wedges_at(p) as u32;
        assert!(
            idx.iter().all(|&w| w < live),
            "{name}: level {p} names a dead wedge"
        );
        let tris = positions_of(pm, &idx);
        for t in &tris {
            assert!(
                t[0] != t[1] && t[1] != t[2] && t[0] != t[2],
                "{name}: level {p} draws a degenerate triangle {t:?}"
            );
        }
        if let Some(finer) = &prev {
            let flags = pm.levels[p].flags;
            if flags & FLAG_FLIPPED == 0 {
                for (k, t) in tris.iter().enumerate() {
                    let (n0, n1) = (normal(pm, finer[k]), normal(pm, *t));
                    if n0.length_squared() > 1e-20 {
                        assert!(
                            n0.dot(n1) > 0.0,
                            "{name}: collapse {} -> {p} flips triangle {k} without the flag",
                            p + 1
                        );
                    }
                }
            }
        }
        prev = Some(tris);
    }
}

/// Walks an instance through levels (steps of 1, jumps, back and forth) and compares with the
/// one-pass rebuild at every stop.
fn check_instance_edits(name: &str, pm: &PmMesh) {
    let edits = PmEdits::new(pm);
    let n = pm.level_count();
    let mut inst = PmInstance::new(pm, n);
    let mut idx = Vec::new();
    let mut stops: Vec<usize> = (1..=n).rev().collect();
    stops.extend(1..=n);
    let mut x = 12345u64;
    for _ in 0..64 {
        x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
        stops.push(1 + (x >> 33) as usize % n);
    }
    for p in stops {
        inst.set_level(pm, &edits, p);
        pm.indices_at(p, &mut idx);
        assert_eq!(
            inst.indices(),
            &idx[..],
            "{name}: edited list differs at level {p}"
        );
    }
}

#[test]
fn hard_meshes_collapse_to_one_vertex_with_valid_lists_at_every_level() {
    for (name, tris) in hard_meshes() {
        let (mesh, _) = TriMesh::weld(&tris);
        for cost in CostKind::ALL {
            let label = format!("{name} ({})", cost.name());
            let (pm, _) = PmMesh::build(&mesh, cost, 0.01, &mut |_, _, _| {});
            assert_eq!(pm.level_count(), mesh.positions.len(), "{label}");
            assert_eq!(pm.triangles.len(), mesh.triangles.len(), "{label}");
            check_levels(&label, &pm);
            check_instance_edits(&label, &pm);
        }
    }
    // The weld itself: duplicates and degenerate triangles are counted, not drawn.
    let (mesh, report) = TriMesh::weld(&hard_meshes()[4].1);
    assert_eq!((report.duplicates_dropped, mesh.triangles.len()), (3, 2));
    let (_, report) = TriMesh::weld(&hard_meshes()[3].1);
    assert_eq!(report.degenerate_dropped, 1);
}

#[test]
fn disconnected_parts_end_in_isolated_collapses() {
    let (name, tris) = &hard_meshes()[5];
    let (mesh, _) = TriMesh::weld(tris);
    let (pm, _) = PmMesh::build(&mesh, CostKind::Quadric, 0.01, &mut |_, _, _| {});
    // Four parts, each ending as lone points once its last triangles vanish (a tetrahedron
    // ends as two points, a triangle as two): these join by isolated collapses, which happen
    // only when nothing is drawn any more.
    let isolated: Vec<usize> = (2..=pm.level_count())
        .filter(|&p| pm.levels[p - 1].flags & FLAG_ISOLATED != 0)
        .collect();
    assert_eq!(
        isolated.len(),
        7,
        "{name}: 3 tetrahedra and a triangle leave 8 points"
    );
    for p in isolated {
        assert_eq!(
            pm.triangles_at(p),
            0,
            "{name}: isolated collapse at a drawn level {p}"
        );
    }
}

/// Points drawn uniformly by area on `tris` (a seeded generator, not the builder's lattice).
/// Uniform numbers in [0, 1) from a seeded xorshift generator (the tests' own).
pub(crate) fn xorshift(seed: u64) -> impl FnMut() -> f64 {
    let mut x = seed.max(1);
    move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        (x >> 11) as f64 / (1u64 << 53) as f64
    }
}

pub(crate) fn random_points(tris: &[[DVec3; 3]], points: usize, seed: u64) -> Vec<DVec3> {
    let areas: Vec<f64> = tris
        .iter()
        .map(|t| (t[1] - t[0]).cross(t[2] - t[0]).length() / 2.0)
        .collect();
    let total: f64 = areas.iter().sum();
    let mut cumulative = Vec::with_capacity(areas.len());
    let mut acc = 0.0;
    for a in &areas {
        acc += a;
        cumulative.push(acc);
    }
    let mut rand = xorshift(seed);
    (0..points)
        .map(|_| {
            let r = rand() * total;
            let k = cumulative.partition_point(|&c| c < r).min(tris.len() - 1);
            let (mut u, mut v) = (rand(), rand());
            if u + v > 1.0 {
                u = 1.0 - u;
                v = 1.0 - v;
            }
            let [a, b, c] = tris[k];
            a + (b - a) * u + (c - a) * v
        })
        .collect()
}

/// Independent reference: points drawn uniformly by area on one mesh, each measured by brute
/// force against every triangle of the other.
pub(crate) fn reference_distance(
    from: &[[DVec3; 3]],
    to: &[[DVec3; 3]],
    points: usize,
    seed: u64,
) -> f64 {
    random_points(from, points, seed)
        .into_iter()
        .map(|p| {
            to.iter()
                .map(|t| segment_free_distance(p, t))
                .fold(f64::INFINITY, f64::min)
        })
        .fold(0.0, f64::max)
}

/// Triangles bucketed by the grid cells their boxes overlap (written for this test, apart from
/// worldgen's hierarchy), to decide "is some triangle within r of p" quickly.
pub(crate) struct Buckets<'a> {
    tris: &'a [[DVec3; 3]],
    lo: DVec3,
    cell: f64,
    dims: [usize; 3],
    /// Cell `c` holds `ids[start[c]..start[c + 1]]`.
    start: Vec<u32>,
    ids: Vec<u32>,
}

impl<'a> Buckets<'a> {
    /// Buckets over the box `lo..hi` (holding every triangle and query point).
    pub(crate) fn new(tris: &'a [[DVec3; 3]], lo: DVec3, hi: DVec3, cell: f64) -> Self {
        let dims = [0, 1, 2].map(|k| ((hi[k] - lo[k]) / cell).floor() as usize + 1);
        let mut b = Buckets {
            tris,
            lo,
            cell,
            dims,
            start: vec![0; dims[0] * dims[1] * dims[2] + 1],
            ids: Vec::new(),
        };
        let ranges: Vec<_> = tris
            .iter()
            .map(|t| b.range(t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2])))
            .collect();
        for r in &ranges {
            cells(dims, *r, |c| b.start[c + 1] += 1);
        }
        for c in 1..b.start.len() {
            b.start[c] += b.start[c - 1];
        }
        let mut fill = b.start.clone();
        b.ids = vec![0; *b.start.last().unwrap_or(&0) as usize];
        for (t, r) in ranges.iter().enumerate() {
            cells(dims, *r, |c| {
                b.ids[fill[c] as usize] = t as u32;
                fill[c] += 1;
            });
        }
        b
    }

    fn range(&self, lo: DVec3, hi: DVec3) -> ([usize; 3], [usize; 3]) {
        let at = |x: f64, k: usize| {
            (((x - self.lo[k]) / self.cell).floor().max(0.0) as usize).min(self.dims[k] - 1)
        };
        (
            [0, 1, 2].map(|k| at(lo[k], k)),
            [0, 1, 2].map(|k| at(hi[k], k)),
        )
    }

    /// Whether some triangle lies within `r` of `p`.
    pub(crate) fn within(&self, p: DVec3, r: f64) -> bool {
        let range = self.range(p - DVec3::splat(r), p + DVec3::splat(r));
        let mut found = false;
        cells(self.dims, range, |c| {
            found = found
                || self.ids[self.start[c] as usize..self.start[c + 1] as usize]
                    .iter()
                    .any(|&t| segment_free_distance(p, &self.tris[t as usize]) <= r);
        });
        found
    }
}

/// Calls `f` with the index of every cell of the box of cells `(a, b)` (inclusive).
fn cells(dims: [usize; 3], (a, b): ([usize; 3], [usize; 3]), mut f: impl FnMut(usize)) {
    for z in a[2]..=b[2] {
        for y in a[1]..=b[1] {
            for x in a[0]..=b[0] {
                f((z * dims[1] + y) * dims[0] + x);
            }
        }
    }
}

/// Every prefix of `pm` up to `max_positions` positions: seeded random points on the full mesh
/// each have a triangle of the level within the level's stored error, and random points on the
/// level a triangle of the full mesh (the two sides of the Hausdorff distance, decided with this
/// test's own distance). Returns the number of levels checked.
fn check_every_prefix(name: &str, pm: &PmMesh, points: usize, max_positions: usize) -> usize {
    let full = level_soup(pm, pm.level_count());
    let lo = full
        .iter()
        .flatten()
        .fold(DVec3::splat(f64::INFINITY), |a, p| a.min(*p));
    let hi = full
        .iter()
        .flatten()
        .fold(DVec3::splat(f64::NEG_INFINITY), |a, p| a.max(*p));
    let base_cell = (hi - lo).length() / 16.0;
    let on_full = random_points(&full, points, 4242);
    let mut full_grid: Option<(f64, Buckets<'_>)> = None;
    let mut checked = 0;
    for p in 1..pm.level_count().min(max_positions + 1) {
        let level = level_soup(pm, p);
        if level.is_empty() {
            continue;
        }
        let stored = f64::from(pm.levels[p - 1].error);
        let r = stored * (1.0 + 1e-5) + 1e-12;
        // Cells of base_cell x 2^k, at least r, so a query visits at most 3 x 3 x 3 cells.
        let cell = base_cell * (r / base_cell).max(1.0).log2().ceil().exp2();
        let level_grid = Buckets::new(&level, lo, hi, cell);
        if let Some(q) = on_full.iter().find(|&&q| !level_grid.within(q, r)) {
            panic!("{name} level {p}: full-mesh point {q} farther than the stored {stored:.4e}");
        }
        if full_grid.as_ref().is_none_or(|(c, _)| *c != cell) {
            full_grid = Some((cell, Buckets::new(&full, lo, hi, cell)));
        }
        let grid = &full_grid.as_ref().expect("made above").1;
        if let Some(q) = random_points(&level, points, 77 + p as u64)
            .into_iter()
            .find(|&q| !grid.within(q, r))
        {
            panic!("{name} level {p}: level point {q} farther than the stored {stored:.4e}");
        }
        checked += 1;
    }
    checked
}

/// Distance from a point to a triangle by barycentric clamping on the three edges and the
/// interior (written independently of worldgen's kernel).
pub(crate) fn segment_free_distance(p: DVec3, t: &[DVec3; 3]) -> f64 {
    let [a, b, c] = *t;
    let n = (b - a).cross(c - a);
    let seg = |s: DVec3, e: DVec3| {
        let d = e - s;
        let l = d.length_squared();
        let h = if l > 0.0 {
            ((p - s).dot(d) / l).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (s + d * h - p).length()
    };
    let mut best = seg(a, b).min(seg(b, c)).min(seg(c, a));
    let nl = n.length();
    if nl > 0.0 {
        let nn = n / nl;
        let q = p - nn * (p - a).dot(nn);
        let w0 = (b - q).cross(c - q).dot(nn);
        let w1 = (c - q).cross(a - q).dot(nn);
        let w2 = (a - q).cross(b - q).dot(nn);
        if w0 >= 0.0 && w1 >= 0.0 && w2 >= 0.0 {
            best = best.min((p - q).length());
        }
    }
    best
}

fn check_bound(path: &Path, cost: CostKind, levels: usize, points: usize) {
    let (mesh, _) = obj::load(path).expect("shared mesh loads");
    let (pm, _) = PmMesh::build(&mesh, cost, 0.005, &mut |_, _, _| {});
    check_levels(&path.display().to_string(), &pm);
    let full = level_soup(&pm, pm.level_count());
    let n = pm.level_count();
    // Log-spaced levels from 3 positions up to about half the mesh, plus seeded random ones.
    let mut chosen: Vec<usize> = (0..levels)
        .map(|k| {
            ((3.0f64).ln() + ((n as f64 / 2.0).ln() - 3.0f64.ln()) * k as f64 / (levels - 1) as f64)
                .exp() as usize
        })
        .collect();
    chosen.extend([n - 1, n - 7, n / 3]);
    chosen.sort_unstable();
    chosen.dedup();
    let mut closest = f64::INFINITY;
    for (k, &p) in chosen.iter().enumerate() {
        let level = level_soup(&pm, p);
        if level.is_empty() {
            continue;
        }
        let measured = reference_distance(&full, &level, points, 7 + k as u64)
            .max(reference_distance(&level, &full, points, 1000 + k as u64));
        let stored = pm.levels[p - 1].error as f64;
        assert!(
            stored >= measured * (1.0 - 1e-5),
            "{} ({}) level {p}: stored error {stored:.4e} below the measured {measured:.4e}",
            path.display(),
            cost.name()
        );
        closest = closest.min(stored / measured.max(1e-12));
    }
    // Every prefix as well, with fewer points, up to 4,000 positions (all of cow and spot, the
    // coarse tenth of the bunny, where the errors are largest).
    let name = format!("{} ({})", path.display(), cost.name());
    let every = check_every_prefix(&name, &pm, 300, 4000);
    println!(
        "{} ({}): {} levels checked against brute force, tightest stored / measured = {closest:.2}; {every} levels (every prefix up to 4,000 positions) within the stored error at 2 x 300 points",
        path.display(),
        cost.name(),
        chosen.len()
    );
}

#[test]
fn stored_error_bounds_an_independent_measurement_on_the_shared_meshes() {
    for (mesh, cost, levels, points) in [
        ("meshes/cow.obj", CostKind::Quadric, 24, 1500),
        ("meshes/cow.obj", CostKind::LongestEdge, 12, 1500),
        ("meshes/spot.obj", CostKind::Melax, 12, 1500),
        ("meshes/stanford-bunny.obj", CostKind::Quadric, 4, 300),
    ] {
        let path = tests::test_data(mesh);
        check_bound(&path, cost, levels, points);
    }
}

#[test]
fn uv_seams_of_spot_stay_split_and_pm_bytes_are_deterministic() {
    let path = tests::test_data("meshes/spot.obj");
    let (mesh, report) = obj::load(&path).expect("spot loads");
    assert!(
        mesh.wedge_position.len() > mesh.positions.len(),
        "spot has UV seams: more wedges ({}) than positions ({})",
        mesh.wedge_position.len(),
        mesh.positions.len()
    );
    assert_eq!(report.degenerate_dropped, 0);
    let (a, _) = PmMesh::build(&mesh, CostKind::Quadric, 0.01, &mut |_, _, _| {});
    let (b, _) = PmMesh::build(&mesh, CostKind::Quadric, 0.01, &mut |_, _, _| {});
    let bytes = file::to_bytes(&a);
    assert_eq!(bytes, file::to_bytes(&b), "two builds give different bytes");
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("spot.pm");
    file::write(&a, &out).expect("write");
    let back = file::read(&out).expect("read back");
    assert_eq!(back, a);
    // Every wedge keeps its UV through the layout (the seam is two wedges on one position).
    assert_eq!(back.uvs.len(), back.wedge_position.len());
}

fn expect_err(bytes: &[u8], what: &str) {
    let path = Path::new("broken/thing.pm");
    let err = file::from_bytes(bytes, path).expect_err(what).to_string();
    assert!(
        err.contains("broken/thing.pm"),
        "{what}: error {err:?} does not name the file"
    );
    println!("{what}: {err}");
}

#[test]
fn malformed_pm_and_obj_files_are_refused_with_the_file_and_the_problem() {
    let (mesh, _) = TriMesh::weld(&grid(3));
    let (pm, _) = PmMesh::build(&mesh, CostKind::Quadric, 0.01, &mut |_, _, _| {});
    let good = file::to_bytes(&pm);
    file::from_bytes(&good, Path::new("ok.pm")).expect("the good file reads");
    expect_err(&good[..good.len() - 1], "truncated");
    expect_err(b"not a mesh at all", "bad magic");
    let mut v = good.clone();
    v[8] = 9;
    expect_err(&v, "version");
    let mut v = good.clone();
    let mid = v.len() / 2;
    v[mid] ^= 0x40;
    let err = file::from_bytes(&v, Path::new("x.pm"))
        .expect_err("flipped bit")
        .to_string();
    assert!(err.contains("checksum"), "{err}");
    // A consistent checksum over an inconsistent body: the validator names the field.
    let mut bad = pm.clone();
    let last = bad.collapse_to.len() - 1;
    bad.collapse_to[last] = last as u32;
    let err = file::from_bytes(&file::to_bytes(&bad), Path::new("x.pm"))
        .expect_err("self-collapse")
        .to_string();
    assert!(err.contains("collapse_to"), "{err}");
    let mut bad = pm.clone();
    bad.levels[0].triangles = 5;
    let err = file::from_bytes(&file::to_bytes(&bad), Path::new("x.pm"))
        .expect_err("level counts")
        .to_string();
    assert!(err.contains("levels.triangles"), "{err}");

    let path = Path::new("models/broken.obj");
    for (text, needle) in [
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 x\nf 1 2 3\n",
            ":3: `v` component 3",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",
            ":4: vertex index 4 is out of range",
        ),
        (
            "v 0 0 0\nv 1 0 0\nf 1 2\n",
            ":3: a face needs at least 3 corners",
        ),
        ("v 0 0 0\nfoo 1\n", ":2: unknown statement"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "index 0"),
        ("v 0 0 nan\n", "not finite"),
    ] {
        let err = obj::parse(text, path).expect_err(needle).to_string();
        assert!(
            err.starts_with("models/broken.obj") && err.contains(needle),
            "{err:?} lacks {needle:?}"
        );
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let empty = dir.path().join("empty.obj");
    std::fs::write(&empty, "v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\n").expect("write");
    let err = obj::load(&empty).expect_err("all degenerate").to_string();
    assert!(
        err.contains("empty.obj") && err.contains("no triangles"),
        "{err}"
    );
}

pub(crate) use tests::gltf_fixture::bumpy_square;
use tests::gltf_fixture::gltf_with_chain;

#[test]
fn gltf_models_and_their_msft_lod_chains_are_read_and_measured() {
    use worldgen::pm::gltf_input;
    use worldgen::pm::measure::{hausdorff, mesh_soup};
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("chain.gltf");
    std::fs::write(&path, gltf_with_chain(4, false, false)).expect("write");
    let model = gltf_input::load(&path).expect("valid glTF loads");
    let counts: Vec<usize> = model.levels.iter().map(|l| l.1.len()).collect();
    assert_eq!(counts, vec![512, 32, 2], "base and two MSFT_lod levels");
    // The node's translation applies to the base and to the chain levels alike.
    for (name, tris) in &model.levels {
        let xs = tris.iter().flatten().map(|c| c.position[0]);
        let (lo, hi) = xs.fold((f32::MAX, f32::MIN), |(a, b), x| (a.min(x), b.max(x)));
        assert!(
            (lo - 10.0).abs() < 1e-6 && (hi - 11.0).abs() < 1e-6,
            "{name}: x in [{lo}, {hi}]"
        );
    }
    // Each chain level gets a measured error; coarser levels are farther from the base.
    let welded: Vec<TriMesh> = model.levels.iter().map(|l| TriMesh::weld(&l.1).0).collect();
    let base = mesh_soup(&welded[0]);
    let errors: Vec<f64> = welded
        .iter()
        .map(|m| hausdorff(&base, &mesh_soup(m), 0.005))
        .collect();
    assert!(
        errors[0] < 1e-9 && errors[1] > 1e-3 && errors[2] > errors[1],
        "{errors:?}"
    );
    // The base level is what `worldgen pm` builds from.
    let (mesh, _) = worldgen::pm::load_mesh(&path).expect("load_mesh reads glTF");
    assert_eq!(mesh.triangles.len(), 512);
    let (pm, _) = PmMesh::build(&mesh, CostKind::Quadric, 0.01, &mut |_, _, _| {});
    check_levels("glTF base", &pm);

    // Broken files name the file and what is wrong.
    for (text, needle) in [
        (gltf_with_chain(1, false, false), "only TRIANGLES"),
        (gltf_with_chain(4, true, false), "MSFT_lod names node 9"),
        ("{ not json".to_string(), "not a valid glTF"),
    ] {
        std::fs::write(&path, text).expect("write");
        let err = gltf_input::load(&path).expect_err(needle).to_string();
        assert!(
            err.contains("chain.gltf") && err.contains(needle),
            "{err:?} lacks {needle:?}"
        );
    }
}

#[test]
fn a_gltf_chain_loads_as_an_object_whose_chain_levels_carry_bounds() {
    use engine::objects::set::PmModel;
    use worldgen::pm::gltf_input;
    use worldgen::pm::measure::mesh_soup;
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("chain.gltf");
    std::fs::write(&path, gltf_with_chain(4, false, false)).expect("write");
    let model = PmModel::load(&path).expect("a glTF chain loads as an object");
    let tris: Vec<usize> = std::iter::once(&model)
        .chain(model.chain.iter().map(|c| &c.model))
        .map(|m| m.pm.triangles.len())
        .collect();
    assert_eq!(tris, vec![512, 32, 2], "base and two chain levels");
    let levels = gltf_input::load(&path).expect("read").levels;
    let soups: Vec<_> = levels
        .iter()
        .map(|l| mesh_soup(&TriMesh::weld(&l.1).0))
        .collect();
    for (k, chain) in model.chain.iter().enumerate() {
        let level = &soups[k + 1];
        let measured = reference_distance(&soups[0], level, 1500, 31 + k as u64)
            .max(reference_distance(level, &soups[0], 1500, 77 + k as u64));
        let bound = f64::from(chain.error);
        assert!(
            bound >= measured * (1.0 - 1e-5) && bound < 1.0,
            "chain level {}: bound {bound:.4e}, measured {measured:.4e}",
            k + 1
        );
    }
    // A chain level without triangles is refused, naming the file and the level.
    std::fs::write(&path, gltf_with_chain(4, false, true)).expect("write");
    let err = PmModel::load(&path)
        .expect_err("a chain level without triangles")
        .to_string();
    assert!(
        err.contains("chain.gltf") && err.contains("MSFT_lod level 2"),
        "{err}"
    );
}

mod silhouette {
    //! A rendered PM object at the level the pixel metric chooses against the full mesh: both
    //! rasterised on the GPU (lavapipe in CI) as coverage masks, compared in pixels.

    use super::{CostKind, PmMesh, obj};
    use engine::objects::lod::{PmLodSettings, choose_level};
    use engine::render::ground::clear_pass;
    use engine::render::{COLOR_FORMAT, Gpu, Target};
    use worldgen::pm::ErrorIndex;

    const SIZE: u32 = 512;
    const FOVY_DEG: f64 = 60.0;
    /// Pixel-centre sampling moves each mask's edge by up to sqrt(2)/2 px: two masks, sqrt(2).
    const RASTER_PX: f64 = std::f64::consts::SQRT_2;

    const SHADER: &str = "
@vertex fn vs(@location(0) p: vec2<f32>) -> @builtin(position) vec4<f32> {
    return vec4<f32>(p, 0.5, 1.0);
}
@fragment fn fs() -> @location(0) vec4<f32> { return vec4<f32>(1.0, 1.0, 1.0, 1.0); }
";

    /// Rasterises triangles given in normalised device coordinates; returns coverage per pixel.
    fn mask(g: &Gpu, ndc: &[[f32; 2]]) -> Vec<bool> {
        use wgpu::util::DeviceExt;
        let d = &g.device;
        let module = d.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("silhouette"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let layout = d.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("silhouette"),
            bind_group_layouts: &[],
            immediate_size: 0,
        });
        let attrs = [wgpu::VertexAttribute {
            format: wgpu::VertexFormat::Float32x2,
            offset: 0,
            shader_location: 0,
        }];
        let pipeline = d.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("silhouette"),
            layout: Some(&layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs"),
                compilation_options: wgpu::PipelineCompilationOptions::default(),
                buffers: &[Some(wgpu::VertexBufferLayout {
                    array_stride: 8,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &attrs,
                })],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: None,
            multisample: wgpu::MultisampleState::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs"),
                compilation_options: wgpu::PipelineCompilationOptions::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: COLOR_FORMAT,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        });
        let bytes: Vec<u8> = ndc.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
        let vb = d.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("silhouette vertices"),
            contents: &bytes,
            usage: wgpu::BufferUsages::VERTEX,
        });
        let target = Target::new(d, [SIZE, SIZE], COLOR_FORMAT);
        let mut enc = d.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        {
            let mut pass = clear_pass(&mut enc, &target.color_view, "silhouette");
            pass.set_pipeline(&pipeline);
            pass.set_vertex_buffer(0, vb.slice(..));
            pass.draw(0..ndc.len() as u32, 0..1);
        }
        g.queue.submit([enc.finish()]);
        let rgba = target.read_rgba(g).expect("readback");
        rgba.chunks_exact(4).map(|p| p[0] > 127).collect()
    }

    /// Largest distance (px) from a pixel covered by one mask to the nearest pixel covered by
    /// the other, both ways (the masks' Hausdorff distance); searched up to `limit` px.
    fn mask_distance(a: &[bool], b: &[bool], limit: i64) -> f64 {
        let n = SIZE as i64;
        let one_way = |from: &[bool], to: &[bool]| {
            let mut worst = 0.0f64;
            for y in 0..n {
                for x in 0..n {
                    if !from[(y * n + x) as usize] || to[(y * n + x) as usize] {
                        continue;
                    }
                    let mut best = f64::INFINITY;
                    for dy in -limit..=limit {
                        for dx in -limit..=limit {
                            let (u, v) = (x + dx, y + dy);
                            if u >= 0 && v >= 0 && u < n && v < n && to[(v * n + u) as usize] {
                                best = best.min(((dx * dx + dy * dy) as f64).sqrt());
                            }
                        }
                    }
                    worst = worst.max(best);
                }
            }
            worst
        };
        one_way(a, b).max(one_way(b, a))
    }

    /// Triangles of `pm` at level `p`, scaled and placed `depth_m` in front of a camera looking
    /// along +y (z up), projected to NDC.
    fn project(
        pm: &PmMesh,
        p: usize,
        centre: [f64; 3],
        scale: f64,
        depth_m: f64,
        k_px: f64,
    ) -> Vec<[f32; 2]> {
        let mut idx = Vec::new();
        pm.indices_at(p, &mut idx);
        let half = f64::from(SIZE) / 2.0;
        idx.iter()
            .map(|&w| {
                let q = pm.positions[pm.wedge_position[w as usize] as usize];
                let x = (q[0] as f64 - centre[0]) * scale;
                let y = (q[1] as f64 - centre[1]) * scale + depth_m;
                let z = (q[2] as f64 - centre[2]) * scale;
                [(k_px * x / y / half) as f32, (k_px * z / y / half) as f32]
            })
            .collect()
    }

    #[test]
    fn a_pm_object_at_the_chosen_level_stays_within_tau_of_the_full_silhouette() {
        let Some(g) = tests::gpu::device() else {
            return;
        };
        let k_px = f64::from(SIZE) / (2.0 * (FOVY_DEG.to_radians() / 2.0).tan());
        for (name, tau) in [("meshes/stanford-bunny.obj", 1.0), ("meshes/cow.obj", 2.0)] {
            let path = tests::test_data(name);
            let (mesh, _) = obj::load(&path).expect("loads");
            let (pm, _) = PmMesh::build(&mesh, CostKind::Quadric, 0.005, &mut |_, _, _| {});
            let index = ErrorIndex::new(&pm);
            let (lo, hi) = mesh.bounds();
            let centre = [0, 1, 2].map(|k| f64::from(lo[k] + hi[k]) / 2.0);
            let diag = f64::from(mesh.diagonal());
            // The object is 2 m across; its bounding sphere has radius 1 m.
            let scale = 2.0 / diag;
            let settings = PmLodSettings {
                min_vertices: 1,
                ..PmLodSettings::default()
            };
            let full = pm.level_count();
            let mut coarsest_share = 1.0f64;
            for depth_m in [5.0, 15.0, 45.0] {
                let near_m = depth_m - 1.0;
                let p = choose_level(&pm, &index, &settings, tau, near_m, k_px, scale);
                let stored_px = f64::from(pm.levels[p - 1].error) * scale * k_px / near_m;
                assert!(
                    stored_px <= tau + 1e-9,
                    "{name}: level {p} projects to {stored_px} px, over tau {tau}"
                );
                let a = mask(&g, &project(&pm, full, centre, scale, depth_m, k_px));
                let b = mask(&g, &project(&pm, p, centre, scale, depth_m, k_px));
                let covered = a.iter().filter(|&&x| x).count();
                assert!(
                    covered > 50,
                    "{name}: the object covers only {covered} px at {depth_m} m"
                );
                let d = mask_distance(&a, &b, (tau + 4.0) as i64);
                let share = pm.triangles_at(p) as f64 / pm.triangles.len() as f64;
                coarsest_share = coarsest_share.min(share);
                println!(
                    "{name} at {depth_m} m, tau {tau}: level {p} of {full} ({:.1} % of the triangles), stored error {stored_px:.2} px, silhouette {d:.2} px",
                    100.0 * share
                );
                assert!(
                    d <= tau + RASTER_PX,
                    "{name} at {depth_m} m: silhouettes differ by {d:.2} px > tau {tau} + {RASTER_PX:.2}"
                );
            }
            // The metric must actually simplify: far away a few percent of the triangles.
            assert!(
                coarsest_share < 0.1,
                "{name}: never below {:.1} % of the triangles",
                100.0 * coarsest_share
            );
        }
    }
}
