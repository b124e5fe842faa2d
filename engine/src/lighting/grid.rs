//! One light grid: sky and sun visibility on [`COLUMNS`] x [`COLUMNS`] columns over a node: the
//! nodes of [`grid_level`] (side [`GRID_SIDE_M`], columns [`COLUMN_SPACING_M`] apart) and every
//! coarser node (the same columns over its larger side), so distant terrain is shaded too.
//!
//! **Sky visibility** of a horizontal receiver is `(1/pi) * integral of T(w) sin(e) cos(e)` over
//! the directions `w` above the terrain horizon (elevation `e`, canopy transmittance `T`).
//! With `s = sin^2 e` the weight is uniform in `s`, so per azimuth the visible part is the
//! integral of `T` over `s` from `sin^2` of the horizon elevation to 1, and open flat ground
//! gives exactly 1. The grid takes [`HORIZON_AZIMUTHS`] azimuths for the horizon and
//! [`CANOPY_AZIMUTHS`] x [`SKY_BANDS`] (equal bands of `s`) rays through the canopy.
//!
//! **Horizons** are marched on the finest surface near the column (a lattice of `F` at
//! [`NEAR_SPACING_M`] over a block of columns widened by [`NEAR_MARGIN_M`], bilinear between
//! its points, read up to one spacing less than the margin from the column) and on the map
//! heights beyond (bilinear), out to [`HORIZON_REACH_M`], with steps that grow with the
//! distance. None of this depends on the grid's level: a column of a coarse grid holds the same
//! bytes as the finer grids' column at the same place (every other column of a grid is a column
//! of its parent's grid), which is what lets a node blend seamlessly toward a coarser
//! neighbour's grid (`render::light_pool`). **Canopy transmittance** is `exp(-optical depth)` of
//! [`Canopy::extinction_per_m`] summed at midpoints along the ray until it leaves the canopy.
//! **Ground bounce** ([`LightGrid::bounce_at`]): in the same horizon march, each band of
//! elevations where the terrain rises above the running horizon is weighted (in `sin^2` of the
//! elevation, as the sky) by `max(0, n . s)` of the terrain seen there: its slope along the ray
//! from the previous march point (a cliff between two points is seen as its face), across the
//! ray from central differences. The terrain is taken as lit wherever it faces the sun (the
//! shadows cast on it are left out). It is marched at columns [`BOUNCE_STRIDE`] grid-level
//! spacings apart (every column of a coarser grid) and interpolated bilinearly between them:
//! light reflected by the terrain a column sees changes little over 8 m, and agrees with the
//! reference as well.
//!
//! **Sun visibility** is the share of the sun's disc above the terrain horizon along its own
//! azimuth ([`terrain_lit`]) times the canopy transmittance toward it. A sample stores the two
//! factors apart, the first as the sun's elevation over the horizon ([`margin_to_byte`]): both
//! are interpolated first and multiplied after, so a terrain shadow's edge falls where the
//! interpolated horizon crosses the sun instead of being smeared over a column spacing.
//!
//! **Cost.** The canopy's rays are most of a grid's time where vegetation grows: each layer of a
//! column sends [`CANOPY_AZIMUTHS`] x [`SKY_BANDS`] sky rays and one sun ray through it. A ray
//! point near the column reads its ground and the canopy's extinction from one cell of the
//! height lattice (the canopy's summed layers sampled at the lattice's points,
//! [`Canopy::band_lattice`]: exact, as the lattice nests in the canopy's cells), rays and columns
//! with no vegetation within their reach are skipped ([`Canopy::any_in`]), and a relight after a
//! sun change keeps the sky, which no sun changes ([`LightGrid::relit`]).
//!
//! Values are stored as bytes (1/255 steps); the tests compare them with a ray-marched
//! reference on the finest surface (tests/tests/e2e/lighting.rs).

use crate::surface::World;
use crate::terrain::quadtree::{NodeKey, QuadTree};
use crate::vegetation::canopy::{BandLattice, Canopy};
use glam::DVec3;
use worldgen::sample::{GridPlacement, bilinear};

/// Side of a light grid's node (m).
pub const GRID_SIDE_M: f64 = 128.0;
/// Distance between columns of a grid-level node (m); a coarser node's columns are as much
/// farther apart as the node is wider.
pub const COLUMN_SPACING_M: f64 = 4.0;
/// Columns along each side (the border columns included).
pub const COLUMNS: usize = (GRID_SIDE_M / COLUMN_SPACING_M) as usize + 1;
/// Height of the ground layer above the finest surface (m): a hand above it, so the surface's own
/// sampling does not shadow the sample.
pub const GROUND_LAYER_M: f64 = 0.25;
/// Layers of a grid.
pub const LAYERS: usize = 8;

/// The layer heights above the finest surface (m) under `canopy`: the ground layer, the top of
/// every canopy layer (the light changes fastest with height just there: above a species' top
/// its crowns no longer shade), and midpoints of the widest gaps until there are [`LAYERS`];
/// at least up to 4 m, so maps without vegetation still have layers above the ground.
pub fn layer_heights_m(canopy: &Canopy) -> [f64; LAYERS] {
    let top = canopy.top_m.max(4.0);
    let mut h = vec![GROUND_LAYER_M, top];
    for t in canopy.layer_tops_m() {
        if t > GROUND_LAYER_M + 0.1 && t < top - 0.1 && h.len() < LAYERS {
            h.push(t);
        }
    }
    h.sort_by(f64::total_cmp);
    while h.len() < LAYERS {
        let widest = (0..h.len() - 1)
            .max_by(|&a, &b| (h[a + 1] - h[a]).total_cmp(&(h[b + 1] - h[b])))
            .unwrap_or(0);
        h.insert(widest + 1, 0.5 * (h[widest] + h[widest + 1]));
    }
    std::array::from_fn(|i| h[i])
}

/// Azimuths of the terrain horizon.
pub const HORIZON_AZIMUTHS: usize = 16;
/// Azimuths of the canopy rays (each serves the horizon azimuths nearest to it).
pub const CANOPY_AZIMUTHS: usize = 8;
/// Equal bands of `sin^2(elevation)` of the canopy rays.
pub const SKY_BANDS: usize = 3;
/// How far horizons are marched (m).
pub const HORIZON_REACH_M: f64 = 4000.0;
/// Spacing of the finest-surface lattice near a column (m; half a grid-level column spacing,
/// the same at every level).
pub const NEAR_SPACING_M: f64 = 2.0;
/// How far beyond its block of columns that lattice reaches (m, at every level).
pub const NEAR_MARGIN_M: f64 = 64.0;
/// Midpoint samples of a sky ray through the canopy.
pub const CANOPY_STEPS: usize = 12;
/// Midpoint samples of the sun ray through the canopy (one a sample, often long and low; it is
/// followed for twice its flat-ground length, over ground that rises toward the sun).
pub const SUN_CANOPY_STEPS: usize = 48;

/// The sun: where it stands, as a compass azimuth (degrees clockwise from north) and an
/// elevation above the horizontal (degrees).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sun {
    pub azimuth_deg: f64,
    pub elevation_deg: f64,
}

impl Default for Sun {
    /// The viewer's sun since its first version: north-east (56 degrees), 49 degrees high.
    fn default() -> Self {
        Self {
            azimuth_deg: 56.0,
            elevation_deg: 49.0,
        }
    }
}

