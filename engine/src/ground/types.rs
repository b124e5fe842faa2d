//! The ground types of a node's ground texture, gathered by the node's CPU phase `ground
//! pieces`, so the GPU holds no copy of the map's ground layer (64 MiB at 32 km).
//!
//! A texel's type is the ground sample nearest to its centre moved by two octaves of value
//! noise of up to 0.7 ground cells ([`perturbed_ground_cell`], the prelude's function of the
//! same name), so type borders are natural instead of the 4 m staircase. Where a node's texels
//! are at most a ground cell apart (every node but the few coarsest), the phase gathers the
//! cells its texels can reach (a few hundred bytes for the finest nodes) and the texture pass
//! perturbs each texel on the GPU as before ([`TypeForm::Cells`]). On coarser nodes that would
//! be a large part of the map, so the phase resolves each texel's type itself
//! ([`TypeForm::Texels`]; a few milliseconds a node), on the coarsest level of the layer whose
//! samples are at most a texel apart ([`crate::surface::stride_levels`]; a few pages, where
//! the layer's own samples under the root are the whole map): its noise makes the same f32
//! operations as the shader's, so on the layer itself the two agree except where a position
//! rounds within an ulp of a half cell, and most texels need none (every sample the
//! perturbation can reach has one type).
//!
//! Both are stored as runs of equal types: a node holds hundreds of bytes (27 KB at most on the
//! default map's flight) where a plain list of its texels would take 64 KiB.

use super::layout::{SIDE, lattice_index, texel_m};
use crate::surface::stride_levels::StrideLevels;
use crate::terrain::quadtree::{NodeKey, QuadTree};
use worldgen::map::GroundTypes;

/// The largest distance (ground cells, per axis) the perturbation moves a position.
const REACH_CELLS: f32 = 0.7;

/// Where a node's texels lie on the ground layer, in the f32 numbers the shader uses: ground
/// cell coordinates of texel (`i`, `j`) are `anchor + (first + (i, j) + 1/2) step`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TexelCells {
    /// Lattice index of texel (0, 0) ([`lattice_index`]).
    pub first: [i32; 2],
    /// Ground-cell coordinates of lattice index (0, 0)'s corner.
    pub anchor: [f32; 2],
    /// Texel size in ground cells.
    pub step: f32,
}

impl TexelCells {
    /// The texels of node `key` on a ground layer of cells `spacing_m` from `origin_m`.
    pub fn new(tree: &QuadTree, key: NodeKey, origin_m: [f64; 2], spacing_m: f64) -> Self {
        let t = texel_m(tree, key.level);
        let root = tree.rect(NodeKey::ROOT).min;
        Self {
            first: lattice_index(key, 0, 0).map(|v| v as i32),
            anchor: [
                ((root[0] - origin_m[0]) / spacing_m) as f32,
                ((root[1] - origin_m[1]) / spacing_m) as f32,
            ],
            step: (t / spacing_m) as f32,
        }
    }

    /// The same texels placed on level `k` of the ground layer (stride `2^k` cells): its
    /// coordinates are the layer's divided by `2^k` (exact in f32).
    fn on_level(&self, k: usize) -> Self {
        let scale = 1.0 / (1u32 << k) as f32;
        Self {
            first: self.first,
            anchor: self.anchor.map(|a| a * scale),
            step: self.step * scale,
        }
    }

    /// Ground-cell coordinates of texel (`i`, `j`)'s centre.
    fn centre(&self, i: u32, j: u32) -> [f32; 2] {
        let c = |first: i32, k: u32, anchor: f32| {
            let centre = (first + k as i32) as f32 + 0.5;
            anchor + centre * self.step
        };
        [
            c(self.first[0], i, self.anchor[0]),
            c(self.first[1], j, self.anchor[1]),
        ]
    }
}

/// The prelude's `lattice_hash`: a value in [0, 1] per integer lattice point.
pub fn lattice_hash(x: i32, y: i32) -> f32 {
    let mut h = (x as u32).wrapping_mul(0x8da6_b343) ^ (y as u32).wrapping_mul(0xd816_3841);
    h = (h ^ (h >> 15)).wrapping_mul(0x2c1b_3c6d);
    h ^= h >> 12;
    (h & 0xffff) as f32 / 65535.0
}

