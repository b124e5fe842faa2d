//! Prefetch where the camera is going: the nodes a predicted camera will need, each in the
//! priority class of the earliest time it is needed (time to need), ahead of the old
//! "lower tau around the camera" prefetch.
//!
//! The prediction is the camera path when the owner knows it (a replayed or automatic flight,
//! [`Streamer::update_along`]) and otherwise the camera moved on at its current velocity
//! ([`Streamer::update`]). Within a class the seed's rule still orders jobs: larger nodes
//! first, then nearer.

use super::Streamer;
use crate::camera::Camera;
use crate::terrain::quadtree::NodeKey;
use rustc_hash::FxHashSet;

/// How far ahead the camera is predicted (s). Class `1 + i` holds what the camera needs
/// `PREDICT_HORIZONS_S[i]` from now and not sooner.
pub const PREDICT_HORIZONS_S: [f64; 3] = [0.4, 1.0, 2.0];

/// Priority classes: 0 needed now, one per horizon, and last the lower-tau prefetch around
/// the camera.
pub const CLASSES: usize = PREDICT_HORIZONS_S.len() + 2;

/// Below this speed the camera is taken as still (no predicted cameras).
const STILL_M_PER_S: f64 = 0.5;

/// The camera moved on at `velocity_m_per_s` for each horizon.
pub fn extrapolate(cam: &Camera, velocity_m_per_s: glam::DVec3) -> Vec<(f64, Camera)> {
    if velocity_m_per_s.length() < STILL_M_PER_S {
        return Vec::new();
    }
    PREDICT_HORIZONS_S
        .iter()
        .map(|&t| {
            let mut c = *cam;
            c.position_m += velocity_m_per_s * t;
            (t, c)
        })
        .collect()
}

/// The path ahead of a camera whose path is known (`camera_at` gives the camera at a time, in
/// s): the cameras at `t_s` plus each horizon, for [`Streamer::update_along`].
pub fn along(t_s: f64, camera_at: impl Fn(f64) -> Camera) -> Vec<(f64, Camera)> {
    PREDICT_HORIZONS_S
        .iter()
        .map(|&h| (h, camera_at(t_s + h)))
        .collect()
}

/// A prefetch part (one predicted camera, or the lower-tau ring around the camera) is stale
/// when its camera moved more than this since it was computed (m) ...
const REFRESH_MOVED_M: f64 = 8.0;
/// ... or turned more than this (cosine of the angle between the view directions). One part
/// is computed again per frame: the first stale one in turn, else the next in turn (so each
/// is at most `PREFETCH_PARTS` frames old).
const REFRESH_TURNED_COS: f64 = 0.996;
/// A part whose camera moved more than this (m) jumped (a teleport, or a prediction thrown far
/// by a change of velocity): it is computed again at once, not in turn, so the jobs of the old
/// place are cancelled in the same frame.
const REFRESH_JUMP_M: f64 = 200.0;

/// Prefetch parts: one per horizon, then the lower-tau ring around the camera.
pub(super) const PREFETCH_PARTS: usize = PREDICT_HORIZONS_S.len() + 1;

/// One part of the prefetch set: the nodes one camera needs, and that camera.
#[derive(Debug, Clone, Default)]
pub(super) struct PrefetchPart {
    camera: Option<Camera>,
    /// Built out in full: a part is computed once in several frames and read in every one.
    nodes: FxHashSet<NodeKey>,
}

impl PrefetchPart {
    /// Whether this part must be computed again in this frame for `cam`: never computed, or
    /// its camera jumped.
    fn needs_now(&self, cam: &Camera) -> bool {
        self.camera
            .is_none_or(|c| c.position_m.distance(cam.position_m) > REFRESH_JUMP_M)
    }

    /// Whether this part, computed for its camera, is stale for `cam`.
    fn stale_for(&self, cam: &Camera) -> bool {
        self.camera.is_none_or(|c| {
            c.position_m.distance(cam.position_m) > REFRESH_MOVED_M
                || c.forward.dot(cam.forward) < REFRESH_TURNED_COS
        })
    }
}

