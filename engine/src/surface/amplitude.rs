//! The ground amplitude `A` of the detail term: the legend's detail amplitude of each ground
//! sample's type, scaled down on and beside roads and paths so the flattened surface stays flat.
//!
//! A whole grid of it (4 bytes per ground sample: 256 MiB on a 32 km map) repeats what the
//! ground types (1 byte per sample, held by the map) and the legend already say everywhere but
//! near roads. So the world keeps only the samples near roads whose amplitude differs from their
//! type's ([`NearRoads`], a few MiB), in blocks of 64 x 64 samples, and reads every other sample
//! from the ground types ([`Amplitude`]): the same f32 values, bit for bit. A baked map stores
//! [`NearRoads`] in `pages/derived/amplitude_roads.bin`, so its open computes nothing.

use crate::surface::decals::DecalField;
use std::path::{Path, PathBuf};
use worldgen::map::GroundTypes;
use worldgen::pages::{PageError, SourceKey, checked_file};
use worldgen::{Grid, Map};

/// Samples per side of a block of [`NearRoads`].
const BLOCK: usize = 64;
const MAGIC: &[u8; 8] = b"TVS-AMPR";
const VERSION: u32 = 1;

/// The file of a baked map's [`NearRoads`] in its `pages` folder.
pub fn near_roads_path(pages_dir: &Path) -> PathBuf {
    pages_dir.join("derived").join("amplitude_roads.bin")
}

/// The ground samples whose amplitude is not their type's (near roads), by block of
/// 64 x 64 samples: block `b`'s samples are `local[offsets[b]..offsets[b + 1]]`
/// (the index inside the block, ascending) with their amplitudes in `value`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NearRoads {
    width: usize,
    height: usize,
    offsets: Vec<u32>,
    local: Vec<u16>,
    value: Vec<f32>,
}

impl NearRoads {
    fn blocks_per_row(width: usize) -> usize {
        width.div_ceil(BLOCK)
    }

    /// The samples of `amplitude_m` that differ (bitwise) from their type's amplitude
    /// (`legend[ground]`).
    pub fn new(amplitude_m: &Grid<f32>, ground: &Grid<u8>, legend: &[f32]) -> Self {
        let (width, height) = (amplitude_m.width(), amplitude_m.height());
        let per_row = Self::blocks_per_row(width);
        let blocks = per_row * height.div_ceil(BLOCK);
        let mut out = Self {
            width,
            height,
            offsets: Vec::with_capacity(blocks + 1),
            local: Vec::new(),
            value: Vec::new(),
        };
        out.offsets.push(0);
        for b in 0..blocks {
            let (bx, by) = (b % per_row * BLOCK, b / per_row * BLOCK);
            for y in by..(by + BLOCK).min(height) {
                for x in bx..(bx + BLOCK).min(width) {
                    let a = amplitude_m.get(x, y);
                    if a.to_bits() != type_amplitude_m(legend, ground.get(x, y)).to_bits() {
                        out.local.push(((y - by) * BLOCK + x - bx) as u16);
                        out.value.push(a);
                    }
                }
            }
            out.offsets.push(out.local.len() as u32);
        }
        out
    }

    /// The amplitude of sample (`x`, `y`) when it is not its type's.
    #[inline]
    fn get(&self, x: usize, y: usize) -> Option<f32> {
        let b = (y / BLOCK) * Self::blocks_per_row(self.width) + x / BLOCK;
        let (lo, hi) = (self.offsets[b] as usize, self.offsets[b + 1] as usize);
        if lo == hi {
            return None;
        }
        let want = ((y % BLOCK) * BLOCK + x % BLOCK) as u16;
        let i = self.local[lo..hi].binary_search(&want).ok()?;
        Some(self.value[lo + i])
    }

    /// Heap bytes.
    pub fn bytes(&self) -> usize {
        self.offsets.len() * 4 + self.local.len() * 2 + self.value.len() * 4
    }

    /// How many samples differ from their type's amplitude.
    pub fn len(&self) -> usize {
        self.local.len()
    }

    pub fn is_empty(&self) -> bool {
        self.local.is_empty()
    }

