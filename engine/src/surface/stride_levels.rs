//! A map raster at every `2^k`-th sample, baked as page files, so that coarse work reads a few
//! pages of its own level instead of every page of the map under it: the heights' levels for
//! coarse nodes' lattices ([`HeightLevels`]), the ground types' for the coarsest nodes' texture
//! texels ([`crate::ground::types`]).
//!
//! A coarse node's vertices stand on height samples (its spacing is a multiple of the height
//! spacing and its corners are on the grid), and the bicubic interpolation on a sample is the
//! sample itself ([`worldgen::sample::bicubic`]). So where the lattice's grid coordinates are
//! all multiples of `2^k` (or the last sample, where coordinates beyond the map are clamped),
//! its height part is level `k` read at `coordinate / 2^k`: the same values, bit for bit.
//!
//! Level `k` (stride `2^k`, `k >= 1`) of a raster of `n` samples along an axis holds
//! `ceil((n - 1) / 2^k) + 1` samples: sample `m` is the raster's `min(m 2^k, n - 1)`. It is
//! stored as `pages/derived/<name>_stride_<2^k>.pages`; levels stop at the first of at most
//! [`LAST_LEVEL_SAMPLES`] samples along each axis.

use std::path::{Path, PathBuf};
use worldgen::Grid;
use worldgen::map::MapRaster;
use worldgen::pages::{CacheSample, PageError, PagedRaster, Paging, SourceKey, bake};

/// The levels of one raster (stride 2, 4, 8, ... samples), in memory or paged.
#[derive(Debug, Clone)]
pub struct StrideLevels<T> {
    /// Level `k` at index `k - 1`.
    levels: Vec<MapRaster<T>>,
    /// Samples of the raster along x and y.
    samples: [usize; 2],
}

impl<T> Default for StrideLevels<T> {
    fn default() -> Self {
        Self {
            levels: Vec::new(),
            samples: [0, 0],
        }
    }
}

/// The heights' levels (read only where the heights are paged).
pub type HeightLevels = StrideLevels<f32>;

/// The file stem of the heights' levels.
pub const HEIGHTS: &str = "heights";

/// The file stem of the ground types' levels.
pub const GROUND_TYPES: &str = "ground_types";

/// The page file of the level of `stride` samples of the raster `name`.
pub fn level_path(pages_dir: &Path, name: &str, stride: usize) -> PathBuf {
    pages_dir
        .join("derived")
        .join(format!("{name}_stride_{stride}.pages"))
}

/// Samples along an axis of `n` samples at `stride`.
fn level_len(n: usize, stride: usize) -> usize {
    (n - 1).div_ceil(stride) + 1
}

/// Samples along each axis of the coarsest level.
pub const LAST_LEVEL_SAMPLES: usize = 256;

/// The strides baked for a raster of `samples`: 2, 4, ... up to the first level of at most
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

/// The key of the level of `stride` of the raster of `raster_key`.
fn key(raster_key: u64, stride: usize) -> u64 {
    let mut k = SourceKey::new(0x4E16_0000);
    k.update(&raster_key.to_le_bytes());
    k.update(&(stride as u64).to_le_bytes());
    k.finish()
}

/// Level of `stride` of `raster`.
fn level<T: Copy>(raster: &Grid<T>, stride: usize) -> Grid<T> {
    let (w, h) = (raster.width(), raster.height());
    let (lw, lh) = (level_len(w, stride), level_len(h, stride));
    let samples = (0..lh).flat_map(|m| {
        let y = (m * stride).min(h - 1);
        (0..lw).map(move |l| raster.get((l * stride).min(w - 1), y))
    });
    Grid::from_vec(lw, lh, samples.collect()).expect("sized above")
}

/// Writes every level of `raster` (of key `raster_key`) named `name` under
/// `pages_dir/derived`.
pub fn write<T: CacheSample>(
    raster: &Grid<T>,
    raster_key: u64,
    name: &str,
    pages_dir: &Path,
    page_side: u32,
) -> Result<(), PageError> {
    let samples = [raster.width(), raster.height()];
    for stride in strides(samples) {
        let path = level_path(pages_dir, name, stride);
        bake::write_grid(
            &path,
            &level(raster, stride),
            page_side,
            key(raster_key, stride),
        )?;
    }
    Ok(())
}

impl<T: CacheSample + std::fmt::Debug> StrideLevels<T> {
    /// Every level of `raster`, in memory.
    pub fn compute(raster: &Grid<T>) -> Self {
        let samples = [raster.width(), raster.height()];
        Self {
            levels: strides(samples)
                .into_iter()
                .map(|stride| MapRaster::Grid(level(raster, stride)))
                .collect(),
            samples,
        }
    }

    /// Opens the levels of the raster `name` baked under `pages_dir` for a raster of `samples`
    /// and `raster_key`, served through `paging`. The levels are all there or none is used
    /// (the error names the first file missing or not of this raster).
    pub fn open(
        pages_dir: &Path,
        name: &str,
        samples: [usize; 2],
        raster_key: u64,
        paging: &Paging,
    ) -> Result<Self, PageError> {
        let mut levels = Vec::new();
        for stride in strides(samples) {
            let (w, h) = (level_len(samples[0], stride), level_len(samples[1], stride));
            let path = level_path(pages_dir, name, stride);
            let file = bake::open_derived(&path, T::KIND, w, h, key(raster_key, stride))?;
            levels.push(MapRaster::Paged(PagedRaster::new(paging, file, T::zero())?));
        }
        Ok(Self { levels, samples })
    }

    pub fn is_empty(&self) -> bool {
        self.levels.is_empty()
    }

    /// Level `k` (`k >= 1`, stride `2^k`), where there is one.
    pub fn level(&self, k: usize) -> Option<&MapRaster<T>> {
        self.levels.get(k.checked_sub(1)?)
    }

    /// The coarsest level, where there is one.
    pub fn coarsest(&self) -> Option<&MapRaster<T>> {
        self.levels.last()
    }

    /// Levels held: the last is the coarsest.
    pub fn count(&self) -> usize {
        self.levels.len()
    }

    /// Bytes the levels hold in memory (paged levels' pages are the cache's).
    pub fn held_bytes(&self) -> usize {
        self.levels.iter().map(MapRaster::held_bytes).sum()
    }
}

impl HeightLevels {
    /// Sets the value served for samples of pages that cannot be read.
    pub fn set_fill(&self, fill: f32) {
        for l in self.levels.iter().filter_map(MapRaster::paged) {
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
