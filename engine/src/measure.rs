//! Measuring what the user sees: the true error of node meshes against the densely sampled
//! finest surface, the on-screen pixel error of a whole view, and a CDLOD-style distance-based
//! selection to compare against. Used by tests and by `nodebench`.

use crate::camera::Camera;
use crate::surface::world::World;
use crate::terrain::bounds::{BLOCKS, BLOCKS_PER_SIDE, BoundsCache};
use crate::terrain::mesh::NodeMesh;
use crate::terrain::mesh_surface::MeshSurface;
use crate::terrain::quadtree::{NODE_QUADS, QuadTree};
use crate::terrain::select::{Selection, traverse};
use glam::{DMat4, DVec3, DVec4};

/// Where inner samples sit inside their lattice step: not on a vertex (0), not on the check
/// lattice (multiples of 1 / CHECK_SUBDIV of a quad, whatever the samples per quad: the
/// fraction is not a multiple of 1/8 or of any 1/n with small n).
pub const SAMPLE_OFFSET: f64 = 0.382;

/// The true largest |mesh - surface| of a node (the mesh sampled through its own triangles) on
/// a lattice of `per_quad` points per mesh quad, inner samples offset by [`SAMPLE_OFFSET`] of a
/// step so they avoid vertices and the bounds' check lattice, and the largest distance of the
/// surface outside the node's height range (<= 0 when inside).
pub fn true_node_error(world: &World, tree: &QuadTree, m: &NodeMesh, per_quad: u32) -> (f64, f64) {
    true_block_errors(world, tree, m, per_quad)
        .iter()
        .fold((0.0, f64::NEG_INFINITY), |(e, o), b| {
            (e.max(b.0), o.max(b.1))
        })
}

/// [`true_node_error`] per bound block (`index = by * BLOCKS_PER_SIDE + bx`): the largest
/// |mesh - surface| inside each block and the largest distance of the surface outside the
/// block's height range. Inner samples are offset, so none lies on a border between blocks.
pub fn true_block_errors(
    world: &World,
    tree: &QuadTree,
    m: &NodeMesh,
    per_quad: u32,
) -> [(f64, f64); BLOCKS] {
    let per_block = (NODE_QUADS * per_quad) as usize / BLOCKS_PER_SIDE;
    let mut out = [(0.0f64, f64::NEG_INFINITY); BLOCKS];
    // The block a sample index lies in along one axis.
    let block_of = |k: usize| (k / per_block).min(BLOCKS_PER_SIDE - 1);
    visit_samples(world, tree, m, per_quad, |[i, j], _, f, diff| {
        let err = diff.abs();
        let b = block_of(j) * BLOCKS_PER_SIDE + block_of(i);
        let bounds = &m.bounds.blocks[b];
        out[b].0 = out[b].0.max(err);
        out[b].1 = out[b].1.max(bounds.z_min_m - f).max(f - bounds.z_max_m);
    });
    out
}

/// Visits a node mesh's sample lattice of `per_quad` points per quad (`NODE_QUADS * per_quad`
/// steps a side; border samples on the border, inner ones offset by [`SAMPLE_OFFSET`] of a
/// step): `visit([i, j], [dx, dy] from the node's corner (m), surface height F, |mesh - F|)`, the
/// mesh sampled through its own triangles.
fn visit_samples(
    world: &World,
    tree: &QuadTree,
    m: &NodeMesh,
    per_quad: u32,
    mut visit: impl FnMut([usize; 2], [f64; 2], f64, f64),
) {
    let r = tree.rect(m.key);
    let n = (NODE_QUADS * per_quad) as usize;
    let step = (r.max[0] - r.min[0]) / n as f64;
    let surface = MeshSurface::new(m, tree);
    let off = |k: usize| if k == 0 || k == n { 0.0 } else { SAMPLE_OFFSET };
    for j in 0..=n {
        for i in 0..=n {
            let d = [
                (i as f64 + off(i)).min(n as f64) * step,
                (j as f64 + off(j)).min(n as f64) * step,
            ];
            let (x, y) = (r.min[0] + d[0], r.min[1] + d[1]);
            let f = world.height_m(x, y);
            visit([i, j], d, f, surface.height_at(x, y) - f);
        }
    }
}

