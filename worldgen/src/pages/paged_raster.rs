//! A raster layer served sample by sample from its page file through a [`PageCache`], for
//! the interpolators ([`crate::sample::Samples`]): what is resident follows what the readers
//! ask for, not the layer's area.
//!
//! Each thread keeps the last few pages it read from (an `Arc` of each: eviction from the
//! cache never invalidates them), so a lattice or a stencil that stays inside a page costs a
//! thread-local lookup per sample and one cache request per page it enters.
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

/// Pages a thread keeps at hand, most recent first.
const RECENT_PAGES: usize = 4;

type Recent = [Option<(u64, u32, Arc<PageData>)>; RECENT_PAGES];

thread_local! {
    static RECENT: RefCell<Recent> = const { RefCell::new([None, None, None, None]) };
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
        let index = index as u32;
        let hit = RECENT.with(|r| {
            let r = r.borrow();
            r.iter().flatten().find_map(|(serial, i, data)| {
                (*serial == self.serial && *i == index).then(|| T::slice(data).map(|s| s[at]))
            })
        });
        match hit {
            Some(Some(v)) => v,
            _ => self.read(index, at),
        }
    }

    /// Sample `at` of page `index`, read through the cache and kept at hand for this thread.
    #[cold]
    fn read(&self, index: u32, at: usize) -> T {
        let failed_before = self
            .failed
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .contains(&index);
        if failed_before {
            return self.fill();
        }
        match self.paging.cache.page::<T>(self.layer, index) {
            Ok(data) => {
                let v = T::slice(&data).map_or_else(|| self.fill(), |s| s[at]);
                RECENT.with(|r| {
                    let mut r = r.borrow_mut();
                    r.rotate_right(1);
                    r[0] = Some((self.serial, index, data));
                });
                v
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
                self.fill()
            }
        }
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
}