impl Sun {
    /// Unit vector toward the sun (x east, y north, z up).
    pub fn toward(&self) -> DVec3 {
        let (a, e) = (
            self.azimuth_deg.to_radians(),
            self.elevation_deg.to_radians(),
        );
        DVec3::new(a.sin() * e.cos(), a.cos() * e.cos(), e.sin())
    }
}

/// A node's light grid (see the module docs). Sample `(layer, row, col)` is at world
/// `origin_m + (col, row) * spacing_m`, `layers_m[layer]` above `ground_m`.
#[derive(Debug, Clone, PartialEq)]
pub struct LightGrid {
    pub key: NodeKey,
    /// World position of column (0, 0), the node's south-west corner.
    pub origin_m: [f64; 2],
    /// Distance between columns (m): [`COLUMN_SPACING_M`] at [`grid_level`], twice that a level
    /// coarser.
    pub spacing_m: f64,
    /// The finest surface at each column (row-major, row 0 south).
    pub ground_m: Vec<f32>,
    /// Sky visibility in 1/255 steps, `[layer][row][col]`.
    pub sky: Vec<u8>,
    /// The canopy's transmittance toward the sun in 1/255 steps, `[layer][row][col]` (0 with
    /// the sun below the horizontal).
    pub sun: Vec<u8>,
    /// The sun's elevation over the terrain horizon toward it ([`margin_to_byte`]),
    /// `[layer][row][col]`: interpolated, then turned into the terrain's shadow
    /// ([`terrain_lit`]), it places a shadow's edge between columns where the horizon crosses
    /// the sun, not halfway.
    pub sun_margin: Vec<u8>,
    /// The ground's bounce in 1/255 steps, `[layer][row][col]`: the irradiance of a
    /// horizontal receiver from the terrain that hides its sky, per unit sun irradiance and
    /// unit albedo of that terrain ([`LightGrid::bounce_at`]).
    pub bounce: Vec<u8>,
    /// The sun the grid was lit for.
    pub sun_dir: Sun,
    /// Heights of the layers above the ground (m), [`layer_heights_m`] of the canopy.
    pub layers_m: [f64; LAYERS],
}

/// The terrain heights a grid's horizons are marched on: the finest-surface lattice within
/// `near_reach_m` of the column a ray starts from, the map heights beyond. The lattice's points
/// lie on one global lattice (multiples of [`NEAR_SPACING_M`] from the tree's origin), and
/// positions are turned into lattice coordinates from that origin, so neighbouring grids read
/// the same numbers for the same position; which of the two surfaces a ray point reads depends
/// only on its distance from the column (never on the node's window), so a column two grids
/// share gets the same bytes in both.
struct HorizonHeights<'a> {
    world: &'a World,
    /// The lattice ([`NEAR_SPACING_M`] apart), row-major, row 0 south.
    near: Vec<f64>,
    /// Points along x and along y.
    n: [usize; 2],
    /// Global lattice index of `near`'s point (0, 0).
    first: [i64; 2],
    tree_origin_m: [f64; 2],
    map_at: GridPlacement,
    /// Ray points up to this far (horizontally) from their column read the lattice: inside the
    /// window of the block the column belongs to (its margin less one spacing).
    near_reach_m: f64,
    /// The canopy's extinction per height band at the lattice's points, where the lattice
    /// nests in the canopy's grid ([`Canopy::band_lattice`]): a canopy ray's point within the
    /// lattice reads its ground and its extinction from the same cell.
    extinction: Option<BandLattice>,
}

impl<'a> HorizonHeights<'a> {
    /// `max(0, n . toward)` for the terrain a ray along horizontal unit `dir` sees between
    /// its points `r0_m` and `r_m` from the column, heights `dh0_m` and `dh_m` over the column's
    /// ground, the second at (`x_m`, `y_m`): the normal's slope along the ray is the profile's
    /// between the two points (a cliff between them is seen as its face, not as the ground
    /// above it), across the ray the surface's at the second point (central differences over
    /// 2 % of the distance, at least a quarter of the lattice's spacing).
    fn facing_sun(
        &self,
        (x_m, y_m): (f64, f64),
        dir: [f64; 2],
        (r0_m, dh0_m): (f64, f64),
        (r_m, dh_m): (f64, f64),
        toward: DVec3,
    ) -> f64 {
        let e = (0.02 * r_m).max(0.25 * NEAR_SPACING_M);
        // The points are up to `r + e` from the column: read them as such (the lattice only
        // within its reach), so every grid holding the column reads the same heights.
        let (cx, cy) = (-dir[1] * e, dir[0] * e);
        let across = (self.height_m(x_m + cx, y_m + cy, r_m + e)
            - self.height_m(x_m - cx, y_m - cy, r_m + e))
            / (2.0 * e);
        let along = (dh_m - dh0_m) / (r_m - r0_m);
        let gradient = [
            along * dir[0] - across * dir[1],
            along * dir[1] + across * dir[0],
        ];
        DVec3::new(-gradient[0], -gradient[1], 1.0)
            .normalize()
            .dot(toward)
            .max(0.0)
    }

    /// Marches the horizons of the column at (`x`, `y`), ground `ground_m`, along `dirs` (the
    /// horizon azimuths, then the sun's; the sun's alone for [`March::Sun`]) at `distances`
    /// (and their inverses): per direction and layer the highest tangent of the terrain into
    /// `tan_max`. Returns per layer (zero unless [`March::All`]) the ground's bounce summed over
    /// the horizon azimuths: the cosine-weighted share of the sky hidden by terrain, each hidden
    /// band weighted by how squarely the terrain seen there faces the sun.
    ///
    /// Two shortcuts leave every result bit the same: a ray point is compared with the layers
    /// only when the lowest layer's tangent there (the largest: `layers_m` ascend) passes the
    /// smallest best so far, and beyond the lattice's reach whole stretches of
    /// [`FAR_STRETCH`] points are skipped when the highest map sample around them
    /// ([`HorizonHeights::far_max_m`]) could not pass it either.
    fn march_column(
        &self,
        (x, y, ground): (f64, f64, f64),
        (dirs, distances, inverse): (&[[f64; 2]], &[f64], &[f64]),
        (layers_m, what): (&[f64; LAYERS], March),
        toward: DVec3,
        tan_max: &mut [[f64; LAYERS]],
    ) -> [f64; LAYERS] {
        let mut bounce = [0.0f64; LAYERS];
        let first_far = distances.partition_point(|&r| r <= self.near_reach_m);
        for (d, (best, dir)) in tan_max.iter_mut().zip(dirs).enumerate() {
            let is_azimuth = d < HORIZON_AZIMUTHS;
            if is_azimuth && what == March::Sun {
                continue;
            }
            let with_bounce = is_azimuth && what == March::All;
            // Horizons below a floor give the same bytes: a horizon azimuth's tangent counts
            // only above the horizontal (`sin2_of_tan`, and the bounce of terrain above it),
            // the sun's only within the stored margin ([`SUN_MARGIN_RANGE_RAD`], clamped).
            let low = if is_azimuth {
                0.0
            } else {
                sun_horizon_floor(toward)
            };
            *best = [low; LAYERS];
            // The smallest of `best`: no point whose lowest-layer tangent is at or under it
            // raises any layer.
            let mut floor = low;
            let at = |r: f64| (x + dir[0] * r, y + dir[1] * r);
            // The previous ray point (distance, height over the ground), or the index of a
            // skipped one whose height is read only if needed.
            let mut previous = Previous::At(0.0, 0.0);
            let mut k = 0;
            while k < distances.len() {
                if k >= first_far && (k - first_far).is_multiple_of(FAR_STRETCH) {
                    let end = (k + FAR_STRETCH).min(distances.len());
                    let top = self.far_max_m(at(distances[k]), at(distances[end - 1]));
                    let rise = (top - ground) - layers_m[0];
                    // The largest tangent any point of the stretch could have.
                    let t = rise
                        * if rise >= 0.0 {
                            inverse[k]
                        } else {
                            inverse[end - 1]
                        };
                    if t <= floor {
                        previous = Previous::Skipped(end - 1);
                        k = end;
                        continue;
                    }
                }
                let (r, inv_r) = (distances[k], inverse[k]);
                let (px, py) = at(r);
                let dh = self.height_m(px, py, r) - ground;
                if (dh - layers_m[0]) * inv_r > floor {
                    // Computed when some layer first sees terrain this high.
                    let mut facing = None;
                    for ((b, lh), add) in best.iter_mut().zip(layers_m).zip(&mut bounce) {
                        let t = (dh - lh) * inv_r;
                        if t > *b {
                            if with_bounce && t > 0.0 && toward.z > 0.0 {
                                let f = *facing.get_or_insert_with(|| {
                                    let before = match previous {
                                        Previous::At(r0, dh0) => (r0, dh0),
                                        Previous::Skipped(i) => {
                                            let (qx, qy) = at(distances[i]);
                                            (
                                                distances[i],
                                                self.height_m(qx, qy, distances[i]) - ground,
                                            )
                                        }
                                    };
                                    self.facing_sun((px, py), *dir, before, (r, dh), toward)
                                });
                                *add += f * (sin2_of_tan(t) - sin2_of_tan(*b));
                            }
                            *b = t;
                        }
                    }
                    floor = best.iter().copied().fold(f64::INFINITY, f64::min);
                }
                previous = Previous::At(r, dh);
                k += 1;
            }
        }
        bounce
    }

