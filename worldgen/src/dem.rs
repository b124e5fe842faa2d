//! Importing real elevation data into a map: GeoTIFF (see [`crate::geotiff`]), SRTM `.hgt` (1201²
//! or 3601² big-endian i16, -32768 = void), 16-bit (or 8-bit) grayscale PNG with a vertical scale,
//! and single-channel EXR (NaN = void). Voids are filled from valid neighbours, layer by layer inwards; the source is resampled
//! (bicubic) onto a square grid and ground types, densities and trees are derived as for
//! generated maps.

use crate::Grid;
use crate::classify::{self, GroundRules};
use crate::generate::{self, AssembleInputs, GenerateError};
use crate::map::{Map, limits};
use crate::par;
use crate::progress::{StepTime, timed};
use crate::sample::{self, GridPlacement};
use std::path::{Path, PathBuf};

/// The spacing of the engine's finest node meshes (8 m leaves of 32 quads); every node's mesh
/// spacing is this times a power of two. `engine::terrain::quadtree` checks that it agrees.
pub const NODE_SPACING_BASE_M: f64 = 0.25;

/// The sample spacing an import resamples to: the largest [`NODE_SPACING_BASE_M`] times a power
/// of two (of any sign) that is at most `finest_m`, the finer source spacing. On that lattice
/// the engine's node meshes line up with the map's samples and read their bounds from the
/// map-error grids computed once per map; at another spacing (the 49.76 m of a 3 arc-second
/// SRTM tile at 57 N) every node measures its own at run time (there: bounds 47x and node
/// preparation 20x slower at the median).
pub fn import_spacing_m(finest_m: f64) -> f64 {
    let k = (finest_m / NODE_SPACING_BASE_M).log2().floor();
    let s = NODE_SPACING_BASE_M * k.exp2();
    // log2 of an exact power of two may round down by one step.
    if 2.0 * s <= finest_m { 2.0 * s } else { s }
}

/// How to import.
#[derive(Debug, Clone)]
pub struct ImportParams {
    pub path: PathBuf,
    /// Further files joined with `path` into one raster (a mosaic of projected GeoTIFFs or of
    /// SRTM tiles; see [`crate::mosaic`]); empty for one file.
    pub mosaic: Vec<PathBuf>,
    pub name: String,
    /// Sample spacing of the source (m); required for PNG and EXR, derived for `.hgt`.
    pub spacing_m: Option<f64>,
    /// Metres per PNG unit (e.g. 0.1 for the Puget Sound height field).
    pub vertical_scale_m: f64,
    /// Latitude of the tile's south edge for `.hgt` when the file name does not carry it.
    pub latitude_deg: Option<f64>,
    pub water_level_m: f64,
    pub snow_line_m: f64,
    pub threads: usize,
}

impl ImportParams {
    /// Defaults for `path`: spacing from the file (`.hgt`) or required (`--spacing-m`), 1 m per
    /// PNG unit, sea level at 0 m, snow from 1800 m, all cores.
    pub fn new(path: PathBuf) -> Self {
        let name = path
            .file_stem()
            .map_or_else(|| "dem".into(), |n| n.to_string_lossy().into_owned());
        Self {
            path,
            mosaic: Vec::new(),
            name,
            spacing_m: None,
            vertical_scale_m: 1.0,
            latitude_deg: None,
            water_level_m: 0.0,
            snow_line_m: 1800.0,
            threads: 0,
        }
    }
}

/// What the import found.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportReport {
    pub source_samples: [usize; 2],
    pub source_spacing_m: [f64; 2],
    pub voids_filled: usize,
    pub spacing_m: f64,
    /// The map's origin: the south-west sample in projected metres (0 when the source has no
    /// projected position).
    pub origin_m: [f64; 2],
    /// How the source was placed, in words (empty for formats without georeferencing).
    pub georeference: String,
}

