//! The decal field's data by tile: its samples, its fine bounds and its road weights cut into
//! tiles of [`TILE_BLOCKS`] x [`TILE_BLOCKS`] blocks (64 m), held in memory or read tile by tile
//! from the file `worldgen bake` writes ([`write`], [`TileFile`]).
//!
//! The file: a 32-byte header (`TVSDECAL`, version, the key of the map and code it was baked
//! from, the offset of its index, the tile count), the tiles one after another, then the index
//! (per tile its position, length and checksum), the field's small global part (the coarse
//! bounds and occupancy, encoded by [`super::decals`]) and a checksum of index and global part.
//! An open reads the header and that tail only; a tile is read on first use with a positioned
//! read, its checksum checked, and kept under a byte budget, least recently used dropped first.
//! A file truncated or damaged after the open gives an error naming the file and the tile,
//! never a crash. The tiles are not a page file ([`worldgen::pages`]): their sizes vary with the
//! roads in them, so they are found through the index rather than at fixed offsets.

use super::levels::PageFaults;
use rustc_hash::FxHashMap;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};
use worldgen::pages::{PageError, SourceKey};

/// Samples per block side (the decal field's unit of storage).
pub(crate) const BLOCK: i64 = 8;
/// Samples per block.
pub(crate) const BLOCK_SAMPLES: usize = (BLOCK * BLOCK) as usize;
/// Blocks per tile side: a tile is 64 m. Small tiles keep what a coarse node's sparse lattice
/// reads small: each of its points near a road reads the tile under it (with 256 m tiles the
/// 32 km map's coarse levels read every tile again and again, beyond any sensible budget).
pub(crate) const TILE_BLOCKS: i64 = 16;
/// Samples per tile side.
pub(crate) const TILE_SAMPLES: i64 = TILE_BLOCKS * BLOCK;
/// Bound levels kept in the tiles (levels `0..TILE_LEVELS`, cells of `2^k` blocks, level
/// `TILE_LEVELS` one cell per tile); coarser levels are the field's global part.
pub(crate) const TILE_LEVELS: usize = 4;

const MAGIC: &[u8; 8] = b"TVSDECAL";
const VERSION: u32 = 1;
const HEADER_BYTES: u64 = 32;
const INDEX_ENTRY_BYTES: usize = 36;

/// Values by key, the keys sorted and unique: looked up by binary search. A tile is kept in
/// this form so that reading one from its file is a copy, with no hashing or allocation per
/// entry (the coarse nodes' sparse lattices read a tile for a few points).
#[derive(Debug, PartialEq)]
pub(crate) struct Sorted<K, V> {
    keys: Vec<K>,
    values: Vec<V>,
}

impl<K, V> Default for Sorted<K, V> {
    fn default() -> Self {
        Self {
            keys: Vec::new(),
            values: Vec::new(),
        }
    }
}

impl<K: Ord + Copy, V> Sorted<K, V> {
    /// The entries of `map` in key order.
    pub(crate) fn from_map(map: FxHashMap<K, V>) -> Self {
        let mut entries: Vec<(K, V)> = map.into_iter().collect();
        entries.sort_unstable_by_key(|e| e.0);
        let (keys, values) = entries.into_iter().unzip();
        Self { keys, values }
    }

    #[inline]
    pub(crate) fn get(&self, key: K) -> Option<&V> {
        self.keys.binary_search(&key).ok().map(|i| &self.values[i])
    }

    pub(crate) fn len(&self) -> usize {
        self.keys.len()
    }

    pub(crate) fn iter(&self) -> impl Iterator<Item = (K, &V)> + '_ {
        self.keys.iter().copied().zip(&self.values)
    }

    /// Appends an entry; false (nothing added) unless its key is above every key so far.
    fn push(&mut self, key: K, value: V) -> bool {
        if self.keys.last().is_some_and(|&k| k >= key) {
            return false;
        }
        self.keys.push(key);
        self.values.push(value);
        true
    }

    fn bytes(&self) -> usize {
        self.keys.capacity() * std::mem::size_of::<K>()
            + self.values.capacity() * std::mem::size_of::<V>()
    }
}