    /// An upper bound of the heights this reads beyond the lattice's reach (bilinear on the map)
    /// anywhere on the segment from `a` to `b`: the highest map sample in the cells around it
    /// (one cell more on each side), plus a margin for the rounding of the interpolation.
    fn far_max_m(&self, a: (f64, f64), b: (f64, f64)) -> f64 {
        // As `bilinear` places a point: clamped into the grid, then the sample below.
        let heights = &self.world.map.heights;
        let last = [heights.width() - 1, heights.height() - 1];
        let cell = |v: f64, axis: usize| {
            ((v - self.map_at.origin_m[axis]) / self.map_at.spacing_m)
                .clamp(0.0, last[axis] as f64)
                .floor() as i64
        };
        let (xa, xb) = (cell(a.0, 0), cell(b.0, 0));
        let (ya, yb) = (cell(a.1, 1), cell(b.1, 1));
        let top = f64::from(self.world.heights_max.max_in(
            [xa.min(xb) - 1, xa.max(xb) + 2],
            [ya.min(yb) - 1, ya.max(yb) + 2],
        ));
        top + 1e-9 * (1.0 + top.abs())
    }

    /// The lattice of `n` points from global index `first` (from `tree_origin_m`), read within
    /// one spacing less than [`NEAR_MARGIN_M`] of a column.
    fn new(
        (world, canopy): (&'a World, &Canopy),
        tree_origin_m: [f64; 2],
        first: [i64; 2],
        n: [usize; 2],
    ) -> Self {
        let axis = |a: usize| -> Vec<f64> {
            (0..n[a] as i64)
                .map(|i| tree_origin_m[a] + (first[a] + i) as f64 * NEAR_SPACING_M)
                .collect()
        };
        let (xs, ys) = (axis(0), axis(1));
        let extinction = if canopy.lattice_nests(tree_origin_m, NEAR_SPACING_M) {
            canopy.band_lattice(&xs, &ys)
        } else {
            None
        };
        Self {
            world,
            extinction,
            near: world.heights_on_lattice(&xs, &ys),
            n,
            first,
            tree_origin_m,
            map_at: GridPlacement {
                origin_m: world.origin_m(),
                spacing_m: world.map.manifest.heights.spacing_m,
            },
            near_reach_m: NEAR_MARGIN_M - NEAR_SPACING_M,
        }
    }

    /// The lattice cell holding world (`x_m`, `y_m`), when inside the lattice: the index of its
    /// south-west point and the fractions past it along x and y.
    fn cell(&self, x_m: f64, y_m: f64) -> Option<(usize, f64, f64)> {
        let gx = (x_m - self.tree_origin_m[0]) / NEAR_SPACING_M;
        let gy = (y_m - self.tree_origin_m[1]) / NEAR_SPACING_M;
        let (fx, fy) = (gx.floor(), gy.floor());
        let (i, j) = (fx as i64 - self.first[0], fy as i64 - self.first[1]);
        ((0..self.n[0] as i64 - 1).contains(&i) && (0..self.n[1] as i64 - 1).contains(&j))
            .then(|| (j as usize * self.n[0] + i as usize, gx - fx, gy - fy))
    }

    /// Bilinear interpolation of lattice values `v` in cell `(k, tx, ty)` ([`Self::cell`]).
    fn blend(&self, v: &[f64], (k, tx, ty): (usize, f64, f64)) -> f64 {
        let nx = self.n[0];
        let lo = v[k] + (v[k + 1] - v[k]) * tx;
        let hi = v[k + nx] + (v[k + nx + 1] - v[k + nx]) * tx;
        lo + (hi - lo) * ty
    }

    /// The height at a ray point `r_m` (horizontally) from its column.
    fn height_m(&self, x_m: f64, y_m: f64, r_m: f64) -> f64 {
        match self.cell(x_m, y_m).filter(|_| r_m <= self.near_reach_m) {
            Some(cell) => self.blend(&self.near, cell),
            None => bilinear(&self.world.map.heights, self.map_at, x_m, y_m),
        }
    }

    /// The canopy's extinction (1/m) at ray point `p`, `r_m` (horizontally) from its column:
    /// [`Canopy::extinction_per_m`] at its height over [`Self::height_m`], the two read from
    /// one lattice cell where the point lies within the lattice's reach.
    fn extinction_per_m(&self, canopy: &Canopy, p: DVec3, r_m: f64) -> f64 {
        let near = self
            .extinction
            .as_ref()
            .filter(|_| r_m <= self.near_reach_m);
        if let Some((ext, cell)) = near.and_then(|e| Some((e, self.cell(p.x, p.y)?))) {
            let above = p.z - self.blend(&self.near, cell);
            if !(0.0..=canopy.top_m).contains(&above) {
                return 0.0;
            }
            let band = ext.tops_m.partition_point(|&t| t < above);
            return ext.values.get(band).map_or(0.0, |v| self.blend(v, cell));
        }
        let above = p.z - self.height_m(p.x, p.y, r_m);
        canopy.extinction_per_m(p.x, p.y, above)
    }

    /// The lattice point at global index (`i`, `j`) (inside the window).
    fn point_m(&self, i: i64, j: i64) -> f64 {
        let (a, b) = ((i - self.first[0]) as usize, (j - self.first[1]) as usize);
        self.near[b * self.n[0] + a]
    }
}

/// What a column's horizon march finds.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum March {
    /// Every horizon and the ground's bounce.
    All,
    /// Every horizon, no bounce.
    Horizons,
    /// The horizon toward the sun alone.
    Sun,
}

