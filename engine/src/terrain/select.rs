//! Per-frame node selection: split a node while its projected error exceeds the pixel
//! threshold; cull by the view frustum against node AABBs.
//!
//! A node's projected error is the largest over its bound blocks of the block's error as it can
//! appear on the screen ([`ScreenBound`]: `error_m * K / dist_m` times the stretch a flat screen
//! gives off its axis, with `K = viewport_height_px / (2 tan(fovy / 2))` and `dist_m` the
//! distance from the camera to the nearest point of the block's box), and at least the
//! vegetation term with the node's box; see [`projected_error_px`]. When culling, blocks outside
//! the view frustum show nothing and do not count.

use crate::camera::{ALL_PLANES, Camera, Frustum, Planes, distance_to_aabb};
use crate::surface::world::World;
use crate::terrain::bounds::{BLOCKS_PER_SIDE, BoundsCache, NodeBounds, block_rect};
use crate::terrain::mesh::MAX_DECIMATION;
use crate::terrain::quadtree::{NodeKey, QuadTree};
pub use crate::terrain::screen_bound::{ScreenBound, Stretch};
use glam::DVec3;
use smallvec::SmallVec;
use std::borrow::Borrow;

/// The world-space box of a node.
pub fn node_aabb(tree: &QuadTree, key: NodeKey, b: &NodeBounds) -> (DVec3, DVec3) {
    let r = tree.rect(key);
    (
        DVec3::new(r.min[0], r.min[1], b.z_min_m),
        DVec3::new(r.max[0], r.max[1], b.z_max_m),
    )
}

/// The world-space box of block `index` of a node.
pub fn block_aabb(tree: &QuadTree, key: NodeKey, b: &NodeBounds, index: usize) -> (DVec3, DVec3) {
    let r = block_rect(tree, key, index);
    let block = &b.blocks[index];
    (
        DVec3::new(r.min[0], r.min[1], block.z_min_m),
        DVec3::new(r.max[0], r.max[1], block.z_max_m),
    )
}

/// A node's projected error bound in pixels on the screen of `screen`: the largest over its
/// blocks (those that may be in `frustum`, when given) of the block error as [`ScreenBound`]
/// bounds it on the screen from the block's box, and the vegetation error likewise from the node's
/// box. Distances are taken as at least `near_m`; a distance of 0 (the eye inside a box that
/// counts) gives infinity.
pub fn projected_error_px(
    tree: &QuadTree,
    key: NodeKey,
    b: &NodeBounds,
    screen: &ScreenBound,
    frustum: Option<&Frustum>,
    near_m: f64,
) -> f64 {
    projected_error_in_px(tree, key, b, screen, frustum, near_m, PxWindow::EXACT)
}

/// Where a caller needs a projected error exactly: below `floor_px` only that it is at or
/// below the floor, above `ceiling_px` only that it is above the ceiling (a split test against
/// a threshold needs the threshold as both).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PxWindow {
    pub floor_px: f64,
    pub ceiling_px: f64,
}

impl PxWindow {
    /// Exact everywhere.
    pub const EXACT: Self = Self {
        floor_px: 0.0,
        ceiling_px: f64::INFINITY,
    };
}

/// [`projected_error_px`] exact only inside `window`: exact when the error is in
/// (`floor_px`, `ceiling_px`]; at or below the floor some value at or below it; above the
/// ceiling some value above it (at most the error). Blocks whose
/// error cannot pass the floor even at the node box's distance need no box of their own, so
/// a node well under the threshold costs a few comparisons; the first block over the ceiling
/// ends the search, so a node well over it costs little more.
pub fn projected_error_in_px(
    tree: &QuadTree,
    key: NodeKey,
    b: &NodeBounds,
    screen: &ScreenBound,
    frustum: Option<&Frustum>,
    near_m: f64,
    window: PxWindow,
) -> f64 {
    let (lo, hi) = node_aabb(tree, key, b);
    let node_dist_m = distance_to_aabb(screen.eye_m, lo, hi);
    projected_error_at(
        tree,
        key,
        b,
        (lo, hi),
        node_dist_m,
        screen,
        PxPerM::UNBOUNDED,
        frustum.map(|f| (f, ALL_PLANES)),
        near_m,
        window,
    )
    .0
}

