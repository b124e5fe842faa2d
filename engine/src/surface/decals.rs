//! Decal height shaping: roads and paths flatten the ground to their centre line's height (plus
//! their offset), building pads to their polygon's height, rock patches raise it.
//!
//! The shaping is a displacement field `E` added to the finest surface. `E` is the C1
//! Catmull-Rom interpolation of offsets stored at a 0.5 m sample lattice (zero where no decal
//! reaches), so its slope and curvature are bounded per cell from sample differences exactly like
//! the map's own bicubic heights ([`crate::surface::world`]). A sample's offset is `w * (target - G)` for
//! roads, paths and pads (`G` the bicubic map height at the sample, `target` the centre line's
//! interpolated z, or a pad's z, plus the decal's offset) and `w * offset` for the other areas;
//! the "road weight" that clears vegetation and procedural detail counts pads too. The weight
//! `w` is 1 within half the width (plus [`FLAT_MARGIN_M`] for roads and paths, so the visible
//! width is exactly flat) and falls to 0 over `falloff_m` (smoothstep). Where decals
//! overlap, the one with the larger weight wins (the first in the file on ties). Sampling at
//! lattice points means a closest-point discontinuity inside a tight bend is just a larger
//! difference between two samples: the bounds stay honest and `E` stays C1.
//!
//! Samples are stored sparsely in 8 x 8 blocks, so a map with 28 km of roads holds about 9 MB;
//! the per-block slope and curvature bounds live in a sparse max pyramid.

use super::decal_tiles::{
    BLOCK, BLOCK_SAMPLES, TILE_BLOCKS, TILE_LEVELS, TILE_SAMPLES, Tile, TileFile, split,
};
use rustc_hash::FxHashMap;
use std::sync::Arc;
use worldgen::map::{Decal, DecalKind};
use worldgen::sample::catmull_rom_weights;

/// Spacing (m) of the decal offset lattice.
pub const DECAL_SPACING_M: f64 = 0.5;
/// The flat core of a road or path reaches this much beyond its half width, so that every
/// sample of the 4 x 4 interpolation stencil of a point within the half width is in the core
/// (the stencil's farthest sample is `2 sqrt(2)` spacings away): the visible road is flat.
pub const FLAT_MARGIN_M: f64 = 2.0 * std::f64::consts::SQRT_2 * DECAL_SPACING_M;
/// Samples per side of the stencils of one block's cells (one before, two after).
pub(super) const STENCIL_SIDE: i64 = BLOCK + 3;
/// Block side (m): bounds are kept per block.
pub const DECAL_BLOCK_M: f64 = DECAL_SPACING_M * BLOCK as f64;

/// Packs signed block coordinates into a hash key.
pub(super) fn key(bx: i64, by: i64) -> u64 {
    ((bx as u32 as u64) << 32) | u64::from(by as u32)
}

/// The block coordinates of a hash key.
pub(super) fn unkey(k: u64) -> (i64, i64) {
    (
        i64::from((k >> 32) as u32 as i32),
        i64::from(k as u32 as i32),
    )
}

/// Slope, curvature and magnitude bounds (|grad E|, Hessian norm of E, |E|) per block.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DecalBounds {
    pub slope: f64,
    pub curvature: f64,
    pub magnitude_m: f64,
}

/// The decal displacement field of a map (see the module docs).
#[derive(Debug, Default, Clone)]
pub struct DecalField {
    pub(super) origin_m: [f64; 2],
    /// The blocks of samples (row-major from a block's south-west sample), the bound levels
    /// below [`TILE_LEVELS`] and the largest road/path weight per sample (for suppressing
    /// procedural detail on roads), by tile: all in memory, or read from a bake.
    pub(super) tiles: Tiles,
    /// Bound levels from [`TILE_LEVELS`] on: level k holds bounds over 2^k x 2^k blocks;
    /// absent = zero.
    pub(super) upper_bounds: Vec<FxHashMap<u64, [f32; 3]>>,
    /// How many bound levels there are in all (levels are made until one cell is left).
    pub(super) bound_levels: usize,
    pub(super) block_count: usize,
    pub(super) road_count: usize,
    /// Per coarse cell: whether any road/path sample lies in it (samples outside the coarse
    /// grid are always looked up), so most lookups away from roads skip the tiles.
    pub(super) road_cells: Vec<bool>,
    /// Coarse occupancy over the map: false where no stored block can reach (fast zero).
    pub(super) coarse: Vec<bool>,
    pub(super) coarse_dims: [usize; 2],
    pub(super) coarse_cell_m: f64,
}

