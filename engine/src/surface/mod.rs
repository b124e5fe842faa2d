//! The finest surface: the map's heights plus procedural detail plus decal shaping, evaluated
//! in f64 at any world position, with proven per-region bounds of its slope and curvature.
//!
//! - [`world`]: [`World`] wraps a loaded map and defines `F = G + H + E`.
//! - [`decals`]: the decal shaping `E` (roads and paths flattened, rock patches raised);
//!   `decal_build` makes it from the decal list, `decal_tiles` holds its data by 64 m tile,
//!   [`decal_bake`] bakes it into a tile file.
//! - [`spline`]: Catmull-Rom slope and curvature bounds shared by both.
//! - [`stride_levels`]: a raster at every `2^k`-th sample, baked: the heights' for coarse nodes'
//!   lattices, the ground types' for the coarsest nodes' texture texels.
//! - [`height_max`]: a max-pyramid of the map's height samples (upper bounds over regions);
//!   `max_pyramid` the per-cell max-pyramids of the slope, curvature and amplitude bounds.
//! - [`levels`]: the pyramids' levels in memory or paged (a baked map), and the page faults.
//! - [`map_error`]: the map part's interpolation error per block of the coarse grids, computed
//!   once at load; [`map_error_cache`] keeps it in a file between runs.

pub mod amplitude;
pub mod decal_bake;
mod decal_build;
mod decal_tiles;
pub mod decals;
pub mod height_max;
pub mod levels;
pub mod map_error;
pub mod map_error_cache;
pub mod map_error_pages;
mod max_pyramid;
mod pyramids;
pub mod spline;
pub mod stride_levels;
pub mod world;

pub use world::{Rect, RegionBounds, World};