/// WGSL's `mix`: `a (1 - t) + b t`.
fn mix(a: f32, b: f32, t: f32) -> f32 {
    a * (1.0 - t) + b * t
}

/// The prelude's `value_noise`: smooth value noise in [0, 1] on a lattice of unit cells.
pub fn value_noise(p: [f32; 2]) -> f32 {
    let c = [p[0].floor(), p[1].floor()];
    let f = [p[0] - c[0], p[1] - c[1]];
    let u = f.map(|f| f * f * (3.0 - 2.0 * f));
    let [x, y] = c.map(|c| c as i32);
    let a = lattice_hash(x, y);
    let b = lattice_hash(x.wrapping_add(1), y);
    let d = lattice_hash(x, y.wrapping_add(1));
    let e = lattice_hash(x.wrapping_add(1), y.wrapping_add(1));
    mix(mix(a, b, u[0]), mix(d, e, u[0]), u[1])
}

/// The prelude's `perturbed_ground_cell`: the ground sample whose type shows at `g` (ground-cell
/// coordinates from the map origin).
pub fn perturbed_ground_cell(g: [f32; 2]) -> [i32; 2] {
    let at = |k: f32, o: f32| [g[0] * k + o, g[1] * k + o];
    let wobble = [
        (value_noise(at(1.3, 0.0)) + 0.5 * value_noise(at(3.7, 17.0))) / 1.5 - 0.5,
        (value_noise(at(1.3, 41.0)) + 0.5 * value_noise(at(3.7, 59.0))) / 1.5 - 0.5,
    ];
    [0, 1].map(|a| (g[a] + 2.0 * REACH_CELLS * wobble[a]).round_ties_even() as i32)
}

/// [`perturbed_ground_cell`] along one row of positions (one `y`): the row's part of each
/// noise term is computed once, and the lattice hashes of a cell are reused while positions
/// stay in it (fine nodes have many texels per noise cell). The same operations in the same
/// order as [`value_noise`], so the same results bit for bit.
struct WobbleRow {
    y: f32,
    terms: [NoiseRow; 4],
}

/// One value-noise term `value_noise(p * scale + offset)` along a row.
struct NoiseRow {
    scale: f32,
    offset: f32,
    iy: i32,
    uy: f32,
    /// The lattice cell column the hashes are of, and the hashes of its four corners.
    ix: Option<i32>,
    hashes: [f32; 4],
}

impl NoiseRow {
    fn new(y: f32, scale: f32, offset: f32) -> Self {
        let py = y * scale + offset;
        let cy = py.floor();
        let fy = py - cy;
        Self {
            scale,
            offset,
            iy: cy as i32,
            uy: fy * fy * (3.0 - 2.0 * fy),
            ix: None,
            hashes: [0.0; 4],
        }
    }

    fn at(&mut self, x: f32) -> f32 {
        let px = x * self.scale + self.offset;
        let cx = px.floor();
        let fx = px - cx;
        let ux = fx * fx * (3.0 - 2.0 * fx);
        let ix = cx as i32;
        if self.ix != Some(ix) {
            let (x1, y1) = (ix.wrapping_add(1), self.iy.wrapping_add(1));
            self.hashes = [
                lattice_hash(ix, self.iy),
                lattice_hash(x1, self.iy),
                lattice_hash(ix, y1),
                lattice_hash(x1, y1),
            ];
            self.ix = Some(ix);
        }
        let [a, b, d, e] = self.hashes;
        mix(mix(a, b, ux), mix(d, e, ux), self.uy)
    }
}

impl WobbleRow {
    fn new(y: f32) -> Self {
        Self {
            y,
            terms: [
                NoiseRow::new(y, 1.3, 0.0),
                NoiseRow::new(y, 3.7, 17.0),
                NoiseRow::new(y, 1.3, 41.0),
                NoiseRow::new(y, 3.7, 59.0),
            ],
        }
    }

    /// `perturbed_ground_cell([x, y])`.
    fn cell(&mut self, x: f32) -> [i32; 2] {
        let [a, b, c, d] = &mut self.terms;
        let wobble = [
            (a.at(x) + 0.5 * b.at(x)) / 1.5 - 0.5,
            (c.at(x) + 0.5 * d.at(x)) / 1.5 - 0.5,
        ];
        let g = [x, self.y];
        [0, 1].map(|k| (g[k] + 2.0 * REACH_CELLS * wobble[k]).round_ties_even() as i32)
    }
}

