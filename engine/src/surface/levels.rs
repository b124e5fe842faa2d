//! Levels of the surface's max-pyramids, held in memory or read through the page cache.
//!
//! A baked map (`worldgen bake`) stores every level of the world's max-pyramids as a page file
//! under `pages/derived/` ([`level_path`]); opening it reads each file's header only, keeps
//! levels of one page in memory and serves the others page by page from a
//! [`PageCache`] under a byte budget. Every use of a level is an upper bound (a maximum over
//! cells), so a page that cannot be read is served as `+inf`: the bounds that need it stay
//! true, only looser, and the fault is recorded once per file and page ([`PageFaults`]) for the
//! log and the viewer.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use worldgen::Grid;
use worldgen::pages::{LayerId, PageCache, PageError, SampleKind};

pub use worldgen::pages::PageFaults;

/// One level of a max-pyramid.
#[derive(Debug, Clone)]
pub(crate) enum Level {
    Memory(Grid<f32>),
    Paged {
        cache: Arc<PageCache>,
        layer: LayerId,
        width: usize,
        height: usize,
        faults: Arc<PageFaults>,
    },
}

impl Level {
    pub(crate) fn width(&self) -> usize {
        match self {
            Level::Memory(g) => g.width(),
            Level::Paged { width, .. } => *width,
        }
    }

    pub(crate) fn height(&self) -> usize {
        match self {
            Level::Memory(g) => g.height(),
            Level::Paged { height, .. } => *height,
        }
    }

    /// Sample (`x`, `y`); `+inf` where its page cannot be read (recorded).
    #[inline]
    pub(crate) fn get(&self, x: usize, y: usize) -> f32 {
        match self {
            Level::Memory(g) => g.get(x, y),
            Level::Paged {
                cache,
                layer,
                faults,
                ..
            } => cache
                .sample::<f32>(*layer, x as u32, y as u32)
                .unwrap_or_else(|e| {
                    faults.record(&e);
                    f32::INFINITY
                }),
        }
    }

    /// The `width` x `height` samples from (`x`, `y`), row-major, in one read of the cache;
    /// `None` where a page cannot be read (recorded with `consequence`).
    pub(crate) fn try_region(
        &self,
        [x, y]: [usize; 2],
        [width, height]: [usize; 2],
        consequence: &str,
    ) -> Option<Vec<f32>> {
        match self {
            Level::Memory(g) => Some(
                (y..y + height)
                    .flat_map(|row| (x..x + width).map(move |col| g.get(col, row)))
                    .collect(),
            ),
            Level::Paged {
                cache,
                layer,
                faults,
                ..
            } => cache
                .region::<f32>(*layer, x as u32, y as u32, width as u32, height as u32)
                .map(|g| g.data().to_vec())
                .map_err(|e| faults.record_as(&e, consequence))
                .ok(),
        }
    }

    /// Bytes held in memory by this level itself (a paged level's resident pages are the
    /// cache's).
    pub(crate) fn bytes(&self) -> usize {
        match self {
            Level::Memory(g) => g.data().len() * 4,
            Level::Paged { .. } => 0,
        }
    }
}

/// The page file of level `k` of the pyramid `name` in a map's `pages` folder.
pub fn level_path(pages_dir: &Path, name: &str, k: usize) -> PathBuf {
    pages_dir.join("derived").join(format!("{name}.{k}.pages"))
}

/// The sizes of a max-pyramid's levels from a base of `width` x `height`: halved (rounded up)
/// until 1 x 1.
pub(crate) fn level_sizes(width: usize, height: usize) -> Vec<(usize, usize)> {
    let mut sizes = vec![(width, height)];
    while let Some(&(w, h)) = sizes.last() {
        if w <= 1 && h <= 1 {
            break;
        }
        sizes.push((w.div_ceil(2), h.div_ceil(2)));
    }
    sizes
}

/// Writes every level of the pyramid `name` (all in memory) as page files.
pub(crate) fn write_levels(
    pages_dir: &Path,
    name: &str,
    levels: &[Level],
    page_side: u32,
    key: u64,
) -> Result<(), PageError> {
    for (k, level) in levels.iter().enumerate() {
        let Level::Memory(grid) = level else {
            return Err(PageError::Request {
                path: level_path(pages_dir, name, k),
                problem: "a paged level cannot be baked again; open the map without its pages"
                    .into(),
            });
        };
        worldgen::pages::bake::write_grid(&level_path(pages_dir, name, k), grid, page_side, key)?;
    }
    Ok(())
}

/// Opens the levels of the pyramid `name` of the given `sizes`, baked with `key`: a level of
/// one page is read into memory, the others are registered with `cache`.
pub(crate) fn open_levels(
    pages_dir: &Path,
    name: &str,
    sizes: &[(usize, usize)],
    key: u64,
    cache: &Arc<PageCache>,
    faults: &Arc<PageFaults>,
) -> Result<Vec<Level>, PageError> {
    sizes
        .iter()
        .enumerate()
        .map(|(k, &size)| open_level(&level_path(pages_dir, name, k), size, key, cache, faults))
        .collect()
}

/// Opens one level's page file `path` of `width` x `height` samples baked with `key`: read
/// into memory when it is one page, else registered with `cache`.
pub(crate) fn open_level(
    path: &Path,
    (width, height): (usize, usize),
    key: u64,
    cache: &Arc<PageCache>,
    faults: &Arc<PageFaults>,
) -> Result<Level, PageError> {
    let file = worldgen::pages::bake::open_derived(path, SampleKind::F32, width, height, key)?;
    Ok(if file.layout().page_count() == 1 {
        Level::Memory(file.read_all()?)
    } else {
        Level::Paged {
            cache: Arc::clone(cache),
            layer: cache.add(file),
            width,
            height,
            faults: Arc::clone(faults),
        }
    })
}
