//! Procedural building meshes: a rectangular house of storeys with window
//! and door insets, a gable or hip roof and a chimney, as one closed, outward-facing triangle
//! mesh with facade texture coordinates in metres (split at every wall corner: UV seams) and flat
//! face normals (every crease a normal seam).
//! Deterministic from the spec and its seed. Built in Z-up metres and returned Y-up, the model
//! convention of progressive-mesh objects.
//!
//! Closed by construction, with no T-junction: every wall is a grid over its own opening edges
//! and its middle, and over the opening heights of the whole building, so neighbouring walls
//! share their corner vertices; an opening is a hole in that grid lined by inset sides and a
//! back face over the same breaks; the roof faces and the floor are fans onto the wall-top and
//! wall-bottom vertices (the wall middles keep the hip fans inside their faces). The chimney is
//! a closed box of its own standing through the roof. [`BuildingMesh::volume_m3`] is the exact
//! enclosed volume computed from the dimensions, for tests.

use crate::noise::unit3;
use crate::pm::mesh::Corner;
use glam::DVec3;

/// Roof shape.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Roof {
    /// Two slopes meeting at a ridge along the longer side, vertical gable ends.
    Gable,
    /// Four slopes of equal pitch (a pyramid on a square footprint).
    Hip,
}

impl Roof {
    pub fn name(self) -> &'static str {
        match self {
            Roof::Gable => "gable",
            Roof::Hip => "hip",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        [Roof::Gable, Roof::Hip]
            .into_iter()
            .find(|r| r.name() == name)
    }
}

/// What to build. Sizes in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BuildingSpec {
    pub width_m: f64,
    pub depth_m: f64,
    pub storeys: u32,
    pub storey_m: f64,
    pub roof: Roof,
    pub roof_pitch_deg: f64,
    /// Varies window spacing and size and the chimney's place.
    pub seed: u64,
}

impl BuildingSpec {
    /// Why this spec cannot be built, if it cannot (names the field).
    pub fn check(&self) -> Result<(), String> {
        let in_range = |v: f64, name: &str, lo: f64, hi: f64| {
            if v.is_finite() && v >= lo && v <= hi {
                Ok(())
            } else {
                Err(format!("{name} = {v}: must lie in [{lo}, {hi}]"))
            }
        };
        in_range(self.width_m, "width_m", 3.0, 200.0)?;
        in_range(self.depth_m, "depth_m", 3.0, 200.0)?;
        in_range(self.storey_m, "storey_m", 2.4, 6.0)?;
        in_range(self.roof_pitch_deg, "roof_pitch_deg", 5.0, 60.0)?;
        if !(1..=40).contains(&self.storeys) {
            return Err(format!("storeys = {}: must lie in [1, 40]", self.storeys));
        }
        Ok(())
    }
}

/// The triangles (Y-up, model units = metres) and the exact enclosed volume.
#[derive(Debug, Clone)]
pub struct BuildingMesh {
    pub triangles: Vec<[Corner; 3]>,
    pub volume_m3: f64,
}

/// A rectangular opening in a wall: wall coordinates (along, up) in metres, and inset depth.
#[derive(Debug, Clone, Copy)]
struct Opening {
    s: [f64; 2],
    t: [f64; 2],
    depth_m: f64,
}

/// One wall: from `origin` along `along` for `length_m`, up to the eaves; outward normal
/// `along x Z`.
struct Wall {
    origin: DVec3,
    along: DVec3,
    length_m: f64,
    openings: Vec<Opening>,
}

impl Wall {
    fn at(&self, s: f64, t: f64) -> DVec3 {
        self.origin + self.along * s + DVec3::Z * t
    }

    fn normal(&self) -> DVec3 {
        self.along.cross(DVec3::Z)
    }

    /// Breaks along the wall: its ends, its middle and every opening edge.
    fn s_breaks(&self) -> Vec<f64> {
        let mut s = vec![0.0, self.length_m, self.length_m / 2.0];
        for o in &self.openings {
            s.extend(o.s);
        }
        sorted(s)
    }
}

fn sorted(mut v: Vec<f64>) -> Vec<f64> {
    v.sort_by(f64::total_cmp);
    v.dedup();
    v
}