/// The ground's bounce is marched at the columns whose global index (in grid-level column
/// spacings) is a multiple of this along both axes (8 m apart) and interpolated bilinearly
/// between them: light reflected by the terrain a column sees changes slowly with the column's
/// place, and agrees with the reference as well (at 16 m apart, 3 % of the benchmark's points
/// moved farther than 0.02 from it). Summing it over every other azimuth instead of all 16 kept
/// the default map's agreement but not the cliff map's (90 % of points within 0.05 instead of
/// 99 %).
pub const BOUNCE_STRIDE: i64 = 2;

/// Points of a horizon march beyond the lattice's reach that are skipped together when the map
/// around them cannot rise above the horizon found so far.
const FAR_STRETCH: usize = 4;

/// The ray point before the current one in a horizon march.
#[derive(Clone, Copy)]
enum Previous {
    /// Its distance and its height over the column's ground.
    At(f64, f64),
    /// Skipped: its index in the march's distances (its height is read when needed).
    Skipped(usize),
}

/// The tangent of a horizon toward the sun (unit `toward`) under which the stored sun margin
/// is the same, the largest ([`margin_to_byte`] clamps margins over [`SUN_MARGIN_RANGE_RAD`]);
/// a hundredth of a radian lower, so rounding never brings the margin back under the range.
fn sun_horizon_floor(toward: DVec3) -> f64 {
    let elevation = toward.z.clamp(-1.0, 1.0).asin();
    let floor = elevation - SUN_MARGIN_RANGE_RAD - 0.01;
    if floor > -0.5 * std::f64::consts::PI + 0.01 {
        floor.tan()
    } else {
        f64::NEG_INFINITY
    }
}

/// The horizontal unit directions of a grid's horizon marches: the [`HORIZON_AZIMUTHS`]
/// azimuths from north, then toward the sun (unit `toward`; north when it stands at the zenith).
fn march_directions(toward: DVec3) -> Vec<[f64; 2]> {
    let mut dirs: Vec<[f64; 2]> = (0..HORIZON_AZIMUTHS)
        .map(|a| {
            let phi = std::f64::consts::TAU * a as f64 / HORIZON_AZIMUTHS as f64;
            [phi.sin(), phi.cos()]
        })
        .collect();
    let flat = toward.truncate().length();
    dirs.push(if flat > 1e-9 {
        [toward.x / flat, toward.y / flat]
    } else {
        [0.0, 1.0]
    });
    dirs
}

/// `sin^2` of the elevation whose tangent is `t` (0 for directions at or below horizontal).
fn sin2_of_tan(t: f64) -> f64 {
    if t <= 0.0 { 0.0 } else { t * t / (1.0 + t * t) }
}

/// The distances of a horizon march: from 1 m, each step 10 % of the distance (at least 1 m;
/// 6 % gave the same agreement with the reference at 20 % more time).
fn march_distances() -> Vec<f64> {
    let mut out = Vec::new();
    let mut r = 1.0f64;
    while r <= HORIZON_REACH_M {
        out.push(r);
        r += (0.10 * r).max(1.0);
    }
    out
}

/// The level of the light-grid nodes in `tree`: the finest whose nodes are at least
/// [`GRID_SIDE_M`] wide (exactly that with 8 m leaves), or the root on a smaller map.
pub fn grid_level(tree: &QuadTree) -> u8 {
    (0..=tree.max_level)
        .rev()
        .find(|&l| tree.node_size_m(l) >= GRID_SIDE_M - 1e-9)
        .unwrap_or(0)
}

impl LightGrid {
    /// Sample index of `(layer, row, col)`.
    pub fn index(layer: usize, row: usize, col: usize) -> usize {
        (layer * COLUMNS + row) * COLUMNS + col
    }

    /// Bytes the grid holds (its heights and its four byte fields).
    pub fn bytes(&self) -> usize {
        self.ground_m.len() * 4
            + self.sky.len()
            + self.sun.len()
            + self.sun_margin.len()
            + self.bounce.len()
    }

    /// The node whose grid shades node `key`: its ancestor at [`grid_level`], or itself when it
    /// is at that level or coarser.
    pub fn owner(tree: &QuadTree, key: NodeKey) -> NodeKey {
        key.ancestor_at(grid_level(tree).min(key.level))
    }

    /// Computes the grid of node `key` (at [`grid_level`] or coarser) for `sun`: [`COLUMNS`]
    /// columns from the node's south-west corner to its north-east one.
    pub fn compute(
        world: &World,
        canopy: &Canopy,
        tree: &QuadTree,
        key: NodeKey,
        sun: Sun,
    ) -> Self {
        Self::compute_with_sky(world, canopy, tree, key, sun, None)
    }

    /// The same node's grid for another sun: equal to [`LightGrid::compute`] for `sun`, at less
    /// cost, since the sky visibility (the terrain's horizons and the canopy's transmittance
    /// toward the sky) depends on no sun and is taken from this grid.
    pub fn relit(&self, world: &World, canopy: &Canopy, tree: &QuadTree, sun: Sun) -> Self {
        Self::with_sky(world, canopy, tree, self.key, sun, &self.sky)
    }

    /// Node `key`'s grid for `sun` with its sky given (an earlier computation's, or its sky
    /// page, [`super::sky_pages`]): [`LightGrid::compute`]'s bytes when `sky` is that node's.
    /// `sky` must hold [`LAYERS`] x [`COLUMNS`] x [`COLUMNS`] bytes.
    pub fn with_sky(
        world: &World,
        canopy: &Canopy,
        tree: &QuadTree,
        key: NodeKey,
        sun: Sun,
        sky: &[u8],
    ) -> Self {
        assert_eq!(sky.len(), LAYERS * COLUMNS * COLUMNS, "a grid's sky");
        Self::compute_with_sky(world, canopy, tree, key, sun, Some(sky))
    }

