//! Ground patches: closed-area decals worldgen places after the roads — rock outcrops on steep
//! slopes, bare-earth patches in meadows and forests, and cultivated fields on flat grassland.
//! They give the ground texture (and, for rock, the surface) features the 4 m ground-type grid
//! cannot draw.
//!
//! Placement is a jittered lattice per kind (one candidate per cell, kept with a probability
//! and when the ground under it fits): a pure function of the seed and the layers, and patches
//! of one kind never overlap because each stays inside its own cell. Kinds use different cell
//! sizes, so a dirt patch may lie on a field's edge; the texture draws areas in file order.

use crate::Grid;
use crate::classify::{FOREST_FLOOR, GRASS, SAND, SNOW, WATER};
use crate::map::{Decal, DecalKind};
use crate::noise::unit3;
use crate::sample::{self, GridPlacement};

/// What patch placement reads.
pub struct PatchInputs<'a> {
    pub seed: u64,
    pub heights: &'a Grid<f32>,
    pub ground: &'a Grid<u8>,
    /// Slope (rise over run) per height sample.
    pub slope: &'a Grid<f32>,
    pub placement: GridPlacement,
    pub size_m: [f64; 2],
    /// Samples within reach of a road or path (patches keep off them).
    pub near_road: &'a Grid<bool>,
}

/// One kind's placement rule.
struct Rule {
    kind: DecalKind,
    salt: u64,
    cell_m: f64,
    keep: f64,
    /// The ground a candidate needs at its centre and outline points.
    fits: fn(ground: u8, slope: f32) -> bool,
    width_m: f32,
    falloff_m: f32,
    height_offset_m: f32,
}

const RULES: [Rule; 3] = [
    Rule {
        kind: DecalKind::Field,
        salt: 0xf1e1d,
        cell_m: 160.0,
        keep: 0.45,
        fits: |g, s| g == GRASS && s < 0.12,
        width_m: 1.0,
        falloff_m: 1.0,
        height_offset_m: 0.0,
    },
    Rule {
        kind: DecalKind::Dirt,
        salt: 0xd127,
        cell_m: 64.0,
        keep: 0.2,
        fits: |g, s| (g == GRASS || g == FOREST_FLOOR) && s < 0.35,
        width_m: 0.5,
        falloff_m: 2.0,
        height_offset_m: 0.0,
    },
    Rule {
        kind: DecalKind::RockPatch,
        salt: 0x20c4,
        cell_m: 48.0,
        keep: 0.35,
        fits: |g, s| !matches!(g, WATER | SAND | SNOW) && (0.45..1.3).contains(&s),
        width_m: 0.5,
        falloff_m: 1.5,
        height_offset_m: 0.4,
    },
];

/// The outline of a candidate of `kind` centred at `c` (world m), from random numbers `r`.
fn outline(kind: DecalKind, c: [f64; 2], r: impl Fn(i64) -> f64) -> Vec<[f64; 2]> {
    if kind == DecalKind::Field {
        // A rectangle, 50-90 m by 35-60 m, at any angle.
        let (hw, hh) = (25.0 + 20.0 * r(10), 17.5 + 12.5 * r(11));
        let a = std::f64::consts::PI * r(12);
        let (u, v) = ([a.cos(), a.sin()], [-a.sin(), a.cos()]);
        [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
            .iter()
            .map(|&(s, t)| {
                [
                    c[0] + s * hw * u[0] + t * hh * v[0],
                    c[1] + s * hw * u[1] + t * hh * v[1],
                ]
            })
            .collect()
    } else {
        // A star-shaped blob: 10 points at a random radius each.
        let (lo, hi) = if kind == DecalKind::Dirt {
            (4.0, 10.0)
        } else {
            (3.0, 7.0)
        };
        let radius = lo + (hi - lo) * r(10);
        let n = 10;
        (0..n)
            .map(|k| {
                let a = std::f64::consts::TAU * f64::from(k) / f64::from(n);
                let rk = radius * (0.6 + 0.4 * r(20 + i64::from(k)));
                [c[0] + rk * a.cos(), c[1] + rk * a.sin()]
            })
            .collect()
    }
}

/// Places the patches, in rule order (fields, dirt, rock), cells row by row.
pub fn place(inp: &PatchInputs<'_>) -> Vec<Decal> {
    let mut out = Vec::new();
    let p = inp.placement;
    let (w, h) = (inp.heights.width(), inp.heights.height());
    let sample_at = |q: [f64; 2]| {
        let x = ((q[0] - p.origin_m[0]) / p.spacing_m).round();
        let y = ((q[1] - p.origin_m[1]) / p.spacing_m).round();
        (x >= 0.0 && y >= 0.0 && (x as usize) < w && (y as usize) < h)
            .then_some((x as usize, y as usize))
    };
    for rule in &RULES {
        let cells = [
            (inp.size_m[0] / rule.cell_m).floor() as i64,
            (inp.size_m[1] / rule.cell_m).floor() as i64,
        ];
        for cy in 0..cells[1] {
            for cx in 0..cells[0] {
                let cell = cy * cells[0] + cx;
                let r = |k: i64| unit3(inp.seed ^ rule.salt, cell, k);
                if r(0) >= rule.keep {
                    continue;
                }
                // Jitter within the middle fifth of the cell, so outlines stay in their cell.
                let c = [
                    p.origin_m[0] + (cx as f64 + 0.4 + 0.2 * r(1)) * rule.cell_m,
                    p.origin_m[1] + (cy as f64 + 0.4 + 0.2 * r(2)) * rule.cell_m,
                ];
                let pts = outline(rule.kind, c, r);
                let mut probes = pts.clone();
                probes.push(c);
                for k in 0..pts.len() {
                    let (a, b) = (pts[k], pts[(k + 1) % pts.len()]);
                    probes.push([0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])]);
                }
                let fits = probes.iter().all(|&q| {
                    sample_at(q).is_some_and(|(x, y)| {
                        !inp.near_road.get(x, y)
                            && (rule.fits)(inp.ground.get(x, y), inp.slope.get(x, y))
                    })
                });
                if !fits {
                    continue;
                }
                out.push(Decal {
                    kind: rule.kind,
                    closed: true,
                    width_m: rule.width_m,
                    falloff_m: rule.falloff_m,
                    height_offset_m: rule.height_offset_m,
                    points: pts
                        .iter()
                        .map(|q| [q[0], q[1], sample::bilinear(inp.heights, p, q[0], q[1])])
                        .collect(),
                });
            }
        }
    }
    out
}