/// Collects triangles with texture coordinates.
#[derive(Default)]
struct Out {
    tris: Vec<[Corner; 3]>,
}

impl Out {
    /// A triangle, counter-clockwise seen from the front, with its face normal at every
    /// corner: flat faces, so every crease is a seam the progressive mesh keeps.
    fn tri(&mut self, p: [DVec3; 3], uv: [[f64; 2]; 3]) {
        // Z-up to the Y-up model convention: (x, y, z) -> (x, z, -y).
        let y_up = |v: DVec3| [v.x as f32, v.z as f32, -v.y as f32];
        let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
        let c = |k: usize| Corner {
            position: y_up(p[k]),
            uv: Some([uv[k][0] as f32, uv[k][1] as f32]),
            normal: Some(y_up(n)),
        };
        self.tris.push([c(0), c(1), c(2)]);
    }

    /// A planar quad a-b-c-d (counter-clockwise seen from the front).
    fn quad(&mut self, p: [DVec3; 4], uv: [[f64; 2]; 4]) {
        self.tri([p[0], p[1], p[2]], [uv[0], uv[1], uv[2]]);
        self.tri([p[0], p[2], p[3]], [uv[0], uv[2], uv[3]]);
    }
}

/// Windows on every storey of a wall and, on the front wall, a door in the middle of the ground
/// floor (on a 0.15 m step, so no opening touches the wall's bottom edge).
fn openings(spec: &BuildingSpec, wall: usize, length_m: f64) -> Vec<Opening> {
    let r = |k: i64| unit3(spec.seed, wall as i64, k);
    let spacing = 2.4 + 1.2 * r(0);
    let width = 0.9 + 0.5 * r(1);
    let height = (1.1 + 0.4 * r(2)).min(spec.storey_m - 1.2);
    let count = ((length_m - 0.6) / spacing).floor().max(0.0) as usize;
    let mut out = Vec::new();
    if count == 0 {
        return out;
    }
    let margin = (length_m - spacing * count as f64) / 2.0;
    let door_slot = count / 2;
    for storey in 0..spec.storeys {
        let floor = f64::from(storey) * spec.storey_m;
        for k in 0..count {
            let centre = margin + spacing * (k as f64 + 0.5);
            if wall == 0 && storey == 0 && k == door_slot {
                out.push(Opening {
                    s: [centre - 0.55, centre + 0.55],
                    t: [0.15, (2.15_f64).min(spec.storey_m - 0.3)],
                    depth_m: 0.2,
                });
            } else {
                out.push(Opening {
                    s: [centre - width / 2.0, centre + width / 2.0],
                    t: [floor + 0.9, floor + 0.9 + height],
                    depth_m: 0.15,
                });
            }
        }
    }
    out
}