/// A tile's column and row (from the tile holding the field's origin).
pub(super) type TileKey = (i64, i64);

/// The field's tiles by key.
pub(super) type TileMap = FxHashMap<TileKey, Arc<Tile>>;

/// Where a field's tiles are.
#[derive(Debug, Clone)]
pub(super) enum Tiles {
    Memory(Arc<TileMap>),
    /// Read on first use from a baked tile file.
    File(Arc<TileFile>),
}

impl Default for Tiles {
    fn default() -> Self {
        Tiles::Memory(Arc::default())
    }
}

/// Reads a field's tiles for one query, keeping the last tile it fetched (most queries stay
/// in one tile).
struct Reader<'a> {
    field: &'a DecalField,
    last: Option<(TileKey, Option<Held<'a>>)>,
    /// Whether a tile could not be read (the fault is recorded).
    failed: bool,
}

/// A tile a reader holds: borrowed from a field in memory (no reference count touched on the
/// per-point path), or shared with a tile file's cache.
enum Held<'a> {
    Borrowed(&'a Tile),
    Shared(Arc<Tile>),
}

impl<'a> Reader<'a> {
    fn new(field: &'a DecalField) -> Self {
        Self {
            field,
            last: None,
            failed: false,
        }
    }

    fn tile(&mut self, t: (i64, i64)) -> Option<&Tile> {
        if self.last.as_ref().is_none_or(|(k, _)| *k != t) {
            let field = self.field;
            let got = match &field.tiles {
                Tiles::Memory(m) => m.get(&t).map(|tile| Held::Borrowed(tile)),
                Tiles::File(f) => f
                    .tile(t)
                    .unwrap_or_else(|()| {
                        self.failed = true;
                        None
                    })
                    .map(Held::Shared),
            };
            self.last = Some((t, got));
        }
        match self.last.as_ref()?.1.as_ref()? {
            Held::Borrowed(tile) => Some(tile),
            Held::Shared(tile) => Some(tile),
        }
    }

    fn block(&mut self, bx: i64, by: i64) -> Option<&[f32; BLOCK_SAMPLES]> {
        let ((tx, lx), (ty, ly)) = (split(bx, TILE_BLOCKS), split(by, TILE_BLOCKS));
        self.tile((tx, ty))?
            .blocks
            .get((ly * TILE_BLOCKS + lx) as u16)
    }

    fn sample(&mut self, ix: i64, iy: i64) -> f64 {
        self.block(ix.div_euclid(BLOCK), iy.div_euclid(BLOCK))
            .map_or(0.0, |b| {
                f64::from(b[(iy.rem_euclid(BLOCK) * BLOCK + ix.rem_euclid(BLOCK)) as usize])
            })
    }
}

/// One lattice coordinate's share of [`DecalField::offset_m`], relative to the field's origin:
/// its coarse cell (`None` where the fast-zero test does not apply), the sample index below it
/// and its Catmull-Rom weights.
struct LatticeAxis {
    coarse: Option<usize>,
    index: i64,
    weights: [f64; 4],
}

impl LatticeAxis {
    fn new(local_m: f64, coarse_cell_m: f64, coarse_len: usize) -> Self {
        let c = local_m / coarse_cell_m;
        let g = local_m / DECAL_SPACING_M;
        let g0 = worldgen::sample::floor_small(g);
        Self {
            coarse: (c >= 0.0 && (c as usize) < coarse_len).then_some(c as usize),
            index: g0 as i64,
            weights: catmull_rom_weights(g - g0),
        }
    }
}

/// Sorted sample indices along one axis grouped in runs of the same block: the block of each
/// run and the run of each index.
struct BlockRuns {
    blocks: Vec<i64>,
    run: Vec<usize>,
    /// First index of each run, and one past the last index.
    starts: Vec<usize>,
}

