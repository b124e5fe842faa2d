//! A raster layer served sample by sample from its page file through a [`PageCache`], for
//! the interpolators ([`crate::sample::Samples`]): what is resident follows what the readers
//! ask for, not the layer's area.
//!
//! Each thread keeps the pages it read from lately in a small table indexed by raster and page
//! (an `Arc` of each: eviction from the cache never invalidates them, clearing the cache does;
//! a page read later into the same slot replaces it), so a lattice or a stencil that stays inside a page costs a
//! thread-local lookup per sample (or per stencil, [`PagedRaster::block`]) and one cache
//! request per page it enters.
//!
//! A page that cannot be read (damaged, truncated, removed) is recorded once in the
//! [`PageFaults`] with its file and page, never read again, and its samples are served as the
//! raster's fill value (set by the owner, for example the map's highest height, so nothing
//! stands below a damaged patch of terrain).

use super::cache::{CacheSample, LayerId, PageCache, PageData};
use super::faults::PageFaults;
use super::file::{PageFile, PageLayout};
use crate::sample::Samples;
use std::cell::RefCell;
use std::collections::HashSet;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// A page cache and the record of its faults, shared by the paged data of one world.
#[derive(Debug, Clone)]
pub struct Paging {
    pub cache: Arc<PageCache>,
    pub faults: Arc<PageFaults>,
}

impl Paging {
    /// A new cache of `budget_bytes` with an empty record of faults.
    pub fn new(budget_bytes: usize) -> Self {
        Self {
            cache: Arc::new(PageCache::new(budget_bytes)),
            faults: Arc::default(),
        }
    }
}

/// Tells the rasters apart in the threads' memos (never reused, unlike addresses).
static NEXT_SERIAL: AtomicU64 = AtomicU64::new(1);

/// Log2 of the pages a thread keeps at hand: a direct-mapped table, one slot per (raster,
/// page) hash, so a look-up compares one entry. Light grids, meshes and bounds interleave
/// reads of several rasters (heights, their coarse levels, max-pyramids), each in a few pages.
const RECENT_SLOTS_LOG2: u32 = 5;

/// A page at hand: the raster's serial, the page's index, the cache's generation it was read
/// in ([`PageCache::generation`]) and its samples.
type Slot = Option<(u64, u32, u64, Arc<PageData>)>;

thread_local! {
    static RECENT: RefCell<[Slot; 1 << RECENT_SLOTS_LOG2]> =
        const { RefCell::new([const { None }; 1 << RECENT_SLOTS_LOG2]) };
}

/// The slot of page `index` of the raster numbered `serial`.
#[inline]
fn slot(serial: u64, index: u32) -> usize {
    let h = (serial as u32)
        .wrapping_mul(0x9E37_79B9)
        .wrapping_add(index.wrapping_mul(0x85EB_CA6B));
    (h >> (32 - RECENT_SLOTS_LOG2)) as usize
}

/// One raster layer of a page file, read through a page cache.
#[derive(Debug, Clone)]
pub struct PagedRaster<T> {
    paging: Paging,
    layer: LayerId,
    layout: PageLayout,
    /// Pages along x, and log2 of the page side where it is a power of two (the usual case:
    /// a shift and a mask find a sample's page instead of two divisions).
    pages_per_row: usize,
    side_shift: Option<u32>,
    key: u64,
    /// The fill value's bits (f32 or u8 widened), shared by clones.
    fill_bits: Arc<AtomicU32>,
    /// Pages that could not be read.
    failed: Arc<Mutex<HashSet<u32>>>,
    serial: u64,
    kind: std::marker::PhantomData<T>,
}

impl<T: CacheSample + std::fmt::Debug> PagedRaster<T> {
    /// Registers `file` (samples of type `T`) with `paging`'s cache; samples of pages that
    /// cannot be read are served as `fill` until [`Self::set_fill`] changes it.
    pub fn new(paging: &Paging, file: PageFile, fill: T) -> Result<Self, super::PageError> {
        let layout = file.layout();
        if layout.kind != T::KIND {
            return Err(super::PageError::Request {
                path: file.path().to_path_buf(),
                problem: format!("{:?} samples asked of {:?} pages", T::KIND, layout.kind),
            });
        }
        let key = file.key();
        let layer = paging.cache.add(file);
        Ok(Self {
            paging: paging.clone(),
            layer,
            layout,
            pages_per_row: layout.pages_per_row() as usize,
            side_shift: layout
                .page_side
                .is_power_of_two()
                .then(|| layout.page_side.trailing_zeros()),
            key,
            fill_bits: Arc::new(AtomicU32::new(T::to_bits(fill))),
            failed: Arc::default(),
            serial: NEXT_SERIAL.fetch_add(1, Ordering::Relaxed),
            kind: std::marker::PhantomData,
        })
    }

    pub fn width(&self) -> usize {
        self.layout.width as usize
    }

    pub fn height(&self) -> usize {
        self.layout.height as usize
    }

    /// The page file's key of the raster it holds (its size and samples).
    pub fn key(&self) -> u64 {
        self.key
    }

    pub fn paging(&self) -> &Paging {
        &self.paging
    }

