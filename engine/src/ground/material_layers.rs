//! The ground materials as the renderer uploads them: one layer per legend type, each with its
//! mip chain. Made from the legend and the seed ([`super::materials`]) by `worldgen bake` into
//! `pages/derived/ground_materials.bin` (a checked file keyed by the legend, the map's
//! material images, the seed and this code), so that a viewer reads a few megabytes at start-up
//! instead of making them (most of a second on two cores). A map without that file, or with
//! one baked for another map or engine, has them made at start-up, with a warning.

use super::materials::{MATERIAL_TEXELS, MAX_RELIEF_M, Material, material_of};
use crate::surface::World;
use std::path::{Path, PathBuf};
use worldgen::Map;
use worldgen::mip_chain::MipChain;
use worldgen::pages::{PageError, SourceKey, checked_file};

const MAGIC: &[u8; 8] = b"TVSGMAT\0";
const VERSION: u32 = 1;
/// Changes whenever the materials or their layout change, so older bakes are made again.
const CODE_VERSION: u32 = 1;

/// Every layer's texels, RGBA8 (sRGB albedo; in alpha the detail height in steps of
/// [`MAX_RELIEF_M`] / 255 above the material's lowest), layer by layer, each layer's mip levels
/// in order from `MATERIAL_TEXELS` square down to one texel.
#[derive(Debug, Clone, PartialEq)]
pub struct MaterialLayers {
    pub layers: u32,
    pub bytes: Vec<u8>,
}

/// Bytes of one layer with its mip chain.
fn layer_bytes() -> usize {
    (0..=MATERIAL_TEXELS.ilog2())
        .map(|level| ((MATERIAL_TEXELS >> level) as usize).pow(2) * 4)
        .sum()
}

/// The texels of `m` as the renderer stores them.
fn material_texels(m: &Material) -> Vec<u8> {
    let scale = (m.relief_m / MAX_RELIEF_M).clamp(0.0, 1.0);
    m.albedo_srgb
        .iter()
        .zip(&m.height)
        .flat_map(|(&[r, g, b, _], &h)| [r, g, b, (f64::from(h) * scale).round() as u8])
        .collect()
}

/// The layers of `map`'s legend (a flat grey one for an empty legend), made here: one thread
/// per type (the bytes do not depend on the threads).
pub fn make(map: &Map) -> MaterialLayers {
    let seed = u64::from_str_radix(&map.manifest.seed, 16).unwrap_or(0);
    let legend = &map.manifest.ground.legend;
    let mut levels0: Vec<Vec<u8>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..legend.len())
            .map(|i| {
                s.spawn(move || material_texels(&material_of(legend, &map.materials, i, seed)))
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("a material thread panicked"))
            .collect()
    });
    if levels0.is_empty() {
        levels0.push([128, 128, 128, 0].repeat((MATERIAL_TEXELS * MATERIAL_TEXELS) as usize));
    }
    let layers = levels0.len() as u32;
    let bytes = levels0
        .into_iter()
        .flat_map(|level0| MipChain::from_level0(MATERIAL_TEXELS.ilog2(), level0).levels)
        .flatten()
        .collect();
    MaterialLayers { layers, bytes }
}

/// The key of the layers `map` gives: its legend's names and colours, its material images, its
/// seed and this code's version.
pub fn key(map: &Map) -> u64 {
    let mut k = SourceKey::new(0x6A7E_0000 + CODE_VERSION);
    k.update(map.manifest.seed.as_bytes());
    k.update(&MATERIAL_TEXELS.to_le_bytes());
    for (i, t) in map.manifest.ground.legend.iter().enumerate() {
        k.update(&(t.name.len() as u64).to_le_bytes());
        k.update(t.name.as_bytes());
        k.update(&t.color);
        match map.materials.get(i).and_then(Option::as_ref) {
            Some(image) => {
                k.update(&image.side.to_le_bytes());
                k.update(&image.rgba.concat());
            }
            None => k.update(&[0xFF; 4]),
        }
    }
    k.finish()
}

/// Where a bake keeps the layers, under the map's `pages` folder.
pub fn baked_path(pages_dir: &Path) -> PathBuf {
    pages_dir.join("derived").join("ground_materials.bin")
}

/// Writes `map`'s layers to [`baked_path`] (written whole, then moved into place).
pub fn write_baked(map: &Map, pages_dir: &Path) -> Result<(), PageError> {
    let layers = make(map);
    let mut payload = Vec::with_capacity(4 + layers.bytes.len());
    payload.extend_from_slice(&layers.layers.to_le_bytes());
    payload.extend_from_slice(&layers.bytes);
    checked_file::write(&baked_path(pages_dir), MAGIC, VERSION, key(map), &payload)
}

/// The layers in the file `path`, refused (naming the file) unless it is whole and was baked
/// for `key`.
pub fn read_baked(path: &Path, key: u64) -> Result<MaterialLayers, PageError> {
    let mut payload = checked_file::read(path, MAGIC, VERSION, key, "the ground materials")?;
    let layers = payload
        .get(..4)
        .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")));
    match layers {
        Some(layers) if payload.len() == 4 + layers as usize * layer_bytes() => {
            payload.drain(..4);
            Ok(MaterialLayers {
                layers,
                bytes: payload,
            })
        }
        _ => Err(PageError::Header {
            path: path.to_path_buf(),
            problem: "holds another number of bytes than its layers need".into(),
        }),
    }
}

/// `world`'s layers: read from its map's bake where it holds them for this map and engine,
/// else made here (with a warning naming why, for a baked map).
pub fn for_world(world: &World) -> MaterialLayers {
    if let Some(pages) = &world.pages_dir {
        match read_baked(&baked_path(pages), key(&world.map)) {
            Ok(layers) => return layers,
            Err(e) => log::warn!(
                "ground materials made at start-up ({e}); `worldgen bake <map> --finish` bakes them"
            ),
        }
    }
    make(&world.map)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ground::materials::materials;

    /// The layers made on several threads equal the materials made one after another, in the
    /// upload layout; a bake reads back equal, and is refused for another key or when damaged.
    #[test]
    fn layers_equal_the_materials_and_read_back_from_their_bake() {
        let map = crate::test_maps::tiny_map();
        let layers = make(&map);
        let seed = u64::from_str_radix(&map.manifest.seed, 16).unwrap();
        let mats = materials(&map.manifest.ground.legend, &map.materials, seed);
        assert_eq!(layers.layers as usize, mats.len());
        assert_eq!(layers.bytes.len(), mats.len() * layer_bytes());
        let texels = (MATERIAL_TEXELS * MATERIAL_TEXELS) as usize * 4;
        for (i, m) in mats.iter().enumerate() {
            let at = i * layer_bytes();
            assert_eq!(
                layers.bytes[at..at + texels],
                material_texels(m),
                "layer {i}"
            );
        }
        let tmp = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(tmp.path().join("derived")).unwrap();
        write_baked(&map, tmp.path()).unwrap();
        let path = baked_path(tmp.path());
        assert_eq!(read_baked(&path, key(&map)).unwrap(), layers);
        assert!(read_baked(&path, key(&map) ^ 1).is_err());
        let mut bytes = std::fs::read(&path).unwrap();
        let at = bytes.len() / 2;
        bytes[at] ^= 0x40;
        std::fs::write(&path, &bytes).unwrap();
        let e = read_baked(&path, key(&map)).unwrap_err().to_string();
        assert!(e.contains("ground_materials.bin"), "{e}");
    }
}