    /// [`LightGrid::compute`], with the sky bytes taken from `sky` when given (an earlier
    /// grid of the node: they depend on no sun).
    fn compute_with_sky(
        world: &World,
        canopy: &Canopy,
        tree: &QuadTree,
        key: NodeKey,
        sun: Sun,
        sky: Option<&[u8]>,
    ) -> Self {
        // Columns and lattice points by global index from the tree's origin (see
        // `HorizonHeights`): a column shared with a neighbour, or with a grid of another level,
        // has the same coordinates.
        let o = tree.origin_m;
        let side_m = tree.node_size_m(key.level);
        let spacing_m = side_m / (COLUMNS - 1) as f64;
        let per_node = (COLUMNS - 1) as i64;
        // Lattice points per column spacing (2 at the grid level, twice as many a level
        // coarser).
        let ratio = (spacing_m / NEAR_SPACING_M).round() as i64;
        let col0 = [i64::from(key.ix) * per_node, i64::from(key.iy) * per_node];
        let column_m = |axis: usize, c: usize| o[axis] + (col0[axis] + c as i64) as f64 * spacing_m;
        let origin = [column_m(0, 0), column_m(1, 0)];
        let margin = (NEAR_MARGIN_M / NEAR_SPACING_M).round() as i64;
        // The lattice near a block of columns (their window widened by the margin): one block
        // at the grid level, blocks of at most [`GRID_SIDE_M`] a level coarser, so a coarse
        // grid's lattice is never larger than a grid-level one's.
        let block_cols = (GRID_SIDE_M / spacing_m).round() as usize + 1;
        let lattice = |c: std::ops::Range<usize>, r: std::ops::Range<usize>| {
            let first = [
                (col0[0] + c.start as i64) * ratio - margin,
                (col0[1] + r.start as i64) * ratio - margin,
            ];
            let count = |n: usize| ((n as i64 - 1) * ratio + 2 * margin + 1) as usize;
            HorizonHeights::new((world, canopy), o, first, [count(c.len()), count(r.len())])
        };
        let distances = march_distances();
        let inverse: Vec<f64> = distances.iter().map(|r| 1.0 / r).collect();
        // Directions: the horizon azimuths, then the sun's.
        let toward = sun.toward();
        let dirs = march_directions(toward);
        let layers_m = layer_heights_m(canopy);
        let cells = COLUMNS * COLUMNS;
        let mut out = Self {
            key,
            origin_m: origin,
            spacing_m,
            ground_m: vec![0.0; cells],
            sky: sky.map_or_else(|| vec![0; LAYERS * cells], <[u8]>::to_vec),
            sun: vec![0; LAYERS * cells],
            sun_margin: vec![0; LAYERS * cells],
            bounce: vec![0; LAYERS * cells],
            sun_dir: sun,
            layers_m,
        };
        let rays = CanopyRays::new(canopy, sun, layers_m);
        // The ground's bounce is computed at the columns whose global index (in grid-level
        // column spacings) is a multiple of [`BOUNCE_STRIDE`] along both axes (every column of
        // a coarser grid); the others interpolate it between them and march no
        // bounce (a relight, or a grid from its sky page, marches only toward the sun there).
        let level_step = (spacing_m / COLUMN_SPACING_M).round() as i64;
        // Highest tangent of the terrain seen from each layer, per direction (per column).
        let mut tan_max = vec![[f64::NEG_INFINITY; LAYERS]; dirs.len()];
        let blocks = || {
            (0..COLUMNS)
                .step_by(block_cols)
                .map(|s| s..(s + block_cols).min(COLUMNS))
        };
        // The bounce per sample before rounding, for the columns that interpolate it.
        let mut bounce_of = vec![0.0f64; LAYERS * cells];
        for (rows, cols) in blocks().flat_map(|r| blocks().map(move |c| (r.clone(), c))) {
            let heights = lattice(cols.clone(), rows.clone());
            // The bounce's columns first: the others interpolate it between them.
            for pass in [true, false] {
                for row in rows.clone() {
                    for col in cols.clone() {
                        let own = [col0[0] + col as i64, col0[1] + row as i64]
                            .iter()
                            .all(|&g| (g * level_step) % BOUNCE_STRIDE == 0);
                        if own != pass {
                            continue;
                        }
                        let (x, y) = (column_m(0, col), column_m(1, row));
                        // The column's ground is a lattice point: exactly the finest surface.
                        let ground = heights.point_m(
                            (col0[0] + col as i64) * ratio,
                            (col0[1] + row as i64) * ratio,
                        );
                        out.ground_m[row * COLUMNS + col] = ground as f32;
                        // Off the bounce's lattice: the horizons for the sky (none when it is
                        // given) and the sun's.
                        let what = match (own, sky.is_none()) {
                            (true, _) => March::All,
                            (false, true) => March::Horizons,
                            (false, false) => March::Sun,
                        };
                        let bounce = heights.march_column(
                            (x, y, ground),
                            (&dirs, &distances, &inverse),
                            (&layers_m, what),
                            toward,
                            &mut tan_max,
                        );
                        let column =
                            rays.column(&heights, (x, y, ground), (&dirs, sky.is_none()), &tan_max);
                        for (l, lit) in column.iter().enumerate() {
                            let i = Self::index(l, row, col);
                            if own {
                                bounce_of[i] = bounce[l] / HORIZON_AZIMUTHS as f64;
                            } else {
                                let g = [
                                    (col0[0] + col as i64) * level_step,
                                    (col0[1] + row as i64) * level_step,
                                ];
                                bounce_of[i] = interpolated(&bounce_of, l, g, col0, level_step);
                            }
                            if sky.is_none() {
                                out.sky[i] = to_byte(lit.sky);
                            }
                            out.sun[i] = to_byte(lit.sun_transmittance);
                            out.sun_margin[i] = margin_to_byte(lit.sun_margin_rad);
                            out.bounce[i] = to_byte(bounce_of[i]);
                        }
                    }
                }
            }
        }
        out
    }

    /// Trilinear sky and sun visibility at world (`x_m`, `y_m`), `above_m` above the ground
    /// (clamped to the grid's columns and layers), as the shaders will sample it.
    pub fn sample(&self, x_m: f64, y_m: f64, above_m: f64) -> (f64, f64) {
        let get = |v: &[u8]| self.trilinear(v, x_m, y_m, above_m);
        let margin = margin_of_unit(get(&self.sun_margin));
        (get(&self.sky), get(&self.sun) * terrain_lit(margin))
    }

    /// Trilinear ground bounce ([`LightGrid::bounce_at`]) at world (`x_m`, `y_m`), `above_m`
    /// above the ground, as the shaders sample it.
    pub fn sample_bounce(&self, x_m: f64, y_m: f64, above_m: f64) -> f64 {
        self.trilinear(&self.bounce, x_m, y_m, above_m)
    }

    /// Trilinear interpolation of one of the grid's byte fields, scaled to [0, 1].
    fn trilinear(&self, v: &[u8], x_m: f64, y_m: f64, above_m: f64) -> f64 {
        let gx = ((x_m - self.origin_m[0]) / self.spacing_m).clamp(0.0, (COLUMNS - 1) as f64);
        let gy = ((y_m - self.origin_m[1]) / self.spacing_m).clamp(0.0, (COLUMNS - 1) as f64);
        let (c0, r0) = (
            (gx as usize).min(COLUMNS - 2),
            (gy as usize).min(COLUMNS - 2),
        );
        let (fx, fy) = (gx - c0 as f64, gy - r0 as f64);
        let h = &self.layers_m;
        let a = above_m.clamp(h[0], h[h.len() - 1]);
        let l0 = (0..h.len() - 1).rfind(|&l| h[l] <= a).unwrap_or(0);
        let fz = (a - h[l0]) / (h[l0 + 1] - h[l0]);
        let mut sum = 0.0;
        for (dl, wz) in [(0, 1.0 - fz), (1, fz)] {
            for (dr, wy) in [(0, 1.0 - fy), (1, fy)] {
                for (dc, wx) in [(0, 1.0 - fx), (1, fx)] {
                    let i = Self::index(l0 + dl, r0 + dr, c0 + dc);
                    sum += wz * wy * wx * f64::from(v[i]) / 255.0;
                }
            }
        }
        sum
    }

    /// The ground's bounce at sample `i`: `(1/pi) * integral of max(0, n . s) cos(theta)` over
    /// the directions where terrain hides the sky (its normal `n` where the horizon march meets
    /// it, `s` toward the sun, `theta` from the zenith). Times the terrain's albedo and the sun's
    /// irradiance, the light that terrain reflects onto a horizontal receiver, taking the
    /// terrain as lit wherever it faces the sun (its own cast shadows are left out).
    pub fn bounce_at(&self, i: usize) -> f64 {
        f64::from(self.bounce[i]) / 255.0
    }

