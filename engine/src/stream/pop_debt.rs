//! Pop debt: a visible drawn node whose own error, projected on the screen at the camera, is
//! over tau (a finer level exists but is not shown yet, so it will pop in). The benchmark's
//! flights and the viewer's statistics panel count it the same way, with [`PopDebtWindow`]
//! keeping the last seconds of it.

use super::{DrawNode, Streamer};
use crate::camera::Camera;
use crate::terrain::select::{ScreenBound, projected_error_px, traverse};
use rustc_hash::FxHashSet;
use std::collections::VecDeque;

impl Streamer {
    /// The drawn nodes the camera sees: a non-empty dither interval (not fully faded out), and
    /// reached by the ideal traversal at `tau_px` as a non-culled node at or below them (a box
    /// test alone passes big boxes behind the camera; the traversal refines them).
    pub fn visible_drawn(&self, cam: &Camera, tau_px: f64) -> Vec<DrawNode> {
        let ideal = traverse(
            self.tree(),
            cam,
            true,
            |key| self.shared.bounds.peek(key),
            |_, _, _, px| px > tau_px,
        );
        let visible: FxHashSet<_> = ideal
            .nodes
            .iter()
            .map(|n| n.key)
            .chain(ideal.unknown_bounds.iter().copied())
            .flat_map(|key| std::iter::once(key).chain(key.ancestors()))
            .collect();
        self.draw_list()
            .iter()
            .filter(|d| d.dither_hi > d.dither_lo && visible.contains(&d.key))
            .copied()
            .collect()
    }

    /// The largest excess over `tau_px` of the projected error of the `visible` drawn nodes
    /// (see [`Self::visible_drawn`]); 0 when none is over tau. Every drawn node is charged,
    /// whether or not its finer nodes' bounds are known yet; nodes at the finest level have
    /// nothing finer and are not.
    pub fn excess_over_tau_px(&self, cam: &Camera, tau_px: f64, visible: &[DrawNode]) -> f64 {
        let tree = self.tree();
        let screen = ScreenBound::new(cam);
        let frustum = cam.frustum();
        let mut excess_px = 0.0f64;
        for d in visible {
            if d.key.level == tree.max_level {
                continue;
            }
            let Some(bounds) = self.resident(d.key).and_then(|r| r.work.bounds) else {
                continue;
            };
            let px = projected_error_px(tree, d.key, &bounds, &screen, Some(&frustum), cam.near_m);
            excess_px = excess_px.max(px - tau_px);
        }
        excess_px
    }

    /// [`Self::excess_over_tau_px`] of the nodes drawn for `cam`: above 0, the frame has pop
    /// debt.
    pub fn drawn_excess_over_tau_px(&self, cam: &Camera, tau_px: f64) -> f64 {
        let visible = self.visible_drawn(cam, tau_px);
        self.excess_over_tau_px(cam, tau_px, &visible)
    }
}

/// The pop debt of the last seconds: per frame, the largest excess over tau (see
/// [`Streamer::drawn_excess_over_tau_px`]), kept for `window_s`.
#[derive(Debug, Clone)]
pub struct PopDebtWindow {
    window_s: f64,
    /// (frame time s, excess px), oldest first.
    frames: VecDeque<(f64, f64)>,
}

impl PopDebtWindow {
    pub fn new(window_s: f64) -> Self {
        Self {
            window_s,
            frames: VecDeque::new(),
        }
    }

    /// The length of the window (s).
    pub fn window_s(&self) -> f64 {
        self.window_s
    }

    /// Records a frame at `t_s` (non-decreasing) and forgets the frames older than the window.
    pub fn push(&mut self, t_s: f64, excess_px: f64) {
        self.frames.push_back((t_s, excess_px.max(0.0)));
        while self
            .frames
            .front()
            .is_some_and(|&(t, _)| t < t_s - self.window_s)
        {
            self.frames.pop_front();
        }
    }

    /// Frames in the window.
    pub fn frames(&self) -> usize {
        self.frames.len()
    }

    /// Share of the window's frames with a drawn node over tau (0 without frames).
    pub fn share(&self) -> f64 {
        let over = self.frames.iter().filter(|&&(_, e)| e > 0.0).count();
        over as f64 / self.frames.len().max(1) as f64
    }

    /// The largest excess over tau in the window (px).
    pub fn worst_px(&self) -> f64 {
        self.frames.iter().map(|&(_, e)| e).fold(0.0, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_window_forgets_old_frames_and_counts_the_frames_over_tau() {
        let mut w = PopDebtWindow::new(1.0);
        assert_eq!((w.frames(), w.share(), w.worst_px()), (0, 0.0, 0.0));
        w.push(0.0, 3.0);
        w.push(0.5, 0.0);
        w.push(0.9, -1.0); // under tau: no debt
        assert_eq!(w.frames(), 3);
        assert!((w.share() - 1.0 / 3.0).abs() < 1e-12);
        assert_eq!(w.worst_px(), 3.0);
        // The frame at 0 s leaves the window; its 3 px goes with it.
        w.push(1.2, 0.5);
        assert_eq!(w.frames(), 3);
        assert!((w.share() - 1.0 / 3.0).abs() < 1e-12);
        assert_eq!(w.worst_px(), 0.5);
    }
}