/// Builds the mesh of `spec` (checked with [`BuildingSpec::check`] first).
pub fn building_mesh(spec: &BuildingSpec) -> Result<BuildingMesh, String> {
    spec.check()?;
    // The ridge runs along x: x is the longer side.
    let (w, d) = (
        spec.width_m.max(spec.depth_m),
        spec.width_m.min(spec.depth_m),
    );
    let h = f64::from(spec.storeys) * spec.storey_m;
    let rise = d / 2.0 * spec.roof_pitch_deg.to_radians().tan();
    let corners = [
        DVec3::new(0.0, 0.0, 0.0),
        DVec3::new(w, 0.0, 0.0),
        DVec3::new(w, d, 0.0),
        DVec3::new(0.0, d, 0.0),
    ];
    // South, east, north, west: counter-clockwise seen from above, outward normals.
    let walls: Vec<Wall> = (0..4)
        .map(|k| {
            let (a, b) = (corners[k], corners[(k + 1) % 4]);
            let length_m = if k % 2 == 0 { w } else { d };
            Wall {
                origin: a,
                along: (b - a) / length_m,
                length_m,
                openings: openings(spec, k, length_m),
            }
        })
        .collect();
    let t_breaks = sorted(
        [0.0, h]
            .into_iter()
            .chain(
                walls
                    .iter()
                    .flat_map(|wl| wl.openings.iter().flat_map(|o| o.t)),
            )
            .collect(),
    );
    let mut out = Out::default();
    let mut volume = w * d * h;
    for wall in &walls {
        volume -= wall_with_openings(&mut out, wall, &t_breaks);
    }
    // Floor: a fan from the centre onto every wall-bottom vertex, facing down.
    let bottom: Vec<DVec3> = walls
        .iter()
        .flat_map(|wl| {
            let s = wl.s_breaks();
            s[..s.len() - 1]
                .iter()
                .map(|&x| wl.at(x, 0.0))
                .collect::<Vec<_>>()
        })
        .collect();
    let centre = DVec3::new(w / 2.0, d / 2.0, 0.0);
    for k in 0..bottom.len() {
        let (a, b) = (bottom[k], bottom[(k + 1) % bottom.len()]);
        out.tri(
            [centre, b, a],
            [[centre.x, centre.y], [b.x, b.y], [a.x, a.y]],
        );
    }
    // Roof: ridge ends R0 (west) and R1 (east).
    let top_z = h + rise;
    let inset = match spec.roof {
        Roof::Gable => 0.0,
        Roof::Hip => d / 2.0,
    };
    let r0 = DVec3::new(inset, d / 2.0, top_z);
    let r1 = DVec3::new(w - inset, d / 2.0, top_z);
    for (k, wall) in walls.iter().enumerate() {
        let eave: Vec<DVec3> = wall.s_breaks().iter().map(|&s| wall.at(s, h)).collect();
        let (start, end) = match k {
            0 => (r0, r1),
            1 => (r1, r1),
            2 => (r1, r0),
            _ => (r0, r0),
        };
        roof_face(&mut out, &eave, start, end);
    }
    volume += match spec.roof {
        Roof::Gable => w * d * rise / 2.0,
        Roof::Hip => d * rise * (3.0 * w - d) / 6.0,
    };
    // Chimney: a closed box through the south slope, rising 0.8 m above the ridge.
    let cx = w * (0.25 + 0.5 * unit3(spec.seed, 9, 0));
    let cy = d * 0.3;
    let side = 0.6;
    let lo = DVec3::new(cx - side / 2.0, cy - side / 2.0, h);
    let hi = DVec3::new(cx + side / 2.0, cy + side / 2.0, top_z + 0.8);
    boxed(&mut out, lo, hi);
    volume += side * side * (hi.z - lo.z);
    Ok(BuildingMesh {
        triangles: out.tris,
        volume_m3: volume,
    })
}

/// The wall's grid cells outside its openings, and each opening's inset (sides and back).
/// Returns the volume the insets remove.
fn wall_with_openings(out: &mut Out, wall: &Wall, t_breaks: &[f64]) -> f64 {
    let s_breaks = wall.s_breaks();
    let inside = |s: f64, t: f64| {
        wall.openings
            .iter()
            .any(|o| s > o.s[0] && s < o.s[1] && t > o.t[0] && t < o.t[1])
    };
    let uv = |s: f64, t: f64| [s, t];
    for i in 0..s_breaks.len() - 1 {
        for j in 0..t_breaks.len() - 1 {
            let (s0, s1, t0, t1) = (s_breaks[i], s_breaks[i + 1], t_breaks[j], t_breaks[j + 1]);
            if inside(s0.midpoint(s1), t0.midpoint(t1)) {
                continue;
            }
            out.quad(
                [
                    wall.at(s0, t0),
                    wall.at(s1, t0),
                    wall.at(s1, t1),
                    wall.at(s0, t1),
                ],
                [uv(s0, t0), uv(s1, t0), uv(s1, t1), uv(s0, t1)],
            );
        }
    }
    let mut removed = 0.0;
    for o in &wall.openings {
        let back = wall.normal() * -o.depth_m;
        let q = |s: f64, t: f64| wall.at(s, t) + back;
        let ss: Vec<f64> = s_breaks
            .iter()
            .copied()
            .filter(|&s| s >= o.s[0] && s <= o.s[1])
            .collect();
        let ts: Vec<f64> = t_breaks
            .iter()
            .copied()
            .filter(|&t| t >= o.t[0] && t <= o.t[1])
            .collect();
        let dp = o.depth_m;
        for p in ss.windows(2) {
            let (a, b) = (p[0], p[1]);
            // Sill (faces up) and lintel (faces down).
            let (t0, t1) = (o.t[0], o.t[1]);
            out.quad(
                [wall.at(a, t0), wall.at(b, t0), q(b, t0), q(a, t0)],
                [[a, 0.0], [b, 0.0], [b, dp], [a, dp]],
            );
            out.quad(
                [wall.at(b, t1), wall.at(a, t1), q(a, t1), q(b, t1)],
                [[b, 0.0], [a, 0.0], [a, dp], [b, dp]],
            );
        }
        for p in ts.windows(2) {
            let (a, b) = (p[0], p[1]);
            // Jambs: the left one faces along the wall, the right one back.
            let (s0, s1) = (o.s[0], o.s[1]);
            out.quad(
                [wall.at(s0, b), wall.at(s0, a), q(s0, a), q(s0, b)],
                [[b, 0.0], [a, 0.0], [a, dp], [b, dp]],
            );
            out.quad(
                [wall.at(s1, a), wall.at(s1, b), q(s1, b), q(s1, a)],
                [[a, 0.0], [b, 0.0], [b, dp], [a, dp]],
            );
        }
        for i in 0..ss.len() - 1 {
            for j in 0..ts.len() - 1 {
                let (s0, s1, t0, t1) = (ss[i], ss[i + 1], ts[j], ts[j + 1]);
                out.quad(
                    [q(s0, t0), q(s1, t0), q(s1, t1), q(s0, t1)],
                    [uv(s0, t0), uv(s1, t0), uv(s1, t1), uv(s0, t1)],
                );
            }
        }
        removed += (o.s[1] - o.s[0]) * (o.t[1] - o.t[0]) * o.depth_m;
    }
    removed
}