/// A view's error: over samples of the drawn meshes, the largest, the 99.9th percentile and the
/// mean in pixels, and the largest by screen region ([`ScreenRegion`] as the index; the
/// on-axis measures leave it at 0).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ViewError {
    pub max_px: f64,
    pub p999_px: f64,
    pub mean_px: f64,
    pub samples: u64,
    pub region_max_px: [f64; 3],
}

impl ViewError {
    /// Summary of per-sample errors (px) and their regions.
    fn of(mut px: Vec<f64>, region_max_px: [f64; 3]) -> Self {
        px.sort_by(f64::total_cmp);
        let n = px.len();
        let at = |q: f64| px[((q * n as f64).ceil() as usize).clamp(1, n) - 1];
        Self {
            max_px: px.last().copied().unwrap_or(0.0),
            p999_px: if n > 0 { at(0.999) } else { 0.0 },
            mean_px: if n > 0 {
                px.iter().sum::<f64>() / n as f64
            } else {
                0.0
            },
            samples: n as u64,
            region_max_px,
        }
    }
}

/// Where on the screen an error shows: the viewport cut in thirds each way, its middle cell,
/// the four cells beside it (edge bands) and the four corner cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScreenRegion {
    Centre = 0,
    Edges = 1,
    Corners = 2,
}

impl ScreenRegion {
    pub const ALL: [Self; 3] = [Self::Centre, Self::Edges, Self::Corners];

    pub fn name(self) -> &'static str {
        match self {
            Self::Centre => "centre third",
            Self::Edges => "edge bands",
            Self::Corners => "corners",
        }
    }
}

/// A camera's projection to pixels, for measuring on the screen: the camera's clip-space
/// matrix ([`Camera::clip_from_rel`]) and viewport, nothing of the selection's bound.
#[derive(Debug, Clone, Copy)]
pub struct ScreenProjection {
    eye_m: DVec3,
    clip_from_rel: DMat4,
    viewport_px: [f64; 2],
    /// `K` and `cos²` of the screen corner's off-axis angle, for [`Self::most_px`].
    k_px: f64,
    cos2_corner: f64,
}

impl ScreenProjection {
    pub fn new(cam: &Camera) -> Self {
        Self {
            eye_m: cam.position_m,
            clip_from_rel: cam.clip_from_rel(),
            viewport_px: [f64::from(cam.viewport_px[0]), f64::from(cam.viewport_px[1])],
            k_px: cam.k_px(),
            cos2_corner: {
                let ty = (cam.fovy_rad * 0.5).tan();
                let tx = ty * cam.aspect();
                1.0 / (1.0 + tx * tx + ty * ty)
            },
        }
    }

    fn clip(&self, p: DVec3) -> DVec4 {
        self.clip_from_rel * (p - self.eye_m).extend(1.0)
    }

    /// The pixel position (x right, y down from the top-left corner) of a clip-space point in
    /// front of the camera.
    fn pixel(&self, c: DVec4) -> [f64; 2] {
        [
            (c.x / c.w + 1.0) * 0.5 * self.viewport_px[0],
            (1.0 - c.y / c.w) * 0.5 * self.viewport_px[1],
        ]
    }

    /// The pixel position of world point `p`, when it is in the view frustum.
    pub fn pixel_of(&self, p: DVec3) -> Option<[f64; 2]> {
        self.segment_px(p, p).map(|(_, at)| at)
    }

