//! glTF 2.0 input (`.gltf` with external or embedded buffers, `.glb`) through the `gltf` crate:
//! every triangle primitive of the default scene, with node transforms applied, POSITION plus
//! NORMAL and TEXCOORD_0 when present. Images are never decoded.
//!
//! **MSFT_lod.** A node may list lower-detail alternatives (`"MSFT_lod": {"ids": [...]}`, node
//! indices, finest first). The base model is the scene as is; chain level k is the scene with
//! that node's mesh replaced by the mesh of its k-th alternative, placed by the base node's
//! transform (the alternative's own transform is ignored: it is the same object). One chain per
//! file is read; a second is refused with an error rather than silently dropped.

use super::mesh::Corner;
use glam::{Mat3, Mat4, Vec3};
use std::path::{Path, PathBuf};

/// Why a glTF file could not be read; names the file and the node, mesh or primitive.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct GltfError {
    pub path: PathBuf,
    pub message: String,
}

/// The model and its artist LOD chain, each as triangles of corners.
#[derive(Debug, Clone, Default)]
pub struct GltfModel {
    /// Level 0 is the full model; levels 1.. come from MSFT_lod, finest first.
    pub levels: Vec<(String, Vec<[Corner; 3]>)>,
}

struct Ctx<'a> {
    path: &'a Path,
    buffers: &'a [gltf::buffer::Data],
}

impl Ctx<'_> {
    fn err(&self, message: String) -> GltfError {
        GltfError {
            path: self.path.to_path_buf(),
            message,
        }
    }

    /// Appends the triangles of `mesh` under the world transform `world`.
    fn mesh_triangles(
        &self,
        mesh: &gltf::Mesh<'_>,
        world: Mat4,
        out: &mut Vec<[Corner; 3]>,
    ) -> Result<(), GltfError> {
        let normal_m = Mat3::from_mat4(world).inverse().transpose();
        for prim in mesh.primitives() {
            let where_ = format!("mesh {} primitive {}", mesh.index(), prim.index());
            if prim.mode() != gltf::mesh::Mode::Triangles {
                return Err(self.err(format!(
                    "{where_}: mode {:?}; only TRIANGLES (4) is read",
                    prim.mode()
                )));
            }
            let reader = prim.reader(|b| self.buffers.get(b.index()).map(|d| &d.0[..]));
            let positions: Vec<[f32; 3]> = reader
                .read_positions()
                .ok_or_else(|| self.err(format!("{where_}: no POSITION attribute")))?
                .collect();
            let normals: Option<Vec<[f32; 3]>> = reader.read_normals().map(Iterator::collect);
            let uvs: Option<Vec<[f32; 2]>> =
                reader.read_tex_coords(0).map(|t| t.into_f32().collect());
            let indices: Vec<u32> = match reader.read_indices() {
                Some(i) => i.into_u32().collect(),
                None => (0..positions.len() as u32).collect(),
            };
            if !indices.len().is_multiple_of(3) {
                return Err(self.err(format!(
                    "{where_}: {} indices is not a multiple of 3",
                    indices.len()
                )));
            }
            for (name, n) in [
                ("NORMAL", normals.as_ref().map(Vec::len)),
                ("TEXCOORD_0", uvs.as_ref().map(Vec::len)),
            ] {
                if let Some(n) = n
                    && n != positions.len()
                {
                    return Err(self.err(format!(
                        "{where_}: {name} has {n} entries, POSITION {}",
                        positions.len()
                    )));
                }
            }
            let corner = |i: u32| -> Result<Corner, GltfError> {
                let k = i as usize;
                let p = positions.get(k).ok_or_else(|| {
                    self.err(format!(
                        "{where_}: index {i} is beyond the {} vertices",
                        positions.len()
                    ))
                })?;
                let wp = world.transform_point3(Vec3::from(*p)).to_array();
                if wp.iter().any(|x| !x.is_finite()) {
                    return Err(self.err(format!("{where_}: vertex {i} is not finite")));
                }
                Ok(Corner {
                    position: wp,
                    uv: uvs.as_ref().map(|u| u[k]),
                    normal: normals
                        .as_ref()
                        .map(|n| (normal_m * Vec3::from(n[k])).normalize_or_zero().to_array()),
                })
            };
            for t in indices.chunks_exact(3) {
                out.push([corner(t[0])?, corner(t[1])?, corner(t[2])?]);
            }
        }
        Ok(())
    }
}

