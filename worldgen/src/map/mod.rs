//! Map format v3: a folder with a `map.toml` manifest and layer files.
//!
//! ```text
//! map.toml          manifest: format = "tvs-map", version = 3, world size, origin, seed, layers
//! heights.exr       OpenEXR, one f32 channel "Y", metres above sea level
//! ground.png        8-bit indexed PNG; the palette index is a ground type from the legend
//! density_*.png     one 8-bit grayscale PNG per vegetation species; 0..255 = 0..max density
//! trees.csv         "tvs-trees 1" then species,x_m,y_m,height_m,crown_radius_m rows
//! decals.toml       format = "tvs-decals", version = 3, [[decal]] polylines and areas
//!                   (version 2 added fields and dirt, version 3 house pads; older ones are read)
//! buildings.csv     "tvs-buildings 2" then type,x_m,y_m,z_m,yaw_deg,width_m,depth_m,storeys,
//!                   storey_m,roof,roof_pitch_deg,seed,facade_texture,roof_texture rows (may be
//!                   empty; an empty version 1 is read)
//! buildings/*.pm    one progressive mesh per house type named in buildings.csv (`.pm` format)
//! buildings/*.png   the houses' facade and roof textures (mip atlases or square images)
//! poisson.csv       "tvs-poisson 1" then x,y rows: the ranked periodic Poisson-disc tile (v2)
//! ```
//!
//! Every raster layer covers the whole world: `(width - 1) * spacing_m == size_m` in both axes,
//! sample (i, j) at `origin_m + (i, j) * spacing_m`, files stored north-up. [`Map::load`] checks
//! every field and every sample before it returns; nothing is allocated from a size that has not
//! been checked against [`limits`].

mod baked;
pub mod building_models;
pub mod layers;
pub mod lists;
pub mod manifest;
pub mod material_image;
pub mod raster;

pub use lists::{Building, Decal, DecalKind, Tree};
pub use manifest::validate as validate_manifest;
pub use manifest::{
    FORMAT_NAME, FORMAT_VERSION, FileSpec, GridSpec, GroundSpec, GroundType, Manifest, PoissonSpec,
    SpeciesSpec,
};
pub use material_image::MaterialImage;
pub use raster::{GroundTypes, Heights, MapRaster};

use crate::Grid;
use crate::sample::{self, GridPlacement};
use std::path::{Path, PathBuf};

/// Documented limits, checked before any allocation.
pub mod limits {
    /// Largest raster side in samples (16385 = 16384 cells + 1).
    pub const MAX_GRID_SIDE: u32 = 16_385;
    /// Largest world side in metres (1000 km).
    pub const MAX_WORLD_SIZE_M: f64 = 1.0e6;
    /// Largest distance of the map origin from (0, 0), metres.
    pub const MAX_ORIGIN_M: f64 = 1.0e8;
    /// Smallest sample spacing, metres.
    pub const MIN_SPACING_M: f64 = 0.01;
    /// Largest vegetation density, items per square metre.
    pub const MAX_DENSITY_PER_M2: f64 = 100.0;
    /// Most ground types in a legend (indices are u8).
    pub const MAX_GROUND_TYPES: usize = 256;
    /// Most vegetation species layers.
    pub const MAX_SPECIES: usize = 64;
    /// Most rows in a tree, building or decal list.
    pub const MAX_LIST_ITEMS: usize = 10_000_000;
    /// Largest text file (lists, decals, manifest) read, bytes: 10 million rows of about 50
    /// bytes. Parsing holds a small multiple of the text, so memory stays bounded.
    pub const MAX_TEXT_FILE_BYTES: u64 = 512 << 20;
    /// Largest magnitude of a height sample, metres.
    pub const MAX_ABS_HEIGHT_M: f32 = 100_000.0;
}

