//! `engine`: the runtime of the terrain streaming engine.
//!
//! The CPU side (every module except `render` and `viewer`) never touches the GPU: it turns a map
//! and a camera into plain data (node keys, bounds, vertex/index arrays, instance groups) that
//! the renderers upload.
//!
//! Main design choices:
//! - **One finest surface.** [`surface::World::height_m`] is the finest terrain the engine can
//!   produce: bicubic map heights plus procedural detail whose amplitude follows the ground type
//!   plus decal shaping. Every mesh samples it; every error is measured against it.
//! - **Conservative, monotone errors.** A node's error is measured on a lattice 4x finer than
//!   its mesh plus a proven bound for between lattice points, and also bounds its descendants'
//!   meshes (see [`terrain::bounds`]).
//! - **One error metric, on the screen.** `px = err_m * K * stretch / dist_m`,
//!   `K = viewport_px / (2 tan(fovy / 2))`, where the stretch bounds what a flat screen does off
//!   its axis (see [`terrain::screen_bound`]).
//! - **Crack-free by skirts of proven depth.** See [`terrain::mesh`].
//! - **Node content as plug-ins.** Terrain, ground textures, vegetation, light grids and houses
//!   are [`stream::ContentKind`]s with [`render::scene::NodeRenderer`]s, registered in
//!   [`kinds`]; the scheduler and the viewer know only the traits.
//! - **Vegetation from one ranked Poisson tile.** Items are a pure function of the map and their
//!   position: no seams, the same result in any generation order (see [`vegetation`]).
//! - World positions are f64; vertices are f32 relative to their node's origin.
//!
//! Modules by concern: [`surface`] (the finest surface), [`terrain`] (quad tree, bounds,
//! selection, tiles, meshes), [`vegetation`], [`stream`] (jobs, residency, fades), [`render`]
//! (one renderer per kind of thing drawn), [`camera`], [`flight`] (automatic flyover, camera
//! paths), [`viewer`] (the frame loop), [`soak`] (long headless flights sampled for growth), and behind the `measure` feature `measure` (dense error
//! measurement and reference selections for tests and benchmarks), `shown_error` (the
//! terrain error a rendered frame shows), `silhouette`, `switch_error` and `pm_image_error` (the
//! image error of vegetation's representation switches and of objects' chosen levels, on
//! rendered frames).

pub mod camera;
pub mod color;
pub mod flight;
pub mod ground;
pub mod kinds;
pub mod lighting;
#[cfg(feature = "measure")]
pub mod measure;
pub mod objects;
#[cfg(feature = "measure")]
pub mod pm_image_error;
pub mod render;
#[cfg(feature = "measure")]
pub mod shown_error;
#[cfg(feature = "measure")]
pub mod silhouette;
pub mod soak;
pub mod stream;
pub mod surface;
#[cfg(feature = "measure")]
pub mod switch_error;
pub mod terrain;
#[cfg(test)]
mod test_maps;
pub mod texcache;
pub mod vegetation;
pub mod viewer;