    /// Sky and sun visibility at sample `i` (no interpolation).
    pub fn at_sample(&self, i: usize) -> (f64, f64) {
        let unit = |v: u8| f64::from(v) / 255.0;
        let lit = terrain_lit(margin_of_unit(unit(self.sun_margin[i])));
        (unit(self.sky[i]), unit(self.sun[i]) * lit)
    }
}

/// An optical depth beyond which a ray counts as blocked: `exp(-6)` = 0.0025, under half a
/// byte step.
const OPAQUE_DEPTH: f64 = 6.0;

/// The sun's elevation over the terrain horizon is stored within +-this (rad): 10 degrees,
/// steps of 0.08 degrees.
pub const SUN_MARGIN_RANGE_RAD: f64 = 10.0 * std::f64::consts::PI / 180.0;

/// The sun's apparent diameter (rad, 0.53 degrees): the terrain's shadow goes from none to full
/// while the horizon crosses it.
pub const SUN_DIAMETER_RAD: f64 = 0.53 * std::f64::consts::PI / 180.0;

/// The byte of a sun margin (rad), clamped to [`SUN_MARGIN_RANGE_RAD`].
pub fn margin_to_byte(margin_rad: f64) -> u8 {
    to_byte(0.5 + 0.5 * margin_rad / SUN_MARGIN_RANGE_RAD)
}

/// The margin (rad) of a stored value scaled to [0, 1] (a byte / 255, or a filtered texel).
pub fn margin_of_unit(v: f64) -> f64 {
    (2.0 * v - 1.0) * SUN_MARGIN_RANGE_RAD
}

/// The share of the sun's disc above the terrain horizon for a margin (rad): linear across the
/// disc's diameter.
pub fn terrain_lit(margin_rad: f64) -> f64 {
    (0.5 + margin_rad / SUN_DIAMETER_RAD).clamp(0.0, 1.0)
}

fn to_byte(v: f64) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Layer `l`'s bounce at a column off the bounce's lattice ([`BOUNCE_STRIDE`]), from
/// `values` (`[layer][row][col]`, filled at the lattice's columns): bilinear between the
/// lattice's columns around it. The column is at global index `g` (in grid-level column
/// spacings from the tree's origin), the grid's column 0 at `col0` (in its own spacings,
/// `level_step` grid-level ones). The weights and the order of the sums depend on `g` alone, so
/// every grid holding the column gets the same value.
fn interpolated(values: &[f64], l: usize, g: [i64; 2], col0: [i64; 2], level_step: i64) -> f64 {
    // Per axis: the lattice's columns below and above (the same when on it; a grid's border
    // columns are on it, so both are in the grid) and the weight of the one above.
    let axis = |a: usize| {
        let below = g[a] - g[a].rem_euclid(BOUNCE_STRIDE);
        let t = (g[a] - below) as f64 / BOUNCE_STRIDE as f64;
        let above = if t > 0.0 {
            below + BOUNCE_STRIDE
        } else {
            below
        };
        let local = |v: i64| (v / level_step - col0[a]) as usize;
        (local(below), local(above), t)
    };
    let ((c0, c1, tx), (r0, r1, ty)) = (axis(0), axis(1));
    let v = |r: usize, c: usize| values[LightGrid::index(l, r, c)];
    let lo = v(r0, c0) * (1.0 - tx) + v(r0, c1) * tx;
    let hi = v(r1, c0) * (1.0 - tx) + v(r1, c1) * tx;
    lo * (1.0 - ty) + hi * ty
}

/// One layer's light at a column, before it is stored as bytes.
#[derive(Clone, Copy, Default)]
struct ColumnLight {
    /// Sky visibility (0 when the sky is not computed).
    sky: f64,
    /// The canopy's transmittance toward the sun.
    sun_transmittance: f64,
    /// The sun's elevation over the terrain horizon toward it (rad).
    sun_margin_rad: f64,
}

/// The canopy's part of a grid: its rays toward the sky and the sun from each layer of a
/// column, and the sums that turn them and the horizons into a column's light.
struct CanopyRays<'a> {
    canopy: &'a Canopy,
    sun: Sun,
    toward: DVec3,
    layers_m: [f64; LAYERS],
    /// How far (horizontally) a sky ray can go before it climbs out of the canopy.
    sky_reach_m: f64,
    /// How far the sun ray can (0 with the sun at or under the horizontal).
    sun_reach_m: f64,
}

impl<'a> CanopyRays<'a> {
    fn new(canopy: &'a Canopy, sun: Sun, layers_m: [f64; LAYERS]) -> Self {
        // A sky ray climbs out of the canopy within `top / tan(elevation)` horizontally, at
        // most the lowest band's; the sun ray is followed twice as far.
        let lowest_sky = ((0.5 / SKY_BANDS as f64) / (1.0 - 0.5 / SKY_BANDS as f64)).sqrt();
        let sun_reach_m = if sun.elevation_deg > 0.0 {
            let sun_tan = sun.elevation_deg.to_radians().tan().max(1e-3);
            (2.0 * canopy.top_m / sun_tan).min(HORIZON_REACH_M)
        } else {
            0.0
        };
        Self {
            canopy,
            sun,
            toward: sun.toward(),
            layers_m,
            sky_reach_m: (canopy.top_m / lowest_sky).min(HORIZON_REACH_M),
            sun_reach_m,
        }
    }

    /// Whether vegetation stands within `reach_m` of (`x`, `y`) (horizontally) along
    /// horizontal unit `dir`, or around it when `dir` is `None`.
    fn canopy_within(&self, (x, y): (f64, f64), dir: Option<[f64; 2]>, reach_m: f64) -> bool {
        match dir {
            None => self
                .canopy
                .any_in([x - reach_m, y - reach_m], [x + reach_m, y + reach_m]),
            Some(d) => {
                let (ex, ey) = (x + d[0] * reach_m, y + d[1] * reach_m);
                self.canopy
                    .any_in([x.min(ex), y.min(ey)], [x.max(ex), y.max(ey)])
            }
        }
    }

