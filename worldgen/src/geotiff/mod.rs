//! GeoTIFF elevation rasters for `import-dem`, decoded with the `tiff` crate (strips or tiles;
//! uncompressed, LZW, Deflate or PackBits; 8/16/32-bit integer or 32/64-bit float samples).
//!
//! Georeferencing comes from ModelPixelScale + ModelTiepoint or from a ModelTransformation
//! without rotation; units from the GeoKeyDirectory (projected metres or feet, geographic degrees
//! converted to metres on the WGS84 ellipsoid at the raster's centre latitude). GDAL's nodata tag
//! marks voids. Whatever cannot be read faithfully (several bands, rotation, other compressions,
//! control-point rasters, geocentric models, unknown units) is refused with the tag that says so.

mod ifd_sizes;

use crate::Grid;
use crate::dem::{DemError, Source, check_size};
use crate::map::limits;
use std::io::{BufReader, Seek};
use std::path::Path;
use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::tags::Tag;

/// GeoKey ids (GeoTIFF 1.1, section 7) read here.
mod key {
    pub const MODEL_TYPE: u16 = 1024;
    pub const RASTER_TYPE: u16 = 1025;
    pub const GEOG_ANGULAR_UNITS: u16 = 2054;
    pub const PROJ_LINEAR_UNITS: u16 = 3076;
    pub const VERTICAL_UNITS: u16 = 4099;
}

/// Metres per degree of latitude and of longitude at `lat_deg` on the WGS84 ellipsoid (from the
/// meridional and prime-vertical radii of curvature).
pub fn metres_per_degree(lat_deg: f64) -> [f64; 2] {
    const A_M: f64 = 6_378_137.0;
    const E2: f64 = 0.006_694_379_990_14;
    let phi = lat_deg.to_radians();
    let w = 1.0 - E2 * phi.sin().powi(2);
    let meridional_m = A_M * (1.0 - E2) / w.powf(1.5);
    let prime_vertical_m = A_M / w.sqrt();
    let per_rad = std::f64::consts::PI / 180.0;
    [
        meridional_m * per_rad,
        prime_vertical_m * phi.cos() * per_rad,
    ]
}

/// The raster's pixel-to-model transform without rotation: model x = `x0 + col * dx`, model
/// y = `y0 + row * dy` at a pixel's corner (dy < 0 for the usual north-up raster).
#[derive(Debug, Clone, Copy)]
struct Affine {
    x0: f64,
    y0: f64,
    dx: f64,
    dy: f64,
}

fn bad(path: &Path, message: String) -> DemError {
    DemError::BadFile {
        path: path.to_path_buf(),
        message,
    }
}

fn unsupported(path: &Path, tag: &'static str, message: String) -> DemError {
    DemError::Unsupported {
        path: path.to_path_buf(),
        tag,
        message,
    }
}

type Dec = Decoder<BufReader<std::fs::File>>;

fn tag_f64s(
    path: &Path,
    dec: &mut Dec,
    tag: Tag,
    name: &str,
) -> Result<Option<Vec<f64>>, DemError> {
    dec.find_tag(tag)
        .and_then(|v| v.map(tiff::decoder::ifd::Value::into_f64_vec).transpose())
        .map_err(|e| bad(path, format!("{name}: cannot read: {e}")))
}

fn tag_u16(path: &Path, dec: &mut Dec, tag: Tag, name: &str) -> Result<Option<u16>, DemError> {
    dec.find_tag_unsigned::<u16>(tag)
        .map_err(|e| bad(path, format!("{name}: cannot read: {e}")))
}

fn compression_name(code: u16) -> &'static str {
    match code {
        2 => "CCITT Huffman",
        3 => "CCITT Group 3 fax",
        4 => "CCITT Group 4 fax",
        6 => "old-style JPEG",
        7 => "JPEG",
        34887 => "LERC",
        34925 => "LZMA",
        50000 => "Zstandard",
        50001 => "WebP",
        _ => "unknown",
    }
}

/// The layout the elevation reader accepted: its compression code and bits per sample.
struct Layout {
    compression: u16,
    bits: u16,
}

