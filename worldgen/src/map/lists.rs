//! List layers: large trees, buildings and the Poisson-disc tile as versioned CSV text, decals as
//! versioned TOML.
//! Numbers are written with Rust's shortest round-trip formatting, so a write/read cycle is exact.

use super::{Manifest, MapError, limits};
use crate::building_mesh::{BuildingSpec, Roof};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::Path;

pub const TREES_MAGIC: &str = "tvs-trees 1";
pub const TREES_COLUMNS: &str = "species,x_m,y_m,height_m,crown_radius_m";
pub const BUILDINGS_MAGIC: &str = "tvs-buildings 2";
pub const BUILDINGS_COLUMNS: &str = "type,x_m,y_m,z_m,yaw_deg,width_m,depth_m,storeys,storey_m,roof,roof_pitch_deg,seed,facade_texture,roof_texture";
/// Version 1 (mesh,x_m,y_m,z_m,yaw_deg,scale rows naming external meshes) was only ever written
/// empty; an empty version 1 file is read as no buildings, one with rows is refused.
const BUILDINGS_MAGIC_V1: &str = "tvs-buildings 1";
const BUILDINGS_COLUMNS_V1: &str = "mesh,x_m,y_m,z_m,yaw_deg,scale";
pub const DECALS_FORMAT: &str = "tvs-decals";
/// Version written; version 1 files (roads, paths and rock patches only) and version 2 files
/// (no pads) are read as well.
pub const DECALS_VERSION: u32 = 3;

/// A large tree placed explicitly by the map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tree {
    /// Index into `Manifest::tree_species`.
    pub species: u16,
    pub x_m: f64,
    pub y_m: f64,
    pub height_m: f32,
    pub crown_radius_m: f32,
}

/// A building (buildings version 2): a procedural house ([`crate::building_mesh`]) of a named
/// type standing on a flattened pad. Every row of one type has the same dimensions: a type's
/// mesh is built once and its instances share it.
#[derive(Debug, Clone, PartialEq)]
pub struct Building {
    pub type_name: String,
    /// Centre of the footprint.
    pub x_m: f64,
    pub y_m: f64,
    /// Floor height: the pad the ground is flattened to.
    pub z_m: f64,
    /// Direction of the width (the longer side) from +x, counter-clockwise.
    pub yaw_deg: f64,
    /// The mesh; `width_m >= depth_m`.
    pub spec: BuildingSpec,
    /// PNG files in the map's `buildings/` folder for the walls and the roof (a mip atlas or a
    /// plain square image, see [`crate::house_textures`]); instances of a type may differ.
    pub facade_texture: String,
    pub roof_texture: String,
}

impl Building {
    /// The footprint's corners, counter-clockwise seen from above.
    pub fn footprint_m(&self) -> [[f64; 2]; 4] {
        self.grown_footprint_m(0.0)
    }

    /// The footprint grown by `margin_m` on every side, corners counter-clockwise.
    pub fn grown_footprint_m(&self, margin_m: f64) -> [[f64; 2]; 4] {
        let (s, c) = self.yaw_deg.to_radians().sin_cos();
        let (hw, hd) = (
            self.spec.width_m * 0.5 + margin_m,
            self.spec.depth_m * 0.5 + margin_m,
        );
        [(-hw, -hd), (hw, -hd), (hw, hd), (-hw, hd)]
            .map(|(u, v)| [self.x_m + c * u - s * v, self.y_m + s * u + c * v])
    }
}

/// What a decal is; decides its ground texture and how it shapes the ground.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DecalKind {
    /// Paved road: the ground is flattened to the polyline's z (+ offset) across its width.
    Road,
    /// Footpath: like a road, narrower, usually a small negative offset (worn in).
    Path,
    /// Rock patch (closed area): the ground is raised by the offset inside the polygon.
    RockPatch,
    /// Cultivated field (closed area, since decals version 2): striped crop rows along the
    /// polygon's first edge; the ground is moved by the offset inside (usually 0).
    Field,
    /// Bare earth (closed area, since decals version 2): a dirt patch in meadow or forest; the
    /// ground is moved by the offset inside (usually 0 or slightly negative).
    Dirt,
    /// Building pad (closed area, since decals version 3): the ground is flattened to the
    /// polygon's z (every point has the same z) plus the offset inside, and nothing grows there.
    Pad,
}

