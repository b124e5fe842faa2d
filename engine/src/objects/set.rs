//! The progressive-mesh models of a run and their placed instances.
//!
//! Models are read from `.pm` files or built at start-up from `.obj` / `.gltf` / `.glb` (quadric
//! cost). Model files are taken as Y-up (glTF's convention, and that of the shared OBJ meshes);
//! the world is Z-up, so a model's +Y becomes the world's +Z and its +Z the world's -Y.
//!
//! A glTF model with an `MSFT_lod` chain (seed 001's artist LOD chains) keeps every chain level
//! as a progressive mesh of its own, with a bound of its two-sided Hausdorff distance to the base
//! model ([`ChainLevel::error`]); the level choice ([`crate::objects::lod::choose`]) adds that
//! bound to the chain level's stored PM error, so artist levels and PM levels meet the same
//! pixel metric.

use glam::DVec3;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use worldgen::house_textures::MipChain;
use worldgen::map::Building;
use worldgen::map::building_models::{BuildingModel, BuildingTexture};
use worldgen::pm::measure::{hausdorff_bound, mesh_soup};
use worldgen::pm::{CostKind, ErrorIndex, PmEdits, PmMesh, TriMesh, file, gltf_input, load_mesh};

/// Sample spacing of the stored PM errors and of the chain bounds, fraction of the diagonal.
const BOUND_FRACTION: f64 = 0.005;

