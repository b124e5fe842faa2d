//! Paged rasters: a map layer stored as fixed square pages, read at run time through a page
//! cache with a memory budget, so what is resident follows the view rather than the map's area.
//!
//! - [`file`](mod@file) the page file: a checked header, then every page at a fixed offset with its own
//!   checksum. A page's bytes are a pure function of the raster and the page's index, so pages
//!   can be baked in any order and any subset, on any machine, into the same bytes.
//! - [`cache`] the page cache: pages are read on first use (checksum verified then), shared
//!   between readers, and evicted least recently used beyond the budget.
//! - [`bake`] writes a map's raster layers as page files (all pages, or any subset of them).
//! - [`paged_raster`] a layer read sample by sample through the cache, for the interpolators;
//!   [`faults`] the record of pages that could not be read.
//! - [`sources`] records the files a bake read, so an open reads the pages instead of them;
//!   [`decal_list`] is the decal list baked into binary.
//!
//! Files are read with positioned reads, never memory-mapped: a file truncated or damaged while
//! it is in use gives an error naming the file and the page, never a crash.

pub mod bake;
pub mod cache;
pub mod checked_file;
pub mod decal_list;
pub mod faults;
pub mod file;
pub mod paged_raster;
pub mod sources;
pub mod tree_list;

pub use cache::{CacheSample, LayerId, PageCache, PageData, PageStats};
pub use faults::PageFaults;
pub use file::{PageFile, PageLayout, SampleKind};
pub use paged_raster::{PagedRaster, Paging};

use std::path::PathBuf;

/// Samples per page side. 256 x 256 f32 samples are 256 KiB, a few disk blocks' worth of
/// positioned reads and about a kilometre of a 4 m map.
pub const DEFAULT_PAGE_SIDE: u32 = 256;

/// The hidden partial file `.<name>.partial` beside `path`, through which a derived file is
/// written and then renamed into place: its folder created, an old partial file removed.
pub fn fresh_partial_path(path: &std::path::Path) -> Result<PathBuf, PageError> {
    let io = |action, source| PageError::Io {
        path: path.to_path_buf(),
        action,
        source,
    };
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(|e| io("create the folder of", e))?;
    }
    let name = path
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let partial = path.with_file_name(format!(".{name}.partial"));
    if partial.exists() {
        std::fs::remove_file(&partial).map_err(|e| io("remove an old partial file of", e))?;
    }
    Ok(partial)
}

/// A 64-bit key of a stream of bytes: two CRC-32s started from `seed + 1` and `seed + 2`. Stable
/// across builds (unlike the standard hasher), it matches a page file to the source it was
/// baked from.
#[derive(Clone, Debug)]
pub struct SourceKey {
    a: crc32fast::Hasher,
    b: crc32fast::Hasher,
}

impl SourceKey {
    pub fn new(seed: u32) -> Self {
        Self {
            a: crc32fast::Hasher::new_with_initial(seed.wrapping_add(1)),
            b: crc32fast::Hasher::new_with_initial(seed.wrapping_add(2)),
        }
    }

    pub fn update(&mut self, bytes: &[u8]) {
        self.a.update(bytes);
        self.b.update(bytes);
    }

    pub fn finish(self) -> u64 {
        (u64::from(self.a.finalize()) << 32) | u64::from(self.b.finalize())
    }
}

/// Why a page file or a page could not be used. Every variant names the file; those about one
/// page name it by its column and row of pages (from the south-west).
#[derive(Debug, thiserror::Error)]
pub enum PageError {
    #[error("{path}: cannot {action}: {source}")]
    Io {
        path: PathBuf,
        action: &'static str,
        source: std::io::Error,
    },
    #[error("{path}: not a page file of this version: {problem}")]
    Header { path: PathBuf, problem: String },
    #[error(
        "{path}: the file is {found} bytes but its header describes {expected}; it was truncated or is still being written"
    )]
    Length {
        path: PathBuf,
        found: u64,
        expected: u64,
    },
    #[error("{path}: page ({column}, {row}) cannot be read: {source}")]
    PageIo {
        path: PathBuf,
        column: u32,
        row: u32,
        source: std::io::Error,
    },
    #[error(
        "{path}: page ({column}, {row}) does not match its checksum (the file is damaged or was changed)"
    )]
    Checksum {
        path: PathBuf,
        column: u32,
        row: u32,
    },
    #[error(
        "{path}: page ({column}, {row}) has not been baked (run `worldgen bake` for it, then `worldgen bake --finish`)"
    )]
    NotBaked {
        path: PathBuf,
        column: u32,
        row: u32,
    },
    #[error("{path}: {problem}")]
    Request { path: PathBuf, problem: String },
}