/// Checks the layout tags the elevation reader depends on: one band, a supported compression
/// and sample type.
fn check_layout(path: &Path, dec: &mut Dec) -> Result<Layout, DemError> {
    let bands = tag_u16(path, dec, Tag::SamplesPerPixel, "SamplesPerPixel (277)")?.unwrap_or(1);
    if bands != 1 {
        return Err(unsupported(
            path,
            "SamplesPerPixel (277)",
            format!(
                "is {bands}: a multi-band raster; import-dem reads one elevation band (extract \
                 it first, e.g. gdal_translate -b 1)"
            ),
        ));
    }
    let compression = tag_u16(path, dec, Tag::Compression, "Compression (259)")?.unwrap_or(1);
    if !matches!(compression, 1 | 5 | 8 | 32946 | 32773) {
        return Err(unsupported(
            path,
            "Compression (259)",
            format!(
                "is {compression} ({}); supported: 1 none, 5 LZW, 8 Deflate, 32773 PackBits",
                compression_name(compression)
            ),
        ));
    }
    let bits = tag_u16(path, dec, Tag::BitsPerSample, "BitsPerSample (258)")?.unwrap_or(1);
    let format = tag_u16(path, dec, Tag::SampleFormat, "SampleFormat (339)")?.unwrap_or(1);
    let ok = match format {
        1 | 2 => matches!(bits, 8 | 16 | 32),
        3 => matches!(bits, 32 | 64),
        _ => false,
    };
    if !ok {
        let kind = match format {
            1 => "unsigned integer",
            2 => "signed integer",
            3 => "float",
            _ => "unknown format",
        };
        return Err(unsupported(
            path,
            "BitsPerSample (258) / SampleFormat (339)",
            format!(
                "{bits}-bit {kind} samples (SampleFormat {format}); supported: 8/16/32-bit \
                 integers and 32/64-bit floats"
            ),
        ));
    }
    Ok(Layout { compression, bits })
}

/// Checks, before the raster is allocated, that every strip or tile lies inside the file and
/// that together they hold enough bytes for `samples` samples even at the compression's highest
/// ratio (PackBits 64:1, Deflate 1032:1, LZW 4096:1): a damaged header cannot make the reader
/// allocate a raster the file could never fill.
fn check_data_size(
    path: &Path,
    dec: &mut Dec,
    layout: &Layout,
    file_len: u64,
    samples: u64,
) -> Result<(), DemError> {
    let tiled = dec
        .find_tag(Tag::TileOffsets)
        .map_err(|e| bad(path, format!("TileOffsets (324): cannot read: {e}")))?
        .is_some();
    let (offsets_tag, counts_tag, names) = if tiled {
        (
            Tag::TileOffsets,
            Tag::TileByteCounts,
            ("TileOffsets (324)", "TileByteCounts (325)"),
        )
    } else {
        (
            Tag::StripOffsets,
            Tag::StripByteCounts,
            ("StripOffsets (273)", "StripByteCounts (279)"),
        )
    };
    let read = |dec: &mut Dec, tag, name| {
        dec.find_tag(tag)
            .and_then(|v| v.map(tiff::decoder::ifd::Value::into_u64_vec).transpose())
            .map_err(|e| bad(path, format!("{name}: cannot read: {e}")))?
            .ok_or_else(|| bad(path, format!("{name} is missing")))
    };
    let offsets = read(dec, offsets_tag, names.0)?;
    let counts = read(dec, counts_tag, names.1)?;
    if offsets.len() != counts.len() {
        return Err(bad(
            path,
            format!(
                "{} lists {} chunks but {} lists {}",
                names.0,
                offsets.len(),
                names.1,
                counts.len()
            ),
        ));
    }
    let mut total = 0u64;
    for (i, (&o, &c)) in offsets.iter().zip(&counts).enumerate() {
        if o.checked_add(c).is_none_or(|end| end > file_len) {
            return Err(bad(
                path,
                format!(
                    "{}: chunk {i} ({c} bytes at {o}) reaches past the end of the {file_len}-byte \
                     file (truncated?)",
                    names.1
                ),
            ));
        }
        total += c;
    }
    let ratio: u64 = match layout.compression {
        32773 => 64,
        8 | 32946 => 1032,
        5 => 4096,
        _ => 1,
    };
    let bits = layout.bits;
    let needed = samples * u64::from(bits / 8).max(1);
    if total.saturating_mul(ratio) < needed {
        return Err(bad(
            path,
            format!(
                "{}: the chunks hold {total} bytes, too few for {samples} samples of {bits} bits \
                 ({needed} bytes) even at the compression's highest ratio {ratio}:1 (truncated?)",
                names.1
            ),
        ));
    }
    Ok(())
}