/// What a node's type list holds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum TypeForm {
    /// Each texel's type, in texel order (row 0 south, west to east): coarse nodes, whose
    /// texels are more than a ground cell apart.
    #[default]
    Texels,
    /// The ground cells the node's texels can reach, `side` cells from cell `first`, rows
    /// south to north, on a layer of `map` cells: the texture pass perturbs each texel's
    /// position and reads its cell here (nodes whose texels are at most a cell apart: their
    /// cells are few, and the noise costs the GPU nothing).
    Cells {
        first: [i32; 2],
        side: [u32; 2],
        map: [i32; 2],
    },
}

/// The ground types of one node texture (see the module docs).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct NodeTypes {
    pub form: TypeForm,
    /// Runs of one type in the form's order: (length - 1, type).
    runs: Vec<[u8; 2]>,
}

/// Appends a run of `t` to `runs`.
fn push_run(runs: &mut Vec<[u8; 2]>, t: u8) {
    match runs.last_mut() {
        Some(run) if run[1] == t && run[0] < u8::MAX => run[0] += 1,
        _ => runs.push([0, t]),
    }
}

impl NodeTypes {
    /// The types of the texels `cells` places on `ground` (with its `levels`), each at most
    /// `last_type` (the materials' last layer): the cells they reach where texels are at most
    /// a cell apart, each texel's type otherwise.
    ///
    /// A texel more than a cell across reads the coarsest level of `levels` whose samples are
    /// at most a texel apart (level `k` for texels of `2^k` to `2^(k+1)` cells), perturbed on
    /// that level's lattice: a node reads a few pages of its level where the ground layer's own
    /// samples under it would be a large part of the map (the root's texel spans 34 cells at
    /// 32 km). Its texels' types are then point samples of the level, as they were of the layer.
    pub fn resolve(
        ground: &GroundTypes,
        levels: &StrideLevels<u8>,
        cells: &TexelCells,
        last_type: u8,
    ) -> Self {
        if cells.step <= 1.0 {
            return Self::reached_cells(ground, cells, last_type);
        }
        let k = (cells.step.log2().floor() as usize).min(levels.count());
        match levels.level(k) {
            Some(level) => Self::texels(level, &cells.on_level(k), last_type),
            None => Self::texels(ground, cells, last_type),
        }
    }

    /// [`TypeForm::Cells`]: the cells within reach of the texels' centres, with a margin of a
    /// cell for rounding.
    fn reached_cells(ground: &GroundTypes, cells: &TexelCells, last_type: u8) -> Self {
        let map = [ground.width() as i32, ground.height() as i32];
        let (lo, hi) = (cells.centre(0, 0), cells.centre(SIDE - 1, SIDE - 1));
        let reach = REACH_CELLS + 1.5;
        let range = |a: usize| {
            let first = ((lo[a] - reach).floor() as i32).clamp(0, map[a] - 1);
            let last = ((hi[a] + reach).ceil() as i32).clamp(0, map[a] - 1);
            (first, (last - first + 1) as u32)
        };
        let ((x0, w), (y0, h)) = (range(0), range(1));
        let region = ground.region(x0 as usize, y0 as usize, w as usize, h as usize);
        let mut runs = Vec::new();
        for &t in region.data() {
            push_run(&mut runs, t.min(last_type));
        }
        runs.shrink_to_fit();
        Self {
            form: TypeForm::Cells {
                first: [x0, y0],
                side: [w, h],
                map,
            },
            runs,
        }
    }