/// A tile: blocks, bound cells and road weights by their index inside the tile (row-major from
/// its south-west corner).
#[derive(Debug, Default, PartialEq)]
pub(crate) struct Tile {
    pub blocks: Sorted<u16, [f32; BLOCK_SAMPLES]>,
    /// Level k: cells of 2^k x 2^k blocks, `TILE_BLOCKS >> k` per tile side; slope, curvature,
    /// magnitude.
    pub bounds: [Sorted<u16, [f32; 3]>; TILE_LEVELS],
    /// Per sample (index `y * TILE_SAMPLES + x`) with a road, path or pad: its largest weight.
    pub road_weight: Sorted<u32, f32>,
}

/// The tile of a coordinate and the coordinate inside it, for tiles `per_tile` units wide.
#[inline]
pub(crate) fn split(v: i64, per_tile: i64) -> (i64, i64) {
    (v.div_euclid(per_tile), v.rem_euclid(per_tile))
}

impl Tile {
    /// Heap bytes.
    pub(crate) fn bytes(&self) -> usize {
        self.blocks.bytes()
            + self.bounds.iter().map(Sorted::bytes).sum::<usize>()
            + self.road_weight.bytes()
    }

    /// The tile's bytes in the file, entries in key order.
    fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.bytes() + 64);
        out.extend_from_slice(&(self.blocks.len() as u32).to_le_bytes());
        for (i, b) in self.blocks.iter() {
            out.extend_from_slice(&i.to_le_bytes());
            for v in b {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        for level in &self.bounds {
            out.extend_from_slice(&(level.len() as u32).to_le_bytes());
            for (i, c) in level.iter() {
                out.extend_from_slice(&i.to_le_bytes());
                for v in c {
                    out.extend_from_slice(&v.to_le_bytes());
                }
            }
        }
        out.extend_from_slice(&(self.road_weight.len() as u32).to_le_bytes());
        for (i, w) in self.road_weight.iter() {
            out.extend_from_slice(&i.to_le_bytes());
            out.extend_from_slice(&w.to_le_bytes());
        }
        out
    }

    /// The tile from its bytes; `None` where they do not parse (counts beyond the bytes,
    /// indices outside the tile or out of order) or bytes are left over.
    fn decode(bytes: &[u8]) -> Option<Tile> {
        let mut r = Bytes(bytes);
        let mut tile = Tile::default();
        let count = |r: &mut Bytes<'_>, entry_bytes: usize| -> Option<usize> {
            let n = r.u32()? as usize;
            // A count the remaining bytes cannot hold is refused before reserving for it.
            (n.checked_mul(entry_bytes)? <= r.0.len()).then_some(n)
        };
        let n = count(&mut r, 2 + BLOCK_SAMPLES * 4)?;
        tile.blocks.keys.reserve_exact(n);
        tile.blocks.values.reserve_exact(n);
        for _ in 0..n {
            let index = r.u16()?;
            let mut b = [0.0f32; BLOCK_SAMPLES];
            for v in &mut b {
                *v = r.f32()?;
            }
            if index >= (TILE_BLOCKS * TILE_BLOCKS) as u16 || !tile.blocks.push(index, b) {
                return None;
            }
        }
        for (k, level) in tile.bounds.iter_mut().enumerate() {
            let side = (TILE_BLOCKS >> k) as u32;
            for _ in 0..count(&mut r, 2 + 12)? {
                let i = r.u16()?;
                let cell = [r.f32()?, r.f32()?, r.f32()?];
                if u32::from(i) >= side * side || !level.push(i, cell) {
                    return None;
                }
            }
        }
        let n = count(&mut r, 8)?;
        tile.road_weight.keys.reserve_exact(n);
        tile.road_weight.values.reserve_exact(n);
        for _ in 0..n {
            let (i, w) = (r.u32()?, r.f32()?);
            if u64::from(i) >= (TILE_SAMPLES * TILE_SAMPLES) as u64 || !tile.road_weight.push(i, w)
            {
                return None;
            }
        }
        r.0.is_empty().then_some(tile)
    }
}