/// Why an import failed; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum DemError {
    #[error("{path}: cannot read: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(
        "{path}: unknown elevation format; expected .tif/.tiff (GeoTIFF), .hgt (SRTM), .png \
         (16-bit grayscale) or .exr"
    )]
    UnknownFormat { path: PathBuf },
    #[error(
        "{path}: {len} bytes is not an SRTM tile (1201x1201 or 3601x3601 big-endian int16 = 2884802 or 25934402 bytes)"
    )]
    HgtSize { path: PathBuf, len: u64 },
    #[error(
        "{path}: cannot tell the latitude from the file name (expected e.g. N57E011.hgt); pass --latitude-deg"
    )]
    HgtLatitude { path: PathBuf },
    #[error(
        "{path}: latitude {latitude_deg} degrees is out of range; --latitude-deg must be a finite \
         number between -85 and 85 (metres per degree of longitude vanish at the poles)"
    )]
    Latitude { path: PathBuf, latitude_deg: f64 },
    #[error("{path}: {what} needs --spacing-m (the distance between samples in metres)")]
    NeedSpacing { path: PathBuf, what: &'static str },
    #[error("{path}: {message}")]
    BadFile { path: PathBuf, message: String },
    #[error("{path}: {width}x{height} samples exceeds the limit of {max} per side")]
    TooLarge {
        path: PathBuf,
        width: u64,
        height: u64,
        max: u32,
    },
    #[error("{path}: {tag}: {message}")]
    Unsupported {
        path: PathBuf,
        tag: &'static str,
        message: String,
    },
    #[error("{path}: every sample is void; nothing to import")]
    AllVoid { path: PathBuf },
    #[error("{path}: invalid parameter: {message}")]
    BadParam { path: PathBuf, message: String },
    #[error(transparent)]
    Generate(#[from] GenerateError),
}

/// A source grid (row 0 = south) with NaN marking voids, its anisotropic spacing, the position of
/// its south-west sample and how that was found.
pub struct Source {
    pub grid: Grid<f32>,
    pub spacing_m: [f64; 2],
    pub origin_m: [f64; 2],
    pub note: String,
    /// Whether `origin_m` is the file's own position in projected metres (a GeoTIFF in a
    /// projected CRS), so that several files can be joined by it.
    pub projected: bool,
}

pub(crate) fn check_size(path: &Path, w: u64, h: u64) -> Result<(), DemError> {
    let max = limits::MAX_GRID_SIDE;
    if w > u64::from(max) || h > u64::from(max) || w < 2 || h < 2 {
        return Err(DemError::TooLarge {
            path: path.to_path_buf(),
            width: w,
            height: h,
            max,
        });
    }
    Ok(())
}

/// An SRTM name's position, `N57E011` / `S12W077`: (sign and digits of the latitude, and the
/// rest of the name after them).
fn hgt_name(path: &Path) -> Option<(f64, &str)> {
    let stem = path.file_stem()?.to_str()?;
    let sign = match stem.chars().next()? {
        'N' | 'n' => 1.0,
        'S' | 's' => -1.0,
        _ => return None,
    };
    let digits = stem[1..].chars().take_while(char::is_ascii_digit).count();
    let lat: f64 = stem[1..=digits].parse().ok()?;
    (lat <= 90.0).then_some((sign * lat, &stem[1 + digits..]))
}

/// Latitude of the south edge from an SRTM name like `N57E011.hgt` / `S12W077.hgt`.
pub(crate) fn hgt_latitude(path: &Path) -> Option<f64> {
    hgt_name(path).map(|(lat, _)| lat)
}

/// Longitude of the west edge from an SRTM name like `N57E011.hgt` / `S12W077.hgt`: the letter
/// right after the latitude's digits, then the longitude's digits.
pub(crate) fn hgt_longitude(path: &Path) -> Option<f64> {
    let (_, rest) = hgt_name(path)?;
    let sign = match rest.chars().next()? {
        'E' | 'e' => 1.0,
        'W' | 'w' => -1.0,
        _ => return None,
    };
    let digits = rest[1..].chars().take_while(char::is_ascii_digit).count();
    let lon: f64 = rest[1..=digits].parse().ok()?;
    (lon <= 180.0).then_some(sign * lon)
}

/// A file's extension in lower case.
pub(crate) fn extension(path: &Path) -> Option<String> {
    path.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
}

/// An SRTM tile's samples (row 0 = south, void = NaN), samples per side and arc-seconds per
/// sample.
pub(crate) fn hgt_samples(path: &Path) -> Result<(Grid<f32>, usize, f64), DemError> {
    let len = std::fs::metadata(path)
        .map_err(|e| DemError::Io {
            path: path.to_path_buf(),
            source: e,
        })?
        .len();
    let (n, arcsec) = match len {
        2_884_802 => (1201usize, 3.0),
        25_934_402 => (3601usize, 1.0),
        _ => {
            return Err(DemError::HgtSize {
                path: path.to_path_buf(),
                len,
            });
        }
    };
    let bytes = std::fs::read(path).map_err(|e| DemError::Io {
        path: path.to_path_buf(),
        source: e,
    })?;
    let north_up: Vec<f32> = bytes
        .chunks_exact(2)
        .map(|b| {
            let v = i16::from_be_bytes([b[0], b[1]]);
            if v == i16::MIN {
                f32::NAN
            } else {
                f32::from(v)
            }
        })
        .collect();
    let grid = Grid::from_north_up(n, n, &north_up).ok_or_else(|| DemError::HgtSize {
        path: path.to_path_buf(),
        len,
    })?;
    Ok((grid, n, arcsec))
}

/// Metres between SRTM samples of `arcsec` arc-seconds around latitude `lat_centre_deg`: 1
/// arc-second of latitude is about 30.87 m; longitude shrinks with its cosine.
pub(crate) fn hgt_spacing_m(arcsec: f64, lat_centre_deg: f64) -> [f64; 2] {
    let dy = arcsec * 30.87;
    [dy * lat_centre_deg.to_radians().cos(), dy]
}

fn read_hgt(p: &ImportParams) -> Result<Source, DemError> {
    let path = &p.path;
    let (grid, _, arcsec) = hgt_samples(path)?;
    let lat = p
        .latitude_deg
        .or_else(|| hgt_latitude(path))
        .ok_or_else(|| DemError::HgtLatitude { path: path.clone() })?;
    if !(lat.is_finite() && lat.abs() <= 85.0) {
        return Err(DemError::Latitude {
            path: path.clone(),
            latitude_deg: lat,
        });
    }
    Ok(Source {
        grid,
        spacing_m: hgt_spacing_m(arcsec, lat + 0.5),
        origin_m: [0.0, 0.0],
        note: format!("SRTM tile, south edge at {lat} N"),
        projected: false,
    })
}

fn read_png(p: &ImportParams) -> Result<Source, DemError> {
    let path = &p.path;
    let spacing = p.spacing_m.ok_or_else(|| DemError::NeedSpacing {
        path: path.clone(),
        what: "a PNG height field",
    })?;
    let bad = |m: String| DemError::BadFile {
        path: path.clone(),
        message: m,
    };
    let file = std::fs::File::open(path).map_err(|e| DemError::Io {
        path: path.clone(),
        source: e,
    })?;
    let mut dec = png::Decoder::new(std::io::BufReader::new(file));
    dec.set_transformations(png::Transformations::IDENTITY);
    dec.set_limits(png::Limits {
        bytes: (limits::MAX_GRID_SIDE as usize).pow(2) * 2,
    });
    let mut reader = dec
        .read_info()
        .map_err(|e| bad(format!("not a valid PNG: {e}")))?;
    let (w, h, ct, depth) = {
        let i = reader.info();
        (i.width, i.height, i.color_type, i.bit_depth)
    };
    check_size(path, w.into(), h.into())?;
    if ct != png::ColorType::Grayscale
        || !matches!(depth, png::BitDepth::Sixteen | png::BitDepth::Eight)
    {
        return Err(bad(format!(
            "is {ct:?} {}-bit; expected 8- or 16-bit grayscale",
            depth as u8
        )));
    }
    let mut buf = vec![
        0u8;
        reader
            .output_buffer_size()
            .ok_or_else(|| bad("too large".into()))?
    ];
    reader
        .next_frame(&mut buf)
        .map_err(|e| bad(format!("cannot decode: {e}")))?;
    let (w, h) = (w as usize, h as usize);
    let scale = p.vertical_scale_m as f32;
    let vals: Vec<f32> = if depth == png::BitDepth::Sixteen {
        buf.chunks_exact(2)
            .take(w * h)
            .map(|b| f32::from(u16::from_be_bytes([b[0], b[1]])) * scale)
            .collect()
    } else {
        buf.iter()
            .take(w * h)
            .map(|&b| f32::from(b) * scale)
            .collect()
    };
    let grid = Grid::from_north_up(w, h, &vals)
        .ok_or_else(|| bad("decoded fewer samples than the header says".into()))?;
    Ok(Source {
        grid,
        spacing_m: [spacing, spacing],
        origin_m: [0.0, 0.0],
        note: String::new(),
        projected: false,
    })
}

fn read_exr(p: &ImportParams) -> Result<Source, DemError> {
    use exr::prelude::*;
    let path = &p.path;
    let spacing = p.spacing_m.ok_or_else(|| DemError::NeedSpacing {
        path: path.clone(),
        what: "an EXR height field",
    })?;
    let bad = |m: String| DemError::BadFile {
        path: path.clone(),
        message: m,
    };
    let meta = MetaData::read_from_file(path, false)
        .map_err(|e| bad(format!("not a valid OpenEXR file: {e}")))?;
    let header = meta
        .headers
        .first()
        .ok_or_else(|| bad("has no layers".into()))?;
    check_size(path, header.layer_size.0 as u64, header.layer_size.1 as u64)?;
    if header.channels.list.len() != 1 {
        return Err(bad(format!(
            "has {} channels; expected one height channel",
            header.channels.list.len()
        )));
    }
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .non_parallel()
        .from_file(path)
        .map_err(|e| bad(format!("cannot decode: {e}")))?;
    let size = image.layer_data.size;
    let vals: Vec<f32> = image.layer_data.channel_data.list[0]
        .sample_data
        .values_as_f32()
        .collect();
    let grid = Grid::from_north_up(size.0, size.1, &vals)
        .ok_or_else(|| bad("sample count mismatch".into()))?;
    Ok(Source {
        grid,
        spacing_m: [spacing, spacing],
        origin_m: [0.0, 0.0],
        note: String::new(),
        projected: false,
    })
}

/// Fills NaN samples from valid 8-neighbours, one ring of voids at a time (each ring reads only
/// values valid before it), and returns the number filled. None when every sample is void.
pub fn fill_voids(grid: &mut Grid<f32>) -> Option<usize> {
    let (w, h) = (grid.width(), grid.height());
    let voids = grid.data().iter().filter(|v| v.is_nan()).count();
    if voids == grid.data().len() {
        return None;
    }
    let neighbours = |i: usize| {
        let (x, y) = ((i % w) as i64, (i / w) as i64);
        [
            (-1i64, -1i64),
            (0, -1),
            (1, -1),
            (-1, 0),
            (1, 0),
            (-1, 1),
            (0, 1),
            (1, 1),
        ]
        .into_iter()
        .map(move |(dx, dy)| (x + dx, y + dy))
        .filter(move |&(nx, ny)| nx >= 0 && ny >= 0 && nx < w as i64 && ny < h as i64)
        .map(move |(nx, ny)| ny as usize * w + nx as usize)
    };
    let mut frontier: Vec<usize> = (0..w * h)
        .filter(|&i| grid.data()[i].is_nan() && neighbours(i).any(|j| !grid.data()[j].is_nan()))
        .collect();
    while !frontier.is_empty() {
        let values: Vec<f32> = frontier
            .iter()
            .map(|&i| {
                let (sum, n) = neighbours(i)
                    .map(|j| grid.data()[j])
                    .filter(|v| !v.is_nan())
                    .fold((0.0f64, 0u32), |(s, n), v| (s + f64::from(v), n + 1));
                (sum / f64::from(n.max(1))) as f32
            })
            .collect();
        for (&i, &v) in frontier.iter().zip(&values) {
            grid.data_mut()[i] = v;
        }
        let mut next: Vec<usize> = frontier
            .iter()
            .flat_map(|&i| neighbours(i))
            .filter(|&j| grid.data()[j].is_nan())
            .collect();
        next.sort_unstable();
        next.dedup();
        frontier = next;
    }
    Some(voids)
}

/// Imports an elevation file into a map (in memory).
pub fn import(
    p: &ImportParams,
    times: &mut Vec<StepTime>,
) -> Result<(Map, ImportReport), DemError> {
    let path = &p.path;
    if !(p.vertical_scale_m.is_finite() && p.vertical_scale_m > 0.0) {
        return Err(DemError::BadParam {
            path: path.clone(),
            message: format!("--vertical-scale-m {} must be positive", p.vertical_scale_m),
        });
    }
    if let Some(s) = p.spacing_m
        && !(s.is_finite() && s >= limits::MIN_SPACING_M)
    {
        return Err(DemError::BadParam {
            path: path.clone(),
            message: format!(
                "--spacing-m {s} must be at least {} m",
                limits::MIN_SPACING_M
            ),
        });
    }
    let ext = extension(path);
    if p.latitude_deg.is_some() && !p.mosaic.is_empty() {
        return Err(DemError::BadParam {
            path: path.clone(),
            message: "--latitude-deg places one .hgt tile whose name lacks its position; a \
                      mosaic places its tiles by their names"
                .into(),
        });
    }
    let mut src = if p.mosaic.is_empty() {
        timed(times, "read elevation file", || match ext.as_deref() {
            Some("tif" | "tiff") => crate::geotiff::read(path, p.spacing_m, p.vertical_scale_m),
            Some("hgt") => read_hgt(p),
            Some("png") => read_png(p),
            Some("exr") => read_exr(p),
            _ => Err(DemError::UnknownFormat { path: path.clone() }),
        })?
    } else {
        let paths: Vec<PathBuf> = std::iter::once(path.clone())
            .chain(p.mosaic.iter().cloned())
            .collect();
        timed(times, "read and join the elevation files", || {
            crate::mosaic::read(&paths, p.spacing_m, p.vertical_scale_m)
        })?
    };
    if let Some(v) = src
        .grid
        .data()
        .iter()
        .find(|v| v.is_finite() && v.abs() > limits::MAX_ABS_HEIGHT_M)
    {
        return Err(DemError::BadFile {
            path: path.clone(),
            message: format!("height {v} m is beyond ±{} m", limits::MAX_ABS_HEIGHT_M),
        });
    }
    for v in src.grid.data_mut() {
        if v.is_infinite() {
            *v = f32::NAN;
        }
    }
    let voids = timed(times, "fill voids", || fill_voids(&mut src.grid))
        .ok_or_else(|| DemError::AllVoid { path: path.clone() })?;
    // Resample to a square grid on the engine's lattice, at least as fine as the finer of the
    // two source spacings.
    let (sw, sh) = (src.grid.width(), src.grid.height());
    let spacing = import_spacing_m(src.spacing_m[0].min(src.spacing_m[1]));
    let nx = ((sw - 1) as f64 * src.spacing_m[0] / spacing).round() as usize + 1;
    let ny = ((sh - 1) as f64 * src.spacing_m[1] / spacing).round() as usize + 1;
    check_size(path, nx as u64, ny as u64)?;
    let size_m = [(nx - 1) as f64 * spacing, (ny - 1) as f64 * spacing];
    let threads = par::thread_count(p.threads);
    let heights = timed(times, "resample to a square grid", || {
        if nx == sw && ny == sh {
            return src.grid.clone();
        }
        let unit = GridPlacement {
            origin_m: [0.0, 0.0],
            spacing_m: 1.0,
        };
        let (fx, fy) = (
            (sw - 1) as f64 / (nx - 1) as f64,
            (sh - 1) as f64 / (ny - 1) as f64,
        );
        let mut g = Grid::new(nx, ny, 0.0f32);
        par::for_each_row(
            g.data_mut(),
            nx,
            threads,
            |y, row| {
                for (x, v) in row.iter_mut().enumerate() {
                    *v = sample::bicubic_limited(&src.grid, unit, x as f64 * fx, y as f64 * fy)
                        as f32;
                }
            },
            &|_| {},
        );
        g
    });
    let (slope, moisture) = timed(times, "slope and moisture", || {
        let s = classify::slope(&heights, spacing, threads);
        let m = classify::moisture(0, &heights, None, spacing, p.water_level_m, threads);
        (s, m)
    });
    let rules = GroundRules {
        water_level_m: p.water_level_m,
        snow_line_m: p.snow_line_m,
    };
    let ground = timed(times, "ground types", || {
        classify::ground_types(&heights, &slope, &moisture, rules)
    });
    let map = generate::assemble(AssembleInputs {
        name: p.name.clone(),
        seed: 0,
        size_m,
        origin_m: src.origin_m,
        water_level_m: p.water_level_m,
        snow_line_m: p.snow_line_m,
        heights,
        spacing_m: spacing,
        ground,
        slope,
        moisture,
        decals: Vec::new(),
        buildings: Vec::new(),
        building_models: Vec::new(),
        building_textures: Vec::new(),
        times,
    })?;
    let report = ImportReport {
        source_samples: [sw, sh],
        source_spacing_m: src.spacing_m,
        voids_filled: voids,
        spacing_m: spacing,
        origin_m: src.origin_m,
        georeference: src.note,
    };
    Ok((map, report))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn void_filling_reaches_every_void_and_keeps_valid_samples() {
        let mut g = Grid::new(5, 4, f32::NAN);
        g.set(0, 0, 10.0);
        g.set(4, 3, 20.0);
        let filled = fill_voids(&mut g).unwrap();
        assert_eq!(filled, 18);
        assert!(
            g.data()
                .iter()
                .all(|v| v.is_finite() && (10.0..=20.0).contains(v))
        );
        assert_eq!(g.get(0, 0), 10.0);
        assert_eq!(g.get(4, 3), 20.0);
        let mut all_void = Grid::new(3, 3, f32::NAN);
        assert_eq!(fill_voids(&mut all_void), None);
    }

    #[test]
    fn latitude_comes_from_srtm_names() {
        assert_eq!(hgt_latitude(Path::new("x/N57E011.hgt")), Some(57.0));
        assert_eq!(hgt_latitude(Path::new("S12W077.hgt")), Some(-12.0));
        assert_eq!(hgt_latitude(Path::new("tile.hgt")), None);
    }

    #[test]
    fn longitude_comes_from_srtm_names() {
        assert_eq!(hgt_longitude(Path::new("x/N57E011.hgt")), Some(11.0));
        assert_eq!(hgt_longitude(Path::new("S12W077.hgt")), Some(-77.0));
        assert_eq!(hgt_longitude(Path::new("n05e123.hgt")), Some(123.0));
        // The letter must follow the latitude: "tile" has an "e" but no position.
        assert_eq!(hgt_longitude(Path::new("tile.hgt")), None);
        assert_eq!(hgt_longitude(Path::new("N57X011.hgt")), None);
        assert_eq!(hgt_longitude(Path::new("N57E.hgt")), None);
        assert_eq!(hgt_longitude(Path::new("N57E181.hgt")), None);
    }
}
