//! Objects other than terrain: progressive meshes (seed 000) whose level per instance follows the
//! terrain's pixel metric (seed 001), with the run-time knobs of seed 003 (STRENGTH, MINVERTS,
//! ZDISP, fixed level). CPU logic only; drawing lives in `render`.
//!
//! State of issue 18: the level choice is here and proven against rendered silhouettes
//! (tests/tests/e2e/pm.rs); streaming PM objects as node content, geomorphing and the viewer's
//! debug views are not built yet.

pub mod lod;
