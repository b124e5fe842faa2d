//! Ground materials: per ground type of the map's legend, an albedo texture and a detail height
//! texture that tile seamlessly, `MATERIAL_TEXELS` texels over [`MATERIAL_TILE_M`] metres.
//!
//! Not stored in the map: they are a pure function of the legend (name and colour) and the map
//! seed, so they need no map layer and no format version. `worldgen bake` makes them (about a
//! tenth of a second per type) into the bake ([`super::material_layers`]); a viewer makes them
//! at start-up only for a map without that bake. A map may instead name a PNG for a type
//! (`ground.legend[i].material`, validated by `Map::load`): its texels are then the albedo,
//! box-filtered (in linear light) or repeated to `MATERIAL_TEXELS`, north up.
//!
//! Each texture is periodic value noise (corner values hashed from lattice indices modulo the
//! lattice size, so the texture's last column continues into its first) in a few octaves whose
//! sizes and contrast follow the type's character (grass fine and streaky, rock coarse and
//! contrasted, snow and water nearly flat). The albedo is the legend colour scaled in linear
//! light by a factor of mean 1, so from afar a material looks like the flat legend colour the
//! terrain had before.

use crate::color::{linear_to_srgb, srgb_to_linear};
use worldgen::map::{GroundType, MaterialImage};
use worldgen::noise::periodic_value;

/// Texels per material side (a power of two: mips tile too): 7.8 mm texels, four times finer
/// than the finest node texture's (3.3 cm), so that close up the terrain shader can show the
/// material's own detail below the node texture's (`render::ground_detail`).
pub const MATERIAL_TEXELS: u32 = 512;
/// Metres one material tile covers.
pub const MATERIAL_TILE_M: f64 = 4.0;

/// One ground type's material.
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    pub name: String,
    /// sRGB albedo, row-major, `MATERIAL_TEXELS^2` texels (alpha 255).
    pub albedo_srgb: Vec<[u8; 4]>,
    /// Detail height in [0, 255] (0.5 = the surface), row-major.
    pub height: Vec<u8>,
    /// Metres between height 0 and height 255: the relief the terrain shader bumps the
    /// ground's normal with near the camera (`render::ground_detail`), at most [`MAX_RELIEF_M`].
    pub relief_m: f64,
}

/// The largest material relief (m); the renderer stores heights in steps of it / 255.
pub const MAX_RELIEF_M: f64 = 0.1;
/// The relief of a material made from a map's image (m): grass or gravel scale, since an
/// image's luminance says nothing of its true depth.
pub const IMAGE_RELIEF_M: f64 = 0.03;

/// How a type's noise looks: octaves as (lattice cells per tile side, weight), the albedo
/// contrast (the factor ranges over `1 +- contrast`) and the relief of its detail height (m).
struct Character {
    octaves: &'static [(u32, f64)],
    contrast: f64,
    relief_m: f64,
}

fn character(name: &str) -> Character {
    let has = |w: &str| name.to_ascii_lowercase().contains(w);
    if has("water") || has("snow") || has("ice") {
        Character {
            octaves: &[(4, 0.7), (16, 0.3)],
            contrast: 0.06,
            relief_m: 0.005,
        }
    } else if has("rock") || has("stone") || has("cliff") {
        Character {
            octaves: &[(4, 0.5), (8, 0.3), (32, 0.2), (256, 0.12)],
            contrast: 0.35,
            relief_m: 0.08,
        }
    } else if has("grass") || has("meadow") {
        Character {
            octaves: &[(8, 0.3), (32, 0.3), (64, 0.4), (256, 0.3)],
            contrast: 0.25,
            relief_m: 0.03,
        }
    } else if has("sand") {
        Character {
            octaves: &[(16, 0.4), (64, 0.6), (256, 0.4)],
            contrast: 0.12,
            relief_m: 0.015,
        }
    } else {
        Character {
            octaves: &[(4, 0.3), (16, 0.4), (64, 0.3), (256, 0.2)],
            contrast: 0.22,
            relief_m: 0.04,
        }
    }
}