/// The pixel-to-model transform from ModelTransformation or ModelPixelScale + ModelTiepoint.
fn read_affine(path: &Path, dec: &mut Dec) -> Result<Option<Affine>, DemError> {
    const TRANSFORM: &str = "ModelTransformationTag (34264)";
    const SCALE: &str = "ModelPixelScaleTag (33550)";
    const TIES: &str = "ModelTiepointTag (33922)";
    let transform = tag_f64s(path, dec, Tag::ModelTransformationTag, TRANSFORM)?;
    let scale = tag_f64s(path, dec, Tag::ModelPixelScaleTag, SCALE)?;
    let ties = tag_f64s(path, dec, Tag::ModelTiepointTag, TIES)?;
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    if let Some(m) = transform {
        if m.len() != 16 || !finite(&m) {
            return Err(bad(
                path,
                format!("{TRANSFORM}: expected 16 finite numbers, found {}", m.len()),
            ));
        }
        if m[1] != 0.0 || m[4] != 0.0 {
            return Err(unsupported(
                path,
                TRANSFORM,
                format!(
                    "the raster is rotated or sheared (terms {} and {}); import-dem needs a \
                     north-up grid: warp it first (e.g. gdalwarp)",
                    m[1], m[4]
                ),
            ));
        }
        if m[0] <= 0.0 || m[5] == 0.0 {
            return Err(bad(
                path,
                format!(
                    "{TRANSFORM}: pixel size {} x {} must be positive across and non-zero down",
                    m[0], m[5]
                ),
            ));
        }
        return Ok(Some(Affine {
            x0: m[3],
            y0: m[7],
            dx: m[0],
            dy: m[5],
        }));
    }
    match (scale, ties) {
        (None, None) => Ok(None),
        (None, Some(t)) => Err(unsupported(
            path,
            TIES,
            format!(
                "{} tie points without {SCALE}: a control-point (warped) raster; warp it to a \
                 regular grid first (e.g. gdalwarp)",
                t.len() / 6
            ),
        )),
        (Some(_), None) => Err(bad(
            path,
            format!("{SCALE} is present but {TIES} is missing: the raster has no position"),
        )),
        (Some(s), Some(t)) => {
            if s.len() < 2 || !finite(&s) || s[0] <= 0.0 || s[1] <= 0.0 {
                return Err(bad(
                    path,
                    format!("{SCALE}: expected a positive, finite pixel size, found {s:?}"),
                ));
            }
            if t.len() < 6 || t.len() % 6 != 0 || !finite(&t) {
                return Err(bad(
                    path,
                    format!(
                        "{TIES}: expected groups of 6 finite numbers (I, J, K, X, Y, Z), found {}",
                        t.len()
                    ),
                ));
            }
            // The first tie point pins raster (I, J) to model (X, Y); the scale does the rest.
            Ok(Some(Affine {
                x0: t[3] - t[0] * s[0],
                y0: t[4] + t[1] * s[1],
                dx: s[0],
                dy: -s[1],
            }))
        }
    }
}

