//! 16 m tiles of the finest surface: heights and ground types at the leaf vertex spacing, with a
//! margin, generated once and shared (refcounted) by every node that needs them.
//!
//! Tiles are anchored at the map origin; tile (tx, ty) covers
//! `[origin + 16 tx, origin + 16 (tx + 1)]` in x (and likewise y), sampled every
//! [`TILE_SPACING_M`] from `-TILE_MARGIN` to `TILE_CELLS + TILE_MARGIN` samples. The values are
//! exactly `World::height_m` at those points, so a node built from tiles is bit-identical to one
//! built from direct evaluation.

use crate::surface::world::World;
use rustc_hash::FxHashMap;
use std::sync::Arc;

pub const TILE_SIZE_M: f64 = 16.0;
/// Same as the leaf nodes' vertex spacing.
pub const TILE_SPACING_M: f64 = 0.25;
pub const TILE_CELLS: usize = 64;
/// Extra samples on every side (for normals and vegetation reaching over the border).
pub const TILE_MARGIN: usize = 4;
/// Samples per tile side.
pub const TILE_SAMPLES: usize = TILE_CELLS + 1 + 2 * TILE_MARGIN;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TileKey {
    pub tx: i32,
    pub ty: i32,
}

/// One tile's samples, row-major from the south-west corner of the margin.
#[derive(Debug, Clone, PartialEq)]
pub struct Tile {
    pub key: TileKey,
    pub heights_m: Vec<f32>,
    pub ground: Vec<u8>,
}

impl Tile {
    /// World position of sample (0, 0) (the south-west corner of the margin).
    pub fn sample_origin_m(world: &World, key: TileKey) -> [f64; 2] {
        let o = world.origin_m();
        let m = TILE_MARGIN as f64 * TILE_SPACING_M;
        [
            o[0] + f64::from(key.tx) * TILE_SIZE_M - m,
            o[1] + f64::from(key.ty) * TILE_SIZE_M - m,
        ]
    }

    /// Generates a tile: the finest surface on its `TILE_SAMPLES^2` lattice.
    pub fn generate(world: &World, key: TileKey) -> Self {
        let o = Self::sample_origin_m(world, key);
        let n = TILE_SAMPLES;
        let axis =
            |from: f64| -> Vec<f64> { (0..n).map(|i| from + i as f64 * TILE_SPACING_M).collect() };
        let (xs, ys) = (axis(o[0]), axis(o[1]));
        let heights_m: Vec<f32> = world
            .heights_on_lattice(&xs, &ys)
            .iter()
            .map(|&z| z as f32)
            .collect();
        let mut ground = Vec::with_capacity(n * n);
        for &y in &ys {
            ground.extend(xs.iter().map(|&x| world.ground_type(x, y)));
        }
        Self {
            key,
            heights_m,
            ground,
        }
    }

    /// The sample at tile-local index (i, j) counted from the tile's own corner (not the margin).
    pub fn height_at(&self, i: i64, j: i64) -> f32 {
        let (ii, jj) = (
            (i + TILE_MARGIN as i64) as usize,
            (j + TILE_MARGIN as i64) as usize,
        );
        self.heights_m[jj * TILE_SAMPLES + ii]
    }

    pub fn ground_at(&self, i: i64, j: i64) -> u8 {
        let (ii, jj) = (
            (i + TILE_MARGIN as i64) as usize,
            (j + TILE_MARGIN as i64) as usize,
        );
        self.ground[jj * TILE_SAMPLES + ii]
    }

    pub fn bytes(&self) -> usize {
        self.heights_m.len() * 4 + self.ground.len()
    }
}

/// Resident tiles with reference counts; a tile is freed when its last user releases it.
#[derive(Debug, Default)]
pub struct TileCache {
    tiles: FxHashMap<TileKey, (Arc<Tile>, u32)>,
    pub generated: u64,
}

impl TileCache {
    pub fn new() -> Self {
        Self::default()
    }

    /// Takes a reference to the tile, generating it if it is not resident.
    pub fn acquire(&mut self, world: &World, key: TileKey) -> Arc<Tile> {
        if let Some((t, rc)) = self.tiles.get_mut(&key) {
            *rc += 1;
            return Arc::clone(t);
        }
        let t = Arc::new(Tile::generate(world, key));
        self.generated += 1;
        self.tiles.insert(key, (Arc::clone(&t), 1));
        t
    }

    /// Takes a reference to the tile if it is resident.
    pub fn try_acquire(&mut self, key: TileKey) -> Option<Arc<Tile>> {
        self.tiles.get_mut(&key).map(|(t, rc)| {
            *rc += 1;
            Arc::clone(t)
        })
    }

    /// Inserts a tile generated elsewhere (e.g. on a worker) with one reference, or adds a
    /// reference to the resident copy.
    pub fn insert_acquired(&mut self, tile: Arc<Tile>) -> Arc<Tile> {
        let entry = self.tiles.entry(tile.key).or_insert_with(|| (tile, 0));
        entry.1 += 1;
        Arc::clone(&entry.0)
    }

    /// Drops a reference; frees the tile at zero. Releasing a tile that is not held is a caller
    /// bug, reported as false.
    pub fn release(&mut self, key: TileKey) -> bool {
        match self.tiles.get_mut(&key) {
            Some((_, rc)) if *rc > 1 => {
                *rc -= 1;
                true
            }
            Some(_) => {
                self.tiles.remove(&key);
                true
            }
            None => false,
        }
    }

    pub fn refcount(&self, key: TileKey) -> u32 {
        self.tiles.get(&key).map_or(0, |e| e.1)
    }

    pub fn resident(&self) -> usize {
        self.tiles.len()
    }

    pub fn bytes(&self) -> usize {
        self.tiles.values().map(|(t, _)| t.bytes()).sum()
    }
}
