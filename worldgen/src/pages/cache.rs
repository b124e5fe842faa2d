//! The page cache: pages of several page files, read on first use and kept under a byte budget.
//!
//! A reader asks for a region of samples (a node's area plus the halo it needs); the cache
//! reads the pages that region touches that are not resident (checksum verified on every read
//! from the file), copies the samples out and marks the pages used. Beyond the budget the least
//! recently used pages are dropped; a reader that holds a page keeps its copy alive, so eviction
//! never invalidates data in use. Reads happen outside the cache's lock, so one slow read does
//! not stall readers of resident pages.

use super::PageError;
use super::file::{PageFile, PageLayout, Sample, SampleKind};
use crate::Grid;
use std::collections::{BTreeMap, HashMap};
use std::sync::{Arc, Mutex, MutexGuard};

/// One page file registered with a cache.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct LayerId(u32);

/// A resident page's samples.
#[derive(Debug)]
pub enum PageData {
    F32(Vec<f32>),
    U8(Vec<u8>),
}

impl PageData {
    fn bytes(&self) -> usize {
        match self {
            PageData::F32(v) => v.len() * 4,
            PageData::U8(v) => v.len(),
        }
    }
}

/// The sample types a cache serves (f32 and u8): their slice of a resident page.
pub trait CacheSample: Sample {
    fn slice(page: &PageData) -> Option<&[Self]>;
    fn wrap(samples: Vec<Self>) -> PageData;
    fn zero() -> Self;
    /// The sample as 32 bits and back (for values kept in an atomic).
    fn to_bits(self) -> u32;
    fn from_bits(bits: u32) -> Self;
    /// A whole grid of these samples as the bake sees it (for its key).
    fn raster(grid: &crate::Grid<Self>) -> super::bake::Raster<'_>;
}

impl CacheSample for f32 {
    fn zero() -> Self {
        0.0
    }
    fn to_bits(self) -> u32 {
        f32::to_bits(self)
    }
    fn from_bits(bits: u32) -> Self {
        f32::from_bits(bits)
    }
    fn slice(page: &PageData) -> Option<&[f32]> {
        match page {
            PageData::F32(v) => Some(v),
            PageData::U8(_) => None,
        }
    }
    fn wrap(samples: Vec<f32>) -> PageData {
        PageData::F32(samples)
    }
    fn raster(grid: &crate::Grid<f32>) -> super::bake::Raster<'_> {
        super::bake::Raster::F32(grid)
    }
}

impl CacheSample for u8 {
    fn zero() -> Self {
        0
    }
    fn to_bits(self) -> u32 {
        u32::from(self)
    }
    fn from_bits(bits: u32) -> Self {
        (bits & 0xFF) as u8
    }
    fn slice(page: &PageData) -> Option<&[u8]> {
        match page {
            PageData::U8(v) => Some(v),
            PageData::F32(_) => None,
        }
    }
    fn wrap(samples: Vec<u8>) -> PageData {
        PageData::U8(samples)
    }
    fn raster(grid: &crate::Grid<u8>) -> super::bake::Raster<'_> {
        super::bake::Raster::U8(grid)
    }
}

/// What the cache has done since it was made.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PageStats {
    /// Pages read from their files (first use, or again after eviction).
    pub page_ins: u64,
    /// Page requests answered from memory.
    pub hits: u64,
    pub evictions: u64,
    /// Bytes of samples resident now, and the most there were.
    pub resident_bytes: usize,
    pub peak_resident_bytes: usize,
    /// Page reads that failed (bad page, short file); each failure is returned to its reader.
    pub failures: u64,
}

#[derive(Debug)]
struct Entry {
    data: Arc<PageData>,
    last_use: u64,
}

#[derive(Debug, Default)]
struct State {
    /// The layout of each registered file, by layer (read under the one lock of a lookup).
    layouts: Vec<PageLayout>,
    entries: HashMap<(LayerId, u32), Entry>,
    /// Last use -> page, for eviction in least-recently-used order.
    by_use: BTreeMap<u64, (LayerId, u32)>,
    tick: u64,
    stats: PageStats,
}