/// Why a map could not be loaded or written. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    #[error("{path}: cannot {action}: {source}")]
    Io {
        path: PathBuf,
        action: &'static str,
        source: std::io::Error,
    },
    #[error("{path}: not a valid manifest: {message}")]
    ManifestSyntax { path: PathBuf, message: String },
    #[error("{path}: field `format` is {found:?}, expected {expected:?}; is this a map folder?")]
    WrongFormat {
        path: PathBuf,
        found: String,
        expected: &'static str,
    },
    #[error(
        "{path}: field `version` is {found}, this build reads version {supported}; {}",
        if *found < i64::from(*supported) {
            "regenerate the map with `worldgen generate` (version 2 added poisson.csv, the vegetation tile; version 3 towns: house rows, meshes and textures, house pads)"
        } else {
            "upgrade the engine or regenerate the map"
        }
    )]
    UnknownVersion {
        path: PathBuf,
        found: i64,
        supported: u32,
    },
    /// A house type's mesh (`buildings/<type>.pm`).
    #[error(transparent)]
    BuildingModel(#[from] crate::pm::file::PmError),
    #[error("{path}: field `{field}`: {problem}")]
    InvalidField {
        path: PathBuf,
        field: String,
        problem: String,
    },
    #[error(
        "{path}: field `{field}`: {width}x{height} samples exceeds the limit of {max}x{max}; use a coarser spacing"
    )]
    TooLarge {
        path: PathBuf,
        field: String,
        width: u64,
        height: u64,
        max: u32,
    },
    #[error(
        "{path}: layer `{field}` is {found_w}x{found_h} samples but the manifest says {expected_w}x{expected_h}"
    )]
    LayerSize {
        path: PathBuf,
        field: String,
        found_w: u64,
        found_h: u64,
        expected_w: u64,
        expected_h: u64,
    },
    #[error("{path}: layer `{field}` is not a valid {kind} file: {message}")]
    BadLayerFile {
        path: PathBuf,
        field: String,
        kind: &'static str,
        message: String,
    },
    #[error(
        "{path}: height sample at column {x}, row {y} (from the south) is {value}: heights must be finite and within ±{max} m"
    )]
    BadHeight {
        path: PathBuf,
        x: usize,
        y: usize,
        value: f32,
        max: f32,
    },
    #[error(
        "{path}: ground sample at column {x}, row {y} (from the south) is type {value}, but the legend has only {legend_len} types"
    )]
    GroundTypeOutOfRange {
        path: PathBuf,
        x: usize,
        y: usize,
        value: u8,
        legend_len: usize,
    },
    #[error("{path}: line {line}: {problem}")]
    ListLine {
        path: PathBuf,
        line: usize,
        problem: String,
    },
}

/// Reads a UTF-8 text file of at most [`limits::MAX_TEXT_FILE_BYTES`]; `what` names it in errors.
pub(crate) fn read_text_file(path: &Path, what: &'static str) -> Result<String, MapError> {
    let len = std::fs::metadata(path)
        .map_err(|e| MapError::io(path, what, e))?
        .len();
    if len > limits::MAX_TEXT_FILE_BYTES {
        return Err(MapError::field(
            path,
            "(file size)",
            format!(
                "{len} bytes is beyond the limit of {} bytes",
                limits::MAX_TEXT_FILE_BYTES
            ),
        ));
    }
    std::fs::read_to_string(path).map_err(|e| MapError::io(path, what, e))
}

impl MapError {
    pub(crate) fn io(path: &Path, action: &'static str, source: std::io::Error) -> Self {
        Self::Io {
            path: path.to_path_buf(),
            action,
            source,
        }
    }

    pub(crate) fn field(path: &Path, field: impl Into<String>, problem: impl Into<String>) -> Self {
        Self::InvalidField {
            path: path.to_path_buf(),
            field: field.into(),
            problem: problem.into(),
        }
    }
}

/// One vegetation species: its manifest entry and density samples (0..255 = 0..max density),
/// shared (readers that keep a layer, such as the engine's canopy, hold it without a copy).
#[derive(Debug, Clone, PartialEq)]
pub struct DensityLayer {
    pub spec: SpeciesSpec,
    pub density: std::sync::Arc<Grid<u8>>,
}