impl DecalKind {
    pub fn name(self) -> &'static str {
        match self {
            Self::Road => "road",
            Self::Path => "path",
            Self::RockPatch => "rock_patch",
            Self::Field => "field",
            Self::Dirt => "dirt",
            Self::Pad => "pad",
        }
    }

    /// Whether this kind is a closed area (a polygon) rather than a polyline.
    pub fn is_area(self) -> bool {
        matches!(self, Self::RockPatch | Self::Field | Self::Dirt | Self::Pad)
    }
}

/// A typed polyline (or closed area) with a width and a height-offset profile: within
/// `width_m / 2` of the centre line the ground is at the line's interpolated z plus
/// `height_offset_m` (roads, paths) or raised by `height_offset_m` (areas); over the next
/// `falloff_m` it blends smoothly back into the terrain.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Decal {
    pub kind: DecalKind,
    #[serde(default)]
    pub closed: bool,
    pub width_m: f32,
    pub falloff_m: f32,
    pub height_offset_m: f32,
    /// (x, y, z) in world metres; z is the surface height along the centre line.
    pub points: Vec<[f64; 3]>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct DecalFile {
    format: String,
    version: u32,
    #[serde(default)]
    decal: Vec<Decal>,
}

fn line_err(path: &Path, line: usize, problem: impl Into<String>) -> MapError {
    MapError::ListLine {
        path: path.to_path_buf(),
        line,
        problem: problem.into(),
    }
}

/// Splits a CSV list file into data rows after checking its magic line and column line.
fn data_rows<'a>(
    path: &Path,
    text: &'a str,
    magic: &str,
    columns: &str,
) -> Result<Vec<(usize, &'a str)>, MapError> {
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim_end_matches('\r')));
    match lines.next() {
        Some((_, l)) if l == magic => {}
        Some((n, l)) => {
            return Err(line_err(
                path,
                n,
                format!("found {l:?}, expected the header {magic:?}"),
            ));
        }
        None => {
            return Err(line_err(
                path,
                1,
                format!("the file is empty; expected the header {magic:?}"),
            ));
        }
    }
    match lines.next() {
        Some((_, l)) if l == columns => {}
        Some((n, l)) => {
            return Err(line_err(
                path,
                n,
                format!("found {l:?}, expected the columns {columns:?}"),
            ));
        }
        None => {
            return Err(line_err(
                path,
                2,
                format!("missing the column line {columns:?}"),
            ));
        }
    }
    let rows: Vec<_> = lines.filter(|(_, l)| !l.trim().is_empty()).collect();
    if rows.len() > limits::MAX_LIST_ITEMS {
        return Err(line_err(
            path,
            0,
            format!(
                "{} rows exceed the limit of {}",
                rows.len(),
                limits::MAX_LIST_ITEMS
            ),
        ));
    }
    Ok(rows)
}

fn parse_field<T: std::str::FromStr>(
    path: &Path,
    line: usize,
    name: &str,
    s: Option<&str>,
) -> Result<T, MapError> {
    let s = s.ok_or_else(|| line_err(path, line, format!("missing column `{name}`")))?;
    s.trim()
        .parse()
        .map_err(|_| line_err(path, line, format!("column `{name}`: cannot parse {s:?}")))
}

fn in_world(m: &Manifest, x: f64, y: f64) -> bool {
    x.is_finite()
        && y.is_finite()
        && x >= m.origin_m[0]
        && y >= m.origin_m[1]
        && x <= m.origin_m[0] + m.size_m[0]
        && y <= m.origin_m[1] + m.size_m[1]
}

fn read_text(path: &Path) -> Result<String, MapError> {
    super::read_text_file(path, "read list file (listed in map.toml)")
}