/// [`projected_error_in_px`] with the node's box (as [`node_aabb`] gives it) and the distance
/// from the eye to it given (`node_dist_m`, as [`distance_to_aabb`] finds it), for a caller
/// that has them already, and
/// the frustum with the planes the node's box crosses (as [`Frustum::classify_aabb`] found
/// them): a block within the node's box is tested against those planes only.
fn projected_error_at(
    tree: &QuadTree,
    key: NodeKey,
    b: &NodeBounds,
    node_box: (DVec3, DVec3),
    node_dist_m: f64,
    screen: &ScreenBound,
    upper: PxPerM,
    frustum: Option<(&Frustum, Planes)>,
    near_m: f64,
    window: PxWindow,
) -> (f64, PxPerM) {
    let k_px = screen.k_px();
    let per_m = |stretch: Stretch, dist_m: f64| PxPerM::of(stretch, dist_m, k_px, near_m);
    // A node that cannot pass the floor even with the screen's largest stretch (or the bound
    // an ancestor's box gives, which holds for its points too) needs no box of its own.
    let most = per_m(screen.most_stretch(), node_dist_m).min(upper);
    let at_most = px(b.error_m, most.vertical).max(px(b.vegetation_error_m, most.any));
    if at_most <= window.floor_px {
        return (at_most, most);
    }
    // The off-axis stretch anywhere in the node's box (never over the screen's largest): no
    // block's is larger (a block's box is within the node's, and its own bound is capped by the
    // node's). Not capped by the ancestor's bound: an exact error is the node's own, whichever
    // way it is reached.
    let node = per_m(
        screen.stretch(node_box.0, node_box.1, node_dist_m),
        node_dist_m,
    );
    // Vegetation's error may point any way: the isotropic stretch.
    let mut out = px(b.vegetation_error_m, node.any);
    if out > window.ceiling_px {
        return (out, node);
    }
    // What a block must pass to change the answer: the largest error so far, or the floor.
    let mut cut = out.max(window.floor_px);
    // A block's box lies inside the node's, so the node's pixels per metre hold for it: a
    // block whose error is at most `skip_m` cannot pass the cut and is skipped without its box.
    // `skip_m` is a little below `cut` over the node's pixels per metre, so a block skipped is
    // one whose error with the node's bound is at most the cut; near the boundary the block is
    // taken and measured exactly, so the answer is the same as without skipping.
    let skip_below = |cut: f64| cut / node.vertical * (1.0 - 8.0 * f64::EPSILON);
    let mut skip_m = skip_below(cut);
    // The node's error is its largest block's: a node that cannot pass with its own bound
    // needs no block at all.
    debug_assert!(b.blocks.iter().all(|x| x.error_m <= b.error_m), "{key:?}");
    if b.error_m <= skip_m {
        return (out, node);
    }
    for (i, block) in b.blocks.iter().enumerate() {
        if block.error_m <= skip_m.max(0.0) {
            continue;
        }
        let (lo, hi) = block_aabb(tree, key, b, i);
        // The block's own bound, or the node's where that is smaller (it holds for the
        // block's points too).
        let dist_m = distance_to_aabb(screen.eye_m, lo, hi);
        let own = per_m(screen.stretch(lo, hi, dist_m), dist_m);
        let block_px = px(block.error_m, own.vertical.min(node.vertical));
        // The frustum test (the costlier part) only for blocks that would pass the cut, and
        // only against the planes the node's box crosses when the block's box is within it.
        let outside = |(f, crossed): (&Frustum, Planes)| {
            let planes = planes_within(
                crossed,
                (b.z_min_m, b.z_max_m),
                (block.z_min_m, block.z_max_m),
            );
            planes != 0 && f.classify_aabb(lo, hi, planes).is_none()
        };
        if block_px <= cut || frustum.is_some_and(outside) {
            continue;
        }
        out = block_px;
        if out > window.ceiling_px {
            return (out, node);
        }
        cut = out;
        skip_m = skip_below(cut);
    }
    (out, node)
}

/// The most pixels a metre of error can show anywhere in a box: for a vertical error and for
/// one of any direction (a [`Stretch`] over the box's distance, times `K`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PxPerM {
    pub vertical: f64,
    pub any: f64,
}

impl PxPerM {
    /// No bound known.
    pub const UNBOUNDED: Self = Self {
        vertical: f64::INFINITY,
        any: f64::INFINITY,
    };

