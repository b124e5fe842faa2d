//! Line-of-sight extinction through vegetation, for splitting less where the view is blocked.

use super::placement::Placer;
use super::sparse_grid::SparseGrid;
use crate::surface::{Rect, World};
use worldgen::sample::Samples;

/// Samples along a line of sight for [`Canopy::visibility`].
pub const SIGHT_SAMPLES: usize = 16;

/// A coarse model of how much vegetation blocks a line of sight, for splitting less where the
/// view is blocked (seed 002). Per species: the extinction `density * crown diameter` (1/m) on
/// the density layer's grid, up to the species' typical height above the ground; large trees
/// from the map's list as crown diameters per 8 m cell, up to their mean height.
///
/// A species' extinction is computed from its density sample when read (not stored as a grid
/// of its own), and the density layers are the map's own (shared, not copied), so the canopy
/// adds only the large trees' grid (sparse: a bit per cell and the cells that hold a tree)
/// and one bit per cell of occupancy.
#[derive(Debug, Clone)]
pub struct Canopy {
    /// Per species with a layer, then the large trees: (extinction, spacing m, height m).
    layers: Vec<(LayerGrid, f64, f64)>,
    origin_m: [f64; 2],
    heights_spacing_m: f64,
    /// The tallest species' height: lines of sight above the ground by more never hit.
    pub top_m: f64,
    /// The layers grouped per height band, when they all lie on one grid.
    bands: Option<Bands>,
}

/// One layer's extinction (1/m) at its grid's samples.
#[derive(Debug, Clone)]
enum LayerGrid {
    /// A species' density samples (0-255; the map's layer, shared), and per sample value the
    /// extinction: the value times the species' scale, rounded to f32.
    Density {
        density: std::sync::Arc<worldgen::Grid<u8>>,
        extinction: Box<[f32; 256]>,
    },
    /// The extinction itself (the large trees), stored only at the cells that hold some.
    Extinction(SparseGrid),
}

impl LayerGrid {
    #[inline]
    fn get(&self, x: usize, y: usize) -> f32 {
        match self {
            LayerGrid::Density {
                density,
                extinction,
            } => extinction[usize::from(density.get(x, y))],
            LayerGrid::Extinction(g) => g.get(x, y),
        }
    }

    /// Bytes held beyond the map's own layers (a shared density layer holds none).
    fn bytes(&self) -> usize {
        match self {
            LayerGrid::Density { .. } => 0,
            LayerGrid::Extinction(g) => g.bytes(),
        }
    }

    /// Sets the bit of every sample above zero in `bits` (rows of `words_per_row` words),
    /// reading each layer in its own form: a density layer byte by byte through a table of
    /// which values have a positive extinction, the large trees at their stored cells only.
    fn mark_positive(&self, bits: &mut [u64], words_per_row: usize) {
        match self {
            LayerGrid::Density {
                density,
                extinction,
            } => {
                let positive: [u64; 256] = std::array::from_fn(|v| u64::from(extinction[v] > 0.0));
                let w = density.width();
                for (row, out) in density
                    .data()
                    .chunks_exact(w)
                    .zip(bits.chunks_exact_mut(words_per_row))
                {
                    for (chunk, word) in row.chunks(64).zip(out.iter_mut()) {
                        let mut m = 0u64;
                        for (i, &v) in chunk.iter().enumerate() {
                            m |= positive[usize::from(v)] << i;
                        }
                        *word |= m;
                    }
                }
            }
            LayerGrid::Extinction(g) => g.for_each_stored(|x, y, v| {
                if v > 0.0 {
                    bits[y * words_per_row + x / 64] |= 1 << (x % 64);
                }
            }),
        }
    }

    /// Samples along x and y.
    fn size(&self) -> (usize, usize) {
        match self {
            LayerGrid::Density { density, .. } => (density.width(), density.height()),
            LayerGrid::Extinction(g) => (g.width(), g.height()),
        }
    }
}

