//! Procedural map generation: a pure function of (seed, size, spacing). See the crate docs for
//! how determinism across thread counts is kept.

use crate::Grid;
use crate::classify::{self, GroundRules};
use crate::erosion;
use crate::map::{
    DensityLayer, FORMAT_NAME, FORMAT_VERSION, FileSpec, GridSpec, GroundSpec, Manifest, Map,
    PoissonSpec,
};
use crate::noise;
use crate::par;
use crate::patches::{self, PatchInputs};
use crate::progress::{Progress, StepTime, timed};
use crate::roads::{self, RoadInputs};
use crate::sample::GridPlacement;
use crate::towns::{self, TownInputs};

/// What to generate.
#[derive(Debug, Clone)]
pub struct GenerateParams {
    pub name: String,
    pub seed: u64,
    /// World side in metres (square maps).
    pub size_m: f64,
    /// Height sample spacing in metres.
    pub spacing_m: f64,
    /// Worker threads for row-parallel steps (0 = all cores); does not change the output.
    pub threads: usize,
}

impl Default for GenerateParams {
    fn default() -> Self {
        Self {
            name: "default".into(),
            seed: 1,
            size_m: 8192.0,
            spacing_m: 4.0,
            threads: 0,
        }
    }
}

/// Why generation parameters were refused.
#[derive(Debug, thiserror::Error)]
pub enum GenerateError {
    #[error(
        "--size {size_m} m must be a positive multiple of twice the spacing ({spacing_m} m) and at most {max_m} m"
    )]
    BadSize {
        size_m: f64,
        spacing_m: f64,
        max_m: f64,
    },
    #[error("--spacing {spacing_m} m must be between 0.5 m and 1000 m")]
    BadSpacing { spacing_m: f64 },
    #[error(
        "the map would have {samples} samples per side, more than the limit {max}; use a larger --spacing"
    )]
    TooManySamples { samples: u64, max: u32 },
    #[error("a house mesh cannot be built (a bug in worldgen): {0}")]
    Building(String),
    #[error("generated map is invalid (a bug in worldgen): {0}")]
    Invalid(#[from] crate::MapError),
}

/// The water surface of generated maps, metres.
pub const WATER_LEVEL_M: f64 = 40.0;

/// Base height (m) of generated terrain at a world position: continents of fBm, ridged
/// mountains under a low-frequency mask, and hills.
pub fn base_height_m(seed: u64, x_m: f64, y_m: f64) -> f64 {
    let continent = noise::fbm(seed, x_m / 3000.0, y_m / 3000.0, 5, 0.5);
    let m = noise::fbm(seed.wrapping_add(1), x_m / 5000.0, y_m / 5000.0, 3, 0.5);
    let t = ((m + 0.1) / 0.6).clamp(0.0, 1.0);
    let mountain_mask = t * t * (3.0 - 2.0 * t);
    let r = noise::ridged(seed.wrapping_add(2), x_m / 1800.0, y_m / 1800.0, 6);
    let hills = noise::fbm(seed.wrapping_add(3), x_m / 700.0, y_m / 700.0, 6, 0.5);
    75.0 + 120.0 * continent + 520.0 * mountain_mask * r * r.sqrt() + 25.0 * hills
}

