//! Vegetation placement: the map's ranked Poisson-disc tile, scaled per species, thinned by the
//! species' density layer, plus the map's explicit large trees.
//!
//! Each species repeats the unit tile with side `tile_side_m = min_distance_m * (1 + 2 J) /
//! tile_min_distance` (J = [`JITTER_FRACTION`]) from a per-species offset, and moves every point by
//! a deterministic jitter of at most `J * min_distance_m` (uniform over the disc, in one of
//! [`JITTER_DIRECTIONS`] directions); so any two items of one species are at
//! least `min_distance_m` apart, across tile periods, 16 m tiles and node borders alike. A point
//! of rank `k` (of `N`) is kept where `(k + 1/2) / N < scale * density(p) / tile_density`, with
//! `tile_density = N / tile_side_m^2` (every point kept): the expected count over a region is the
//! integral of `scale * density`, and a point kept at one scale is kept at every larger one
//! (monotone thinning). Nothing is kept on a road or path decal (road weight > 0 at any of the
//! decal lattice points around it), on water ground or below the water level.
//!
//! Every item is a pure function of the map and its world position: the result for a rectangle
//! does not depend on what was placed before, nor on how the world is cut into rectangles.

use crate::surface::world::{Rect, World};
use worldgen::noise::{hash3, unit3};

/// Largest jitter of a point, as a fraction of the species' minimum distance.
pub const JITTER_FRACTION: f64 = 0.05;

/// Directions a point's jitter takes, evenly spaced (a table: a sine and cosine per point were
/// about a tenth of the vegetation phase). At the largest jitter of the default map's sparsest
/// species (0.2 m) neighbouring directions are 1.2 mm apart.
pub const JITTER_DIRECTIONS: usize = 1024;

/// What an item is drawn as (the size classes of the representation ladder).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Kind {
    GrassClump,
    Bush,
    SmallTree,
    LargeTree,
}

/// One placed item.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Item {
    /// Index into [`Placer::species`].
    pub species: u16,
    pub x_m: f64,
    pub y_m: f64,
    /// Ground height at the item (finest surface), metres.
    pub z_m: f64,
    pub height_m: f32,
    pub radius_m: f32,
    /// Rotation about z, radians.
    pub yaw_rad: f32,
}

/// A species as placement sees it.
#[derive(Debug, Clone, PartialEq)]
pub struct Species {
    pub name: String,
    pub kind: Kind,
    /// Index of the density layer in the map, `None` for large trees (explicit list).
    pub layer: Option<usize>,
    pub min_distance_m: f64,
    pub max_density_per_m2: f64,
    /// Side of one period of the Poisson tile for this species, metres.
    pub tile_side_m: f64,
    /// Items per m² with every tile point kept.
    pub tile_density_per_m2: f64,
    /// Start of the tile period (0, 0) in world metres (the map origin plus a per-species
    /// offset).
    pub offset_m: [f64; 2],
    /// Typical height (m) and crown radius (m); items vary by +-25%.
    pub height_m: f64,
    pub radius_m: f64,
    seed: u64,
}

/// The tile's points bucketed into a grid of cells, each cell's points in rank order.
#[derive(Debug, Clone)]
struct TileIndex {
    cells: usize,
    /// Per cell: (rank, x, y) in the unit tile, ascending rank.
    slots: Vec<Vec<(u32, [f64; 2])>>,
    len: usize,
}

impl TileIndex {
    fn new(points: &[[f64; 2]]) -> Self {
        let cells = (((points.len() as f64) / 4.0).sqrt().ceil() as usize).clamp(1, 256);
        let mut slots = vec![Vec::new(); cells * cells];
        for (k, p) in points.iter().enumerate() {
            let c = |v: f64| ((v * cells as f64) as usize).min(cells - 1);
            slots[c(p[1]) * cells + c(p[0])].push((k as u32, *p));
        }
        Self {
            cells,
            slots,
            len: points.len(),
        }
    }
}

