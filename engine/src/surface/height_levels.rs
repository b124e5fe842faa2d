//! The map's heights at every `2^k`-th sample, baked as page files, so that a coarse node
//! reads its lattice from a few pages of its own level instead of every page of the map
//! under it.
//!
//! A coarse node's vertices stand on height samples (its spacing is a multiple of the height
//! spacing and its corners are on the grid), and the bicubic interpolation on a sample is the
//! sample itself ([`worldgen::sample::bicubic`]). So where the lattice's grid coordinates are
//! all multiples of `2^k` (or the last sample, where coordinates beyond the map are clamped),
//! its height part is level `k` read at `coordinate / 2^k`: the same values, bit for bit.
//!
//! Level `k` (stride `2^k`, `k >= 1`) of a raster of `n` samples along an axis holds
//! `ceil((n - 1) / 2^k) + 1` samples: sample `m` is the raster's `min(m 2^k, n - 1)`. It is
//! stored as `pages/derived/heights_stride_<2^k>.pages`; levels stop at the first of at most
//! [`LAST_LEVEL_SAMPLES`] samples along each axis.

use std::path::{Path, PathBuf};
use worldgen::Grid;
use worldgen::pages::{PageError, PagedRaster, Paging, SourceKey, bake};

/// The levels of a world's heights (stride 2, 4, 8, ... samples).
#[derive(Debug, Clone, Default)]
pub struct HeightLevels {
    /// Level `k` at index `k - 1`.
    levels: Vec<PagedRaster<f32>>,
    /// Samples of the heights along x and y.
    samples: [usize; 2],
}

/// The page file of the level of `stride` samples.
pub fn level_path(pages_dir: &Path, stride: usize) -> PathBuf {
    pages_dir
        .join("derived")
        .join(format!("heights_stride_{stride}.pages"))
}

/// Samples along an axis of `n` samples at `stride`.
fn level_len(n: usize, stride: usize) -> usize {
    (n - 1).div_ceil(stride) + 1
}

/// Samples along each axis of the coarsest level.
pub const LAST_LEVEL_SAMPLES: usize = 256;

/// The strides baked for heights of `samples`: 2, 4, ... up to the first level of at most
/// [`LAST_LEVEL_SAMPLES`] samples along each axis.
fn strides(samples: [usize; 2]) -> Vec<usize> {
    let mut out = Vec::new();
    if samples[0] < 2 || samples[1] < 2 {
        return out;
    }
    let mut stride = 2;
    loop {
        out.push(stride);
        let fits = |n: usize| level_len(n, stride) <= LAST_LEVEL_SAMPLES;
        if (fits(samples[0]) && fits(samples[1])) || stride >= 1 << 20 {
            return out;
        }
        stride *= 2;
    }
}

/// The key of the level of `stride` of the heights of `heights_key`.
fn key(heights_key: u64, stride: usize) -> u64 {
    let mut k = SourceKey::new(0x4E16_0000);
    k.update(&heights_key.to_le_bytes());
    k.update(&(stride as u64).to_le_bytes());
    k.finish()
}

/// Level of `stride` of `heights`.
fn level(heights: &Grid<f32>, stride: usize) -> Grid<f32> {
    let (w, h) = (heights.width(), heights.height());
    let (lw, lh) = (level_len(w, stride), level_len(h, stride));
    let samples = (0..lh).flat_map(|m| {
        let y = (m * stride).min(h - 1);
        (0..lw).map(move |l| heights.get((l * stride).min(w - 1), y))
    });
    Grid::from_vec(lw, lh, samples.collect()).expect("sized above")
}

/// Writes every level of `heights` (of key `heights_key`) under `pages_dir/derived`.
pub fn write(
    heights: &Grid<f32>,
    heights_key: u64,
    pages_dir: &Path,
    page_side: u32,
) -> Result<(), PageError> {
    let samples = [heights.width(), heights.height()];
    for stride in strides(samples) {
        let path = level_path(pages_dir, stride);
        bake::write_grid(
            &path,
            &level(heights, stride),
            page_side,
            key(heights_key, stride),
        )?;
    }
    Ok(())
}

impl HeightLevels {
    /// Opens the levels baked under `pages_dir` for heights of `samples` and `heights_key`,
    /// served through `paging`. The levels are all there or none is used (the error names the
    /// first file missing or not of these heights).
    pub fn open(
        pages_dir: &Path,
        samples: [usize; 2],
        heights_key: u64,
        paging: &Paging,
    ) -> Result<Self, PageError> {
        let mut levels = Vec::new();
        for stride in strides(samples) {
            let (w, h) = (level_len(samples[0], stride), level_len(samples[1], stride));
            let path = level_path(pages_dir, stride);
            let file = bake::open_derived(
                &path,
                worldgen::pages::SampleKind::F32,
                w,
                h,
                key(heights_key, stride),
            )?;
            levels.push(PagedRaster::new(paging, file, 0.0)?);
        }
        Ok(Self { levels, samples })
    }

    pub fn is_empty(&self) -> bool {
        self.levels.is_empty()
    }

    /// Sets the value served for samples of pages that cannot be read.
    pub fn set_fill(&self, fill: f32) {
        for l in &self.levels {
            l.set_fill(fill);
        }
    }

    /// The coarsest level whose samples include every grid coordinate of `xs` and `ys`
    /// (each already an integer in range), as its index (`k - 1`) and stride; `None` when
    /// the finest level does not.
    fn coarsest_for(&self, xs: &[usize], ys: &[usize]) -> Option<(usize, usize)> {
        let mut best = None;
        for (i, _) in self.levels.iter().enumerate() {
            let stride = 2usize << i;
            let on = |v: &[usize], n: usize| v.iter().all(|&g| g % stride == 0 || g == n - 1);
            if on(xs, self.samples[0]) && on(ys, self.samples[1]) {
                best = Some((i, stride));
            } else {
                break;
            }
        }
        best
    }

    /// The height samples at grid coordinates `xs` x `ys` (row-major), read from the
    /// coarsest level holding them all; `None` when no level does.
    pub fn samples(&self, xs: &[usize], ys: &[usize]) -> Option<Vec<f64>> {
        let (i, stride) = self.coarsest_for(xs, ys)?;
        let level = &self.levels[i];
        let index = |g: usize, n: usize, len: usize| {
            if g == n - 1 { len - 1 } else { g / stride }
        };
        let cols: Vec<usize> = xs
            .iter()
            .map(|&g| index(g, self.samples[0], level.width()))
            .collect();
        Some(
            ys.iter()
                .flat_map(|&g| {
                    let row = index(g, self.samples[1], level.height());
                    cols.iter().map(move |&c| f64::from(level.get(c, row)))
                })
                .collect(),
        )
    }
}

/// The grid coordinates of world coordinates `v` along an axis of `n` samples from `origin`
/// at `spacing` (clamped into the grid, as the interpolators place them), when every one is
/// exactly on a sample.
pub fn on_samples(v: &[f64], origin: f64, spacing: f64, n: usize) -> Option<Vec<usize>> {
    v.iter()
        .map(|&t| {
            let g = ((t - origin) / spacing).clamp(0.0, (n - 1) as f64);
            (g.fract() == 0.0).then_some(g as usize)
        })
        .collect()
}