impl BlockRuns {
    fn new(samples: &[i64]) -> Self {
        let (mut blocks, mut run, mut starts) = (Vec::new(), Vec::new(), Vec::new());
        for (k, s) in samples.iter().enumerate() {
            let b = s.div_euclid(BLOCK);
            if blocks.last() != Some(&b) {
                blocks.push(b);
                starts.push(k);
            }
            run.push(blocks.len() - 1);
        }
        starts.push(samples.len());
        Self {
            blocks,
            run,
            starts,
        }
    }

    /// The indices (positions in the sample list) of run `r`.
    fn entries(&self, r: usize) -> std::ops::Range<usize> {
        self.starts[r]..self.starts[r + 1]
    }
}

/// Decal weight at distance `d_m` from its centre line (or outside its area).
pub fn decal_weight(d: &Decal, d_m: f64) -> f64 {
    let half = flat_half_width_m(d);
    let falloff = f64::from(d.falloff_m);
    if d_m <= half {
        1.0
    } else if falloff <= 0.0 || d_m >= half + falloff {
        0.0
    } else {
        let s = 1.0 - (d_m - half) / falloff;
        s * s * (3.0 - 2.0 * s)
    }
}

/// Half the width of the part at full weight (roads and paths get [`FLAT_MARGIN_M`] more).
pub(super) fn flat_half_width_m(d: &Decal) -> f64 {
    let half = f64::from(d.width_m) * 0.5;
    match d.kind {
        DecalKind::Road | DecalKind::Path => half + FLAT_MARGIN_M,
        DecalKind::RockPatch | DecalKind::Field | DecalKind::Dirt | DecalKind::Pad => half,
    }
}

/// Distance (m) from a decal's centre line (or outline) beyond which it changes nothing: its
/// samples reach its flat half width plus its falloff, and the interpolation stencil of a point
/// reaches samples up to `2 sqrt(2)` spacings away.
pub fn decal_reach_m(d: &Decal) -> f64 {
    flat_half_width_m(d) + f64::from(d.falloff_m) + 2.0 * std::f64::consts::SQRT_2 * DECAL_SPACING_M
}

impl DecalField {
    /// Heap bytes, approximately: hash-map entries times their size (key, value, a control
    /// byte), boxed blocks, the occupancy grids.
    pub fn heap_bytes(&self) -> usize {
        let tiles = match &self.tiles {
            Tiles::Memory(m) => {
                m.capacity() * (16 + 8 + 1) + m.values().map(|t| t.bytes()).sum::<usize>()
            }
            Tiles::File(f) => f.bytes(),
        };
        tiles
            + self
                .upper_bounds
                .iter()
                .map(|b| b.capacity() * (8 + 12 + 1))
                .sum::<usize>()
            + self.road_cells.len()
            + self.coarse.len()
    }

    /// The coarse cell holding lattice sample (ix, iy), None outside the coarse grid.
    pub(super) fn cell_of(dims: [usize; 2], cell_m: f64, ix: i64, iy: i64) -> Option<usize> {
        let c = |i: i64, n: usize| {
            let v = (i as f64 * DECAL_SPACING_M / cell_m).floor();
            (v >= 0.0 && v < n as f64).then_some(v as usize)
        };
        Some(c(iy, dims[1])? * dims[0] + c(ix, dims[0])?)
    }

    pub fn is_empty(&self) -> bool {
        self.block_count == 0
    }

    /// Stored samples (blocks x 64).
    pub fn bytes(&self) -> usize {
        self.block_count * BLOCK_SAMPLES * 4
    }

    /// Offset (m) stored at lattice sample (ix, iy); zero where no decal reaches (or where
    /// its tile cannot be read).
    pub fn sample(&self, ix: i64, iy: i64) -> f64 {
        Reader::new(self).sample(ix, iy)
    }