/// Why a model could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ObjectError {
    #[error(transparent)]
    Pm(#[from] worldgen::pm::file::PmError),
    #[error(transparent)]
    Mesh(#[from] worldgen::pm::MeshInputError),
    #[error("{path}: the model has no triangles")]
    Empty { path: PathBuf },
    #[error("{path}: MSFT_lod level {level} ({name}) has no triangles")]
    EmptyChainLevel {
        path: PathBuf,
        level: usize,
        name: String,
    },
}

/// One level of an artist LOD chain: its own progressive mesh (in the base model's space) and
/// an upper bound of its full mesh's two-sided Hausdorff distance to the base model.
#[derive(Debug)]
pub struct ChainLevel {
    pub model: PmModel,
    /// Model units; a PM level of this chain level is within `error` + its stored error of the
    /// base model (the triangle inequality of the Hausdorff distance).
    pub error: f32,
}

/// One progressive mesh with everything instances share.
#[derive(Debug)]
pub struct PmModel {
    pub name: String,
    pub pm: PmMesh,
    pub edits: PmEdits,
    pub index: ErrorIndex,
    /// Per-wedge unit normals (from the file, else area-weighted over each position's faces).
    pub normals: Vec<[f32; 3]>,
    /// Bounds of the full mesh, model units.
    pub lo: DVec3,
    pub hi: DVec3,
    /// Coarser artist levels (`MSFT_lod`), finest first; empty for most models.
    pub chain: Vec<ChainLevel>,
}

/// The world position of model point `p` (model units, Y-up) for an instance.
pub fn model_to_world(p: DVec3, inst: &ObjectInstance, model: &PmModel) -> DVec3 {
    // Centre the footprint on the instance position, base on the ground.
    let c = (model.lo + model.hi) * 0.5;
    let local = DVec3::new(p.x - c.x, -(p.z - c.z), p.y - model.lo.y) * inst.scale;
    let (s, co) = inst.yaw_rad.sin_cos();
    inst.position_m
        + DVec3::new(
            co * local.x - s * local.y,
            s * local.x + co * local.y,
            local.z,
        )
}

impl PmModel {
    /// Reads a `.pm` file, or builds one from a mesh file (with a glTF file's `MSFT_lod`
    /// chain, if it has one).
    pub fn load(path: &Path) -> Result<Self, ObjectError> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        let name = path
            .file_stem()
            .map_or_else(|| "model".into(), |s| s.to_string_lossy().into_owned());
        let empty = || ObjectError::Empty {
            path: path.to_path_buf(),
        };
        if ext == "gltf" || ext == "glb" {
            let model = gltf_input::load(path).map_err(worldgen::pm::MeshInputError::from)?;
            let mut meshes = Vec::with_capacity(model.levels.len());
            for (level, (level_name, tris)) in model.levels.iter().enumerate() {
                let (mesh, _) = TriMesh::weld(tris);
                if mesh.triangles.is_empty() {
                    return Err(if level == 0 {
                        empty()
                    } else {
                        ObjectError::EmptyChainLevel {
                            path: path.to_path_buf(),
                            level,
                            name: level_name.clone(),
                        }
                    });
                }
                meshes.push(mesh);
            }
            return Ok(Self::with_chain(&name, &meshes));
        }
        let pm = if ext == "pm" {
            file::read(path)?
        } else {
            let (mesh, _) = load_mesh(path)?;
            PmMesh::build(&mesh, CostKind::Quadric, BOUND_FRACTION, &mut |_, _, _| {}).0
        };
        if pm.triangles.is_empty() {
            return Err(empty());
        }
        Ok(Self::from_pm(name, pm))
    }

    /// A model from its base mesh (`meshes[0]`) and artist chain levels (the rest, finest
    /// first, non-empty): a progressive mesh each (quadric cost), every chain level with its
    /// Hausdorff bound to the base, sampled at the stored errors' spacing (base diagonal).
    pub fn with_chain(name: &str, meshes: &[TriMesh]) -> Self {
        let build =
            |m: &TriMesh| PmMesh::build(m, CostKind::Quadric, BOUND_FRACTION, &mut |_, _, _| {}).0;
        let mut model = Self::from_pm(name.to_string(), build(&meshes[0]));
        let base = mesh_soup(&meshes[0]);
        let spacing = (meshes[0].diagonal() as f64 * BOUND_FRACTION).max(f64::MIN_POSITIVE);
        for (k, mesh) in meshes.iter().enumerate().skip(1) {
            let error = hausdorff_bound(&base, &mesh_soup(mesh), spacing) as f32;
            model.chain.push(ChainLevel {
                model: Self::from_pm(format!("{name} lod {k}"), build(mesh)),
                error,
            });
        }
        model
    }

    /// The progressive mesh of chain option `option`: 0 the base, `k` chain level `k`.
    pub fn option(&self, option: usize) -> &PmModel {
        if option == 0 {
            self
        } else {
            &self.chain[option - 1].model
        }
    }

    pub fn from_pm(name: String, pm: PmMesh) -> Self {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = -lo;
        for p in &pm.positions {
            let v = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            lo = lo.min(v);
            hi = hi.max(v);
        }
        let normals = if pm.normals.is_empty() {
            let mut acc = vec![DVec3::ZERO; pm.positions.len()];
            for t in &pm.triangles {
                let p = t.map(|w| pm.wedge_position[w as usize] as usize);
                let v = p.map(|i| {
                    let q = pm.positions[i];
                    DVec3::new(q[0] as f64, q[1] as f64, q[2] as f64)
                });
                let n = (v[1] - v[0]).cross(v[2] - v[0]);
                for i in p {
                    acc[i] += n;
                }
            }
            pm.wedge_position
                .iter()
                .map(|&p| acc[p as usize].normalize_or_zero().as_vec3().to_array())
                .collect()
        } else {
            pm.normals.clone()
        };
        PmModel {
            name,
            edits: PmEdits::new(&pm),
            index: ErrorIndex::new(&pm),
            normals,
            pm,
            lo,
            hi,
            chain: Vec::new(),
        }
    }

    /// Radius of the bounding sphere around the bounds' centre, model units.
    pub fn radius(&self) -> f64 {
        (self.hi - self.lo).length() * 0.5
    }
}

/// One placed object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjectInstance {
    pub model: u32,
    /// Where the middle of the model's base stands, world metres.
    pub position_m: DVec3,
    pub yaw_rad: f64,
    /// Metres per model unit.
    pub scale: f64,
    /// Indices into [`ObjectSet::textures`] of the facade and roof textures (faces whose normal
    /// points up more than [`ROOF_NORMAL_UP`] take the roof's), if the instance is textured.
    pub textures: Option<[u32; 2]>,
}

/// A face whose unit normal's up component exceeds this takes an instance's roof texture.
pub const ROOF_NORMAL_UP: f32 = 0.3;
/// Linear albedo of untextured objects.
pub const PLAIN_ALBEDO: [f32; 3] = [0.62, 0.58, 0.52];