    /// [`TypeForm::Texels`] read from `ground` (the layer or one of its levels, `cells` placed
    /// on it).
    fn texels(ground: &GroundTypes, cells: &TexelCells, last_type: u8) -> Self {
        let (w, h) = (ground.width() as i32, ground.height() as i32);
        // The samples the perturbation can reach from `v` along one axis (a margin of a
        // hundredth of a cell beyond the reach covers rounding differences).
        let span = |v: f32, n: i32| {
            let lo = (v - REACH_CELLS - 0.01).round() as i32;
            let hi = (v + REACH_CELLS + 0.01).round() as i32;
            (lo.clamp(0, n - 1) as usize, hi.clamp(0, n - 1) as usize)
        };
        let columns: Vec<(f32, (usize, usize))> = (0..SIDE)
            .map(|i| {
                let gx = cells.centre(i, 0)[0];
                (gx, span(gx, w))
            })
            .collect();
        // Every sample any texel can reach, read at once.
        let (x0, x1) = (columns[0].1.0, columns[SIDE as usize - 1].1.1);
        let (y0, y1) = (
            span(cells.centre(0, 0)[1], h).0,
            span(cells.centre(0, SIDE - 1)[1], h).1,
        );
        let region = ground.region(x0, y0, x1 - x0 + 1, y1 - y0 + 1);
        let sample = |x: usize, y: usize| region.get(x - x0, y - y0);
        let mut runs: Vec<[u8; 2]> = Vec::new();
        for j in 0..SIDE {
            let gy = cells.centre(0, j)[1];
            let (ya, yb) = span(gy, h);
            let mut noise = WobbleRow::new(gy);
            // The last column span's single type (None: mixed): neighbouring texels of a fine
            // node share their spans.
            let mut last: Option<((usize, usize), Option<u8>)> = None;
            for &(gx, (xa, xb)) in &columns {
                let single = match last {
                    Some((span, single)) if span == (xa, xb) => single,
                    _ => {
                        let first = sample(xa, ya);
                        let single = (ya..=yb)
                            .all(|y| (xa..=xb).all(|x| sample(x, y) == first))
                            .then_some(first);
                        last = Some(((xa, xb), single));
                        single
                    }
                };
                let t = single
                    .unwrap_or_else(|| {
                        let [x, y] = noise.cell(gx);
                        let x = x.clamp(x0 as i32, x1 as i32) as usize;
                        sample(x, y.clamp(y0 as i32, y1 as i32) as usize)
                    })
                    .min(last_type);
                push_run(&mut runs, t);
            }
        }
        runs.shrink_to_fit();
        Self {
            form: TypeForm::Texels,
            runs,
        }
    }

    /// Types the list holds (texels or cells).
    pub fn count(&self) -> usize {
        match self.form {
            TypeForm::Texels => (SIDE * SIDE) as usize,
            TypeForm::Cells { side, .. } => side[0] as usize * side[1] as usize,
        }
    }

    /// Words [`Self::append_words`] appends.
    pub fn words(&self) -> usize {
        self.count().div_ceil(4)
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(self.runs.as_slice())
    }

