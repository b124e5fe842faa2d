//! Several elevation files imported as one raster (a mosaic, as a GDAL VRT lists its tiles):
//! projected GeoTIFFs, each read on its own ([`crate::geotiff::read`]) and placed by its
//! position in projected metres, or SRTM tiles (`.hgt`), placed by the latitude and longitude
//! in their names and converted to metres at the mosaic's centre latitude as one tile is at its
//! own. The files may come in any order and need not touch. They must share one sample
//! lattice: the same spacing, and every file's samples on the first file's lattice (adjacent
//! tiles that repeat their border row or column, as SRTM tiles do, are fine). Where files
//! overlap, the first file (in the order given) with a sample there keeps it, and the samples
//! where they disagree are counted in the import's note; samples no file covers are voids,
//! filled and counted like a file's own voids.

use crate::dem::{
    DemError, Source, check_size, extension, hgt_latitude, hgt_longitude, hgt_samples,
    hgt_spacing_m,
};
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
    let srtm = extension(&paths[0]).as_deref() == Some("hgt");
    for path in paths {
        let ext = extension(path);
        let ok = if srtm {
            ext.as_deref() == Some("hgt")
        } else {
            matches!(ext.as_deref(), Some("tif" | "tiff"))
        };
        if !ok {
            return Err(refuse(
                path,
                "a mosaic joins files of one kind: GeoTIFF files (.tif, .tiff) or SRTM tiles \
                 (.hgt)"
                    .into(),
            ));
        }
    }
    if srtm {
        read_srtm(paths)
    } else {
        read_geotiffs(paths, spacing_m, vertical_scale)
    }
}

/// SRTM tiles placed by the positions in their names.
fn read_srtm(paths: &[PathBuf]) -> Result<Source, DemError> {
    let mut tiles = Vec::with_capacity(paths.len());
    for path in paths {
        let (Some(lat), Some(lon)) = (hgt_latitude(path), hgt_longitude(path)) else {
            return Err(refuse(
                path,
                "a mosaic places SRTM tiles by their names (e.g. N57E011.hgt), and this name \
                 carries no latitude and longitude"
                    .into(),
            ));
        };
        let (grid, n, arcsec) = hgt_samples(path)?;
        tiles.push((path.as_path(), grid, n, arcsec, [lon, lat]));
    }
    let (first_path, _, n, arcsec, _) = &tiles[0];
    if let Some((path, _, _, other, _)) = tiles.iter().find(|t| t.2 != *n) {
        return Err(refuse(
            path,
            format!(
                "a {other}-arc-second tile; {} is a {arcsec}-arc-second one, and a mosaic joins \
                 tiles of one resolution",
                first_path.display()
            ),
        ));
    }
    let per_degree = (*n - 1) as f64;
    let parts: Vec<Part<'_>> = tiles
        .iter()
        .map(|(path, grid, _, _, at)| Part {
            path,
            grid,
            at: [
                (at[0] * per_degree).round() as i64,
                (at[1] * per_degree).round() as i64,
            ],
        })
        .collect();
    let joined = join(&parts)?;
    // The degrees the tiles cover along an axis (0: longitude, 1: latitude).
    let range = |axis: usize| {
        let starts = tiles.iter().map(|t| t.4[axis]);
        (
            starts.clone().fold(f64::INFINITY, f64::min),
            starts.fold(f64::NEG_INFINITY, f64::max) + 1.0,
        )
    };
    let ((west, east), (south, north)) = (range(0), range(1));
    if south < -85.0 || north > 85.0 {
        return Err(DemError::Latitude {
            path: first_path.to_path_buf(),
            latitude_deg: if south < -85.0 { south } else { north },
        });
    }
    let mut note = format!(
        "mosaic of {} SRTM tiles, {south} to {north} N, {west} to {east} E, degrees to metres \
         at {} N",
        tiles.len(),
        0.5 * (south + north)
    );
    joined.note_disagreements(&mut note);
    Ok(Source {
        grid: joined.grid,
        spacing_m: hgt_spacing_m(*arcsec, 0.5 * (south + north)),
        origin_m: [0.0, 0.0],
        note,
        projected: false,
    })
}

/// Projected GeoTIFFs placed by their positions.
fn read_geotiffs(
    paths: &[PathBuf],
    spacing_m: Option<f64>,
    vertical_scale: f64,
) -> Result<Source, DemError> {
    let mut parts = Vec::with_capacity(paths.len());
    for path in paths {
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
    let placed: Vec<Part<'_>> = parts
        .iter()
        .zip(&offsets)
        .map(|((path, s), &at)| Part {
            path,
            grid: &s.grid,
            at,
        })
        .collect();
    let joined = join(&placed)?;
    let lo = joined.south_west;
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
    joined.note_disagreements(&mut note);
    Ok(Source {
        grid: joined.grid,
        spacing_m: spacing,
        origin_m,
        note,
        projected: true,
    })
}

/// A file's samples and where its south-west sample lies, in samples of the mosaic's lattice.
struct Part<'a> {
    path: &'a Path,
    grid: &'a Grid<f32>,
    at: [i64; 2],
}

/// The joined grid, the lattice position of its south-west sample, and how many samples where
/// files overlap differed.
struct Joined {
    grid: Grid<f32>,
    south_west: [i64; 2],
    disagree: usize,
}

impl Joined {
    fn note_disagreements(&self, note: &mut String) {
        if self.disagree > 0 {
            let _ = write!(
                note,
                "; {} samples where files overlap differ (the first file's are kept)",
                self.disagree
            );
        }
    }
}

/// The parts on one grid covering them all (NaN where none reaches), each sample from the first
/// part that has one there.
fn join(parts: &[Part<'_>]) -> Result<Joined, DemError> {
    let size = |p: &Part<'_>| [p.grid.width() as i64, p.grid.height() as i64];
    let lo = [0, 1].map(|a| parts.iter().map(|p| p.at[a]).min().unwrap_or(0));
    let hi = [0, 1].map(|a| {
        parts
            .iter()
            .map(|p| p.at[a] + size(p)[a] - 1)
            .max()
            .unwrap_or(0)
    });
    let (w, h) = ((hi[0] - lo[0] + 1) as u64, (hi[1] - lo[1] + 1) as u64);
    check_size(parts[0].path, w, h)?;
    let mut grid = Grid::new(w as usize, h as usize, f32::NAN);
    let mut disagree = 0usize;
    for p in parts {
        let (x0, y0) = ((p.at[0] - lo[0]) as usize, (p.at[1] - lo[1]) as usize);
        for y in 0..p.grid.height() {
            for x in 0..p.grid.width() {
                let v = p.grid.get(x, y);
                let kept = grid.get(x0 + x, y0 + y);
                if kept.is_nan() {
                    grid.set(x0 + x, y0 + y, v);
                } else if !v.is_nan() && v != kept {
                    disagree += 1;
                }
            }
        }
    }
    Ok(Joined {
        grid,
        south_west: lo,
        disagree,
    })
}
