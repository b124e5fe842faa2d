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

use rustc_hash::FxHashMap;
use worldgen::map::{Decal, DecalKind};
use worldgen::roads::{inside_polygon, segment_closest};
use worldgen::sample::catmull_rom_weights;

/// Spacing (m) of the decal offset lattice.
pub const DECAL_SPACING_M: f64 = 0.5;
/// The flat core of a road or path reaches this much beyond its half width, so that every
/// sample of the 4 x 4 interpolation stencil of a point within the half width is in the core
/// (the stencil's farthest sample is `2 sqrt(2)` spacings away): the visible road is flat.
pub const FLAT_MARGIN_M: f64 = 2.0 * std::f64::consts::SQRT_2 * DECAL_SPACING_M;
/// Samples per block side.
const BLOCK: i64 = 8;
/// Samples per side of the stencils of one block's cells (one before, two after).
const STENCIL_SIDE: i64 = BLOCK + 3;
/// Block side (m): bounds are kept per block.
pub const DECAL_BLOCK_M: f64 = DECAL_SPACING_M * BLOCK as f64;

/// Packs signed block coordinates into a hash key.
fn key(bx: i64, by: i64) -> u64 {
    ((bx as u32 as u64) << 32) | u64::from(by as u32)
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
    origin_m: [f64; 2],
    /// Block key -> samples, row-major from the block's south-west sample.
    blocks: FxHashMap<u64, Box<[f32; (BLOCK * BLOCK) as usize]>>,
    /// Level k: bounds over 2^k x 2^k blocks; absent = zero.
    bounds: Vec<FxHashMap<u64, [f32; 3]>>,
    /// Largest road/path weight per sample (for suppressing procedural detail on roads).
    road_weight: FxHashMap<(i64, i64), f32>,
    /// Per coarse cell: whether any road/path sample lies in it (samples outside the coarse
    /// grid are always looked up), so most lookups away from roads skip the hash map.
    road_cells: Vec<bool>,
    /// Coarse occupancy over the map: false where no stored block can reach (fast zero).
    coarse: Vec<bool>,
    coarse_dims: [usize; 2],
    coarse_cell_m: f64,
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
fn flat_half_width_m(d: &Decal) -> f64 {
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

/// Per lattice sample within reach of one decal: (distance m, centre-line z at the closest point).
fn decal_footprint(d: &Decal, origin_m: [f64; 2]) -> FxHashMap<(i64, i64), (f64, f64)> {
    let reach = flat_half_width_m(d) + f64::from(d.falloff_m);
    let s = DECAL_SPACING_M;
    let mut out: FxHashMap<(i64, i64), (f64, f64)> = FxHashMap::default();
    let lattice_box = |lo: [f64; 2], hi: [f64; 2]| {
        (
            ((lo[0] - reach - origin_m[0]) / s).floor() as i64,
            ((hi[0] + reach - origin_m[0]) / s).ceil() as i64,
            ((lo[1] - reach - origin_m[1]) / s).floor() as i64,
            ((hi[1] + reach - origin_m[1]) / s).ceil() as i64,
        )
    };
    let n = d.points.len();
    let segments = if d.closed { n } else { n - 1 };
    for k in 0..segments {
        let (pa, pb) = (d.points[k], d.points[(k + 1) % n]);
        let (a, b) = ([pa[0], pa[1]], [pb[0], pb[1]]);
        let (x0, x1, y0, y1) = lattice_box(
            [a[0].min(b[0]), a[1].min(b[1])],
            [a[0].max(b[0]), a[1].max(b[1])],
        );
        for iy in y0..=y1 {
            for ix in x0..=x1 {
                let p = [origin_m[0] + ix as f64 * s, origin_m[1] + iy as f64 * s];
                let (dist, t) = segment_closest(p, a, b);
                if dist > reach {
                    continue;
                }
                let z = pa[2] + t * (pb[2] - pa[2]);
                let e = out.entry((ix, iy)).or_insert((f64::INFINITY, z));
                if dist < e.0 {
                    *e = (dist, z);
                }
            }
        }
    }
    if d.closed {
        // Inside the area the distance is zero.
        let lo = d
            .points
            .iter()
            .fold([f64::INFINITY; 2], |m, p| [m[0].min(p[0]), m[1].min(p[1])]);
        let hi = d.points.iter().fold([f64::NEG_INFINITY; 2], |m, p| {
            [m[0].max(p[0]), m[1].max(p[1])]
        });
        let (x0, x1, y0, y1) = lattice_box(lo, hi);
        for iy in y0..=y1 {
            for ix in x0..=x1 {
                let p = [origin_m[0] + ix as f64 * s, origin_m[1] + iy as f64 * s];
                if inside_polygon(p, &d.points) {
                    // A pad's z is its points' (one z); other areas do not use it.
                    out.insert((ix, iy), (0.0, d.points[0][2]));
                }
            }
        }
    }
    out
}

impl DecalField {
    /// Heap bytes, approximately: hash-map entries times their size (key, value, a control
    /// byte), boxed blocks, the occupancy grids.
    pub fn heap_bytes(&self) -> usize {
        let block = (BLOCK * BLOCK) as usize * 4;
        self.blocks.capacity() * (8 + 8 + 1)
            + self.blocks.len() * block
            + self
                .bounds
                .iter()
                .map(|b| b.capacity() * (8 + 12 + 1))
                .sum::<usize>()
            + self.road_weight.capacity() * (16 + 4 + 1)
            + self.road_cells.len()
            + self.coarse.len()
    }

    /// Rasterizes the decals. `ground_height_m` is the map's bicubic height (without detail).
    pub fn new(
        decals: &[Decal],
        origin_m: [f64; 2],
        size_m: [f64; 2],
        ground_height_m: impl Fn(f64, f64) -> f64,
    ) -> Self {
        // Per sample: (weight, offset); the larger weight wins, the earlier decal on ties.
        let mut samples: FxHashMap<(i64, i64), (f64, f64)> = FxHashMap::default();
        let mut road_weight: FxHashMap<(i64, i64), f32> = FxHashMap::default();
        for d in decals {
            for ((ix, iy), (dist, z)) in decal_footprint(d, origin_m) {
                let w = decal_weight(d, dist);
                if w <= 0.0 {
                    continue;
                }
                let offset = match d.kind {
                    DecalKind::Road | DecalKind::Path | DecalKind::Pad => {
                        let p = [
                            origin_m[0] + ix as f64 * DECAL_SPACING_M,
                            origin_m[1] + iy as f64 * DECAL_SPACING_M,
                        ];
                        let rw = road_weight.entry((ix, iy)).or_insert(0.0);
                        *rw = rw.max(w as f32);
                        w * (z + f64::from(d.height_offset_m) - ground_height_m(p[0], p[1]))
                    }
                    DecalKind::RockPatch | DecalKind::Field | DecalKind::Dirt => {
                        w * f64::from(d.height_offset_m)
                    }
                };
                let e = samples.entry((ix, iy)).or_insert((0.0, 0.0));
                if w > e.0 {
                    *e = (w, offset);
                }
            }
        }
        let mut field = Self {
            origin_m,
            blocks: FxHashMap::default(),
            bounds: Vec::new(),
            road_weight,
            road_cells: Vec::new(),
            coarse: Vec::new(),
            coarse_dims: [0, 0],
            coarse_cell_m: 1.0,
        };
        for ((ix, iy), (_, offset)) in samples {
            if offset == 0.0 {
                continue;
            }
            let (bx, by) = (ix.div_euclid(BLOCK), iy.div_euclid(BLOCK));
            let block = field
                .blocks
                .entry(key(bx, by))
                .or_insert_with(|| Box::new([0.0; (BLOCK * BLOCK) as usize]));
            block[(iy.rem_euclid(BLOCK) * BLOCK + ix.rem_euclid(BLOCK)) as usize] = offset as f32;
        }
        field.build_bounds();
        field.build_coarse(size_m);
        field
    }

    /// Marks the coarse cells (at least 32 m, at most 1024 x 1024 over the map) that a stored
    /// block's interpolation stencil can reach.
    fn build_coarse(&mut self, size_m: [f64; 2]) {
        let cell = 32f64.max(size_m[0].max(size_m[1]) / 1024.0);
        let dims = [
            (size_m[0] / cell).ceil() as usize + 1,
            (size_m[1] / cell).ceil() as usize + 1,
        ];
        let mut coarse = vec![false; dims[0] * dims[1]];
        let margin = 2.0 * DECAL_SPACING_M;
        for &k in self.blocks.keys() {
            let (bx, by) = (
                i64::from((k >> 32) as u32 as i32),
                i64::from(k as u32 as i32),
            );
            let cells = |b: i64, n: usize| {
                let lo = ((b as f64 * DECAL_BLOCK_M - margin) / cell)
                    .floor()
                    .max(0.0) as usize;
                let hi = (((b + 1) as f64 * DECAL_BLOCK_M + margin) / cell)
                    .floor()
                    .max(0.0) as usize;
                lo.min(n - 1)..=hi.min(n - 1)
            };
            for cy in cells(by, dims[1]) {
                for cx in cells(bx, dims[0]) {
                    coarse[cy * dims[0] + cx] = true;
                }
            }
        }
        let mut road_cells = vec![false; dims[0] * dims[1]];
        for &(ix, iy) in self.road_weight.keys() {
            if let Some(c) = Self::cell_of(dims, cell, ix, iy) {
                road_cells[c] = true;
            }
        }
        self.coarse = coarse;
        self.road_cells = road_cells;
        self.coarse_dims = dims;
        self.coarse_cell_m = cell;
    }

    /// The coarse cell holding lattice sample (ix, iy), None outside the coarse grid.
    fn cell_of(dims: [usize; 2], cell_m: f64, ix: i64, iy: i64) -> Option<usize> {
        let c = |i: i64, n: usize| {
            let v = (i as f64 * DECAL_SPACING_M / cell_m).floor();
            (v >= 0.0 && v < n as f64).then_some(v as usize)
        };
        Some(c(iy, dims[1])? * dims[0] + c(ix, dims[0])?)
    }

    pub fn is_empty(&self) -> bool {
        self.blocks.is_empty()
    }

    /// Stored samples (blocks x 64).
    pub fn bytes(&self) -> usize {
        self.blocks.len() * (BLOCK * BLOCK) as usize * 4
    }

    /// Offset (m) stored at lattice sample (ix, iy); zero where no decal reaches.
    pub fn sample(&self, ix: i64, iy: i64) -> f64 {
        self.blocks
            .get(&key(ix.div_euclid(BLOCK), iy.div_euclid(BLOCK)))
            .map_or(0.0, |b| {
                f64::from(b[(iy.rem_euclid(BLOCK) * BLOCK + ix.rem_euclid(BLOCK)) as usize])
            })
    }

    /// The displacement `E` (m) at a world position.
    pub fn offset_m(&self, x_m: f64, y_m: f64) -> f64 {
        if self.blocks.is_empty() {
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
        if !(by0..=by1).any(|by| (bx0..=bx1).any(|bx| self.blocks.contains_key(&key(bx, by)))) {
            return 0.0;
        }
        let mut sum = 0.0;
        for (j, wyj) in y.weights.iter().enumerate() {
            let mut row = 0.0;
            for (i, wxi) in x.weights.iter().enumerate() {
                row += wxi * self.sample(ix + i as i64 - 1, iy + j as i64 - 1);
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
        if self.blocks.is_empty() || xs.is_empty() || ys.is_empty() {
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
        let mut present = |rx: usize, ry: usize| -> bool {
            let k = ry * nrx + rx;
            if state[k] == 0 {
                state[k] = 1;
                if let Some(b) = self.blocks.get(&key(runs_x.blocks[rx], runs_y.blocks[ry])) {
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
            return !self.road_weight.is_empty();
        }
        let c = self.coarse_cell_m;
        // Non-negative: truncation is the floor.
        let (cx0, cy0) = ((x0 / c) as usize, (y0 / c) as usize);
        let (cx1, cy1) = (((x0 + 2.0 * r) / c) as usize, ((y0 + 2.0 * r) / c) as usize);
        let [w, h] = self.coarse_dims;
        if cx1 >= w || cy1 >= h {
            return !self.road_weight.is_empty();
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
        self.road_weight
            .get(&(ix, iy))
            .map_or(0.0, |&w| f64::from(w))
    }

    /// Road/path lattice samples with their weight (for suppressing detail on roads).
    pub fn road_samples(&self) -> impl Iterator<Item = ([f64; 2], f64)> + '_ {
        self.road_weight.iter().map(|(&(ix, iy), &w)| {
            (
                [
                    self.origin_m[0] + ix as f64 * DECAL_SPACING_M,
                    self.origin_m[1] + iy as f64 * DECAL_SPACING_M,
                ],
                f64::from(w),
            )
        })
    }

    /// Per-block bounds from the samples: a cell (ix, iy) reads samples ix-1..ix+2, so a stored
    /// block affects cells of its own block and of its eight neighbours.
    fn build_bounds(&mut self) {
        let mut level0: FxHashMap<u64, [f32; 3]> = FxHashMap::default();
        let mut candidates: Vec<(i64, i64)> = Vec::new();
        for &k in self.blocks.keys() {
            let (bx, by) = (
                i64::from((k >> 32) as u32 as i32),
                i64::from(k as u32 as i32),
            );
            for dy in -1..=1 {
                for dx in -1..=1 {
                    candidates.push((bx + dx, by + dy));
                }
            }
        }
        candidates.sort_unstable();
        candidates.dedup();
        // The block's cells read samples -1..=BLOCK + 1 around it: gathered once per block.
        let mut local = [0.0f64; (STENCIL_SIDE * STENCIL_SIDE) as usize];
        for (bx, by) in candidates {
            let mut b = DecalBounds::default();
            for (k, v) in local.iter_mut().enumerate() {
                let (i, j) = (k as i64 % STENCIL_SIDE - 1, k as i64 / STENCIL_SIDE - 1);
                *v = self.sample(bx * BLOCK + i, by * BLOCK + j);
            }
            for cy in 0..BLOCK {
                for cx in 0..BLOCK {
                    let p =
                        |a: i64, c: i64| local[((cy + c + 1) * STENCIL_SIDE + cx + a + 1) as usize];
                    b.slope = b
                        .slope
                        .max(super::spline::catmull_rom_cell_slope(&p, DECAL_SPACING_M));
                    b.curvature = b.curvature.max(super::spline::catmull_rom_cell_curvature(
                        &p,
                        DECAL_SPACING_M,
                    ));
                    b.magnitude_m = b
                        .magnitude_m
                        .max(super::spline::catmull_rom_cell_magnitude(&p));
                }
            }
            if b.slope > 0.0 || b.curvature > 0.0 || b.magnitude_m > 0.0 {
                // Rounded up so the f32 value stays an upper bound.
                let up = |v: f64| (v * (1.0 + 1e-6)) as f32;
                level0.insert(
                    key(bx, by),
                    [up(b.slope), up(b.curvature), up(b.magnitude_m)],
                );
            }
        }
        let mut levels = vec![level0];
        while levels.last().is_some_and(|l| l.len() > 1) && levels.len() < 40 {
            let prev = levels.last().expect("non-empty");
            let mut next: FxHashMap<u64, [f32; 3]> = FxHashMap::default();
            for (&k, v) in prev {
                let (bx, by) = (
                    i64::from((k >> 32) as u32 as i32),
                    i64::from(k as u32 as i32),
                );
                let e = next.entry(key(bx >> 1, by >> 1)).or_insert([0.0; 3]);
                for (a, b) in e.iter_mut().zip(v) {
                    *a = a.max(*b);
                }
            }
            levels.push(next);
        }
        self.bounds = levels;
    }

    /// Bounds of `E` over a world rectangle (possibly over a little more: still an upper bound).
    pub fn region_bounds(&self, min_m: [f64; 2], max_m: [f64; 2]) -> DecalBounds {
        if self.bounds.is_empty() {
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
        let k = ((u64::BITS - 1 - span.leading_zeros()) as usize).min(self.bounds.len() - 1);
        let level = &self.bounds[k];
        let mut m = [0.0f32; 3];
        for by in (y0 >> k)..=(y1 >> k) {
            for bx in (x0 >> k)..=(x1 >> k) {
                if let Some(v) = level.get(&key(bx, by)) {
                    for (a, b) in m.iter_mut().zip(v) {
                        *a = a.max(*b);
                    }
                }
            }
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