/// The short-valued GeoKeys, as (id, value) pairs.
fn read_geokeys(path: &Path, dec: &mut Dec) -> Result<Vec<(u16, u16)>, DemError> {
    const NAME: &str = "GeoKeyDirectoryTag (34735)";
    let Some(v) = dec
        .find_tag(Tag::GeoKeyDirectoryTag)
        .and_then(|v| v.map(tiff::decoder::ifd::Value::into_u16_vec).transpose())
        .map_err(|e| bad(path, format!("{NAME}: cannot read: {e}")))?
    else {
        return Ok(Vec::new());
    };
    if v.len() < 4 {
        return Err(bad(
            path,
            format!("{NAME}: {} values, expected a 4-value header", v.len()),
        ));
    }
    let n = usize::from(v[3]);
    if v.len() < 4 + 4 * n {
        return Err(bad(
            path,
            format!("{NAME}: declares {n} keys but holds {} values", v.len()),
        ));
    }
    // Keys stored inline (location 0) are the shorts this reader needs; others are skipped.
    Ok(v[4..4 + 4 * n]
        .chunks_exact(4)
        .filter(|e| e[1] == 0)
        .map(|e| (e[0], e[3]))
        .collect())
}

fn linear_unit_m(path: &Path, code: u16, tag: &'static str) -> Result<f64, DemError> {
    match code {
        9001 => Ok(1.0),
        9002 => Ok(0.3048),
        9003 => Ok(1200.0 / 3937.0),
        9036 => Ok(1000.0),
        _ => Err(unsupported(
            path,
            tag,
            format!(
                "unit code {code}; supported: 9001 metre, 9002 foot, 9003 US survey foot, 9036 km"
            ),
        )),
    }
}

/// Reads a GeoTIFF elevation raster (`vertical_scale` metres per unit, on top of its vertical
/// unit). `spacing_m` is only for files without georeferencing.
pub fn read(path: &Path, spacing_m: Option<f64>, vertical_scale: f64) -> Result<Source, DemError> {
    let mut file = std::fs::File::open(path).map_err(|e| DemError::Io {
        path: path.to_path_buf(),
        source: e,
    })?;
    let file_len = file
        .metadata()
        .map_err(|e| DemError::Io {
            path: path.to_path_buf(),
            source: e,
        })?
        .len();
    ifd_sizes::check(&mut file, file_len).map_err(|m| bad(path, m))?;
    file.seek(std::io::SeekFrom::Start(0))
        .map_err(|e| DemError::Io {
            path: path.to_path_buf(),
            source: e,
        })?;
    let mut dec_limits = Limits::default();
    dec_limits.decoding_buffer_size = (limits::MAX_GRID_SIDE as usize).pow(2) * 8;
    // Tag values (strip and tile offsets of the largest raster fit) are decoded into lists of
    // 32-byte values: keep their raw size small.
    dec_limits.ifd_value_size = 1 << 20;
    let mut dec = Decoder::new(BufReader::new(file))
        .map_err(|e| bad(path, format!("not a readable TIFF: {e}")))?
        .with_limits(dec_limits);
    let (w, h) = dec
        .dimensions()
        .map_err(|e| bad(path, format!("ImageWidth/ImageLength: {e}")))?;
    check_size(path, w.into(), h.into())?;
    let layout = check_layout(path, &mut dec)?;
    check_data_size(
        path,
        &mut dec,
        &layout,
        file_len,
        u64::from(w) * u64::from(h),
    )?;
    let affine = read_affine(path, &mut dec)?;
    let keys = read_geokeys(path, &mut dec)?;
    let key = |id| keys.iter().find(|k| k.0 == id).map(|k| k.1);
    let nodata = read_nodata(path, &mut dec)?;
    let vertical_unit = match key(key::VERTICAL_UNITS) {
        None => 1.0,
        Some(c) => linear_unit_m(path, c, "VerticalUnitsGeoKey (4099)")?,
    };
    let place = match affine {
        None => {
            let s = spacing_m.ok_or_else(|| {
                bad(
                    path,
                    "has no georeferencing (neither ModelPixelScaleTag 33550 with \
                     ModelTiepointTag 33922 nor ModelTransformationTag 34264); pass --spacing-m \
                     to import it as a plain height field"
                        .into(),
                )
            })?;
            Placement {
                spacing_m: [s, s],
                origin_m: [0.0, 0.0],
                north_up: true,
                note: format!("no georeferencing, {s} m from --spacing-m"),
                projected: false,
            }
        }
        Some(a) => {
            if spacing_m.is_some() {
                return Err(DemError::BadParam {
                    path: path.to_path_buf(),
                    message: "the GeoTIFF carries its own pixel size; drop --spacing-m".into(),
                });
            }
            place(path, a, &keys, h)?
        }
    };
    if place
        .spacing_m
        .iter()
        .any(|s| !(*s >= limits::MIN_SPACING_M))
    {
        return Err(bad(
            path,
            format!(
                "pixel size {:.4} x {:.4} m is below the {} m minimum",
                place.spacing_m[0],
                place.spacing_m[1],
                limits::MIN_SPACING_M
            ),
        ));
    }
    let image = dec
        .read_image()
        .map_err(|e| bad(path, format!("cannot decode the raster: {e}")))?;
    let vals = samples_f32(image, nodata, vertical_unit * vertical_scale).ok_or_else(|| {
        unsupported(
            path,
            "BitsPerSample (258)",
            "unsupported sample type".into(),
        )
    })?;
    let (w, h) = (w as usize, h as usize);
    let grid = if place.north_up {
        Grid::from_north_up(w, h, &vals)
    } else {
        Grid::from_vec(w, h, vals)
    }
    .ok_or_else(|| {
        bad(
            path,
            "decoded fewer samples than ImageWidth x ImageLength".into(),
        )
    })?;
    Ok(Source {
        grid,
        spacing_m: place.spacing_m,
        origin_m: place.origin_m,
        note: place.note,
        projected: place.projected,
    })
}

