//! Town sites, roads between them (least-cost paths over slope on a coarse grid, joined by a
//! minimum spanning tree) and footpaths, emitted as decal polylines whose z is a smoothed
//! surface height (so roads are graded, not draped over every bump).

use crate::Grid;
use crate::map::{Decal, DecalKind};
use crate::noise;
use crate::sample::{self, GridPlacement};
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// Inputs for road planning.
pub struct RoadInputs<'a> {
    pub seed: u64,
    pub heights: &'a Grid<f32>,
    pub placement: GridPlacement,
    pub size_m: [f64; 2],
    pub water_level_m: f64,
}

/// Town sites and the decals that join them.
#[derive(Debug, Clone, Default)]
pub struct RoadNetwork {
    pub towns_m: Vec<[f64; 2]>,
    pub decals: Vec<Decal>,
}

const ROAD_WIDTH_M: f32 = 6.0;
const PATH_WIDTH_M: f32 = 2.0;

struct CostGrid {
    w: usize,
    h: usize,
    cell_m: f64,
    origin_m: [f64; 2],
    height: Vec<f64>,
    water: Vec<bool>,
}

impl CostGrid {
    fn new(inp: &RoadInputs<'_>) -> Self {
        // About 256 cells across, at least the height spacing.
        let cell_m = (inp.size_m[0].max(inp.size_m[1]) / 256.0).max(inp.placement.spacing_m);
        let w = (inp.size_m[0] / cell_m).floor() as usize + 1;
        let h = (inp.size_m[1] / cell_m).floor() as usize + 1;
        let mut height = Vec::with_capacity(w * h);
        let mut water = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let (wx, wy) = (
                    inp.placement.origin_m[0] + x as f64 * cell_m,
                    inp.placement.origin_m[1] + y as f64 * cell_m,
                );
                let z = sample::bilinear(inp.heights, inp.placement, wx, wy);
                height.push(z);
                water.push(z <= inp.water_level_m + 0.5);
            }
        }
        Self {
            w,
            h,
            cell_m,
            origin_m: inp.placement.origin_m,
            height,
            water,
        }
    }

    fn world(&self, i: usize) -> [f64; 2] {
        [
            self.origin_m[0] + (i % self.w) as f64 * self.cell_m,
            self.origin_m[1] + (i / self.w) as f64 * self.cell_m,
        ]
    }

    fn index(&self, p: [f64; 2]) -> usize {
        let x = (((p[0] - self.origin_m[0]) / self.cell_m).round() as usize).min(self.w - 1);
        let y = (((p[1] - self.origin_m[1]) / self.cell_m).round() as usize).min(self.h - 1);
        y * self.w + x
    }

    /// Dijkstra from `a` to `b`; cost per step = length x (1 + slope_weight x slope²), water is
    /// very expensive (bridges are allowed but avoided). Returns cell indices from a to b.
    fn path(&self, a: usize, b: usize, slope_weight: f64) -> Option<Vec<usize>> {
        let n = self.w * self.h;
        let mut dist = vec![f64::INFINITY; n];
        let mut prev = vec![usize::MAX; n];
        let mut heap = BinaryHeap::new();
        dist[a] = 0.0;
        heap.push(Reverse((Ordered(0.0), a)));
        while let Some(Reverse((Ordered(d), i))) = heap.pop() {
            if i == b {
                break;
            }
            if d > dist[i] {
                continue;
            }
            let (x, y) = ((i % self.w) as i64, (i / self.w) as i64);
            for (dx, dy) in [
                (-1, 0),
                (1, 0),
                (0, -1),
                (0, 1),
                (-1, -1),
                (1, -1),
                (-1, 1),
                (1, 1),
            ] {
                let (nx, ny) = (x + dx, y + dy);
                if nx < 0 || ny < 0 || nx >= self.w as i64 || ny >= self.h as i64 {
                    continue;
                }
                let j = ny as usize * self.w + nx as usize;
                let len = self.cell_m
                    * if dx != 0 && dy != 0 {
                        std::f64::consts::SQRT_2
                    } else {
                        1.0
                    };
                let slope = (self.height[j] - self.height[i]).abs() / len;
                let mut c = len * (1.0 + slope_weight * slope * slope);
                if self.water[j] {
                    c += len * 50.0;
                }
                let nd = d + c;
                if nd < dist[j] {
                    dist[j] = nd;
                    prev[j] = i;
                    heap.push(Reverse((Ordered(nd), j)));
                }
            }
        }
        if !dist[b].is_finite() {
            return None;
        }
        let mut out = vec![b];
        let mut i = b;
        while i != a {
            i = prev[i];
            out.push(i);
        }
        out.reverse();
        Some(out)
    }
}