/// Large trees bucketed by 64 m cells for rectangle queries.
#[derive(Debug, Clone)]
struct TreeIndex {
    cell_m: f64,
    origin_m: [f64; 2],
    cols: usize,
    rows: usize,
    slots: Vec<Vec<u32>>,
}

/// Places vegetation for any rectangle of the world (see the module docs).
#[derive(Debug, Clone)]
pub struct Placer {
    pub species: Vec<Species>,
    tile: TileIndex,
    trees: TreeIndex,
    /// Index of the first large-tree species in `species` (one per map tree species).
    large_tree_base: usize,
    /// The jitter directions (cos, sin), [`JITTER_DIRECTIONS`] of them.
    directions: Vec<[f64; 2]>,
    water_type: Option<u8>,
}

/// Size class defaults by species name (height, crown radius, kind).
fn looks(name: &str) -> (Kind, f64, f64) {
    match name {
        "grass_clump" => (Kind::GrassClump, 0.45, 0.25),
        "bush" => (Kind::Bush, 1.4, 0.9),
        "small_tree" => (Kind::SmallTree, 5.0, 1.6),
        _ => (Kind::Bush, 1.2, 0.8),
    }
}

impl Placer {
    pub fn new(world: &World) -> Self {
        let map = &world.map;
        let tile = TileIndex::new(&map.poisson.points);
        let tile_min = map.manifest.poisson.min_distance;
        let n = tile.len as f64;
        let origin = world.origin_m();
        let mut species = Vec::new();
        for (i, layer) in map.densities.iter().enumerate() {
            let spec = &layer.spec;
            let (kind, height_m, radius_m) = looks(&spec.species);
            let side = spec.min_distance_m * (1.0 + 2.0 * JITTER_FRACTION) / tile_min;
            let seed = hash3(0x7665_6765, i as i64, 0);
            species.push(Species {
                name: spec.species.clone(),
                kind,
                layer: Some(i),
                min_distance_m: spec.min_distance_m,
                max_density_per_m2: spec.max_density_per_m2,
                tile_side_m: side,
                tile_density_per_m2: n / (side * side),
                // Periods start from the map's origin (like the procedural detail, placement is
                // map-local: a map grows the same plants wherever it is placed in the world).
                offset_m: [
                    origin[0] + unit3(seed, 1, 0) * side,
                    origin[1] + unit3(seed, 1, 1) * side,
                ],
                height_m,
                radius_m,
                seed,
            });
        }
        let large_tree_base = species.len();
        for name in &map.manifest.tree_species {
            species.push(Species {
                name: name.clone(),
                kind: Kind::LargeTree,
                layer: None,
                min_distance_m: 0.0,
                max_density_per_m2: 0.0,
                tile_side_m: 0.0,
                tile_density_per_m2: 0.0,
                offset_m: [0.0; 2],
                height_m: 20.0,
                radius_m: 4.0,
                seed: 0,
            });
        }
        let water_type = map
            .manifest
            .ground
            .legend
            .iter()
            .position(|g| g.name == "water")
            .and_then(|i| u8::try_from(i).ok());
        let directions = (0..JITTER_DIRECTIONS)
            .map(|i| {
                let a = std::f64::consts::TAU * i as f64 / JITTER_DIRECTIONS as f64;
                [a.cos(), a.sin()]
            })
            .collect();
        Self {
            species,
            tile,
            trees: Self::index_trees(world),
            large_tree_base,
            directions,
            water_type,
        }
    }

    fn index_trees(world: &World) -> TreeIndex {
        let cell_m = 64.0;
        let o = world.origin_m();
        let s = world.size_m();
        let cols = ((s[0] / cell_m).ceil() as usize).max(1);
        let rows = ((s[1] / cell_m).ceil() as usize).max(1);
        let mut slots = vec![Vec::new(); cols * rows];
        for (i, t) in world.map.trees.iter().enumerate() {
            let cx = (((t.x_m - o[0]) / cell_m) as usize).min(cols - 1);
            let cy = (((t.y_m - o[1]) / cell_m) as usize).min(rows - 1);
            slots[cy * cols + cx].push(i as u32);
        }
        TreeIndex {
            cell_m,
            origin_m: o,
            cols,
            rows,
            slots,
        }
    }

