//! The finest surface's interpolation error on the coarse grids, computed once per map at
//! load: for every grid of spacing `hs 2^k` (`hs` the height-sample spacing, `k >= -1`) anchored
//! at the map origin and triangulated with diagonals from (i, j) to (i + 1, j + 1), per square
//! block of [`BLOCK_QUADS`] quads: a proven range of `F` over the block, a proven bound of
//! `|Lin F - F|` (the grid's linear interpolation of `F` at its vertices, against `F`) over the
//! block, and a proven bound of the same for every finer grid (spacing `hs 2^j`, `j < k`, and
//! every spacing of at most `hs / 2` anchored at the origin).
//!
//! Terrain nodes whose vertex spacing is one of these grids take their bounds from here
//! ([`crate::terrain::bounds::from_map_error`]) instead of measuring the surface at run time: the
//! blocks of a node of spacing `hs 2^k` are exactly these blocks. On the default map that is
//! every node of 64 m and more; the 32 m nodes' grid (`k = -2`) is added by the terrain
//! ([`crate::terrain::precomputed`], [`MapErrorPyramid::insert_finer`]).
//!
//! Why it is a proof: the argument of [`crate::terrain::bounds`]. `F` is evaluated on a check
//! lattice of [`CHECK_PER_CELL`] points per height-cell side (spacing `c`); every grid's vertices
//! are lattice points and its triangles are unions of check triangles with the same diagonal
//! direction, so on each check cell
//! `|Lin F - F| <= max over its corners of |Lin F - F| + between(c)`, with `between` from the
//! region bounds of the height cell that contains the check cell
//! ([`super::world::RegionBounds::between_m`]), and `F` lies within its corners' range widened by
//! `between(c)`. The grid of spacing `hs / 2` (grid index 0, `k = -1`) is measured the same way;
//! the grid of spacing `c` has zero error at lattice points, so its bound is `between(c)`, and
//! every finer grid's triangles lie inside check triangles with legs `t <= c / 2`, bounded by
//! `between(t) <= between(c)` (it grows with `t`). f32 storage rounds every bound outwards, and a margin of
//! `1e-9 (1 + |F|)` covers the f64 evaluation and vertex positions an ulp apart.

use super::world::{Rect, World};

/// Quads per block side (the terrain's blocks: `NODE_QUADS / BLOCKS_PER_SIDE`).
pub const BLOCK_QUADS: usize = 8;
/// Check-lattice points per height-cell side.
pub const CHECK_PER_CELL: usize = 4;

/// One block's bounds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapBlock {
    pub z_min_m: f64,
    pub z_max_m: f64,
    /// Bound of `|Lin F - F|` over the block for this grid.
    pub error_m: f64,
    /// Bound of the same for every finer grid.
    pub finer_error_m: f64,
}

/// Blocks of one grid spacing, row-major from the south-west: `[z_min, z_max, error, finer]`.
#[derive(Debug, Clone)]
pub(super) struct Level {
    pub(super) per_row: usize,
    pub(super) rows: usize,
    /// In memory (empty when `paged`).
    pub(super) blocks: Vec<[f32; 4]>,
    /// A baked map's grid read page by page ([`super::map_error_pages`]): per block row, the
    /// block's four values as four samples.
    pub(super) paged: Option<super::levels::Level>,
}

/// The per-block bounds of `F` for the grids of spacing `hs 2^k`, `k >= -1`: grid index
/// `k + 1`, so grid 0 has spacing `hs / 2`; with [`Self::insert_finer`], also `k = -2` (grid
/// index `k + 2`).
#[derive(Debug, Clone, Default)]
pub struct MapErrorPyramid {
    pub(super) origin_m: [f64; 2],
    /// The vertex spacing of grid 0 (`hs / 2`).
    pub(super) spacing_m: f64,
    pub(super) levels: Vec<Level>,
}

/// Per band of `BLOCK_QUADS` height-cell rows, the band's partial block values
/// `[z_min, z_max, error, finer error]` (min, max, max, max) for each block column.
struct Band {
    /// Per grid of spacing `hs 2^k`, `k >= 0`: one row of blocks.
    coarse: Vec<Vec<[f64; 4]>>,
    /// The grid of spacing `hs / 2`, whose blocks are half as high as the band: two rows.
    half: [Vec<[f64; 4]>; 2],
}

