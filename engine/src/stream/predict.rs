//! Prefetch where the camera is going: the nodes a predicted camera will need, each in the
//! priority class of the earliest time it is needed (time to need), ahead of the old
//! "lower tau around the camera" prefetch.
//!
//! The prediction is the camera path when the owner knows it (a replayed or automatic flight,
//! [`Streamer::update_along`]) and otherwise the camera moved on at its current velocity and
//! turn rate ([`Streamer::update`], [`extrapolate_turning`]), with the views to either side
//! prefetched too ([`Guess::Extrapolated`]): a hand on the controls can turn at any moment.
//! Within a class the seed's rule still orders jobs: larger nodes first, then nearer.

use super::Streamer;
use crate::camera::Camera;
use crate::terrain::quadtree::NodeKey;
use glam::{DMat3, DVec3};
use rustc_hash::FxHashSet;

/// How far ahead the camera is predicted (s). Class `1 + i` holds what the camera needs
/// `PREDICT_HORIZONS_S[i]` from now and not sooner.
pub const PREDICT_HORIZONS_S: [f64; 3] = [0.4, 1.0, 2.0];

/// Priority classes: 0 needed now, one per horizon, and last the lower-tau prefetch around
/// the camera.
pub const CLASSES: usize = PREDICT_HORIZONS_S.len() + 2;

/// Whether the predicted cameras are the camera's known path or extrapolated from its past.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Guess {
    Known,
    /// A camera flown by hand can turn at any moment, and its turn is seen only once it has
    /// begun: the views [`SIDE_VIEW_DEG`] to either side of the current one are prefetched too
    /// (in the class of the second horizon), so the view a turn sweeps into is there.
    Extrapolated,
}

/// The side views' yaw from the current view (degrees): with a 16:9 screen at 60° (91°
/// across) the two side views and the view cover about 190°.
pub const SIDE_VIEW_DEG: f64 = 50.0;

/// The side views are prefetched at this multiple of the request threshold. At 1 a settled
/// view pins about three views' worth (29 MiB against 9 MiB without side views, on the tiny
/// map's test view); at 2 (a level coarser) 21 MiB, but the hidden-future pilots at 300 m/s
/// on one worker (light grids and ground textures off) then showed pop debt in 1.0 % and
/// 4.2 % of frames (turning, reversing) instead of 0.6 % and 0 %. Memory is what the budget
/// bounds; a pop is what a person sees.
pub const SIDE_VIEW_TAU_FACTOR: f64 = 1.0;

/// The camera turned about the vertical through its position by `angle_rad` (anticlockwise
/// seen from above).
pub fn yawed(cam: &Camera, angle_rad: f64) -> Camera {
    let turn = DMat3::from_rotation_z(angle_rad);
    Camera {
        forward: turn * cam.forward,
        up: turn * cam.up,
        ..*cam
    }
}

/// Below this speed and turn rate the camera is taken as still (no predicted cameras).
const STILL_M_PER_S: f64 = 0.5;
const STILL_RAD_PER_S: f64 = 0.05;

/// The largest turn a prediction extrapolates (rad): a camera turning round is predicted to
/// look back, not to come round again.
pub const MAX_PREDICTED_TURN_RAD: f64 = std::f64::consts::PI;

/// The camera's yaw rate is smoothed over about this long (s): a hand on the mouse turns in
/// jerks from one frame to the next.
const YAW_RATE_SMOOTHING_S: f64 = 0.1;

/// The camera moved on at `velocity_m_per_s` for each horizon.
pub fn extrapolate(cam: &Camera, velocity_m_per_s: DVec3) -> Vec<(f64, Camera)> {
    extrapolate_turning(cam, velocity_m_per_s, 0.0)
}

/// The camera moved on for each horizon as it moves now: turning about the vertical at
/// `yaw_rate_rad_per_s` (positive anticlockwise seen from above), its view and its horizontal
/// velocity turning together as in a banked turn (an arc; in place when it does not move), the
/// vertical velocity kept. The turn is extrapolated up to [`MAX_PREDICTED_TURN_RAD`].
pub fn extrapolate_turning(
    cam: &Camera,
    velocity_m_per_s: DVec3,
    yaw_rate_rad_per_s: f64,
) -> Vec<(f64, Camera)> {
    if velocity_m_per_s.length() < STILL_M_PER_S && yaw_rate_rad_per_s.abs() < STILL_RAD_PER_S {
        return Vec::new();
    }
    let w = yaw_rate_rad_per_s;
    let v = velocity_m_per_s;
    PREDICT_HORIZONS_S
        .iter()
        .map(|&t| {
            let mut c = *cam;
            // The turn stops at the cap: on the arc until then, straight on after.
            let turn_s = if w == 0.0 {
                t
            } else {
                t.min(MAX_PREDICTED_TURN_RAD / w.abs())
            };
            let a = w * turn_s;
            let (sin, cos) = a.sin_cos();
            // Integral over the turn of the horizontal velocity rotated by w s.
            let (along, across) = if w.abs() < 1e-9 {
                (turn_s, 0.0)
            } else {
                (sin / w, (1.0 - cos) / w)
            };
            let on_arc = DVec3::new(along * v.x - across * v.y, across * v.x + along * v.y, 0.0);
            let straight_after =
                DMat3::from_rotation_z(a) * DVec3::new(v.x, v.y, 0.0) * (t - turn_s);
            c.position_m += on_arc + straight_after + DVec3::Z * v.z * t;
            (t, yawed(&c, a))
        })
        .collect()
}

