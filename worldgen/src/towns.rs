//! Towns: houses along the roads and paths near each town site, each on a flattened
//! pad.
//!
//! A map has a few house **types** ([`house_types`]: dimensions, storeys, roof and seed from the
//! map seed); every house is an instance of one, so a type's mesh is built once. Walking every
//! road and path within [`town_radius_m`] of a town site in steps of [`LOT_STEP_M`], each step
//! offers a lot on either side, taken with a probability that falls from the centre outwards:
//! the footprint's longer side runs along the road, its near edge [`ROAD_SETBACK_M`] beyond the
//! road's edge. A lot is built only if its footprint
//! - stays [`ROAD_SETBACK_M`] clear of the edge of every road and path (exact polygon-segment
//!   distances),
//! - stays [`BUILDING_GAP_M`] clear of every house already placed,
//! - stands on dry ground (every height sample over its pad at least [`DRY_MARGIN_M`] above the
//!   water level) with at most [`MAX_RELIEF_M`] between its highest and lowest sample, and
//! - lies inside the world with its pad.
//!
//! Each house gets a **pad** decal ([`crate::map::DecalKind::Pad`]): its footprint grown by
//! [`PAD_MARGIN_M`] at the mean ground height, which flattens the ground there, clears
//! vegetation and procedural detail, and shows as trodden earth. Large trees whose crowns reach
//! a footprint are removed by [`clear_trees`].

use crate::Grid;
use crate::building_mesh::{BuildingSpec, Roof, building_mesh};
use crate::house_textures;
use crate::map::building_models::{self, BuildingModel, BuildingTexture};
use crate::map::{Building, Decal, DecalKind, Tree};
use crate::noise;
use crate::pm::{CostKind, PmMesh, TriMesh};
use crate::roads::segment_closest;
use crate::sample::{self, GridPlacement};

/// Distance between lot candidates along a road, metres.
pub const LOT_STEP_M: f64 = 3.0;
/// Clearance between a footprint and the edge of any road or path, metres.
pub const ROAD_SETBACK_M: f64 = 4.0;
/// Clearance between two footprints, metres (two pads and the interpolation stencil between).
pub const BUILDING_GAP_M: f64 = 5.0;
/// A pad reaches this far beyond its footprint, metres: the ground under the footprint is flat
/// (the decal interpolation stencil of a footprint point stays inside the pad).
pub const PAD_MARGIN_M: f64 = 1.5;
/// Width over which a pad's flattening fades out beyond its margin, metres.
pub const PAD_FALLOFF_M: f32 = 3.0;
/// Highest minus lowest ground sample over a pad, at most, metres.
pub const MAX_RELIEF_M: f64 = 2.5;
/// Every ground sample under a pad is at least this far above the water level, metres.
pub const DRY_MARGIN_M: f64 = 1.0;
/// House types per map.
pub const TYPE_COUNT: usize = 6;
/// Facade textures per map (`facade_<k>.png`).
pub const FACADES: u64 = 4;
/// Roof textures per map (`roof_<k>.png`).
pub const ROOFS: u64 = 2;

/// Ground samples per side of the lattice over a pad.
const PAD_SAMPLES: usize = 9;

const SALT: u64 = 0x7095_B111_D1A6_0000;

/// What town placement reads.
pub struct TownInputs<'a> {
    pub seed: u64,
    pub heights: &'a Grid<f32>,
    pub placement: GridPlacement,
    pub origin_m: [f64; 2],
    pub size_m: [f64; 2],
    pub water_level_m: f64,
    pub towns_m: &'a [[f64; 2]],
    /// The road and path decals (other kinds are ignored).
    pub decals: &'a [Decal],
}

/// The houses of every town and their pads.
#[derive(Debug, Clone, Default)]
pub struct Towns {
    pub buildings: Vec<Building>,
    pub pads: Vec<Decal>,
}

/// Houses are placed within this distance of a town site: an eighth of the map's smaller side,
/// between 60 and 180 m.
pub fn town_radius_m(size_m: [f64; 2]) -> f64 {
    (size_m[0].min(size_m[1]) * 0.125).clamp(60.0, 180.0)
}

/// Rounds to centimetres (tidy files; every check runs on the rounded values).
fn cm(x: f64) -> f64 {
    (x * 100.0).round() / 100.0
}

