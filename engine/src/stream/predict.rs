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
use rustc_hash::FxHashMap;

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

impl Streamer {
    /// The prefetch classes for this frame: every node not needed now, mapped to the class of
    /// the earliest predicted camera (`future`, sorted by time) that needs it, else to the
    /// lower-tau class around `cam`.
    pub(super) fn prefetch_classes(
        &self,
        cam: &Camera,
        future: &[(f64, Camera)],
    ) -> FxHashMap<NodeKey, usize> {
        let tau = self.settings.tau_px;
        let mut out = FxHashMap::default();
        let mut add = |set: rustc_hash::FxHashSet<NodeKey>, class: usize| {
            for k in set {
                if !self.needed.contains(&k) {
                    out.entry(k).or_insert(class);
                }
            }
        };
        for (i, (_, c)) in future.iter().take(PREDICT_HORIZONS_S.len()).enumerate() {
            let wanted = self.select_wanted(c, tau * self.settings.split_factor);
            let ancestors = Self::ancestors_of(&wanted);
            add(self.needed_for(&wanted, &ancestors), 1 + i);
        }
        let wanted = self.select_wanted(cam, tau * self.settings.prefetch_factor);
        let ancestors = Self::ancestors_of(&wanted);
        add(self.needed_for(&wanted, &ancestors), CLASSES - 1);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

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