impl Samples for LayerGrid {
    fn width(&self) -> usize {
        self.size().0
    }
    fn height(&self) -> usize {
        self.size().1
    }
    #[inline]
    fn at(&self, x: usize, y: usize) -> f32 {
        self.get(x, y)
    }
}

/// The sum of some layers at each sample (f32, added in the layers' order): a band of
/// [`Bands`], read as a raster.
struct BandSum<'a> {
    layers: &'a [(LayerGrid, f64, f64)],
    members: &'a [usize],
}

impl Samples for BandSum<'_> {
    fn width(&self) -> usize {
        self.layers[0].0.width()
    }
    fn height(&self) -> usize {
        self.layers[0].0.height()
    }
    #[inline]
    fn at(&self, x: usize, y: usize) -> f32 {
        let mut sum = 0.0f32;
        for &i in self.members {
            sum += self.layers[i].0.get(x, y);
        }
        sum
    }
}

/// The canopy's layers grouped per height band, for layers that share one grid (the usual
/// case: every density layer and the large trees' grid on 8 m cells from the map's origin):
/// one bilinear look-up of the band's sum per extinction, and a test of whether any
/// vegetation stands in a rectangle that reads one bit per cell.
#[derive(Debug, Clone)]
struct Bands {
    /// The distinct layer tops (m), ascending.
    tops_m: Vec<f64>,
    /// Per top: the layers (indices, ascending) that reach at least that high.
    members: Vec<Vec<usize>>,
    spacing_m: f64,
    /// One bit per cell, set where any layer is above zero: rows of `words_per_row` words.
    occupied: Vec<u64>,
    words_per_row: usize,
}

impl Bands {
    fn new(layers: &[(LayerGrid, f64, f64)]) -> Option<Self> {
        let (first, spacing_m, _) = layers.first()?;
        let (w, h) = (first.width(), first.height());
        if layers
            .iter()
            .any(|(g, s, _)| g.width() != w || g.height() != h || s != spacing_m)
        {
            return None;
        }
        let mut tops_m: Vec<f64> = layers.iter().map(|l| l.2).collect();
        tops_m.sort_by(f64::total_cmp);
        tops_m.dedup();
        let members = tops_m
            .iter()
            .map(|&top| (0..layers.len()).filter(|&i| layers[i].2 >= top).collect())
            .collect();
        let words_per_row = w.div_ceil(64);
        let mut occupied = vec![0u64; words_per_row * h];
        for (g, _, _) in layers {
            g.mark_positive(&mut occupied, words_per_row);
        }
        Some(Self {
            tops_m,
            members,
            spacing_m: *spacing_m,
            occupied,
            words_per_row,
        })
    }

    /// Band `band`'s summed layers as a raster.
    fn sum<'a>(&'a self, layers: &'a [(LayerGrid, f64, f64)], band: usize) -> BandSum<'a> {
        BandSum {
            layers,
            members: &self.members[band],
        }
    }

    /// Whether any cell of columns `x0..=x1` and rows `y0..=y1` is occupied.
    fn any_in_cells(&self, (x0, x1): (usize, usize), (y0, y1): (usize, usize)) -> bool {
        let (w0, w1) = (x0 / 64, x1 / 64);
        (y0..=y1).any(|y| {
            let row = &self.occupied[y * self.words_per_row..][..self.words_per_row];
            (w0..=w1).any(|k| {
                let lo = if k == w0 { x0 % 64 } else { 0 };
                let hi = if k == w1 { x1 % 64 } else { 63 };
                let mask = (u64::MAX >> (63 - hi)) & (u64::MAX << lo);
                row[k] & mask != 0
            })
        })
    }
}