/// A whole, validated map in memory.
#[derive(Debug, Clone, PartialEq)]
pub struct Map {
    pub manifest: Manifest,
    /// Heights in metres, `manifest.heights.width` x `manifest.heights.height`: in memory, or
    /// served from the bake's pages ([`Self::load_paged`]).
    pub heights: Heights,
    /// Ground type index per sample, < `manifest.ground.legend.len()` when held in memory;
    /// served from the bake's pages ([`Self::load_paged`]) it is not read at the open, and its
    /// readers clamp to the legend's last type.
    pub ground: GroundTypes,
    /// One layer per `manifest.vegetation` entry, in the same order.
    pub densities: Vec<DensityLayer>,
    pub trees: Vec<Tree>,
    pub decals: Vec<Decal>,
    pub buildings: Vec<Building>,
    /// One progressive mesh per house type in `buildings`, in order of first appearance.
    pub building_models: Vec<building_models::BuildingModel>,
    /// Every texture `buildings` name, in order of first appearance.
    pub building_textures: Vec<building_models::BuildingTexture>,
    /// The ranked Poisson-disc tile (points in rank order on the unit torus).
    pub poisson: crate::poisson::PoissonTile,
    /// Per legend entry, the material image it names (`ground.legend[i].material`), if any.
    pub materials: Vec<Option<MaterialImage>>,
}

/// Seconds taken by the parts of a load, for its log line.
struct PartClock {
    start: std::time::Instant,
    parts: Vec<String>,
}

impl Default for PartClock {
    fn default() -> Self {
        Self {
            start: std::time::Instant::now(),
            parts: Vec::new(),
        }
    }
}

impl PartClock {
    /// Records the time since the last part as `name`'s.
    fn part(&mut self, name: &str) {
        let now = std::time::Instant::now();
        let s = now.duration_since(self.start).as_secs_f64();
        self.parts.push(format!("{name} {s:.2} s"));
        self.start = now;
    }
}

/// Summary numbers for `worldgen check` and logs.
#[derive(Debug, Clone, PartialEq)]
pub struct MapSummary {
    pub size_m: [f64; 2],
    pub heights_samples: [usize; 2],
    pub height_min_m: f32,
    pub height_max_m: f32,
    pub ground_type_counts: Vec<(String, usize)>,
    pub species: Vec<(String, f64)>,
    pub trees: usize,
    pub decals_by_kind: Vec<(String, usize)>,
    pub buildings: usize,
}

impl Map {
    /// Loads and validates the map in folder `dir`. Either the whole map is returned or an error
    /// that names the file and the field.
    pub fn load(dir: &Path) -> Result<Self, MapError> {
        Self::load_with(dir, None)
    }

    /// [`Self::load`], with the heights served page by page through `paging`'s cache from
    /// the bake's page file, where the record of the bake's sources says it holds the map's
    /// heights file as it is now (else they are read whole, as by [`Self::load`]). The bake
    /// checked every sample when it read the heights file, and each page's checksum is checked
    /// as it is read.
    pub fn load_paged(dir: &Path, paging: &crate::pages::Paging) -> Result<Self, MapError> {
        Self::load_with(dir, Some(paging))
    }