/// GDAL's nodata value (an ASCII number), if the file has one.
fn read_nodata(path: &Path, dec: &mut Dec) -> Result<Option<f64>, DemError> {
    const NAME: &str = "GDAL_NODATA (42113)";
    let Some(v) = dec
        .find_tag(Tag::GdalNodata)
        .map_err(|e| bad(path, format!("{NAME}: cannot read: {e}")))?
    else {
        return Ok(None);
    };
    let s = v
        .into_string()
        .map_err(|e| bad(path, format!("{NAME}: {e}")))?;
    let t = s.trim_matches(|c: char| c.is_whitespace() || c == '\0');
    t.parse::<f64>()
        .map(Some)
        .map_err(|_| bad(path, format!("{NAME}: {t:?} is not a number")))
}

/// Where the samples lie, in metres.
struct Placement {
    spacing_m: [f64; 2],
    /// The south-west sample (0 for geographic rasters).
    origin_m: [f64; 2],
    /// Whether the file's first row is the northern one.
    north_up: bool,
    note: String,
    /// Whether `origin_m` is a position in projected metres.
    projected: bool,
}

/// Placement of a georeferenced raster of `h` rows from its transform and GeoKeys.
fn place(path: &Path, a: Affine, keys: &[(u16, u16)], h: u32) -> Result<Placement, DemError> {
    let key = |id| keys.iter().find(|k| k.0 == id).map(|k| k.1);
    // PixelIsArea (the default) ties the pixel's corner; its sample is at the centre.
    let half = match key(key::RASTER_TYPE) {
        None | Some(1) => 0.5,
        Some(2) => 0.0,
        Some(c) => {
            return Err(unsupported(
                path,
                "GTRasterTypeGeoKey (1025)",
                format!("is {c}; expected 1 (pixel is area) or 2 (pixel is point)"),
            ));
        }
    };
    let north_up = a.dy < 0.0;
    let first_x = a.x0 + half * a.dx;
    let south_row = if north_up { f64::from(h - 1) } else { 0.0 };
    let south_y = a.y0 + (south_row + half) * a.dy;
    let model = key(key::MODEL_TYPE).unwrap_or(1);
    match model {
        1 => {
            let unit = match key(key::PROJ_LINEAR_UNITS) {
                None => 1.0,
                Some(c) => linear_unit_m(path, c, "ProjLinearUnitsGeoKey (3076)")?,
            };
            let origin = [first_x * unit, south_y * unit];
            if origin.iter().any(|o| o.abs() > limits::MAX_ORIGIN_M) {
                return Err(bad(
                    path,
                    format!(
                        "ModelTiepointTag (33922): position ({:.0}, {:.0}) m is beyond \
                         ±{} m",
                        origin[0],
                        origin[1],
                        limits::MAX_ORIGIN_M
                    ),
                ));
            }
            let note = format!(
                "projected, {} per unit, south-west sample at ({:.2}, {:.2}) m",
                if unit == 1.0 {
                    "1 m".to_string()
                } else {
                    format!("{unit} m")
                },
                origin[0],
                origin[1]
            );
            Ok(Placement {
                spacing_m: [a.dx * unit, a.dy.abs() * unit],
                origin_m: origin,
                north_up,
                note,
                projected: true,
            })
        }
        2 => {
            let to_deg = match key(key::GEOG_ANGULAR_UNITS) {
                None | Some(9102) => 1.0,
                Some(9101) => 180.0 / std::f64::consts::PI,
                Some(c) => {
                    return Err(unsupported(
                        path,
                        "GeogAngularUnitsGeoKey (2054)",
                        format!("unit code {c}; supported: 9102 degree, 9101 radian"),
                    ));
                }
            };
            let south_deg = south_y * to_deg;
            let north_deg = south_deg + f64::from(h - 1) * a.dy.abs() * to_deg;
            let centre_deg = 0.5 * (south_deg + north_deg);
            if !(south_deg >= -85.0 && north_deg <= 85.0) {
                return Err(DemError::Latitude {
                    path: path.to_path_buf(),
                    latitude_deg: if south_deg < -85.0 {
                        south_deg
                    } else {
                        north_deg
                    },
                });
            }
            let [m_lat, m_lon] = metres_per_degree(centre_deg);
            let spacing = [a.dx * to_deg * m_lon, a.dy.abs() * to_deg * m_lat];
            let note = format!(
                "geographic, south-west sample at {:.5} E {:.5} N, degrees to metres at \
                 {centre_deg:.3} N (WGS84)",
                first_x * to_deg,
                south_deg
            );
            Ok(Placement {
                spacing_m: spacing,
                origin_m: [0.0, 0.0],
                north_up,
                note,
                projected: false,
            })
        }
        c => Err(unsupported(
            path,
            "GTModelTypeGeoKey (1024)",
            format!("is {c}; supported: 1 projected, 2 geographic"),
        )),
    }
}