/// The map's house types: names `house_0` .. and their specs, from the seed.
pub fn house_types(seed: u64) -> Vec<(String, BuildingSpec)> {
    (0..TYPE_COUNT)
        .map(|k| {
            let u = |j: i64| noise::unit3(seed ^ SALT, k as i64, j);
            let width_m = cm(7.0 + 6.0 * u(0));
            let depth_m = cm((5.0 + 3.5 * u(1)).min(width_m));
            let storeys = 1 + u32::from(u(2) < 0.45) + u32::from(u(2) < 0.1);
            let spec = BuildingSpec {
                width_m,
                depth_m,
                storeys,
                storey_m: cm(2.8 + 0.4 * u(3)),
                roof: if k % 2 == 0 { Roof::Gable } else { Roof::Hip },
                roof_pitch_deg: cm(25.0 + 20.0 * u(4)),
                seed: noise::hash3(seed ^ SALT, k as i64, 5),
            };
            (format!("house_{k}"), spec)
        })
        .collect()
}

/// Distance between two 2-D segments (0 when they cross).
fn segment_distance(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> f64 {
    let cross = |o: [f64; 2], p: [f64; 2], q: [f64; 2]| {
        (p[0] - o[0]) * (q[1] - o[1]) - (p[1] - o[1]) * (q[0] - o[0])
    };
    let (d1, d2) = (cross(a, b, c), cross(a, b, d));
    let (d3, d4) = (cross(c, d, a), cross(c, d, b));
    if d1 * d2 < 0.0 && d3 * d4 < 0.0 {
        return 0.0;
    }
    segment_closest(a, c, d)
        .0
        .min(segment_closest(b, c, d).0)
        .min(segment_closest(c, a, b).0)
        .min(segment_closest(d, a, b).0)
}

/// Whether `p` is inside the convex polygon `poly` (counter-clockwise).
fn inside_convex(p: [f64; 2], poly: &[[f64; 2]]) -> bool {
    let n = poly.len();
    (0..n).all(|i| {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]) >= 0.0
    })
}

/// Distance from a convex polygon (counter-clockwise) to a segment; 0 when they touch.
pub fn polygon_segment_distance(poly: &[[f64; 2]], a: [f64; 2], b: [f64; 2]) -> f64 {
    if inside_convex(a, poly) || inside_convex(b, poly) {
        return 0.0;
    }
    let n = poly.len();
    (0..n)
        .map(|i| segment_distance(poly[i], poly[(i + 1) % n], a, b))
        .fold(f64::INFINITY, f64::min)
}

/// Distance between two convex polygons (counter-clockwise); 0 when they touch.
pub fn polygon_distance(p: &[[f64; 2]], q: &[[f64; 2]]) -> f64 {
    let n = q.len();
    (0..n)
        .map(|i| polygon_segment_distance(p, q[i], q[(i + 1) % n]))
        .fold(f64::INFINITY, f64::min)
}

/// A road or path segment with its half width.
struct RoadSegment {
    a: [f64; 2],
    b: [f64; 2],
    half_width_m: f64,
}