pub fn read_trees(path: &Path, m: &Manifest) -> Result<Vec<Tree>, MapError> {
    let text = read_text(path)?;
    let rows = data_rows(path, &text, TREES_MAGIC, TREES_COLUMNS)?;
    let mut trees = Vec::with_capacity(rows.len());
    for (n, row) in rows {
        let mut cols = row.split(',');
        let t = Tree {
            species: parse_field(path, n, "species", cols.next())?,
            x_m: parse_field(path, n, "x_m", cols.next())?,
            y_m: parse_field(path, n, "y_m", cols.next())?,
            height_m: parse_field(path, n, "height_m", cols.next())?,
            crown_radius_m: parse_field(path, n, "crown_radius_m", cols.next())?,
        };
        if cols.next().is_some() {
            return Err(line_err(
                path,
                n,
                format!("too many columns; expected {TREES_COLUMNS}"),
            ));
        }
        if let Some(problem) = tree_problem(&t, m) {
            return Err(line_err(path, n, problem));
        }
        trees.push(t);
    }
    Ok(trees)
}

/// What is wrong with tree `t` of a map with manifest `m`, if anything: a species the
/// manifest does not name, a position outside the world, or a size out of range.
fn tree_problem(t: &Tree, m: &Manifest) -> Option<String> {
    if usize::from(t.species) >= m.tree_species.len() {
        return Some(format!(
            "species {} is not in map.toml `tree_species` ({} names)",
            t.species,
            m.tree_species.len()
        ));
    }
    if !in_world(m, t.x_m, t.y_m) {
        return Some(format!(
            "position ({}, {}) is outside the world",
            t.x_m, t.y_m
        ));
    }
    if !(t.height_m > 0.0
        && t.height_m <= 200.0
        && t.crown_radius_m > 0.0
        && t.crown_radius_m <= 50.0)
    {
        return Some(format!(
            "height {} m / crown radius {} m out of range (0, 200] / (0, 50]",
            t.height_m, t.crown_radius_m
        ));
    }
    None
}

/// Checks trees read from elsewhere than the CSV `path` (its binary copy in the bake) as
/// [`read_trees`] checks each row; an error names `path` and the tree's index.
pub fn check_trees(path: &Path, trees: &[Tree], m: &Manifest) -> Result<(), MapError> {
    for (i, t) in trees.iter().enumerate() {
        if let Some(problem) = tree_problem(t, m) {
            return Err(MapError::field(path, format!("tree[{i}]"), problem));
        }
    }
    Ok(())
}

pub fn write_trees(path: &Path, trees: &[Tree], _m: &Manifest) -> Result<(), MapError> {
    let mut s = format!("{TREES_MAGIC}\n{TREES_COLUMNS}\n");
    for t in trees {
        let _ = writeln!(
            s,
            "{},{},{},{},{}",
            t.species, t.x_m, t.y_m, t.height_m, t.crown_radius_m
        );
    }
    std::fs::write(path, s).map_err(|e| MapError::io(path, "write", e))
}