    fn payload(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.bytes() + 16);
        for v in [self.width, self.height, self.local.len()] {
            out.extend_from_slice(&(v as u32).to_le_bytes());
        }
        for v in &self.offsets {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for v in &self.local {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for v in &self.value {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out
    }

    /// Writes the file `path` for `key` ([`worldgen::pages::checked_file`]; payload: width,
    /// height and count as u32, the block offsets, the local indices, the values).
    pub fn write(&self, path: &Path, key: u64) -> Result<(), PageError> {
        checked_file::write(path, MAGIC, VERSION, key, &self.payload())
    }

    /// Reads the file `path`, refused (naming the file) unless it is whole, was written for
    /// `key` and holds a `width` x `height` raster.
    pub fn read(path: &Path, key: u64, width: usize, height: usize) -> Result<Self, PageError> {
        let what = "the ground amplitude near roads";
        let payload = checked_file::read(path, MAGIC, VERSION, key, what)?;
        let payload = payload.as_slice();
        let bad = |problem: &str| PageError::Header {
            path: path.to_path_buf(),
            problem: problem.into(),
        };
        if payload.len() < 12 {
            return Err(bad("cut short"));
        }
        let u32_at = |b: &[u8], at: usize| u32::from_le_bytes(b[at..at + 4].try_into().expect("4"));
        let (w, h, n) = (
            u32_at(payload, 0) as usize,
            u32_at(payload, 4) as usize,
            u32_at(payload, 8) as usize,
        );
        let blocks = Self::blocks_per_row(w) * h.div_ceil(BLOCK);
        if (w, h) != (width, height) || payload.len() != 12 + (blocks + 1) * 4 + n * 6 {
            return Err(bad("holds another raster size or is cut short"));
        }
        let mut at = 12;
        let mut next = |len: usize| {
            let s = &payload[at..at + len];
            at += len;
            s
        };
        let offsets: Vec<u32> = next((blocks + 1) * 4)
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().expect("4")))
            .collect();
        let local: Vec<u16> = next(n * 2)
            .chunks_exact(2)
            .map(|c| u16::from_le_bytes(c.try_into().expect("2")))
            .collect();
        let value: Vec<f32> = next(n * 4)
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().expect("4")))
            .collect();
        let ordered = offsets.first() == Some(&0)
            && offsets.last() == Some(&(n as u32))
            && offsets.windows(2).all(|p| p[0] <= p[1])
            && offsets.windows(2).all(|p| {
                let s = &local[p[0] as usize..p[1] as usize];
                s.windows(2).all(|q| q[0] < q[1])
                    && s.iter().all(|&l| usize::from(l) < BLOCK * BLOCK)
            });
        if !ordered {
            return Err(bad("its blocks are out of order"));
        }
        Ok(Self {
            width: w,
            height: h,
            offsets,
            local,
            value,
        })
    }
}

/// The amplitude raster as the interpolators read it: a sample's type's amplitude unless it is
/// near a road.
pub struct Amplitude<'a> {
    pub ground: &'a GroundTypes,
    pub legend_m: &'a [f32],
    pub near_roads: &'a NearRoads,
}

impl worldgen::sample::Samples for Amplitude<'_> {
    #[inline]
    fn width(&self) -> usize {
        self.ground.width()
    }
    #[inline]
    fn height(&self) -> usize {
        self.ground.height()
    }
    #[inline]
    fn at(&self, x: usize, y: usize) -> f32 {
        self.near_roads
            .get(x, y)
            .unwrap_or_else(|| type_amplitude_m(self.legend_m, self.ground.get(x, y)))
    }
}

/// The legend's amplitude of ground type `t` (`legend`'s last for a type past its end: a paged
/// ground layer is not checked against the legend at the open; 0 for an empty legend).
#[inline]
fn type_amplitude_m(legend: &[f32], t: u8) -> f32 {
    let last = legend.len().saturating_sub(1);
    legend.get(usize::from(t).min(last)).copied().unwrap_or(0.0)
}

/// The legend's detail amplitude per ground type.
pub fn legend_m(map: &Map) -> Vec<f32> {
    map.manifest
        .ground
        .legend
        .iter()
        .map(|t| t.detail_amplitude_m)
        .collect()
}

/// The key of the amplitude's inputs: the ground types, the legend's amplitudes, the decal
/// field's key (roads suppress detail) and the code's version.
pub fn key(map: &Map, decals_key: u64) -> u64 {
    let mut k = SourceKey::new(0xA3B1_0001);
    k.update(&map.ground.key().to_le_bytes());
    k.update(&decals_key.to_le_bytes());
    for t in &map.manifest.ground.legend {
        k.update(&t.detail_amplitude_m.to_le_bytes());
    }
    k.finish()
}