/// Generates a whole map in memory. `times` receives the wall time of every step.
pub fn generate(
    p: &GenerateParams,
    progress: &dyn Progress,
    times: &mut Vec<StepTime>,
) -> Result<Map, GenerateError> {
    if !(p.spacing_m.is_finite() && (0.5..=1000.0).contains(&p.spacing_m)) {
        return Err(GenerateError::BadSpacing {
            spacing_m: p.spacing_m,
        });
    }
    let max_m = crate::map::limits::MAX_WORLD_SIZE_M;
    let cells = p.size_m / (2.0 * p.spacing_m);
    if !(p.size_m.is_finite()
        && p.size_m > 0.0
        && p.size_m <= max_m
        && (cells - cells.round()).abs() < 1e-9
        && cells >= 1.0)
    {
        return Err(GenerateError::BadSize {
            size_m: p.size_m,
            spacing_m: p.spacing_m,
            max_m,
        });
    }
    let n = (p.size_m / p.spacing_m).round() as u64 + 1;
    if n > u64::from(crate::map::limits::MAX_GRID_SIDE) {
        return Err(GenerateError::TooManySamples {
            samples: n,
            max: crate::map::limits::MAX_GRID_SIDE,
        });
    }
    let n = n as usize;
    let threads = par::thread_count(p.threads);
    let seed = p.seed;
    let spacing = p.spacing_m;
    let origin_m = [0.0, 0.0];
    let placement = GridPlacement {
        origin_m,
        spacing_m: spacing,
    };

    let mut heights = timed(times, "base heights (fBm + ridged)", || {
        let mut g = Grid::new(n, n, 0.0f32);
        progress.begin("base heights", n as u64);
        par::for_each_row(
            g.data_mut(),
            n,
            threads,
            |y, row| {
                for (x, v) in row.iter_mut().enumerate() {
                    *v = base_height_m(seed, x as f64 * spacing, y as f64 * spacing) as f32;
                }
            },
            &|rows| progress.advance(rows),
        );
        progress.end();
        g
    });
    let flow = timed(times, "hydraulic erosion", || {
        let params = erosion::Hydraulic::for_cells(n * n);
        erosion::hydraulic(&mut heights, seed, &params, threads, progress)
    });
    timed(times, "thermal erosion", || {
        erosion::thermal(&mut heights, spacing, 0.9, 8, threads, progress);
    });
    let (slope, moisture) = timed(times, "slope and moisture", || {
        let s = classify::slope(&heights, spacing, threads);
        let m = classify::moisture(seed, &heights, Some(&flow), spacing, WATER_LEVEL_M, threads);
        (s, m)
    });
    let (_, hmax) = heights.min_max();
    let rules = GroundRules {
        water_level_m: WATER_LEVEL_M,
        snow_line_m: WATER_LEVEL_M + 0.72 * (f64::from(hmax) - WATER_LEVEL_M),
    };
    let ground = timed(times, "ground types", || {
        classify::ground_types(&heights, &slope, &moisture, rules)
    });
    let network = timed(times, "towns and roads (least-cost paths)", || {
        roads::plan(&RoadInputs {
            seed,
            heights: &heights,
            placement,
            size_m: [p.size_m; 2],
            water_level_m: WATER_LEVEL_M,
        })
    });
    let towns = timed(times, "towns (houses along the roads)", || {
        towns::place(&TownInputs {
            seed,
            heights: &heights,
            placement,
            origin_m,
            size_m: [p.size_m; 2],
            water_level_m: WATER_LEVEL_M,
            towns_m: &network.towns_m,
            decals: &network.decals,
        })
    });
    let building_models = timed(times, "house meshes (progressive)", || {
        towns::house_models(&towns.buildings, threads)
    })
    .map_err(GenerateError::Building)?;
    let building_textures = timed(times, "house textures (mip chains)", || {
        towns::house_textures(seed, &towns.buildings)
    });
    let mut decals = network.decals;
    decals.extend(towns.pads);
    let patches = timed(times, "ground patches (fields, dirt, rock)", || {
        let (w, h) = (heights.width(), heights.height());
        let near_road = roads::decal_mask(&decals, placement, w, h, 6.0);
        patches::place(&PatchInputs {
            seed,
            heights: &heights,
            ground: &ground,
            slope: &slope,
            placement,
            size_m: [p.size_m; 2],
            near_road: &near_road,
        })
    });
    decals.extend(patches);
    assemble(AssembleInputs {
        name: p.name.clone(),
        seed,
        size_m: [p.size_m; 2],
        origin_m,
        water_level_m: WATER_LEVEL_M,
        snow_line_m: rules.snow_line_m,
        heights,
        spacing_m: spacing,
        ground,
        slope,
        moisture,
        decals,
        buildings: towns.buildings,
        building_models,
        building_textures,
        times,
    })
}