    /// The segment `a..b` (world metres) as the screen shows it: clipped to the view frustum
    /// (the four sides and the near plane) in clip space, its length in pixels and the pixel
    /// position of its middle; `None` when no part of it is on the screen. A straight segment
    /// projects to a straight one, so the length is the distance between the clipped ends'
    /// pixels.
    pub fn segment_px(&self, a: DVec3, b: DVec3) -> Option<(f64, [f64; 2])> {
        let (ca, cb) = (self.clip(a), self.clip(b));
        // Inside where each is >= 0: |x| <= w, |y| <= w, and the near plane (reversed Z: the
        // clip z is the near distance and w the depth, so z <= w).
        let inside = |c: DVec4| [c.w + c.x, c.w - c.x, c.w + c.y, c.w - c.y, c.w - c.z];
        let (ia, ib) = (inside(ca), inside(cb));
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for (da, db) in ia.into_iter().zip(ib) {
            if da < 0.0 && db < 0.0 {
                return None;
            }
            if da < 0.0 {
                t0 = t0.max(da / (da - db));
            } else if db < 0.0 {
                t1 = t1.min(da / (da - db));
            }
        }
        if t0 > t1 {
            return None;
        }
        let (pa, pb) = (self.pixel(ca.lerp(cb, t0)), self.pixel(ca.lerp(cb, t1)));
        let length = ((pa[0] - pb[0]).powi(2) + (pa[1] - pb[1]).powi(2)).sqrt();
        Some((length, [(pa[0] + pb[0]) * 0.5, (pa[1] + pb[1]) * 0.5]))
    }

    /// The region of the screen a pixel position lies in.
    pub fn region(&self, at: [f64; 2]) -> ScreenRegion {
        let third = |v: f64, size: f64| ((3.0 * v / size).floor() as i64).clamp(0, 2);
        let (cx, cy) = (
            third(at[0], self.viewport_px[0]),
            third(at[1], self.viewport_px[1]),
        );
        match (cx == 1, cy == 1) {
            (true, true) => ScreenRegion::Centre,
            (false, false) => ScreenRegion::Corners,
            _ => ScreenRegion::Edges,
        }
    }

    /// An upper bound of what any displacement of `error_m` at distance at least `dist_m` can
    /// become on this screen: `error_m * K / (dist_m * cos²θcorner)` (the largest stretch of a
    /// flat screen is `1 / cos²θ`, largest at its corners), for skipping samples that cannot
    /// beat a larger error found already.
    fn most_px(&self, error_m: f64, dist_m: f64) -> f64 {
        if dist_m > 0.0 {
            error_m * self.k_px / (dist_m * self.cos2_corner)
        } else {
            f64::INFINITY
        }
    }
}

/// On-screen error of a view: for points on a lattice of `per_side` x `per_side` in every drawn
/// node, the true surface point and the drawn mesh point above or below it (the mesh sampled
/// through its own triangles, grid or TIN), projected through the camera's matrices: the
/// length in pixels of the part of the segment between them that is on the screen. Samples with
/// no part on the screen do not count.
pub fn view_error(
    world: &World,
    tree: &QuadTree,
    meshes: &[NodeMesh],
    cam: &Camera,
    per_side: u32,
) -> ViewError {
    let screen = ScreenProjection::new(cam);
    let mut px = Vec::new();
    let mut region_max_px = [0.0f64; 3];
    visit_lattice(world, tree, meshes, per_side, |truth, drawn_z| {
        let drawn = DVec3::new(truth.x, truth.y, drawn_z);
        if let Some((len, at)) = screen.segment_px(truth, drawn) {
            let region = screen.region(at) as usize;
            region_max_px[region] = region_max_px[region].max(len);
            px.push(len);
        }
    });
    ViewError::of(px, region_max_px)
}

/// Visits `per_side` x `per_side` points in every mesh's node (cell centres):
/// `visit(true surface point, the mesh's height there through its own triangles)`.
fn visit_lattice(
    world: &World,
    tree: &QuadTree,
    meshes: &[NodeMesh],
    per_side: u32,
    mut visit: impl FnMut(DVec3, f64),
) {
    for m in meshes {
        let r = tree.rect(m.key);
        let step = (r.max[0] - r.min[0]) / f64::from(per_side);
        let surface = MeshSurface::new(m, tree);
        for j in 0..per_side {
            for i in 0..per_side {
                let (x, y) = (
                    r.min[0] + (f64::from(i) + 0.5) * step,
                    r.min[1] + (f64::from(j) + 0.5) * step,
                );
                visit(
                    DVec3::new(x, y, world.height_m(x, y)),
                    surface.height_at(x, y),
                );
            }
        }
    }
}