/// Pages of several page files under one memory budget.
#[derive(Debug)]
pub struct PageCache {
    budget_bytes: usize,
    files: Mutex<Vec<Arc<PageFile>>>,
    state: Mutex<State>,
    /// Incremented by [`Self::clear`]: pages that readers keep at hand from an older
    /// generation are read again.
    generation: std::sync::atomic::AtomicU64,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A reader that panicked cannot leave the state half-changed: every change below is made
    // in full before the lock is released, so the data is still consistent.
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl PageCache {
    /// A cache that keeps at most about `budget_bytes` of samples resident (at least the pages
    /// of the request being answered).
    pub fn new(budget_bytes: usize) -> Self {
        Self {
            budget_bytes,
            files: Mutex::new(Vec::new()),
            state: Mutex::new(State::default()),
            generation: std::sync::atomic::AtomicU64::new(0),
        }
    }

    /// How many times the cache was cleared ([`Self::clear`]).
    #[inline]
    pub fn generation(&self) -> u64 {
        self.generation.load(std::sync::atomic::Ordering::Relaxed)
    }

    pub fn budget_bytes(&self) -> usize {
        self.budget_bytes
    }

    /// Registers an opened page file.
    pub fn add(&self, file: PageFile) -> LayerId {
        let mut files = lock(&self.files);
        lock(&self.state).layouts.push(file.layout());
        files.push(Arc::new(file));
        LayerId(files.len() as u32 - 1)
    }

    /// The error for a request `layer` cannot answer: `what` of samples of `kind`.
    fn refused(&self, layer: LayerId, what: &str, kind: SampleKind) -> PageError {
        let file = self.file(layer);
        let l = file.layout();
        PageError::Request {
            path: file.path().to_path_buf(),
            problem: format!(
                "{what} of {kind:?} samples asked of a raster of {}x{} {:?} samples",
                l.width, l.height, l.kind
            ),
        }
    }

    /// The file of `layer`.
    pub fn file(&self, layer: LayerId) -> Arc<PageFile> {
        Arc::clone(&lock(&self.files)[layer.0 as usize])
    }

    /// How many files are registered.
    pub fn file_count(&self) -> usize {
        lock(&self.files).len()
    }

    pub fn stats(&self) -> PageStats {
        lock(&self.state).stats
    }

    /// Drops every resident page (the next requests read them again, also those of pages a
    /// reader keeps at hand, [`super::PagedRaster`]).
    pub fn clear(&self) {
        let mut s = lock(&self.state);
        self.generation
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        s.stats.evictions += s.entries.len() as u64;
        s.entries.clear();
        s.by_use.clear();
        s.stats.resident_bytes = 0;
    }

    fn touch(s: &mut State, key: (LayerId, u32)) -> Option<Arc<PageData>> {
        s.tick += 1;
        let tick = s.tick;
        let entry = s.entries.get_mut(&key)?;
        let old = std::mem::replace(&mut entry.last_use, tick);
        let data = Arc::clone(&entry.data);
        s.by_use.remove(&old);
        s.by_use.insert(tick, key);
        Some(data)
    }

    /// Page `index` of `layer`, resident or read now (for readers that keep a page while
    /// they read many of its samples).
    pub fn page<T: CacheSample>(
        &self,
        layer: LayerId,
        index: u32,
    ) -> Result<Arc<PageData>, PageError> {
        {
            let mut s = lock(&self.state);
            if let Some(data) = Self::touch(&mut s, (layer, index)) {
                s.stats.hits += 1;
                return Ok(data);
            }
        }
        let file = self.file(layer);
        let (column, row) = file.layout().column_row(index);
        let read = file.read_page::<T>(column, row);
        let mut s = lock(&self.state);
        let samples = match read {
            Ok(samples) => samples,
            Err(e) => {
                s.stats.failures += 1;
                return Err(e);
            }
        };
        s.stats.page_ins += 1;
        // Another reader may have read the same page meanwhile: keep theirs.
        if let Some(data) = Self::touch(&mut s, (layer, index)) {
            return Ok(data);
        }
        let data = Arc::new(T::wrap(samples));
        s.tick += 1;
        let tick = s.tick;
        s.stats.resident_bytes += data.bytes();
        s.entries.insert(
            (layer, index),
            Entry {
                data: Arc::clone(&data),
                last_use: tick,
            },
        );
        s.by_use.insert(tick, (layer, index));
        self.evict_beyond_budget(&mut s, (layer, index));
        s.stats.peak_resident_bytes = s.stats.peak_resident_bytes.max(s.stats.resident_bytes);
        Ok(data)
    }

    fn evict_beyond_budget(&self, s: &mut State, keep: (LayerId, u32)) {
        while s.stats.resident_bytes > self.budget_bytes {
            let Some((&tick, &key)) = s.by_use.iter().find(|(_, k)| **k != keep) else {
                break;
            };
            s.by_use.remove(&tick);
            if let Some(e) = s.entries.remove(&key) {
                s.stats.resident_bytes -= e.data.bytes();
                s.stats.evictions += 1;
            }
        }
    }

    /// Sample (`x`, `y`) of `layer` (row 0 = south), read through the cache: one lock, a hash
    /// lookup and the page's use recorded when its page is resident.
    pub fn sample<T: CacheSample>(&self, layer: LayerId, x: u32, y: u32) -> Result<T, PageError> {
        let (index, at) = {
            let mut s = lock(&self.state);
            let l = s.layouts[layer.0 as usize];
            if T::KIND != l.kind || x >= l.width || y >= l.height {
                drop(s);
                return Err(self.refused(layer, &format!("sample ({x}, {y})"), T::KIND));
            }
            let side = l.page_side;
            let index = l.index(x / side, y / side);
            let at = ((y % side) * side + x % side) as usize;
            if let Some(data) = Self::touch(&mut s, (layer, index)) {
                s.stats.hits += 1;
                return Ok(T::slice(&data).expect("a layer's pages hold its sample kind")[at]);
            }
            (index, at)
        };
        let data = self.page::<T>(layer, index)?;
        Ok(T::slice(&data).expect("a layer's pages hold its sample kind")[at])
    }

    /// The samples of `layer` in columns `x0..x0 + width` and rows `y0..y0 + height` (row 0 =
    /// south), read through the cache. The region must lie inside the raster.
    pub fn region<T: CacheSample>(
        &self,
        layer: LayerId,
        x0: u32,
        y0: u32,
        width: u32,
        height: u32,
    ) -> Result<Grid<T>, PageError> {
        let file = self.file(layer);
        let l = file.layout();
        let inside = T::KIND == l.kind
            && width > 0
            && height > 0
            && u64::from(x0) + u64::from(width) <= u64::from(l.width)
            && u64::from(y0) + u64::from(height) <= u64::from(l.height);
        if !inside {
            let what = format!("region of {width}x{height} at ({x0}, {y0})");
            return Err(self.refused(layer, &what, T::KIND));
        }
        let side = l.page_side;
        let mut out = vec![T::zero(); width as usize * height as usize];
        for row in y0 / side..=(y0 + height - 1) / side {
            for column in x0 / side..=(x0 + width - 1) / side {
                let data = self.page::<T>(layer, l.index(column, row))?;
                let samples = T::slice(&data).expect("a layer's pages hold its sample kind");
                let (px, py) = (column * side, row * side);
                let (xa, xb) = (x0.max(px), (x0 + width).min(px + side));
                for y in y0.max(py)..(y0 + height).min(py + side) {
                    let src = ((y - py) * side + (xa - px)) as usize;
                    let dst = ((y - y0) * width + (xa - x0)) as usize;
                    let n = (xb - xa) as usize;
                    out[dst..dst + n].copy_from_slice(&samples[src..src + n]);
                }
            }
        }
        Ok(Grid::from_vec(width as usize, height as usize, out).expect("sized above"))
    }
}