/// The yaw rate (rad/s, anticlockwise seen from above) between two cameras `dt_s` apart, none
/// when either looks straight up or down.
pub(super) fn yaw_rate_rad_per_s(before: &Camera, after: &Camera, dt_s: f64) -> Option<f64> {
    let flat = |c: &Camera| {
        let f = c.forward.truncate();
        (f.length() > 1e-3).then_some(f)
    };
    let (a, b) = (flat(before)?, flat(after)?);
    (dt_s > 0.0).then(|| a.perp_dot(b).atan2(a.dot(b)) / dt_s)
}

/// The smoothed yaw rate after a frame of `dt_s` that measured `measured` (see
/// [`YAW_RATE_SMOOTHING_S`]).
pub(super) fn smoothed_yaw_rate(previous: f64, measured: f64, dt_s: f64) -> f64 {
    let k = (dt_s / YAW_RATE_SMOOTHING_S).min(1.0);
    previous + k * (measured - previous)
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

/// Prefetch parts: one per horizon, the two side views (for an extrapolated future), then the
/// lower-tau ring around the camera.
pub(super) const PREFETCH_PARTS: usize = PREDICT_HORIZONS_S.len() + 3;
/// The first side view's part.
const SIDE_PARTS: usize = PREDICT_HORIZONS_S.len();

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
    pub(super) fn refresh_prefetch(
        &mut self,
        cam: &Camera,
        future: &[(f64, Camera)],
        guess: Guess,
    ) -> u8 {
        let mut refreshed = 0;
        let tau = self.settings.tau_px;
        let turn = (self.frame % PREFETCH_PARTS as u64) as usize;
        let sides = (guess == Guess::Extrapolated).then(|| {
            let yaw = SIDE_VIEW_DEG.to_radians();
            [yawed(cam, yaw), yawed(cam, -yaw)]
        });
        let split = self.settings.split_factor;
        let part_camera = |part: usize| {
            if part + 1 == PREFETCH_PARTS {
                Some((cam, self.settings.prefetch_factor))
            } else if part >= SIDE_PARTS {
                sides
                    .as_ref()
                    .map(|s| (&s[part - SIDE_PARTS], SIDE_VIEW_TAU_FACTOR * split))
            } else {
                future.get(part).map(|(_, c)| (c, split))
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
            let camera = *camera;
            let wanted = self.select_wanted(&camera, tau * factor);
            self.prefetch_parts[part] = PrefetchPart {
                camera: Some(camera),
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

/// The priority class of prefetch part `part`: one class per horizon, the side views in the
/// second horizon's, the last (lower-tau ring) part in the last class.
fn part_class(part: usize) -> usize {
    if part + 1 == PREFETCH_PARTS {
        CLASSES - 1
    } else if part >= SIDE_PARTS {
        2
    } else {
        1 + part
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn a_turning_camera_is_predicted_on_its_arc_looking_where_it_will_look() {
        let cam = Camera::look_at(DVec3::ZERO, DVec3::X, 1.0, [64, 64]);
        let (v, w) = (100.0, 0.5);
        for (t, c) in extrapolate_turning(&cam, DVec3::new(v, 0.0, 3.0), w) {
            // A circle of radius v / w about (0, v / w): the heading turned by w t.
            let r = v / w;
            let a = w * t;
            let expected = DVec3::new(r * a.sin(), r * (1.0 - a.cos()), 3.0 * t);
            assert!(
                c.position_m.distance(expected) < 1e-9,
                "{t}: {}",
                c.position_m
            );
            assert!((c.forward.y.atan2(c.forward.x) - a).abs() < 1e-9);
            assert!(c.up.dot(c.forward).abs() < 1e-12);
        }
        // Turning in place: views turned, the place kept; the turn stops at half a turn.
        let f = extrapolate_turning(&cam, DVec3::ZERO, std::f64::consts::PI);
        assert_eq!(f.len(), PREDICT_HORIZONS_S.len());
        for (t, c) in f {
            assert!(c.position_m.length() < 1e-12);
            let expected = (std::f64::consts::PI * t).min(std::f64::consts::PI);
            let turned = DVec3::X.angle_between(c.forward);
            assert!((turned - expected).abs() < 1e-6, "{t}: {turned}");
        }
        // Past the cap it flies straight on, on the turned heading.
        let f = extrapolate_turning(&cam, DVec3::new(10.0, 0.0, 0.0), std::f64::consts::PI);
        let (t, last) = f[f.len() - 1];
        assert!(t > 1.0);
        let r = 10.0 / std::f64::consts::PI;
        let expected = DVec3::new(-10.0 * (t - 1.0), 2.0 * r, 0.0);
        assert!(
            last.position_m.distance(expected) < 1e-9,
            "{}",
            last.position_m
        );
        // A side view turns the view and nothing else.
        let side = yawed(&cam, 0.3);
        assert_eq!(side.position_m, cam.position_m);
        assert!((side.forward.y.atan2(side.forward.x) - 0.3).abs() < 1e-12);
        assert_eq!(side.fovy_rad, cam.fovy_rad);
        // The measured rate: a quarter turn anticlockwise in a second.
        let left = Camera::look_at(DVec3::ZERO, DVec3::Y, 1.0, [64, 64]);
        let rate = yaw_rate_rad_per_s(&cam, &left, 1.0).unwrap();
        assert!((rate - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
        assert!((smoothed_yaw_rate(0.0, 1.0, 1.0 / 60.0) - 1.0 / 6.0).abs() < 1e-12);
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