impl MapErrorPyramid {
    /// Computes the pyramid of `world`'s surface, on all cores. Grids are kept while the map
    /// holds at least four blocks of them per side (a terrain root's blocks are a quarter of a
    /// map at least as large).
    pub fn new(world: &World) -> Self {
        let heights = &world.map.heights;
        let (hs, o) = (world.cell_spacings_m().0, world.origin_m());
        let (cw, ch) = (heights.width() - 1, heights.height() - 1);
        let mut k_count = 0;
        while cw.min(ch) / (BLOCK_QUADS << k_count) >= 4 {
            k_count += 1;
        }
        let threads = worldgen::par::thread_count(0);
        // F at every height-sample position: the vertices of every grid.
        let mut vertices = vec![0.0f64; (cw + 1) * (ch + 1)];
        worldgen::par::for_each_row(
            &mut vertices,
            cw + 1,
            threads,
            |j, row| {
                for (i, v) in row.iter_mut().enumerate() {
                    *v = world.height_m(o[0] + i as f64 * hs, o[1] + j as f64 * hs);
                }
            },
            &|_| {},
        );
        let mut bands: Vec<Option<Band>> = (0..ch / BLOCK_QUADS).map(|_| None).collect();
        worldgen::par::for_each_row(
            &mut bands,
            1,
            threads,
            |b, out| out[0] = Some(band(world, &vertices, b, k_count)),
            &|_| {},
        );
        let bands: Vec<Band> = bands
            .into_iter()
            .map(|b| b.expect("every band computed"))
            .collect();
        let half_side = BLOCK_QUADS / 2;
        let half = {
            // Only the bands computed (whole bands of the map).
            let (per_row, rows) = (cw / half_side, 2 * bands.len());
            let blocks = (0..rows)
                .flat_map(|row| {
                    bands[row / 2].half[row % 2]
                        .iter()
                        .take(per_row)
                        .map(|v| round_outwards(*v))
                })
                .collect();
            Level {
                per_row,
                rows,
                blocks,
                paged: None,
            }
        };
        let coarse = (0..k_count).map(|k| {
            let side = BLOCK_QUADS << k;
            let (per_row, rows) = (cw / side, ch / side);
            let mut acc = vec![[f64::INFINITY, f64::NEG_INFINITY, 0.0, 0.0]; per_row * rows];
            for (b, band) in bands.iter().enumerate() {
                let row = b >> k;
                if row >= rows {
                    continue;
                }
                for (col, v) in band.coarse[k].iter().enumerate().take(per_row) {
                    let a = &mut acc[row * per_row + col];
                    a[0] = a[0].min(v[0]);
                    a[1] = a[1].max(v[1]);
                    a[2] = a[2].max(v[2]);
                    a[3] = a[3].max(v[3]);
                }
            }
            Level {
                per_row,
                rows,
                blocks: acc.iter().map(|a| round_outwards(*a)).collect(),
                paged: None,
            }
        });
        let mut p = Self {
            origin_m: o,
            spacing_m: 0.5 * hs,
            levels: std::iter::once(half).chain(coarse).collect(),
        };
        p.spread_finer_errors();
        p
    }

    /// Adds a grid of half the finest grid's spacing, whose blocks (`per_row` x `rows`,
    /// row-major from the map's south-west corner, `[z_min, z_max, error, finer error]` each)
    /// were bounded by the caller: the terrain's 32 m nodes on a 4 m map, measured by the node
    /// bounds' own argument ([`crate::terrain::precomputed`]). Stored rounded outwards like the
    /// others. The coarser grids' finer-grid bounds already cover it (they bound every grid of
    /// spacing at most `hs / 2`), so they are not changed.
    pub fn insert_finer(&mut self, per_row: usize, rows: usize, blocks: &[[f64; 4]]) {
        assert_eq!(blocks.len(), per_row * rows, "one value per block");
        assert!(
            !self.levels.is_empty(),
            "the map's own grids are computed first"
        );
        self.spacing_m *= 0.5;
        self.levels.insert(
            0,
            Level {
                per_row,
                rows,
                blocks: blocks.iter().map(|b| round_outwards(*b)).collect(),
                paged: None,
            },
        );
    }

    /// The vertex spacing of the finest grid kept (`hs / 2`, or `hs / 4` with
    /// [`Self::insert_finer`]'s grid).
    pub fn finest_spacing_m(&self) -> f64 {
        self.spacing_m
    }

    /// Heap bytes of the blocks in memory (a paged grid's resident pages are the page
    /// cache's).
    pub fn bytes(&self) -> usize {
        self.levels
            .iter()
            .map(|l| l.blocks.len() * 16 + l.paged.as_ref().map_or(0, super::levels::Level::bytes))
            .sum()
    }

