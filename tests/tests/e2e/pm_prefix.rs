//! The stored error of *every* prefix of a large progressive mesh (the bunny: 34,834 levels),
//! checked against this test's own distance measurement. Rebuilding each level from scratch
//! costs O(levels x triangles); instead the levels are walked from the full mesh down, one
//! collapse at a time, following the PM's collapse map in the test:
//!
//! - **Full mesh to level**: fixed random points on the full mesh each keep a witness, a level
//!   triangle within the level's stored error; a witness is looked for again (first around the
//!   collapse, then among all the level's triangles) when its triangle changes or the stored
//!   error drops below its distance. A point without one fails.
//! - **Level to full mesh**: every triangle shape that any level draws (each time a collapse
//!   moves a triangle, a new shape) is sampled at its centroid and at six random points, and
//!   each sample must lie within the smallest stored error of the levels that draw that shape.

use crate::pm::{Buckets, random_points, segment_free_distance, xorshift};
use glam::DVec3;
use worldgen::pm::PmMesh;
use worldgen::pm::measure::level_soup;

/// Smallest value of `v` over index ranges, in O(1) a query (a sparse table).
struct RangeMin {
    rows: Vec<Vec<f64>>,
}

impl RangeMin {
    fn new(v: &[f64]) -> Self {
        let mut rows = vec![v.to_vec()];
        let mut span = 1;
        while 2 * span <= v.len() {
            let prev = rows.last().expect("one row");
            let next = (0..=v.len() - 2 * span)
                .map(|i| prev[i].min(prev[i + span]))
                .collect();
            rows.push(next);
            span *= 2;
        }
        RangeMin { rows }
    }

    /// The smallest of `v[lo..=hi]`.
    fn min(&self, lo: usize, hi: usize) -> f64 {
        let k = (usize::BITS - 1 - (hi - lo + 1).leading_zeros()) as usize;
        self.rows[k][lo].min(self.rows[k][hi + 1 - (1 << k)])
    }
}

/// A triangle's current corners (positions) and when that shape first appeared (its finest
/// level), with a count of its shapes so far.
#[derive(Clone, Copy)]
struct Shape {
    corners: [u32; 3],
    born: usize,
    version: u32,
}

/// A full-mesh point and its witness: a triangle (at a shape version) and the distance to it.
struct Witness {
    point: DVec3,
    triangle: usize,
    version: u32,
    distance: f64,
}

/// One level of the walk, for the full-mesh-to-level side.
struct WalkLevel<'a> {
    p: usize,
    tol: f64,
    /// Triangles drawn (the first ones).
    alive: usize,
    shapes: &'a [Shape],
    pos_tris: &'a [Vec<usize>],
    /// The triangles the last collapse changed.
    changed: &'a [usize],
}

fn corners_at(pm: &PmMesh, s: &Shape) -> [DVec3; 3] {
    s.corners.map(|p| {
        let q = pm.positions[p as usize];
        DVec3::new(f64::from(q[0]), f64::from(q[1]), f64::from(q[2]))
    })
}

impl WalkLevel<'_> {
    /// Gives every point whose witness changed or is now too far a new one: a triangle within
    /// the stored error, looked for first around the old witness (or the collapse), then among
    /// all the level's triangles. Panics when there is none.
    fn find_witnesses(&self, name: &str, pm: &PmMesh, witnesses: &mut [Witness]) {
        let (tol, alive) = (self.tol, self.alive);
        for wit in witnesses {
            let valid = wit.triangle < alive
                && self.shapes[wit.triangle].version == wit.version
                && wit.distance <= tol;
            if valid {
                continue;
            }
            let near =
                |t: usize| segment_free_distance(wit.point, &corners_at(pm, &self.shapes[t]));
            let around: Vec<usize> = if wit.triangle < alive {
                self.shapes[wit.triangle]
                    .corners
                    .iter()
                    .flat_map(|&c| self.pos_tris[c as usize].iter().copied())
                    .collect()
            } else {
                self.changed
                    .iter()
                    .copied()
                    .filter(|&t| t < alive)
                    .collect()
            };
            let found = around
                .into_iter()
                .chain(0..alive)
                .map(|t| (t, near(t)))
                .find(|&(_, d)| d <= tol);
            let Some((t, d)) = found else {
                panic!(
                    "{name} level {}: full-mesh point {} farther than the stored {tol:.4e}",
                    self.p, wit.point
                );
            };
            *wit = Witness {
                point: wit.point,
                triangle: t,
                version: self.shapes[t].version,
                distance: d,
            };
        }
    }
}

/// Points sampled on every triangle shape: the centroid and random ones.
const SHAPE_POINTS: usize = 7;

