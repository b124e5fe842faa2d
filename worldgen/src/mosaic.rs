//! Several GeoTIFF files imported as one raster (a mosaic, as a GDAL VRT lists its tiles): each
//! file is read on its own ([`crate::geotiff::read`]) and placed by its own position in
//! projected metres, so the files may come in any order and need not touch. They must share
//! one sample lattice: the same spacing, and every file's samples on the first file's lattice
//! (adjacent tiles that repeat their border row or column, as SRTM tiles do, are fine). Where
//! files overlap, the first file (in the order given) with a sample there keeps it, and the
//! samples where they disagree are counted in the import's note; samples no file covers are
//! voids, filled and counted like a file's own voids.

use crate::dem::{DemError, Source, check_size};
use crate::grid::Grid;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// How far (in samples) a file's position may lie off the first file's lattice and still be
/// taken as on it: f64 positions of a few hundred km carry about 1e-10 m of rounding.
const LATTICE_TOLERANCE: f64 = 1e-6;

fn refuse(path: &Path, message: String) -> DemError {
    DemError::BadParam {
        path: path.to_path_buf(),
        message,
    }
}

/// The mosaic of `paths` (at least one): one source grid covering every file, row 0 south.
pub(crate) fn read(
    paths: &[PathBuf],
    spacing_m: Option<f64>,
    vertical_scale: f64,
) -> Result<Source, DemError> {
    let mut parts = Vec::with_capacity(paths.len());
    for path in paths {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        if !matches!(ext.as_deref(), Some("tif" | "tiff")) {
            return Err(refuse(
                path,
                "a mosaic joins GeoTIFF files (.tif, .tiff) only".into(),
            ));
        }
        let s = crate::geotiff::read(path, spacing_m, vertical_scale)?;
        if !s.projected {
            return Err(refuse(
                path,
                format!(
                    "a mosaic places each file by its position in projected metres, and this \
                     one has none ({})",
                    s.note
                ),
            ));
        }
        parts.push((path.as_path(), s));
    }
    let (first_path, first) = &parts[0];
    let spacing = first.spacing_m;
    // Each file's south-west sample, in samples of the first file's lattice.
    let mut offsets = Vec::with_capacity(parts.len());
    for (path, s) in &parts {
        for axis in 0..2 {
            if (s.spacing_m[axis] - spacing[axis]).abs() > 1e-9 * spacing[axis] {
                return Err(refuse(
                    path,
                    format!(
                        "sample spacing {:?} m differs from {}'s {:?} m; a mosaic joins files \
                         of one sample lattice",
                        s.spacing_m,
                        first_path.display(),
                        spacing
                    ),
                ));
            }
        }
        let at = [
            (s.origin_m[0] - first.origin_m[0]) / spacing[0],
            (s.origin_m[1] - first.origin_m[1]) / spacing[1],
        ];
        if at.iter().any(|v| (v - v.round()).abs() > LATTICE_TOLERANCE) {
            return Err(refuse(
                path,
                format!(
                    "its south-west sample at ({:.3}, {:.3}) m is not on {}'s sample lattice \
                     (off by ({:.3}, {:.3}) samples)",
                    s.origin_m[0],
                    s.origin_m[1],
                    first_path.display(),
                    at[0] - at[0].round(),
                    at[1] - at[1].round()
                ),
            ));
        }
        offsets.push([at[0].round() as i64, at[1].round() as i64]);
    }
    let size = |s: &Source| [s.grid.width() as i64, s.grid.height() as i64];
    let lo = [0, 1].map(|a| offsets.iter().map(|o| o[a]).min().unwrap_or(0));
    let hi = [0, 1].map(|a| {
        parts
            .iter()
            .zip(&offsets)
            .map(|((_, s), o)| o[a] + size(s)[a] - 1)
            .max()
            .unwrap_or(0)
    });
    let (w, h) = ((hi[0] - lo[0] + 1) as u64, (hi[1] - lo[1] + 1) as u64);
    check_size(first_path, w, h)?;
    let mut grid = Grid::new(w as usize, h as usize, f32::NAN);
    let mut disagree = 0usize;
    for ((_, s), o) in parts.iter().zip(&offsets) {
        let (x0, y0) = ((o[0] - lo[0]) as usize, (o[1] - lo[1]) as usize);
        for y in 0..s.grid.height() {
            for x in 0..s.grid.width() {
                let v = s.grid.get(x, y);
                let kept = grid.get(x0 + x, y0 + y);
                if kept.is_nan() {
                    grid.set(x0 + x, y0 + y, v);
                } else if !v.is_nan() && v != kept {
                    disagree += 1;
                }
            }
        }
    }
    let origin_m = [
        first.origin_m[0] + lo[0] as f64 * spacing[0],
        first.origin_m[1] + lo[1] as f64 * spacing[1],
    ];
    let mut note = format!(
        "mosaic of {} GeoTIFFs on {}'s lattice, south-west sample at ({:.2}, {:.2}) m",
        parts.len(),
        first_path.display(),
        origin_m[0],
        origin_m[1]
    );
    if disagree > 0 {
        let _ = write!(
            note,
            "; {disagree} samples where files overlap differ (the first file's are kept)"
        );
    }
    Ok(Source {
        grid,
        spacing_m: spacing,
        origin_m,
        note,
        projected: true,
    })
}