    /// Density of species `s` at a point (items per m², bilinear in the layer, 0 outside the map).
    pub fn density(&self, world: &World, s: usize, x_m: f64, y_m: f64) -> f64 {
        let Some(layer) = self.species[s].layer else {
            return 0.0;
        };
        let l = &world.map.densities[layer];
        let o = world.origin_m();
        let gx = (x_m - o[0]) / l.spec.spacing_m;
        let gy = (y_m - o[1]) / l.spec.spacing_m;
        let (w, h) = (l.density.width(), l.density.height());
        if !(gx >= 0.0 && gy >= 0.0 && gx <= (w - 1) as f64 && gy <= (h - 1) as f64) {
            return 0.0;
        }
        let (ix, iy) = ((gx as usize).min(w - 2), (gy as usize).min(h - 2));
        let (fx, fy) = (gx - ix as f64, gy - iy as f64);
        let v = |x: usize, y: usize| f64::from(l.density.get(x, y));
        let top = v(ix, iy + 1) * (1.0 - fx) + v(ix + 1, iy + 1) * fx;
        let bottom = v(ix, iy) * (1.0 - fx) + v(ix + 1, iy) * fx;
        (bottom * (1.0 - fy) + top * fy) / 255.0 * l.spec.max_density_per_m2
    }

    /// Largest density of species `s` over a rectangle (the largest sample of the cells it
    /// touches; bilinear interpolation never exceeds it).
    fn density_max(&self, world: &World, s: usize, rect: Rect) -> f64 {
        let Some(layer) = self.species[s].layer else {
            return 0.0;
        };
        f64::from(layer_max(world, layer, rect)) / 255.0
            * world.map.densities[layer].spec.max_density_per_m2
    }

    /// True where nothing may grow: on a road or path decal, on water ground, below the water
    /// level, or outside the map.
    pub fn excluded(&self, world: &World, x_m: f64, y_m: f64) -> bool {
        self.excluded_at(world, x_m, y_m, world.height_m(x_m, y_m))
    }

    /// [`Self::excluded`] where the surface height `z_m` at the point is known.
    fn excluded_at(&self, world: &World, x_m: f64, y_m: f64, z_m: f64) -> bool {
        let o = world.origin_m();
        let s = world.size_m();
        if !(x_m >= o[0] && y_m >= o[1] && x_m <= o[0] + s[0] && y_m <= o[1] + s[1]) {
            return true;
        }
        if self.water_type == Some(world.ground_type(x_m, y_m))
            || z_m <= world.map.manifest.water_level_m
        {
            return true;
        }
        // The road weight is stored on a 0.5 m lattice: look at the lattice points around.
        let d = crate::surface::decals::DECAL_SPACING_M;
        if !world.decals.road_near(x_m, y_m, d) {
            return false;
        }
        [(0.0, 0.0), (d, 0.0), (-d, 0.0), (0.0, d), (0.0, -d)]
            .iter()
            .any(|&(dx, dy)| world.decals.road_weight(x_m + dx, y_m + dy) > 0.0)
    }

