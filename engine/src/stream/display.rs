//! What is drawn: split states that cross-fade between a node and its children, and the draw
//! list with dither intervals that partition [0, 1) at every point.

use super::Streamer;
use crate::camera::Camera;
use crate::terrain::bounds::NodeBounds;
use crate::terrain::mesh::MAX_DECIMATION;
use crate::terrain::quadtree::NodeKey;
use crate::terrain::select::{ScreenBound, WALK_STACK_INLINE};
use rustc_hash::FxHashMap;

/// The bounds of a node's parent, grandparent, ... as far as a decimation looks (`None` where
/// not known).
type Ancestors<'a> = [Option<&'a NodeBounds>; MAX_DECIMATION as usize];

/// One node to draw this frame, with its dither interval (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DrawNode {
    pub key: NodeKey,
    pub dither_lo: f32,
    pub dither_hi: f32,
    /// Halvings of the vertex spacing its grid mesh is drawn with (see
    /// [`crate::terrain::select::decimation`]).
    pub decimation: u8,
}

/// A fade to children that must finish before the parent's projected error reaches tau plans
/// on this share of the frames its error growth since the last frame leaves (the error grows
/// faster than linearly as the camera closes in).
const FADE_MARGIN: f64 = 0.75;

impl Streamer {
    /// Moves every node's split state towards its target (with `dt_s`, the time since the
    /// last frame; without, the states stay) and makes the draw list, in one walk of the
    /// resident tree from the root.
    ///
    /// Target: split when it is an ancestor of wanted nodes and all its children are ready,
    /// merged otherwise (a node merges only once its children have merged). A fade to the
    /// children normally takes [`super::StreamSettings::fade_s`], but never shows the parent
    /// over tau: a fading parent whose projected error grew since the last frame fades fast
    /// enough to finish before it reaches tau at that growth, and one already at tau (a fast
    /// camera, or ground coming into view) is replaced at once.
    ///
    /// Draw list: children take the lower part of their parent's dither interval in
    /// proportion to its split state; the list is front to back in plan view.
    pub(super) fn advance_fades_and_draw(&mut self, dt_s: Option<f64>) {
        // The normal fade step of this frame; none when the states stay.
        let step = dt_s.map(|dt| {
            if self.settings.fade_s > 0.0 {
                (dt / self.settings.fade_s) as f32
            } else {
                1.0
            }
        });
        // Sized like last frame's, so they are not grown node by node.
        let mut fade_px =
            FxHashMap::with_capacity_and_hasher(self.fade_px.len(), rustc_hash::FxBuildHasher);
        let mut drawn = Vec::with_capacity(self.drawn.len());
        // The camera's frustum and pixel bound, made once for the frame's walk.
        let view = self
            .camera
            .map(|cam| (cam, cam.frustum(), ScreenBound::new(&cam)));
        // The new split states: a node the walk does not reach, or whose state reaches 0,
        // has none. (Each node is reached once, after its parent and before its children, so
        // the old states read below are all from the last frame.)
        let mut split: FxHashMap<NodeKey, f32> =
            FxHashMap::with_capacity_and_hasher(self.split.len() + 64, rustc_hash::FxBuildHasher);
        // Each entry carries its dither interval and its ancestors' bounds for the decimation
        // (the walk came through them), so a drawn node needs no lookup of its ancestors.
        // Depth first, so short: on the call stack.
        let mut stack: smallvec::SmallVec<[(NodeKey, f32, f32, Ancestors); WALK_STACK_INLINE]> =
            smallvec::smallvec![(NodeKey::ROOT, 0.0, 1.0, [None; MAX_DECIMATION as usize])];
        while let Some((key, lo, hi, up)) = stack.pop() {
            if !self.shared.tree.overlaps_map(key) {
                continue;
            }
            let Some(r) = self.resident.get(&key) else {
                continue;
            };
            // Whether all its children can be shown: looked up only where it matters (most
            // nodes reached are drawn whole and stay so).
            let mut drawable = None;
            let mut children_drawable =
                || *drawable.get_or_insert_with(|| self.children_drawable(key));
            let s = self.split.get(&key).copied().unwrap_or(0.0);
            let ns = if let Some(step) = step {
                let wants_split = self.show_split.contains(&key) && children_drawable();
                // A node may only merge back once its children are no longer split
                // themselves.
                let children_merged = || {
                    key.children()
                        .iter()
                        .all(|c| self.split.get(c).copied().unwrap_or(0.0) == 0.0)
                };
                let target = if wants_split || !children_merged() {
                    1.0
                } else {
                    0.0
                };
                // Step towards the target (and stay there once reached).
                if target > s {
                    let step = match view
                        .as_ref()
                        .and_then(|(cam, f, screen)| self.error_px(key, cam, f, screen))
                    {
                        Some(px) => {
                            fade_px.insert(key, px);
                            split_step(
                                step,
                                s,
                                px,
                                self.fade_px.get(&key).copied(),
                                self.settings.tau_px,
                            )
                        }
                        None => step,
                    };
                    (s + step).min(target)
                } else {
                    (s - step).max(target)
                }
            } else {
                s
            };
            // Children must be resident to show them at all.
            if ns <= 0.0 || !children_drawable() {
                drawn.push(DrawNode {
                    key,
                    dither_lo: lo,
                    dither_hi: hi,
                    decimation: self.decimation(key, &up, view.as_ref()),
                });
                continue;
            }
            split.insert(key, ns);
            // Children take [lo, lo + ns (hi - lo)); the node keeps the rest.
            let mid = lo + ns * (hi - lo);
            if mid < hi {
                drawn.push(DrawNode {
                    key,
                    dither_lo: mid,
                    dither_hi: hi,
                    decimation: self.decimation(key, &up, view.as_ref()),
                });
            }
            // Popped nearest first, so the list is front to back in plan view.
            let mut below = [None; MAX_DECIMATION as usize];
            below[0] = r.work.bounds.as_ref();
            below[1..].copy_from_slice(&up[..up.len() - 1]);
            for c in self.children_far_to_near(key) {
                stack.push((c, lo, mid, below));
            }
        }
        drop(stack);
        self.split = split;
        if step.is_some() {
            self.fade_px = fade_px;
        }
        self.drawn = drawn;
    }