    /// `stretch` over a box `dist_m` away (at least `near_m`; infinite at 0), times `k_px`.
    fn of(stretch: Stretch, dist_m: f64, k_px: f64, near_m: f64) -> Self {
        let d = dist_m.max(near_m);
        let per = |s: f64| if d > 0.0 { s * k_px / d } else { f64::INFINITY };
        Self {
            vertical: per(stretch.vertical),
            any: per(stretch.any),
        }
    }

    /// The smaller of two bounds of the same points (both hold, so their minimum does).
    fn min(self, other: Self) -> Self {
        Self {
            vertical: self.vertical.min(other.vertical),
            any: self.any.min(other.any),
        }
    }
}

/// An error of `error_m` at `per_m` pixels per metre: 0 without error.
fn px(error_m: f64, per_m: f64) -> f64 {
    if error_m <= 0.0 { 0.0 } else { error_m * per_m }
}

/// The frustum planes a box may cross whose plan lies within an outer box's, given the planes
/// `crossed` by the outer box: those when its height range (`inner_z_m`) lies within the
/// outer's (`outer_z_m`), else all (a box inside a plane has every box within it inside).
fn planes_within(crossed: Planes, outer_z_m: (f64, f64), inner_z_m: (f64, f64)) -> Planes {
    if inner_z_m.0 >= outer_z_m.0 && inner_z_m.1 <= outer_z_m.1 {
        crossed
    } else {
        ALL_PLANES
    }
}

/// How many halvings of its grid mesh's vertex spacing node `key` may be drawn with (at most
/// [`MAX_DECIMATION`]) at threshold `tau_px` on the screen of `screen`.
///
/// Drawn with `d` halvings, the node shows its level-`L - d` ancestor's mesh over its own
/// square (see [`crate::terrain::mesh`]), whose error there is bounded by the ancestor's blocks
/// covering that square (each block's error projected from its own box, as in
/// [`projected_error_px`], without frustum culling). `bounds` gives the ancestors' bounds; an
/// unknown one stops the search. The node's own vegetation is drawn as before, so its term
/// does not change.
pub fn decimation<B: Borrow<NodeBounds>>(
    tree: &QuadTree,
    key: NodeKey,
    screen: &ScreenBound,
    near_m: f64,
    tau_px: f64,
    mut bounds: impl FnMut(NodeKey) -> Option<B>,
) -> u8 {
    let mut out = 0;
    let mut ancestor = key;
    for d in 1..=MAX_DECIMATION.min(key.level) {
        let Some(a) = ancestor.parent() else { break };
        ancestor = a;
        let Some(owned) = bounds(a) else { break };
        let b = owned.borrow();
        // The ancestor's blocks over the node: `per x per` of them from (ox, oy).
        let per = BLOCKS_PER_SIDE >> d;
        let cell = |i: u32| (i % (1 << d)) as usize * per;
        let (ox, oy) = (cell(key.ix), cell(key.iy));
        let within = (oy..oy + per).all(|by| {
            (ox..ox + per).all(|bx| {
                let i = by * BLOCKS_PER_SIDE + bx;
                let (lo, hi) = block_aabb(tree, a, b, i);
                let dist_m = distance_to_aabb(screen.eye_m, lo, hi);
                let e = b.blocks[i].error_m;
                let shows = |stretch: Stretch| {
                    px(
                        e,
                        PxPerM::of(stretch, dist_m, screen.k_px(), near_m).vertical,
                    )
                };
                // The box's own stretch only where the screen's largest does not do.
                shows(screen.most_stretch()) <= tau_px
                    || shows(screen.stretch(lo, hi, dist_m)) <= tau_px
            })
        });
        if !within {
            break;
        }
        out = d;
    }
    out
}

/// One selected node.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Selected {
    pub key: NodeKey,
    pub bounds: NodeBounds,
    pub dist_m: f64,
    /// Projected error bound in pixels at `dist_m`: exact within the window the selection was
    /// made with ([`select`]: exact above tau; at or below tau some value at or below it).
    pub error_px: f64,
    /// Halvings of the vertex spacing its grid mesh is drawn with ([`decimation`]; 0 unless the
    /// selection was asked for them).
    pub decimation: u8,
}

/// The result of one selection.
#[derive(Debug, Clone, Default)]
pub struct Selection {
    pub nodes: Vec<Selected>,
    pub visited: u32,
    pub culled: u32,
    /// Nodes reached whose bounds are not known yet (only when the bounds source may not know
    /// them, as during streaming): kept as they are, not culled or descended into.
    pub unknown_bounds: Vec<NodeKey>,
    /// Selected nodes at the finest level whose error bound still exceeds the threshold (the
    /// engine has no finer data there; reported, never hidden).
    pub over_tau_at_finest: u32,
}