/// Total order on finite f64 for the heap (costs are never NaN).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Ordered(f64);
impl Eq for Ordered {}
impl PartialOrd for Ordered {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Ordered {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

/// Picks town sites: flat, dry cells away from the border, greedily by a hashed score, at least
/// a quarter of the map size apart.
fn pick_towns(g: &CostGrid, seed: u64, count: usize) -> Vec<usize> {
    let margin = (g.w / 10).max(1);
    let mut cands: Vec<(f64, usize)> = Vec::new();
    for y in margin..g.h.saturating_sub(margin) {
        for x in margin..g.w.saturating_sub(margin) {
            let i = y * g.w + x;
            if g.water[i] {
                continue;
            }
            let mut rough = 0.0;
            for (dx, dy) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                let j = (y as i64 + dy) as usize * g.w + (x as i64 + dx) as usize;
                rough += (g.height[j] - g.height[i]).abs() / g.cell_m;
            }
            let score = rough + 0.3 * noise::unit3(seed ^ 0x70E7, x as i64, y as i64);
            cands.push((score, i));
        }
    }
    cands.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let min_sep_m = g.cell_m * g.w.max(g.h) as f64 / 4.0;
    let mut towns: Vec<usize> = Vec::new();
    for (_, i) in cands {
        let p = g.world(i);
        if towns.iter().all(|&t| {
            let q = g.world(t);
            (p[0] - q[0]).hypot(p[1] - q[1]) >= min_sep_m
        }) {
            towns.push(i);
            if towns.len() == count {
                break;
            }
        }
    }
    towns
}

/// Turns a cell path into a smoothed decal polyline: Chaikin corner cutting on the plan, then a
/// moving average of the surface height for a graded road surface.
fn polyline(g: &CostGrid, inp: &RoadInputs<'_>, cells: &[usize]) -> Vec<[f64; 3]> {
    let mut pts: Vec<[f64; 2]> = cells.iter().map(|&i| g.world(i)).collect();
    for _ in 0..2 {
        if pts.len() < 3 {
            break;
        }
        let mut next = vec![pts[0]];
        for w in pts.windows(2) {
            let (a, b) = (w[0], w[1]);
            next.push([0.75 * a[0] + 0.25 * b[0], 0.75 * a[1] + 0.25 * b[1]]);
            next.push([0.25 * a[0] + 0.75 * b[0], 0.25 * a[1] + 0.75 * b[1]]);
        }
        next.push(pts[pts.len() - 1]);
        pts = next;
    }
    let z: Vec<f64> = pts
        .iter()
        .map(|p| {
            sample::bilinear(inp.heights, inp.placement, p[0], p[1]).max(inp.water_level_m + 0.5)
        })
        .collect();
    let k = 3usize;
    (0..pts.len())
        .map(|i| {
            let lo = i.saturating_sub(k);
            let hi = (i + k + 1).min(pts.len());
            let zs = z[lo..hi].iter().sum::<f64>() / (hi - lo) as f64;
            [pts[i][0], pts[i][1], zs]
        })
        .collect()
}

/// Plans towns, roads (minimum spanning tree over towns) and two footpaths per town.
pub fn plan(inp: &RoadInputs<'_>) -> RoadNetwork {
    let g = CostGrid::new(inp);
    let area_km2 = inp.size_m[0] * inp.size_m[1] / 1.0e6;
    let count = ((area_km2 / 12.0).round() as usize).clamp(2, 12);
    let towns = pick_towns(&g, inp.seed, count);
    let mut decals = Vec::new();
    // Prim's MST on straight-line distance.
    let mut in_tree = vec![false; towns.len()];
    if !towns.is_empty() {
        in_tree[0] = true;
    }
    for _ in 1..towns.len() {
        let mut best: Option<(f64, usize, usize)> = None;
        for (a, &ta) in towns.iter().enumerate().filter(|(a, _)| in_tree[*a]) {
            for (b, &tb) in towns.iter().enumerate().filter(|(b, _)| !in_tree[*b]) {
                let (pa, pb) = (g.world(ta), g.world(tb));
                let d = (pa[0] - pb[0]).hypot(pa[1] - pb[1]);
                if best.is_none_or(|(bd, _, _)| d < bd) {
                    best = Some((d, a, b));
                }
            }
        }
        let Some((_, a, b)) = best else { break };
        in_tree[b] = true;
        if let Some(cells) = g.path(towns[a], towns[b], 60.0) {
            decals.push(Decal {
                kind: DecalKind::Road,
                closed: false,
                width_m: ROAD_WIDTH_M,
                falloff_m: 4.0,
                height_offset_m: 0.0,
                points: polyline(&g, inp, &cells),
            });
        }
    }
    for (t, &town) in towns.iter().enumerate() {
        for k in 0..2i64 {
            let h = noise::hash3(inp.seed ^ 0xFA7B, t as i64, k);
            let angle_turns = noise::unit(h);
            let dist_m = (inp.size_m[0].min(inp.size_m[1])
                * (0.08 + 0.1 * noise::unit(h.rotate_left(17))))
            .max(g.cell_m * 3.0);
            // Direction from a 16-way table: no trig, so the bytes are the same everywhere.
            let dir = noise::DIRECTIONS_16[(angle_turns * 16.0) as usize % 16];
            let p = g.world(town);
            let goal = g.index([p[0] + dir.0 * dist_m, p[1] + dir.1 * dist_m]);
            if goal == town || g.water[goal] {
                continue;
            }
            if let Some(cells) = g.path(town, goal, 15.0) {
                decals.push(Decal {
                    kind: DecalKind::Path,
                    closed: false,
                    width_m: PATH_WIDTH_M,
                    falloff_m: 1.5,
                    height_offset_m: -0.1,
                    points: polyline(&g, inp, &cells),
                });
            }
        }
    }
    RoadNetwork {
        towns_m: towns.iter().map(|&i| g.world(i)).collect(),
        decals,
    }
}

/// Distance from point p to segment ab (2-D).
pub fn point_segment_distance_m(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    segment_closest(p, a, b).0
}

/// Distance (m) from point p to segment ab (2-D) and the segment parameter in [0, 1] of the
/// closest point.
pub fn segment_closest(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> (f64, f64) {
    let (abx, aby) = (b[0] - a[0], b[1] - a[1]);
    let len2 = abx * abx + aby * aby;
    let t = if len2 > 0.0 {
        (((p[0] - a[0]) * abx + (p[1] - a[1]) * aby) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    ((p[0] - (a[0] + t * abx)).hypot(p[1] - (a[1] + t * aby)), t)
}

/// A boolean grid (`w` x `h` samples at `placement`) marking samples within half a decal's width
/// plus `extra_m` of any decal's centre line (open decals) or outline (closed areas), and every
/// sample inside a closed area.
pub fn decal_mask(
    decals: &[Decal],
    placement: GridPlacement,
    w: usize,
    h: usize,
    extra_m: f64,
) -> Grid<bool> {
    let mut mask = Grid::new(w, h, false);
    let s = placement.spacing_m;
    let to_cell = |v: f64, o: f64| (v - o) / s;
    let cell_range = |lo: f64, hi: f64, o: f64, n: usize| {
        let a = to_cell(lo, o).floor().max(0.0) as usize;
        let b = (to_cell(hi, o).ceil().max(0.0) as usize).min(n - 1);
        a..=b
    };
    let at = |x: usize, y: usize| {
        [
            placement.origin_m[0] + x as f64 * s,
            placement.origin_m[1] + y as f64 * s,
        ]
    };
    for d in decals {
        let r = f64::from(d.width_m) * 0.5 + extra_m;
        let n = d.points.len();
        let segments = if d.closed { n } else { n.saturating_sub(1) };
        for k in 0..segments {
            let (pa, pb) = (d.points[k], d.points[(k + 1) % n]);
            let (a, b) = ([pa[0], pa[1]], [pb[0], pb[1]]);
            for y in cell_range(
                a[1].min(b[1]) - r,
                a[1].max(b[1]) + r,
                placement.origin_m[1],
                h,
            ) {
                for x in cell_range(
                    a[0].min(b[0]) - r,
                    a[0].max(b[0]) + r,
                    placement.origin_m[0],
                    w,
                ) {
                    if point_segment_distance_m(at(x, y), a, b) <= r {
                        mask.set(x, y, true);
                    }
                }
            }
        }
        if d.closed && n >= 3 {
            let (lo, hi) = d.points.iter().fold(
                ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
                |(lo, hi), p| {
                    (
                        [lo[0].min(p[0]), lo[1].min(p[1])],
                        [hi[0].max(p[0]), hi[1].max(p[1])],
                    )
                },
            );
            for y in cell_range(lo[1], hi[1], placement.origin_m[1], h) {
                for x in cell_range(lo[0], hi[0], placement.origin_m[0], w) {
                    if inside_polygon(at(x, y), &d.points) {
                        mask.set(x, y, true);
                    }
                }
            }
        }
    }
    mask
}

/// Even-odd point-in-polygon test on the (x, y) of `pts`.
pub fn inside_polygon(p: [f64; 2], pts: &[[f64; 3]]) -> bool {
    let mut inside = false;
    let n = pts.len();
    for i in 0..n {
        let (a, b) = (pts[i], pts[(i + n - 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if p[0] < x {
                inside = !inside;
            }
        }
    }
    inside
}
