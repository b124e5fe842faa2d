//! Ground types, vegetation densities and large trees derived from heights, slope and moisture.
//! Shared by procedural generation and DEM import so both produce the same kind of map.

use crate::Grid;
use crate::map::{GroundType, SpeciesSpec, Tree};
use crate::noise;
use crate::par;

pub const WATER: u8 = 0;
pub const SAND: u8 = 1;
pub const GRASS: u8 = 2;
pub const FOREST_FLOOR: u8 = 3;
pub const DIRT: u8 = 4;
pub const ROCK: u8 = 5;
pub const SNOW: u8 = 6;

/// The ground-type legend written by worldgen (index = constant above).
pub fn default_legend() -> Vec<GroundType> {
    let t = |name: &str, color: [u8; 3], detail_amplitude_m: f32| GroundType {
        name: name.into(),
        color,
        detail_amplitude_m,
        material: None,
    };
    vec![
        t("water", [52, 92, 140], 0.0),
        t("sand", [212, 196, 148], 0.05),
        t("grass", [96, 138, 62], 0.15),
        t("forest_floor", [58, 84, 44], 0.25),
        t("dirt", [128, 102, 74], 0.3),
        t("rock", [122, 118, 112], 0.8),
        t("snow", [236, 240, 244], 0.1),
    ]
}

/// Large-tree species names written by worldgen (index used in trees.csv).
pub fn default_tree_species() -> Vec<String> {
    ["pine", "spruce", "birch", "oak"]
        .iter()
        .map(|s| (*s).to_string())
        .collect()
}

/// Vegetation species layers written by worldgen, with the given density sample spacing.
pub fn default_species(width: u32, height: u32, spacing_m: f64) -> Vec<SpeciesSpec> {
    let s = |species: &str, max: f64, min_dist: f64| SpeciesSpec {
        species: species.into(),
        file: format!("density_{species}.png"),
        width,
        height,
        spacing_m,
        max_density_per_m2: max,
        min_distance_m: min_dist,
    };
    vec![
        s("bush", 0.08, 2.5),
        s("small_tree", 0.03, 4.0),
        s("grass_clump", 0.8, 0.8),
    ]
}

/// Slope magnitude (rise over run, dimensionless) per sample, by central differences.
pub fn slope(heights: &Grid<f32>, spacing_m: f64, threads: usize) -> Grid<f32> {
    let (w, h) = (heights.width(), heights.height());
    let mut out = Grid::new(w, h, 0.0f32);
    par::for_each_row(
        out.data_mut(),
        w,
        threads,
        |y, row| {
            for (x, v) in row.iter_mut().enumerate() {
                let (xi, yi) = (x as i64, y as i64);
                let dx = f64::from(heights.get_clamped(xi + 1, yi))
                    - f64::from(heights.get_clamped(xi - 1, yi));
                let dy = f64::from(heights.get_clamped(xi, yi + 1))
                    - f64::from(heights.get_clamped(xi, yi - 1));
                let nx = if x == 0 || x + 1 == w { 1.0 } else { 2.0 };
                let ny = if y == 0 || y + 1 == h { 1.0 } else { 2.0 };
                *v = ((dx / (nx * spacing_m)).powi(2) + (dy / (ny * spacing_m)).powi(2)).sqrt()
                    as f32;
            }
        },
        &|_| {},
    );
    out
}

/// Moisture in [0, 1]: low ground, flow paths (`flow`, from erosion, may be empty) and noise.
pub fn moisture(
    seed: u64,
    heights: &Grid<f32>,
    flow: Option<&Grid<f32>>,
    spacing_m: f64,
    water_level_m: f64,
    threads: usize,
) -> Grid<f32> {
    let (w, h) = (heights.width(), heights.height());
    let (lo, hi) = heights.min_max();
    let range = f64::from(hi - lo).max(1.0);
    let mut out = Grid::new(w, h, 0.0f32);
    par::for_each_row(
        out.data_mut(),
        w,
        threads,
        |y, row| {
            for (x, v) in row.iter_mut().enumerate() {
                let hm = f64::from(heights.get(x, y));
                let low = 1.0 - ((hm - water_level_m.max(f64::from(lo))) / range).clamp(0.0, 1.0);
                let n = noise::fbm(
                    seed ^ 0x4D6F_6973,
                    x as f64 * spacing_m / 900.0,
                    y as f64 * spacing_m / 900.0,
                    4,
                    0.5,
                );
                let f = flow.map_or(0.0, |f| (f64::from(f.get(x, y)).ln_1p() / 4.0).min(1.0));
                *v = (0.1 + 0.3 * low + 0.45 * n + 0.3 * f).clamp(0.0, 1.0) as f32;
            }
        },
        &|_| {},
    );
    out
}

/// Thresholds for [`ground_types`].
#[derive(Debug, Clone, Copy)]
pub struct GroundRules {
    pub water_level_m: f64,
    /// Snow from this height up (on slopes that hold snow).
    pub snow_line_m: f64,
}

