//! Procedural plant meshes, generated deterministically at start-up: unit-sized shapes (height 1,
//! crown radius 1) that instances scale, rotate and place. CPU only: plain vertex/index arrays.
//!
//! Shapes: a conifer (six-sided trunk, two stacked cones), a broadleaf tree (trunk and a
//! squashed sphere crown), a bush (a sphere touching the ground) and a grass clump (five
//! crossed, tapered blades). Each has a high- and a low-detail variant (segment counts). The
//! high variant's rings are inscribed in the round shape; the low variant's are pushed out so
//! that its outline lies as far outside the round shape at its corners as inside between them
//! (a regular n-gon of circumradius `2 r / (1 + cos(pi / n))`), so switching between the two,
//! and between the low mesh and a billboard baked from the high one, moves the silhouette
//! least.

/// How far from its axis a unit shape reaches (the low variant's corners; the high variant
/// stays within 1).
pub const REACH: f64 = 1.2;

/// The shape an item's species is drawn with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Shape {
    Conifer = 0,
    Broadleaf = 1,
    Bush = 2,
    Grass = 3,
}

/// One vertex: unit-shape position, normal, part (0 trunk, 1 foliage).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlantVertex {
    pub position: [f32; 3],
    pub normal: [f32; 3],
    pub part: u32,
}

/// All shapes in one vertex/index array; `ranges[shape][detail]` = (first index, index count,
/// base vertex), detail 0 high, 1 low.
#[derive(Debug, Clone, Default)]
pub struct PlantMeshes {
    pub vertices: Vec<PlantVertex>,
    pub indices: Vec<u32>,
    pub ranges: [[(u32, u32, i32); 2]; 4],
}

#[derive(Default)]
struct Builder {
    v: Vec<PlantVertex>,
    i: Vec<u32>,
    /// Push rings out to balance their polygon against the round shape (the low variant).
    balanced: bool,
}

/// The circumradius of a regular `n`-gon whose outline lies as far outside a unit circle (at
/// its corners) as inside it (at its edges' middles).
fn balanced_radius(n: u32) -> f32 {
    2.0 / (1.0 + (std::f32::consts::PI / n as f32).cos())
}

impl Builder {
    fn vertex(&mut self, p: [f32; 3], n: [f32; 3], part: u32) -> u32 {
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt().max(1e-6);
        self.v.push(PlantVertex {
            position: p,
            normal: [n[0] / len, n[1] / len, n[2] / len],
            part,
        });
        (self.v.len() - 1) as u32
    }

    /// A ring-to-ring band (cylinder or cone part) of `seg` segments.
    #[allow(clippy::too_many_arguments, reason = "two rings and their shading")]
    fn band(&mut self, seg: u32, z0: f32, r0: f32, z1: f32, r1: f32, part: u32) {
        let slope = (r0 - r1) / (z1 - z0).max(1e-6);
        let grow = if self.balanced {
            balanced_radius(seg)
        } else {
            1.0
        };
        let (r0, r1) = (r0 * grow, r1 * grow);
        let base = self.v.len() as u32;
        for k in 0..=seg {
            let a = std::f32::consts::TAU * k as f32 / seg as f32;
            let (s, c) = a.sin_cos();
            let n = [c, s, slope];
            self.vertex([r0 * c, r0 * s, z0], n, part);
            self.vertex([r1 * c, r1 * s, z1], n, part);
        }
        for k in 0..seg {
            let a = base + 2 * k;
            self.i
                .extend_from_slice(&[a, a + 2, a + 1, a + 1, a + 2, a + 3]);
        }
    }

    /// An ellipsoid centred at (0, 0, zc) with radii (r, r, rz).
    fn ellipsoid(&mut self, seg: u32, rings: u32, zc: f32, r: f32, rz: f32, part: u32) {
        // Seen from the side the rings' outline is a 2 * rings-gon in the profile (pushed out
        // sideways only, so the poles stay at the shape's top and bottom).
        let grow = if self.balanced {
            balanced_radius(seg) * balanced_radius(2 * rings)
        } else {
            1.0
        };
        let base = self.v.len() as u32;
        for j in 0..=rings {
            let t = std::f32::consts::PI * j as f32 / rings as f32;
            let (st, ct) = t.sin_cos();
            for k in 0..=seg {
                let a = std::f32::consts::TAU * k as f32 / seg as f32;
                let (s, c) = a.sin_cos();
                let p = [grow * r * st * c, grow * r * st * s, zc - rz * ct];
                let n = [st * c / r, st * s / r, -ct / rz];
                self.vertex(p, n, part);
            }
        }
        let w = seg + 1;
        for j in 0..rings {
            for k in 0..seg {
                let a = base + j * w + k;
                self.i
                    .extend_from_slice(&[a, a + 1, a + w, a + 1, a + w + 1, a + w]);
            }
        }
    }