    /// The pyramid as bytes (little-endian; see [`super::map_error_cache`]).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::new();
        for v in [self.origin_m[0], self.origin_m[1], self.spacing_m] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&(self.levels.len() as u32).to_le_bytes());
        for l in &self.levels {
            out.extend_from_slice(&(l.per_row as u32).to_le_bytes());
            out.extend_from_slice(&(l.rows as u32).to_le_bytes());
            for b in &l.blocks {
                for v in b {
                    out.extend_from_slice(&v.to_le_bytes());
                }
            }
        }
        out
    }

    /// The pyramid from [`Self::to_bytes`]' layout; `None` if the bytes do not hold one.
    pub fn from_bytes(bytes: &[u8]) -> Option<Self> {
        let mut at = 0usize;
        let mut take = |n: usize| {
            let s = bytes.get(at..at + n)?;
            at += n;
            Some(s)
        };
        let f64_at = |s: &[u8]| f64::from_le_bytes(s.try_into().expect("8 bytes"));
        let u32_at = |s: &[u8]| u32::from_le_bytes(s.try_into().expect("4 bytes")) as usize;
        let origin_m = [f64_at(take(8)?), f64_at(take(8)?)];
        let spacing_m = f64_at(take(8)?);
        let count = u32_at(take(4)?);
        let mut levels = Vec::new();
        for _ in 0..count.min(64) {
            let (per_row, rows) = (u32_at(take(4)?), u32_at(take(4)?));
            let data = take(per_row.checked_mul(rows)?.checked_mul(16)?)?;
            let blocks = data
                .chunks_exact(16)
                .map(|c| {
                    std::array::from_fn(|i| {
                        f32::from_le_bytes(c[4 * i..4 * i + 4].try_into().expect("4 bytes"))
                    })
                })
                .collect();
            levels.push(Level {
                per_row,
                rows,
                blocks,
                paged: None,
            });
        }
        (levels.len() == count && at == bytes.len()).then_some(Self {
            origin_m,
            spacing_m,
            levels,
        })
    }

    /// Number of grids kept.
    pub fn level_count(&self) -> usize {
        self.levels.len()
    }

    /// The grid index whose vertex spacing is `vertex_spacing_m`, if one is kept.
    pub fn level_of_spacing(&self, vertex_spacing_m: f64) -> Option<usize> {
        (0..self.levels.len()).find(|&k| self.spacing_of_level_m(k) == vertex_spacing_m)
    }

    /// The vertex spacing of grid `k` (`hs 2^(k - 1)`).
    pub fn spacing_of_level_m(&self, k: usize) -> f64 {
        self.spacing_m * f64::from(1u32 << k)
    }

    /// The block of grid `k` whose south-west corner is at world `min_m`, if it is a whole block
    /// of the map (and, on a baked map, its page can be read).
    pub fn block_at(&self, k: usize, min_m: [f64; 2]) -> Option<MapBlock> {
        self.blocks_at(k, min_m, 1).map(|b| b[0])
    }

    /// The `n` x `n` blocks of grid `k` from the one whose south-west corner is at world
    /// `min_m`, row-major from the south-west (a node's blocks, read at once): `None` unless all
    /// are whole blocks of the map (and, on a baked map, their pages can be read).
    pub fn blocks_at(&self, k: usize, min_m: [f64; 2], n: usize) -> Option<Vec<MapBlock>> {
        let level = self.levels.get(k)?;
        let side = self.spacing_of_level_m(k) * BLOCK_QUADS as f64;
        let whole = |v: f64| {
            let r = v.round();
            ((v - r).abs() <= 1e-9 && r >= 0.0).then_some(r as usize)
        };
        let bx = whole((min_m[0] - self.origin_m[0]) / side)?;
        let by = whole((min_m[1] - self.origin_m[1]) / side)?;
        if n == 0 || bx + n > level.per_row || by + n > level.rows {
            return None;
        }
        let block = |v: &[f32]| MapBlock {
            z_min_m: f64::from(v[0]),
            z_max_m: f64::from(v[1]),
            error_m: f64::from(v[2]),
            finer_error_m: f64::from(v[3]),
        };
        match &level.paged {
            None => Some(
                (by..by + n)
                    .flat_map(|y| (bx..bx + n).map(move |x| (x, y)))
                    .map(|(x, y)| block(&level.blocks[y * level.per_row + x]))
                    .collect(),
            ),
            Some(paged) => {
                let fault = super::map_error_pages::FAULT;
                let samples = paged.try_region([4 * bx, by], [4 * n, n], fault)?;
                Some(samples.chunks_exact(4).map(block).collect())
            }
        }
    }

    /// A block's finer-grid bound also covers the grids of its four quarter blocks (one level
    /// finer) and everything finer than them.
    fn spread_finer_errors(&mut self) {
        for k in 1..self.levels.len() {
            let (lower, upper) = self.levels.split_at_mut(k);
            let (fine, coarse) = (&lower[k - 1], &mut upper[0]);
            for by in 0..coarse.rows {
                for bx in 0..coarse.per_row {
                    let mut m = coarse.blocks[by * coarse.per_row + bx][3];
                    for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        let f = fine.blocks[(2 * by + dy) * fine.per_row + 2 * bx + dx];
                        m = m.max(f[2]).max(f[3]);
                    }
                    coarse.blocks[by * coarse.per_row + bx][3] = m;
                }
            }
        }
    }
}