    fn load_with(dir: &Path, paging: Option<&crate::pages::Paging>) -> Result<Self, MapError> {
        let manifest_path = dir.join("map.toml");
        let manifest = manifest::read(&manifest_path)?;
        let mut clock = PartClock::default();
        let mut baked = baked::Baked::open(dir);
        let paged = paging.and_then(|p| baked.paged(&manifest.heights, p));
        let heights = match paged {
            Some(p) => Heights::Paged(p),
            None => match baked.raster::<f32>(&manifest.heights) {
                Some(g) => {
                    layers::check_heights(&dir.join(&manifest.heights.file), &g)?;
                    Heights::Grid(g)
                }
                None => Heights::Grid(layers::read_heights(dir, &manifest)?),
            },
        };
        clock.part("heights");
        let ground_spec = manifest.ground.grid();
        let paged = paging.and_then(|p| baked.paged(&ground_spec, p));
        let ground = match paged {
            Some(p) => GroundTypes::Paged(p),
            None => GroundTypes::Grid(match baked.raster::<u8>(&ground_spec) {
                Some(g) => {
                    layers::check_ground(&dir.join(&ground_spec.file), &g, &manifest)?;
                    g
                }
                None => layers::read_ground(dir, &manifest)?,
            }),
        };
        clock.part("ground types");
        let mut densities = Vec::with_capacity(manifest.vegetation.len());
        for (i, spec) in manifest.vegetation.iter().enumerate() {
            let grid = spec.grid();
            let density = match baked.raster::<u8>(&grid) {
                Some(g) => g,
                None => layers::read_gray8(dir, &format!("vegetation[{i}].file"), &grid)?,
            };
            densities.push(DensityLayer {
                spec: spec.clone(),
                density: density.into(),
            });
        }
        clock.part("densities");
        let trees_path = dir.join(&manifest.trees.file);
        let trees = match baked.trees(&manifest.trees.file) {
            Some(list) => {
                lists::check_trees(&trees_path, &list, &manifest)?;
                list
            }
            None => lists::read_trees(&trees_path, &manifest)?,
        };
        clock.part("trees");
        let decals_path = dir.join(&manifest.decals.file);
        let decals = match baked.decals(&manifest.decals.file) {
            Some(list) => {
                lists::check_decals(&decals_path, &list, &manifest, lists::DECALS_VERSION.into())?;
                list
            }
            None => lists::read_decals(&decals_path, &manifest)?,
        };
        clock.part("decals");
        let buildings = lists::read_buildings(&dir.join(&manifest.buildings.file), &manifest)?;
        let building_models = building_models::read(dir, &buildings)?;
        let building_textures = building_models::read_textures(dir, &buildings)?;
        clock.part("buildings");
        let poisson = lists::read_poisson(
            &dir.join(&manifest.poisson.file),
            manifest.poisson.min_distance,
        )?;
        let mut materials = Vec::with_capacity(manifest.ground.legend.len());
        for (i, t) in manifest.ground.legend.iter().enumerate() {
            materials.push(match &t.material {
                Some(file) => Some(material_image::read(
                    &dir.join(file),
                    &format!("ground.legend[{i}].material"),
                )?),
                None => None,
            });
        }
        clock.part("Poisson tile and materials");
        baked.finish();
        log::info!(
            "map files of {} read: {}; from the bake's pages: {}",
            dir.display(),
            clock.parts.join(", "),
            if baked.read.is_empty() {
                "none".to_string()
            } else {
                baked.read.join(", ")
            }
        );
        Ok(Self {
            manifest,
            heights,
            ground,
            densities,
            trees,
            decals,
            buildings,
            building_models,
            building_textures,
            poisson,
            materials,
        })
    }

    /// Writes the map into folder `dir`. Files are first written into a sibling folder and moved
    /// into place only when all are complete, so an interrupted write never leaves a half map.
    pub fn write(&self, dir: &Path) -> Result<(), MapError> {
        self.validate_in_memory(dir)?;
        let parent = dir
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        std::fs::create_dir_all(parent).map_err(|e| MapError::io(parent, "create folder", e))?;
        let name = dir
            .file_name()
            .map_or_else(|| "map".into(), |n| n.to_string_lossy().into_owned());
        let staging = parent.join(format!(".{name}.partial"));
        if staging.exists() {
            std::fs::remove_dir_all(&staging)
                .map_err(|e| MapError::io(&staging, "remove stale folder", e))?;
        }
        std::fs::create_dir_all(&staging)
            .map_err(|e| MapError::io(&staging, "create folder", e))?;
        manifest::write(&staging.join("map.toml"), &self.manifest)?;
        let heights_path = staging.join(&self.manifest.heights.file);
        let heights = self.heights.whole().map_err(|e| {
            MapError::io(
                &heights_path,
                "read the heights pages",
                std::io::Error::other(e),
            )
        })?;
        layers::write_heights(&heights_path, &heights)?;
        let ground_path = staging.join(&self.manifest.ground.file);
        let ground = self.ground.whole().map_err(|e| {
            MapError::io(
                &ground_path,
                "read the ground type pages",
                std::io::Error::other(e),
            )
        })?;
        layers::write_ground(&ground_path, &ground, &self.manifest.ground)?;
        for layer in &self.densities {
            layers::write_gray8(&staging.join(&layer.spec.file), &layer.density)?;
        }
        lists::write_trees(
            &staging.join(&self.manifest.trees.file),
            &self.trees,
            &self.manifest,
        )?;
        lists::write_decals(&staging.join(&self.manifest.decals.file), &self.decals)?;
        lists::write_buildings(
            &staging.join(&self.manifest.buildings.file),
            &self.buildings,
        )?;
        building_models::write(&staging, &self.building_models)?;
        building_models::write_textures(&staging, &self.building_textures)?;
        lists::write_poisson(&staging.join(&self.manifest.poisson.file), &self.poisson)?;
        for (i, (t, image)) in self
            .manifest
            .ground
            .legend
            .iter()
            .zip(&self.materials)
            .enumerate()
        {
            if let (Some(file), Some(image)) = (&t.material, image) {
                let field = format!("ground.legend[{i}].material");
                material_image::write(&staging.join(file), &field, image)?;
            }
        }
        if dir.exists() {
            std::fs::remove_dir_all(dir).map_err(|e| MapError::io(dir, "replace folder", e))?;
        }
        std::fs::rename(&staging, dir)
            .map_err(|e| MapError::io(dir, "move finished map into place", e))
    }