    /// The light of each layer of the column at (`x`, `y`), ground `ground_m`, whose horizons
    /// per march direction (`dirs`: the horizon azimuths, then the sun's) are `tan_max`; its
    /// sky only `with_sky`.
    fn column(
        &self,
        heights: &HorizonHeights<'_>,
        (x, y, ground_m): (f64, f64, f64),
        (dirs, with_sky): (&[[f64; 2]], bool),
        tan_max: &[[f64; LAYERS]],
    ) -> [ColumnLight; LAYERS] {
        let canopy = self.canopy;
        let per_canopy = HORIZON_AZIMUTHS / CANOPY_AZIMUTHS;
        // The same test around the column alone (most columns of a grid with some canopy have
        // none within their rays' reach), then along each ray.
        let sky_canopy = with_sky && self.canopy_within((x, y), None, self.sky_reach_m);
        let sun_canopy = self.sun_reach_m > 0.0
            && self.canopy_within((x, y), Some(dirs[HORIZON_AZIMUTHS]), self.sun_reach_m);
        let mut out = [ColumnLight::default(); LAYERS];
        for ((lit, &lh), l) in out.iter_mut().zip(&self.layers_m).zip(0..) {
            let p0 = DVec3::new(x, y, ground_m + lh);
            let under = lh < canopy.top_m;
            if with_sky {
                // Canopy transmittance per canopy azimuth and band.
                let mut trans = [[1.0f64; SKY_BANDS]; CANOPY_AZIMUTHS];
                if sky_canopy && under {
                    for (c, t) in trans.iter_mut().enumerate() {
                        let dir = dirs[c * per_canopy];
                        if !self.canopy_within((x, y), Some(dir), self.sky_reach_m) {
                            continue;
                        }
                        for (b, tb) in t.iter_mut().enumerate() {
                            let s = (b as f64 + 0.5) / SKY_BANDS as f64;
                            let (sin_e, cos_e) = (s.sqrt(), (1.0 - s).sqrt());
                            let w = DVec3::new(dir[0] * cos_e, dir[1] * cos_e, sin_e);
                            *tb = canopy_transmittance(
                                heights,
                                canopy,
                                (p0, w),
                                lh,
                                (CANOPY_STEPS, 1.0),
                            );
                        }
                    }
                }
                let mut sky = 0.0;
                for (a, tan) in tan_max.iter().take(HORIZON_AZIMUTHS).enumerate() {
                    let s_h = sin2_of_tan(tan[l]);
                    // The canopy azimuth nearest to horizon azimuth `a`.
                    let c = ((a + per_canopy / 2) / per_canopy) % CANOPY_AZIMUTHS;
                    for (b, tb) in trans[c].iter().enumerate() {
                        let (lo, hi) = (
                            b as f64 / SKY_BANDS as f64,
                            (b + 1) as f64 / SKY_BANDS as f64,
                        );
                        sky += tb * (hi - s_h.max(lo)).max(0.0);
                    }
                }
                lit.sky = sky / HORIZON_AZIMUTHS as f64;
            }
            // The sun's elevation over the terrain horizon toward it, and the canopy's
            // transmittance toward it (wherever the terrain shadows, too: both are interpolated
            // before they are combined, `LightGrid::sample`).
            lit.sun_margin_rad =
                self.sun.elevation_deg.to_radians() - tan_max[HORIZON_AZIMUTHS][l].atan();
            lit.sun_transmittance = if self.sun.elevation_deg <= 0.0 {
                0.0
            } else if sun_canopy && under {
                canopy_transmittance(
                    heights,
                    canopy,
                    (p0, self.toward),
                    lh,
                    (SUN_CANOPY_STEPS, 2.0),
                )
            } else {
                1.0
            };
        }
        out
    }
}

