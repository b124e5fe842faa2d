//! Progressive meshes (seed 000): view-independent half-edge collapse orders built offline,
//! stored as stateless data that every instance of an object shares, with per-instance index
//! lists edited as the level changes.
//!
//! - [`mesh`]: welded input (positions, wedges = render vertices split at UV/normal seams).
//! - [`obj`], [`gltf_input`]: readers (glTF with MSFT_lod artist chains).
//! - [`build`]: the collapse order under three costs (the seed's longest edge, quadric, Melax).
//! - [`bound`]: the stored per-level error, a measured upper bound of the two-sided Hausdorff
//!   distance to the full mesh (never the cost).
//! - [`data`]: the level layout; [`lod`]: index lists per level; [`mod@file`]: the `.pm` format.
//! - [`measure`]: dense two-sided Hausdorff measurement between any two meshes.

pub mod bound;
pub mod build;
pub mod bvh;
pub mod data;
pub mod file;
pub mod geom;
pub mod gltf_input;
mod heap;
mod lists;
mod locality;
pub mod lod;
pub mod measure;
pub mod mesh;
pub mod obj;

pub use build::CostKind;
pub use data::{Level, PmMesh};
pub use lod::{ErrorIndex, PmEdits, PmInstance};
pub use mesh::TriMesh;

use std::path::Path;

/// Why an input mesh could not be read.
#[derive(Debug, thiserror::Error)]
pub enum MeshInputError {
    #[error(transparent)]
    Obj(#[from] obj::ObjError),
    #[error(transparent)]
    Gltf(#[from] gltf_input::GltfError),
    #[error("{path}: unknown mesh format (expected .obj, .gltf or .glb)")]
    UnknownFormat { path: std::path::PathBuf },
}

/// Reads an input mesh by file extension (for glTF, the base level of the model).
pub fn load_mesh(path: &Path) -> Result<(TriMesh, mesh::WeldReport), MeshInputError> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "obj" => Ok(obj::load(path)?),
        "gltf" | "glb" => {
            let model = gltf_input::load(path)?;
            let (_, tris) = &model.levels[0];
            let (mesh, report) = TriMesh::weld(tris);
            if mesh.triangles.is_empty() {
                return Err(gltf_input::GltfError {
                    path: path.to_path_buf(),
                    message: "every triangle is degenerate".into(),
                }
                .into());
            }
            Ok((mesh, report))
        }
        _ => Err(MeshInputError::UnknownFormat {
            path: path.to_path_buf(),
        }),
    }
}