/// Everything [`assemble`] needs to derive densities and trees and build the manifest.
pub struct AssembleInputs<'a> {
    pub name: String,
    pub seed: u64,
    pub size_m: [f64; 2],
    pub origin_m: [f64; 2],
    pub water_level_m: f64,
    pub snow_line_m: f64,
    pub heights: Grid<f32>,
    pub spacing_m: f64,
    pub ground: Grid<u8>,
    pub slope: Grid<f32>,
    pub moisture: Grid<f32>,
    pub decals: Vec<crate::map::Decal>,
    /// Houses (their pads are among the decals); large trees keep clear of them.
    pub buildings: Vec<crate::map::Building>,
    /// One mesh per house type of `buildings`.
    pub building_models: Vec<crate::map::building_models::BuildingModel>,
    /// The textures `buildings` name.
    pub building_textures: Vec<crate::map::building_models::BuildingTexture>,
    pub times: &'a mut Vec<StepTime>,
}

/// Derives vegetation densities (at twice the height spacing where the grid allows) and large
/// trees, and builds a validated [`Map`]. Used by generation and DEM import.
pub fn assemble(a: AssembleInputs<'_>) -> Result<Map, GenerateError> {
    let (w, h) = (a.heights.width(), a.heights.height());
    let stride = if (w - 1) % 2 == 0 && (h - 1) % 2 == 0 && w > 2 && h > 2 {
        2
    } else {
        1
    };
    let dw = (w - 1) / stride + 1;
    let dh = (h - 1) / stride + 1;
    let dspacing = a.spacing_m * stride as f64;
    let dplacement = GridPlacement {
        origin_m: a.origin_m,
        spacing_m: dspacing,
    };
    let blocked = roads::decal_mask(&a.decals, dplacement, dw, dh, 1.0);
    let species = crate::classify::default_species(dw as u32, dh as u32, dspacing);
    let density_grids = timed(a.times, "vegetation densities", || {
        classify::densities(
            a.seed,
            &a.ground,
            &a.slope,
            &a.moisture,
            stride,
            a.spacing_m,
            &blocked,
        )
    });
    let placement = GridPlacement {
        origin_m: a.origin_m,
        spacing_m: a.spacing_m,
    };
    let trees = timed(a.times, "large trees", || {
        let tree_block = roads::decal_mask(&a.decals, dplacement, dw, dh, 4.0);
        let mut trees = classify::large_trees(
            a.seed,
            a.origin_m,
            a.size_m,
            &density_grids[1],
            dspacing,
            &tree_block,
            a.snow_line_m,
            &|x, y| crate::sample::bilinear(&a.heights, placement, x, y),
        );
        towns::clear_trees(&mut trees, &a.buildings);
        trees
    });
    let poisson = timed(a.times, "Poisson-disc tile", || {
        crate::poisson::PoissonTile::generate(
            a.seed ^ 0x5EED_D15C,
            crate::poisson::DEFAULT_MIN_DISTANCE,
        )
    });
    let manifest = Manifest {
        format: FORMAT_NAME.into(),
        version: FORMAT_VERSION,
        name: a.name,
        seed: format!("{:016x}", a.seed),
        size_m: a.size_m,
        origin_m: a.origin_m,
        water_level_m: a.water_level_m,
        heights: GridSpec {
            file: "heights.exr".into(),
            width: w as u32,
            height: h as u32,
            spacing_m: a.spacing_m,
        },
        ground: GroundSpec {
            file: "ground.png".into(),
            width: w as u32,
            height: h as u32,
            spacing_m: a.spacing_m,
            legend: classify::default_legend(),
        },
        tree_species: classify::default_tree_species(),
        vegetation: species.clone(),
        trees: FileSpec {
            file: "trees.csv".into(),
        },
        decals: FileSpec {
            file: "decals.toml".into(),
        },
        buildings: FileSpec {
            file: "buildings.csv".into(),
        },
        poisson: PoissonSpec {
            file: "poisson.csv".into(),
            min_distance: crate::poisson::DEFAULT_MIN_DISTANCE,
        },
    };
    crate::map::validate_manifest(std::path::Path::new("<generated>/map.toml"), &manifest)?;
    let densities = species
        .into_iter()
        .zip(density_grids)
        .map(|(spec, density)| DensityLayer {
            spec,
            density: density.into(),
        })
        .collect();
    let materials = vec![None; manifest.ground.legend.len()];
    Ok(Map {
        manifest,
        heights: a.heights.into(),
        ground: a.ground.into(),
        densities,
        trees,
        decals: a.decals,
        buildings: a.buildings,
        building_models: a.building_models,
        building_textures: a.building_textures,
        poisson,
        materials,
    })
}