/// The error of a view in the pixel metric's on-axis model (not on the screen: off axis the
/// screen stretches an error up to `1 / cos²θ` more): for points on a lattice of `per_side` x
/// `per_side` in every drawn node that lie in the view frustum, `|mesh - surface| * K /
/// distance`, the mesh sampled through its own triangles (grid or TIN). No percentile or
/// regions.
pub fn view_error_on_axis(
    world: &World,
    tree: &QuadTree,
    meshes: &[NodeMesh],
    cam: &Camera,
    per_side: u32,
) -> ViewError {
    let k = cam.k_px();
    let frustum = cam.frustum();
    let (mut max_px, mut sum, mut samples) = (0.0f64, 0.0f64, 0u64);
    visit_lattice(world, tree, meshes, per_side, |p, drawn_z| {
        // Only points inside the view frustum count (a point is a degenerate box).
        if frustum.intersects_aabb(p, p) {
            let px = (drawn_z - p.z).abs() * k / (p - cam.position_m).length().max(1e-9);
            max_px = max_px.max(px);
            sum += px;
            samples += 1;
        }
    });
    ViewError {
        max_px,
        mean_px: if samples > 0 {
            sum / samples as f64
        } else {
            0.0
        },
        samples,
        ..ViewError::default()
    }
}

/// A node mesh's error on a dense lattice, kept to find a view's largest on-screen error
/// quickly: the samples are camera-independent, so they are measured once per mesh and each view
/// only projects them (see [`view_max_error_px`]).
#[derive(Debug, Clone)]
pub struct ErrorSamples {
    /// Sample box (world metres): x, y over the node, z over the sampled surface heights.
    pub min_m: DVec3,
    pub max_m: DVec3,
    /// Node origin (the rectangle's minimum corner) the sample positions are relative to.
    origin_m: [f64; 2],
    /// (x, y relative to `origin_m`, surface z, mesh - surface), largest |error| first; samples
    /// with zero error are left out.
    samples: Vec<[f32; 4]>,
}

impl ErrorSamples {
    /// The largest |error| of any sample (m).
    pub fn max_error_m(&self) -> f64 {
        self.samples.first().map_or(0.0, |s| f64::from(s[3].abs()))
    }
}