/// Checks both sides at every level of `pm` with `full_points` fixed points on the full mesh;
/// returns the number of shapes sampled. Panics naming the level on the first failure.
pub(crate) fn check_every_level_incrementally(
    name: &str,
    pm: &PmMesh,
    full_points: usize,
) -> usize {
    let n = pm.level_count();
    let full = level_soup(pm, n);
    let (lo, hi) = full.iter().flatten().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(a, b), p| (a.min(*p), b.max(*p)),
    );
    let full_grid = Buckets::new(&full, lo, hi, (hi - lo).length() / 64.0);
    // r[p - 1]: the tolerance at level p.
    let r: Vec<f64> = pm
        .levels
        .iter()
        .map(|l| f64::from(l.error) * (1.0 + 1e-5) + 1e-12)
        .collect();
    let min_r = RangeMin::new(&r);
    let tris = pm.triangles_at(n);
    assert_eq!(
        tris,
        pm.triangles.len(),
        "{name}: the full level draws every triangle"
    );
    // The walk: each triangle's corners as positions, each position's triangles.
    let mut shapes: Vec<Shape> = pm
        .triangles
        .iter()
        .map(|t| Shape {
            corners: t.map(|w| pm.wedge_position[w as usize]),
            born: n,
            version: 0,
        })
        .collect();
    let mut wedge_now: Vec<u32> = (0..pm.wedge_position.len() as u32).collect();
    let mut pos_tris: Vec<Vec<usize>> = vec![Vec::new(); pm.positions.len()];
    for (t, s) in shapes.iter().enumerate() {
        for &c in &s.corners {
            pos_tris[c as usize].push(t);
        }
    }
    let mut witnesses: Vec<Witness> = random_points(&full, full_points, 991)
        .into_iter()
        .map(|point| Witness {
            point,
            triangle: usize::MAX,
            version: 0,
            distance: f64::INFINITY,
        })
        .collect();
    let mut rand = xorshift(5151);
    let mut sampled = 0;
    // Checks the shape of triangle t that levels born..=last drew (last >= 1).
    let mut retire = |s: &Shape, last: usize, sampled: &mut usize| {
        if s.born == n {
            return; // a full-mesh triangle: on the full mesh
        }
        let tol = min_r.min(last - 1, s.born - 1);
        let [a, b, c] = corners_at(pm, s);
        let random = (0..SHAPE_POINTS - 1).map(|_| {
            let (mut u, mut v) = (rand(), rand());
            if u + v > 1.0 {
                u = 1.0 - u;
                v = 1.0 - v;
            }
            a + (b - a) * u + (c - a) * v
        });
        for q in std::iter::once((a + b + c) / 3.0).chain(random.collect::<Vec<_>>()) {
            assert!(
                full_grid.within(q, tol),
                "{name}: a triangle drawn at levels {last}..={}: point {q} farther than the stored {tol:.4e} from the full mesh",
                s.born
            );
        }
        *sampled += 1;
    };
    let mut changed: Vec<usize> = Vec::new();
    for p in (2..=n).rev() {
        // From level p to p - 1: position p - 1 goes; its wedges follow the collapse map.
        let x = (p - 1) as u32;
        let live = pm.wedges_at(p - 1) as u32;
        let alive = pm.triangles_at(p - 1);
        changed.clear();
        changed.extend(std::mem::take(&mut pos_tris[x as usize]));
        for &t in &changed {
            let old = shapes[t];
            retire(&old, p, &mut sampled);
            for &c in &old.corners {
                if c != x {
                    pos_tris[c as usize].retain(|&o| o != t);
                }
            }
            // Each corner's wedge follows the collapse map until it is alive (remembered, so
            // later levels continue from there).
            let corners = pm.triangles[t].map(|w| {
                let mut to = wedge_now[w as usize];
                while to >= live {
                    to = pm.collapse_to[to as usize];
                }
                wedge_now[w as usize] = to;
                pm.wedge_position[to as usize]
            });
            if t < alive {
                assert!(
                    corners.iter().all(|&c| c < x)
                        && corners[0] != corners[1]
                        && corners[1] != corners[2]
                        && corners[0] != corners[2],
                    "{name}: level {}: triangle {t} has corners {corners:?}",
                    p - 1
                );
                shapes[t] = Shape {
                    corners,
                    born: p - 1,
                    version: old.version + 1,
                };
                for &c in &corners {
                    pos_tris[c as usize].push(t);
                }
            } else {
                shapes[t].version = old.version + 1;
                assert!(
                    corners
                        .iter()
                        .any(|&c| corners.iter().filter(|&&d| d == c).count() > 1),
                    "{name}: level {}: triangle {t} vanishes but its corners {corners:?} differ",
                    p - 1
                );
            }
        }
        // The full mesh to level p - 1.
        if alive > 0 {
            let level = WalkLevel {
                p: p - 1,
                tol: r[p - 2],
                alive,
                shapes: &shapes,
                pos_tris: &pos_tris,
                changed: &changed,
            };
            level.find_witnesses(name, pm, &mut witnesses);
        }
    }
    // Every triangle vanished through a collapse of one of its corners, so every shape was
    // checked.
    assert!(
        pos_tris.iter().all(Vec::is_empty),
        "{name}: triangles left after the last level"
    );
    sampled
}

#[test]
fn stored_error_bounds_the_measured_error_at_every_level_of_every_shared_mesh() {
    for mesh_name in ["cow.obj", "spot.obj", "stanford-bunny.obj"] {
        let path = tests::test_data(&format!("meshes/{mesh_name}"));
        let (mesh, _) = worldgen::pm::obj::load(&path).expect("a shared mesh loads");
        for cost in worldgen::pm::CostKind::ALL {
            let (pm, _) = PmMesh::build(&mesh, cost, 0.005, &mut |_, _, _| {});
            let t0 = std::time::Instant::now();
            let name = format!("{mesh_name} ({})", cost.name());
            let shapes = check_every_level_incrementally(&name, &pm, FULL_POINTS);
            println!(
                "{name}: all {} levels: {FULL_POINTS} full-mesh points and {shapes} triangle shapes ({SHAPE_POINTS} points each) within the stored errors ({:.1} s)",
                pm.level_count(),
                t0.elapsed().as_secs_f64()
            );
            assert!(
                shapes > pm.triangles.len() / 2,
                "{name}: {shapes} shapes sampled"
            );
        }
    }
}

/// Fixed points on the full mesh.
const FULL_POINTS: usize = 4000;