impl Canopy {
    pub fn new(world: &World, placer: &Placer) -> Self {
        let mut layers = Vec::new();
        let mut top = 0.0f64;
        for sp in &placer.species {
            let Some(l) = sp.layer else { continue };
            let layer = &world.map.densities[l];
            let scale = layer.spec.max_density_per_m2 / 255.0 * 2.0 * sp.radius_m;
            top = top.max(sp.height_m);
            let density = std::sync::Arc::clone(&layer.density);
            let extinction = Box::new(std::array::from_fn(|v| (v as f64 * scale) as f32));
            layers.push((
                LayerGrid::Density {
                    density,
                    extinction,
                },
                layer.spec.spacing_m,
                sp.height_m,
            ));
        }
        // Large trees: crown diameters per cell area on an 8 m grid, up to their mean height.
        if !world.map.trees.is_empty() {
            let cell = 8.0;
            let s = world.size_m();
            let (w, h) = (
                (s[0] / cell).ceil() as usize + 1,
                (s[1] / cell).ceil() as usize + 1,
            );
            let o = world.origin_m();
            let mut height_sum = 0.0;
            let mut adds = Vec::with_capacity(world.map.trees.len());
            for t in &world.map.trees {
                let x = (((t.x_m - o[0]) / cell).round() as usize).min(w - 1);
                let y = (((t.y_m - o[1]) / cell).round() as usize).min(h - 1);
                let add = 2.0 * f64::from(t.crown_radius_m) / (cell * cell);
                adds.push((y * w + x, add as f32));
                height_sum += f64::from(t.height_m);
            }
            let ext = SparseGrid::from_adds(w, h, adds);
            let mean = height_sum / world.map.trees.len() as f64;
            top = top.max(mean);
            layers.push((LayerGrid::Extinction(ext), cell, mean));
        }
        Self {
            bands: Bands::new(&layers),
            layers,
            origin_m: world.origin_m(),
            heights_spacing_m: world.map.manifest.heights.spacing_m,
            top_m: top,
        }
    }

    /// Bytes the canopy holds beyond the map's density layers (the large trees' grid and the
    /// occupancy bits).
    pub fn bytes(&self) -> usize {
        self.layers.iter().map(|l| l.0.bytes()).sum::<usize>()
            + self.bands.as_ref().map_or(0, |b| b.occupied.len() * 8)
    }

    /// The fraction of the line of sight from `eye` to `target` that vegetation leaves clear,
    /// `exp(-optical depth)`, with the optical depth summed at [`SIGHT_SAMPLES`] midpoints
    /// (ground from the bilinear map heights).
    pub fn visibility(&self, world: &World, eye: glam::DVec3, target: glam::DVec3) -> f64 {
        let d = target - eye;
        let len = d.length();
        if len <= 0.0 || self.layers.is_empty() {
            return 1.0;
        }
        let step = len / SIGHT_SAMPLES as f64;
        let heights = worldgen::sample::GridPlacement {
            origin_m: self.origin_m,
            spacing_m: self.heights_spacing_m,
        };
        let mut depth = 0.0;
        for i in 0..SIGHT_SAMPLES {
            let p = eye + d * ((i as f64 + 0.5) / SIGHT_SAMPLES as f64);
            let above = p.z - worldgen::sample::bilinear(&world.map.heights, heights, p.x, p.y);
            depth += self.extinction_per_m(p.x, p.y, above) * step;
        }
        (-depth).exp()
    }
}

impl Canopy {
    /// The extinction (1/m) at world point (`x_m`, `y_m`) and `above_m` metres above the
    /// ground: the sum over the species layers (and large trees) that reach that high, each
    /// bilinear on its own grid. Zero below the ground and above [`Self::top_m`].
    pub fn extinction_per_m(&self, x_m: f64, y_m: f64, above_m: f64) -> f64 {
        if !(0.0..=self.top_m).contains(&above_m) {
            return 0.0;
        }
        if let Some(b) = &self.bands {
            let band = b.tops_m.partition_point(|&t| t < above_m);
            let at = worldgen::sample::GridPlacement {
                origin_m: self.origin_m,
                spacing_m: b.spacing_m,
            };
            if band >= b.tops_m.len() {
                return 0.0;
            }
            return worldgen::sample::bilinear(&b.sum(&self.layers, band), at, x_m, y_m);
        }
        let mut sum = 0.0;
        for (ext, spacing, h) in &self.layers {
            if above_m <= *h {
                let at = worldgen::sample::GridPlacement {
                    origin_m: self.origin_m,
                    spacing_m: *spacing,
                };
                sum += worldgen::sample::bilinear(ext, at, x_m, y_m);
            }
        }
        sum
    }
}

