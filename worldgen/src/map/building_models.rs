//! The house types' progressive meshes and the houses' textures, in the map's `buildings/`
//! folder: `<type>.pm`, one per type named in `buildings.csv` (each type is built
//! once, offline, and its instances share it), and the PNG textures the rows name. Meshes are
//! read with the checksummed, validated `.pm` reader; a mesh that does not match its type's
//! footprint (a stale mesh after `buildings.csv` was edited) is refused; a texture must be a mip
//! atlas or a square power-of-two image ([`crate::house_textures`]).

use super::{Building, MapError};
use crate::house_textures::MipChain;
use crate::pm::PmMesh;
use crate::pm::file;
use std::path::{Path, PathBuf};

/// Folder of the house meshes inside the map folder.
pub const FOLDER: &str = "buildings";

/// How closely a mesh's extent must match its type's footprint, metres.
const FIT_TOLERANCE_M: f64 = 0.02;

/// One house type's progressive mesh (model space: Y-up metres, the longer side along x).
#[derive(Debug, Clone, PartialEq)]
pub struct BuildingModel {
    pub type_name: String,
    pub pm: PmMesh,
}

/// A texture the houses name, with its mip chain.
#[derive(Debug, Clone, PartialEq)]
pub struct BuildingTexture {
    /// File name in the `buildings/` folder.
    pub name: String,
    pub chain: MipChain,
}

/// The texture names `buildings` use, in order of first appearance (facade before roof).
pub fn texture_names(buildings: &[Building]) -> Vec<&str> {
    let mut seen: Vec<&str> = Vec::new();
    for b in buildings {
        for name in [b.facade_texture.as_str(), b.roof_texture.as_str()] {
            if !seen.contains(&name) {
                seen.push(name);
            }
        }
    }
    seen
}

/// Reads every texture `buildings` name.
pub fn read_textures(dir: &Path, buildings: &[Building]) -> Result<Vec<BuildingTexture>, MapError> {
    texture_names(buildings)
        .into_iter()
        .map(|name| {
            let p = dir.join(FOLDER).join(name);
            let chain = MipChain::from_png(&p).map_err(|problem| MapError::InvalidField {
                path: p.clone(),
                field: "texture".into(),
                problem,
            })?;
            Ok(BuildingTexture {
                name: name.to_string(),
                chain,
            })
        })
        .collect()
}

/// Writes every texture as a mip atlas into `dir`'s building folder.
pub fn write_textures(dir: &Path, textures: &[BuildingTexture]) -> Result<(), MapError> {
    let folder = dir.join(FOLDER);
    if !textures.is_empty() {
        std::fs::create_dir_all(&folder).map_err(|e| MapError::io(&folder, "create folder", e))?;
    }
    for t in textures {
        let p = folder.join(&t.name);
        t.chain
            .write_png(&p)
            .map_err(|problem| MapError::InvalidField {
                path: p.clone(),
                field: "texture".into(),
                problem,
            })?;
    }
    Ok(())
}

/// Where a type's mesh lives.
pub fn path(dir: &Path, type_name: &str) -> PathBuf {
    dir.join(FOLDER).join(format!("{type_name}.pm"))
}

/// The types of `buildings` in order of first appearance, each with one of its rows.
pub fn types(buildings: &[Building]) -> Vec<&Building> {
    let mut seen: Vec<&Building> = Vec::new();
    for b in buildings {
        if !seen.iter().any(|s| s.type_name == b.type_name) {
            seen.push(b);
        }
    }
    seen
}

/// Reads and checks the mesh of every type in `buildings`.
pub fn read(dir: &Path, buildings: &[Building]) -> Result<Vec<BuildingModel>, MapError> {
    types(buildings)
        .into_iter()
        .map(|b| {
            let p = path(dir, &b.type_name);
            let pm = file::read(&p)?;
            check_fit(&p, b, &pm)?;
            Ok(BuildingModel {
                type_name: b.type_name.clone(),
                pm,
            })
        })
        .collect()
}

/// Writes every model into `dir`'s building folder.
pub fn write(dir: &Path, models: &[BuildingModel]) -> Result<(), MapError> {
    if models.is_empty() {
        return Ok(());
    }
    let folder = dir.join(FOLDER);
    std::fs::create_dir_all(&folder).map_err(|e| MapError::io(&folder, "create folder", e))?;
    for m in models {
        file::write(&m.pm, &path(dir, &m.type_name))?;
    }
    Ok(())
}

/// The mesh's extent along x (model) is the type's width and along z its depth.
pub fn check_fit(path: &Path, b: &Building, pm: &PmMesh) -> Result<(), MapError> {
    let extent = |axis: usize| {
        let (lo, hi) = pm
            .positions
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(f64::from(p[axis])), hi.max(f64::from(p[axis])))
            });
        hi - lo
    };
    for (axis, field, want) in [
        (0, "width_m", b.spec.width_m),
        (2, "depth_m", b.spec.depth_m),
    ] {
        let got = extent(axis);
        if (got - want).abs() > FIT_TOLERANCE_M {
            return Err(MapError::InvalidField {
                path: path.to_path_buf(),
                field: format!("house type {}", b.type_name),
                problem: format!(
                    "the mesh is {got:.3} m across where buildings.csv says {field} = {want}; regenerate the mesh (`worldgen generate`) after editing a type"
                ),
            });
        }
    }
    Ok(())
}
