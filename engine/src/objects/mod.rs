//! Objects other than terrain: progressive meshes (seed 000) whose level per instance follows the
//! terrain's pixel metric (seed 001), with the run-time knobs of seed 003 (STRENGTH, MINVERTS,
//! ZDISP, fixed level). CPU logic only; drawing lives in `render`.
//!
//! - [`set`]: models (`.pm`, or built from `.obj` / glTF at start-up) and placed instances.
//! - [`content`]: the `objects` kind (a node's payload: the instances inside it).
//! - [`lod`]: the level per instance (proven against rendered silhouettes in tests/e2e/pm.rs).
//! - [`texturing`]: what the texture cache is asked for each drawn textured instance.
//! - [`hlod`]: a wide node's houses merged into one far mesh.
//!
//! The renderer (`render::objects`) keeps one index list per drawn instance, edited level by
//! level (seed 000's per-instance triangle lists), and geomorphs level changes over
//! `PmLodSettings::morph_s` (MORPH).

pub mod content;
pub mod hlod;
pub mod lod;
pub mod set;
pub mod texturing;
