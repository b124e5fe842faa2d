//! Material images a map may name for its ground types (`ground.legend[i].material`): 8-bit RGB
//! or RGBA PNGs, square, with a power-of-two side in [`MIN_SIDE`]..=[`MAX_SIDE`] texels. The
//! reader checks the header before it allocates, so a huge or broken file is refused with an
//! error naming the file and the field, never decoded half-way.

use super::MapError;
use std::io::BufReader;
use std::path::Path;

/// Smallest accepted side, texels.
pub const MIN_SIDE: u32 = 16;
/// Largest accepted side, texels.
pub const MAX_SIDE: u32 = 1024;

/// A decoded material image: `side x side` sRGB texels, row-major, top row first, alpha 255
/// where the file had none.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MaterialImage {
    pub side: u32,
    pub rgba: Vec<[u8; 4]>,
}

fn bad(path: &Path, field: &str, message: impl std::fmt::Display) -> MapError {
    MapError::BadLayerFile {
        path: path.to_path_buf(),
        field: field.to_string(),
        kind: "material PNG",
        message: message.to_string(),
    }
}

/// Reads the material image at `path`, named by manifest field `field`.
pub fn read(path: &Path, field: &str) -> Result<MaterialImage, MapError> {
    let file = std::fs::File::open(path)
        .map_err(|e| MapError::io(path, "open material image (listed in map.toml)", e))?;
    let mut decoder = png::Decoder::new(BufReader::new(file));
    decoder.set_transformations(png::Transformations::IDENTITY);
    decoder.set_limits(png::Limits {
        bytes: (MAX_SIDE as usize * MAX_SIDE as usize * 4) + (1 << 20),
    });
    let mut reader = decoder.read_info().map_err(|e| bad(path, field, e))?;
    let info = reader.info();
    let (w, h) = (info.width, info.height);
    if w != h || !w.is_power_of_two() || !(MIN_SIDE..=MAX_SIDE).contains(&w) {
        return Err(bad(
            path,
            field,
            format!(
                "is {w}x{h} texels, expected a square with a power-of-two side in \
                 {MIN_SIDE}..={MAX_SIDE}"
            ),
        ));
    }
    let channels = match (info.color_type, info.bit_depth) {
        (png::ColorType::Rgb, png::BitDepth::Eight) => 3,
        (png::ColorType::Rgba, png::BitDepth::Eight) => 4,
        (c, d) => {
            return Err(bad(
                path,
                field,
                format!("is {c:?} {}-bit, expected 8-bit RGB or RGBA", d as u8),
            ));
        }
    };
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| bad(path, field, "image too large for this machine"))?;
    let mut buf = vec![0u8; size];
    let frame = reader
        .next_frame(&mut buf)
        .map_err(|e| bad(path, field, e))?;
    let texels = (w * h) as usize;
    if frame.buffer_size() < texels * channels {
        return Err(bad(path, field, "decoded size does not match its header"));
    }
    let rgba = buf[..texels * channels]
        .chunks_exact(channels)
        .map(|c| [c[0], c[1], c[2], if channels == 4 { c[3] } else { 255 }])
        .collect();
    Ok(MaterialImage { side: w, rgba })
}

/// Writes `image` as an 8-bit RGBA PNG.
pub fn write(path: &Path, field: &str, image: &MaterialImage) -> Result<(), MapError> {
    let file = std::fs::File::create(path).map_err(|e| MapError::io(path, "create", e))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), image.side, image.side);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_color(png::ColorType::Rgba);
    let fail = |e: png::EncodingError| bad(path, field, format!("cannot be written: {e}"));
    let mut writer = enc.write_header().map_err(fail)?;
    writer
        .write_image_data(image.rgba.as_flattened())
        .map_err(fail)?;
    writer.finish().map_err(fail)
}
