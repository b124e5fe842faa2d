//! The world's max-pyramids: per-cell bounds of the map surface's slope and curvature, of the
//! detail term's slope, curvature and amplitude, and of the height samples. They are derived
//! from the map's heights and the ground amplitude grid: computed at open for an unbaked map,
//! or baked into page files (`worldgen bake`) and opened from them ([`super::levels`]).

use super::height_max::HeightMax;
use super::levels::{self, Level, PageFaults};
use super::max_pyramid::MaxPyramid;
use super::spline::{catmull_rom_cell_curvature, catmull_rom_cell_slope};
use super::world::{DETAIL_OCTAVES, GRADIENT_NOISE_HESSIAN, GRADIENT_NOISE_LIPSCHITZ};
use std::path::Path;
use std::sync::Arc;
use worldgen::Grid;
use worldgen::pages::{PageCache, PageError};

/// Changes whenever what the pyramids hold changes: part of their page files' key.
const PYRAMIDS_VERSION: u64 = 1;

/// The per-cell max-pyramids behind [`super::World::region_bounds`].
#[derive(Debug, Clone)]
pub(crate) struct Pyramids {
    /// Slope bound of the bicubic map surface per height cell.
    pub(crate) slope_g: MaxPyramid,
    /// Slope bound of the detail term per ground cell.
    pub(crate) slope_detail: MaxPyramid,
    /// Hessian-norm bound of the bicubic map surface per height cell.
    pub(crate) curv_g: MaxPyramid,
    /// Hessian-norm bound of the detail term inside each ground cell (it is only C0 across
    /// ground-cell borders, where the bilinear amplitude has kinks).
    pub(crate) curv_detail: MaxPyramid,
    /// Largest detail amplitude at the corners of each ground cell.
    pub(crate) amp_max: MaxPyramid,
}

impl Pyramids {
    /// Computes the pyramids of `heights` (spacing `hs`) and `amplitude_m` (spacing `gs`),
    /// and the max-pyramid of the height samples.
    pub(crate) fn compute(
        heights: &Grid<f32>,
        hs: f64,
        amplitude_m: &Grid<f32>,
        gs: f64,
    ) -> (Self, HeightMax) {
        let p = Self {
            slope_g: MaxPyramid::new(bicubic_cell_slopes(heights, hs)),
            slope_detail: MaxPyramid::new(detail_cell_slopes(amplitude_m, gs)),
            curv_g: MaxPyramid::new(bicubic_cell_curvatures(heights, hs)),
            curv_detail: MaxPyramid::new(detail_cell_curvatures(amplitude_m, gs)),
            amp_max: MaxPyramid::new(cell_corner_max(amplitude_m)),
        };
        (p, HeightMax::new(heights))
    }

    /// Bytes of the levels held in memory.
    pub(crate) fn bytes(&self) -> usize {
        self.named().iter().map(|(_, p)| p.bytes()).sum()
    }