/// `exp(-optical depth)` from `p0` (`above_m` over the ground) along unit `w` until the ray
/// leaves the canopy, at `steps` midpoints (ground from the horizon heights).
fn canopy_transmittance(
    heights: &HorizonHeights<'_>,
    canopy: &Canopy,
    (p0, w): (DVec3, DVec3),
    above_m: f64,
    (steps, reach): (usize, f64),
) -> f64 {
    if w.z <= 1e-6 {
        return 0.0;
    }
    // `reach` times the length that climbs from its height to the canopy's top over flat
    // ground (more than 1 follows ground rising under the ray, which keeps it in the canopy).
    let len = (reach * (canopy.top_m - above_m) / w.z).min(HORIZON_REACH_M);
    if len <= 0.0 {
        return 1.0;
    }
    let dl = len / steps as f64;
    // Rays that stay well within the lattice's reach read it at every point: no distance
    // needed.
    let flat = w.truncate().length();
    let near = len * flat < heights.near_reach_m - 1e-6;
    // The horizontal distance of a step.
    let dl_flat = dl * flat;
    let mut depth = 0.0;
    for k in 0..steps {
        let p = p0 + w * ((k as f64 + 0.5) * dl);
        let r = if near {
            0.0
        } else {
            (k as f64 + 0.5) * dl_flat
        };
        depth += heights.extinction_per_m(canopy, p, r) * dl;
        if depth > OPAQUE_DEPTH {
            return 0.0;
        }
    }
    (-depth).exp()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vegetation::placement::Placer;

    /// The tiny map moved to an origin with a fraction of a metre, its canopy and its tree.
    fn shifted_tiny() -> (World, Canopy, QuadTree) {
        let mut map = crate::test_maps::tiny_map();
        map.manifest.origin_m = [1234.567, -89.0123];
        let world = World::new(map);
        let canopy = Canopy::new(&world, &Placer::new(&world));
        let tree = QuadTree::new(world.origin_m(), world.size_m());
        (world, canopy, tree)
    }

    /// The horizon march without its shortcuts: every point, every layer, from minus infinity.
    /// Returns the tangents per direction and layer, and the bounce per layer.
    fn plain_march(
        h: &HorizonHeights<'_>,
        (x, y, ground): (f64, f64, f64),
        dirs: &[[f64; 2]],
        layers_m: &[f64; LAYERS],
        toward: DVec3,
    ) -> (Vec<[f64; LAYERS]>, [f64; LAYERS]) {
        let mut bounce = [0.0; LAYERS];
        let mut tans = vec![[f64::NEG_INFINITY; LAYERS]; dirs.len()];
        for (d, (best, dir)) in tans.iter_mut().zip(dirs).enumerate() {
            let mut previous = (0.0, 0.0);
            for r in march_distances() {
                let (px, py) = (x + dir[0] * r, y + dir[1] * r);
                let dh = h.height_m(px, py, r) - ground;
                for l in 0..LAYERS {
                    let t = (dh - layers_m[l]) * (1.0 / r);
                    if t > best[l] {
                        if d < HORIZON_AZIMUTHS && t > 0.0 && toward.z > 0.0 {
                            let f = h.facing_sun((px, py), *dir, previous, (r, dh), toward);
                            bounce[l] += f * (sin2_of_tan(t) - sin2_of_tan(best[l]));
                        }
                        best[l] = t;
                    }
                }
                previous = (r, dh);
            }
        }
        (tans, bounce)
    }

    /// The horizon march's shortcuts (horizons floored where their bytes cannot change, points
    /// and far stretches skipped where they cannot raise a horizon) give the bytes of the plain
    /// march exactly: the sky's `sin^2` of every horizon, the sun's stored margin and the
    /// bounce, at columns over a whole grid-level node of the tiny map, under a high, a low and
    /// a grazing sun.
    #[test]
    fn the_march_shortcuts_change_no_stored_value() {
        let (world, canopy, tree) = shifted_tiny();
        let level = grid_level(&tree);
        let key = NodeKey {
            level,
            ix: 1,
            iy: 1,
        };
        let r = tree.rect(key);
        let margin = (NEAR_MARGIN_M / NEAR_SPACING_M).round() as i64;
        let per = (GRID_SIDE_M / NEAR_SPACING_M).round() as i64;
        let first = [
            i64::from(key.ix) * per - margin,
            i64::from(key.iy) * per - margin,
        ];
        let n = (per + 2 * margin + 1) as usize;
        let h = HorizonHeights::new((&world, &canopy), tree.origin_m, first, [n, n]);
        let layers_m = layer_heights_m(&canopy);
        let distances = march_distances();
        let inverse: Vec<f64> = distances.iter().map(|r| 1.0 / r).collect();
        let mut compared = 0;
        let mut raised = 0;
        for (azimuth_deg, elevation_deg) in [(56.0, 49.0), (250.0, 12.0), (120.0, 2.0)] {
            let sun = Sun {
                azimuth_deg,
                elevation_deg,
            };
            let toward = sun.toward();
            let dirs = march_directions(toward);
            let mut tans = vec![[0.0; LAYERS]; dirs.len()];
            for row in (0..COLUMNS).step_by(3) {
                for col in (0..COLUMNS).step_by(3) {
                    let (x, y) = (
                        r.min[0] + col as f64 * COLUMN_SPACING_M,
                        r.min[1] + row as f64 * COLUMN_SPACING_M,
                    );
                    let ground = h.point_m(
                        first[0] + margin + 2 * col as i64,
                        first[1] + margin + 2 * row as i64,
                    );
                    let bounce = h.march_column(
                        (x, y, ground),
                        (&dirs, &distances, &inverse),
                        (&layers_m, March::All),
                        toward,
                        &mut tans,
                    );
                    let (plain, plain_bounce) =
                        plain_march(&h, (x, y, ground), &dirs, &layers_m, toward);
                    assert_eq!(bounce, plain_bounce, "bounce at column ({row}, {col})");
                    for l in 0..LAYERS {
                        for a in 0..HORIZON_AZIMUTHS {
                            assert_eq!(
                                sin2_of_tan(tans[a][l]),
                                sin2_of_tan(plain[a][l]),
                                "sky, column ({row}, {col}), azimuth {a}, layer {l}"
                            );
                            raised += usize::from(plain[a][l] > 0.0);
                        }
                        let margin_byte =
                            |t: f64| margin_to_byte(elevation_deg.to_radians() - t.atan());
                        assert_eq!(
                            margin_byte(tans[HORIZON_AZIMUTHS][l]),
                            margin_byte(plain[HORIZON_AZIMUTHS][l]),
                            "sun, column ({row}, {col}), layer {l}"
                        );
                        compared += 1;
                    }
                }
            }
        }
        // Terrain rises above the horizontal somewhere (else the sky test is trivial).
        assert!(
            compared > 2000 && raised > 1000,
            "{compared} compared, {raised} raised"
        );
    }

    /// Neighbouring grids hold exactly the same values (ground, sky, sun, bounce, every layer)
    /// in the columns they share, on a map moved to an origin with a fraction of a metre.
    #[test]
    fn shared_border_columns_are_identical() {
        let (world, canopy, tree) = shifted_tiny();
        let level = grid_level(&tree);
        let at = |ix, iy| {
            let key = NodeKey { level, ix, iy };
            LightGrid::compute(&world, &canopy, &tree, key, Sun::default())
        };
        let (a, east, north) = (at(1, 1), at(2, 1), at(1, 2));
        let last = COLUMNS - 1;
        let layers = LAYERS;
        for k in 0..COLUMNS {
            assert_eq!(a.ground_m[k * COLUMNS + last], east.ground_m[k * COLUMNS]);
            assert_eq!(a.ground_m[last * COLUMNS + k], north.ground_m[k]);
            for l in 0..layers {
                let (ae, e) = (LightGrid::index(l, k, last), LightGrid::index(l, k, 0));
                let (an, n) = (LightGrid::index(l, last, k), LightGrid::index(l, 0, k));
                assert_eq!(
                    (a.sky[ae], a.sun[ae], a.sun_margin[ae], a.bounce[ae]),
                    (east.sky[e], east.sun[e], east.sun_margin[e], east.bounce[e]),
                    "east {l} {k}"
                );
                assert_eq!(
                    (a.sky[an], a.sun[an], a.sun_margin[an], a.bounce[an]),
                    (
                        north.sky[n],
                        north.sun[n],
                        north.sun_margin[n],
                        north.bounce[n]
                    ),
                    "north {l} {k}"
                );
            }
        }
        // Not a constant field: the test would pass on anything uniform.
        assert!(a.sky.iter().any(|&v| v != a.sky[0]));
    }

    /// A grid relit for another sun (its sky kept) equals the grid computed for that sun: the
    /// sky depends on no sun, and everything else is computed anew.
    #[test]
    fn a_relit_grid_equals_one_computed_for_its_sun() {
        let (world, canopy, tree) = shifted_tiny();
        let key = NodeKey {
            level: grid_level(&tree),
            ix: 2,
            iy: 1,
        };
        let low = Sun {
            azimuth_deg: 250.0,
            elevation_deg: 8.0,
        };
        let high = Sun::default();
        let first = LightGrid::compute(&world, &canopy, &tree, key, low);
        let direct = LightGrid::compute(&world, &canopy, &tree, key, high);
        assert_eq!(first.relit(&world, &canopy, &tree, high), direct);
        // No sun changes the sky; the rest moves with the sun.
        assert_eq!(first.sky, direct.sky);
        assert_ne!(first.sun_margin, direct.sun_margin);
        assert_ne!(first.bounce, direct.bounce);
        assert!(
            first.sky.iter().any(|&v| v < 250),
            "no sky is hidden on this node"
        );
    }

    /// A grid a level coarser holds exactly the values of its four children's grids at its
    /// columns (every other column of theirs), and the same again a level up: a node can blend
    /// toward a coarser neighbour's grid without a step at their border. Under a low sun, so
    /// that terrain shadows (the values that depend most on the terrain near the column) vary.
    #[test]
    fn coarser_grids_equal_finer_ones_where_columns_coincide() {
        let (world, canopy, tree) = shifted_tiny();
        let level = grid_level(&tree);
        assert!(
            level >= 2,
            "the tiny map has two levels above its grid level"
        );
        let sun = Sun {
            azimuth_deg: 250.0,
            elevation_deg: 12.0,
        };
        let grid = |level, ix, iy| {
            LightGrid::compute(&world, &canopy, &tree, NodeKey { level, ix, iy }, sun)
        };
        let mut compared = 0;
        let mut shaded = 0;
        for (coarse_level, cix, ciy) in [(level - 1, 0, 1), (level - 2, 0, 0)] {
            let coarse = grid(coarse_level, cix, ciy);
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let fine = grid(coarse_level + 1, 2 * cix + dx, 2 * ciy + dy);
                let half = (COLUMNS - 1) / 2;
                for r in 0..=half {
                    for c in 0..=half {
                        let (cr, cc) = (dy as usize * half + r, dx as usize * half + c);
                        let (fr, fc) = (2 * r, 2 * c);
                        assert_eq!(
                            coarse.ground_m[cr * COLUMNS + cc],
                            fine.ground_m[fr * COLUMNS + fc]
                        );
                        for l in 0..LAYERS {
                            let (i, j) = (LightGrid::index(l, cr, cc), LightGrid::index(l, fr, fc));
                            assert_eq!(
                                (
                                    coarse.sky[i],
                                    coarse.sun[i],
                                    coarse.sun_margin[i],
                                    coarse.bounce[i]
                                ),
                                (fine.sky[j], fine.sun[j], fine.sun_margin[j], fine.bounce[j]),
                                "level {coarse_level} child ({dx}, {dy}) layer {l} column ({r}, {c})"
                            );
                            compared += 1;
                            shaded += usize::from(fine.at_sample(j).1 < 0.5);
                        }
                    }
                }
            }
        }
        assert!(
            compared > 10_000 && shaded > 100,
            "{compared} compared, {shaded} shaded"
        );
    }
}
