//! The map's raster layers read at run time (heights, ground types): a grid in memory (a
//! generated, imported or plainly loaded map), or served page by page from the bake's page file
//! ([`Map::load_paged`](super::Map::load_paged)), so that a viewer holds only the pages its view
//! reads.

use crate::Grid;
use crate::pages::{CacheSample, PageError, PagedRaster};
use crate::sample::Samples;
use std::borrow::Cow;

/// One raster layer, row 0 = south: held whole or read through pages.
#[derive(Debug, Clone)]
pub enum MapRaster<T> {
    Grid(Grid<T>),
    Paged(PagedRaster<T>),
}

/// Heights in metres.
pub type Heights = MapRaster<f32>;

/// Ground type index per sample (an index into the manifest's legend).
pub type GroundTypes = MapRaster<u8>;

impl<T> From<Grid<T>> for MapRaster<T> {
    fn from(g: Grid<T>) -> Self {
        MapRaster::Grid(g)
    }
}

impl<T: CacheSample + PartialEq + std::fmt::Debug> PartialEq for MapRaster<T> {
    /// Grids compare sample by sample; paged rasters by their page file's key of the samples
    /// (a key, not the samples: two paged rasters of equal keys hold the same raster).
    fn eq(&self, other: &Self) -> bool {
        match (self, other) {
            (MapRaster::Grid(a), MapRaster::Grid(b)) => a == b,
            (MapRaster::Paged(a), MapRaster::Paged(b)) => {
                a.key() == b.key() && (a.width(), a.height()) == (b.width(), b.height())
            }
            _ => false,
        }
    }
}

impl<T: CacheSample + std::fmt::Debug> MapRaster<T> {
    pub fn width(&self) -> usize {
        match self {
            MapRaster::Grid(g) => g.width(),
            MapRaster::Paged(p) => p.width(),
        }
    }

    pub fn height(&self) -> usize {
        match self {
            MapRaster::Grid(g) => g.height(),
            MapRaster::Paged(p) => p.height(),
        }
    }

    /// Sample (`x`, `y`), both in range.
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> T {
        match self {
            MapRaster::Grid(g) => g.get(x, y),
            MapRaster::Paged(p) => p.get(x, y),
        }
    }

    /// The sample nearest (`x`, `y`) inside the raster.
    #[inline]
    pub fn get_clamped(&self, x: i64, y: i64) -> T {
        let xc = x.clamp(0, self.width() as i64 - 1) as usize;
        let yc = y.clamp(0, self.height() as i64 - 1) as usize;
        self.get(xc, yc)
    }

    /// The samples in columns `x0..x0 + width` and rows `y0..y0 + height` (inside the
    /// raster, not empty): copied from the grid, or read through the page cache (a page that
    /// cannot be read is served as the raster's fill value, its fault recorded).
    pub fn region(&self, x0: usize, y0: usize, width: usize, height: usize) -> Grid<T> {
        match self {
            MapRaster::Grid(g) => {
                let rows = (y0..y0 + height).flat_map(|y| &g.data()[y * g.width() + x0..][..width]);
                Grid::from_vec(width, height, rows.copied().collect()).expect("sized above")
            }
            MapRaster::Paged(p) => p.region(x0, y0, width, height),
        }
    }

    /// Every sample, for work on the whole map: the grid itself, or the pages read whole
    /// (logged), or, where a page cannot be read, sample by sample (the faults recorded and
    /// the raster's fill value served for them). `name` names the layer in the log.
    pub fn whole_or_filled(&self, name: &str) -> Cow<'_, Grid<T>> {
        match self {
            MapRaster::Grid(g) => Cow::Borrowed(g),
            MapRaster::Paged(p) => {
                log::info!("{name} read whole from their pages, to compute what was not baked");
                Cow::Owned(p.read_whole().unwrap_or_else(|e| {
                    log::error!("{e}; the {name} are read sample by sample instead");
                    p.region(0, 0, p.width(), p.height())
                }))
            }
        }
    }

    /// The grid, when the raster is held in memory.
    pub fn grid(&self) -> Option<&Grid<T>> {
        match self {
            MapRaster::Grid(g) => Some(g),
            MapRaster::Paged(_) => None,
        }
    }

    /// The grid to change, when the raster is held in memory.
    pub fn grid_mut(&mut self) -> Option<&mut Grid<T>> {
        match self {
            MapRaster::Grid(g) => Some(g),
            MapRaster::Paged(_) => None,
        }
    }

    /// The paged raster, when the samples are served from pages.
    pub fn paged(&self) -> Option<&PagedRaster<T>> {
        match self {
            MapRaster::Grid(_) => None,
            MapRaster::Paged(p) => Some(p),
        }
    }

    /// Every sample: the grid itself, or all pages read (for work on the whole map, such as a
    /// bake of what is derived from it).
    pub fn whole(&self) -> Result<Cow<'_, Grid<T>>, PageError> {
        match self {
            MapRaster::Grid(g) => Ok(Cow::Borrowed(g)),
            MapRaster::Paged(p) => p.read_whole().map(Cow::Owned),
        }
    }

    /// The key of the raster's size and samples ([`crate::pages::bake::Raster::key`]): read
    /// from the page file's header when paged (the bake wrote it from the same samples).
    pub fn key(&self) -> u64 {
        match self {
            MapRaster::Grid(g) => T::raster(g).key(),
            MapRaster::Paged(p) => p.key(),
        }
    }

    /// Bytes held in memory for the raster itself (a paged raster's pages are the cache's).
    pub fn held_bytes(&self) -> usize {
        match self {
            MapRaster::Grid(g) => std::mem::size_of_val(g.data()),
            MapRaster::Paged(_) => 0,
        }
    }
}

impl Samples for MapRaster<f32> {
    #[inline]
    fn width(&self) -> usize {
        MapRaster::width(self)
    }
    #[inline]
    fn height(&self) -> usize {
        MapRaster::height(self)
    }
    #[inline]
    fn at(&self, x: usize, y: usize) -> f32 {
        MapRaster::get(self, x, y)
    }
    #[inline]
    fn quad(&self, x: usize, y: usize) -> [[f32; 2]; 2] {
        match self {
            MapRaster::Grid(g) => g.quad(x, y),
            MapRaster::Paged(p) => p.block(x, y),
        }
    }
    #[inline]
    fn block4(&self, x: usize, y: usize) -> [[f32; 4]; 4] {
        match self {
            MapRaster::Grid(g) => g.block4(x, y),
            MapRaster::Paged(p) => p.block(x, y),
        }
    }
}