    /// A resident node's projected error (px) for camera `cam` (its pixel bound `screen`),
    /// inside its view `frustum`.
    fn error_px(
        &self,
        key: NodeKey,
        cam: &Camera,
        frustum: &crate::camera::Frustum,
        screen: &ScreenBound,
    ) -> Option<f64> {
        let b = self.resident.get(&key)?.work.bounds.as_ref()?;
        Some(crate::terrain::select::projected_error_px(
            &self.shared.tree,
            key,
            b,
            screen,
            Some(frustum),
            cam.near_m,
        ))
    }

    /// How coarsely drawn node `key`'s grid may be drawn: its decimation at the display's split
    /// threshold (`show_factor * tau`) for the `view` (camera, frustum and pixel bound), from
    /// its ancestors' bounds (`up`: the parent's, the grandparent's, ... as far as known); 0
    /// when off or without a camera.
    fn decimation(
        &self,
        key: NodeKey,
        up: &Ancestors<'_>,
        view: Option<&(Camera, crate::camera::Frustum, ScreenBound)>,
    ) -> u8 {
        match view {
            Some((cam, _, screen))
                if self.settings.decimate && self.settings.fixed_level.is_none() =>
            {
                crate::terrain::select::decimation(
                    &self.shared.tree,
                    key,
                    screen,
                    cam.near_m,
                    self.settings.show_factor.max(self.settings.split_factor)
                        * self.settings.tau_px,
                    |a| {
                        up.get(usize::from(key.level - a.level) - 1)
                            .copied()
                            .flatten()
                    },
                )
            }
            _ => 0,
        }
    }

