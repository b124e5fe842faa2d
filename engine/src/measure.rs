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
use glam::DVec3;

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
    visit_samples(world, tree, m, per_quad, |[i, j], _, f, err| {
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
            visit([i, j], d, f, (surface.height_at(x, y) - f).abs());
        }
    }
}

/// On-screen error of a view: for points on a lattice of `per_side` x `per_side` in every drawn
/// node that lie in front of the camera, `|mesh - surface| * K / distance`, the mesh sampled
/// through its own triangles (grid or TIN).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ViewError {
    pub max_px: f64,
    pub mean_px: f64,
    pub samples: u64,
}

pub fn view_error(
    world: &World,
    tree: &QuadTree,
    meshes: &[NodeMesh],
    cam: &Camera,
    per_side: u32,
) -> ViewError {
    let k = cam.k_px();
    let frustum = cam.frustum();
    let (mut max_px, mut sum, mut samples) = (0.0f64, 0.0f64, 0u64);
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
                let f = world.height_m(x, y);
                let p = DVec3::new(x, y, f);
                // Only points inside the view frustum count (a point is a degenerate box).
                if !frustum.intersects_aabb(p, p) {
                    continue;
                }
                let px = (surface.height_at(x, y) - f).abs() * k
                    / (p - cam.position_m).length().max(1e-9);
                max_px = max_px.max(px);
                sum += px;
                samples += 1;
            }
        }
    }
    ViewError {
        max_px,
        mean_px: if samples > 0 {
            sum / samples as f64
        } else {
            0.0
        },
        samples,
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
    /// (x, y relative to `origin_m`, surface z, |mesh - surface|), largest error first; samples
    /// with zero error are left out.
    samples: Vec<[f32; 4]>,
}

impl ErrorSamples {
    /// The largest error of any sample (m).
    pub fn max_error_m(&self) -> f64 {
        self.samples.first().map_or(0.0, |s| f64::from(s[3]))
    }
}

/// Measures `|mesh - surface|` (the mesh through its own triangles) on a lattice of `per_quad`
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
    visit_samples(world, tree, m, per_quad, |_, [dx, dy], f, err| {
        z_lo = z_lo.min(f);
        z_hi = z_hi.max(f);
        if err > 0.0 {
            samples.push([dx as f32, dy as f32, f as f32, err as f32]);
        }
    });
    samples.sort_by(|a, b| b[3].total_cmp(&a[3]));
    ErrorSamples {
        // f32 positions: widen the box by their rounding so it still holds every sample.
        min_m: DVec3::new(r.min[0], r.min[1], z_lo - z_lo.abs() * 1e-6 - 1e-6),
        max_m: DVec3::new(r.max[0], r.max[1], z_hi + z_hi.abs() * 1e-6 + 1e-6),
        origin_m: r.min,
        samples,
    }
}

/// The largest on-screen error `|mesh - surface| * K / distance` over the samples of the given
/// nodes that lie in the view frustum: exact over the samples, found by branch and bound (a node
/// is skipped once its largest error over its box distance cannot beat the best so far).
pub fn view_max_error_px(nodes: &[&ErrorSamples], cam: &Camera) -> f64 {
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
            let err = f64::from(p[3]);
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
    use super::SAMPLE_OFFSET;
    use crate::terrain::bounds::CHECK_SUBDIV;

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
