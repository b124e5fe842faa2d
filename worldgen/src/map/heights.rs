//! The map's heights: a grid in memory (a generated, imported or plainly loaded map), or
//! served page by page from the bake's page file ([`Map::load_paged`](super::Map::load_paged)),
//! so that a viewer holds only the pages its view reads.

use crate::Grid;
use crate::pages::{PageError, PagedRaster};
use crate::sample::Samples;
use std::borrow::Cow;

/// Heights in metres, row 0 = south.
#[derive(Debug, Clone)]
pub enum Heights {
    Grid(Grid<f32>),
    Paged(PagedRaster<f32>),
}

impl From<Grid<f32>> for Heights {
    fn from(g: Grid<f32>) -> Self {
        Heights::Grid(g)
    }
}

impl PartialEq for Heights {
    /// Grids compare sample by sample; paged heights by their page file's key of the samples
    /// (a key, not the samples: two paged rasters of equal keys hold the same raster).
    fn eq(&self, other: &Self) -> bool {
        match (self, other) {
            (Heights::Grid(a), Heights::Grid(b)) => a == b,
            (Heights::Paged(a), Heights::Paged(b)) => {
                a.key() == b.key() && (a.width(), a.height()) == (b.width(), b.height())
            }
            _ => false,
        }
    }
}

impl Heights {
    pub fn width(&self) -> usize {
        match self {
            Heights::Grid(g) => g.width(),
            Heights::Paged(p) => p.width(),
        }
    }

    pub fn height(&self) -> usize {
        match self {
            Heights::Grid(g) => g.height(),
            Heights::Paged(p) => p.height(),
        }
    }

    /// Sample (`x`, `y`), both in range.
    pub fn get(&self, x: usize, y: usize) -> f32 {
        match self {
            Heights::Grid(g) => g.get(x, y),
            Heights::Paged(p) => p.get(x, y),
        }
    }

    /// The grid, when the heights are held in memory.
    pub fn grid(&self) -> Option<&Grid<f32>> {
        match self {
            Heights::Grid(g) => Some(g),
            Heights::Paged(_) => None,
        }
    }

    /// The grid to change, when the heights are held in memory.
    pub fn grid_mut(&mut self) -> Option<&mut Grid<f32>> {
        match self {
            Heights::Grid(g) => Some(g),
            Heights::Paged(_) => None,
        }
    }

    /// The paged raster, when the heights are served from pages.
    pub fn paged(&self) -> Option<&PagedRaster<f32>> {
        match self {
            Heights::Grid(_) => None,
            Heights::Paged(p) => Some(p),
        }
    }

    /// Every sample: the grid itself, or all pages read (for work on the whole map, such as a
    /// bake of what is derived from it).
    pub fn whole(&self) -> Result<Cow<'_, Grid<f32>>, PageError> {
        match self {
            Heights::Grid(g) => Ok(Cow::Borrowed(g)),
            Heights::Paged(p) => p.read_whole().map(Cow::Owned),
        }
    }

    /// The key of the raster's size and samples ([`crate::pages::bake::Raster::key`]): read
    /// from the page file's header when paged (the bake wrote it from the same samples).
    pub fn key(&self) -> u64 {
        match self {
            Heights::Grid(g) => crate::pages::bake::Raster::F32(g).key(),
            Heights::Paged(p) => p.key(),
        }
    }
}

impl Samples for Heights {
    #[inline]
    fn width(&self) -> usize {
        Heights::width(self)
    }
    #[inline]
    fn height(&self) -> usize {
        Heights::height(self)
    }
    #[inline]
    fn at(&self, x: usize, y: usize) -> f32 {
        Heights::get(self, x, y)
    }
    #[inline]
    fn quad(&self, x: usize, y: usize) -> [[f32; 2]; 2] {
        match self {
            Heights::Grid(g) => g.quad(x, y),
            Heights::Paged(p) => p.block(x, y),
        }
    }
    #[inline]
    fn block4(&self, x: usize, y: usize) -> [[f32; 4]; 4] {
        match self {
            Heights::Grid(g) => g.block4(x, y),
            Heights::Paged(p) => p.block(x, y),
        }
    }
}