    /// Checks that in-memory layers agree with the manifest (used before writing).
    fn validate_in_memory(&self, dir: &Path) -> Result<(), MapError> {
        let path = dir.join("map.toml");
        manifest::validate(&path, &self.manifest)?;
        let check = |field: &str, spec: &GridSpec, w: usize, h: usize| {
            if (w as u64, h as u64) == (u64::from(spec.width), u64::from(spec.height)) {
                Ok(())
            } else {
                Err(MapError::LayerSize {
                    path: path.clone(),
                    field: field.into(),
                    found_w: w as u64,
                    found_h: h as u64,
                    expected_w: spec.width.into(),
                    expected_h: spec.height.into(),
                })
            }
        };
        check(
            "heights",
            &self.manifest.heights,
            self.heights.width(),
            self.heights.height(),
        )?;
        check(
            "ground",
            &self.manifest.ground.grid(),
            self.ground.width(),
            self.ground.height(),
        )?;
        if self.densities.len() != self.manifest.vegetation.len() {
            return Err(MapError::field(
                &path,
                "vegetation",
                "one density layer per species entry is required",
            ));
        }
        for (i, d) in self.densities.iter().enumerate() {
            check(
                &format!("vegetation[{i}]"),
                &d.spec.grid(),
                d.density.width(),
                d.density.height(),
            )?;
        }
        let legend = &self.manifest.ground.legend;
        if self.materials.len() != legend.len() {
            return Err(MapError::field(
                &path,
                "ground.legend",
                "one material entry (an image or none) per legend entry is required",
            ));
        }
        for (i, (t, image)) in legend.iter().zip(&self.materials).enumerate() {
            let ok = match (&t.material, image) {
                (Some(_), Some(m)) => {
                    m.side.is_power_of_two()
                        && (material_image::MIN_SIDE..=material_image::MAX_SIDE).contains(&m.side)
                        && m.rgba.len() == (m.side * m.side) as usize
                }
                (None, None) => true,
                _ => false,
            };
            if !ok {
                return Err(MapError::field(
                    &path,
                    format!("ground.legend[{i}].material"),
                    "names a file without an image in memory, or the image has a bad size",
                ));
            }
        }
        let types = building_models::types(&self.buildings);
        let names: Vec<&str> = self
            .building_models
            .iter()
            .map(|m| m.type_name.as_str())
            .collect();
        let want: Vec<&str> = types.iter().map(|b| b.type_name.as_str()).collect();
        if names != want {
            return Err(MapError::field(
                &path,
                "buildings",
                format!("house types {want:?} but meshes for {names:?}"),
            ));
        }
        let textures: Vec<&str> = self
            .building_textures
            .iter()
            .map(|t| t.name.as_str())
            .collect();
        if textures != building_models::texture_names(&self.buildings) {
            return Err(MapError::field(
                &path,
                "buildings",
                format!(
                    "the houses name textures {:?} but the map holds {textures:?}",
                    building_models::texture_names(&self.buildings)
                ),
            ));
        }
        for (b, m) in types.iter().zip(&self.building_models) {
            building_models::check_fit(&building_models::path(dir, &b.type_name), b, &m.pm)?;
        }
        Ok(())
    }

    /// Where the height grid lies in the world.
    pub fn height_placement(&self) -> GridPlacement {
        GridPlacement {
            origin_m: self.manifest.origin_m,
            spacing_m: self.manifest.heights.spacing_m,
        }
    }

