//! `worldgen`: everything that happens before the engine runs.
//!
//! - [`map`] owns **map format v2**: a folder with a `map.toml` manifest and layer files (heights as
//!   single-channel f32 OpenEXR, ground types as an indexed PNG, one 8-bit PNG per vegetation
//!   species, text lists of large trees, decals and buildings, the ranked Poisson-disc tile). Every file carries a format name and
//!   a version. [`map::Map::load`] validates everything before it returns: a map opens whole or not
//!   at all, and every error names the file, the field and what was expected.
//! - [`generate`] makes a believable landscape from a seed (fBm + ridged noise, hydraulic and
//!   thermal erosion, ground types, species densities, large trees, roads and footpaths).
//! - [`dem`] imports real elevation data (SRTM `.hgt`, 16-bit PNG, single-channel EXR).
//! - [`sample`] interpolates a height grid at any f64 world position (bilinear and C1 bicubic).
//!
//! Design choices: world coordinates are f64 metres, x east, y north, z up; grids are stored with
//! row 0 at the south edge (files are written north-up, as maps are looked at). Generation is a
//! pure function of (seed, size): randomness comes from a stateless hash of (seed, position), and
//! parallel steps split work by rows, so the bytes do not depend on the thread count.

pub mod building_mesh;
pub mod classify;
pub mod color;
pub mod dem;
pub mod erosion;
pub mod generate;
pub mod geotiff;
pub mod grid;
pub mod house_textures;
pub mod map;
pub mod mip_chain;
pub mod mosaic;
pub mod noise;
pub mod pages;
pub mod par;
pub mod patches;
pub mod pm;
pub mod poisson;
pub mod progress;
pub mod roads;
pub mod sample;
pub mod towns;

pub use grid::Grid;
pub use map::{Map, MapError};
