//! The ranked, periodic Poisson-disc tile used to place vegetation.
//!
//! Points live on the unit torus `[0, 1)^2` (the tile repeats in x and y, so distances wrap). The
//! list order is a *rank*: points are thrown as darts with a radius that shrinks stage by stage
//! (`r <- r * RADIUS_STEP`) down to the tile's minimum distance, and each accepted dart is
//! appended. So every prefix is itself a Poisson-disc set, with a radius that grows as the
//! prefix gets shorter (about `r_min / sqrt(fraction)`): keeping the points whose normalised
//! rank is below a density ratio thins the set evenly, and a point kept at one density is kept at
//! every higher one.
//!
//! Deterministic: darts come from the stateless hash [`crate::noise::unit3`] of (seed, dart
//! number), so the same seed gives the same tile on every machine.

use crate::noise::unit3;

/// Factor between the dart radii of consecutive stages.
pub const RADIUS_STEP: f64 = 0.94;
/// Consecutive misses that end a stage (the last stage uses [`FINAL_MISSES`]).
pub const STAGE_MISSES: u32 = 400;
/// Consecutive misses that end the last stage (close to maximal).
pub const FINAL_MISSES: u32 = 30_000;
/// Minimum distance of the default tile in tile units: about 3,800 points.
pub const DEFAULT_MIN_DISTANCE: f64 = 0.0135;

/// A ranked Poisson-disc tile (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct PoissonTile {
    /// Points in `[0, 1)^2`, in rank order.
    pub points: Vec<[f64; 2]>,
}

/// Distance on the unit torus.
pub fn torus_distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    let wrap = |d: f64| {
        let d = d.abs();
        d.min(1.0 - d)
    };
    wrap(a[0] - b[0]).hypot(wrap(a[1] - b[1]))
}

/// A uniform grid over the torus holding point indices, for neighbour queries.
struct TorusGrid {
    cells: usize,
    slots: Vec<Vec<u32>>,
}

impl TorusGrid {
    fn new(cell: f64) -> Self {
        let cells = ((1.0 / cell).floor() as usize).clamp(1, 4096);
        Self {
            cells,
            slots: vec![Vec::new(); cells * cells],
        }
    }

    fn cell_of(&self, p: [f64; 2]) -> (usize, usize) {
        let c = |v: f64| ((v * self.cells as f64) as usize).min(self.cells - 1);
        (c(p[0]), c(p[1]))
    }

    fn insert(&mut self, p: [f64; 2], index: u32) {
        let (x, y) = self.cell_of(p);
        self.slots[y * self.cells + x].push(index);
    }

    /// Whether any stored point lies closer than `r` to `p`.
    fn any_within(&self, points: &[[f64; 2]], p: [f64; 2], r: f64) -> bool {
        let n = self.cells as i64;
        let reach = ((r * self.cells as f64).ceil() as i64).min(n / 2);
        let (cx, cy) = self.cell_of(p);
        if 2 * reach + 1 >= n {
            return points.iter().any(|&q| torus_distance(p, q) < r);
        }
        for dy in -reach..=reach {
            for dx in -reach..=reach {
                let x = (cx as i64 + dx).rem_euclid(n) as usize;
                let y = (cy as i64 + dy).rem_euclid(n) as usize;
                for &i in &self.slots[y * self.cells + x] {
                    if torus_distance(p, points[i as usize]) < r {
                        return true;
                    }
                }
            }
        }
        false
    }
}

/// The first pair (in rank order) of points closer than `r` on the torus, with their distance;
/// None when every pair is at least `r` apart. Linear time for any input: points are added in
/// order to a grid of cells no smaller than `r` and each is checked against its neighbours, so
/// the search stops at the first violation (a valid set has a few points per cell at most).
pub fn closer_pair(points: &[[f64; 2]], r: f64) -> Option<(usize, usize, f64)> {
    let mut grid = TorusGrid::new(r);
    for (i, &p) in points.iter().enumerate() {
        if grid.any_within(&points[..i], p, r) {
            let (j, d) = points[..i]
                .iter()
                .enumerate()
                .map(|(j, &q)| (j, torus_distance(p, q)))
                .min_by(|a, b| a.1.total_cmp(&b.1))?;
            return Some((j, i, d));
        }
        grid.insert(p, i as u32);
    }
    None
}