/// Ground type per sample from height, slope and moisture.
pub fn ground_types(
    heights: &Grid<f32>,
    slope: &Grid<f32>,
    moisture: &Grid<f32>,
    rules: GroundRules,
) -> Grid<u8> {
    let mut out = Grid::new(heights.width(), heights.height(), GRASS);
    for (i, g) in out.data_mut().iter_mut().enumerate() {
        let h = f64::from(heights.data()[i]);
        let s = slope.data()[i];
        let m = moisture.data()[i];
        *g = if h <= rules.water_level_m {
            WATER
        } else if h <= rules.water_level_m + 1.5 && s < 0.15 {
            SAND
        } else if h >= rules.snow_line_m && s < 0.9 {
            SNOW
        } else if s > 1.0 {
            ROCK
        } else if s > 0.6 {
            DIRT
        } else if m > 0.55 {
            FOREST_FLOOR
        } else {
            GRASS
        };
    }
    out
}

/// Density in [0, 1] of each default species on a ground type at a slope and moisture.
fn species_density01(species: usize, ground: u8, slope: f32, moisture: f32) -> f32 {
    let flat = (1.0 - slope / 0.8).clamp(0.0, 1.0);
    let base = match (species, ground) {
        (0, GRASS) => 0.35,
        (0, FOREST_FLOOR) => 0.6,
        (0, DIRT) => 0.2,
        (1, FOREST_FLOOR) => 0.4 + 0.6 * moisture,
        (1, GRASS) => 0.05,
        (2, GRASS) => 1.0,
        (2, FOREST_FLOOR) => 0.3,
        (2, DIRT) => 0.3,
        (2, SAND) => 0.1,
        _ => 0.0,
    };
    base * flat
}

/// Density layers (0..255) for [`default_species`], sampled from ground/slope/moisture grids at
/// `stride` samples per density sample, modulated by noise, zero where `blocked` is true.
pub fn densities(
    seed: u64,
    ground: &Grid<u8>,
    slope: &Grid<f32>,
    moisture: &Grid<f32>,
    stride: usize,
    spacing_m: f64,
    blocked: &Grid<bool>,
) -> Vec<Grid<u8>> {
    let w = (ground.width() - 1) / stride + 1;
    let h = (ground.height() - 1) / stride + 1;
    (0..3)
        .map(|species| {
            let mut g = Grid::new(w, h, 0u8);
            for y in 0..h {
                for x in 0..w {
                    let (sx, sy) = (x * stride, y * stride);
                    if blocked.get(x, y) {
                        continue;
                    }
                    let d = species_density01(
                        species,
                        ground.get(sx, sy),
                        slope.get(sx, sy),
                        moisture.get(sx, sy),
                    );
                    let n = noise::fbm(
                        seed ^ (0xD3 + species as u64),
                        sx as f64 * spacing_m / 250.0,
                        sy as f64 * spacing_m / 250.0,
                        3,
                        0.5,
                    );
                    let v = (f64::from(d) * (0.7 + 0.5 * n)).clamp(0.0, 1.0);
                    g.set(x, y, (v * 255.0).round() as u8);
                }
            }
            g
        })
        .collect()
}

/// Large trees on a jittered grid where the small-tree density is high, never where `blocked`.
/// `height_at` gives the ground height (for the species choice by altitude).
pub fn large_trees(
    seed: u64,
    origin_m: [f64; 2],
    size_m: [f64; 2],
    small_tree_density: &Grid<u8>,
    density_spacing_m: f64,
    blocked: &Grid<bool>,
    snow_line_m: f64,
    height_at: &dyn Fn(f64, f64) -> f64,
) -> Vec<Tree> {
    const CELL_M: f64 = 20.0;
    let nx = (size_m[0] / CELL_M).floor() as i64;
    let ny = (size_m[1] / CELL_M).floor() as i64;
    let mut trees = Vec::new();
    for cy in 0..ny {
        for cx in 0..nx {
            let h = noise::hash3(seed ^ 0x7EE5, cx, cy);
            let x = (cx as f64 + 0.1 + 0.8 * noise::unit(h)) * CELL_M;
            let y = (cy as f64 + 0.1 + 0.8 * noise::unit(h.rotate_left(21))) * CELL_M;
            let (gx, gy) = (
                (x / density_spacing_m).round() as i64,
                (y / density_spacing_m).round() as i64,
            );
            let d = f64::from(small_tree_density.get_clamped(gx, gy)) / 255.0;
            if blocked.get_clamped(gx, gy) || noise::unit(h.rotate_left(42)) >= d * 0.6 {
                continue;
            }
            let (wx, wy) = (origin_m[0] + x, origin_m[1] + y);
            let alt = height_at(wx, wy) / snow_line_m.max(1.0);
            let r = noise::unit3(seed ^ 0x59EC, cx, cy);
            let species: u16 = if alt > 0.6 {
                u16::from(r >= 0.6)
            } else if r < 0.3 {
                1
            } else if r < 0.6 {
                2
            } else if r < 0.8 {
                3
            } else {
                0
            };
            let s = noise::unit3(seed ^ 0x517E, cx, cy);
            let height_m = (14.0 + 16.0 * s) as f32;
            let crown_radius_m = (height_m * if species == 3 { 0.22 } else { 0.15 }).max(2.0);
            trees.push(Tree {
                species,
                x_m: wx,
                y_m: wy,
                height_m,
                crown_radius_m,
            });
        }
    }
    trees
}