    /// Calls `f(rank, period_seed, x, y)` for every jittered tile point of species `s` in `rect`
    /// (half-open) whose rank is below `k_end` and below `cell_k_end(area)`, where `area` holds
    /// every jittered position of the points of the point's tile cell, and for which
    /// `pre(rank, period_seed)` holds (`pre` sees the point before its jittered position is
    /// computed: a cheap early filter).
    fn visit(
        &self,
        s: usize,
        rect: Rect,
        k_end: u32,
        mut cell_k_end: impl FnMut(Rect) -> u32,
        mut pre: impl FnMut(u32, u64) -> bool,
        mut f: impl FnMut(u32, u64, f64, f64),
    ) {
        let sp = &self.species[s];
        let t = sp.tile_side_m;
        let jitter = JITTER_FRACTION * sp.min_distance_m;
        // Unjittered positions that can land in the rectangle.
        let (lo, hi) = (
            [rect.min[0] - jitter, rect.min[1] - jitter],
            [rect.max[0] + jitter, rect.max[1] + jitter],
        );
        let period_of = |v: f64, o: f64| ((v - o) / t).floor() as i64;
        let cells = self.tile.cells;
        // Tile cells overlapping [a, b] in the period starting at `base`.
        let cell_range = |a: f64, b: f64, base: f64| {
            let u0 = ((a - base) / t * cells as f64).floor().max(0.0) as usize;
            let u1 = ((b - base) / t * cells as f64).floor();
            (u1 >= 0.0).then(|| (u0, (u1 as usize).min(cells - 1)))
        };
        for py in period_of(lo[1], sp.offset_m[1])..=period_of(hi[1], sp.offset_m[1]) {
            for px in period_of(lo[0], sp.offset_m[0])..=period_of(hi[0], sp.offset_m[0]) {
                let base = [
                    sp.offset_m[0] + px as f64 * t,
                    sp.offset_m[1] + py as f64 * t,
                ];
                let (Some((cx0, cx1)), Some((cy0, cy1))) = (
                    cell_range(lo[0], hi[0], base[0]),
                    cell_range(lo[1], hi[1], base[1]),
                ) else {
                    continue;
                };
                let period = hash3(sp.seed, px, py);
                let cell_m = t / cells as f64;
                for cy in cy0..=cy1 {
                    for cx in cx0..=cx1 {
                        let slots = &self.tile.slots[cy * cells + cx];
                        if slots.first().is_none_or(|&(k, _)| k >= k_end) {
                            continue;
                        }
                        let (x0, y0) = (base[0] + cx as f64 * cell_m, base[1] + cy as f64 * cell_m);
                        let area = Rect {
                            min: [x0 - jitter, y0 - jitter],
                            max: [x0 + cell_m + jitter, y0 + cell_m + jitter],
                        };
                        let k_end = k_end.min(cell_k_end(area));
                        for &(k, u) in slots {
                            if k >= k_end {
                                break;
                            }
                            if !pre(k, period) {
                                continue;
                            }
                            let kk = i64::from(k);
                            let turn = hash3(period, kk, 0) >> (64 - JITTER_DIRECTIONS.ilog2());
                            let [cos, sin] = self.directions[turn as usize];
                            let radius = jitter * unit3(period, kk, 1).sqrt();
                            let x = base[0] + u[0] * t + radius * cos;
                            let y = base[1] + u[1] * t + radius * sin;
                            if x >= rect.min[0]
                                && x < rect.max[0]
                                && y >= rect.min[1]
                                && y < rect.max[1]
                            {
                                f(k, period, x, y);
                            }
                        }
                    }
                }
            }
        }
    }

    /// Positions only: the jittered tile points of species `s` in `rect` with normalised rank
    /// below `fraction` (a uniform density of `fraction * tile_density_per_m2`). The bare tile
    /// lookup, without density maps, heights or exclusions (what `nodebench` compares with
    /// Bridson sampling).
    pub fn positions(&self, s: usize, rect: Rect, fraction: f64, out: &mut Vec<[f64; 2]>) {
        let n = self.tile.len as f64;
        let k_end = ((n * fraction).ceil().max(0.0) as u32).min(self.tile.len as u32);
        self.visit(
            s,
            rect,
            k_end,
            |_| u32::MAX,
            |_, _| true,
            |k, _, x, y| {
                if (f64::from(k) + 0.5) / n < fraction {
                    out.push([x, y]);
                }
            },
        );
    }

    /// Appends the items of species `s` whose position lies in `rect` (half-open:
    /// `min <= p < max`), at density multiplied by `scale` (1 = the map's density).
    pub fn place(&self, world: &World, s: usize, rect: Rect, scale: f64, out: &mut Vec<Item>) {
        self.place_where(world, s, rect, scale, |_| true, out);
    }