impl PoissonTile {
    /// Generates a ranked tile whose points are at least `min_distance` (tile units, in
    /// `(0.001, 0.5)`) apart on the torus.
    pub fn generate(seed: u64, min_distance: f64) -> Self {
        assert!(
            min_distance > 0.001 && min_distance < 0.5,
            "tile min distance {min_distance} out of (0.001, 0.5)"
        );
        let mut grid = TorusGrid::new(min_distance / std::f64::consts::SQRT_2);
        let mut points: Vec<[f64; 2]> = Vec::new();
        let mut dart = 0i64;
        let mut r = 0.5f64;
        loop {
            let last = r <= min_distance;
            let r_stage = r.max(min_distance);
            let limit = if last { FINAL_MISSES } else { STAGE_MISSES };
            let mut misses = 0;
            while misses < limit {
                let p = [unit3(seed, dart, 0), unit3(seed, dart, 1)];
                dart += 1;
                if grid.any_within(&points, p, r_stage) {
                    misses += 1;
                } else {
                    grid.insert(p, points.len() as u32);
                    points.push(p);
                    misses = 0;
                }
            }
            if last {
                break;
            }
            r *= RADIUS_STEP;
        }
        Self { points }
    }

    /// The smallest torus distance between two of the first `count` points (infinity for fewer
    /// than two).
    pub fn prefix_min_distance(&self, count: usize) -> f64 {
        let pts = &self.points[..count.min(self.points.len())];
        if pts.len() < 2 {
            return f64::INFINITY;
        }
        // A grid with about one point per cell; check the 5 x 5 neighbourhood, then widen if
        // the best found is larger than the neighbourhood covers.
        let cell = (1.0 / (pts.len() as f64).sqrt()).min(0.5);
        let mut grid = TorusGrid::new(cell);
        for (i, &p) in pts.iter().enumerate() {
            grid.insert(p, i as u32);
        }
        let n = grid.cells as i64;
        let mut best = f64::INFINITY;
        for (i, &p) in pts.iter().enumerate() {
            let (cx, cy) = grid.cell_of(p);
            let reach = 2.min(n / 2);
            for dy in -reach..=reach {
                for dx in -reach..=reach {
                    let x = (cx as i64 + dx).rem_euclid(n) as usize;
                    let y = (cy as i64 + dy).rem_euclid(n) as usize;
                    for &j in &grid.slots[y * grid.cells + x] {
                        if j as usize != i {
                            best = best.min(torus_distance(p, pts[j as usize]));
                        }
                    }
                }
            }
        }
        // The neighbourhood covers at least 2 cells in every direction: a closer pair would
        // have been seen. Beyond that, fall back to all pairs (only for tiny point counts).
        if best > 2.0 / grid.cells as f64 {
            for (i, &p) in pts.iter().enumerate() {
                for &q in &pts[i + 1..] {
                    best = best.min(torus_distance(p, q));
                }
            }
        }
        best
    }

    /// The smallest torus distance between any two points.
    pub fn min_distance(&self) -> f64 {
        self.prefix_min_distance(self.points.len())
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_prefix_is_well_spread_and_the_tile_is_dense() {
        let t = PoissonTile::generate(7, 0.03);
        let r = t.min_distance();
        assert!(r >= 0.03, "min distance {r}");
        // Close to maximal: a maximal set has about 0.6-0.7 / r^2 points.
        let n = t.len() as f64;
        assert!(n * 0.03 * 0.03 > 0.55, "{n} points");
        for frac in [1.0 / 16.0, 0.25, 0.5] {
            let k = (n * frac) as usize;
            let rk = t.prefix_min_distance(k);
            assert!(
                rk >= 0.75 * 0.03 / frac.sqrt(),
                "prefix {frac}: min distance {rk}"
            );
        }
    }

    #[test]
    fn generation_is_deterministic() {
        assert_eq!(
            PoissonTile::generate(3, 0.05),
            PoissonTile::generate(3, 0.05)
        );
        assert_ne!(
            PoissonTile::generate(3, 0.05),
            PoissonTile::generate(4, 0.05)
        );
    }

    #[test]
    fn min_distance_sees_pairs_across_the_wrap() {
        let t = PoissonTile {
            points: vec![[0.001, 0.5], [0.999, 0.5], [0.5, 0.2]],
        };
        assert!((t.min_distance() - 0.002).abs() < 1e-12);
    }
}