/// Measures `mesh - surface` (the mesh through its own triangles) on a lattice of `per_quad`
/// points per quad, inner samples offset by [`SAMPLE_OFFSET`] of a step like
/// [`true_node_error`].
pub fn node_error_samples(
    world: &World,
    tree: &QuadTree,
    m: &NodeMesh,
    per_quad: u32,
) -> ErrorSamples {
    let r = tree.rect(m.key);
    let (mut z_lo, mut z_hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let mut samples = Vec::new();
    visit_samples(world, tree, m, per_quad, |_, [dx, dy], f, diff| {
        z_lo = z_lo.min(f).min(f + diff);
        z_hi = z_hi.max(f).max(f + diff);
        if diff != 0.0 {
            samples.push([dx as f32, dy as f32, f as f32, diff as f32]);
        }
    });
    samples.sort_by(|a, b| b[3].abs().total_cmp(&a[3].abs()));
    ErrorSamples {
        // f32 positions: widen the box by their rounding so it still holds every sample.
        min_m: DVec3::new(r.min[0], r.min[1], z_lo - z_lo.abs() * 1e-6 - 1e-6),
        max_m: DVec3::new(r.max[0], r.max[1], z_hi + z_hi.abs() * 1e-6 + 1e-6),
        origin_m: r.min,
        samples,
    }
}

/// The largest error in the pixel metric's on-axis model, `|mesh - surface| * K / distance`,
/// over the samples of the given nodes that lie in the view frustum: exact over the samples,
/// found by branch and bound (a node is skipped once its largest error over its box distance
/// cannot beat the best so far). Not on the screen: see [`view_max_error_px`].
pub fn view_max_error_on_axis_px(nodes: &[&ErrorSamples], cam: &Camera) -> f64 {
    let k = cam.k_px();
    let frustum = cam.frustum();
    let eye = cam.position_m;
    let mut order: Vec<(f64, &ErrorSamples)> = nodes
        .iter()
        .filter(|s| frustum.intersects_aabb(s.min_m, s.max_m))
        .map(|s| {
            let d = crate::camera::distance_to_aabb(eye, s.min_m, s.max_m);
            let bound = if d > 0.0 {
                s.max_error_m() * k / d
            } else {
                f64::INFINITY
            };
            (bound, *s)
        })
        .collect();
    order.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut best = 0.0f64;
    for (bound, s) in order {
        if bound <= best {
            break;
        }
        let d_min = crate::camera::distance_to_aabb(eye, s.min_m, s.max_m);
        for p in &s.samples {
            let err = f64::from(p[3].abs());
            if d_min > 0.0 && err * k / d_min <= best {
                break; // sorted by error: no later sample can beat `best`
            }
            let at = DVec3::new(
                s.origin_m[0] + f64::from(p[0]),
                s.origin_m[1] + f64::from(p[1]),
                f64::from(p[2]),
            );
            if frustum.intersects_aabb(at, at) {
                best = best.max(err * k / (at - eye).length().max(1e-9));
            }
        }
    }
    best
}

/// The largest on-screen error over the samples of the given nodes (each measured as
/// [`view_error`] measures its lattice: the true and the drawn point projected through the
/// camera's matrices, the segment between them clipped to the view), and the largest by screen
/// region. With `by_region` false only the overall largest is wanted, and it is found by branch
/// and bound: a node, or the rest of a node's samples (sorted by error), is skipped once its
/// largest error cannot beat the best so far even with a flat screen's largest stretch.
pub fn view_max_error_px(nodes: &[&ErrorSamples], cam: &Camera, by_region: bool) -> ViewError {
    let screen = ScreenProjection::new(cam);
    let frustum = cam.frustum();
    let eye = cam.position_m;
    let most = |error_m: f64, dist_m: f64| screen.most_px(error_m, dist_m);
    let mut order: Vec<(f64, &ErrorSamples)> = nodes
        .iter()
        .filter(|s| frustum.intersects_aabb(s.min_m, s.max_m))
        .map(|s| {
            let d = crate::camera::distance_to_aabb(eye, s.min_m, s.max_m);
            (most(s.max_error_m(), d), *s)
        })
        .collect();
    order.sort_by(|a, b| b.0.total_cmp(&a.0));
    let (mut best, mut region_max_px, mut samples) = (0.0f64, [0.0f64; 3], 0u64);
    for (bound, s) in order {
        if !by_region && bound <= best {
            break;
        }
        let d_min = crate::camera::distance_to_aabb(eye, s.min_m, s.max_m);
        for p in &s.samples {
            let err = f64::from(p[3].abs());
            if !by_region && most(err, d_min) <= best {
                break; // sorted by error: no later sample can beat `best`
            }
            let (x, y) = (
                s.origin_m[0] + f64::from(p[0]),
                s.origin_m[1] + f64::from(p[1]),
            );
            let truth = DVec3::new(x, y, f64::from(p[2]));
            let drawn = DVec3::new(x, y, f64::from(p[2]) + f64::from(p[3]));
            if let Some((len, at)) = screen.segment_px(truth, drawn) {
                samples += 1;
                best = best.max(len);
                let region = screen.region(at) as usize;
                region_max_px[region] = region_max_px[region].max(len);
            }
        }
    }
    ViewError {
        max_px: best,
        samples,
        region_max_px,
        ..ViewError::default()
    }
}

/// What a rendered frame shows at each pixel: the view depth (metres along the camera's axis)
/// of the nearest thing drawn there, infinite where nothing was drawn; rows top first. Read from
/// the renderer's depth buffer, it tells which error samples the frame shows and which something
/// drawn in front of them (vegetation, a nearer hill) hides.
#[derive(Debug, Clone)]
pub struct DepthImage {
    size: [u32; 2],
    depth_m: Vec<f32>,
}

/// How much nearer than a point something drawn must be to hide it: this share of the point's
/// depth plus [`HIDDEN_MARGIN_M`] (the drawn terrain under a sample, rasterized at pixel
/// centres, must never count as hiding it).
pub const HIDDEN_MARGIN: f64 = 0.01;
/// See [`HIDDEN_MARGIN`].
pub const HIDDEN_MARGIN_M: f64 = 0.05;

impl DepthImage {
    /// From a reversed-Z depth buffer with an infinite far plane (`near_m / view depth`, 0
    /// where nothing was drawn), as `render::Target::read_depth` returns it.
    pub fn from_reversed_z(size: [u32; 2], z: &[f32], near_m: f64) -> Self {
        assert_eq!(
            z.len(),
            size[0] as usize * size[1] as usize,
            "one depth value per pixel"
        );
        let depth_m = z
            .iter()
            .map(|&z| {
                if z > 0.0 {
                    (near_m / f64::from(z)) as f32
                } else {
                    f32::INFINITY
                }
            })
            .collect();
        Self { size, depth_m }
    }

    /// The farthest depth drawn in the 3 x 3 pixels around pixel position `at` (x right, y down),
    /// so that a point between pixel centres is judged by the least hiding of its neighbours.
    fn farthest_around_m(&self, at: [f64; 2]) -> f64 {
        let (w, h) = (i64::from(self.size[0]), i64::from(self.size[1]));
        let (cx, cy) = (at[0].floor() as i64, at[1].floor() as i64);
        let mut far = f64::NEG_INFINITY;
        for y in (cy - 1).max(0)..=(cy + 1).min(h - 1) {
            for x in (cx - 1).max(0)..=(cx + 1).min(w - 1) {
                far = far.max(f64::from(self.depth_m[(y * w + x) as usize]));
            }
        }
        far
    }
}

/// The on-screen error of the samples a rendered frame shows (as [`view_max_error_px`]
/// measures each sample), and how many samples on the screen it hides. A sample counts when its
/// true or its drawn point lies on the screen and is not hidden there (or when both lie off the
/// screen and the segment between them crosses it): hidden means everything
/// `depth` shows in the 3 x 3 pixels around the point's pixel is nearer than the point by more
/// than [`HIDDEN_MARGIN`] of its depth plus [`HIDDEN_MARGIN_M`]. The margins and the
/// neighbourhood lean towards counting a sample as shown, so the error found can only be larger
/// than what the frame shows.
pub fn view_error_shown_px(
    nodes: &[&ErrorSamples],
    cam: &Camera,
    depth: &DepthImage,
) -> (ViewError, u64) {
    let screen = ScreenProjection::new(cam);
    let frustum = cam.frustum();
    // None when the point is off the screen.
    let shown = |p: DVec3| {
        let depth_m = screen.clip(p).w;
        screen.pixel_of(p).map(|at| {
            depth.farthest_around_m(at) >= depth_m * (1.0 - HIDDEN_MARGIN) - HIDDEN_MARGIN_M
        })
    };
    let (mut px, mut region_max_px, mut hidden) = (Vec::new(), [0.0f64; 3], 0u64);
    for s in nodes
        .iter()
        .filter(|s| frustum.intersects_aabb(s.min_m, s.max_m))
    {
        for p in &s.samples {
            let (x, y) = (
                s.origin_m[0] + f64::from(p[0]),
                s.origin_m[1] + f64::from(p[1]),
            );
            let truth = DVec3::new(x, y, f64::from(p[2]));
            let drawn = DVec3::new(x, y, f64::from(p[2]) + f64::from(p[3]));
            let Some((len, at)) = screen.segment_px(truth, drawn) else {
                continue;
            };
            // A segment that crosses the screen with both ends off it counts as shown.
            let ends = [shown(drawn), shown(truth)];
            if ends.contains(&Some(true)) || ends == [None, None] {
                let region = screen.region(at) as usize;
                region_max_px[region] = region_max_px[region].max(len);
                px.push(len);
            } else {
                hidden += 1;
            }
        }
    }
    (ViewError::of(px, region_max_px), hidden)
}

/// A CDLOD-style selection: split a node while the camera is closer than
/// `ratio * node size` to its box (one distance ratio for every level, no error metric), with
/// the same frustum culling. This is the baseline "uniform distance selection".
pub fn select_by_distance(
    world: &World,
    tree: &QuadTree,
    cache: &mut BoundsCache,
    cam: &Camera,
    ratio: f64,
) -> Selection {
    traverse(
        tree,
        cam,
        true,
        |key| cache.get(world, tree, key),
        |key, _, dist, _| dist < ratio * tree.node_size_m(key.level),
    )
}

/// A reproducible flight over a map: a low pass along a valley-height line, then a climb to a
/// high overview, looking ahead and down. `frames` cameras.
pub fn default_flight(world: &World, frames: usize, viewport_px: [u32; 2]) -> Vec<Camera> {
    let o = world.origin_m();
    let s = world.size_m();
    let frames = frames.max(2);
    (0..frames)
        .map(|f| {
            let t = f as f64 / (frames - 1) as f64;
            let x = o[0] + s[0] * (0.15 + 0.6 * t);
            let y = o[1] + s[1] * (0.25 + 0.45 * t + 0.05 * (t * 9.0).sin());
            let ground = world.height_m(x, y);
            // Low (25 m) for the first half, then climbing to 40% of the map size.
            let climb = ((t - 0.5) / 0.5).clamp(0.0, 1.0);
            let above = 25.0 + climb * climb * 0.4 * s[0].max(s[1]);
            let pos = DVec3::new(x, y, ground + above);
            let ahead = DVec3::new(s[0] * 0.6, s[1] * 0.45, 0.0).normalize();
            let pitch = -(0.12 + 0.5 * climb);
            let dir = DVec3::new(ahead.x * pitch.cos(), ahead.y * pitch.cos(), pitch.sin());
            Camera::look_at(pos, pos + dir, 60f64.to_radians(), viewport_px)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::{DepthImage, ErrorSamples, SAMPLE_OFFSET, ScreenProjection, view_error_shown_px};
    use crate::camera::Camera;
    use crate::terrain::bounds::CHECK_SUBDIV;
    use glam::DVec3;

    /// A wall drawn 10 m ahead over the screen's left half: a sample 20 m ahead on the left is
    /// hidden, one on the right and one 5 m ahead on the left are shown, and the shown error is
    /// the largest of the two shown samples' own projected lengths.
    #[test]
    fn samples_behind_something_drawn_are_hidden() {
        let cam = Camera::look_at(DVec3::ZERO, DVec3::X, 60f64.to_radians(), [64, 32]);
        // Screen left is +y for a camera looking along +x with z up.
        let (w, h) = (64usize, 32usize);
        let wall_z = (cam.near_m / 10.0) as f32;
        let z: Vec<f32> = (0..w * h)
            .map(|i| if i % w < w / 2 { wall_z } else { 0.0 })
            .collect();
        let depth = DepthImage::from_reversed_z([64, 32], &z, cam.near_m);
        // (x, y, surface z, error): largest error first, as node_error_samples sorts them.
        let points = [
            [20.0f32, 3.0, 0.0, 0.5],
            [20.0, -3.0, 0.0, 0.2],
            [5.0, 1.0, 0.0, 0.1],
        ];
        let node = ErrorSamples {
            min_m: DVec3::new(0.0, -5.0, -1.0),
            max_m: DVec3::new(30.0, 5.0, 1.0),
            origin_m: [0.0, 0.0],
            samples: points.to_vec(),
        };
        let (shown, hidden) = view_error_shown_px(&[&node], &cam, &depth);
        assert_eq!(hidden, 1);
        assert_eq!(shown.samples, 2);
        let screen = ScreenProjection::new(&cam);
        let length = |p: [f32; 4]| {
            let at = DVec3::new(f64::from(p[0]), f64::from(p[1]), 0.0);
            screen
                .segment_px(at, at + DVec3::Z * f64::from(p[3]))
                .expect("on the screen")
                .0
        };
        let expected = length(points[1]).max(length(points[2]));
        assert!((shown.max_px - expected).abs() < 1e-9);
        assert!(
            length(points[0]) > expected,
            "the hidden sample was the largest"
        );
    }

    /// Inner samples of `true_node_error` never land on a check-lattice point, for any number
    /// of samples per quad up to 64 (the old half-step offset did at 2 per quad: 0.25, 0.75).
    #[test]
    fn samples_avoid_the_check_lattice() {
        for per_quad in 1..=64u32 {
            for i in 0..per_quad {
                let in_quads = (f64::from(i) + SAMPLE_OFFSET) / f64::from(per_quad);
                let on_check = in_quads * f64::from(CHECK_SUBDIV);
                assert!(
                    (on_check - on_check.round()).abs() > 1e-6,
                    "{per_quad} per quad: sample {i} is on the check lattice"
                );
            }
        }
    }
}
