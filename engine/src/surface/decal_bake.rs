//! The decal field baked by `worldgen bake` and opened without deriving it: its tiles in a tile
//! file (`decal_tiles`), its small global part (coarse bounds, occupancy, counts) in
//! that file's tail, all keyed by [`DecalField::bake_key`].

pub use super::decal_tiles::TileStats;
use super::decal_tiles::{self, Bytes, TILE_LEVELS, TileFile};
#[cfg(test)]
use super::decals::DECAL_SPACING_M;
use super::decals::{DecalField, Tiles, key, unkey};
use super::levels::PageFaults;
use rustc_hash::FxHashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use worldgen::Map;
use worldgen::pages::{PageError, SourceKey};

/// Changes whenever the decal field's construction or its file's encoding changes, so files
/// baked by another engine are refused.
const DECAL_FIELD_VERSION: u64 = 2;

/// The decal tile file of a map's `pages` folder.
pub fn tiles_path(pages_dir: &Path) -> PathBuf {
    pages_dir.join("derived").join("decals.tiles")
}

impl DecalField {
    /// The key of what the field is made from: the map's decals, origin and size, the key of its
    /// heights (offsets flatten the bicubic heights) and this code's version.
    pub fn bake_key(map: &Map, heights_key: u64) -> u64 {
        let mut k = SourceKey::new(0xDEC0_0001);
        for v in [
            DECAL_FIELD_VERSION,
            heights_key,
            map.manifest.origin_m[0].to_bits(),
            map.manifest.origin_m[1].to_bits(),
            map.manifest.size_m[0].to_bits(),
            map.manifest.size_m[1].to_bits(),
            map.decals.len() as u64,
        ] {
            k.update(&v.to_le_bytes());
        }
        for d in &map.decals {
            k.update(format!("{:?}", d.kind).as_bytes());
            k.update(&[u8::from(d.closed)]);
            for v in [d.width_m, d.falloff_m, d.height_offset_m] {
                k.update(&v.to_le_bytes());
            }
            k.update(&(d.points.len() as u64).to_le_bytes());
            for p in &d.points {
                for v in p {
                    k.update(&v.to_le_bytes());
                }
            }
        }
        k.finish()
    }

    /// Writes this field (made in memory) as the tile file `path` keyed by `key`.
    pub fn write_tiles(&self, path: &Path, key: u64) -> Result<(), PageError> {
        let Tiles::Memory(tiles) = &self.tiles else {
            return Err(PageError::Request {
                path: path.to_path_buf(),
                problem: "a baked decal field cannot be baked again; open the map without it"
                    .into(),
            });
        };
        decal_tiles::write(path, key, tiles, &self.encode_global())
    }

    /// Opens the tile file `path` baked with `key` for a map at `origin_m`: reads its index and
    /// global part; tiles are read on first use and kept under `budget_bytes`, and a tile that
    /// cannot be read is recorded in `faults`.
    pub fn open_tiles(
        path: &Path,
        key: u64,
        origin_m: [f64; 2],
        budget_bytes: usize,
        faults: Arc<PageFaults>,
    ) -> Result<Self, PageError> {
        let (file, global) = TileFile::open(path, key, budget_bytes, faults)?;
        let mut field = Self::decode_global(&global).ok_or_else(|| PageError::Header {
            path: path.to_path_buf(),
            problem: "the decal field's global part does not parse; bake the map again".into(),
        })?;
        field.origin_m = origin_m;
        field.tiles = Tiles::File(Arc::new(file));
        Ok(field)
    }

    /// Tiles read from the file, hits, evictions and resident bytes, for a baked field.
    pub fn tile_stats(&self) -> Option<TileStats> {
        match &self.tiles {
            Tiles::File(f) => Some(f.stats()),
            Tiles::Memory(_) => None,
        }
    }

    /// How many tiles hold decal data.
    pub fn tile_count(&self) -> usize {
        match &self.tiles {
            Tiles::File(f) => f.tile_count(),
            Tiles::Memory(m) => m.len(),
        }
    }