/// Places the houses of every town (module docs).
pub fn place(inp: &TownInputs<'_>) -> Towns {
    let types = house_types(inp.seed);
    let radius_m = town_radius_m(inp.size_m);
    let roads: Vec<(usize, &Decal)> = inp
        .decals
        .iter()
        .enumerate()
        .filter(|(_, d)| matches!(d.kind, DecalKind::Road | DecalKind::Path))
        .collect();
    let mut towns = Towns::default();
    for (t, town) in inp.towns_m.iter().enumerate() {
        // Road segments that can come near this town's lots.
        let reach = radius_m + 40.0;
        let near: Vec<RoadSegment> = roads
            .iter()
            .flat_map(|(_, d)| {
                d.points.windows(2).filter_map(|w| {
                    let (a, b) = ([w[0][0], w[0][1]], [w[1][0], w[1][1]]);
                    (segment_closest(*town, a, b).0 <= reach).then_some(RoadSegment {
                        a,
                        b,
                        half_width_m: f64::from(d.width_m) * 0.5,
                    })
                })
            })
            .collect();
        for &(di, d) in &roads {
            let mut k = 0i64;
            for w in d.points.windows(2) {
                let (a, b) = ([w[0][0], w[0][1]], [w[1][0], w[1][1]]);
                let len = (b[0] - a[0]).hypot(b[1] - a[1]);
                if len < 1e-6 {
                    continue;
                }
                let u = [(b[0] - a[0]) / len, (b[1] - a[1]) / len];
                let yaw_deg = (u[1].atan2(u[0]).to_degrees() * 1000.0).round() / 1000.0;
                let mut s = 0.0;
                while s < len {
                    let p = [a[0] + u[0] * s, a[1] + u[1] * s];
                    s += LOT_STEP_M;
                    k += 1;
                    let dist = (p[0] - town[0]).hypot(p[1] - town[1]);
                    if dist > radius_m {
                        continue;
                    }
                    for (side_index, side) in [1.0f64, -1.0].into_iter().enumerate() {
                        let h = noise::hash3(
                            inp.seed ^ SALT,
                            (t * 4096 + di) as i64,
                            k * 2 + side_index as i64,
                        );
                        let r = dist / radius_m;
                        if noise::unit(h) >= 0.9 * (1.0 - r * r) {
                            continue;
                        }
                        let type_index = (h >> 40) as usize % types.len();
                        let (name, spec) = &types[type_index];
                        let offset =
                            f64::from(d.width_m) * 0.5 + ROAD_SETBACK_M + spec.depth_m * 0.5;
                        // Normal to the left of the road direction.
                        let n = [-u[1] * side, u[0] * side];
                        let mut b = Building {
                            type_name: name.clone(),
                            x_m: cm(p[0] + n[0] * offset),
                            y_m: cm(p[1] + n[1] * offset),
                            z_m: 0.0,
                            yaw_deg,
                            spec: *spec,
                            // Facades vary per house, roofs per type.
                            facade_texture: format!("facade_{}.png", (h >> 20) % FACADES),
                            roof_texture: format!("roof_{}.png", type_index as u64 % ROOFS),
                        };
                        if let Some(z) = lot_fits(inp, &b, &near, &towns.buildings) {
                            b.z_m = cm(z);
                            towns.pads.push(pad(&b));
                            towns.buildings.push(b);
                        }
                    }
                }
            }
        }
    }
    towns
}

/// The pad decal of a house.
pub fn pad(b: &Building) -> Decal {
    Decal {
        kind: DecalKind::Pad,
        closed: true,
        width_m: 0.5,
        falloff_m: PAD_FALLOFF_M,
        height_offset_m: 0.0,
        points: b
            .grown_footprint_m(PAD_MARGIN_M)
            .iter()
            .map(|c| [c[0], c[1], b.z_m])
            .collect(),
    }
}

/// The pad height when the lot is buildable (module docs), else `None`.
fn lot_fits(
    inp: &TownInputs<'_>,
    b: &Building,
    roads: &[RoadSegment],
    placed: &[Building],
) -> Option<f64> {
    let foot = b.footprint_m();
    let padded = b.grown_footprint_m(PAD_MARGIN_M + f64::from(PAD_FALLOFF_M));
    let (o, s) = (inp.origin_m, inp.size_m);
    let in_world =
        |c: &[f64; 2]| c[0] >= o[0] && c[1] >= o[1] && c[0] <= o[0] + s[0] && c[1] <= o[1] + s[1];
    if !padded.iter().all(in_world) {
        return None;
    }
    if roads
        .iter()
        .any(|r| polygon_segment_distance(&foot, r.a, r.b) < r.half_width_m + ROAD_SETBACK_M - 0.01)
    {
        return None;
    }
    if placed
        .iter()
        .any(|p| polygon_distance(&foot, &p.footprint_m()) < BUILDING_GAP_M)
    {
        return None;
    }
    // Ground samples over the pad on a lattice.
    let pad = b.grown_footprint_m(PAD_MARGIN_M);
    let (mut lo, mut hi, mut sum) = (f64::INFINITY, f64::NEG_INFINITY, 0.0);
    let n = PAD_SAMPLES;
    for i in 0..n {
        for j in 0..n {
            let (fu, fv) = (i as f64 / (n - 1) as f64, j as f64 / (n - 1) as f64);
            let x = pad[0][0] + (pad[1][0] - pad[0][0]) * fu + (pad[3][0] - pad[0][0]) * fv;
            let y = pad[0][1] + (pad[1][1] - pad[0][1]) * fu + (pad[3][1] - pad[0][1]) * fv;
            let z = sample::bicubic(inp.heights, inp.placement, x, y);
            lo = lo.min(z);
            hi = hi.max(z);
            sum += z;
        }
    }
    (lo >= inp.water_level_m + DRY_MARGIN_M && hi - lo <= MAX_RELIEF_M)
        .then_some(sum / (n * n) as f64)
}

