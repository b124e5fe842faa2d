//! Raster layer files: heights as single-channel f32 OpenEXR, ground types as 8-bit indexed PNG,
//! densities as 8-bit grayscale PNG. Every reader checks the header against the manifest before
//! it allocates sample memory.

use super::{GridSpec, GroundSpec, Manifest, MapError, limits};
use crate::Grid;
use std::io::BufReader;
use std::path::Path;

fn layer_size_error(path: &Path, field: &str, found: (u64, u64), spec: &GridSpec) -> MapError {
    MapError::LayerSize {
        path: path.to_path_buf(),
        field: field.to_string(),
        found_w: found.0,
        found_h: found.1,
        expected_w: spec.width.into(),
        expected_h: spec.height.into(),
    }
}

fn bad_file(
    path: &Path,
    field: &str,
    kind: &'static str,
    message: impl std::fmt::Display,
) -> MapError {
    MapError::BadLayerFile {
        path: path.to_path_buf(),
        field: field.to_string(),
        kind,
        message: message.to_string(),
    }
}

fn require_file(path: &Path, field: &str) -> Result<(), MapError> {
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => Ok(()),
        Ok(_) => Err(bad_file(path, field, "layer", "is not a regular file")),
        Err(e) => Err(MapError::io(
            path,
            "open layer file (listed in map.toml)",
            e,
        )),
    }
}

/// Reads the height layer and checks every sample.
pub fn read_heights(dir: &Path, manifest: &Manifest) -> Result<Grid<f32>, MapError> {
    use exr::prelude::*;
    let spec = &manifest.heights;
    let path = dir.join(&spec.file);
    let field = "heights.file";
    require_file(&path, field)?;
    // Header first: refuse wrong sizes and types before any sample memory is allocated.
    let meta =
        MetaData::read_from_file(&path, false).map_err(|e| bad_file(&path, field, "OpenEXR", e))?;
    let [header] = meta.headers.as_slice() else {
        return Err(bad_file(
            &path,
            field,
            "OpenEXR",
            format!("has {} layers, expected 1", meta.headers.len()),
        ));
    };
    let found = (header.layer_size.0 as u64, header.layer_size.1 as u64);
    if found != (u64::from(spec.width), u64::from(spec.height)) {
        return Err(layer_size_error(&path, "heights", found, spec));
    }
    if header.deep
        || header.channels.list.len() != 1
        || header.channels.list[0].sample_type != SampleType::F32
    {
        return Err(bad_file(
            &path,
            field,
            "OpenEXR",
            "expected exactly one flat f32 channel of heights in metres",
        ));
    }
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .non_parallel()
        .from_file(&path)
        .map_err(|e| bad_file(&path, field, "OpenEXR", e))?;
    let channel = &image.layer_data.channel_data.list[0];
    let FlatSamples::F32(samples) = &channel.sample_data else {
        return Err(bad_file(&path, field, "OpenEXR", "channel is not f32"));
    };
    let (w, h) = (spec.width as usize, spec.height as usize);
    let grid = Grid::from_north_up(w, h, samples).ok_or_else(|| {
        bad_file(
            &path,
            field,
            "OpenEXR",
            format!("holds {} samples, expected {}", samples.len(), w * h),
        )
    })?;
    check_heights(&path, &grid)?;
    Ok(grid)
}

/// Checks that every height of the layer `path` is finite and within the map's limit.
pub fn check_heights(path: &Path, grid: &Grid<f32>) -> Result<(), MapError> {
    let w = grid.width();
    for (i, &v) in grid.data().iter().enumerate() {
        if !v.is_finite() || v.abs() > limits::MAX_ABS_HEIGHT_M {
            return Err(MapError::BadHeight {
                path: path.to_path_buf(),
                x: i % w,
                y: i / w,
                value: v,
                max: limits::MAX_ABS_HEIGHT_M,
            });
        }
    }
    Ok(())
}

/// Writes heights as a single-channel f32 OpenEXR (ZIP-compressed, lossless, deterministic).
pub fn write_heights(path: &Path, heights: &Grid<f32>) -> Result<(), MapError> {
    use exr::prelude::*;
    let channel = AnyChannel::new("Y", FlatSamples::F32(heights.to_north_up()));
    let layer = Layer::new(
        (heights.width(), heights.height()),
        LayerAttributes::named("heights_m"),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(SmallVec::from_vec(vec![channel])),
    );
    Image::from_layer(layer)
        .write()
        .non_parallel()
        .to_file(path)
        .map_err(|e| {
            bad_file(
                path,
                "heights.file",
                "OpenEXR",
                format!("cannot be written: {e}"),
            )
        })
}