/// Models, textures and instances of a run.
#[derive(Debug, Default)]
pub struct ObjectSet {
    pub models: Vec<PmModel>,
    /// Textures with their mip chains (texture coordinates in metres over
    /// [`worldgen::house_textures::TILE_M`]); streamed by the texture cache.
    pub textures: Vec<MipChain>,
    pub instances: Vec<ObjectInstance>,
}

impl ObjectSet {
    /// The map's houses: one model per house type (its progressive mesh from the map's
    /// `buildings/<type>.pm`), one instance per row, standing on its pad with its longer side
    /// along its yaw, with the facade and roof textures its row names.
    pub fn from_buildings(
        buildings: &[Building],
        models: &[BuildingModel],
        textures: &[BuildingTexture],
    ) -> Self {
        let mut set = ObjectSet {
            models: models
                .iter()
                .map(|m| PmModel::from_pm(m.type_name.clone(), m.pm.clone()))
                .collect(),
            textures: textures.iter().map(|t| t.chain.clone()).collect(),
            instances: Vec::with_capacity(buildings.len()),
        };
        let texture = |name: &str| {
            textures
                .iter()
                .position(|t| t.name == name)
                .map(|i| i as u32)
        };
        let index: HashMap<&str, u32> = models
            .iter()
            .enumerate()
            .map(|(i, m)| (m.type_name.as_str(), i as u32))
            .collect();
        // `Map::load` checked that every type has its mesh.
        for b in buildings {
            if let Some(&model) = index.get(b.type_name.as_str()) {
                set.instances.push(ObjectInstance {
                    model,
                    position_m: DVec3::new(b.x_m, b.y_m, b.z_m),
                    yaw_rad: b.yaw_deg.to_radians(),
                    scale: 1.0,
                    textures: texture(&b.facade_texture)
                        .zip(texture(&b.roof_texture))
                        .map(|(f, r)| [f, r]),
                });
            }
        }
        set
    }

    /// Appends another set's models, textures and instances.
    pub fn append(&mut self, other: ObjectSet) {
        let offset = self.models.len() as u32;
        let tex_offset = self.textures.len() as u32;
        self.models.extend(other.models);
        self.textures.extend(other.textures);
        self.instances
            .extend(other.instances.into_iter().map(|i| ObjectInstance {
                model: i.model + offset,
                textures: i.textures.map(|t| t.map(|k| k + tex_offset)),
                ..i
            }));
    }

    /// The centre and radius (m) of an instance's bounding sphere.
    pub fn sphere(&self, inst: &ObjectInstance) -> (DVec3, f64) {
        let m = &self.models[inst.model as usize];
        let c = model_to_world((m.lo + m.hi) * 0.5, inst, m);
        (c, m.radius() * inst.scale)
    }

    /// Places `count` instances of every model in a row: from `start_m` along `dir`, `spacing_m`
    /// apart, each `size_m` across, standing on the ground given by `ground_m`.
    pub fn place_row(
        models: Vec<PmModel>,
        start_m: [f64; 2],
        dir: [f64; 2],
        count: usize,
        spacing_m: f64,
        size_m: f64,
        ground_m: impl Fn(f64, f64) -> f64,
    ) -> Self {
        let len = dir[0].hypot(dir[1]).max(1e-9);
        let (dx, dy) = (dir[0] / len, dir[1] / len);
        let mut instances = Vec::new();
        let mut k = 0usize;
        for i in 0..count {
            for (m, model) in models.iter().enumerate() {
                let along = spacing_m * k as f64;
                // Alternate sides of the line so the row does not block itself.
                let side = if k.is_multiple_of(2) { 1.0 } else { -1.0 } * spacing_m * 0.4;
                let x = start_m[0] + dx * along - dy * side;
                let y = start_m[1] + dy * along + dx * side;
                let extent = (model.hi - model.lo).max_element().max(1e-9);
                instances.push(ObjectInstance {
                    model: m as u32,
                    position_m: DVec3::new(x, y, ground_m(x, y)),
                    yaw_rad: (i as f64 * 0.9 + m as f64 * 2.1) % std::f64::consts::TAU,
                    scale: size_m / extent,
                    textures: None,
                });
                k += 1;
            }
        }
        ObjectSet {
            models,
            textures: Vec::new(),
            instances,
        }
    }
}