/// The material of legend entry `index` (type `t`) for a map of `seed`.
pub fn material(index: usize, t: &GroundType, seed: u64) -> Material {
    let ch = character(&t.name);
    let n = MATERIAL_TEXELS;
    let base = t.color.map(srgb_to_linear);
    let total: f64 = ch.octaves.iter().map(|o| o.1).sum();
    let mut albedo_srgb = Vec::with_capacity((n * n) as usize);
    let mut height = Vec::with_capacity((n * n) as usize);
    for j in 0..n {
        for i in 0..n {
            let v: f64 = ch
                .octaves
                .iter()
                .enumerate()
                .map(|(k, &(cells, w))| {
                    let s = seed ^ (index as u64) << 8 ^ k as u64;
                    w * periodic_value(s, MATERIAL_TEXELS, cells, i, j)
                })
                .sum::<f64>()
                / total;
            // Value noise averages 1/2: the factor averages 1.
            let factor = 1.0 + 2.0 * ch.contrast * (v - 0.5);
            let c = base.map(|b| linear_to_srgb(b * factor));
            albedo_srgb.push([c[0], c[1], c[2], 255]);
            height.push((v * 255.0).round().clamp(0.0, 255.0) as u8);
        }
    }
    Material {
        name: t.name.clone(),
        albedo_srgb,
        height,
        relief_m: ch.relief_m,
    }
}

/// The material made from a map's image for type `t`: `MATERIAL_TEXELS` texels a side (each
/// the linear-light mean of the image texels it covers, or a repeat of the one it lies in when
/// the image is smaller), rows south to north like the generated ones; detail height from the
/// texels' luminance, stretched to 0..=255.
pub fn material_from_image(t: &GroundType, image: &MaterialImage) -> Material {
    let n = MATERIAL_TEXELS;
    let side = image.side;
    let (step, span) = if side >= n {
        (side / n, side / n)
    } else {
        (1, 1)
    };
    let mut linear = Vec::with_capacity((n * n) as usize);
    for j in 0..n {
        // Material row j counts from the south; image row 0 is the north edge.
        for i in 0..n {
            let mut sum = [0.0f64; 3];
            for dy in 0..span {
                for dx in 0..span {
                    let (x, y) = if side >= n {
                        (i * step + dx, (n - 1 - j) * step + dy)
                    } else {
                        (i * side / n, (n - 1 - j) * side / n)
                    };
                    let p = image.rgba[(y * side + x) as usize];
                    for c in 0..3 {
                        sum[c] += srgb_to_linear(p[c]);
                    }
                }
            }
            linear.push(sum.map(|v| v / f64::from(span * span)));
        }
    }
    let luminance: Vec<f64> = linear
        .iter()
        .map(|c| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2])
        .collect();
    let lo = luminance.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = luminance.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let range = (hi - lo).max(1e-9);
    Material {
        name: t.name.clone(),
        albedo_srgb: linear
            .iter()
            .map(|c| {
                let s = c.map(linear_to_srgb);
                [s[0], s[1], s[2], 255]
            })
            .collect(),
        height: luminance
            .iter()
            .map(|l| ((l - lo) / range * 255.0).round() as u8)
            .collect(),
        relief_m: IMAGE_RELIEF_M,
    }
}

/// The materials of a legend, in legend order: from the map's image where it names one
/// (`images[i]`, missing entries count as none), generated otherwise.
pub fn materials(
    legend: &[GroundType],
    images: &[Option<MaterialImage>],
    seed: u64,
) -> Vec<Material> {
    (0..legend.len())
        .map(|i| material_of(legend, images, i, seed))
        .collect()
}