/// A little-endian reader over a byte slice; every read checks the length.
pub(crate) struct Bytes<'a>(pub &'a [u8]);

impl<'a> Bytes<'a> {
    pub(crate) fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        if self.0.len() < n {
            return None;
        }
        let (head, rest) = self.0.split_at(n);
        self.0 = rest;
        Some(head)
    }
    fn array<const N: usize>(&mut self) -> Option<[u8; N]> {
        self.take(N)?.try_into().ok()
    }
    pub(crate) fn u16(&mut self) -> Option<u16> {
        self.array().map(u16::from_le_bytes)
    }
    pub(crate) fn u32(&mut self) -> Option<u32> {
        self.array().map(u32::from_le_bytes)
    }
    pub(crate) fn u64(&mut self) -> Option<u64> {
        self.array().map(u64::from_le_bytes)
    }
    pub(crate) fn i64(&mut self) -> Option<i64> {
        self.array().map(i64::from_le_bytes)
    }
    pub(crate) fn f32(&mut self) -> Option<f32> {
        self.array().map(f32::from_le_bytes)
    }
    pub(crate) fn f64(&mut self) -> Option<f64> {
        self.array().map(f64::from_le_bytes)
    }
}

fn checksum(bytes: &[u8]) -> u64 {
    let mut k = SourceKey::new(0xDEC0_0000);
    k.update(bytes);
    k.finish()
}

/// Writes `tiles` and the field's global part as the tile file `path` (through a hidden partial
/// file beside it, renamed when complete), keyed by `key`.
pub(crate) fn write(
    path: &Path,
    key: u64,
    tiles: &FxHashMap<(i64, i64), Arc<Tile>>,
    global: &[u8],
) -> Result<(), PageError> {
    let io = |action, source| PageError::Io {
        path: path.to_path_buf(),
        action,
        source,
    };
    let partial = worldgen::pages::fresh_partial_path(path)?;
    let mut order: Vec<(i64, i64)> = tiles.keys().copied().collect();
    order.sort_unstable();
    let mut body = Vec::new();
    let mut index = Vec::with_capacity(order.len() * INDEX_ENTRY_BYTES + global.len() + 16);
    for t in &order {
        let bytes = tiles[t].encode();
        index.extend_from_slice(&t.0.to_le_bytes());
        index.extend_from_slice(&t.1.to_le_bytes());
        index.extend_from_slice(&(HEADER_BYTES + body.len() as u64).to_le_bytes());
        index.extend_from_slice(&(bytes.len() as u32).to_le_bytes());
        index.extend_from_slice(&checksum(&bytes).to_le_bytes());
        body.extend_from_slice(&bytes);
    }
    index.extend_from_slice(&(global.len() as u64).to_le_bytes());
    index.extend_from_slice(global);
    let tail_sum = checksum(&index);
    index.extend_from_slice(&tail_sum.to_le_bytes());
    let mut header = Vec::with_capacity(HEADER_BYTES as usize);
    header.extend_from_slice(MAGIC);
    header.extend_from_slice(&VERSION.to_le_bytes());
    header.extend_from_slice(&key.to_le_bytes());
    header.extend_from_slice(&(HEADER_BYTES + body.len() as u64).to_le_bytes());
    header.extend_from_slice(&(order.len() as u32).to_le_bytes());
    {
        use std::io::Write;
        let file = std::fs::File::create(&partial).map_err(|e| io("create", e))?;
        let mut w = std::io::BufWriter::new(file);
        for part in [&header, &body, &index] {
            w.write_all(part).map_err(|e| io("write", e))?;
        }
        let file = w.into_inner().map_err(|e| io("write", e.into_error()))?;
        file.sync_all().map_err(|e| io("flush", e))?;
    }
    std::fs::rename(&partial, path).map_err(|e| io("move the tile file into place", e))
}