impl Streamer {
    /// Refreshes the prefetch parts for this frame: the nodes each predicted camera (`future`,
    /// sorted by time) needs, in the class of its horizon, and the lower-tau ring around `cam`
    /// in the last class (a node's class is the smallest of the parts holding it, see
    /// [`entries`]). The parts' selections are the costliest bookkeeping of a
    /// frame, so one part is computed again per frame (the first stale one in turn, else the
    /// next in turn): a part is at most `PREFETCH_PARTS` frames old; a part with no selection
    /// yet (the camera starts moving) or whose camera jumped is computed at once. The display
    /// set is computed every frame, so a stale part delays prefetch only.
    ///
    /// Returns the parts computed again (bit `i` for part `i`): only their nodes can be
    /// missing or need a higher class (a part's nodes are all requested when it is computed,
    /// and a request for a prefetched node is never cancelled, nor is a prefetched resident
    /// node evicted).
    pub(super) fn refresh_prefetch(&mut self, cam: &Camera, future: &[(f64, Camera)]) -> u8 {
        let mut refreshed = 0;
        let tau = self.settings.tau_px;
        let turn = (self.frame % PREFETCH_PARTS as u64) as usize;
        let part_camera = |part: usize| {
            if part + 1 == PREFETCH_PARTS {
                Some((cam, self.settings.prefetch_factor))
            } else {
                future
                    .get(part)
                    .map(|(_, c)| (c, self.settings.split_factor))
            }
        };
        // One part a frame: the first stale one from this frame's turn on, else the turn's;
        // and every part that has no selection yet or whose camera jumped.
        let refresh_in_turn = (0..PREFETCH_PARTS)
            .map(|i| (turn + i) % PREFETCH_PARTS)
            .find(|&part| {
                part_camera(part).is_some_and(|(c, _)| self.prefetch_parts[part].stale_for(c))
            })
            .unwrap_or(turn);
        for part in 0..PREFETCH_PARTS {
            let Some((camera, factor)) = part_camera(part) else {
                self.prefetch_parts[part] = PrefetchPart::default();
                continue;
            };
            if part != refresh_in_turn && !self.prefetch_parts[part].needs_now(camera) {
                continue;
            }
            let wanted = self.select_wanted(camera, tau * factor);
            self.prefetch_parts[part] = PrefetchPart {
                camera: Some(*camera),
                nodes: self.needed_for(&wanted).to_set(),
            };
            refreshed |= 1 << part;
        }
        refreshed
    }

    /// Whether a prefetch part holds `key`.
    pub(super) fn prefetched(&self, key: &NodeKey) -> bool {
        self.prefetch_parts.iter().any(|p| p.nodes.contains(key))
    }
}

/// Every prefetch part's nodes, each with the part's priority class: a node in several parts
/// (or needed now) comes once per part, and the caller takes its smallest class. No merged set
/// is built: that took two hash operations per node of every part in every frame, more than
/// the frame's part selection.
pub(super) fn entries(parts: &[PrefetchPart]) -> impl Iterator<Item = (usize, NodeKey)> + '_ {
    entries_of(parts, u8::MAX)
}

/// [`entries`] of the parts in `mask` (bit `i` for part `i`).
pub(super) fn entries_of(
    parts: &[PrefetchPart],
    mask: u8,
) -> impl Iterator<Item = (usize, NodeKey)> + '_ {
    parts
        .iter()
        .enumerate()
        .filter(move |(part, _)| mask & (1 << part) != 0)
        .flat_map(|(part, p)| p.nodes.iter().map(move |&k| (part_class(part), k)))
}

/// The priority class of prefetch part `part`: one class per horizon, the last (lower-tau
/// ring) part in the last class.
fn part_class(part: usize) -> usize {
    if part + 1 == PREFETCH_PARTS {
        CLASSES - 1
    } else {
        1 + part
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn a_prefetch_part_is_stale_when_new_moved_or_turned() {
        let cam = Camera::look_at(DVec3::ZERO, DVec3::X, 1.0, [64, 64]);
        assert!(PrefetchPart::default().stale_for(&cam), "never computed");
        let part = PrefetchPart {
            camera: Some(cam),
            nodes: FxHashSet::default(),
        };
        assert!(!part.stale_for(&cam));
        let moved = |m: f64| {
            let mut c = cam;
            c.position_m.y += m;
            c
        };
        assert!(!part.stale_for(&moved(0.5 * REFRESH_MOVED_M)));
        assert!(part.stale_for(&moved(1.5 * REFRESH_MOVED_M)));
        let turned = |deg: f64| {
            let a = deg.to_radians();
            Camera::look_at(
                DVec3::ZERO,
                DVec3::new(a.cos(), a.sin(), 0.0),
                1.0,
                [64, 64],
            )
        };
        assert!(!part.stale_for(&turned(2.0)));
        assert!(part.stale_for(&turned(10.0)));
        // Stale parts wait for their turn; a jump is computed at once.
        assert!(PrefetchPart::default().needs_now(&cam));
        assert!(!part.needs_now(&moved(150.0)));
        assert!(!part.needs_now(&turned(90.0)));
        assert!(part.needs_now(&moved(250.0)));
    }

    #[test]
    fn a_still_camera_predicts_nothing_and_a_moving_one_moves_on() {
        let cam = Camera::look_at(DVec3::ZERO, DVec3::X, 1.0, [64, 64]);
        assert!(extrapolate(&cam, DVec3::ZERO).is_empty());
        let f = extrapolate(&cam, DVec3::new(100.0, 0.0, 0.0));
        assert_eq!(f.len(), PREDICT_HORIZONS_S.len());
        for (t, c) in f {
            assert!((c.position_m.x - 100.0 * t).abs() < 1e-9);
            assert_eq!(c.forward, cam.forward);
        }
    }
}