/// Sample spacing of the house meshes' stored errors, a fraction of the diagonal (that of the
/// engine's other progressive meshes).
pub const HOUSE_BOUND_FRACTION: f64 = 0.005;

/// The progressive mesh of a house type (quadric cost, stored errors bounding the two-sided
/// Hausdorff distance).
pub fn house_model(spec: &BuildingSpec) -> Result<PmMesh, String> {
    let mesh = building_mesh(spec)?;
    let (mesh, _) = TriMesh::weld(&mesh.triangles);
    Ok(PmMesh::build(
        &mesh,
        CostKind::Quadric,
        HOUSE_BOUND_FRACTION,
        &mut |_, _, _| {},
    )
    .0)
}

/// The meshes of every house type in `buildings` (in order of first appearance), built on up
/// to `threads` threads.
pub fn house_models(buildings: &[Building], threads: usize) -> Result<Vec<BuildingModel>, String> {
    let types = building_models::types(buildings);
    let mut out: Vec<Option<Result<PmMesh, String>>> = vec![None; types.len()];
    let chunk = types.len().div_ceil(threads.max(1)).max(1);
    std::thread::scope(|scope| {
        for (ts, slots) in types.chunks(chunk).zip(out.chunks_mut(chunk)) {
            scope.spawn(move || {
                for (b, slot) in ts.iter().zip(slots) {
                    *slot = Some(house_model(&b.spec));
                }
            });
        }
    });
    types
        .iter()
        .zip(out)
        .map(|(b, pm)| {
            let pm = pm
                .unwrap_or_else(|| Err("not built".into()))
                .map_err(|e| format!("house type {}: {e}", b.type_name))?;
            Ok(BuildingModel {
                type_name: b.type_name.clone(),
                pm,
            })
        })
        .collect()
}

/// The textures `buildings` name (the map's generated facades and roofs), made from the seed.
pub fn house_textures(seed: u64, buildings: &[Building]) -> Vec<BuildingTexture> {
    building_models::texture_names(buildings)
        .into_iter()
        .map(|name| {
            let index = |prefix: &str| {
                name.strip_prefix(prefix)
                    .and_then(|r| r.strip_suffix(".png"))
                    .and_then(|k| k.parse::<i64>().ok())
            };
            let chain = match (index("facade_"), index("roof_")) {
                (Some(k), _) => house_textures::facade(noise::hash3(seed ^ SALT, k, 20)),
                (_, Some(k)) => house_textures::roof(noise::hash3(seed ^ SALT, k, 21)),
                _ => house_textures::facade(seed),
            };
            BuildingTexture {
                name: name.to_string(),
                chain,
            }
        })
        .collect()
}

/// Removes the large trees whose crowns come within a metre of a footprint.
pub fn clear_trees(trees: &mut Vec<Tree>, buildings: &[Building]) {
    trees.retain(|t| {
        buildings.iter().all(|b| {
            let reach = f64::from(t.crown_radius_m) + 1.0;
            let foot = b.footprint_m();
            // Cheap reject first: farther than the footprint's circumradius plus the reach.
            let r = b.spec.width_m.hypot(b.spec.depth_m) * 0.5;
            if (t.x_m - b.x_m).hypot(t.y_m - b.y_m) > r + reach {
                return true;
            }
            let p = [t.x_m, t.y_m];
            polygon_segment_distance(&foot, p, p) >= reach
        })
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn polygon_distances() {
        let sq = [[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]];
        assert_eq!(polygon_segment_distance(&sq, [1.0, 1.0], [1.0, 1.0]), 0.0);
        assert!((polygon_segment_distance(&sq, [3.0, -5.0], [3.0, 5.0]) - 1.0).abs() < 1e-12);
        // Crossing without an endpoint inside.
        assert_eq!(polygon_segment_distance(&sq, [-1.0, 1.0], [3.0, 1.0]), 0.0);
        let far = [[5.0, 5.0], [6.0, 5.0], [6.0, 6.0], [5.0, 6.0]];
        assert!((polygon_distance(&sq, &far) - 18f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn house_types_are_buildable_and_wider_than_deep() {
        for (name, spec) in house_types(7) {
            spec.check().unwrap_or_else(|e| panic!("{name}: {e}"));
            assert!(spec.width_m >= spec.depth_m, "{name}");
        }
    }
}