    /// Height (m) at a world position, bilinear, clamped at the border.
    pub fn height_bilinear_m(&self, x_m: f64, y_m: f64) -> f64 {
        let at = self.height_placement();
        match &self.heights {
            Heights::Grid(h) => sample::bilinear(h, at, x_m, y_m),
            Heights::Paged(h) => sample::bilinear(h, at, x_m, y_m),
        }
    }

    /// Height (m) at a world position, C1 bicubic (Catmull-Rom), clamped at the border.
    pub fn height_bicubic_m(&self, x_m: f64, y_m: f64) -> f64 {
        let at = self.height_placement();
        match &self.heights {
            Heights::Grid(h) => sample::bicubic(h, at, x_m, y_m),
            Heights::Paged(h) => sample::bicubic(h, at, x_m, y_m),
        }
    }

    /// Ground type index of the nearest ground sample.
    pub fn ground_type_at(&self, x_m: f64, y_m: f64) -> u8 {
        let g = &self.manifest.ground;
        let gx = ((x_m - self.manifest.origin_m[0]) / g.spacing_m).round() as i64;
        let gy = ((y_m - self.manifest.origin_m[1]) / g.spacing_m).round() as i64;
        self.ground.get_clamped(gx, gy)
    }

    /// Summary numbers (sizes, height range, counts).
    pub fn summary(&self) -> MapSummary {
        let (lo, hi) = self
            .heights
            .whole()
            .map_or((f32::NAN, f32::NAN), |g| g.min_max());
        let mut counts = vec![0usize; self.manifest.ground.legend.len()];
        if let Ok(ground) = self.ground.whole() {
            for &g in ground.data() {
                if let Some(c) = counts.get_mut(g as usize) {
                    *c += 1;
                }
            }
        }
        let cell_m2 = self.manifest.size_m[0] * self.manifest.size_m[1];
        let species = self
            .densities
            .iter()
            .map(|d| {
                let mean = d.density.data().iter().map(|&v| f64::from(v)).sum::<f64>()
                    / d.density.data().len().max(1) as f64;
                (
                    d.spec.species.clone(),
                    mean / 255.0 * d.spec.max_density_per_m2 * cell_m2,
                )
            })
            .collect();
        let mut decals_by_kind: Vec<(String, usize)> = Vec::new();
        for d in &self.decals {
            let k = d.kind.name().to_string();
            match decals_by_kind.iter_mut().find(|(n, _)| *n == k) {
                Some(e) => e.1 += 1,
                None => decals_by_kind.push((k, 1)),
            }
        }
        MapSummary {
            size_m: self.manifest.size_m,
            heights_samples: [self.heights.width(), self.heights.height()],
            height_min_m: lo,
            height_max_m: hi,
            ground_type_counts: self
                .manifest
                .ground
                .legend
                .iter()
                .zip(counts)
                .map(|(t, c)| (t.name.clone(), c))
                .collect(),
            species,
            trees: self.trees.len(),
            decals_by_kind,
            buildings: self.buildings.len(),
        }
    }
}

impl std::fmt::Display for MapSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "size:        {} m x {} m",
            self.size_m[0], self.size_m[1]
        )?;
        writeln!(
            f,
            "heights:     {} x {} samples",
            self.heights_samples[0], self.heights_samples[1]
        )?;
        writeln!(
            f,
            "height:      {:.2} m .. {:.2} m",
            self.height_min_m, self.height_max_m
        )?;
        let total: usize = self
            .ground_type_counts
            .iter()
            .map(|c| c.1)
            .sum::<usize>()
            .max(1);
        for (name, c) in &self.ground_type_counts {
            writeln!(
                f,
                "ground {name:<13} {:6.2} %",
                100.0 * *c as f64 / total as f64
            )?;
        }
        for (name, n) in &self.species {
            writeln!(f, "species {name:<12} ~{n:.0} items")?;
        }
        writeln!(f, "large trees: {}", self.trees)?;
        for (k, n) in &self.decals_by_kind {
            writeln!(f, "decals {k:<13} {n}")?;
        }
        write!(f, "buildings:   {}", self.buildings)
    }
}