    /// The value served for samples of pages that cannot be read.
    pub fn fill(&self) -> T {
        T::from_bits(self.fill_bits.load(Ordering::Relaxed))
    }

    pub fn set_fill(&self, fill: T) {
        self.fill_bits.store(T::to_bits(fill), Ordering::Relaxed);
    }

    /// Sample (`x`, `y`), both in range (row 0 = south).
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> T {
        let (index, at) = if let Some(s) = self.side_shift {
            let mask = (1usize << s) - 1;
            let index = (y >> s) * self.pages_per_row + (x >> s);
            (index, ((y & mask) << s) + (x & mask))
        } else {
            let side = self.layout.page_side as usize;
            let index = (y / side) * self.pages_per_row + x / side;
            (index, (y % side) * side + x % side)
        };
        self.with_page(index as u32, |page| page[at])
            .unwrap_or_else(|| self.fill())
    }

    /// The samples `x..x + N` by `y..y + N` (`[row][column]`, south row first), all in range:
    /// one look-up of their page where they share one (the usual case for a stencil), else
    /// sample by sample. Equal to [`Self::get`] at each sample.
    #[inline]
    pub fn block<const N: usize>(&self, x: usize, y: usize) -> [[T; N]; N] {
        if let Some(s) = self.side_shift {
            let side = 1usize << s;
            let (px, py) = (x & (side - 1), y & (side - 1));
            if px + N <= side && py + N <= side {
                let index = ((y >> s) * self.pages_per_row + (x >> s)) as u32;
                return self
                    .with_page(index, |page| {
                        std::array::from_fn(|j| {
                            let row = &page[(py + j) * side + px..][..N];
                            std::array::from_fn(|i| row[i])
                        })
                    })
                    .unwrap_or_else(|| [[self.fill(); N]; N]);
            }
        }
        std::array::from_fn(|j| std::array::from_fn(|i| self.get(x + i, y + j)))
    }

    /// `f` of the samples of page `index`: from this thread's recent pages, else read through
    /// the cache (and kept at hand). `None` where the page cannot be read.
    #[inline]
    fn with_page<R>(&self, index: u32, f: impl Fn(&[T]) -> R) -> Option<R> {
        let hit = RECENT.with(|r| {
            let r = r.borrow();
            let (serial, i, generation, data) = r[slot(self.serial, index)].as_ref()?;
            let current = *generation == self.paging.cache.generation();
            (*serial == self.serial && *i == index && current).then(|| T::slice(data).map(&f))
        });
        match hit {
            Some(value) => value,
            None => self.read(index).and_then(|data| T::slice(&data).map(f)),
        }
    }

    /// Page `index`, read through the cache and kept at hand for this thread; `None` (and the
    /// fault recorded once) where it cannot be read.
    #[cold]
    fn read(&self, index: u32) -> Option<Arc<PageData>> {
        let failed_before = self
            .failed
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .contains(&index);
        if failed_before {
            return None;
        }
        let generation = self.paging.cache.generation();
        match self.paging.cache.page::<T>(self.layer, index) {
            Ok(data) => {
                RECENT.with(|r| {
                    r.borrow_mut()[slot(self.serial, index)] =
                        Some((self.serial, index, generation, Arc::clone(&data)));
                });
                Some(data)
            }
            Err(e) => {
                self.failed
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .insert(index);
                let consequence = format!(
                    "its samples are taken as {:?} (the raster's fill value)",
                    self.fill()
                );
                self.paging.faults.record_as(&e, &consequence);
                None
            }
        }
    }

    /// The samples in columns `x0..x0 + width` and rows `y0..y0 + height` (inside the
    /// raster, not empty), in one request of the cache; where a page cannot be read, sample by
    /// sample (its fault recorded once and the fill value served).
    pub fn region(&self, x0: usize, y0: usize, width: usize, height: usize) -> crate::Grid<T> {
        let read = self.paging.cache.region::<T>(
            self.layer,
            x0 as u32,
            y0 as u32,
            width as u32,
            height as u32,
        );
        read.unwrap_or_else(|_| {
            let samples = (y0..y0 + height).flat_map(|y| (x0..x0 + width).map(move |x| (x, y)));
            let samples = samples.map(|(x, y)| self.get(x, y)).collect();
            crate::Grid::from_vec(width, height, samples).expect("sized above")
        })
    }

    /// Every sample, read page by page (for work that needs the whole layer).
    pub fn read_whole(&self) -> Result<crate::Grid<T>, super::PageError> {
        self.paging.cache.file(self.layer).read_all::<T>()
    }
}

impl Samples for PagedRaster<f32> {
    #[inline]
    fn width(&self) -> usize {
        PagedRaster::width(self)
    }
    #[inline]
    fn height(&self) -> usize {
        PagedRaster::height(self)
    }
    #[inline]
    fn at(&self, x: usize, y: usize) -> f32 {
        self.get(x, y)
    }
    #[inline]
    fn quad(&self, x: usize, y: usize) -> [[f32; 2]; 2] {
        self.block(x, y)
    }
    #[inline]
    fn block4(&self, x: usize, y: usize) -> [[f32; 4]; 4] {
        self.block(x, y)
    }
}
