//! The independent reference for light grids (feature `measure`, for tests and nodebench): sky
//! and sun visibility at one point by rays marched on the finest surface `F`
//! ([`World::height_m`] at every step, not the grid's height lattice or the map heights)
//! through the canopy model, with many more directions and finer steps than the grid takes.
//! It shares no code with [`super::grid`]; only the model is common (`F` and
//! [`Canopy::extinction_per_m`]).

use super::grid::Sun;
use crate::surface::World;
use crate::vegetation::canopy::Canopy;
use glam::DVec3;

/// Azimuths (offset half a step, so none coincides with a grid azimuth).
pub const REF_AZIMUTHS: usize = 48;
/// Bands of `sin^2(elevation)` (equal weight for a horizontal receiver).
pub const REF_BANDS: usize = 24;
/// Canopy step (m).
pub const REF_CANOPY_STEP_M: f64 = 1.5;

/// Highest tangent of the terrain seen from `p` along unit horizontal `dir`, marched on `F`
/// from 0.5 m with steps of 2 % of the distance (at least 0.5 m) out to 4 km.
fn horizon_tan(world: &World, p: DVec3, dir: [f64; 2]) -> f64 {
    let mut best = f64::NEG_INFINITY;
    let mut r = 0.5f64;
    while r <= 4000.0 {
        let h = world.height_m(p.x + dir[0] * r, p.y + dir[1] * r);
        best = best.max((h - p.z) / r);
        r += (0.02 * r).max(0.5);
    }
    best
}

/// `exp(-optical depth)` from `p` along unit `w`, marched on `F` in 1.5 m steps for twice the
/// length that climbs out of the canopy over flat ground (so ground rising under the ray is
/// followed), at most 400 m.
fn transmittance(world: &World, canopy: &Canopy, p: DVec3, w: DVec3) -> f64 {
    let above0 = p.z - world.height_m(p.x, p.y);
    if above0 >= canopy.top_m {
        return 1.0;
    }
    let len = (2.0 * (canopy.top_m - above0) / w.z).min(400.0);
    let n = (len / REF_CANOPY_STEP_M).ceil().max(1.0) as usize;
    let dl = len / n as f64;
    let mut depth = 0.0;
    for k in 0..n {
        let q = p + w * ((k as f64 + 0.5) * dl);
        let above = q.z - world.height_m(q.x, q.y);
        depth += canopy.extinction_per_m(q.x, q.y, above) * dl;
    }
    (-depth).exp()
}

/// Sky and sun visibility at (`x_m`, `y_m`), `above_m` metres over `F`.
pub fn visibility(
    world: &World,
    canopy: &Canopy,
    x_m: f64,
    y_m: f64,
    above_m: f64,
    sun: Sun,
) -> (f64, f64) {
    let p = DVec3::new(x_m, y_m, world.height_m(x_m, y_m) + above_m);
    let mut sky = 0.0;
    for a in 0..REF_AZIMUTHS {
        let phi = std::f64::consts::TAU * (a as f64 + 0.5) / REF_AZIMUTHS as f64;
        let dir = [phi.sin(), phi.cos()];
        let t = horizon_tan(world, p, dir);
        // The horizon's elevation as sin^2, 0 when it lies below the horizontal.
        let s_h = if t > 0.0 { t * t / (1.0 + t * t) } else { 0.0 };
        for b in 0..REF_BANDS {
            let s = (b as f64 + 0.5) / REF_BANDS as f64;
            if s <= s_h {
                continue;
            }
            let c = (1.0 - s).sqrt();
            let w = DVec3::new(dir[0] * c, dir[1] * c, s.sqrt());
            sky += transmittance(world, canopy, p, w);
        }
    }
    sky /= (REF_AZIMUTHS * REF_BANDS) as f64;
    let toward = sun.toward();
    let flat = toward.truncate().length();
    let sun_vis = if sun.elevation_deg <= 0.0 {
        0.0
    } else if flat <= 1e-9 {
        transmittance(world, canopy, p, toward)
    } else {
        let t = horizon_tan(world, p, [toward.x / flat, toward.y / flat]);
        if t < toward.z / flat {
            transmittance(world, canopy, p, toward)
        } else {
            0.0
        }
    };
    (sky, sun_vis)
}

/// The ground's bounce at (`x_m`, `y_m`), `above_m` metres over `F` (the quantity of
/// `LightGrid::bounce_at`): over [`REF_AZIMUTHS`] x [`REF_BANDS`] directions of a horizontal
/// receiver's sky (equal weight), each ray is marched on `F` (steps of 1 % of the distance, at
/// least 0.25 m, out to 4 km) to the first point below the surface; there `F`'s normal (central
/// differences over 0.25 m) gives `max(0, n . s)`. Like the grid, it takes the terrain as lit
/// wherever it faces the sun.
pub fn bounce(world: &World, x_m: f64, y_m: f64, above_m: f64, sun: Sun) -> f64 {
    if sun.elevation_deg <= 0.0 {
        return 0.0;
    }
    let toward = sun.toward();
    let p = DVec3::new(x_m, y_m, world.height_m(x_m, y_m) + above_m);
    let mut sum = 0.0;
    for a in 0..REF_AZIMUTHS {
        let phi = std::f64::consts::TAU * (a as f64 + 0.5) / REF_AZIMUTHS as f64;
        for b in 0..REF_BANDS {
            let s = (b as f64 + 0.5) / REF_BANDS as f64;
            let c = (1.0 - s).sqrt();
            let w = DVec3::new(phi.sin() * c, phi.cos() * c, s.sqrt());
            let mut t = 0.25f64;
            while t * c <= 4000.0 {
                let q = p + w * t;
                if q.z < world.height_m(q.x, q.y) {
                    let e = 0.25;
                    let gx =
                        (world.height_m(q.x + e, q.y) - world.height_m(q.x - e, q.y)) / (2.0 * e);
                    let gy =
                        (world.height_m(q.x, q.y + e) - world.height_m(q.x, q.y - e)) / (2.0 * e);
                    sum += DVec3::new(-gx, -gy, 1.0).normalize().dot(toward).max(0.0);
                    break;
                }
                t += (0.01 * t).max(0.25);
            }
        }
    }
    sum / (REF_AZIMUTHS * REF_BANDS) as f64
}