/// One roof face over a wall's eave vertices `eave` (in the wall's direction): a fan onto
/// `start` for the first half, onto `end` for the second, and the triangle between them at the
/// wall's middle break (none when they coincide: a gable end or a pyramid's face).
fn roof_face(out: &mut Out, eave: &[DVec3], start: DVec3, end: DVec3) {
    let along = (eave[eave.len() - 1] - eave[0]).normalize();
    let up = (start + end) / 2.0 - eave[0];
    let up_dir = (up - along * up.dot(along)).normalize();
    let uv = |p: DVec3| [(p - eave[0]).dot(along), (p - eave[0]).dot(up_dir)];
    let length = (eave[eave.len() - 1] - eave[0]).length();
    let m = (0..eave.len())
        .min_by(|&a, &b| {
            let da = ((eave[a] - eave[0]).length() - length / 2.0).abs();
            let db = ((eave[b] - eave[0]).length() - length / 2.0).abs();
            da.total_cmp(&db)
        })
        .unwrap_or(0);
    for k in 0..eave.len() - 1 {
        let apex = if k < m { start } else { end };
        let p = [eave[k], eave[k + 1], apex];
        out.tri(p, p.map(uv));
    }
    if start != end {
        let p = [eave[m], end, start];
        out.tri(p, p.map(uv));
    }
}

/// A closed axis-aligned box, faces outward.
fn boxed(out: &mut Out, lo: DVec3, hi: DVec3) {
    let v = |x: usize, y: usize, z: usize| {
        DVec3::new(
            if x == 0 { lo.x } else { hi.x },
            if y == 0 { lo.y } else { hi.y },
            if z == 0 { lo.z } else { hi.z },
        )
    };
    let uv = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    // Each face counter-clockwise seen from outside.
    for f in [
        [v(0, 0, 0), v(0, 1, 0), v(1, 1, 0), v(1, 0, 0)],
        [v(0, 0, 1), v(1, 0, 1), v(1, 1, 1), v(0, 1, 1)],
        [v(0, 0, 0), v(1, 0, 0), v(1, 0, 1), v(0, 0, 1)],
        [v(1, 1, 0), v(0, 1, 0), v(0, 1, 1), v(1, 1, 1)],
        [v(0, 1, 0), v(0, 0, 0), v(0, 0, 1), v(0, 1, 1)],
        [v(1, 0, 0), v(1, 1, 0), v(1, 1, 1), v(1, 0, 1)],
    ] {
        out.quad(f, uv);
    }
}