    pub(super) fn children_drawable(&self, key: NodeKey) -> bool {
        key.level < self.shared.tree.max_level
            && key
                .children()
                .iter()
                .all(|c| !self.shared.tree.overlaps_map(*c) || self.resident.contains_key(c))
    }

    /// The nodes the display needs or draws, for asking about nodes one by one (no set of
    /// every needed node is built).
    pub fn display_nodes(&self) -> super::DisplayNodes {
        super::DisplayNodes {
            needed: self.needed.clone(),
            drawn: self.drawn.iter().map(|d| d.key).collect(),
        }
    }

    /// The nodes to draw and their dither intervals. Nothing is missing: the root (once ready)
    /// covers everything not covered by ready descendants.
    pub fn draw_list(&self) -> &[DrawNode] {
        &self.drawn
    }

    /// The node's children, the one on the camera's side of both midlines last and the one
    /// across both first: a depth-first walk that takes them in reverse order lists every
    /// node before the nodes it can hide in plan view, so the depth test rejects what a
    /// nearer node covers before it is shaded. Child order without a camera.
    fn children_far_to_near(&self, key: NodeKey) -> [NodeKey; 4] {
        let c = key.children();
        let Some(cam) = self.camera else {
            return c;
        };
        let r = self.shared.tree.rect(key);
        let east = usize::from(cam.position_m.x >= 0.5 * (r.min[0] + r.max[0]));
        let north = usize::from(cam.position_m.y >= 0.5 * (r.min[1] + r.max[1]));
        // Children are SW, SE, NW, NE: index = east + 2 north.
        let near = east + 2 * north;
        [c[near ^ 3], c[near ^ 2], c[near ^ 1], c[near]]
    }
}

/// The fade step (share of the fade per frame) for a node at split state `s` fading to its
/// children with the normal step `step`, whose projected error is `px` now and was `px_before`
/// in the last frame (if it was fading then), at threshold `tau_px`: at least `step`, 1 at or
/// over tau, else large enough to finish within [`FADE_MARGIN`] of the frames left before the
/// error reaches tau at its growth since the last frame.
fn split_step(step: f32, s: f32, px: f64, px_before: Option<f64>, tau_px: f64) -> f32 {
    if px >= tau_px {
        return 1.0;
    }
    match px_before {
        Some(p0) if px > p0 => {
            let frames_left = (FADE_MARGIN * (tau_px - px) / (px - p0)).floor().max(1.0);
            step.max(((1.0 - f64::from(s)) / frames_left) as f32)
        }
        _ => step,
    }
}

#[cfg(test)]
mod tests {
    use super::split_step;

    #[test]
    fn a_fade_finishes_before_the_error_reaches_tau() {
        let (step, tau) = (1.0 / 12.0, 2.0);
        // Slow growth, or none: the normal step.
        assert_eq!(split_step(step, 0.0, 1.3, Some(1.299), tau), step);
        assert_eq!(split_step(step, 0.0, 1.3, None, tau), step);
        assert_eq!(split_step(step, 0.5, 1.3, Some(1.4), tau), step);
        // At or over tau: at once.
        assert_eq!(split_step(step, 0.1, 2.0, Some(1.9), tau), 1.0);
        assert_eq!(split_step(step, 0.1, 7.0, None, tau), 1.0);
        // 0.1 px a frame from 1.4 px (6 frames to tau): faster than the normal step, a little
        // more each frame as the margin shrinks, done in the frame at 1.8 px, before tau.
        let (mut s, mut px, mut before) = (0.2f32, 1.4, 1.3);
        let mut steps = Vec::new();
        loop {
            let st = split_step(step, s, px, Some(before), tau);
            steps.push(st);
            s = (s + st).min(1.0);
            if s >= 1.0 {
                break;
            }
            before = px;
            px += 0.1;
        }
        assert!(px < tau, "the fade ended at {px} px");
        assert!(
            (px - 1.8).abs() < 1e-9,
            "the fade ended at {px} px, steps {steps:?}"
        );
        assert!(
            steps.iter().all(|&st| st > step && st < 1.0),
            "steps {steps:?}"
        );
    }
}