    fn named(&self) -> [(&'static str, &MaxPyramid); 5] {
        [
            ("slope_g", &self.slope_g),
            ("slope_detail", &self.slope_detail),
            ("curv_g", &self.curv_g),
            ("curv_detail", &self.curv_detail),
            ("amp_max", &self.amp_max),
        ]
    }

    /// The key of the pyramids' inputs and of this code: a [`worldgen::pages::SourceKey`] of
    /// the key of the heights ([`worldgen::pages::bake::Raster::key`]), the key of the
    /// amplitude grid's inputs, their spacings and [`PYRAMIDS_VERSION`].
    pub(crate) fn key(heights_key: u64, hs: f64, amplitude_key: u64, gs: f64) -> u64 {
        let mut key = worldgen::pages::SourceKey::new(0x9E7A_0000);
        for part in [
            heights_key,
            amplitude_key,
            hs.to_bits(),
            gs.to_bits(),
            PYRAMIDS_VERSION,
        ] {
            key.update(&part.to_le_bytes());
        }
        key.finish()
    }

    /// Writes every level of these pyramids and of `heights_max` as page files under
    /// `pages_dir/derived`.
    pub(crate) fn write(
        &self,
        heights_max: &HeightMax,
        pages_dir: &Path,
        page_side: u32,
        key: u64,
    ) -> Result<(), PageError> {
        for (name, p) in self.named() {
            levels::write_levels(pages_dir, name, &p.levels, page_side, key)?;
        }
        levels::write_levels(pages_dir, "height_max", &heights_max.levels, page_side, key)
    }

    /// Opens the pyramids of a map with `height_samples` and `ground_samples` (width, height)
    /// from their page files, baked with `key`.
    pub(crate) fn open(
        pages_dir: &Path,
        height_samples: [usize; 2],
        ground_samples: [usize; 2],
        key: u64,
        cache: &Arc<PageCache>,
        faults: &Arc<PageFaults>,
    ) -> Result<(Self, HeightMax), PageError> {
        let cells = |s: [usize; 2]| levels::level_sizes((s[0] - 1).max(1), (s[1] - 1).max(1));
        let open = |name: &str, sizes: &[(usize, usize)]| -> Result<Vec<Level>, PageError> {
            levels::open_levels(pages_dir, name, sizes, key, cache, faults)
        };
        let pyramid = |name: &str, s: [usize; 2]| -> Result<MaxPyramid, PageError> {
            Ok(MaxPyramid {
                levels: open(name, &cells(s))?,
            })
        };
        let p = Self {
            slope_g: pyramid("slope_g", height_samples)?,
            slope_detail: pyramid("slope_detail", ground_samples)?,
            curv_g: pyramid("curv_g", height_samples)?,
            curv_detail: pyramid("curv_detail", ground_samples)?,
            amp_max: pyramid("amp_max", ground_samples)?,
        };
        let hm = HeightMax::from_levels(
            open("height_max", &HeightMax::level_sizes(height_samples))?,
            height_samples,
        );
        Ok((p, hm))
    }
}

/// A grid with one value per cell of `src` (between samples x..x+1, y..y+1), rounded up so
/// the f32 value stays an upper bound of the f64 one.
fn per_cell(src: &Grid<f32>, value: impl Fn(usize, usize) -> f64) -> Grid<f32> {
    let (w, h) = ((src.width() - 1).max(1), (src.height() - 1).max(1));
    let mut out = Grid::new(w, h, 0.0f32);
    for y in 0..h {
        for x in 0..w {
            out.set(x, y, (value(x, y) * (1.0 + 1e-6)) as f32);
        }
    }
    out
}

/// The four corner samples of cell (x, y), clamped at the far border.
fn cell_corners(a: &Grid<f32>, x: usize, y: usize) -> [f64; 4] {
    let (x1, y1) = ((x + 1).min(a.width() - 1), (y + 1).min(a.height() - 1));
    [a.get(x, y), a.get(x1, y), a.get(x, y1), a.get(x1, y1)].map(f64::from)
}

/// Bound of |grad| of the bilinear interpolation of a cell's corners `c` (x-neighbours 0-1 and
/// 2-3, y-neighbours 0-2 and 1-3).
fn bilinear_gradient_bound(c: &[f64; 4], spacing_m: f64) -> f64 {
    let gx = (c[1] - c[0]).abs().max((c[3] - c[2]).abs());
    let gy = (c[2] - c[0]).abs().max((c[3] - c[1]).abs());
    gx.hypot(gy) / spacing_m
}

/// Bound of |grad D| for the detail noise (|D| <= 1).
fn detail_gradient_bound() -> f64 {
    DETAIL_OCTAVES
        .iter()
        .map(|&(wl, w)| w * GRADIENT_NOISE_LIPSCHITZ / wl)
        .sum()
}

/// Per height cell: a bound of |grad G| over the cell (clamped at the map border like G).
fn bicubic_cell_slopes(h: &Grid<f32>, spacing_m: f64) -> Grid<f32> {
    per_cell(h, |x, y| {
        let p = |a: i64, b: i64| f64::from(h.get_clamped(x as i64 + a, y as i64 + b));
        catmull_rom_cell_slope(&p, spacing_m)
    })
}

/// Per height cell: a bound of the Frobenius norm of the Hessian of G over the cell.
fn bicubic_cell_curvatures(h: &Grid<f32>, spacing_m: f64) -> Grid<f32> {
    per_cell(h, |x, y| {
        let p = |a: i64, b: i64| f64::from(h.get_clamped(x as i64 + a, y as i64 + b));
        catmull_rom_cell_curvature(&p, spacing_m)
    })
}

/// Per ground cell: a bound of the Hessian norm of A D inside the cell:
/// `A_max |H(D)| + 2 |grad A| |grad D| + |A_xy|` (A is bilinear, so A_xx = A_yy = 0).
fn detail_cell_curvatures(a: &Grid<f32>, spacing_m: f64) -> Grid<f32> {
    let grad_d = detail_gradient_bound();
    let hess_d: f64 = DETAIL_OCTAVES
        .iter()
        .map(|&(wl, w)| w * GRADIENT_NOISE_HESSIAN / (wl * wl))
        .sum();
    per_cell(a, |x, y| {
        let c = cell_corners(a, x, y);
        let a_max = c.iter().copied().fold(0.0, f64::max);
        let grad_a = bilinear_gradient_bound(&c, spacing_m);
        let a_xy = (c[3] - c[2] - c[1] + c[0]).abs() / (spacing_m * spacing_m);
        a_max * hess_d + 2.0 * grad_a * grad_d + a_xy
    })
}

/// Per cell: the largest of its four corner samples.
fn cell_corner_max(a: &Grid<f32>) -> Grid<f32> {
    per_cell(a, |x, y| {
        cell_corners(a, x, y)
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max)
    })
}

/// Per ground cell: a bound of |grad (A D)| <= A_max |grad D| + |grad A| (|D| <= 1), with A
/// bilinear between the cell's corners.
fn detail_cell_slopes(a: &Grid<f32>, spacing_m: f64) -> Grid<f32> {
    let grad_d = detail_gradient_bound();
    per_cell(a, |x, y| {
        let c = cell_corners(a, x, y);
        let a_max = c.iter().copied().fold(0.0, f64::max);
        let grad_a = bilinear_gradient_bound(&c, spacing_m);
        a_max * grad_d + grad_a
    })
}