    /// Appends the types to `out` as [`Self::words`] words whose bytes are the types in the
    /// form's order (the GPU reads words little-endian: the first type in the low byte).
    pub fn append_words(&self, out: &mut Vec<u32>) {
        let start = out.len();
        out.resize(start + self.words(), 0);
        let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut out[start..]);
        let mut texel = 0usize;
        for &[length, t] in &self.runs {
            let end = texel + usize::from(length) + 1;
            bytes[texel..end].fill(t);
            texel = end;
        }
        debug_assert_eq!(texel, self.count(), "runs cover the list");
    }

    /// The type of texel (`i`, `j`) (`i` east, `j` north from the south-west border texel) of
    /// the node whose texels `cells` places, as the texture pass reads it.
    pub fn texel(&self, cells: &TexelCells, i: u32, j: u32) -> u8 {
        match self.form {
            TypeForm::Texels => self.at((j * SIDE + i) as usize),
            TypeForm::Cells { first, side, map } => {
                let c = perturbed_ground_cell(cells.centre(i, j));
                let local = [0, 1]
                    .map(|a| (c[a].clamp(0, map[a] - 1) - first[a]).clamp(0, side[a] as i32 - 1));
                self.at(local[1] as usize * side[0] as usize + local[0] as usize)
            }
        }
    }

    /// The list's `at`-th type.
    fn at(&self, at: usize) -> u8 {
        let mut texel = 0usize;
        for &[length, t] in &self.runs {
            texel += usize::from(length) + 1;
            if at < texel {
                return t;
            }
        }
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use worldgen::Grid;

    /// A ground layer of stripes and noise-free blocks with types 0 - 3.
    fn ground(n: usize) -> Grid<u8> {
        let mut g = Grid::new(n, n, 0u8);
        for y in 0..n {
            for x in 0..n {
                g.set(x, y, (((x / 7) + (y / 5) * 3 + (x * y) % 3 / 2) % 4) as u8);
            }
        }
        g
    }

    /// Every texel reads the perturbed sample of its centre, computed texel by texel: on a
    /// coarse node from its own type, on the level of stride `2^k` for texels of `2^k` to
    /// `2^(k+1)` cells (sample `m` of the level is the layer's `min(m 2^k, n - 1)`), or on the
    /// layer itself where there are no levels (the shortcut for uniform spans changes nothing);
    /// from the node's reached cells on finer ones (the cells cover every reachable one).
    #[test]
    fn every_texel_reads_its_perturbed_cell() {
        let n = 1025;
        let g = ground(n);
        let layer = GroundTypes::Grid(g.clone());
        // The tree's corner off the layer's origin: the texels' anchor is not zero.
        let tree = QuadTree::new([-3.0, -5.0], [1024.0, 1024.0]);
        let key = |level, ix, iy| NodeKey { level, ix, iy };
        let mut levels_read = Vec::new();
        for (levels, with_levels) in [
            (StrideLevels::compute(&g), true),
            (StrideLevels::default(), false),
        ] {
            assert_eq!(levels.count(), if with_levels { 3 } else { 0 });
            for (key, texels) in [
                (key(0, 0, 0), true),
                (key(1, 0, 0), true),
                (key(2, 1, 0), true),
                (key(3, 3, 1), false),
                (key(4, 2, 5), false),
                (key(tree.max_level, 7, 3), false),
            ] {
                let cells = TexelCells::new(&tree, key, [0.0, 0.0], 1.0);
                let types = NodeTypes::resolve(&layer, &levels, &cells, 3);
                assert_eq!(types.form == TypeForm::Texels, texels, "{key:?}");
                let k = if texels && with_levels {
                    (cells.step.log2().floor() as usize).min(3)
                } else {
                    0
                };
                levels_read.push(k);
                let stride = 1i32 << k;
                let last = (n - 1).div_ceil(1 << k) as i32;
                for j in 0..SIDE {
                    for i in 0..SIDE {
                        let [x, y] = if texels {
                            let c = cells.centre(i, j).map(|v| v / stride as f32);
                            perturbed_ground_cell(c)
                        } else {
                            perturbed_ground_cell(cells.centre(i, j))
                        };
                        let on_layer = |m: i32| (m.clamp(0, last) * stride).min(n as i32 - 1);
                        let want = g.get(on_layer(x) as usize, on_layer(y) as usize);
                        assert_eq!(types.texel(&cells, i, j), want, "{key:?} texel {i}, {j}");
                    }
                }
                let mut words = vec![7];
                types.append_words(&mut words);
                assert_eq!(words.len(), 1 + types.words());
                let k = types.count() - 1;
                assert_eq!((words[1 + k / 4] >> (8 * (k % 4))) as u8, types.at(k));
            }
        }
        // The root's texels span 4.3 cells (level 2), its children's 2.1 (level 1), theirs
        // 1.07 (the layer).
        assert_eq!(levels_read[..3], [2, 1, 0]);
    }

    /// The perturbation moves positions by up to 0.7 cells and does move them: a position's
    /// nearest sample differs from its perturbed sample for a good share of positions.
    #[test]
    fn the_perturbation_reaches_up_to_seven_tenths_of_a_cell() {
        let mut moved = 0;
        for k in 0..10_000 {
            let g = [k as f32 * 0.173 + 3.0, (k / 100) as f32 * 0.291 + 1000.0];
            let p = perturbed_ground_cell(g);
            for a in 0..2 {
                assert!(
                    (p[a] as f32 - g[a]).abs() <= 0.5 + REACH_CELLS + 1e-3,
                    "{g:?} {p:?}"
                );
            }
            moved += usize::from(p != g.map(|v| v.round_ties_even() as i32));
        }
        assert!((2_000..8_000).contains(&moved), "{moved} of 10000 moved");
    }

    /// Types above the last layer are clamped, and a map of one type gives one run.
    #[test]
    fn one_type_is_one_run_and_types_clamp() {
        let g = Grid::new(33, 33, 9u8);
        let levels = StrideLevels::compute(&g);
        let tree = QuadTree::new([0.0, 0.0], [128.0, 128.0]);
        let cells = TexelCells::new(&tree, NodeKey::ROOT, [0.0, 0.0], 4.0);
        let types = NodeTypes::resolve(&g.into(), &levels, &cells, 5);
        assert_eq!(types.texel(&cells, 3, 200), 5);
        assert_eq!(types.bytes(), 2 * types.count().div_ceil(256));
    }
}