pub fn read_buildings(path: &Path, m: &Manifest) -> Result<Vec<Building>, MapError> {
    let text = read_text(path)?;
    if text.lines().next().map(|l| l.trim_end_matches('\r')) == Some(BUILDINGS_MAGIC_V1) {
        let rows = data_rows(path, &text, BUILDINGS_MAGIC_V1, BUILDINGS_COLUMNS_V1)?;
        return match rows.first() {
            None => Ok(Vec::new()),
            Some(&(n, _)) => Err(line_err(
                path,
                n,
                format!(
                    "version 1 building rows (external meshes) are no longer read; expected the header {BUILDINGS_MAGIC:?}"
                ),
            )),
        };
    }
    let rows = data_rows(path, &text, BUILDINGS_MAGIC, BUILDINGS_COLUMNS)?;
    let mut out: Vec<Building> = Vec::with_capacity(rows.len());
    // Per type: the first row's line and spec.
    let mut types: std::collections::HashMap<String, (usize, BuildingSpec)> =
        std::collections::HashMap::new();
    for (n, row) in rows {
        let mut cols = row.split(',');
        let mut field = |name: &str| {
            cols.next()
                .map(str::trim)
                .ok_or_else(|| line_err(path, n, format!("missing column `{name}`")))
        };
        let type_name = field("type")?.to_string();
        let number = |name: &str, v: &str| -> Result<f64, MapError> {
            v.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    line_err(
                        path,
                        n,
                        format!("column `{name}`: cannot parse {v:?} as a finite number"),
                    )
                })
        };
        let x_m = number("x_m", field("x_m")?)?;
        let y_m = number("y_m", field("y_m")?)?;
        let z_m = number("z_m", field("z_m")?)?;
        let yaw_deg = number("yaw_deg", field("yaw_deg")?)?;
        let width_m = number("width_m", field("width_m")?)?;
        let depth_m = number("depth_m", field("depth_m")?)?;
        let storeys_text = field("storeys")?;
        let storeys: u32 = storeys_text.parse().map_err(|_| {
            line_err(
                path,
                n,
                format!("column `storeys`: cannot parse {storeys_text:?} as a whole number"),
            )
        })?;
        let storey_m = number("storey_m", field("storey_m")?)?;
        let roof_text = field("roof")?;
        let roof = Roof::from_name(roof_text).ok_or_else(|| {
            line_err(
                path,
                n,
                format!("column `roof`: {roof_text:?} is not gable or hip"),
            )
        })?;
        let roof_pitch_deg = number("roof_pitch_deg", field("roof_pitch_deg")?)?;
        let seed_text = field("seed")?;
        let facade_texture = field("facade_texture")?.to_string();
        let roof_texture = field("roof_texture")?.to_string();
        let seed = u64::from_str_radix(seed_text, 16).map_err(|_| {
            line_err(
                path,
                n,
                format!("column `seed`: cannot parse {seed_text:?} as hexadecimal"),
            )
        })?;
        if cols.next().is_some() {
            return Err(line_err(
                path,
                n,
                format!("too many columns; expected {BUILDINGS_COLUMNS}"),
            ));
        }
        let b = Building {
            type_name,
            x_m,
            y_m,
            z_m,
            yaw_deg,
            spec: BuildingSpec {
                width_m,
                depth_m,
                storeys,
                storey_m,
                roof,
                roof_pitch_deg,
                seed,
            },
            facade_texture,
            roof_texture,
        };
        check_building(path, n, m, &b)?;
        match types.get(&b.type_name) {
            Some(&(first, spec)) if spec != b.spec => {
                return Err(line_err(
                    path,
                    n,
                    format!(
                        "type {:?} has other dimensions, roof or seed than on line {first}; a type is one mesh",
                        b.type_name
                    ),
                ));
            }
            Some(_) => {}
            None => {
                types.insert(b.type_name.clone(), (n, b.spec));
            }
        }
        out.push(b);
    }
    Ok(out)
}

/// A texture file name in `buildings/`: no folders, ends in `.png`.
fn texture_name_ok(name: &str) -> bool {
    name.len() <= 64
        && name.len() > 4
        && Path::new(name)
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("png"))
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
}

/// A building row's values: a type name, a footprint inside the world, a buildable spec.
fn check_building(path: &Path, n: usize, m: &Manifest, b: &Building) -> Result<(), MapError> {
    let name_ok = !b.type_name.is_empty()
        && b.type_name.len() <= 64
        && b.type_name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if !name_ok {
        return Err(line_err(
            path,
            n,
            format!(
                "column `type`: {:?} must be 1 to 64 letters, digits, '_' or '-'",
                b.type_name
            ),
        ));
    }
    for (column, name) in [
        ("facade_texture", &b.facade_texture),
        ("roof_texture", &b.roof_texture),
    ] {
        if !texture_name_ok(name) {
            return Err(line_err(
                path,
                n,
                format!(
                    "column `{column}`: {name:?} must be a .png file name of letters, digits, '_', '-' and '.' (in the buildings/ folder)"
                ),
            ));
        }
    }
    b.spec
        .check()
        .map_err(|e| line_err(path, n, format!("column {e}")))?;
    if b.spec.width_m < b.spec.depth_m {
        return Err(line_err(
            path,
            n,
            format!(
                "column `width_m` = {} is less than `depth_m` = {}: the width is the longer side",
                b.spec.width_m, b.spec.depth_m
            ),
        ));
    }
    if !(-360.0..=360.0).contains(&b.yaw_deg) {
        return Err(line_err(
            path,
            n,
            format!("column `yaw_deg` = {} outside [-360, 360]", b.yaw_deg),
        ));
    }
    if let Some(&[x, y]) = b.footprint_m().iter().find(|&&[x, y]| !in_world(m, x, y)) {
        return Err(line_err(
            path,
            n,
            format!("the footprint reaches ({x:.1}, {y:.1}) m, outside the world"),
        ));
    }
    if b.z_m.abs() > 20_000.0 {
        return Err(line_err(
            path,
            n,
            format!("column `z_m` = {} is not a plausible height", b.z_m),
        ));
    }
    Ok(())
}