/// `max |Lin - F|` over a cell's `(sub + 1)^2` check points `f` (row-major), for the quad with
/// corner values `v` of `per` lattice steps a side, the cell's first point lying (`dx`, `dy`)
/// steps from the quad's origin. `per` is a power of two, so the fractions are exact.
fn grid_error_at(f: &[f64], sub: usize, v: [f64; 4], dx: usize, dy: usize, per: usize) -> f64 {
    let inv = 1.0 / per as f64;
    let mut err = 0.0f64;
    for b in 0..=sub {
        let fy = (dy + b) as f64 * inv;
        for a in 0..=sub {
            let fx = (dx + a) as f64 * inv;
            err = err.max((lin(v, fx, fy) - f[b * (sub + 1) + a]).abs());
        }
    }
    err
}

/// Linear interpolation on the quad with corners `v = [v00, v10, v01, v11]` at fractions
/// (fx, fy) in [0, 1], triangulated by the diagonal (0, 0) - (1, 1): the triangulation of every
/// terrain mesh (also [`crate::terrain::bounds::interpolate_grid`]).
pub fn lin(v: [f64; 4], fx: f64, fy: f64) -> f64 {
    if fx >= fy {
        v[0] + fx * (v[1] - v[0]) + fy * (v[3] - v[1])
    } else {
        v[0] + fy * (v[2] - v[0]) + fx * (v[3] - v[2])
    }
}

/// f32 values that still bound the f64 ones: ranges widened, errors rounded up.
fn round_outwards(v: [f64; 4]) -> [f32; 4] {
    let down = |x: f64| {
        let f = x as f32;
        if f64::from(f) > x { f.next_down() } else { f }
    };
    let up = |x: f64| {
        let f = x as f32;
        if f64::from(f) < x { f.next_up() } else { f }
    };
    [down(v[0]), up(v[1]), up(v[2]), up(v[3])]
}