impl Canopy {
    /// The heights (m) up to which each layer (species, large trees) blocks light, ascending.
    pub fn layer_tops_m(&self) -> Vec<f64> {
        let mut v: Vec<f64> = self.layers.iter().map(|l| l.2).collect();
        v.sort_by(f64::total_cmp);
        v.dedup();
        v
    }

    /// An upper bound of [`Self::extinction_per_m`] over the rectangle `min`..`max` (world m)
    /// at any height: per layer the largest grid value whose cell touches the rectangle (a
    /// bilinear value never exceeds its corners; positions outside a grid clamp to its border).
    fn max_extinction_in(&self, min: [f64; 2], max: [f64; 2]) -> f64 {
        let mut sum = 0.0;
        for (ext, spacing, _) in &self.layers {
            let range = |axis: usize, len: usize| {
                let to =
                    |v: f64| ((v - self.origin_m[axis]) / spacing).clamp(0.0, (len - 1) as f64);
                (
                    to(min[axis]).floor() as usize,
                    to(max[axis]).ceil() as usize,
                )
            };
            let (x0, x1) = range(0, ext.width());
            let (y0, y1) = range(1, ext.height());
            let mut m = 0.0f64;
            for y in y0..=y1 {
                for x in x0..=x1 {
                    m = m.max(f64::from(ext.get(x, y)));
                }
            }
            sum += m;
        }
        sum
    }
}

/// [`Canopy::extinction_per_m`] on a lattice of points: per height band (its top) the summed
/// layers there, for look-ups between the points (see [`Canopy::band_lattice`]).
#[derive(Debug, Clone, Default)]
pub struct BandLattice {
    /// The band tops (m), ascending: a height `above` reads the first band whose top is at
    /// least `above`.
    pub tops_m: Vec<f64>,
    /// Per band, the lattice's values (row-major, as the lattice was given).
    pub values: Vec<Vec<f64>>,
}

impl Canopy {
    /// The canopy's summed layers per height band at every point of the lattice `xs` x `ys`
    /// (world m), each equal to [`Self::extinction_per_m`] there for the band's heights; `None`
    /// when the layers lie on different grids. Where every cell of the lattice lies within one
    /// cell of the canopy's grid (a lattice aligned with it, its spacing dividing the grid's),
    /// bilinear interpolation between the lattice's points gives the extinction anywhere
    /// between them, up to rounding: the canopy is bilinear in each of its cells.
    pub fn band_lattice(&self, xs: &[f64], ys: &[f64]) -> Option<BandLattice> {
        let b = self.bands.as_ref()?;
        let at = worldgen::sample::GridPlacement {
            origin_m: self.origin_m,
            spacing_m: b.spacing_m,
        };
        Some(BandLattice {
            tops_m: b.tops_m.clone(),
            values: (0..b.tops_m.len())
                .map(|band| {
                    worldgen::sample::bilinear_lattice(&b.sum(&self.layers, band), at, xs, ys)
                })
                .collect(),
        })
    }

    /// Whether a lattice of `spacing_m` whose point (0, 0) is at `origin_m` nests in the
    /// canopy's grid (see [`Self::band_lattice`]).
    pub fn lattice_nests(&self, origin_m: [f64; 2], spacing_m: f64) -> bool {
        let Some(b) = &self.bands else { return false };
        let whole = |v: f64| (v - v.round()).abs() < 1e-9;
        whole(b.spacing_m / spacing_m)
            && (0..2).all(|a| whole((origin_m[a] - self.origin_m[a]) / spacing_m))
    }
}

