//! `engine`: the runtime of the terrain streaming engine.
//!
//! The CPU side (this crate's `world`, `decals`, `quadtree`, `bounds`, `select`, `tiles`, `mesh`,
//! `tin`, `stream`, `vegetation`, `plants` modules) never touches the GPU: it turns a map and a camera into plain data (node keys, bounds,
//! vertex/index arrays) that a renderer uploads.
//!
//! Main design choices:
//! - **One finest surface.** [`world::World::height_m`] is the finest terrain the engine can
//!   produce: bicubic map heights plus procedural detail whose amplitude follows the ground type.
//!   Every mesh samples it; every error is measured against it.
//! - **Conservative errors.** A node's error is measured on a lattice 4x finer than its mesh,
//!   plus a proven bound for what can happen between lattice points (Lipschitz constants of the
//!   surface and of the mesh). See [`bounds`].
//! - **One error metric.** `px = err_m * K / dist_m`, `K = viewport_px / (2 tan(fovy / 2))`.
//! - **Monotone errors.** A node's error also bounds its descendants' meshes, so a parent's
//!   error is never below a child's (see [`bounds`]).
//! - **Crack-free by skirts of proven depth.** See [`mesh`].
//! - **Vegetation from one ranked Poisson tile.** Items are a pure function of the map and their
//!   position: no seams, the same result in any generation order (see [`vegetation`]).
//! - World positions are f64; vertices are f32 relative to their node's origin.

pub mod app;
pub mod bounds;
pub mod decals;
pub mod measure;
pub mod mesh;
pub mod plants;
pub mod quadtree;
pub mod render;
pub mod select;
pub mod stream;
pub mod tiles;
pub mod tin;
pub mod vegetation;
pub mod world;