/// The partial block values of one band of `BLOCK_QUADS` height-cell rows for the grids of
/// spacing `hs 2^k`, `k` in `0..k_count`, and for the grid of spacing `hs / 2`, from `F` at the
/// height-sample positions (`vertices`) and on the band's check lattice. The finer-grid value
/// of the coarse grids is the bound for grids of spacing at most `hs / 2`; that of the `hs / 2`
/// grid, for grids of spacing at most `c`.
fn band(world: &World, vertices: &[f64], band: usize, k_count: usize) -> Band {
    let heights = &world.map.heights;
    let (hs, o) = (world.cell_spacings_m().0, world.origin_m());
    let (cw, ch) = (heights.width() - 1, heights.height() - 1);
    let sub = CHECK_PER_CELL;
    let c = hs / sub as f64;
    // F on the band's check lattice: (BLOCK_QUADS sub + 1) rows of (cw sub + 1) points.
    let (lw, lh) = (cw * sub + 1, BLOCK_QUADS * sub + 1);
    let y0 = band * BLOCK_QUADS;
    let xs: Vec<f64> = (0..lw).map(|i| o[0] + i as f64 * c).collect();
    let ys: Vec<f64> = (0..lh).map(|j| o[1] + (y0 * sub + j) as f64 * c).collect();
    let lattice = world.heights_on_lattice(&xs, &ys);
    let empty = [f64::INFINITY, f64::NEG_INFINITY, 0.0, 0.0];
    let mut out = Band {
        coarse: (0..k_count)
            .map(|k| vec![empty; cw / (BLOCK_QUADS << k)])
            .collect(),
        half: std::array::from_fn(|_| vec![empty; cw / (BLOCK_QUADS / 2)]),
    };
    let vertex = |x: usize, y: usize| vertices[y * (cw + 1) + x];
    let at = |i: usize, j: usize| lattice[j * lw + i];
    for y in y0..y0 + BLOCK_QUADS {
        let ly = (y - y0) * sub;
        for x in 0..cw {
            let lx = x * sub;
            let cell = Rect {
                min: [o[0] + x as f64 * hs, o[1] + y as f64 * hs],
                max: [o[0] + (x + 1) as f64 * hs, o[1] + (y + 1) as f64 * hs],
            };
            let between = world.region_bounds(cell).between_m(c);
            let mut f = [0.0f64; (CHECK_PER_CELL + 1) * (CHECK_PER_CELL + 1)];
            for b in 0..=sub {
                for a in 0..=sub {
                    f[b * (sub + 1) + a] = at(lx + a, ly + b);
                }
            }
            let lo = f.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = f.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let margin = 1e-9 * (1.0 + lo.abs().max(hi.abs()));
            // The grid of spacing hs / 2: quads of 2 lattice steps, so a cell of `sub` steps
            // holds (sub / 2)^2 of them.
            let mut half = 0.0f64;
            for qb in (ly..ly + sub).step_by(2) {
                for qa in (lx..lx + sub).step_by(2) {
                    let v = [
                        at(qa, qb),
                        at(qa + 2, qb),
                        at(qa, qb + 2),
                        at(qa + 2, qb + 2),
                    ];
                    let inv = 0.5;
                    for b in 0..=2 {
                        for a in 0..=2 {
                            let (fx, fy) = (a as f64 * inv, b as f64 * inv);
                            half = half.max((lin(v, fx, fy) - at(qa + a, qb + b)).abs());
                        }
                    }
                }
            }
            let finer = half + between + 2.0 * margin;
            if let Some(v) = out.half[(y - y0) / (BLOCK_QUADS / 2)].get_mut(x / (BLOCK_QUADS / 2)) {
                v[0] = v[0].min(lo - between - margin);
                v[1] = v[1].max(hi + between + margin);
                v[2] = v[2].max(finer);
                v[3] = v[3].max(between + 2.0 * margin);
            }
            for (k, blocks) in out.coarse.iter_mut().enumerate() {
                // Only cells of whole blocks (the quads of partial ones may leave the map).
                if y / (BLOCK_QUADS << k) >= ch / (BLOCK_QUADS << k) {
                    continue;
                }
                let Some(v) = blocks.get_mut(x / (BLOCK_QUADS << k)) else {
                    continue;
                };
                let q = 1usize << k;
                let (qx, qy) = (x >> k << k, y >> k << k);
                let corners = [
                    vertex(qx, qy),
                    vertex(qx + q, qy),
                    vertex(qx, qy + q),
                    vertex(qx + q, qy + q),
                ];
                let err = grid_error_at(&f, sub, corners, (x - qx) * sub, (y - qy) * sub, sub * q);
                v[0] = v[0].min(lo - between - margin);
                v[1] = v[1].max(hi + between + margin);
                v[2] = v[2].max(err + between + 2.0 * margin);
                v[3] = v[3].max(finer);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use worldgen::noise::unit3;

    /// The committed tiny map (512 m, roads, detail) moved off the origin, with a 60 m cliff
    /// between two sample columns and two single-sample spikes burned into its heights.
    fn hard_world() -> World {
        let mut map = crate::test_maps::tiny_map();
        let (w, h) = (map.heights.width(), map.heights.height());
        for y in 0..h {
            for x in 70..w {
                let hg = map.heights.grid_mut().expect("heights in memory");
                hg.set(x, y, hg.get(x, y) + 60.0);
            }
        }
        let hg = map.heights.grid_mut().expect("heights in memory");
        hg.set(30, 40, hg.get(30, 40) + 40.0);
        let hg = map.heights.grid_mut().expect("heights in memory");
        hg.set(100, 20, hg.get(100, 20) - 25.0);
        World::new(map)
    }

    /// `Lin F` of the grid of spacing `t` anchored at `o` (diagonals (i, j) -> (i + 1, j + 1)),
    /// vertices evaluated from the surface itself, at a world position.
    fn lin(w: &World, o: [f64; 2], t: f64, x: f64, y: f64) -> f64 {
        let (gx, gy) = ((x - o[0]) / t, (y - o[1]) / t);
        let (i, j) = (gx.floor(), gy.floor());
        let (fx, fy) = (gx - i, gy - j);
        let v = |a: f64, b: f64| w.height_m(o[0] + (i + a) * t, o[1] + (j + b) * t);
        let (v00, v10, v01, v11) = (v(0.0, 0.0), v(1.0, 0.0), v(0.0, 1.0), v(1.0, 1.0));
        if fx >= fy {
            v00 + fx * (v10 - v00) + fy * (v11 - v10)
        } else {
            v00 + fy * (v01 - v00) + fx * (v11 - v01)
        }
    }

    /// Every stored bound holds at 80,000 random points (a third of them on the cliff band)
    /// against the surface evaluated directly, for the block's own grid and for finer grids,
    /// and the bounds are measured, not guessed: random points come close to them.
    #[test]
    fn stored_bounds_hold_at_random_points_on_a_hard_map() {
        let w = hard_world();
        let (o, hs) = (w.origin_m(), w.cell_spacings_m().0);
        let p = &w.map_error;
        assert_eq!(
            p.level_count(),
            4,
            "128 cells: blocks of 4 (the half-spacing grid), 8, 16 and 32 cells"
        );
        let mut worst_ratio = [0.0f64; 4];
        for i in 0..80_000i64 {
            let k = (i % 4) as usize;
            let t = p.spacing_of_level_m(k);
            let side = t * BLOCK_QUADS as f64;
            let (x, y) = if i % 3 == 0 {
                (
                    o[0] + 276.0 + 8.0 * unit3(1, i, 0),
                    o[1] + 512.0 * unit3(1, i, 1),
                )
            } else {
                (o[0] + 512.0 * unit3(2, i, 0), o[1] + 512.0 * unit3(2, i, 1))
            };
            let min = [
                o[0] + ((x - o[0]) / side).floor() * side,
                o[1] + ((y - o[1]) / side).floor() * side,
            ];
            let b = p.block_at(k, min).expect("whole block");
            let z = w.height_m(x, y);
            assert!(
                z >= b.z_min_m && z <= b.z_max_m,
                "F {z} outside [{}, {}]",
                b.z_min_m,
                b.z_max_m
            );
            let e = (lin(&w, o, t, x, y) - z).abs();
            assert!(
                e <= b.error_m,
                "grid {k} at ({x}, {y}): error {e} > bound {}",
                b.error_m
            );
            worst_ratio[k] = worst_ratio[k].max(e / b.error_m.max(1e-9));
            for finer in [0.5 * t, 0.5 * hs, 0.25 * hs, 0.1 * hs] {
                if finer < t {
                    let e = (lin(&w, o, finer, x, y) - z).abs();
                    assert!(
                        e <= b.finer_error_m,
                        "grid {k}, finer spacing {finer}: error {e} > bound {}",
                        b.finer_error_m
                    );
                }
            }
        }
        // Grid 0 (spacing hs / 2) has only two check points per quad side, so the
        // between-points term is a larger share of its bound than of the coarser grids'.
        for (k, r) in worst_ratio.iter().enumerate() {
            let least = if k == 0 { 0.4 } else { 0.5 };
            assert!(*r > least, "grid {k}: largest error / bound only {r}");
        }
    }

    #[test]
    fn blocks_outside_the_map_or_off_the_grid_are_not_served() {
        let w = hard_world();
        let (p, o) = (&w.map_error, w.origin_m());
        let at = |x: f64, y: f64| [o[0] + x, o[1] + y];
        assert!(p.block_at(1, at(0.0, 0.0)).is_some());
        assert!(p.block_at(1, at(32.0, 480.0)).is_some());
        assert!(p.block_at(1, at(512.0, 0.0)).is_none(), "east of the map");
        assert!(p.block_at(1, at(-32.0, 0.0)).is_none());
        assert!(
            p.block_at(1, at(16.0, 0.0)).is_none(),
            "not on the block grid"
        );
        assert!(p.block_at(0, at(16.0, 0.0)).is_some(), "half-spacing grid");
        assert!(p.block_at(0, at(8.0, 0.0)).is_none());
        assert!(p.block_at(4, at(0.0, 0.0)).is_none(), "grid not kept");
        assert_eq!(p.level_of_spacing(8.0), Some(2));
        assert_eq!(p.level_of_spacing(2.0), Some(0));
        assert_eq!(p.level_of_spacing(1.0), None);
    }
}
