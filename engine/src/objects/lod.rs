//! Which level of a progressive mesh an instance draws.
//!
//! The pixel metric of the terrain applied to an object: a level whose stored error (an upper
//! bound of the two-sided Hausdorff distance to the full mesh, model units) is `e` moves no
//! surface point by more than `e x scale` metres, which at distance `d` projects to at most
//! `e x scale x K x stretch / d` pixels on the screen (`K` = [`Camera::k_px`], `stretch` what a
//! flat screen does to a displacement of any direction off its axis, from the object's box:
//! [`ScreenBound::stretch`]; [`on_screen`] gives `d` and `K x stretch`). The instance draws the
//! coarsest level with `e x scale x K x stretch x strength / max(d - z_disp, 1 m) <= tau`, tau
//! being the terrain's (one threshold for everything drawn).
//!
//! [`Camera::k_px`]: crate::camera::Camera::k_px

use super::set::PmModel;
use crate::terrain::screen_bound::ScreenBound;
use glam::DVec3;
use worldgen::pm::{ErrorIndex, PmMesh};

/// Run-time level-of-detail settings for progressive meshes (seed 003's names in brackets).
/// The pixel threshold is not among them: objects use the terrain's tau (the streamer's).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PmLodSettings {
    /// Scales the metric: 2 halves the distance at which detail is kept (STRENGTH).
    pub strength: f64,
    /// Fewest positions ever drawn (MINVERTS).
    pub min_vertices: usize,
    /// Distance in metres subtracted before the metric applies (ZDISP).
    pub z_disp_m: f64,
    /// Draw this fraction of the positions regardless of distance (MLFIX), when set.
    pub fixed_fraction: Option<f64>,
    /// Geomorph (MORPH) over this many seconds when an instance's level changes: vertices a
    /// finer level adds grow out of the vertex they collapse onto, and vertices a coarser level
    /// drops shrink into it before they go. 0: levels switch at once.
    pub morph_s: f64,
}

impl Default for PmLodSettings {
    fn default() -> Self {
        PmLodSettings {
            strength: 1.0,
            min_vertices: 4,
            z_disp_m: 0.0,
            fixed_fraction: None,
            morph_s: 0.0,
        }
    }
}

/// The distance and the pixels per (metre / metre of distance) an object inside the sphere
/// `centre_m`, `radius_m` takes its metric with on the screen of `screen`: the distance to the
/// sphere's box, and `K` times the stretch an error of any direction in that box may get off
/// the view axis. Pass both to [`choose`].
pub fn on_screen(screen: &ScreenBound, centre_m: DVec3, radius_m: f64) -> (f64, f64) {
    let (lo, hi) = (
        centre_m - DVec3::splat(radius_m),
        centre_m + DVec3::splat(radius_m),
    );
    let d = crate::camera::distance_to_aabb(screen.eye_m, lo, hi);
    (d, screen.k_px() * screen.stretch(lo, hi, d).any)
}

/// The largest stored error (model units) allowed at `distance_m` for an object drawn at
/// `scale` metres per model unit, at threshold `tau_px`.
pub fn error_budget(
    settings: &PmLodSettings,
    tau_px: f64,
    distance_m: f64,
    k_px: f64,
    scale: f64,
) -> f64 {
    let d = (distance_m - settings.z_disp_m).max(1.0);
    tau_px * d / (k_px * settings.strength.max(1e-6) * scale.max(1e-12))
}

/// The level (number of positions) an instance draws at threshold `tau_px`. `distance_m` is the
/// distance from the camera to the nearest point of the object's bounds.
pub fn choose_level(
    pm: &PmMesh,
    index: &ErrorIndex,
    settings: &PmLodSettings,
    tau_px: f64,
    distance_m: f64,
    k_px: f64,
    scale: f64,
) -> usize {
    let n = pm.level_count();
    if let Some(f) = settings.fixed_fraction {
        return pm.clamp_level((f.clamp(0.0, 1.0) * n as f64).ceil() as usize);
    }
    let budget = error_budget(settings, tau_px, distance_m, k_px, scale) as f32;
    index.coarsest_within(pm, budget, settings.min_vertices)
}

/// What an instance of a model draws: chain option `option` (0 the base progressive mesh, `k`
/// the `MSFT_lod` chain level `k`) at `level` of that option's progressive mesh.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Choice {
    pub option: usize,
    pub level: usize,
}

/// The fewest triangles within the metric over the base and its artist chain: an option's
/// error is its chain bound plus the stored error of its level (the Hausdorff distance obeys the
/// triangle inequality), and the option whose coarsest level within the budget draws the fewest
/// triangles wins (ties: the finer option). A fixed fraction (MLFIX) applies to the base.
pub fn choose(
    model: &PmModel,
    settings: &PmLodSettings,
    tau_px: f64,
    distance_m: f64,
    k_px: f64,
    scale: f64,
) -> Choice {
    let base = choose_level(
        &model.pm,
        &model.index,
        settings,
        tau_px,
        distance_m,
        k_px,
        scale,
    );
    let mut best = Choice {
        option: 0,
        level: base,
    };
    if settings.fixed_fraction.is_some() {
        return best;
    }
    let mut fewest = model.pm.triangles_at(base);
    let budget = error_budget(settings, tau_px, distance_m, k_px, scale);
    for (k, chain) in model.chain.iter().enumerate() {
        let left = budget - f64::from(chain.error);
        if left < 0.0 {
            continue;
        }
        let m = &chain.model;
        let level = m
            .index
            .coarsest_within(&m.pm, left as f32, settings.min_vertices);
        let tris = m.pm.triangles_at(level);
        if tris < fewest {
            fewest = tris;
            best = Choice {
                option: k + 1,
                level,
            };
        }
    }
    best
}