    /// [`Self::place`] for the items whose height `keep` accepts: the same items as `place`
    /// followed by a filter on `height_m`, but the surface height and the exclusions are only
    /// evaluated for items that pass (a node keeps only the heights it draws).
    pub fn place_where(
        &self,
        world: &World,
        s: usize,
        rect: Rect,
        scale: f64,
        keep: impl Fn(f32) -> bool,
        out: &mut Vec<Item>,
    ) {
        if s >= self.large_tree_base {
            self.place_large_trees(world, s, rect, &keep, out);
            return;
        }
        let sp = &self.species[s];
        let dmax = self.density_max(world, s, rect) * scale;
        if dmax <= 0.0 || self.tile.len == 0 {
            return;
        }
        let n = self.tile.len as f64;
        // Ranks at or beyond this cannot be kept where the density is at most `d`: a point of
        // rank k is kept where (k + 1/2) / n < density / tile density.
        let k_end_for =
            |d: f64| ((n * (d / sp.tile_density_per_m2)).ceil() as u32).min(self.tile.len as u32);
        let k_end = k_end_for(dmax);
        // The same bound per tile cell, from the density samples around it (most points of a
        // large node fail the density test; this skips them before their jitter and density
        // are computed): from the largest density sample around the cell's area (that of
        // `density_max`, or a column more; see `RowMax`), and the bound per sample value
        // computed once.
        let layer = sp
            .layer
            .expect("a species placed from the tile has a density layer");
        let max_density = world.map.densities[layer].spec.max_density_per_m2;
        let margin =
            sp.tile_side_m / self.tile.cells as f64 + 2.0 * JITTER_FRACTION * sp.min_distance_m;
        let window = Rect {
            min: [rect.min[0] - margin, rect.min[1] - margin],
            max: [rect.max[0] + margin, rect.max[1] + margin],
        };
        let mut row_max = RowMax::new(world, layer, window);
        let mut k_end_of_sample = [u32::MAX; 256];
        let cell_k_end = |area: Rect| {
            let m = row_max.max(area);
            let e = &mut k_end_of_sample[usize::from(m)];
            if *e == u32::MAX {
                *e = k_end_for(f64::from(m) / 255.0 * max_density * scale);
            }
            *e
        };
        // Size factor (+-25%) of the item of rank k in a period, and its height.
        let size_of = |k: u32, period: u64| 0.75 + 0.5 * unit3(period, i64::from(k), 2);
        let height_of = |size: f64| (sp.height_m * size) as f32;
        let pre = |k: u32, period: u64| keep(height_of(size_of(k, period)));
        self.visit(s, rect, k_end, cell_k_end, pre, |k, period, x, y| {
            let rank = (f64::from(k) + 0.5) / n;
            let d = scale * self.density(world, s, x, y);
            if rank >= d / sp.tile_density_per_m2 {
                return;
            }
            let kk = i64::from(k);
            let size = size_of(k, period);
            let height_m = height_of(size);
            let z = world.height_m(x, y);
            if self.excluded_at(world, x, y, z) {
                return;
            }
            out.push(Item {
                species: s as u16,
                x_m: x,
                y_m: y,
                z_m: z,
                height_m,
                radius_m: (sp.radius_m * size) as f32,
                yaw_rad: (std::f64::consts::TAU * unit3(period, kk, 3)) as f32,
            });
        });
    }

    fn place_large_trees(
        &self,
        world: &World,
        s: usize,
        rect: Rect,
        keep: impl Fn(f32) -> bool,
        out: &mut Vec<Item>,
    ) {
        let ti = &self.trees;
        if ti.slots.is_empty() {
            return;
        }
        let species = (s - self.large_tree_base) as u16;
        let c =
            |v: f64, o: f64, n: usize| (((v - o) / ti.cell_m).floor().max(0.0) as usize).min(n - 1);
        for cy in c(rect.min[1], ti.origin_m[1], ti.rows)..=c(rect.max[1], ti.origin_m[1], ti.rows)
        {
            for cx in
                c(rect.min[0], ti.origin_m[0], ti.cols)..=c(rect.max[0], ti.origin_m[0], ti.cols)
            {
                for &i in &ti.slots[cy * ti.cols + cx] {
                    let t = &world.map.trees[i as usize];
                    if t.species != species
                        || !keep(t.height_m)
                        || !(t.x_m >= rect.min[0]
                            && t.x_m < rect.max[0]
                            && t.y_m >= rect.min[1]
                            && t.y_m < rect.max[1])
                    {
                        continue;
                    }
                    let z = world.height_m(t.x_m, t.y_m);
                    if self.excluded_at(world, t.x_m, t.y_m, z) {
                        continue;
                    }
                    out.push(Item {
                        species: s as u16,
                        x_m: t.x_m,
                        y_m: t.y_m,
                        z_m: z,
                        height_m: t.height_m,
                        radius_m: t.crown_radius_m,
                        yaw_rad: (std::f64::consts::TAU * unit3(17, i64::from(i), 0)) as f32,
                    });
                }
            }
        }
    }

