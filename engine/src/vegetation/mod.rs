//! Vegetation: items placed from the map's ranked Poisson-disc tile (a pure function of their
//! position: no seams, any order), drawn by the representation ladder (mesh, billboard, group
//! billboard, left out) chosen by the pixel metric, and a canopy model for splitting less
//! behind dense vegetation.
//!
//! - [`placement`]: the ranked tile scaled per species, density thinning, large trees.
//! - [`representation`](mod@representation): the ladder, a node's instance groups, the kept-groups rule, and the
//!   group-billboard clusters.
//! - [`canopy`]: line-of-sight extinction (its large trees in a sparse grid).
//! - [`plants`]: procedural unit plant meshes and each species' look.
//! - [`content`]: vegetation as a node-content kind of the streaming system.

pub mod canopy;
pub mod content;
pub mod placement;
pub mod plants;
pub mod representation;
mod sparse_grid;

pub use canopy::Canopy;
pub use placement::{Item, Kind, Placer, Species};
pub use representation::{
    InstanceGroup, NodeVegetation, Representation, node_vegetation, representation,
};