/// The MSFT_lod alternatives of a node, if it has any.
fn lod_ids(node: &gltf::Node<'_>, ctx: &Ctx<'_>) -> Result<Option<Vec<usize>>, GltfError> {
    let Some(v) = node.extension_value("MSFT_lod") else {
        return Ok(None);
    };
    let ids = v.get("ids").and_then(|x| x.as_array()).ok_or_else(|| {
        ctx.err(format!(
            "node {}: MSFT_lod has no `ids` array",
            node.index()
        ))
    })?;
    ids.iter()
        .map(|x| {
            x.as_u64().map(|i| i as usize).ok_or_else(|| {
                ctx.err(format!(
                    "node {}: MSFT_lod id {x} is not a node index",
                    node.index()
                ))
            })
        })
        .collect::<Result<Vec<_>, _>>()
        .map(Some)
}

/// Reads a glTF or GLB file.
pub fn load(path: &Path) -> Result<GltfModel, GltfError> {
    // The gltf crate (1.4) panics on some damaged files instead of returning an error (an
    // accessor index past its array in validation, accessor readers on inconsistent views);
    // found by fuzzing. Contained here as an error naming the file.
    std::panic::catch_unwind(|| read_model(path)).unwrap_or_else(|_| {
        Err(GltfError {
            path: path.to_path_buf(),
            message: "not a valid glTF: the glTF reader failed on it (an index or a view points \
                      outside its data)"
                .into(),
        })
    })
}

fn read_model(path: &Path) -> Result<GltfModel, GltfError> {
    let fail = |message: String| GltfError {
        path: path.to_path_buf(),
        message,
    };
    let gltf = gltf::Gltf::open(path).map_err(|e| fail(format!("not a valid glTF: {e}")))?;
    let buffers = gltf::import_buffers(&gltf.document, path.parent(), gltf.blob.clone())
        .map_err(|e| fail(format!("cannot load buffers: {e}")))?;
    let doc = &gltf.document;
    let ctx = Ctx {
        path,
        buffers: &buffers,
    };
    let scene = doc
        .default_scene()
        .or_else(|| doc.scenes().next())
        .ok_or_else(|| fail("no scene".into()))?;
    // Walk the scene: (node, parent world transform).
    let mut stack: Vec<(gltf::Node<'_>, Mat4)> =
        scene.nodes().map(|n| (n, Mat4::IDENTITY)).collect();
    let mut placed: Vec<(gltf::Node<'_>, Mat4)> = Vec::new();
    let mut visited = vec![false; doc.nodes().len()];
    while let Some((node, parent)) = stack.pop() {
        if std::mem::replace(&mut visited[node.index()], true) {
            return Err(fail(format!(
                "node {} appears twice in the scene",
                node.index()
            )));
        }
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        for c in node.children() {
            stack.push((c, world));
        }
        placed.push((node, parent));
    }
    placed.sort_by_key(|(n, _)| n.index());
    let chains: Vec<(usize, Vec<usize>)> = placed
        .iter()
        .filter_map(|(n, _)| {
            lod_ids(n, &ctx)
                .transpose()
                .map(|ids| ids.map(|i| (n.index(), i)))
        })
        .collect::<Result<_, _>>()?;
    if chains.len() > 1 {
        return Err(fail(format!(
            "nodes {} and {} both carry MSFT_lod; one chain per file is supported",
            chains[0].0, chains[1].0
        )));
    }
    let chain = chains.into_iter().next();
    let n_levels = 1 + chain.as_ref().map_or(0, |c| c.1.len());
    let mut levels = Vec::with_capacity(n_levels);
    for level in 0..n_levels {
        let mut tris = Vec::new();
        for (node, parent) in &placed {
            let mut source = node.clone();
            if let Some((base, ids)) = &chain
                && *base == node.index()
                && level > 0
            {
                let id = ids[level - 1];
                source = doc.nodes().nth(id).ok_or_else(|| {
                    fail(format!(
                        "node {base}: MSFT_lod names node {id}, which does not exist"
                    ))
                })?;
            }
            // The alternative takes the base node's place: the base node's transform applies.
            let world = *parent * Mat4::from_cols_array_2d(&node.transform().matrix());
            if let Some(mesh) = source.mesh() {
                ctx.mesh_triangles(&mesh, world, &mut tris)?;
            }
        }
        let name = if level == 0 {
            "LOD0 (base)".to_string()
        } else {
            format!("LOD{level} (MSFT_lod)")
        };
        if tris.is_empty() {
            return Err(fail(format!("{name}: no triangles")));
        }
        levels.push((name, tris));
    }
    Ok(GltfModel { levels })
}