/// The material of type `i` of `legend` (one of [`materials`]).
pub fn material_of(
    legend: &[GroundType],
    images: &[Option<MaterialImage>],
    i: usize,
    seed: u64,
) -> Material {
    match images.get(i).and_then(Option::as_ref) {
        Some(image) => material_from_image(&legend[i], image),
        None => material(i, &legend[i], seed),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn legend() -> Vec<GroundType> {
        crate::test_maps::tiny_map().manifest.ground.legend
    }

    /// The same legend and seed give the same bytes; another seed or type gives others.
    #[test]
    fn materials_are_deterministic_and_distinct() {
        let l = legend();
        assert!(l.len() >= 3);
        let a = materials(&l, &[], 7);
        assert_eq!(a, materials(&l, &[], 7));
        assert_ne!(a[0].height, materials(&l, &[], 8)[0].height);
        for (i, m) in a.iter().enumerate().skip(1) {
            assert_ne!(
                m.height,
                a[i - 1].height,
                "{} and {}",
                m.name,
                a[i - 1].name
            );
        }
    }

    /// Seamless: across the wrap (last column to first, last row to first) neighbouring texels
    /// differ no more than the largest difference between neighbours inside the texture.
    #[test]
    fn materials_tile_without_a_seam() {
        let n = MATERIAL_TEXELS as usize;
        for m in materials(&legend(), &[], 3) {
            let h = |i: usize, j: usize| i32::from(m.height[(j % n) * n + i % n]);
            let mut inside = 0;
            let mut across = 0;
            for j in 0..n {
                for i in 0..n {
                    let d = (h(i + 1, j) - h(i, j))
                        .abs()
                        .max((h(i, j + 1) - h(i, j)).abs());
                    if i + 1 < n && j + 1 < n {
                        inside = inside.max(d);
                    } else {
                        across = across.max(d);
                    }
                }
            }
            assert!(inside > 0, "{}: flat", m.name);
            assert!(
                across <= inside,
                "{}: seam {across} > inside {inside}",
                m.name
            );
        }
    }

    /// An image material: an image twice `MATERIAL_TEXELS` wide becomes texels of 2x2 means
    /// (a 4-texel checker of two colours survives: each mean covers one colour), north up; a
    /// 32-texel image is repeated, each image texel over `MATERIAL_TEXELS / 32` texels.
    #[test]
    fn image_materials_are_filtered_and_north_up() {
        let t = legend().remove(0);
        let red = [200, 30, 30, 255];
        let blue = [20, 40, 220, 255];
        let side = 2 * MATERIAL_TEXELS;
        let half = side / 2;
        // Top half red, bottom half blue, with a 4-texel checker of the two in the top-left
        // quarter.
        let rgba = (0..side * side)
            .map(|k| {
                let (x, y) = (k % side, k / side);
                let checker = x < half && y < half && ((x / 4 + y / 4) % 2 == 1);
                if (y < half) == checker { blue } else { red }
            })
            .collect();
        let m = material_from_image(&t, &MaterialImage { side, rgba });
        let n = MATERIAL_TEXELS as usize;
        let at = |i: usize, j: usize| m.albedo_srgb[j * n + i];
        // Row 0 is the south (image bottom, blue); the last row the north (image top).
        assert_eq!(at(100, 0), blue);
        assert_eq!(at(100, n - 1), red);
        // The checker survives 2x2 filtering: texel (0, n-1) is image (0..2, 0..2), red.
        assert_eq!(at(0, n - 1), red);
        assert_eq!(at(2, n - 1), blue);
        let small = MaterialImage {
            side: 32,
            rgba: (0..32 * 32)
                .map(|k| if k % 32 < 16 { red } else { blue })
                .collect(),
        };
        let m = material_from_image(&t, &small);
        assert_eq!(m.albedo_srgb[n / 2 - 1], red);
        assert_eq!(m.albedo_srgb[n / 2], blue);
        assert!(m.height.contains(&0) && m.height.contains(&255));
    }

    /// From afar a material looks like its legend colour: the mean linear albedo is within 2 %
    /// of the legend colour's (plus sRGB rounding).
    #[test]
    fn mean_albedo_is_the_legend_colour() {
        let l = legend();
        for (t, m) in l.iter().zip(materials(&l, &[], 5)) {
            for c in 0..3 {
                let want = srgb_to_linear(t.color[c]);
                let mean = m
                    .albedo_srgb
                    .iter()
                    .map(|p| srgb_to_linear(p[c]))
                    .sum::<f64>()
                    / m.albedo_srgb.len() as f64;
                assert!(
                    (mean - want).abs() <= 0.02 * want + 0.004,
                    "{} channel {c}: mean {mean}, legend {want}",
                    t.name
                );
            }
        }
    }
}
