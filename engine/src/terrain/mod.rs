//! Terrain: the quad tree, conservative node bounds, per-frame selection by the pixel metric,
//! 16 m tiles of the finest surface, and crack-free skirted node meshes.
//!
//! - [`quadtree`]: node keys and geometry (root over the map, 8 m leaves, 32 x 32 quads a node).
//! - [`bounds`]: proven, monotone per-node errors and height ranges; [`precomputed`]: the 32 m
//!   nodes' bounds measured once per map and kept with the map-error grids.
//! - [`select`]: split while the projected error exceeds tau; frustum culling;
//!   [`screen_bound`]: the projected error on a flat screen, off-axis stretch included.
//! - [`tiles`]: 16 m tiles of the finest surface at 0.25 m, refcounted.
//! - [`mesh`]: node meshes with skirts of proven depth; [`mesh_surface`]: a mesh's drawn
//!   surface sampled through its own triangles (for measuring any variant).
//! - [`content`]: terrain as a node-content kind of the streaming system.
//! - `tin` (feature `measure`): an error-bounded TIN variant, a benchmark reference.

pub mod bounds;
pub mod content;
pub mod mesh;
pub mod mesh_surface;
pub mod precomputed;
pub mod quadtree;
pub mod refine;
pub mod screen_bound;
pub mod select;
pub mod tiles;
#[cfg(feature = "measure")]
pub mod tin;