impl Canopy {
    /// Whether [`Self::extinction_per_m`] can be above zero anywhere in the rectangle
    /// `min`..`max` (world m) at any height: some layer has a value above zero in a cell that
    /// touches it, as the scan of the layers' cells looks: one bit per cell where the layers
    /// share one grid.
    pub fn any_in(&self, min: [f64; 2], max: [f64; 2]) -> bool {
        let Some(b) = &self.bands else {
            return self.max_extinction_in(min, max) > 0.0;
        };
        // Bands exist only for layers that share one grid.
        let (w, h) = self.layers[0].0.size();
        let range = |axis: usize, len: usize| {
            let to =
                |v: f64| ((v - self.origin_m[axis]) / b.spacing_m).clamp(0.0, (len - 1) as f64);
            (
                to(min[axis]).floor() as usize,
                to(max[axis]).ceil() as usize,
            )
        };
        b.any_in_cells(range(0, w), range(1, h))
    }
}

impl Canopy {
    /// The factor on a node's projected error for a camera at `eye`: the largest visibility of
    /// the node's top centre (integrated up to the node's border: its own vegetation does not
    /// hide it) and of its four top corners, or 1 when the camera is above the canopy or the node
    /// is near. One line of sight stands for a whole node poorly: rendered at eye height, the
    /// centre's line alone let a far node keep 3.6 px of error where its ridge showed above or
    /// between the trees (tau 2); the corners' lines catch such nodes.
    pub fn error_factor(
        &self,
        world: &World,
        eye: glam::DVec3,
        rect: Rect,
        z_top_m: f64,
        dist_m: f64,
    ) -> f64 {
        let half = 0.5 * (rect.max[0] - rect.min[0]);
        if dist_m <= 2.0 * half || self.layers.is_empty() {
            return 1.0;
        }
        let heights = worldgen::sample::GridPlacement {
            origin_m: self.origin_m,
            spacing_m: self.heights_spacing_m,
        };
        let ground = worldgen::sample::bilinear(&world.map.heights, heights, eye.x, eye.y);
        if eye.z - ground > self.top_m {
            return 1.0;
        }
        let centre = glam::DVec3::new(
            0.5 * (rect.min[0] + rect.max[0]),
            0.5 * (rect.min[1] + rect.max[1]),
            z_top_m,
        );
        let d = centre - eye;
        let flat = d.truncate().length().max(1e-9);
        // Stop at the node's border (approximately: half its side before the centre).
        let end = eye + d * (1.0 - (half / flat).min(1.0));
        let corners = [
            [rect.min[0], rect.min[1]],
            [rect.max[0], rect.min[1]],
            [rect.min[0], rect.max[1]],
            [rect.max[0], rect.max[1]],
        ];
        // Clear lines stop the search: no visibility exceeds 1.
        let mut best = self.visibility(world, eye, end);
        for c in corners {
            if best >= 1.0 {
                break;
            }
            best = best.max(self.visibility(world, eye, glam::DVec3::new(c[0], c[1], z_top_m)));
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The canopy of the tiny map, moved off the round origin, and the same canopy with its
    /// bands left out (every look-up sums the layers one by one: the model itself).
    fn canopies() -> (Canopy, Canopy) {
        let mut map = crate::test_maps::tiny_map();
        map.manifest.origin_m = [1234.567, -89.0123];
        let world = World::new(map);
        let canopy = Canopy::new(&world, &Placer::new(&world));
        let mut plain = canopy.clone();
        plain.bands = None;
        assert!(
            canopy.bands.is_some(),
            "the tiny map's layers share one grid"
        );
        (canopy, plain)
    }

    /// Points over the map and a little beyond it, seeded.
    fn points(n: usize) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let u = |k: i64| worldgen::noise::unit3(7, i as i64, k);
                [
                    1234.567 - 20.0 + 552.0 * u(0),
                    -89.0123 - 20.0 + 552.0 * u(1),
                    -1.0 + 26.0 * u(2),
                ]
            })
            .collect()
    }

    /// The summed bands give each species layer's sum at every height, within f32 rounding.
    #[test]
    fn banded_extinction_equals_the_sum_of_the_layers() {
        let (canopy, plain) = canopies();
        // The banded value against the layers' sum at one point; the sum.
        let check = |x: f64, y: f64, above: f64| {
            let (a, b) = (
                canopy.extinction_per_m(x, y, above),
                plain.extinction_per_m(x, y, above),
            );
            assert!(
                (a - b).abs() <= 1e-6 * (1.0 + b),
                "({x}, {y}, {above} m): {a} vs {b}"
            );
            b
        };
        let nonzero = points(4000)
            .into_iter()
            .filter(|&[x, y, above]| check(x, y, above) > 0.0)
            .count();
        assert!(nonzero > 500, "only {nonzero} points with vegetation");
        // Heights at the layer tops and just over them pick the right band.
        for top in plain.layer_tops_m() {
            for above in [top, top + 1e-6] {
                for [x, y, _] in points(50) {
                    check(x, y, above);
                }
            }
        }
    }

    /// The O(1) occupancy test answers as the scan of the layers' cells, on rectangles from a
    /// point to wider than the map.
    #[test]
    fn any_in_agrees_with_the_cell_scan() {
        let (canopy, plain) = canopies();
        let (mut some, mut none) = (0, 0);
        for (i, [x, y, z]) in points(3000).into_iter().enumerate() {
            let half = [0.0, 3.0, 17.0, 60.0, 400.0][i % 5] * (0.5 + z.abs() / 26.0);
            let (min, max) = ([x - half, y - 0.7 * half], [x + half, y + 0.7 * half]);
            let scan = plain.max_extinction_in(min, max) > 0.0;
            assert_eq!(canopy.any_in(min, max), scan, "{min:?}..{max:?}");
            if scan { some += 1 } else { none += 1 }
        }
        assert!(
            some > 100 && none > 100,
            "{some} with vegetation, {none} without"
        );
    }

    /// Between the points of a lattice that nests in the canopy's grid, bilinear
    /// interpolation of the band lattice gives the extinction there; a lattice off the grid
    /// is refused.
    #[test]
    fn a_nested_band_lattice_interpolates_to_the_extinction() {
        let (canopy, plain) = canopies();
        let origin = [1234.567 + 16.0, -89.0123 + 40.0];
        assert!(canopy.lattice_nests(origin, 2.0));
        assert!(!canopy.lattice_nests([origin[0] + 1.0, origin[1]], 2.0));
        assert!(!canopy.lattice_nests(origin, 3.0));
        let n = 200;
        let axis = |a: usize| -> Vec<f64> { (0..n).map(|i| origin[a] + 2.0 * i as f64).collect() };
        let lattice = canopy.band_lattice(&axis(0), &axis(1)).expect("bands");
        let mut nonzero = 0;
        for [u, v, above] in points(3000) {
            // Lattice coordinates within its last cell.
            let gx = (u - 1214.567) / 552.0 * (n - 1) as f64 * 0.999;
            let gy = (v + 109.0123) / 552.0 * (n - 1) as f64 * 0.999;
            let (x, y) = (origin[0] + 2.0 * gx, origin[1] + 2.0 * gy);
            let want = plain.extinction_per_m(x, y, above);
            let band = lattice.tops_m.partition_point(|&t| t < above);
            let got = match lattice.values.get(band) {
                Some(values) if above >= 0.0 => {
                    let k = |i: usize, j: usize| values[j * n + i];
                    let (i, j) = (gx.floor() as usize, gy.floor() as usize);
                    let (tx, ty) = (gx - i as f64, gy - j as f64);
                    let lo = k(i, j) + (k(i + 1, j) - k(i, j)) * tx;
                    let hi = k(i, j + 1) + (k(i + 1, j + 1) - k(i, j + 1)) * tx;
                    lo + (hi - lo) * ty
                }
                _ => 0.0,
            };
            assert!(
                (got - want).abs() <= 1e-6 * (1.0 + want),
                "({x}, {y}, {above}): {got} vs {want}"
            );
            nonzero += usize::from(want > 0.0);
        }
        assert!(nonzero > 200, "only {nonzero} points with vegetation");
    }
}