    /// The counts, the coarse grids and the bound levels from [`TILE_LEVELS`] on, in a fixed
    /// order (sorted keys).
    fn encode_global(&self) -> Vec<u8> {
        let mut out = Vec::new();
        for v in [
            self.bound_levels as u64,
            self.block_count as u64,
            self.road_count as u64,
            self.coarse_dims[0] as u64,
            self.coarse_dims[1] as u64,
        ] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&self.coarse_cell_m.to_le_bytes());
        out.extend(self.coarse.iter().map(|&b| u8::from(b)));
        out.extend(self.road_cells.iter().map(|&b| u8::from(b)));
        out.extend_from_slice(&(self.upper_bounds.len() as u64).to_le_bytes());
        for level in &self.upper_bounds {
            let mut cells: Vec<(u64, [f32; 3])> = level.iter().map(|(&k, &v)| (k, v)).collect();
            cells.sort_unstable_by_key(|c| unkey(c.0));
            out.extend_from_slice(&(cells.len() as u64).to_le_bytes());
            for (k, v) in cells {
                out.extend_from_slice(&k.to_le_bytes());
                for x in v {
                    out.extend_from_slice(&x.to_le_bytes());
                }
            }
        }
        out
    }

    /// The field (without tiles and origin) from [`Self::encode_global`]'s bytes; `None`
    /// where they do not parse.
    fn decode_global(bytes: &[u8]) -> Option<Self> {
        let mut r = Bytes(bytes);
        let (bound_levels, block_count, road_count) = (r.u64()?, r.u64()?, r.u64()?);
        let dims = [r.u64()? as usize, r.u64()? as usize];
        let coarse_cell_m = r.f64()?;
        let cells = dims[0].checked_mul(dims[1])?;
        let coarse = r.take(cells)?.iter().map(|&b| b != 0).collect();
        let road_cells = r.take(cells)?.iter().map(|&b| b != 0).collect();
        let upper_count = r.u64()? as usize;
        if bound_levels as usize != upper_count + TILE_LEVELS.min(bound_levels as usize) {
            return None;
        }
        let mut upper_bounds = Vec::with_capacity(upper_count);
        for _ in 0..upper_count {
            let n = r.u64()? as usize;
            let mut level = FxHashMap::default();
            for _ in 0..n {
                let k = r.u64()?;
                let (bx, by) = unkey(k);
                level.insert(key(bx, by), [r.f32()?, r.f32()?, r.f32()?]);
            }
            upper_bounds.push(level);
        }
        if !r.0.is_empty() || !(coarse_cell_m > 0.0) {
            return None;
        }
        Some(Self {
            origin_m: [0.0; 2],
            tiles: Tiles::default(),
            upper_bounds,
            bound_levels: bound_levels as usize,
            block_count: block_count as usize,
            road_count: road_count as usize,
            road_cells,
            coarse,
            coarse_dims: dims,
            coarse_cell_m,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::surface::World;
    use crate::test_maps::tiny_map;

    /// The tiny map's world and its decal field written as a tile file keyed `key`.
    fn baked_tiny(name: &str, key: u64) -> (World, PathBuf) {
        let dir = std::env::temp_dir().join(format!("tvs-decal-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp folder");
        let path = dir.join("decals.tiles");
        let world = World::without_error_grids(tiny_map());
        world.decals.write_tiles(&path, key).expect("written");
        (world, path)
    }

    /// Points of the tiny map's decal lattice region on a step that is no multiple of the
    /// lattice spacing, a little beyond the map's edges.
    fn points(world: &World) -> Vec<[f64; 2]> {
        let (o, size) = (world.origin_m(), world.size_m());
        let mut out = Vec::new();
        for j in 0..200 {
            for i in 0..200 {
                let (fx, fy) = (f64::from(i) / 199.0, f64::from(j) / 199.0);
                out.push([
                    o[0] - 3.0 + fx * (size[0] + 6.0),
                    o[1] - 3.0 + fy * (size[1] + 6.0),
                ]);
            }
        }
        out
    }

    /// Every query of a baked field equals the computed field's bit for bit, with a budget of
    /// one tile (every change of tile reads it again from the file).
    #[test]
    fn a_baked_field_answers_like_the_computed_one_through_evictions() {
        let (world, path) = baked_tiny("same", 7);
        let computed = &world.decals;
        let faults = Arc::new(PageFaults::default());
        let baked = DecalField::open_tiles(&path, 7, world.origin_m(), 1, Arc::clone(&faults))
            .expect("opened");
        assert!(
            computed.tile_count() >= 4,
            "{} tiles",
            computed.tile_count()
        );
        assert_eq!(baked.tile_count(), computed.tile_count());
        let mut on_roads = 0;
        for p in points(&world) {
            let (x, y) = (p[0], p[1]);
            let e = computed.offset_m(x, y);
            assert_eq!(
                baked.offset_m(x, y).to_bits(),
                e.to_bits(),
                "offset at {p:?}"
            );
            assert_eq!(baked.road_weight(x, y), computed.road_weight(x, y), "{p:?}");
            assert_eq!(baked.road_near(x, y, 2.0), computed.road_near(x, y, 2.0));
            on_roads += usize::from(e != 0.0);
            for r in [0.3, 3.0, 17.0, 90.0, 400.0] {
                let (lo, hi) = ([x - r, y - r * 0.5], [x + r, y + r]);
                assert_eq!(
                    baked.region_bounds(lo, hi),
                    computed.region_bounds(lo, hi),
                    "bounds of {r} m at {p:?}"
                );
            }
        }
        assert!(on_roads > 1000, "{on_roads} points on decals");
        let xs: Vec<f64> = (0..300).map(|i| 100.0 + f64::from(i) * 0.31).collect();
        let ys: Vec<f64> = (0..250).map(|j| 40.0 + f64::from(j) * 1.7).collect();
        let o = world.origin_m();
        let (xs, ys): (Vec<f64>, Vec<f64>) = (
            xs.iter().map(|x| x + o[0]).collect(),
            ys.iter().map(|y| y + o[1]).collect(),
        );
        assert_eq!(
            baked.offsets_on_lattice(&xs, &ys),
            computed.offsets_on_lattice(&xs, &ys)
        );
        let sorted = |f: &DecalField| {
            let mut v: Vec<[u64; 3]> = f
                .road_samples()
                .into_iter()
                .map(|(p, w)| [p[0].to_bits(), p[1].to_bits(), w.to_bits()])
                .collect();
            v.sort_unstable();
            v
        };
        assert_eq!(sorted(&baked), sorted(computed));
        let stats = baked.tile_stats().expect("a baked field");
        assert!(stats.evictions > 100 && stats.tile_ins > 100, "{stats:?}");
        assert!(faults.list().is_empty(), "{:?}", faults.list());
    }

    /// A damaged tile (the largest): its offsets are zero and its bounds unbounded, the fault
    /// names the file and the tile, every other tile still answers as computed. A truncated file, or one
    /// baked with another key, is refused at the open with the file's name.
    #[test]
    fn a_damaged_tile_is_reported_and_the_others_still_answer() {
        let (world, path) = baked_tiny("damaged", 9);
        let computed = &world.decals;
        let faults = Arc::new(PageFaults::default());
        let origin = world.origin_m();
        let open = || DecalField::open_tiles(&path, 9, origin, 1 << 20, Arc::clone(&faults));
        let Tiles::File(file) = &open().expect("opened").tiles else {
            panic!("a baked field reads its file");
        };
        // The largest tile gets a flipped byte in its middle.
        let (first, (offset, len)) = file
            .tiles()
            .into_iter()
            .filter_map(|t| Some((t, file.span(t)?)))
            .max_by_key(|(_, span)| span.1)
            .expect("tiles");
        let mut bytes = std::fs::read(&path).expect("read back");
        bytes[(offset + u64::from(len / 2)) as usize] ^= 0x40;
        std::fs::write(&path, &bytes).expect("damaged");
        let baked = open().expect("the index is intact");
        let tile_m = DECAL_SPACING_M * decal_tiles::TILE_SAMPLES as f64;
        let in_first = |p: &[f64; 2]| {
            let t = |v: f64, o: f64| ((v - o) / tile_m).floor() as i64;
            (t(p[0], origin[0]), t(p[1], origin[1])) == first
        };
        let (mut zeroed, mut others) = (0, 0);
        for p in points(&world) {
            let (want, got) = (computed.offset_m(p[0], p[1]), baked.offset_m(p[0], p[1]));
            // Points whose stencil reaches into the damaged tile may read it; the rest never do.
            let near_first = [[-2.0, -2.0], [2.0, -2.0], [-2.0, 2.0], [2.0, 2.0]]
                .iter()
                .any(|d| in_first(&[p[0] + d[0], p[1] + d[1]]));
            if in_first(&p) && want != 0.0 {
                assert_eq!(got, 0.0, "{p:?}");
                zeroed += 1;
            } else if !near_first {
                assert_eq!(got.to_bits(), want.to_bits(), "{p:?}");
                others += usize::from(want != 0.0);
            }
        }
        assert!(
            zeroed > 10 && others > 100,
            "{zeroed} zeroed, {others} others"
        );
        let corner = [
            origin[0] + first.0 as f64 * tile_m + 1.0,
            origin[1] + first.1 as f64 * tile_m + 1.0,
        ];
        let b = baked.region_bounds(corner, [corner[0] + 2.0, corner[1] + 2.0]);
        assert!(
            b.slope.is_infinite() && b.magnitude_m.is_infinite(),
            "{b:?}"
        );
        let listed = faults.list();
        assert_eq!(listed.len(), 1, "{listed:?}");
        let tile = format!("decal tile ({}, {})", first.0, first.1);
        assert!(
            listed[0].contains(&path.display().to_string()) && listed[0].contains(&tile),
            "{listed:?}"
        );
        let refused = |key: u64| {
            DecalField::open_tiles(&path, key, origin, 1 << 20, Arc::new(PageFaults::default()))
                .map(|_| ())
                .expect_err("refused")
                .to_string()
        };
        assert!(refused(10).contains("another map"), "{}", refused(10));
        std::fs::write(&path, &bytes[..bytes.len() - 5]).expect("truncated");
        let why = refused(9);
        assert!(why.contains(&path.display().to_string()), "{why}");
    }
}