    /// All items of every species in `rect` (density scale 1), species by species.
    pub fn place_all(&self, world: &World, rect: Rect, out: &mut Vec<Item>) {
        for s in 0..self.species.len() {
            self.place(world, s, rect, 1.0, out);
        }
    }
}

/// The samples of density layer `layer` at the corners of the cells that the span `lo..=hi`
/// along axis `axis` (0: x, 1: y) touches: `[first, last]`.
#[inline]
fn sample_span(world: &World, layer: usize, axis: usize, lo: f64, hi: f64) -> [usize; 2] {
    let l = &world.map.densities[layer];
    let o = world.origin_m()[axis];
    let n = if axis == 0 {
        l.density.width()
    } else {
        l.density.height()
    };
    let idx = |v: f64, f: fn(f64) -> f64| {
        f((v - o) / l.spec.spacing_m).clamp(0.0, (n - 1) as f64) as usize
    };
    [idx(lo, f64::floor), idx(hi, f64::ceil)]
}

/// The samples of density layer `layer` at the corners of the cells `rect` touches: columns
/// `x0..=x1` and rows `y0..=y1` as `([x0, x1], [y0, y1])`.
fn sample_range(world: &World, layer: usize, rect: Rect) -> ([usize; 2], [usize; 2]) {
    (
        sample_span(world, layer, 0, rect.min[0], rect.max[0]),
        sample_span(world, layer, 1, rect.min[1], rect.max[1]),
    )
}

/// Largest sample of density layer `layer` over the cells `rect` touches (bilinear
/// interpolation never exceeds it).
pub(super) fn layer_max(world: &World, layer: usize, rect: Rect) -> u8 {
    let density = &world.map.densities[layer].density;
    let ([x0, x1], [y0, y1]) = sample_range(world, layer, rect);
    let mut m = 0u8;
    for y in y0..=y1 {
        for x in x0..=x1 {
            m = m.max(density.get(x, y));
        }
    }
    m
}

/// A bound of [`layer_max`] for the tile cells of one [`Placer::visit`], row after row: the
/// cells of a row touch the same rows of samples, so each column's largest sample over those
/// rows is found once per row and kept, for the columns of a window around the visited
/// rectangle (a rectangle reaching outside it is measured by `layer_max`). The columns a cell
/// touches are found with a multiplication where `layer_max` divides, and widened by
/// [`Self::MARGIN`] columns so that they include every column `layer_max` takes: the result is
/// never below it (at most a column wider, where a cell's side lies within the margin of a
/// sample column).
struct RowMax<'a> {
    world: &'a World,
    layer: usize,
    /// The map's west edge, the inverse sample spacing and the last column (m, 1/m, -).
    origin_x_m: f64,
    per_m: f64,
    last_column: f64,
    /// The y span of the current row of cells, its sample rows and its number.
    span_m: [f64; 2],
    rows: [usize; 2],
    row_id: u32,
    /// The window's first column.
    base: usize,
    /// Per column of the window: the row number it was found for and its largest sample.
    cols: Vec<(u32, u8)>,
}

impl<'a> RowMax<'a> {
    /// Far above the rounding of `(x - origin) * per_m` against `(x - origin) / spacing`
    /// (a few ulp of at most the layer's width).
    const MARGIN: f64 = 1e-9;

