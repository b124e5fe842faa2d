//! Making the decal field from a map's decal list: every decal rasterized onto the 0.5 m
//! lattice ([`decal_footprint`]), the samples' blocks, their bounds ([`build_bounds`]) and the
//! coarse occupancy grids, then all cut into tiles ([`into_tiles`]). What the field is and how
//! it is read: [`super::decals`].

use super::decal_tiles::{
    BLOCK, BLOCK_SAMPLES, Sorted, TILE_BLOCKS, TILE_LEVELS, TILE_SAMPLES, Tile, split,
};
use super::decals::{
    DECAL_BLOCK_M, DECAL_SPACING_M, DecalBounds, DecalField, STENCIL_SIDE, TileMap, Tiles,
    decal_weight, flat_half_width_m, key, unkey,
};
use rustc_hash::FxHashMap;
use std::sync::Arc;
use worldgen::map::{Decal, DecalKind};
use worldgen::roads::{inside_polygon, segment_closest};

/// Per lattice sample within reach of one decal: (distance m, centre-line z at the closest point).
pub(super) fn decal_footprint(d: &Decal, origin_m: [f64; 2]) -> FxHashMap<(i64, i64), (f64, f64)> {
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
        let mut blocks: FxHashMap<u64, Box<[f32; BLOCK_SAMPLES]>> = FxHashMap::default();
        for ((ix, iy), (_, offset)) in samples {
            if offset == 0.0 {
                continue;
            }
            let (bx, by) = (ix.div_euclid(BLOCK), iy.div_euclid(BLOCK));
            let block = blocks
                .entry(key(bx, by))
                .or_insert_with(|| Box::new([0.0; BLOCK_SAMPLES]));
            block[(iy.rem_euclid(BLOCK) * BLOCK + ix.rem_euclid(BLOCK)) as usize] = offset as f32;
        }
        let levels = build_bounds(&blocks);
        let mut field = Self {
            origin_m,
            bound_levels: levels.len(),
            block_count: blocks.len(),
            road_count: road_weight.len(),
            coarse_cell_m: 1.0,
            ..Self::default()
        };
        field.build_coarse(size_m, &blocks, &road_weight);
        let (tiles, upper) = into_tiles(blocks, levels, road_weight);
        field.tiles = Tiles::Memory(Arc::new(tiles));
        field.upper_bounds = upper;
        field
    }

    /// Marks the coarse cells (at least 32 m, at most 1024 x 1024 over the map) that a stored
    /// block's interpolation stencil can reach.
    fn build_coarse(
        &mut self,
        size_m: [f64; 2],
        blocks: &FxHashMap<u64, Box<[f32; BLOCK_SAMPLES]>>,
        road_weight: &FxHashMap<(i64, i64), f32>,
    ) {
        let cell = 32f64.max(size_m[0].max(size_m[1]) / 1024.0);
        let dims = [
            (size_m[0] / cell).ceil() as usize + 1,
            (size_m[1] / cell).ceil() as usize + 1,
        ];
        let mut coarse = vec![false; dims[0] * dims[1]];
        let margin = 2.0 * DECAL_SPACING_M;
        for &k in blocks.keys() {
            let (bx, by) = unkey(k);
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
        for &(ix, iy) in road_weight.keys() {
            if let Some(c) = Self::cell_of(dims, cell, ix, iy) {
                road_cells[c] = true;
            }
        }
        self.coarse = coarse;
        self.road_cells = road_cells;
        self.coarse_dims = dims;
        self.coarse_cell_m = cell;
    }
}

/// Per-block bounds from the samples: a cell (ix, iy) reads samples ix-1..ix+2, so a stored
/// block affects cells of its own block and of its eight neighbours.
pub(super) fn build_bounds(
    blocks: &FxHashMap<u64, Box<[f32; BLOCK_SAMPLES]>>,
) -> Vec<FxHashMap<u64, [f32; 3]>> {
    let mut level0: FxHashMap<u64, [f32; 3]> = FxHashMap::default();
    let mut candidates: Vec<(i64, i64)> = Vec::new();
    for &k in blocks.keys() {
        let (bx, by) = unkey(k);
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
            let (ix, iy) = (bx * BLOCK + i, by * BLOCK + j);
            *v = blocks
                .get(&key(ix.div_euclid(BLOCK), iy.div_euclid(BLOCK)))
                .map_or(0.0, |b| {
                    f64::from(b[(iy.rem_euclid(BLOCK) * BLOCK + ix.rem_euclid(BLOCK)) as usize])
                });
        }
        for cy in 0..BLOCK {
            for cx in 0..BLOCK {
                let p = |a: i64, c: i64| local[((cy + c + 1) * STENCIL_SIDE + cx + a + 1) as usize];
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
            let (bx, by) = unkey(k);
            let e = next.entry(key(bx >> 1, by >> 1)).or_insert([0.0; 3]);
            for (a, b) in e.iter_mut().zip(v) {
                *a = a.max(*b);
            }
        }
        levels.push(next);
    }
    levels
}

/// Cuts the field's blocks, its bound levels below [`TILE_LEVELS`] and its road weights into
/// tiles; returns the tiles and the coarser levels.
pub(super) fn into_tiles(
    blocks: FxHashMap<u64, Box<[f32; BLOCK_SAMPLES]>>,
    mut levels: Vec<FxHashMap<u64, [f32; 3]>>,
    road_weight: FxHashMap<(i64, i64), f32>,
) -> (TileMap, Vec<FxHashMap<u64, [f32; 3]>>) {
    /// A tile's parts by local index while they are gathered.
    #[derive(Default)]
    struct Parts {
        blocks: FxHashMap<u16, [f32; BLOCK_SAMPLES]>,
        bounds: [FxHashMap<u16, [f32; 3]>; TILE_LEVELS],
        road_weight: FxHashMap<u32, f32>,
    }
    let mut tiles: FxHashMap<(i64, i64), Parts> = FxHashMap::default();
    for (k, b) in blocks {
        let (bx, by) = unkey(k);
        let ((tx, lx), (ty, ly)) = (split(bx, TILE_BLOCKS), split(by, TILE_BLOCKS));
        let local = (ly * TILE_BLOCKS + lx) as u16;
        tiles.entry((tx, ty)).or_default().blocks.insert(local, *b);
    }
    let upper = levels.split_off(TILE_LEVELS.min(levels.len()));
    for (k, level) in levels.into_iter().enumerate() {
        let per = TILE_BLOCKS >> k;
        for (c, v) in level {
            let (cx, cy) = unkey(c);
            let ((tx, lx), (ty, ly)) = (split(cx, per), split(cy, per));
            let local = (ly * per + lx) as u16;
            tiles.entry((tx, ty)).or_default().bounds[k].insert(local, v);
        }
    }
    for ((ix, iy), w) in road_weight {
        let ((tx, lx), (ty, ly)) = (split(ix, TILE_SAMPLES), split(iy, TILE_SAMPLES));
        let local = (ly * TILE_SAMPLES + lx) as u32;
        let parts = tiles.entry((tx, ty)).or_default();
        parts.road_weight.insert(local, w);
    }
    let tiles = tiles
        .into_iter()
        .map(|(t, p)| {
            let tile = Tile {
                blocks: Sorted::from_map(p.blocks),
                bounds: p.bounds.map(Sorted::from_map),
                road_weight: Sorted::from_map(p.road_weight),
            };
            (t, Arc::new(tile))
        })
        .collect();
    (tiles, upper)
}