impl Selection {
    /// Adds what a [`walk`] reached: a selected node (its bounds copied), or one whose bounds
    /// are unknown.
    fn add<B: Borrow<NodeBounds>>(&mut self, reached: Reached<B>) {
        match reached {
            Reached::Selected {
                key,
                bounds,
                dist_m,
                error_px,
            } => self.nodes.push(Selected {
                key,
                bounds: *bounds.borrow(),
                dist_m,
                error_px,
                decimation: 0,
            }),
            Reached::Unknown(key) => self.unknown_bounds.push(key),
        }
    }
}

/// Selection settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SelectParams {
    /// The user's detail level: largest projected error in pixels.
    pub tau_px: f64,
    /// Finest level to descend to (the tree's `max_level` normally; lower for debugging).
    pub max_level: u8,
    /// Frustum culling on (off: select everywhere, e.g. for shadow or debug).
    pub cull: bool,
    /// Find each node's [`decimation`] (off: every node is drawn through all its vertices).
    pub decimate: bool,
    /// Bound the stretch a flat screen gives an error off its axis ([`ScreenBound::new`]); off:
    /// the on-axis model `error_m * K / dist_m` ([`ScreenBound::on_axis`]), which the screen
    /// exceeds away from its centre, kept to measure what the stretch costs.
    pub off_axis: bool,
}

impl SelectParams {
    /// The usual selection: threshold `tau_px`, down to the tree's finest level, culled.
    pub fn culled(tau_px: f64, tree: &QuadTree) -> Self {
        Self {
            tau_px,
            max_level: tree.max_level,
            cull: true,
            decimate: true,
            off_axis: true,
        }
    }
}

/// The traversal every selection shares: depth-first from the root, skipping nodes outside the
/// map, culling by the frustum (when `cull`), and descending while `split(key, bounds, dist_m,
/// error_px)` says so (never below the finest level). `bounds` gives each visited node's
/// bounds; a node whose bounds are unknown (`None`) goes to `unknown_bounds`.
pub fn traverse<B: Into<Option<NodeBounds>>>(
    tree: &QuadTree,
    cam: &Camera,
    cull: bool,
    bounds: impl FnMut(NodeKey) -> B,
    split: impl FnMut(NodeKey, &NodeBounds, f64, f64) -> bool,
) -> Selection {
    traverse_in(tree, cam, cull.then(|| cam.frustum()), bounds, split)
}

/// [`traverse`] culling by `frustum` (none: no culling), which may differ from the camera's
/// own (a guard band); pixel errors are on the camera's screen.
pub fn traverse_in<B: Into<Option<NodeBounds>>>(
    tree: &QuadTree,
    cam: &Camera,
    frustum: Option<Frustum>,
    mut bounds: impl FnMut(NodeKey) -> B,
    split: impl FnMut(NodeKey, &NodeBounds, f64, f64) -> bool,
) -> Selection {
    let mut out = Selection::default();
    let walked = walk(
        tree,
        &ScreenBound::new(cam),
        frustum,
        PxWindow::EXACT,
        ByKey(|key| bounds(key).into()),
        split,
        |reached| out.add(reached),
    );
    out.visited = walked.visited;
    out.culled = walked.culled;
    out
}

/// Where a [`walk`] finds the bounds of the nodes it visits.
pub trait WalkBounds {
    /// What the source gives for a node: its bounds, owned or lent.
    type Found: Borrow<NodeBounds>;

    /// The bounds of node `key`; `None` when not known.
    fn get(&mut self, key: NodeKey) -> Option<Self::Found>;

    /// The bounds of `child`, a child of the node whose bounds this source gave as `parent`:
    /// looked up by key, unless the source keeps links from a node to its children.
    fn child(&mut self, parent: &Self::Found, child: NodeKey) -> Option<Self::Found> {
        let _ = parent;
        self.get(child)
    }
}

/// A [`WalkBounds`] that looks every node up by key with a function.
pub struct ByKey<F>(pub F);

impl<B: Borrow<NodeBounds>, F: FnMut(NodeKey) -> Option<B>> WalkBounds for ByKey<F> {
    type Found = B;