    fn new(world: &'a World, layer: usize, window: Rect) -> Self {
        let ([x0, x1], _) = sample_range(world, layer, window);
        let l = &world.map.densities[layer];
        Self {
            world,
            layer,
            origin_x_m: world.origin_m()[0],
            per_m: 1.0 / l.spec.spacing_m,
            last_column: (l.density.width() - 1) as f64,
            span_m: [f64::NAN; 2],
            rows: [0; 2],
            row_id: 0,
            base: x0,
            cols: vec![(0, 0); x1 - x0 + 1],
        }
    }

    /// At least `layer_max(world, layer, rect)`.
    #[inline]
    fn max(&mut self, rect: Rect) -> u8 {
        let column = |v: f64, f: fn(f64) -> f64, margin: f64| {
            f((v - self.origin_x_m) * self.per_m + margin).clamp(0.0, self.last_column) as usize
        };
        let x0 = column(rect.min[0], f64::floor, -Self::MARGIN);
        let x1 = column(rect.max[0], f64::ceil, Self::MARGIN);
        if x0 < self.base || x1 >= self.base + self.cols.len() {
            return layer_max(self.world, self.layer, rect);
        }
        if [rect.min[1], rect.max[1]] != self.span_m {
            self.span_m = [rect.min[1], rect.max[1]];
            self.rows = sample_span(self.world, self.layer, 1, rect.min[1], rect.max[1]);
            self.row_id += 1;
        }
        let [y0, y1] = self.rows;
        let density = &self.world.map.densities[self.layer].density;
        let mut m = 0u8;
        for x in x0..=x1 {
            let c = &mut self.cols[x - self.base];
            if c.0 != self.row_id {
                *c = (
                    self.row_id,
                    (y0..=y1).map(|y| density.get(x, y)).max().unwrap_or(0),
                );
            }
            m = m.max(c.1);
        }
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use worldgen::noise::unit3;

    /// The row-by-row bound is never below `layer_max` and at most one column wider: over rows
    /// of cells like a visit's (cells of uneven width, a side exactly on a sample column, cells
    /// past the map's edges and outside the window).
    #[test]
    fn row_max_bounds_layer_max() {
        let w = World::without_error_grids(crate::test_maps::tiny_map());
        let (o, size) = (w.origin_m(), w.size_m());
        for layer in 0..w.map.densities.len() {
            let spacing = w.map.densities[layer].spec.spacing_m;
            let window = Rect {
                min: [o[0] + 0.2 * size[0], o[1] - 30.0],
                max: [o[0] + 0.9 * size[0], o[1] + size[1] + 30.0],
            };
            let mut rows = RowMax::new(&w, layer, window);
            let (mut equal, mut wider) = (0usize, 0usize);
            for row in 0..40i64 {
                let y = o[1] - 20.0 + unit3(3, row, 0) * (size[1] + 40.0);
                let h = 0.5 + 30.0 * unit3(3, row, 1);
                let mut x = o[0] + 0.1 * size[0];
                for cell in 0..200i64 {
                    let wide = if cell % 7 == 0 {
                        // A side on a sample column.
                        let next = ((x - o[0]) / spacing).ceil() * spacing + o[0] - x;
                        if next > 0.0 { next } else { spacing }
                    } else {
                        0.3 + 20.0 * unit3(4, row, cell)
                    };
                    let rect = Rect {
                        min: [x, y],
                        max: [x + wide, y + h],
                    };
                    let exact = layer_max(&w, layer, rect);
                    let bound = rows.max(rect);
                    assert!(bound >= exact, "{rect:?}: {bound} < {exact}");
                    // At most a column more on each side.
                    let wide_rect = Rect {
                        min: [x - spacing, y],
                        max: [x + wide + spacing, y + h],
                    };
                    assert!(bound <= layer_max(&w, layer, wide_rect), "{rect:?}");
                    if bound == exact {
                        equal += 1;
                    } else {
                        wider += 1;
                    }
                    x += wide;
                }
            }
            assert!(
                equal > 10 * wider,
                "layer {layer}: {equal} equal, {wider} wider"
            );
        }
    }
}
