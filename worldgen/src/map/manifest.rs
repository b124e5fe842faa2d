//! The `map.toml` manifest: its serde model (a text format with an explicit `format` name and
//! `version`, so the serializer's layout is not the file format) and its validation.

use super::{MapError, limits};
use serde::{Deserialize, Serialize};
use std::path::Path;

pub const FORMAT_NAME: &str = "tvs-map";
pub const FORMAT_VERSION: u32 = 3;

/// The manifest of a map folder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// Always [`FORMAT_NAME`].
    pub format: String,
    /// Always [`FORMAT_VERSION`] for this reader.
    pub version: u32,
    /// A human-readable name.
    pub name: String,
    /// The generator seed as 16 hex digits (TOML integers cannot hold every u64).
    pub seed: String,
    /// World extent in metres (east, north).
    pub size_m: [f64; 2],
    /// World position of the south-west corner, metres.
    pub origin_m: [f64; 2],
    /// Height of the water surface (lakes, sea), metres.
    pub water_level_m: f64,
    pub heights: GridSpec,
    pub ground: GroundSpec,
    /// Large tree species names; `trees.csv` rows refer to them by index.
    pub tree_species: Vec<String>,
    #[serde(default)]
    pub vegetation: Vec<SpeciesSpec>,
    pub trees: FileSpec,
    pub decals: FileSpec,
    pub buildings: FileSpec,
    /// The ranked, periodic Poisson-disc tile for vegetation placement (since version 2).
    pub poisson: PoissonSpec,
}

/// Where the Poisson-disc tile is and the minimum distance between its points (tile units).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoissonSpec {
    pub file: String,
    /// Smallest distance between two points, in units of the tile side.
    pub min_distance: f64,
}

/// A raster layer covering the whole world.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridSpec {
    pub file: String,
    pub width: u32,
    pub height: u32,
    pub spacing_m: f64,
}

/// A file-backed list layer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FileSpec {
    pub file: String,
}

/// One entry of the ground-type legend.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroundType {
    pub name: String,
    /// sRGB colour used for the PNG palette and as the base render colour.
    pub color: [u8; 3],
    /// Amplitude (m) of the procedural detail the engine adds on this ground type.
    pub detail_amplitude_m: f32,
    /// Optional albedo image for this type's ground material: a PNG in the map folder (8-bit
    /// RGB or RGBA, square, a power-of-two side in 16..=1024 texels) that tiles over one
    /// material tile. Without it the engine makes the material from the name and colour.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub material: Option<String>,
}

/// The ground-type layer: an indexed PNG and its legend (index = position in `legend`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroundSpec {
    pub file: String,
    pub width: u32,
    pub height: u32,
    pub spacing_m: f64,
    pub legend: Vec<GroundType>,
}

impl GroundSpec {
    pub fn grid(&self) -> GridSpec {
        GridSpec {
            file: self.file.clone(),
            width: self.width,
            height: self.height,
            spacing_m: self.spacing_m,
        }
    }
}

/// One vegetation species density layer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpeciesSpec {
    pub species: String,
    pub file: String,
    pub width: u32,
    pub height: u32,
    pub spacing_m: f64,
    /// Items per square metre at density sample 255.
    pub max_density_per_m2: f64,
    /// Smallest distance between two items of this species, metres.
    pub min_distance_m: f64,
}

impl SpeciesSpec {
    pub fn grid(&self) -> GridSpec {
        GridSpec {
            file: self.file.clone(),
            width: self.width,
            height: self.height,
            spacing_m: self.spacing_m,
        }
    }
}

impl GridSpec {
    /// The number of samples a layer of this spacing needs to cover `size_m` (None when the
    /// spacing does not divide the size within a millimetre).
    pub fn samples_for(size_m: f64, spacing_m: f64) -> Option<u32> {
        let cells = size_m / spacing_m;
        let rounded = cells.round();
        ((cells - rounded).abs() * spacing_m < 1e-3
            && rounded >= 1.0
            && rounded < f64::from(u32::MAX))
        .then_some(rounded as u32 + 1)
    }
}