    fn get(&mut self, key: NodeKey) -> Option<B> {
        (self.0)(key)
    }
}

/// What [`walk`] reached: a selected node with its bounds (as the bounds source gave them),
/// distance and projected error, or a node whose bounds are unknown.
#[derive(Debug)]
pub enum Reached<B> {
    Selected {
        key: NodeKey,
        bounds: B,
        dist_m: f64,
        error_px: f64,
    },
    Unknown(NodeKey),
}

/// Nodes a [`walk`] visited and culled.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Walked {
    pub visited: u32,
    pub culled: u32,
}

/// Entries a depth-first walk of the tree ([`walk`], the streamer's draw-list walk) keeps on
/// the call stack: three siblings per level of a 20-level tree and the node popped (a deeper
/// tree spills to the heap).
pub(crate) const WALK_STACK_INLINE: usize = 64;

/// The traversal of [`traverse_in`], handing each node it reaches to `reached` instead of
/// collecting them, with the bounds as `bounds` gives them: a source that lends its bounds
/// (`&NodeBounds`) lets a per-frame selection run without copying any, and one that links a
/// node to its children finds them without a lookup by key. Projected errors are
/// exact inside `window` only ([`projected_error_in_px`]): a caller that splits at a threshold
/// passes it as the floor, and as the ceiling when no larger error matters to it.
pub fn walk<S: WalkBounds>(
    tree: &QuadTree,
    screen: &ScreenBound,
    frustum: Option<Frustum>,
    window: PxWindow,
    mut bounds: S,
    mut split: impl FnMut(NodeKey, &NodeBounds, f64, f64) -> bool,
    mut reached: impl FnMut(Reached<S::Found>),
) -> Walked {
    let mut out = Walked::default();
    // Each node's bounds are looked up when it is pushed, a split node's children one after
    // another: no lookup waits for another's result, so their cache misses can overlap. Each
    // entry carries the frustum planes its box may cross: those its parent's box crossed when
    // its box lies within the parent's (a box inside a plane has every box within it inside).
    // The stack is depth first, so it holds at most three siblings per level below the root
    // and the node popped: it lives on the call stack for any tree of up to 20 levels (a heap
    // vector grown in each walk reallocated three or four times a call, and glibc consolidated
    // its free lists for the larger blocks, in the frame thread).
    let mut stack: SmallVec<[_; WALK_STACK_INLINE]> = SmallVec::new();
    if tree.overlaps_map(NodeKey::ROOT) {
        stack.push((
            NodeKey::ROOT,
            bounds.get(NodeKey::ROOT),
            ALL_PLANES,
            PxPerM::UNBOUNDED,
        ));
    }
    while let Some((key, found, planes, upper)) = stack.pop() {
        out.visited += 1;
        let Some(owned) = found else {
            reached(Reached::Unknown(key));
            continue;
        };
        let b = owned.borrow();
        let (min, max) = node_aabb(tree, key, b);
        let crossed = match &frustum {
            Some(f) if planes != 0 => f.classify_aabb(min, max, planes),
            _ => Some(planes),
        };
        let Some(crossed) = crossed else {
            out.culled += 1;
            continue;
        };
        let dist_m = distance_to_aabb(screen.eye_m, min, max);
        let (error_px, per_m) = projected_error_at(
            tree,
            key,
            b,
            (min, max),
            dist_m,
            screen,
            upper,
            frustum.as_ref().map(|f| (f, crossed)),
            0.0,
            window,
        );
        if key.level < tree.max_level && split(key, b, dist_m, error_px) {
            // Children pushed in reverse so the output is in SW, SE, NW, NE order; those
            // outside the map are skipped.
            for c in key.children().into_iter().rev() {
                if tree.overlaps_map(c) {
                    let found = bounds.child(&owned, c);
                    let planes = found.as_ref().map_or(ALL_PLANES, |cb| {
                        let cb = cb.borrow();
                        planes_within(crossed, (b.z_min_m, b.z_max_m), (cb.z_min_m, cb.z_max_m))
                    });
                    stack.push((c, found, planes, per_m));
                }
            }
        } else {
            reached(Reached::Selected {
                key,
                bounds: owned,
                dist_m,
                error_px,
            });
        }
    }
    out
}

/// Selects the nodes to draw for `cam`: split while the projected error exceeds `tau_px`.
pub fn select(
    world: &World,
    tree: &QuadTree,
    cache: &mut BoundsCache,
    cam: &Camera,
    p: SelectParams,
) -> Selection {
    select_occluded(world, tree, cache, cam, p, None)
}

