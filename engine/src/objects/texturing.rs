//! What the texture cache is asked for each drawn textured object (seed 000's
//! MipMapFactor per texture per object): per model the length of one unit of texture
//! coordinate over its facade faces and over its roof faces, and per drawn instance each
//! texture's needed level ([`crate::texcache::mip`]) with the instance's on-screen area as its
//! importance. The objects renderer and nodebench both go through [`request_instance`].

use super::set::{ObjectSet, PmModel, ROOF_NORMAL_UP};
use crate::camera::Camera;
use crate::texcache::mip::{level_for, px_per_m, texel_m};
use crate::texcache::pool::TexturePool;
use glam::{DVec3, Vec3};

/// Per model, the longest edge (model units) of one unit of texture coordinate over the faces
/// that take the facade texture and over those that take the roof's (0 without UVs). A
/// texture's MipMapFactor on an instance is this times the instance's scale over the
/// texture's edge in texels. Texture coordinates are the mesh's UVs (metres) over
/// [`worldgen::house_textures::TILE_M`].
pub fn units_per_texture(model: &PmModel) -> [f64; 2] {
    let pm = &model.pm;
    if pm.uvs.is_empty() {
        return [0.0; 2];
    }
    let positions: Vec<[f32; 3]> = pm
        .wedge_position
        .iter()
        .map(|&p| pm.positions[p as usize])
        .collect();
    let tile = worldgen::house_textures::TILE_M as f32;
    let uvs: Vec<[f32; 2]> = pm.uvs.iter().map(|uv| uv.map(|c| c / tile)).collect();
    let (mut facade, mut roof) = (Vec::new(), Vec::new());
    for t in &pm.triangles {
        let p = t.map(|w| Vec3::from(positions[w as usize]));
        // Model space is Y-up.
        let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
        if n.y > ROOF_NORMAL_UP {
            roof.push(*t);
        } else {
            facade.push(*t);
        }
    }
    [facade, roof].map(|tris| texel_m(&positions, &uvs, &tris, 1).unwrap_or(0.0))
}

/// Registers every texture of `set` with `pool` (texture ids are indices into
/// `set.textures`) and returns each texture's mean linear colour ([`mean_colors`]).
pub fn register(pool: &mut TexturePool, set: &ObjectSet) -> Vec<[f32; 3]> {
    for chain in &set.textures {
        // Edges outside the pool's sizes are refused when the map loads.
        let _ = pool.add_texture(chain.edge_log2);
    }
    mean_colors(set)
}

/// Each texture's mean linear colour: its 1 x 1 mip level.
pub fn mean_colors(set: &ObjectSet) -> Vec<[f32; 3]> {
    set.textures
        .iter()
        .map(|chain| {
            let last = chain.levels.last().map_or(&[128u8; 4][..], |l| &l[..]);
            [0, 1, 2].map(|c| crate::color::srgb_to_linear(last[c]) as f32)
        })
        .collect()
}

/// Asks `pool` for each texture of instance `id` (bounded by the ball `centre_m`, `radius_m`)
/// at the level it needs for `camera`; `units` is [`units_per_texture`] per model.
pub fn request_instance(
    pool: &mut TexturePool,
    set: &ObjectSet,
    units: &[[f64; 2]],
    camera: &Camera,
    id: u32,
    (centre_m, radius_m): (DVec3, f64),
) {
    let inst = &set.instances[id as usize];
    let (Some(textures), Some(ppm)) = (inst.textures, px_per_m(camera, centre_m, radius_m)) else {
        return;
    };
    let screen_px = f64::from(camera.viewport_px[0]) * f64::from(camera.viewport_px[1]);
    let area_px = (radius_m * ppm).powi(2).min(screen_px);
    for (k, &t) in textures.iter().enumerate() {
        let edge = f64::from(set.textures[t as usize].edge(0));
        let texel = units[inst.model as usize][k] * inst.scale / edge;
        pool.request(t, level_for(texel, ppm, pool.coarsest_level(t)), area_px);
    }
}