/// Samples as metres (NaN where the sample equals `nodata` or is not finite).
fn samples_f32(image: DecodingResult, nodata: Option<f64>, scale: f64) -> Option<Vec<f32>> {
    fn convert<T: Copy>(
        v: Vec<T>,
        is_void: impl Fn(T) -> bool,
        f: impl Fn(T) -> f64,
        scale: f64,
    ) -> Vec<f32> {
        v.into_iter()
            .map(|x| {
                if is_void(x) {
                    f32::NAN
                } else {
                    (f(x) * scale) as f32
                }
            })
            .collect()
    }
    let nd = nodata.unwrap_or(f64::NAN);
    // Integer samples equal the nodata value exactly; floats as stored at their own precision.
    Some(match image {
        DecodingResult::U8(v) => convert(v, |x| f64::from(x) == nd, f64::from, scale),
        DecodingResult::U16(v) => convert(v, |x| f64::from(x) == nd, f64::from, scale),
        DecodingResult::U32(v) => convert(v, |x| f64::from(x) == nd, f64::from, scale),
        DecodingResult::I8(v) => convert(v, |x| f64::from(x) == nd, f64::from, scale),
        DecodingResult::I16(v) => convert(v, |x| f64::from(x) == nd, f64::from, scale),
        DecodingResult::I32(v) => convert(v, |x| f64::from(x) == nd, f64::from, scale),
        DecodingResult::F32(v) => {
            convert(v, |x| !x.is_finite() || x == nd as f32, f64::from, scale)
        }
        DecodingResult::F64(v) => convert(v, |x| !x.is_finite() || x == nd, |x| x, scale),
        _ => return None,
    })
}
