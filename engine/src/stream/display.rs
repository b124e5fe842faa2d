//! What is drawn: split states that cross-fade between a node and its children, and the draw
//! list with dither intervals that partition [0, 1) at every point.

use super::Streamer;
use crate::terrain::quadtree::NodeKey;
use rustc_hash::FxHashSet;

/// One node to draw this frame, with its dither interval (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DrawNode {
    pub key: NodeKey,
    pub dither_lo: f32,
    pub dither_hi: f32,
}

impl Streamer {
    /// Moves every node's split state towards its target: split when it is an ancestor of
    /// wanted nodes and all its children are ready, merged otherwise (a node merges only once
    /// its children have merged).
    pub(super) fn advance_fades(&mut self, dt_s: f64) {
        let step = if self.settings.fade_s > 0.0 {
            (dt_s / self.settings.fade_s) as f32
        } else {
            1.0
        };
        let mut stack = vec![NodeKey::ROOT];
        let mut seen: FxHashSet<NodeKey> = FxHashSet::default();
        while let Some(key) = stack.pop() {
            if !self.resident.contains_key(&key) {
                continue;
            }
            seen.insert(key);
            let wants_split = self.to_split.contains(&key) && self.children_drawable(key);
            let s = self.split.get(&key).copied().unwrap_or(0.0);
            // A node may only merge back once its children are no longer split themselves.
            let children_merged = key
                .children()
                .iter()
                .all(|c| self.split.get(c).copied().unwrap_or(0.0) == 0.0);
            let target = if wants_split || !children_merged {
                1.0
            } else {
                0.0
            };
            // Step towards the target (and stay there once reached).
            let ns = if target > s {
                (s + step).min(target)
            } else {
                (s - step).max(target)
            };
            // Children must be resident to show them at all.
            let ns = if ns > 0.0 && !self.children_drawable(key) {
                0.0
            } else {
                ns
            };
            if ns > 0.0 {
                self.split.insert(key, ns);
                stack.extend(key.children());
            } else {
                self.split.remove(&key);
            }
        }
        self.split.retain(|k, _| seen.contains(k));
    }

    pub(super) fn children_drawable(&self, key: NodeKey) -> bool {
        key.level < self.shared.tree.max_level
            && key
                .children()
                .iter()
                .all(|c| !self.shared.tree.overlaps_map(*c) || self.resident.contains_key(c))
    }

    /// The nodes to draw and their dither intervals. Nothing is missing: the root (once ready)
    /// covers everything not covered by ready descendants.
    pub fn draw_list(&self) -> &[DrawNode] {
        &self.drawn
    }

    /// Walks the resident tree from the root, giving children the lower part of their parent's
    /// dither interval in proportion to its split state.
    pub(super) fn compute_draw_list(&self) -> Vec<DrawNode> {
        let mut out = Vec::new();
        if !self.resident.contains_key(&NodeKey::ROOT) {
            return out;
        }
        let mut stack = vec![(NodeKey::ROOT, 0.0f32, 1.0f32)];
        while let Some((key, lo, hi)) = stack.pop() {
            if !self.shared.tree.overlaps_map(key) || !self.resident.contains_key(&key) {
                continue;
            }
            let s = self.split.get(&key).copied().unwrap_or(0.0);
            if s <= 0.0 {
                out.push(DrawNode {
                    key,
                    dither_lo: lo,
                    dither_hi: hi,
                });
                continue;
            }
            // Children take [lo, lo + s (hi - lo)); the node keeps the rest.
            let mid = lo + s * (hi - lo);
            if mid < hi {
                out.push(DrawNode {
                    key,
                    dither_lo: mid,
                    dither_hi: hi,
                });
            }
            for c in key.children() {
                stack.push((c, lo, mid));
            }
        }
        out
    }
}