    /// A tapered blade (two-sided quad narrowing to a tip) leaning out along angle `a`.
    fn blade(&mut self, a: f32, width: f32, lean: f32) {
        let (s, c) = a.sin_cos();
        let side = [-s * width, c * width];
        let n = [c, s, 0.3];
        let b0 = self.vertex([side[0], side[1], 0.0], n, 1);
        let b1 = self.vertex([-side[0], -side[1], 0.0], n, 1);
        let tip = self.vertex([c * lean, s * lean, 1.0], n, 1);
        self.i.extend_from_slice(&[b0, b1, tip, b1, b0, tip]);
    }
}

fn shape(shape: Shape, low: bool) -> Builder {
    let mut b = Builder {
        balanced: low,
        ..Builder::default()
    };
    let seg = if low { 5 } else { 10 };
    match shape {
        Shape::Conifer => {
            b.band(if low { 3 } else { 6 }, 0.0, 0.07, 0.3, 0.05, 0);
            b.band(seg, 0.18, 1.0, 0.7, 0.25, 1);
            b.band(seg, 0.5, 0.7, 1.0, 0.0, 1);
        }
        Shape::Broadleaf => {
            b.band(if low { 3 } else { 6 }, 0.0, 0.08, 0.45, 0.06, 0);
            b.ellipsoid(seg, if low { 3 } else { 6 }, 0.62, 1.0, 0.38, 1);
        }
        Shape::Bush => {
            b.ellipsoid(seg, if low { 3 } else { 5 }, 0.5, 1.0, 0.5, 1);
        }
        Shape::Grass => {
            let blades = if low { 3 } else { 5 };
            for k in 0..blades {
                let a = std::f32::consts::TAU * (k as f32 + 0.3) / blades as f32;
                b.blade(a, 0.18, 0.45);
            }
        }
    }
    b
}

impl PlantMeshes {
    pub fn generate() -> Self {
        let mut m = Self::default();
        for s in [Shape::Conifer, Shape::Broadleaf, Shape::Bush, Shape::Grass] {
            for (d, low) in [false, true].into_iter().enumerate() {
                let b = shape(s, low);
                m.ranges[s as usize][d] = (
                    m.indices.len() as u32,
                    b.i.len() as u32,
                    m.vertices.len() as i32,
                );
                m.vertices.extend(b.v);
                m.indices.extend(b.i);
            }
        }
        m
    }

    /// Triangles of a shape at a detail (0 high, 1 low).
    pub fn triangles(&self, shape: Shape, detail: usize) -> u32 {
        self.ranges[shape as usize][detail].1 / 3
    }
}

/// The shape and foliage colour (sRGB) of a species by name.
pub fn look(name: &str) -> (Shape, [u8; 3]) {
    match name {
        "pine" => (Shape::Conifer, [46, 84, 48]),
        "spruce" => (Shape::Conifer, [34, 70, 52]),
        "birch" => (Shape::Broadleaf, [112, 150, 62]),
        "oak" => (Shape::Broadleaf, [70, 112, 44]),
        "small_tree" => (Shape::Broadleaf, [92, 136, 58]),
        "grass_clump" => (Shape::Grass, [110, 150, 64]),
        _ => (Shape::Bush, [74, 110, 50]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn balanced_rings_straddle_the_circle() {
        for n in [3u32, 5, 6, 10] {
            let r = balanced_radius(n);
            let inner = r * (std::f32::consts::PI / n as f32).cos();
            assert!(((r - 1.0) - (1.0 - inner)).abs() < 1e-6, "{n}: {r} {inner}");
        }
    }

    #[test]
    fn shapes_are_unit_sized_and_deterministic() {
        let a = PlantMeshes::generate();
        let b = PlantMeshes::generate();
        assert_eq!(a.vertices, b.vertices);
        assert_eq!(a.indices, b.indices);
        for s in [Shape::Conifer, Shape::Broadleaf, Shape::Bush, Shape::Grass] {
            assert!(a.triangles(s, 0) > 0 && a.triangles(s, 1) < a.triangles(s, 0));
            for (detail, reach) in [(0, 1.0), (1, REACH as f32)] {
                let (first, count, base) = a.ranges[s as usize][detail];
                for &i in &a.indices[first as usize..(first + count) as usize] {
                    let p = a.vertices[(base + i as i32) as usize].position;
                    assert!(p[2] >= -1e-6 && p[2] <= 1.0 + 1e-6, "{s:?} z {}", p[2]);
                    assert!(p[0].hypot(p[1]) <= reach + 1e-5, "{s:?} {detail} radius");
                }
            }
        }
    }
}
