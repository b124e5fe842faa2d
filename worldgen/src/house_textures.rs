//! Facade and roof textures of the house types: square sRGB RGBA8 images generated
//! from a type's seed, with full mip chains (each level the mean of four texels of the level
//! above, in linear light), tiling with a period of [`TILE_M`] metres of the house's facade and
//! roof texture coordinates (which are in metres).
//!
//! On disk each is a [`MipChain`] mip atlas.

use crate::color::linear_to_srgb;
pub use crate::mip_chain::MipChain;
use crate::noise;

/// Edge of a generated texture, as a power of two (512 texels: 7.8 mm over [`TILE_M`]).
pub const EDGE_LOG2: u32 = 9;
/// Metres of facade or roof one texture spans before it repeats.
pub const TILE_M: f64 = 4.0;
/// Periodic value noise in [0, 1) at texel (`x`, `y`) of an `n`-texel texture, lattice cells of
/// `cell` texels (dividing `n`).
fn value_noise(seed: u64, x: usize, y: usize, n: usize, cell: usize) -> f64 {
    noise::periodic_value(seed, n as u32, (n / cell) as u32, x as u32, y as u32)
}

/// Facade colours (linear RGB): plaster tones and brick.
const PLASTER: [[f64; 3]; 4] = [
    [0.72, 0.66, 0.52],
    [0.78, 0.74, 0.68],
    [0.70, 0.52, 0.36],
    [0.62, 0.64, 0.62],
];
const BRICK: [f64; 3] = [0.42, 0.16, 0.09];
const MORTAR: [f64; 3] = [0.55, 0.52, 0.47];

/// A house type's facade: plaster of one of four tones, or brick courses, from the seed.
pub fn facade(seed: u64) -> MipChain {
    let n = 1usize << EDGE_LOG2;
    let pick = noise::hash3(seed, 11, 0);
    let brick = pick.is_multiple_of(3);
    let tone = PLASTER[(pick >> 8) as usize % PLASTER.len()];
    let mut rgba = vec![0u8; n * n * 4];
    // 128 texels a metre: bricks 0.25 x 0.0625 m (32 x 8 texels), 1-texel joints.
    for y in 0..n {
        for x in 0..n {
            let grain =
                0.5 * value_noise(seed, x, y, n, 4) + 0.5 * value_noise(seed ^ 1, x, y, n, 32);
            let c = if brick {
                let course = y / 8;
                let offset = if course % 2 == 0 { 0 } else { 16 };
                let (bx, by) = ((x + offset) % 32, y % 8);
                if bx == 0 || by == 0 {
                    MORTAR.map(|v| v * (0.9 + 0.2 * grain))
                } else {
                    let shade = noise::unit3(seed ^ 2, ((x + offset) / 32) as i64, course as i64);
                    BRICK.map(|v| v * (0.75 + 0.4 * shade) * (0.92 + 0.16 * grain))
                }
            } else {
                let streak = value_noise(seed ^ 3, x, 0, n, 16);
                tone.map(|v| v * (0.88 + 0.16 * grain) * (0.96 + 0.06 * streak))
            };
            let i = (y * n + x) * 4;
            for k in 0..3 {
                rgba[i + k] = linear_to_srgb(c[k]);
            }
            rgba[i + 3] = 255;
        }
    }
    MipChain::from_level0(EDGE_LOG2, rgba)
}

/// A house type's roof: rows of tiles (terracotta or slate from the seed), 0.25 m courses of
/// staggered 0.25 m tiles, each a shade of its own and darker toward the course above it.
pub fn roof(seed: u64) -> MipChain {
    let n = 1usize << EDGE_LOG2;
    let slate = noise::hash3(seed, 12, 0).is_multiple_of(2);
    let base = if slate {
        [0.16, 0.17, 0.19]
    } else {
        [0.45, 0.17, 0.08]
    };
    let mut rgba = vec![0u8; n * n * 4];
    for y in 0..n {
        for x in 0..n {
            // Texture v (image rows) runs up the slope.
            let course = y / 32;
            let offset = if course % 2 == 0 { 0 } else { 16 };
            let (tx, ty) = ((x + offset) % 32, y % 32);
            let tile = noise::unit3(seed ^ 4, ((x + offset) / 32) as i64, course as i64);
            let grain = value_noise(seed ^ 5, x, y, n, 4);
            // Darker toward the course above (which overlaps and shades it).
            let overlap = 0.7 + 0.3 * (1.0 - ty as f64 / 31.0);
            let gap = if tx == 0 { 0.5 } else { 1.0 };
            let c = base.map(|v| v * (0.8 + 0.35 * tile) * overlap * gap * (0.94 + 0.12 * grain));
            let i = (y * n + x) * 4;
            for k in 0..3 {
                rgba[i + k] = linear_to_srgb(c[k]);
            }
            rgba[i + 3] = 255;
        }
    }
    MipChain::from_level0(EDGE_LOG2, rgba)
}