    /// The displacement `E` (m) at a world position.
    pub fn offset_m(&self, x_m: f64, y_m: f64) -> f64 {
        if self.block_count == 0 {
            return 0.0;
        }
        let x = self.lattice_axis(x_m, 0);
        let y = self.lattice_axis(y_m, 1);
        if self.fast_zero(&x, &y) {
            return 0.0;
        }
        let (ix, iy) = (x.index, y.index);
        // The 4 x 4 stencil touches at most 2 x 2 blocks; none stored means zero.
        let (bx0, bx1) = ((ix - 1).div_euclid(BLOCK), (ix + 2).div_euclid(BLOCK));
        let (by0, by1) = ((iy - 1).div_euclid(BLOCK), (iy + 2).div_euclid(BLOCK));
        let mut reader = Reader::new(self);
        if !(by0..=by1).any(|by| (bx0..=bx1).any(|bx| reader.block(bx, by).is_some())) {
            return 0.0;
        }
        let mut sum = 0.0;
        for (j, wyj) in y.weights.iter().enumerate() {
            let mut row = 0.0;
            for (i, wxi) in x.weights.iter().enumerate() {
                row += wxi * reader.sample(ix + i as i64 - 1, iy + j as i64 - 1);
            }
            sum += wyj * row;
        }
        sum
    }

    /// One world coordinate along `axis` (0 = x, 1 = y) as [`Self::offset_m`] reads it.
    fn lattice_axis(&self, v_m: f64, axis: usize) -> LatticeAxis {
        LatticeAxis::new(
            v_m - self.origin_m[axis],
            self.coarse_cell_m,
            self.coarse_dims[axis],
        )
    }

    /// Fast zero away from decals: the position's coarse cell holds no stored block (positions
    /// outside the coarse grid take the full path).
    fn fast_zero(&self, x: &LatticeAxis, y: &LatticeAxis) -> bool {
        matches!((x.coarse, y.coarse), (Some(cx), Some(cy))
            if !self.coarse[cy * self.coarse_dims[0] + cx])
    }

