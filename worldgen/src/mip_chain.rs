//! Square sRGB RGBA8 textures with their full mip chains (each level the mean of four texels of
//! the level above, in linear light): the house textures and the ground materials use them.
//!
//! On disk a chain is one PNG in the classic mip-atlas layout ([`MipChain::to_atlas`]): level 0
//! on the left, levels 1, 2, ... stacked top-down in a column to its right, so the file is
//! 1.5 x as wide as it is high. A plain square power-of-two PNG is read as level 0 and its chain
//! computed ([`MipChain::from_png`]), so a map can carry its own pictures.

use crate::color::{linear_to_srgb, srgb_to_linear};
use std::path::Path;

/// Largest edge read from a file, as a power of two.
pub const MAX_EDGE_LOG2: u32 = 12;
/// Smallest edge read from a file, as a power of two.
pub const MIN_EDGE_LOG2: u32 = 2;

/// A square RGBA8 (sRGB) texture with every mip level down to 1 x 1: level `k` is
/// `2^(edge_log2 - k)` texels across, rows from the top.
#[derive(Debug, Clone, PartialEq)]
pub struct MipChain {
    pub edge_log2: u32,
    pub levels: Vec<Vec<u8>>,
}

impl MipChain {
    /// The chain of a level-0 image (`2^edge_log2` squared RGBA8 texels).
    pub fn from_level0(edge_log2: u32, level0: Vec<u8>) -> Self {
        let mut levels = vec![level0];
        for k in 1..=edge_log2 {
            let above = &levels[k as usize - 1];
            let (n, m) = (1usize << (edge_log2 - k + 1), 1usize << (edge_log2 - k));
            let mut next = vec![0u8; m * m * 4];
            for y in 0..m {
                for x in 0..m {
                    for c in 0..4 {
                        let at =
                            |dx: usize, dy: usize| above[((2 * y + dy) * n + 2 * x + dx) * 4 + c];
                        let texels = [at(0, 0), at(1, 0), at(0, 1), at(1, 1)];
                        next[(y * m + x) * 4 + c] = if c == 3 {
                            let sum: u32 = texels.iter().map(|&t| u32::from(t)).sum();
                            ((sum + 2) / 4) as u8
                        } else {
                            linear_to_srgb(
                                texels.iter().map(|&t| srgb_to_linear(t)).sum::<f64>() / 4.0,
                            )
                        };
                    }
                }
            }
            levels.push(next);
        }
        MipChain { edge_log2, levels }
    }

    /// Texels across level `level`.
    pub fn edge(&self, level: u32) -> u32 {
        1 << (self.edge_log2 - level)
    }

    /// The mip atlas: (width, height, RGBA8 rows from the top); see the module docs.
    pub fn to_atlas(&self) -> (u32, u32, Vec<u8>) {
        let e = self.edge(0) as usize;
        let w = e + e / 2;
        let mut out = vec![0u8; w * e * 4];
        for (k, level) in self.levels.iter().enumerate() {
            let (x0, y0) = atlas_origin(e, k);
            let n = e >> k;
            for y in 0..n {
                let dst = ((y0 + y) * w + x0) * 4;
                out[dst..dst + n * 4].copy_from_slice(&level[y * n * 4..(y + 1) * n * 4]);
            }
        }
        (w as u32, e as u32, out)
    }

    /// A chain from a mip atlas or from a plain square image (its chain computed).
    pub fn from_image(width: u32, height: u32, rgba: &[u8]) -> Result<Self, String> {
        if rgba.len() as u64 != u64::from(width) * u64::from(height) * 4 {
            return Err(format!("{width}x{height} texels but {} bytes", rgba.len()));
        }
        let square = width == height;
        let atlas = u64::from(width) * 2 == u64::from(height) * 3;
        if !(square || atlas) || !height.is_power_of_two() {
            return Err(format!(
                "{width}x{height} texels: expected a square power-of-two image or a mip atlas 1.5 times as wide as its power-of-two height"
            ));
        }
        let edge_log2 = height.trailing_zeros();
        if !(MIN_EDGE_LOG2..=MAX_EDGE_LOG2).contains(&edge_log2) {
            return Err(format!(
                "{height} texels high: expected {} to {}",
                1u32 << MIN_EDGE_LOG2,
                1u32 << MAX_EDGE_LOG2
            ));
        }
        let e = height as usize;
        let w = width as usize;
        let level = |k: usize| {
            let (x0, y0) = if square { (0, 0) } else { atlas_origin(e, k) };
            let n = e >> k;
            let mut out = Vec::with_capacity(n * n * 4);
            for y in 0..n {
                let src = ((y0 + y) * w + x0) * 4;
                out.extend_from_slice(&rgba[src..src + n * 4]);
            }
            out
        };
        if square {
            return Ok(Self::from_level0(edge_log2, level(0)));
        }
        Ok(MipChain {
            edge_log2,
            levels: (0..=edge_log2 as usize).map(level).collect(),
        })
    }