/// Where a tile lies in its file.
#[derive(Debug, Clone, Copy)]
struct Entry {
    offset: u64,
    len: u32,
    checksum: u64,
}

/// What a tile file's cache has done since the open.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TileStats {
    pub tile_ins: u64,
    pub hits: u64,
    pub evictions: u64,
    pub resident_bytes: usize,
    pub peak_resident_bytes: usize,
}

#[derive(Debug, Default)]
struct Lru {
    resident: FxHashMap<(i64, i64), (Arc<Tile>, usize, u64)>,
    by_use: BTreeMap<u64, (i64, i64)>,
    tick: u64,
    stats: TileStats,
}

/// An opened tile file: its index in memory, its tiles read on first use under a byte budget.
#[derive(Debug)]
pub(crate) struct TileFile {
    path: PathBuf,
    file: std::fs::File,
    index: FxHashMap<(i64, i64), Entry>,
    budget_bytes: usize,
    lru: Mutex<Lru>,
    faults: Arc<PageFaults>,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // Every change to the state is made in full under the lock, so a panicked holder leaves it
    // consistent.
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl TileFile {
    /// Opens the tile file `path` baked with `key`: reads and checks its header, index and
    /// global part (returned), no tile.
    pub(crate) fn open(
        path: &Path,
        key: u64,
        budget_bytes: usize,
        faults: Arc<PageFaults>,
    ) -> Result<(Self, Vec<u8>), PageError> {
        use std::os::unix::fs::FileExt;
        let bad = |problem: String| PageError::Header {
            path: path.to_path_buf(),
            problem,
        };
        let io = |action, source| PageError::Io {
            path: path.to_path_buf(),
            action,
            source,
        };
        let file = std::fs::File::open(path).map_err(|e| io("open", e))?;
        let len = file
            .metadata()
            .map_err(|e| io("read the size of", e))?
            .len();
        let mut header = [0u8; HEADER_BYTES as usize];
        if len < HEADER_BYTES {
            return Err(bad(format!("{len} bytes is shorter than a header")));
        }
        file.read_exact_at(&mut header, 0)
            .map_err(|e| io("read the header of", e))?;
        let mut h = Bytes(&header);
        let magic = h.take(8).unwrap_or_default();
        let (version, file_key, index_at, count) = (
            h.u32().unwrap_or_default(),
            h.u64().unwrap_or_default(),
            h.u64().unwrap_or_default(),
            h.u32().unwrap_or_default(),
        );
        if magic != MAGIC || version != VERSION {
            return Err(bad(format!(
                "not a decal tile file of version {VERSION}; bake the map again"
            )));
        }
        if file_key != key {
            return Err(bad(
                "baked from another map or another engine; bake the map again".into(),
            ));
        }
        if index_at < HEADER_BYTES || index_at > len {
            return Err(PageError::Length {
                path: path.to_path_buf(),
                found: len,
                expected: index_at,
            });
        }
        let mut tail = vec![0u8; (len - index_at) as usize];
        file.read_exact_at(&mut tail, index_at)
            .map_err(|e| io("read the index of", e))?;
        let damaged = || bad("the index does not match its checksum: the file is damaged".into());
        let (body, sum) = tail.split_at(tail.len().checked_sub(8).ok_or_else(damaged)?);
        if checksum(body) != u64::from_le_bytes(sum.try_into().map_err(|_| damaged())?) {
            return Err(damaged());
        }
        let mut r = Bytes(body);
        let mut index = FxHashMap::default();
        for _ in 0..count {
            let t = (r.i64().ok_or_else(damaged)?, r.i64().ok_or_else(damaged)?);
            let e = Entry {
                offset: r.u64().ok_or_else(damaged)?,
                len: r.u32().ok_or_else(damaged)?,
                checksum: r.u64().ok_or_else(damaged)?,
            };
            if e.offset < HEADER_BYTES || e.offset + u64::from(e.len) > index_at {
                return Err(damaged());
            }
            index.insert(t, e);
        }
        let global_len = r.u64().ok_or_else(damaged)?;
        let global = r.take(global_len as usize).ok_or_else(damaged)?.to_vec();
        let opened = Self {
            path: path.to_path_buf(),
            file,
            index,
            budget_bytes,
            lru: Mutex::new(Lru::default()),
            faults,
        };
        Ok((opened, global))
    }

    /// Tile `t`: `Ok(None)` where the field has nothing, an error (recorded in the faults) where
    /// it cannot be read.
    pub(crate) fn tile(&self, t: (i64, i64)) -> Result<Option<Arc<Tile>>, ()> {
        let Some(&entry) = self.index.get(&t) else {
            return Ok(None);
        };
        {
            let mut s = lock(&self.lru);
            s.tick += 1;
            let tick = s.tick;
            if let Some((tile, _, last)) = s.resident.get_mut(&t) {
                let (tile, old) = (Arc::clone(tile), *last);
                *last = tick;
                s.by_use.remove(&old);
                s.by_use.insert(tick, t);
                s.stats.hits += 1;
                return Ok(Some(tile));
            }
        }
        let tile = Arc::new(self.read(t, entry).map_err(|e| self.faults.record(&e))?);
        let bytes = tile.bytes();
        let mut s = lock(&self.lru);
        s.tick += 1;
        let tick = s.tick;
        if let Some((_, b, old)) = s.resident.insert(t, (Arc::clone(&tile), bytes, tick)) {
            // Another reader read it meanwhile: replace its entry.
            s.by_use.remove(&old);
            s.stats.resident_bytes -= b;
        }
        s.by_use.insert(tick, t);
        s.stats.tile_ins += 1;
        s.stats.resident_bytes += bytes;
        s.stats.peak_resident_bytes = s.stats.peak_resident_bytes.max(s.stats.resident_bytes);
        while s.stats.resident_bytes > self.budget_bytes && s.by_use.len() > 1 {
            let Some((_, victim)) = s.by_use.pop_first() else {
                break;
            };
            if let Some((_, b, _)) = s.resident.remove(&victim) {
                s.stats.resident_bytes -= b;
                s.stats.evictions += 1;
            }
        }
        Ok(Some(tile))
    }

    fn read(&self, t: (i64, i64), e: Entry) -> Result<Tile, PageError> {
        use std::os::unix::fs::FileExt;
        let problem = |what: String| PageError::Request {
            path: self.path.clone(),
            problem: format!("decal tile ({}, {}) {what}", t.0, t.1),
        };
        let mut bytes = vec![0u8; e.len as usize];
        self.file
            .read_exact_at(&mut bytes, e.offset)
            .map_err(|err| problem(format!("cannot be read: {err}")))?;
        if checksum(&bytes) != e.checksum {
            return Err(problem(
                "does not match its checksum (the file is damaged or was changed)".into(),
            ));
        }
        Tile::decode(&bytes).ok_or_else(|| problem("does not parse".into()))
    }

    pub(crate) fn tile_count(&self) -> usize {
        self.index.len()
    }

    pub(crate) fn stats(&self) -> TileStats {
        lock(&self.lru).stats
    }

    /// Heap bytes of the index and the resident tiles.
    pub(crate) fn bytes(&self) -> usize {
        self.index.capacity() * (16 + 24 + 1) + self.stats().resident_bytes
    }

    /// Where tile `t` lies in the file: its offset and length in bytes (tests).
    #[cfg(test)]
    pub(crate) fn span(&self, t: (i64, i64)) -> Option<(u64, u32)> {
        self.index.get(&t).map(|e| (e.offset, e.len))
    }

    /// The tiles the file holds.
    pub(crate) fn tiles(&self) -> Vec<(i64, i64)> {
        let mut t: Vec<(i64, i64)> = self.index.keys().copied().collect();
        t.sort_unstable();
        t
    }
}