pub fn write_buildings(path: &Path, buildings: &[Building]) -> Result<(), MapError> {
    let mut s = format!("{BUILDINGS_MAGIC}\n{BUILDINGS_COLUMNS}\n");
    for b in buildings {
        let p = &b.spec;
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},{:016x},{},{}",
            b.type_name,
            b.x_m,
            b.y_m,
            b.z_m,
            b.yaw_deg,
            p.width_m,
            p.depth_m,
            p.storeys,
            p.storey_m,
            p.roof.name(),
            p.roof_pitch_deg,
            p.seed,
            b.facade_texture,
            b.roof_texture
        );
    }
    std::fs::write(path, s).map_err(|e| MapError::io(path, "write", e))
}

pub fn read_decals(path: &Path, m: &Manifest) -> Result<Vec<Decal>, MapError> {
    let text = read_text(path)?;
    let table: toml::Table = toml::from_str(&text).map_err(|e| MapError::ManifestSyntax {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    if table.get("format").and_then(toml::Value::as_str) != Some(DECALS_FORMAT) {
        return Err(MapError::field(
            path,
            "format",
            format!("expected format = \"{DECALS_FORMAT}\""),
        ));
    }
    let version = table.get("version").and_then(toml::Value::as_integer);
    if !version.is_some_and(|v| (1..=i64::from(DECALS_VERSION)).contains(&v)) {
        return Err(MapError::field(
            path,
            "version",
            format!("expected version = 1..={DECALS_VERSION}"),
        ));
    }
    let file: DecalFile = toml::from_str(&text).map_err(|e| MapError::ManifestSyntax {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    check_decals(path, &file.decal, m, version.unwrap_or(0))?;
    Ok(file.decal)
}

/// Checks the decals of the list `path` (of list `version`) against the map's manifest `m`,
/// naming the first bad field: the text list's check, also applied to a baked binary list.
pub fn check_decals(
    path: &Path,
    decals: &[Decal],
    m: &Manifest,
    version: i64,
) -> Result<(), MapError> {
    let v1 = version == 1;
    let before_v3 = version < 3;
    if decals.len() > limits::MAX_LIST_ITEMS {
        return Err(MapError::field(path, "decal", "too many decals"));
    }
    for (i, d) in decals.iter().enumerate() {
        let f = |name: &str| format!("decal[{i}].{name}");
        if v1 && matches!(d.kind, DecalKind::Field | DecalKind::Dirt) {
            return Err(MapError::field(
                path,
                f("kind"),
                format!(
                    "{:?} needs decals version 2, the file says version 1",
                    d.kind.name()
                ),
            ));
        }
        if before_v3 && d.kind == DecalKind::Pad {
            return Err(MapError::field(
                path,
                f("kind"),
                format!("\"pad\" needs decals version 3, the file says version {version}"),
            ));
        }
        if d.kind == DecalKind::Pad
            && let Some(p) = d.points.iter().find(|p| p[2] != d.points[0][2])
        {
            return Err(MapError::field(
                path,
                f("points"),
                format!(
                    "a pad is flat: point {p:?} has another z than the first, {}",
                    d.points[0][2]
                ),
            ));
        }
        if d.closed != d.kind.is_area() {
            return Err(MapError::field(
                path,
                f("closed"),
                format!(
                    "is {}, but a {} decal is {}",
                    d.closed,
                    d.kind.name(),
                    if d.kind.is_area() {
                        "a closed area (closed = true)"
                    } else {
                        "an open polyline (closed = false)"
                    }
                ),
            ));
        }
        let min_points = if d.closed { 3 } else { 2 };
        if d.points.len() < min_points {
            return Err(MapError::field(
                path,
                f("points"),
                format!(
                    "has {} points, expected at least {min_points}",
                    d.points.len()
                ),
            ));
        }
        if let Some(p) = d
            .points
            .iter()
            .find(|p| !in_world(m, p[0], p[1]) || !p[2].is_finite())
        {
            return Err(MapError::field(
                path,
                f("points"),
                format!("point {p:?} is outside the world or not finite"),
            ));
        }
        if !(d.width_m > 0.0 && d.width_m <= 100.0) {
            return Err(MapError::field(
                path,
                f("width_m"),
                format!("is {}, expected (0, 100]", d.width_m),
            ));
        }
        if !(d.falloff_m >= 0.0 && d.falloff_m <= 100.0) {
            return Err(MapError::field(
                path,
                f("falloff_m"),
                format!("is {}, expected [0, 100]", d.falloff_m),
            ));
        }
        if !(d.height_offset_m.abs() <= 10.0) {
            return Err(MapError::field(
                path,
                f("height_offset_m"),
                format!("is {}, expected [-10, 10]", d.height_offset_m),
            ));
        }
    }
    Ok(())
}

pub fn write_decals(path: &Path, decals: &[Decal]) -> Result<(), MapError> {
    let file = DecalFile {
        format: DECALS_FORMAT.into(),
        version: DECALS_VERSION,
        decal: decals.to_vec(),
    };
    let text = toml::to_string(&file)
        .map_err(|e| MapError::field(path, "decal", format!("cannot be serialised: {e}")))?;
    std::fs::write(path, text).map_err(|e| MapError::io(path, "write", e))
}

pub const POISSON_MAGIC: &str = "tvs-poisson 1";
pub const POISSON_COLUMNS: &str = "x,y";
/// The fewest points a Poisson tile may have (placement needs a dense tile).
pub const POISSON_MIN_POINTS: usize = 64;

/// Reads the ranked Poisson-disc tile: points in rank order, each in `[0, 1)^2`, at least
/// `min_distance` apart on the torus (checked, so a damaged file cannot break spacing).
pub fn read_poisson(
    path: &Path,
    min_distance: f64,
) -> Result<crate::poisson::PoissonTile, MapError> {
    let text = read_text(path)?;
    let rows = data_rows(path, &text, POISSON_MAGIC, POISSON_COLUMNS)?;
    let mut points = Vec::with_capacity(rows.len());
    for (n, row) in rows {
        let mut cols = row.split(',');
        let x: f64 = parse_field(path, n, "x", cols.next())?;
        let y: f64 = parse_field(path, n, "y", cols.next())?;
        if cols.next().is_some() {
            return Err(line_err(
                path,
                n,
                format!("too many columns; expected {POISSON_COLUMNS}"),
            ));
        }
        if !((0.0..1.0).contains(&x) && (0.0..1.0).contains(&y)) {
            return Err(line_err(
                path,
                n,
                format!("point ({x}, {y}) is outside the unit tile [0, 1)^2"),
            ));
        }
        points.push([x, y]);
    }
    if points.len() < POISSON_MIN_POINTS {
        return Err(line_err(
            path,
            0,
            format!(
                "{} points; a tile needs at least {POISSON_MIN_POINTS}",
                points.len()
            ),
        ));
    }
    // At most about 1.155 / d^2 points fit d apart on the unit torus (hexagonal packing):
    // refuse more before measuring distances, so a huge file cannot stall the loader.
    let packing = 1.2 / (min_distance * min_distance);
    if points.len() as f64 > packing {
        return Err(line_err(
            path,
            0,
            format!(
                "{} points cannot be poisson.min_distance = {min_distance} apart in the unit tile \
                 (at most about {packing:.0})",
                points.len()
            ),
        ));
    }
    if let Some((a, b, d)) = crate::poisson::closer_pair(&points, min_distance) {
        return Err(line_err(
            path,
            0,
            format!(
                "points {} and {} (in rank order) are {d} apart, closer than poisson.min_distance \
                 = {min_distance} in map.toml",
                a + 1,
                b + 1
            ),
        ));
    }
    Ok(crate::poisson::PoissonTile { points })
}

pub fn write_poisson(path: &Path, tile: &crate::poisson::PoissonTile) -> Result<(), MapError> {
    let mut s = format!("{POISSON_MAGIC}\n{POISSON_COLUMNS}\n");
    for p in &tile.points {
        let _ = writeln!(s, "{},{}", p[0], p[1]);
    }
    std::fs::write(path, s).map_err(|e| MapError::io(path, "write", e))
}