    /// Reads a PNG (8-bit RGBA or RGB): a mip atlas or a plain square image.
    pub fn from_png(path: &Path) -> Result<Self, String> {
        let file = std::fs::File::open(path).map_err(|e| format!("cannot open: {e}"))?;
        let mut decoder = png::Decoder::new(std::io::BufReader::new(file));
        decoder.set_transformations(png::Transformations::EXPAND);
        let mut reader = decoder.read_info().map_err(|e| format!("not a PNG: {e}"))?;
        let (w, h) = (reader.info().width, reader.info().height);
        if w > 3 << (MAX_EDGE_LOG2 - 1) || h > 1 << MAX_EDGE_LOG2 {
            return Err(format!("{w}x{h} texels: larger than a texture may be"));
        }
        let mut buf = vec![0u8; reader.output_buffer_size().ok_or("image too large")?];
        let info = reader
            .next_frame(&mut buf)
            .map_err(|e| format!("cannot decode: {e}"))?;
        let rgba = match (info.color_type, info.bit_depth) {
            (png::ColorType::Rgba, png::BitDepth::Eight) => buf[..info.buffer_size()].to_vec(),
            (png::ColorType::Rgb, png::BitDepth::Eight) => buf[..info.buffer_size()]
                .chunks_exact(3)
                .flat_map(|p| [p[0], p[1], p[2], 255])
                .collect(),
            (c, d) => return Err(format!("{c:?} at {d:?}: expected 8-bit RGB or RGBA")),
        };
        Self::from_image(w, h, &rgba)
    }

    /// Writes the mip atlas as a PNG.
    pub fn write_png(&self, path: &Path) -> Result<(), String> {
        let (w, h, rgba) = self.to_atlas();
        let file = std::fs::File::create(path).map_err(|e| format!("cannot create: {e}"))?;
        let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w, h);
        enc.set_color(png::ColorType::Rgba);
        enc.set_depth(png::BitDepth::Eight);
        let mut writer = enc.write_header().map_err(|e| e.to_string())?;
        writer.write_image_data(&rgba).map_err(|e| e.to_string())
    }
}

/// Where level `k` of a chain of edge `e` sits in the atlas (x, y of its top-left texel).
fn atlas_origin(e: usize, k: usize) -> (usize, usize) {
    if k == 0 {
        return (0, 0);
    }
    // Levels 1, 2, ... stacked downwards: level k starts below e/2 + e/4 + ... + e/2^(k-1).
    let y: usize = (1..k).map(|j| e >> j).sum();
    (e, y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::house_textures::{EDGE_LOG2, facade};

    #[test]
    fn atlas_round_trips_and_levels_halve() {
        let chain = facade(3);
        assert_eq!(chain.levels.len(), EDGE_LOG2 as usize + 1);
        for (k, l) in chain.levels.iter().enumerate() {
            let e = chain.edge(k as u32) as usize;
            assert_eq!(l.len(), e * e * 4);
        }
        let (w, h, rgba) = chain.to_atlas();
        assert_eq!((w, h), (768, 512));
        assert_eq!(MipChain::from_image(w, h, &rgba).unwrap(), chain);
        // A plain square image gets the same chain computed.
        let plain = MipChain::from_image(512, 512, &chain.levels[0]).unwrap();
        assert_eq!(plain, chain);
        assert!(MipChain::from_image(500, 500, &vec![0; 500 * 500 * 4]).is_err());
        assert!(MipChain::from_image(768, 500, &vec![0; 768 * 500 * 4]).is_err());
    }

    #[test]
    fn a_mip_texel_is_the_linear_mean_of_four() {
        // Black and white checks: every level-1 texel is mid grey in linear light (sRGB 188).
        let n = 4usize;
        let level0: Vec<u8> = (0..n * n)
            .flat_map(|i| {
                let v = if (i % n + i / n).is_multiple_of(2) {
                    0
                } else {
                    255
                };
                [v, v, v, 255]
            })
            .collect();
        let chain = MipChain::from_level0(2, level0);
        assert!(
            chain.levels[1]
                .chunks(4)
                .all(|p| p[0] == 188 && p[3] == 255)
        );
        assert_eq!(chain.levels[2], vec![188, 188, 188, 255]);
    }
}
