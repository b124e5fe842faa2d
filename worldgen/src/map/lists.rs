//! List layers: large trees, buildings and the Poisson-disc tile as versioned CSV text, decals as
//! versioned TOML.
//! Numbers are written with Rust's shortest round-trip formatting, so a write/read cycle is exact.

use super::{Manifest, MapError, limits};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::Path;

pub const TREES_MAGIC: &str = "tvs-trees 1";
pub const TREES_COLUMNS: &str = "species,x_m,y_m,height_m,crown_radius_m";
pub const BUILDINGS_MAGIC: &str = "tvs-buildings 1";
pub const BUILDINGS_COLUMNS: &str = "mesh,x_m,y_m,z_m,yaw_deg,scale";
pub const DECALS_FORMAT: &str = "tvs-decals";
/// Version written; version 1 files (roads, paths and rock patches only) are read as well.
pub const DECALS_VERSION: u32 = 2;

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

/// A building placement (a progressive mesh by name).
#[derive(Debug, Clone, PartialEq)]
pub struct Building {
    pub mesh: String,
    pub x_m: f64,
    pub y_m: f64,
    pub z_m: f64,
    pub yaw_deg: f32,
    pub scale: f32,
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
}

impl DecalKind {
    pub fn name(self) -> &'static str {
        match self {
            Self::Road => "road",
            Self::Path => "path",
            Self::RockPatch => "rock_patch",
            Self::Field => "field",
            Self::Dirt => "dirt",
        }
    }

    /// Whether this kind is a closed area (a polygon) rather than a polyline.
    pub fn is_area(self) -> bool {
        matches!(self, Self::RockPatch | Self::Field | Self::Dirt)
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
    std::fs::read_to_string(path)
        .map_err(|e| MapError::io(path, "read list file (listed in map.toml)", e))
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
        if usize::from(t.species) >= m.tree_species.len() {
            return Err(line_err(
                path,
                n,
                format!(
                    "species {} is not in map.toml `tree_species` ({} names)",
                    t.species,
                    m.tree_species.len()
                ),
            ));
        }
        if !in_world(m, t.x_m, t.y_m) {
            return Err(line_err(
                path,
                n,
                format!("position ({}, {}) is outside the world", t.x_m, t.y_m),
            ));
        }
        if !(t.height_m > 0.0
            && t.height_m <= 200.0
            && t.crown_radius_m > 0.0
            && t.crown_radius_m <= 50.0)
        {
            return Err(line_err(
                path,
                n,
                format!(
                    "height {} m / crown radius {} m out of range (0, 200] / (0, 50]",
                    t.height_m, t.crown_radius_m
                ),
            ));
        }
        trees.push(t);
    }
    Ok(trees)
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
    let rows = data_rows(path, &text, BUILDINGS_MAGIC, BUILDINGS_COLUMNS)?;
    let mut out = Vec::with_capacity(rows.len());
    for (n, row) in rows {
        let mut cols = row.split(',');
        let mesh: String = parse_field(path, n, "mesh", cols.next())?;
        let b = Building {
            mesh,
            x_m: parse_field(path, n, "x_m", cols.next())?,
            y_m: parse_field(path, n, "y_m", cols.next())?,
            z_m: parse_field(path, n, "z_m", cols.next())?,
            yaw_deg: parse_field(path, n, "yaw_deg", cols.next())?,
            scale: parse_field(path, n, "scale", cols.next())?,
        };
        if cols.next().is_some() {
            return Err(line_err(
                path,
                n,
                format!("too many columns; expected {BUILDINGS_COLUMNS}"),
            ));
        }
        if b.mesh.is_empty() || !in_world(m, b.x_m, b.y_m) || !b.z_m.is_finite() {
            return Err(line_err(
                path,
                n,
                "empty mesh name or position outside the world",
            ));
        }
        if !(b.yaw_deg.is_finite() && b.scale.is_finite() && b.scale > 0.0 && b.scale <= 1000.0) {
            return Err(line_err(
                path,
                n,
                format!("yaw {} / scale {} out of range", b.yaw_deg, b.scale),
            ));
        }
        out.push(b);
    }
    Ok(out)
}

pub fn write_buildings(path: &Path, buildings: &[Building]) -> Result<(), MapError> {
    let mut s = format!("{BUILDINGS_MAGIC}\n{BUILDINGS_COLUMNS}\n");
    for b in buildings {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{}",
            b.mesh, b.x_m, b.y_m, b.z_m, b.yaw_deg, b.scale
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
    let v1 = version == Some(1);
    let file: DecalFile = toml::from_str(&text).map_err(|e| MapError::ManifestSyntax {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    if file.decal.len() > limits::MAX_LIST_ITEMS {
        return Err(MapError::field(path, "decal", "too many decals"));
    }
    for (i, d) in file.decal.iter().enumerate() {
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
    Ok(file.decal)
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