/// Opens a PNG and checks its size against `spec` before decoding.
fn open_png(
    path: &Path,
    field: &str,
    spec: &GridSpec,
) -> Result<png::Reader<BufReader<std::fs::File>>, MapError> {
    require_file(path, field)?;
    let file = std::fs::File::open(path).map_err(|e| MapError::io(path, "open", e))?;
    let mut decoder = png::Decoder::new(BufReader::new(file));
    decoder.set_transformations(png::Transformations::IDENTITY);
    // The manifest sizes are already within limits; allow the decoder just what they need.
    decoder.set_limits(png::Limits {
        bytes: (spec.width as usize * spec.height as usize * 2).max(1 << 20) + (1 << 20),
    });
    let reader = decoder
        .read_info()
        .map_err(|e| bad_file(path, field, "PNG", e))?;
    let info = reader.info();
    let found = (u64::from(info.width), u64::from(info.height));
    if found != (u64::from(spec.width), u64::from(spec.height)) {
        return Err(layer_size_error(
            path,
            field.trim_end_matches(".file"),
            found,
            spec,
        ));
    }
    Ok(reader)
}

fn decode_8bit(
    mut reader: png::Reader<BufReader<std::fs::File>>,
    path: &Path,
    field: &str,
    want: png::ColorType,
) -> Result<Vec<u8>, MapError> {
    let info = reader.info();
    if info.color_type != want || info.bit_depth != png::BitDepth::Eight {
        return Err(bad_file(
            path,
            field,
            "PNG",
            format!(
                "is {:?} {:?}-bit, expected {want:?} 8-bit",
                info.color_type, info.bit_depth as u8
            ),
        ));
    }
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| bad_file(path, field, "PNG", "image too large for this machine"))?;
    let mut buf = vec![0u8; size];
    let frame = reader
        .next_frame(&mut buf)
        .map_err(|e| bad_file(path, field, "PNG", e))?;
    buf.truncate(frame.buffer_size());
    Ok(buf)
}

/// Reads an 8-bit grayscale layer (vegetation density).
pub fn read_gray8(dir: &Path, field: &str, spec: &GridSpec) -> Result<Grid<u8>, MapError> {
    let path = dir.join(&spec.file);
    let reader = open_png(&path, field, spec)?;
    let buf = decode_8bit(reader, &path, field, png::ColorType::Grayscale)?;
    Grid::from_north_up(spec.width as usize, spec.height as usize, &buf).ok_or_else(|| {
        bad_file(
            &path,
            field,
            "PNG",
            "decoded size does not match its header",
        )
    })
}

/// Reads the ground-type layer and checks every index against the legend.
pub fn read_ground(dir: &Path, manifest: &Manifest) -> Result<Grid<u8>, MapError> {
    let spec = manifest.ground.grid();
    let path = dir.join(&spec.file);
    let field = "ground.file";
    let reader = open_png(&path, field, &spec)?;
    let buf = decode_8bit(reader, &path, field, png::ColorType::Indexed)?;
    let grid =
        Grid::from_north_up(spec.width as usize, spec.height as usize, &buf).ok_or_else(|| {
            bad_file(
                &path,
                field,
                "PNG",
                "decoded size does not match its header",
            )
        })?;
    check_ground(&path, &grid, manifest)?;
    Ok(grid)
}

/// Checks that every ground type of the layer `path` is an index into the manifest's legend.
pub fn check_ground(path: &Path, grid: &Grid<u8>, manifest: &Manifest) -> Result<(), MapError> {
    let n = manifest.ground.legend.len();
    let w = grid.width();
    if let Some((i, &v)) = grid
        .data()
        .iter()
        .enumerate()
        .find(|&(_, &v)| v as usize >= n)
    {
        return Err(MapError::GroundTypeOutOfRange {
            path: path.to_path_buf(),
            x: i % w,
            y: i / w,
            value: v,
            legend_len: n,
        });
    }
    Ok(())
}

fn write_png(
    path: &Path,
    field: &str,
    grid: &Grid<u8>,
    palette: Option<Vec<u8>>,
) -> Result<(), MapError> {
    let file = std::fs::File::create(path).map_err(|e| MapError::io(path, "create", e))?;
    let mut enc = png::Encoder::new(
        std::io::BufWriter::new(file),
        grid.width() as u32,
        grid.height() as u32,
    );
    enc.set_depth(png::BitDepth::Eight);
    match palette {
        Some(p) => {
            enc.set_color(png::ColorType::Indexed);
            enc.set_palette(p);
        }
        None => enc.set_color(png::ColorType::Grayscale),
    }
    let io_err =
        |e: png::EncodingError| bad_file(path, field, "PNG", format!("cannot be written: {e}"));
    let mut writer = enc.write_header().map_err(io_err)?;
    writer
        .write_image_data(&grid.to_north_up())
        .map_err(io_err)?;
    writer.finish().map_err(io_err)
}

/// Writes an 8-bit grayscale layer.
pub fn write_gray8(path: &Path, grid: &Grid<u8>) -> Result<(), MapError> {
    write_png(path, "vegetation.file", grid, None)
}

/// Writes the ground-type layer as an indexed PNG whose palette is the legend's colours.
pub fn write_ground(path: &Path, grid: &Grid<u8>, spec: &GroundSpec) -> Result<(), MapError> {
    let palette: Vec<u8> = spec.legend.iter().flat_map(|t| t.color).collect();
    write_png(path, "ground.file", grid, Some(palette))
}