/// Like [`select`], and with a canopy splits less where vegetation blocks the view: a node's
/// projected error is multiplied by [`crate::vegetation::Canopy::error_factor`] before the
/// comparison with tau.
pub fn select_occluded(
    world: &World,
    tree: &QuadTree,
    cache: &mut BoundsCache,
    cam: &Camera,
    p: SelectParams,
    canopy: Option<&crate::vegetation::Canopy>,
) -> Selection {
    let screen = if p.off_axis {
        ScreenBound::new(cam)
    } else {
        ScreenBound::on_axis(cam)
    };
    // The split test needs the errors exactly only about tau, and above it where a canopy may
    // lower them.
    let window = PxWindow {
        floor_px: p.tau_px,
        ceiling_px: if canopy.is_some() {
            f64::INFINITY
        } else {
            p.tau_px
        },
    };
    let mut split = |key: NodeKey, b: &NodeBounds, dist: f64, px: f64| {
        px > p.tau_px
            && key.level < p.max_level
            && canopy.is_none_or(|c| {
                px * c.error_factor(world, cam.position_m, tree.rect(key), b.z_max_m, dist)
                    > p.tau_px
            })
    };
    let frustum = p.cull.then(|| cam.frustum());
    // The walk borrows the cached bounds (no copy per node); nodes it reaches whose bounds are
    // not measured yet are measured and the walk is made again (a warm cache walks once).
    let mut out = loop {
        let mut sel = Selection::default();
        let walked = walk(
            tree,
            &screen,
            frustum,
            window,
            ByKey(|key| cache.lend(key)),
            &mut split,
            |reached| sel.add(reached),
        );
        if sel.unknown_bounds.is_empty() {
            sel.visited = walked.visited;
            sel.culled = walked.culled;
            break sel;
        }
        for key in sel.unknown_bounds {
            cache.get(world, tree, key);
        }
    };
    // A node kept over tau (at the finest level) reports its whole bound, not only that it is
    // over tau.
    for s in out.nodes.iter_mut().filter(|s| s.error_px > p.tau_px) {
        s.error_px = projected_error_px(tree, s.key, &s.bounds, &screen, frustum.as_ref(), 0.0);
    }
    out.over_tau_at_finest = out.nodes.iter().filter(|s| s.error_px > p.tau_px).count() as u32;
    if p.decimate {
        // Every selected node's ancestors were walked through, so their bounds are measured.
        decimate(&mut out, tree, &screen, p.tau_px, |k| cache.lend(k));
    }
    out
}