/// Reads and validates a manifest. The format name and version are checked before the rest is
/// parsed, so a future version gets a version error rather than a confusing field error.
pub fn read(path: &Path) -> Result<Manifest, MapError> {
    let text = super::read_text_file(path, "read manifest")?;
    let table: toml::Table = toml::from_str(&text).map_err(|e| MapError::ManifestSyntax {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    match table.get("format") {
        Some(toml::Value::String(s)) if s == FORMAT_NAME => {}
        Some(v) => {
            return Err(MapError::WrongFormat {
                path: path.to_path_buf(),
                found: v.to_string(),
                expected: FORMAT_NAME,
            });
        }
        None => {
            return Err(MapError::field(
                path,
                "format",
                format!("missing; expected format = \"{FORMAT_NAME}\""),
            ));
        }
    }
    match table.get("version") {
        Some(toml::Value::Integer(v)) if *v == i64::from(FORMAT_VERSION) => {}
        Some(toml::Value::Integer(v)) => {
            return Err(MapError::UnknownVersion {
                path: path.to_path_buf(),
                found: *v,
                supported: FORMAT_VERSION,
            });
        }
        _ => {
            return Err(MapError::field(
                path,
                "version",
                format!("missing or not an integer; expected version = {FORMAT_VERSION}"),
            ));
        }
    }
    let manifest: Manifest = toml::from_str(&text).map_err(|e| MapError::ManifestSyntax {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    validate(path, &manifest)?;
    Ok(manifest)
}

/// Writes a manifest as TOML.
pub fn write(path: &Path, manifest: &Manifest) -> Result<(), MapError> {
    let text = toml::to_string_pretty(manifest)
        .map_err(|e| MapError::field(path, "manifest", format!("cannot be serialised: {e}")))?;
    std::fs::write(path, text).map_err(|e| MapError::io(path, "write manifest", e))
}

fn finite_in(
    path: &Path,
    field: &str,
    v: f64,
    lo: f64,
    hi: f64,
    fix: &str,
) -> Result<(), MapError> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(())
    } else {
        Err(MapError::field(
            path,
            field,
            format!("is {v}, expected a finite number in [{lo}, {hi}]; {fix}"),
        ))
    }
}

fn check_file_name(path: &Path, field: &str, file: &str) -> Result<(), MapError> {
    let ok = !file.is_empty()
        && !file.contains(['/', '\\'])
        && file != "."
        && file != ".."
        && file != "map.toml";
    if ok {
        Ok(())
    } else {
        Err(MapError::field(
            path,
            field,
            format!("{file:?} must be a plain file name inside the map folder"),
        ))
    }
}

fn check_grid(path: &Path, field: &str, spec: &GridSpec, size_m: [f64; 2]) -> Result<(), MapError> {
    check_file_name(path, &format!("{field}.file"), &spec.file)?;
    if !(spec.spacing_m.is_finite() && spec.spacing_m >= limits::MIN_SPACING_M) {
        return Err(MapError::field(
            path,
            format!("{field}.spacing_m"),
            format!(
                "is {}, expected a positive sample spacing of at least {} m",
                spec.spacing_m,
                limits::MIN_SPACING_M
            ),
        ));
    }
    if spec.width > limits::MAX_GRID_SIDE || spec.height > limits::MAX_GRID_SIDE {
        return Err(MapError::TooLarge {
            path: path.to_path_buf(),
            field: field.to_string(),
            width: spec.width.into(),
            height: spec.height.into(),
            max: limits::MAX_GRID_SIDE,
        });
    }
    for (axis, samples, size) in [
        ("width", spec.width, size_m[0]),
        ("height", spec.height, size_m[1]),
    ] {
        let expected = GridSpec::samples_for(size, spec.spacing_m);
        if expected != Some(samples) {
            let want = expected.map_or_else(
                || format!("a spacing that divides the world size {size} m"),
                |n| {
                    format!(
                        "{n} samples ((size_m / spacing_m) + 1 = {size} / {} + 1)",
                        spec.spacing_m
                    )
                },
            );
            return Err(MapError::field(
                path,
                format!("{field}.{axis}"),
                format!("is {samples}, expected {want}"),
            ));
        }
    }
    Ok(())
}

/// Checks every manifest field that does not need the layer files.
pub fn validate(path: &Path, m: &Manifest) -> Result<(), MapError> {
    if m.format != FORMAT_NAME {
        return Err(MapError::WrongFormat {
            path: path.to_path_buf(),
            found: m.format.clone(),
            expected: FORMAT_NAME,
        });
    }
    if m.version != FORMAT_VERSION {
        return Err(MapError::UnknownVersion {
            path: path.to_path_buf(),
            found: m.version.into(),
            supported: FORMAT_VERSION,
        });
    }
    if m.seed.len() != 16 || u64::from_str_radix(&m.seed, 16).is_err() {
        return Err(MapError::field(
            path,
            "seed",
            format!("is {:?}, expected 16 hex digits", m.seed),
        ));
    }
    for (i, axis) in ["size_m[0]", "size_m[1]"].iter().enumerate() {
        finite_in(
            path,
            axis,
            m.size_m[i],
            1.0,
            limits::MAX_WORLD_SIZE_M,
            "the world side must be positive",
        )?;
        finite_in(
            path,
            &format!("origin_m[{i}]"),
            m.origin_m[i],
            -limits::MAX_ORIGIN_M,
            limits::MAX_ORIGIN_M,
            "move the origin closer to 0",
        )?;
    }
    finite_in(
        path,
        "water_level_m",
        m.water_level_m,
        -f64::from(limits::MAX_ABS_HEIGHT_M),
        f64::from(limits::MAX_ABS_HEIGHT_M),
        "",
    )?;
    check_grid(path, "heights", &m.heights, m.size_m)?;
    if m.heights.width < 2 || m.heights.height < 2 {
        return Err(MapError::field(
            path,
            "heights.width",
            "a height layer needs at least 2x2 samples",
        ));
    }
    validate_ground(path, m)?;
    validate_vegetation(path, m)?;
    validate_files(path, m)
}

/// The ground layer's grid and legend.
fn validate_ground(path: &Path, m: &Manifest) -> Result<(), MapError> {
    check_grid(path, "ground", &m.ground.grid(), m.size_m)?;
    if m.ground.legend.is_empty() || m.ground.legend.len() > limits::MAX_GROUND_TYPES {
        return Err(MapError::field(
            path,
            "ground.legend",
            format!(
                "has {} entries, expected 1..={}",
                m.ground.legend.len(),
                limits::MAX_GROUND_TYPES
            ),
        ));
    }
    for (i, t) in m.ground.legend.iter().enumerate() {
        if t.name.is_empty() || m.ground.legend[..i].iter().any(|o| o.name == t.name) {
            return Err(MapError::field(
                path,
                format!("ground.legend[{i}].name"),
                format!("{:?} must be non-empty and unique", t.name),
            ));
        }
        finite_in(
            path,
            &format!("ground.legend[{i}].detail_amplitude_m"),
            f64::from(t.detail_amplitude_m),
            0.0,
            100.0,
            "",
        )?;
        if let Some(file) = &t.material {
            check_file_name(path, &format!("ground.legend[{i}].material"), file)?;
        }
    }
    Ok(())
}

/// The vegetation species, their density layers and the large-tree species names.
fn validate_vegetation(path: &Path, m: &Manifest) -> Result<(), MapError> {
    if m.vegetation.len() > limits::MAX_SPECIES {
        return Err(MapError::field(
            path,
            "vegetation",
            format!(
                "has {} species, at most {}",
                m.vegetation.len(),
                limits::MAX_SPECIES
            ),
        ));
    }
    for (i, s) in m.vegetation.iter().enumerate() {
        let f = format!("vegetation[{i}]");
        if s.species.is_empty() || m.vegetation[..i].iter().any(|o| o.species == s.species) {
            return Err(MapError::field(
                path,
                format!("{f}.species"),
                format!("{:?} must be non-empty and unique", s.species),
            ));
        }
        check_grid(path, &f, &s.grid(), m.size_m)?;
        finite_in(
            path,
            &format!("{f}.max_density_per_m2"),
            s.max_density_per_m2,
            0.0,
            limits::MAX_DENSITY_PER_M2,
            "density is items per square metre at sample value 255",
        )?;
        finite_in(
            path,
            &format!("{f}.min_distance_m"),
            s.min_distance_m,
            0.01,
            1000.0,
            "",
        )?;
        // Items at least min_distance apart cannot be denser than one per disc-packing cell.
        let packing_limit = 1.0 / (s.min_distance_m * s.min_distance_m * 0.866);
        if s.max_density_per_m2 > packing_limit {
            return Err(MapError::field(
                path,
                format!("{f}.max_density_per_m2"),
                format!(
                    "is {}, but items {} m apart fit at most {packing_limit:.4} per m²; lower the density or the distance",
                    s.max_density_per_m2, s.min_distance_m
                ),
            ));
        }
    }
    if m.tree_species
        .iter()
        .enumerate()
        .any(|(i, s)| s.is_empty() || m.tree_species[..i].contains(s))
    {
        return Err(MapError::field(
            path,
            "tree_species",
            "names must be non-empty and unique",
        ));
    }
    Ok(())
}

/// The list and tile files: plain names, each used by one layer; the Poisson tile's distance.
fn validate_files(path: &Path, m: &Manifest) -> Result<(), MapError> {
    check_file_name(path, "trees.file", &m.trees.file)?;
    check_file_name(path, "decals.file", &m.decals.file)?;
    check_file_name(path, "buildings.file", &m.buildings.file)?;
    check_file_name(path, "poisson.file", &m.poisson.file)?;
    if !(m.poisson.min_distance > 0.001 && m.poisson.min_distance < 0.5) {
        return Err(MapError::field(
            path,
            "poisson.min_distance",
            format!(
                "{} is outside (0.001, 0.5) (tile units)",
                m.poisson.min_distance
            ),
        ));
    }
    let mut files: Vec<&str> = vec![
        &m.heights.file,
        &m.ground.file,
        &m.trees.file,
        &m.decals.file,
        &m.buildings.file,
        &m.poisson.file,
    ];
    files.extend(m.vegetation.iter().map(|s| s.file.as_str()));
    for (i, f) in files.iter().enumerate() {
        if files[..i].contains(f) {
            return Err(MapError::field(
                path,
                "file",
                format!("{f:?} is used by two layers"),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_for_requires_a_dividing_spacing() {
        assert_eq!(GridSpec::samples_for(512.0, 4.0), Some(129));
        assert_eq!(GridSpec::samples_for(512.0, 3.0), None);
        assert_eq!(GridSpec::samples_for(512.0, 1024.0), None);
    }
}
