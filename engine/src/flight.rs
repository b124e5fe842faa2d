//! Camera flights: the automatic flyover over a map (a low valley flight, then a climb to an
//! overview) and recorded camera paths (`tvs-camera-path 1`, text, one key per line).

use crate::camera::Camera;
use crate::surface::World;
use glam::DVec3;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// A camera path file that cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum PathError {
    #[error("camera path {path}, line {line}: {problem}")]
    Line {
        path: PathBuf,
        line: usize,
        problem: String,
    },
    #[error("camera path {path}: {reason}")]
    File { path: PathBuf, reason: String },
}

/// The automatic flyover: a low valley flight (25 m above the ground) for the first half, then
/// a climb to a high overview of the whole map. `t` in [0, 1].
pub fn auto_flyover(world: &World, t: f64, viewport_px: [u32; 2]) -> Camera {
    let o = world.origin_m();
    let s = world.size_m();
    let t = t.clamp(0.0, 1.0);
    let path = |t: f64| {
        [
            o[0] + s[0] * (0.15 + 0.6 * t),
            o[1] + s[1] * (0.25 + 0.45 * t + 0.05 * (t * 9.0).sin()),
        ]
    };
    // Height over the ground smoothed along the path, so the camera does not jitter over bumps.
    let ground = (0..9)
        .map(|i| {
            let p = path(t + (f64::from(i) - 4.0) * 0.004);
            world.height_m(p[0], p[1])
        })
        .fold(f64::NEG_INFINITY, f64::max);
    let climb = ((t - 0.5) / 0.5).clamp(0.0, 1.0);
    let above = 25.0 + climb * climb * 0.6 * s[0].max(s[1]);
    let p = path(t);
    let pos = DVec3::new(p[0], p[1], ground + above);
    let ahead = DVec3::new(s[0] * 0.6, s[1] * 0.45, 0.0).normalize();
    let pitch: f64 = -0.1;
    let low = DVec3::new(ahead.x * pitch.cos(), ahead.y * pitch.cos(), pitch.sin());
    // While climbing, turn from straight ahead to the map's centre, so the end is an overview.
    let centre = DVec3::new(
        o[0] + s[0] * 0.5,
        o[1] + s[1] * 0.5,
        world.height_m(o[0] + s[0] * 0.5, o[1] + s[1] * 0.5),
    );
    let w = climb * climb * (3.0 - 2.0 * climb);
    let dir = low
        .lerp((centre - pos).normalize_or(low), w)
        .normalize_or(low);
    Camera::look_at(pos, pos + dir, 60f64.to_radians(), viewport_px)
}

/// One key of a camera path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathKey {
    pub t_s: f64,
    pub position_m: DVec3,
    pub forward: DVec3,
}

const PATH_MAGIC: &str = "tvs-camera-path 1";

/// A recorded camera path: text, one key per line (`t_s x y z forward_x forward_y forward_z`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CameraPath {
    pub keys: Vec<PathKey>,
}

impl CameraPath {
    pub fn load(path: &Path) -> Result<Self, PathError> {
        // A day of keys at 60 per second is about 300 MB: refuse more before reading it.
        const MAX_BYTES: u64 = 512 << 20;
        if let Ok(meta) = std::fs::metadata(path)
            && meta.len() > MAX_BYTES
        {
            return Err(PathError::File {
                path: path.to_path_buf(),
                reason: format!(
                    "{} bytes is beyond the limit of {MAX_BYTES} bytes",
                    meta.len()
                ),
            });
        }
        let text = std::fs::read_to_string(path).map_err(|e| PathError::File {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        let bad = |line: usize, problem: String| PathError::Line {
            path: path.to_path_buf(),
            line,
            problem,
        };
        let mut lines = text.lines().enumerate();
        match lines.next() {
            Some((_, l)) if l.trim() == PATH_MAGIC => {}
            _ => return Err(bad(1, format!("expected the first line {PATH_MAGIC:?}"))),
        }
        let mut keys: Vec<PathKey> = Vec::new();
        for (i, l) in lines {
            let l = l.trim();
            if l.is_empty() || l.starts_with('#') {
                continue;
            }
            let v: Vec<f64> = l
                .split_whitespace()
                .map(str::parse)
                .collect::<Result<_, _>>()
                .map_err(|e| bad(i + 1, format!("not a number: {e}")))?;
            if v.len() != 7 || v.iter().any(|x| !x.is_finite()) {
                return Err(bad(
                    i + 1,
                    format!("expected 7 finite numbers (t_s x y z fx fy fz), got {l:?}"),
                ));
            }
            let forward = DVec3::new(v[4], v[5], v[6]);
            if forward.length() < 1e-9 {
                return Err(bad(i + 1, "forward direction is zero".into()));
            }
            if keys.last().is_some_and(|k| v[0] <= k.t_s) {
                return Err(bad(i + 1, format!("time {} s does not increase", v[0])));
            }
            keys.push(PathKey {
                t_s: v[0],
                position_m: DVec3::new(v[1], v[2], v[3]),
                forward: forward.normalize(),
            });
        }
        if keys.is_empty() {
            return Err(PathError::File {
                path: path.to_path_buf(),
                reason: "no keys".into(),
            });
        }
        Ok(Self { keys })
    }

    pub fn save(&self, path: &Path) -> Result<(), PathError> {
        let mut s = format!("{PATH_MAGIC}\n# t_s x_m y_m z_m forward_x forward_y forward_z\n");
        for k in &self.keys {
            let (p, f) = (k.position_m, k.forward);
            let _ = writeln!(
                s,
                "{:.4} {:.4} {:.4} {:.4} {:.6} {:.6} {:.6}",
                k.t_s, p.x, p.y, p.z, f.x, f.y, f.z
            );
        }
        std::fs::write(path, s).map_err(|e| PathError::File {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })
    }

    pub fn duration_s(&self) -> f64 {
        self.keys.last().map_or(0.0, |k| k.t_s)
    }

    /// The camera at time `t_s` (linear between keys, clamped at the ends).
    pub fn at(&self, t_s: f64, viewport_px: [u32; 2]) -> Camera {
        let i = self.keys.partition_point(|k| k.t_s <= t_s);
        let (a, b) = (
            self.keys[i.saturating_sub(1)],
            self.keys[i.min(self.keys.len() - 1)],
        );
        let f = if b.t_s > a.t_s {
            ((t_s - a.t_s) / (b.t_s - a.t_s)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let pos = a.position_m.lerp(b.position_m, f);
        let fwd = a.forward.lerp(b.forward, f).normalize_or(a.forward);
        Camera::look_at(pos, pos + fwd, 60f64.to_radians(), viewport_px)
    }
}
