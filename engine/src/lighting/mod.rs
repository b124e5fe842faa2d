//! Static lighting from light grids (seed 002: "static lighting is calculated using a light
//! grid, which is created for a higher-level node when there are descendant nodes that need
//! it"). CPU only, no wgpu.
//!
//! A [`grid::LightGrid`] belongs to a node of side [`grid::GRID_SIDE_M`]; its samples are
//! columns [`grid::COLUMN_SPACING_M`] apart (the border columns are shared with the
//! neighbouring grids and computed from the same world positions, so both hold the same values)
//! with layers at fixed heights above the finest surface up to the tree tops. Each sample holds
//! the sky visibility (the share of a horizontal receiver's cosine-weighted sky that neither the
//! terrain horizon nor the vegetation canopy hides), the sun visibility (terrain shadow times
//! the canopy's transmittance toward the sun, [`grid::Sun`]) and the ground's bounce (the
//! sunlit terrain that hides the sky, per unit albedo and sun irradiance; the shaders colour it
//! with the map's mean ground albedo, so the ambient light takes the ground's colour where
//! terrain hides the sky).
//!
//! Grids of every level compute a column identically, so a coarse grid's columns hold the finer
//! grids' bytes; [`seams`] finds the drawn nodes that must read their grid at a coarser
//! neighbour's columns along a side to meet it without a step.
//!
//! [`sky_pages`] keeps each grid's sky (no sun changes it, and it is most of a grid's cost)
//! with the map, so a node's grid is made again from its page at a fraction of the cost.
//!
//! [`content`] makes grids a node-content kind (shared by a grid node's descendants, relit in
//! the background when the sun changes); `render::lighting` uploads them into slots of one 3D
//! texture that the terrain, vegetation and object shaders sample trilinearly.
//!
//! Not done: a dominant light direction; the bounce leaves out the shadows cast on
//! the terrain that bounces the light.

pub mod content;
pub mod grid;
#[cfg(feature = "measure")]
pub mod reference;
pub mod seams;
pub mod sky_pages;

pub use grid::{LightGrid, Sun};