/// Sets every selected node's [`decimation`] at threshold `tau_px` on the screen of `screen`
/// (`bounds` gives the ancestors' bounds).
pub fn decimate<B: Borrow<NodeBounds>>(
    sel: &mut Selection,
    tree: &QuadTree,
    screen: &ScreenBound,
    tau_px: f64,
    mut bounds: impl FnMut(NodeKey) -> Option<B>,
) {
    for s in &mut sel.nodes {
        s.decimation = decimation(tree, s.key, screen, 0.0, tau_px, &mut bounds);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frustum_keeps_boxes_in_front_and_drops_boxes_behind() {
        let cam = Camera::look_at(DVec3::ZERO, DVec3::new(0.0, 100.0, 0.0), 1.0, [640, 480]);
        let f = cam.frustum();
        assert!(f.intersects_aabb(DVec3::new(-1.0, 50.0, -1.0), DVec3::new(1.0, 52.0, 1.0)));
        assert!(!f.intersects_aabb(DVec3::new(-1.0, -52.0, -1.0), DVec3::new(1.0, -50.0, 1.0)));
        assert!(!f.intersects_aabb(DVec3::new(200.0, 50.0, -1.0), DVec3::new(201.0, 52.0, 1.0)));
        // A box around the camera always intersects.
        assert!(f.intersects_aabb(DVec3::splat(-1.0), DVec3::splat(1.0)));
        assert!((cam.k_px() - 480.0 / (2.0 * 0.5f64.tan())).abs() < 1e-9);
    }

    #[test]
    fn aabb_distance_is_zero_inside_and_euclidean_outside() {
        let (lo, hi) = (DVec3::ZERO, DVec3::ONE);
        assert_eq!(distance_to_aabb(DVec3::splat(0.5), lo, hi), 0.0);
        assert!((distance_to_aabb(DVec3::new(4.0, 5.0, 0.5), lo, hi) - 5.0).abs() < 1e-12);
    }

    #[test]
    fn the_error_in_a_window_is_exact_inside_it_and_on_the_right_side_outside() {
        // Random nodes of a 4 km tree (block heights and errors from a fixed-seed generator),
        // random eyes and windows, with and without a frustum: the error equals the largest
        // over all counting blocks taken one by one, and the windowed error is that whenever it
        // is inside the window, else at most the floor below it and over the ceiling (and not
        // over the error) above it.
        let tree = QuadTree::new([0.0, 0.0], [4096.0, 4096.0]);
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut over, mut inside, mut below) = (0, 0, 0);
        for _ in 0..6000 {
            let level = (next() * f64::from(tree.max_level + 1)) as u8;
            let side = 1u32 << level;
            let key = NodeKey {
                level,
                ix: (next() * f64::from(side)) as u32,
                iy: (next() * f64::from(side)) as u32,
            };
            let mut b = NodeBounds::exact(0.0, 0.0);
            b.vegetation_error_m = if next() < 0.5 { 0.0 } else { next() * 2.0 };
            for block in &mut b.blocks {
                block.z_min_m = next() * 300.0;
                block.z_max_m = block.z_min_m + next() * 100.0;
                block.error_m = if next() < 0.2 { 0.0 } else { next() * 8.0 };
            }
            b.error_m = b.blocks.iter().map(|x| x.error_m).fold(0.0, f64::max);
            b.z_min_m = b
                .blocks
                .iter()
                .map(|x| x.z_min_m)
                .fold(f64::INFINITY, f64::min);
            b.z_max_m = b.blocks.iter().map(|x| x.z_max_m).fold(0.0, f64::max);
            let eye = DVec3::new(next() * 4096.0, next() * 4096.0, next() * 600.0);
            let look = DVec3::new(next() * 4096.0, next() * 4096.0, 0.0);
            let cam = Camera::look_at(eye, look, 1.0, [1280, 720]);
            let frustum = cam.frustum();
            let f = (next() < 0.5).then_some(&frustum);
            let screen = if next() < 0.8 {
                ScreenBound::new(&cam)
            } else {
                ScreenBound::on_axis(&cam)
            };
            let k = screen.k_px();
            // The reference: every block that counts, none skipped, each stretched as far as
            // the node's box allows at most.
            let (lo, hi) = node_aabb(&tree, key, &b);
            let node_d = distance_to_aabb(eye, lo, hi);
            let per_m = |stretch, d| PxPerM::of(stretch, d, k, 0.0);
            let node = per_m(screen.stretch(lo, hi, node_d), node_d);
            let mut exact = px(b.vegetation_error_m, node.any);
            for i in 0..b.blocks.len() {
                let (lo, hi) = block_aabb(&tree, key, &b, i);
                if f.is_none_or(|f| f.intersects_aabb(lo, hi)) {
                    let d = distance_to_aabb(eye, lo, hi);
                    let own = per_m(screen.stretch(lo, hi, d), d);
                    let e = b.blocks[i].error_m;
                    exact = exact.max(px(e, own.vertical.min(node.vertical)));
                }
            }
            assert_eq!(
                projected_error_px(&tree, key, &b, &screen, f, 0.0),
                exact,
                "{key:?}"
            );
            let floor = next() * 2.0 * exact.min(1e3) + next();
            let ceiling = if next() < 0.3 {
                f64::INFINITY
            } else {
                floor + next() * exact.min(1e3)
            };
            let window = PxWindow {
                floor_px: floor,
                ceiling_px: ceiling,
            };
            let windowed = projected_error_in_px(&tree, key, &b, &screen, f, 0.0, window);
            if exact > ceiling {
                over += 1;
                assert!(
                    windowed > ceiling && windowed <= exact,
                    "{key:?}: {windowed} for {exact} over the ceiling {ceiling}"
                );
            } else if exact > floor {
                inside += 1;
                assert_eq!(windowed, exact, "{key:?} window {window:?}");
            } else {
                below += 1;
                assert!(
                    windowed <= floor,
                    "{key:?}: {windowed} over the floor {floor}"
                );
            }
        }
        assert!(
            over > 500 && inside > 500 && below > 500,
            "{over} over, {inside} inside, {below} below"
        );
    }
}