/// The detail amplitude (m) at each ground sample: the legend's, suppressed on roads.
pub fn grid(map: &Map, decals: &DecalField) -> Grid<f32> {
    let legend = legend_m(map);
    let ground = map.ground.whole_or_filled("ground types");
    let mut amplitude_m = ground.map(|g| type_amplitude_m(&legend, g));
    suppress_detail_on_roads(&mut amplitude_m, map, decals);
    amplitude_m
}

/// Scales the detail amplitude down to zero at ground samples near roads and paths, so the
/// flattened surface stays flat: a ground sample within one ground-cell diagonal of a road
/// lattice sample of weight `w` keeps at most `1 - w` of its amplitude. Then A (bilinear) is zero
/// everywhere on a road's core and falloff.
fn suppress_detail_on_roads(amplitude_m: &mut Grid<f32>, map: &Map, decals: &DecalField) {
    let gs = map.manifest.ground.spacing_m;
    let o = map.manifest.origin_m;
    let reach = gs * std::f64::consts::SQRT_2;
    let (w, h) = (amplitude_m.width() as i64, amplitude_m.height() as i64);
    let mut keep = Grid::new(amplitude_m.width(), amplitude_m.height(), 1.0f32);
    for (p, weight) in decals.road_samples() {
        let (gx, gy) = ((p[0] - o[0]) / gs, (p[1] - o[1]) / gs);
        let (x0, x1) = (
            (gx - reach / gs).floor() as i64,
            (gx + reach / gs).ceil() as i64,
        );
        let (y0, y1) = (
            (gy - reach / gs).floor() as i64,
            (gy + reach / gs).ceil() as i64,
        );
        for y in y0.max(0)..=y1.min(h - 1) {
            for x in x0.max(0)..=x1.min(w - 1) {
                let d = (x as f64 - gx).hypot(y as f64 - gy) * gs;
                if d <= reach {
                    let k = keep.get(x as usize, y as usize).min((1.0 - weight) as f32);
                    keep.set(x as usize, y as usize, k);
                }
            }
        }
    }
    for y in 0..amplitude_m.height() {
        for x in 0..amplitude_m.width() {
            amplitude_m.set(x, y, amplitude_m.get(x, y) * keep.get(x, y));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use worldgen::sample::Samples;

    /// Every sample of the tiny map's amplitude read through [`Amplitude`] equals the whole
    /// grid's bit for bit, also after a write and read of [`NearRoads`]; a damaged or foreign
    /// file is refused naming the file.
    #[test]
    fn near_roads_and_ground_types_give_the_whole_grid_bit_for_bit() {
        let map = crate::test_maps::tiny_map();
        let decals = DecalField::new(
            &map.decals,
            map.manifest.origin_m,
            map.manifest.size_m,
            |x, y| map.height_bicubic_m(x, y),
        );
        let whole = grid(&map, &decals);
        let legend = legend_m(&map);
        let ground = map.ground.grid().expect("the tiny map is held whole");
        let near = NearRoads::new(&whole, ground, &legend);
        assert!(!near.is_empty(), "the tiny map has roads");
        assert!(
            near.len() * 10 < whole.data().len(),
            "{} samples near roads",
            near.len()
        );
        let dir = std::env::temp_dir().join(format!("tvs-ampr-{}", std::process::id()));
        let path = near_roads_path(&dir);
        near.write(&path, 7).expect("write");
        let read = NearRoads::read(&path, 7, whole.width(), whole.height()).expect("read");
        assert_eq!(read, near);
        for n in [&near, &read] {
            let a = Amplitude {
                ground: &map.ground,
                legend_m: &legend,
                near_roads: n,
            };
            for y in 0..whole.height() {
                for x in 0..whole.width() {
                    assert_eq!(
                        a.at(x, y).to_bits(),
                        whole.get(x, y).to_bits(),
                        "({x}, {y})"
                    );
                }
            }
        }
        assert!(NearRoads::read(&path, 8, whole.width(), whole.height()).is_err());
        let mut bytes = std::fs::read(&path).expect("bytes");
        let n = bytes.len();
        bytes[n - 3] ^= 1;
        std::fs::write(&path, &bytes).expect("damage");
        let err = NearRoads::read(&path, 7, whole.width(), whole.height()).expect_err("damaged");
        assert!(err.to_string().contains("amplitude_roads.bin"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