    /// [`Self::offset_m`] at every point of the lattice `xs` x `ys` (row-major, one row per
    /// `ys` entry), equal to it point by point. The blocks the lattice's stencils reach are read
    /// once into a dense patch, each sample row is filtered along x once per column, and each
    /// point sums four such values (the same operations in the same order); the fast-zero tests
    /// are the point version's, per column and row.
    pub fn offsets_on_lattice(&self, xs: &[f64], ys: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; xs.len() * ys.len()];
        if self.block_count == 0 || xs.is_empty() || ys.is_empty() {
            return out;
        }
        let axis = |v: &[f64], a: usize| -> Vec<LatticeAxis> {
            v.iter().map(|&t| self.lattice_axis(t, a)).collect()
        };
        let (cols, rows) = (axis(xs, 0), axis(ys, 1));
        // The points that pass the fast-zero test (the point version's, per column and row).
        let mut live: Vec<(usize, usize)> = Vec::new();
        for (j, y) in rows.iter().enumerate() {
            for (i, x) in cols.iter().enumerate() {
                let fast_zero = self.fast_zero(x, y);
                if !fast_zero {
                    live.push((i, j));
                }
            }
        }
        if live.is_empty() {
            return out;
        }
        // The distinct samples the stencils read along each axis, in runs by block.
        let stencils = |a: &[LatticeAxis]| {
            let starts: Vec<i64> = a.iter().map(|c| c.index - 1).collect();
            let (samples, first) = worldgen::sample::stencil_indices(&starts, 4);
            let runs = BlockRuns::new(&samples);
            (samples, first, runs)
        };
        let (sx, first_x, runs_x) = stencils(&cols);
        let (sy, first_y, runs_y) = stencils(&rows);
        let (pw, ph, nrx) = (sx.len(), sy.len(), runs_x.blocks.len());
        // Blocks looked up on first use (0 unknown, 1 absent, 2 present); a present block's
        // samples are copied into the patch then (absent samples are 0, as `sample` says).
        let mut state = vec![0u8; nrx * runs_y.blocks.len()];
        let mut patch = vec![0.0f64; pw * ph];
        let mut reader = Reader::new(self);
        let mut present = |rx: usize, ry: usize| -> bool {
            let k = ry * nrx + rx;
            if state[k] == 0 {
                state[k] = 1;
                if let Some(b) = reader.block(runs_x.blocks[rx], runs_y.blocks[ry]) {
                    state[k] = 2;
                    for y in runs_y.entries(ry) {
                        for x in runs_x.entries(rx) {
                            let t = sy[y].rem_euclid(BLOCK) * BLOCK + sx[x].rem_euclid(BLOCK);
                            patch[y * pw + x] = f64::from(b[t as usize]);
                        }
                    }
                }
            }
            state[k] == 2
        };
        // Keep the points with a stored block under their stencil.
        live.retain(|&(i, j)| {
            let (x0, x1) = (runs_x.run[first_x[i]], runs_x.run[first_x[i] + 3]);
            let (y0, y1) = (runs_y.run[first_y[j]], runs_y.run[first_y[j] + 3]);
            let mut any = false;
            for ry in y0..=y1 {
                for rx in x0..=x1 {
                    any |= present(rx, ry);
                }
            }
            any
        });
        // Each patch row the kept points read, filtered along x per column (`row` of the point
        // version); then each point sums four of them.
        let n = xs.len();
        let mut row_needed = vec![false; ph];
        for &(_, j) in &live {
            row_needed[first_y[j]..first_y[j] + 4].fill(true);
        }
        let mut along_x = vec![0.0f64; ph * n];
        for r in (0..ph).filter(|&r| row_needed[r]) {
            for (i, c) in cols.iter().enumerate() {
                let samples = &patch[r * pw + first_x[i]..][..4];
                let mut row = 0.0;
                for (w, v) in c.weights.iter().zip(samples) {
                    row += w * v;
                }
                along_x[r * n + i] = row;
            }
        }
        for (i, j) in live {
            let mut sum = 0.0;
            for (k, wy) in rows[j].weights.iter().enumerate() {
                sum += wy * along_x[(first_y[j] + k) * n + i];
            }
            out[j * n + i] = sum;
        }
        out
    }

    /// False only when no road/path sample lies within `margin_m` (plus one lattice spacing)
    /// of the position: then every [`Self::road_weight`] within `margin_m` is 0. A cheap test
    /// on the coarse road cells (true where unsure: outside the coarse grid).
    pub fn road_near(&self, x_m: f64, y_m: f64, margin_m: f64) -> bool {
        let r = margin_m + DECAL_SPACING_M;
        let (x0, y0) = (x_m - r - self.origin_m[0], y_m - r - self.origin_m[1]);
        if self.road_cells.is_empty() || x0 < 0.0 || y0 < 0.0 {
            return self.road_count > 0;
        }
        let c = self.coarse_cell_m;
        // Non-negative: truncation is the floor.
        let (cx0, cy0) = ((x0 / c) as usize, (y0 / c) as usize);
        let (cx1, cy1) = (((x0 + 2.0 * r) / c) as usize, ((y0 + 2.0 * r) / c) as usize);
        let [w, h] = self.coarse_dims;
        if cx1 >= w || cy1 >= h {
            return self.road_count > 0;
        }
        (cy0..=cy1).any(|cy| (cx0..=cx1).any(|cx| self.road_cells[cy * w + cx]))
    }

    /// Largest road or path weight at the lattice sample nearest to a world position.
    pub fn road_weight(&self, x_m: f64, y_m: f64) -> f64 {
        let ix = ((x_m - self.origin_m[0]) / DECAL_SPACING_M).round() as i64;
        let iy = ((y_m - self.origin_m[1]) / DECAL_SPACING_M).round() as i64;
        if let Some(c) = Self::cell_of(self.coarse_dims, self.coarse_cell_m, ix, iy)
            && !self.road_cells[c]
        {
            return 0.0;
        }
        let ((tx, lx), (ty, ly)) = (split(ix, TILE_SAMPLES), split(iy, TILE_SAMPLES));
        Reader::new(self)
            .tile((tx, ty))
            .and_then(|t| t.road_weight.get((ly * TILE_SAMPLES + lx) as u32))
            .map_or(0.0, |&w| f64::from(w))
    }

    /// Road/path lattice samples with their weight (for suppressing detail on roads).
    /// Reads every tile of a baked field (the ones that cannot be read give none).
    pub fn road_samples(&self) -> Vec<([f64; 2], f64)> {
        let tiles: Vec<(i64, i64)> = match &self.tiles {
            Tiles::Memory(m) => m.keys().copied().collect(),
            Tiles::File(f) => f.tiles(),
        };
        let mut reader = Reader::new(self);
        let mut out = Vec::with_capacity(self.road_count);
        for (tx, ty) in tiles {
            let Some(tile) = reader.tile((tx, ty)) else {
                continue;
            };
            out.extend(tile.road_weight.iter().map(|(i, &w)| {
                let ix = tx * TILE_SAMPLES + i64::from(i) % TILE_SAMPLES;
                let iy = ty * TILE_SAMPLES + i64::from(i) / TILE_SAMPLES;
                (
                    [
                        self.origin_m[0] + ix as f64 * DECAL_SPACING_M,
                        self.origin_m[1] + iy as f64 * DECAL_SPACING_M,
                    ],
                    f64::from(w),
                )
            }));
        }
        out
    }

    /// Bounds of `E` over a world rectangle (possibly over a little more: still an upper bound).
    pub fn region_bounds(&self, min_m: [f64; 2], max_m: [f64; 2]) -> DecalBounds {
        if self.bound_levels == 0 {
            return DecalBounds::default();
        }
        let cell = DECAL_SPACING_M * BLOCK as f64;
        // A point on a block border touches both blocks; widen by a hair so both are counted.
        let e = cell * 1e-9;
        let to = |v: f64, o: f64| ((v - o) / cell).floor() as i64;
        let (x0, x1) = (
            to(min_m[0] - e, self.origin_m[0]),
            to(max_m[0] + e, self.origin_m[0]),
        );
        let (y0, y1) = (
            to(min_m[1] - e, self.origin_m[1]),
            to(max_m[1] + e, self.origin_m[1]),
        );
        let span = (x1 - x0 + 1).max(y1 - y0 + 1) as u64;
        let k = ((u64::BITS - 1 - span.leading_zeros()) as usize).min(self.bound_levels - 1);
        let mut reader = Reader::new(self);
        let mut m = [0.0f32; 3];
        for by in (y0 >> k)..=(y1 >> k) {
            for bx in (x0 >> k)..=(x1 >> k) {
                let cell = if k < TILE_LEVELS {
                    let per = TILE_BLOCKS >> k;
                    let ((tx, lx), (ty, ly)) = (split(bx, per), split(by, per));
                    reader
                        .tile((tx, ty))
                        .and_then(|t| t.bounds[k].get((ly * per + lx) as u16).copied())
                } else {
                    self.upper_bounds[k - TILE_LEVELS]
                        .get(&key(bx, by))
                        .copied()
                };
                if let Some(v) = cell {
                    for (a, b) in m.iter_mut().zip(v) {
                        *a = a.max(b);
                    }
                }
            }
        }
        if reader.failed {
            // A tile that cannot be read bounds nothing: its bounds are unbounded.
            return DecalBounds {
                slope: f64::INFINITY,
                curvature: f64::INFINITY,
                magnitude_m: f64::INFINITY,
            };
        }
        DecalBounds {
            slope: f64::from(m[0]),
            curvature: f64::from(m[1]),
            magnitude_m: f64::from(m[2]),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn road(points: Vec<[f64; 3]>) -> Decal {
        Decal {
            kind: DecalKind::Road,
            closed: false,
            width_m: 6.0,
            falloff_m: 4.0,
            height_offset_m: 0.0,
            points,
        }
    }

    #[test]
    fn road_flattens_a_slope_to_its_centre_line() {
        // Ground rising 0.3 m per m in y; a road along x at y = 50 with z = 20.
        let ground = |_x: f64, y: f64| 5.0 + 0.3 * y;
        let f = DecalField::new(
            &[road(vec![[10.0, 50.0, 20.0], [90.0, 50.0, 20.0]])],
            [0.0; 2],
            [100.0; 2],
            ground,
        );
        for &(x, y) in &[(30.0, 50.0), (50.5, 51.7), (70.2, 48.1)] {
            let h = ground(x, y) + f.offset_m(x, y);
            assert!((h - 20.0).abs() < 1e-5, "({x}, {y}): {h}");
        }
        // Far away: untouched.
        assert_eq!(f.offset_m(50.0, 80.0), 0.0);
        assert!(f.road_weight(50.0, 50.0) > 0.99 && f.road_weight(50.0, 70.0) == 0.0);
    }

    /// The coarse road-cell skip changes no answer: at every lattice point of a 300 m map
    /// with a winding road (and beyond its edges), `road_weight` equals the stored samples, and
    /// where `road_near` says no road, every weight within its margin is 0.
    #[test]
    fn road_weight_with_the_coarse_skip_equals_the_stored_samples() {
        let f = DecalField::new(
            &[road(vec![
                [-5.0, 20.0, 3.0],
                [120.0, 140.0, 3.0],
                [150.0, 290.0, 3.0],
                [305.0, 250.0, 3.0],
            ])],
            [0.0; 2],
            [300.0; 2],
            |_, _| 0.0,
        );
        let stored: FxHashMap<(i64, i64), f64> = f
            .road_samples()
            .into_iter()
            .map(|(p, w)| {
                let i = |v: f64| (v / DECAL_SPACING_M).round() as i64;
                ((i(p[0]), i(p[1])), w)
            })
            .collect();
        assert!(stored.len() > 500, "{} road samples", stored.len());
        let (mut on_road, mut off_road, mut far) = (0, 0, 0);
        for iy in -20..=620 {
            for ix in -20..=620 {
                let (x, y) = (ix as f64 * DECAL_SPACING_M, iy as f64 * DECAL_SPACING_M);
                let want = stored.get(&(ix, iy)).copied().unwrap_or(0.0);
                assert_eq!(f.road_weight(x + 0.1, y - 0.2), want, "({x}, {y})");
                if !f.road_near(x, y, 1.0) {
                    for (dx, dy) in [(1.0, 1.0), (-1.0, 0.3), (0.2, -1.0), (0.0, 0.0)] {
                        assert_eq!(f.road_weight(x + dx, y + dy), 0.0, "({x}, {y}) near");
                    }
                    far += 1;
                }
                if want > 0.0 {
                    on_road += 1;
                } else {
                    off_road += 1;
                }
            }
        }
        assert!(on_road > 500 && off_road > 100_000 && far > 50_000, "{far}");
    }

    #[test]
    fn rock_patch_raises_inside_and_bounds_hold() {
        let patch = Decal {
            kind: DecalKind::RockPatch,
            closed: true,
            width_m: 0.0,
            falloff_m: 3.0,
            height_offset_m: 2.0,
            points: vec![
                [20.0, 20.0, 0.0],
                [40.0, 20.0, 0.0],
                [40.0, 35.0, 0.0],
                [20.0, 35.0, 0.0],
            ],
        };
        let f = DecalField::new(&[patch], [0.0; 2], [100.0; 2], |_, _| 0.0);
        assert!((f.offset_m(30.0, 27.0) - 2.0).abs() < 1e-6);
        assert_eq!(f.offset_m(60.0, 27.0), 0.0);
        // Finite-difference slope and curvature never exceed the block bounds.
        let h = 1e-4;
        for i in 0..4000i64 {
            let x = 10.0 + 40.0 * worldgen::noise::unit3(3, i, 0);
            let y = 10.0 + 35.0 * worldgen::noise::unit3(3, i, 1);
            let e = |a: f64, b: f64| f.offset_m(a, b);
            let gx = (e(x + h, y) - e(x - h, y)) / (2.0 * h);
            let gy = (e(x, y + h) - e(x, y - h)) / (2.0 * h);
            let b = f.region_bounds([x - 0.1, y - 0.1], [x + 0.1, y + 0.1]);
            assert!(
                gx.hypot(gy) <= b.slope + 1e-6,
                "slope {} > {}",
                gx.hypot(gy),
                b.slope
            );
            let (hh, f0) = (1e-3, e(x, y));
            let fxx = (e(x + hh, y) - 2.0 * f0 + e(x - hh, y)) / (hh * hh);
            let fyy = (e(x, y + hh) - 2.0 * f0 + e(x, y - hh)) / (hh * hh);
            assert!(fxx.abs().max(fyy.abs()) <= b.curvature * 1.01 + 1e-3);
            assert!(
                f0.abs() <= b.magnitude_m,
                "|E| {} > {}",
                f0.abs(),
                b.magnitude_m
            );
            // A big region's bound covers a small one's.
            let big = f.region_bounds([0.0, 0.0], [100.0, 100.0]);
            assert!(
                big.slope >= b.slope
                    && big.curvature >= b.curvature
                    && big.magnitude_m >= b.magnitude_m
            );
        }
    }
}
