//! Merged far meshes (HLOD): far away, the houses of a node are drawn as one mesh
//! made of each house at a coarse level of its progressive mesh, one draw instead of one per
//! house.
//!
//! A node of side `s` gets an error budget of one mesh cell of the node, `s / 32` metres
//! ([`error_budget_m`]); each house in it takes the coarsest level that still has a triangle
//! and whose stored error (an upper bound of the two-sided Hausdorff distance to the full mesh)
//! times its scale is within that budget, so the merged mesh is within the budget of every
//! house at full detail. It is drawn
//! instead of the single houses when the pixel metric of the objects accepts its error at the
//! distance of its bounding box: `budget x K x stretch x strength / max(d - z_disp, 1 m) <= tau`
//! ([`accepts`]; `stretch` what the flat screen does off its axis,
//! [`crate::terrain::screen_bound`]), the test each house's own level passes. Colours are per vertex: the mean
//! colour of the house's facade or roof texture (its 1 x 1 mip level), by the face's normal.

use super::lod::PmLodSettings;
use super::set::{ObjectSet, PLAIN_ALBEDO, ROOF_NORMAL_UP, model_to_world};
use crate::terrain::quadtree::NODE_QUADS;
use crate::terrain::screen_bound::ScreenBound;
use glam::DVec3;
use worldgen::pm::ErrorIndex;

/// A node's merged mesh of its houses, node-relative (origin: the node's south-west corner at
/// the lowest house base).
#[derive(Debug, Clone)]
pub struct NodeHlod {
    pub origin_m: DVec3,
    /// Per vertex: position relative to `origin_m`, unit normal, linear albedo; three vertices
    /// a triangle (flat shaded, drawn without an index list).
    pub vertices: Vec<[f32; 9]>,
    /// The error budget every house's level meets, metres.
    pub error_m: f64,
    /// Bounds of the merged mesh, world metres.
    pub lo_m: DVec3,
    pub hi_m: DVec3,
    /// Triangles of the merged houses at full detail.
    pub full_triangles: usize,
}

/// A node's error budget: one mesh cell of the node, metres.
pub fn error_budget_m(node_side_m: f64) -> f64 {
    node_side_m / f64::from(NODE_QUADS)
}

/// Whether the objects' pixel metric accepts `hlod` on the screen of `screen` (module docs),
/// with the stretch the screen gives an error of any direction in the mesh's box.
pub fn accepts(
    hlod: &NodeHlod,
    settings: &PmLodSettings,
    tau_px: f64,
    screen: &ScreenBound,
) -> bool {
    let d = crate::camera::distance_to_aabb(screen.eye_m, hlod.lo_m, hlod.hi_m);
    let stretch = screen.stretch(hlod.lo_m, hlod.hi_m, d).any;
    hlod.error_m * screen.k_px() * stretch * settings.strength / (d - settings.z_disp_m).max(1.0)
        <= tau_px
}

/// The coarsest level of a model whose stored error times `scale` is within `budget_m`, at
/// least the default MINVERTS positions and at least one triangle (a coarser level draws
/// nothing: its stored error is the distance to its points, but a house must not vanish from
/// the merged mesh that stands for it).
fn level_within(pm: &worldgen::pm::PmMesh, index: &ErrorIndex, budget_m: f64, scale: f64) -> usize {
    // The metric with K = 1 / budget at 1 m: error x scale / budget <= 1.
    let settings = PmLodSettings::default();
    let level = super::lod::choose_level(pm, index, &settings, 1.0, 1.0, 1.0 / budget_m, scale);
    let first_drawn = pm
        .levels
        .iter()
        .position(|l| l.triangles > 0)
        .map_or(1, |i| i + 1);
    level.max(first_drawn)
}

/// Merges `ids` (instances of `set`) into one mesh within `budget_m`; `means` is each texture's
/// mean linear colour. `None` for fewer than two instances.
pub fn build(
    set: &ObjectSet,
    ids: &[u32],
    node_min_m: [f64; 2],
    budget_m: f64,
    means: &[[f32; 3]],
) -> Option<NodeHlod> {
    if ids.len() < 2 {
        return None;
    }
    let base_z = ids
        .iter()
        .map(|&i| set.instances[i as usize].position_m.z)
        .fold(f64::INFINITY, f64::min);
    let origin_m = DVec3::new(node_min_m[0], node_min_m[1], base_z);
    let mut vertices = Vec::new();
    let (mut lo_m, mut hi_m) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    let mut full_triangles = 0;
    let mut list = Vec::new();
    for &id in ids {
        let inst = &set.instances[id as usize];
        let model = &set.models[inst.model as usize];
        let pm = &model.pm;
        full_triangles += pm.triangles.len();
        let level = level_within(pm, &model.index, budget_m, inst.scale);
        pm.indices_at(level, &mut list);
        let colors = inst
            .textures
            .map_or([PLAIN_ALBEDO; 2], |t| t.map(|k| means[k as usize]));
        // Flat per triangle: three vertices each (the coarse levels are small).
        for tri in list.chunks_exact(3) {
            let p = [tri[0], tri[1], tri[2]].map(|w| {
                let q = pm.positions[pm.wedge_position[w as usize] as usize];
                model_to_world(DVec3::from(q.map(f64::from)), inst, model)
            });
            let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
            let albedo = if n.z as f32 > ROOF_NORMAL_UP {
                colors[1]
            } else {
                colors[0]
            };
            for v in p {
                lo_m = lo_m.min(v);
                hi_m = hi_m.max(v);
                let r = (v - origin_m).as_vec3();
                vertices.push([
                    r.x, r.y, r.z, n.x as f32, n.y as f32, n.z as f32, albedo[0], albedo[1],
                    albedo[2],
                ]);
            }
        }
    }
    Some(NodeHlod {
        origin_m,
        vertices,
        error_m: budget_m,
        lo_m,
        hi_m,
        full_triangles,
    })
}
