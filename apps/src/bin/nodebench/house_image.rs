//! Buildings rows: the image error of the houses' chosen levels (and far meshes) against every
//! house at full detail, on frames drawn on the GPU around the map's largest town, with the
//! town in the middle of the view and near its corner (where a flat screen stretches most).

use crate::report::{Report, bar};
use engine::camera::Camera;
use engine::lighting::content::LightingContent;
use engine::pm_image_error::{ObjectImageError, chosen_against_full};
use engine::render::{COLOR_FORMAT, Target};
use engine::stream::StreamSettings;
use engine::surface::World;
use engine::viewer::Viewer;

/// Each view is drawn this many times as finely per side (the silhouettes' quantization is half
/// a pixel), with tau as many times as large (the same choices).
const SUPERSAMPLE: u32 = 2;

/// `cam` turned so that what it looked at sits `share` of the way from the middle of the view
/// to its lower-right corner.
fn towards_corner(cam: &Camera, share: f64) -> Camera {
    let ty = (cam.fovy_rad * 0.5).tan();
    let tx = ty * cam.aspect();
    // The old forward direction seen from the turned camera at (share tx, -share ty).
    let (f, r, u) = (cam.forward, cam.right(), cam.up);
    let new_forward = (f - r * (share * tx) + u * (share * ty)).normalize();
    Camera::look_at(
        cam.position_m,
        cam.position_m + new_forward,
        cam.fovy_rad,
        cam.viewport_px,
    )
}

/// `cam` drawn `factor` times as finely per side.
fn finer(cam: &Camera, factor: u32) -> Camera {
    Camera {
        viewport_px: [cam.viewport_px[0] * factor, cam.viewport_px[1] * factor],
        ..*cam
    }
}

pub(crate) fn house_image_rows(
    world: &World,
    orbits: &[(f64, Vec<Camera>)],
    tau_px: f64,
    r: &mut Report,
) {
    let Some((g, adapter)) = crate::gpu::adapter() else {
        eprintln!("no GPU adapter: the house image-error rows left out");
        return;
    };
    let mut kinds = engine::kinds::registered(world);
    kinds.retain(|k| k.kind.name() != LightingContent::NAME);
    let settings = StreamSettings {
        workers: 2,
        tau_px: tau_px * f64::from(SUPERSAMPLE),
        ..StreamSettings::default()
    };
    let mut v = Viewer::with_kinds(&g, COLOR_FORMAT, world.clone(), settings, &kinds);
    let Some(first) = orbits.first().and_then(|(_, c)| c.first()) else {
        return;
    };
    let target = Target::new(
        &g.device,
        finer(first, SUPERSAMPLE).viewport_px,
        COLOR_FORMAT,
    );
    let views: usize = orbits.iter().map(|(_, c)| 2 * c.len()).sum();
    let b = bar(views as u64, "house image error");
    for (distance_m, cams) in orbits {
        for (place, share) in [
            ("in the middle of the view", 0.0),
            ("near its corner", 0.85),
        ] {
            let mut got: Vec<ObjectImageError> = Vec::new();
            for cam in cams {
                let cam = finer(&towards_corner(cam, share), SUPERSAMPLE);
                match chosen_against_full(&g, &mut v, &target, &cam, 600.0) {
                    Ok(mut e) => {
                        e.silhouette = e.silhouette.in_pixels_of(SUPERSAMPLE);
                        got.push(e);
                    }
                    Err(e) => b.println(format!("house image error: {e}")),
                }
                b.inc(1);
            }
            if got.is_empty() {
                continue;
            }
            let worst = got.iter().map(|e| e.silhouette.max_px).fold(0.0, f64::max);
            let p99 = got.iter().map(|e| e.silhouette.p99_px).fold(0.0, f64::max);
            let tris: [u64; 2] = got.iter().fold([0, 0], |t, e| {
                [t[0] + e.triangles[0], t[1] + e.triangles[1]]
            });
            let params = format!(
                "tau {tau_px} px, town orbit at {distance_m} m, town {place}, {} views of {}x{} px \
                 drawn {SUPERSAMPLE}x{SUPERSAMPLE} as finely on {adapter}; chosen levels (far \
                 meshes on) against every house at full detail, silhouettes against the frame \
                 without houses; house triangles {} chosen / {} full{}",
                got.len(),
                first.viewport_px[0],
                first.viewport_px[1],
                tris[0],
                tris[1],
                if worst > tau_px { "; above tau" } else { "" }
            );
            r.add(
                "buildings",
                &format!("house image error at {distance_m} m, {place}: max"),
                worst,
                "px",
                &params,
            );
            r.add(
                "buildings",
                &format!("house image error at {distance_m} m, {place}: largest p99 of a view"),
                p99,
                "px",
                &params,
            );
        }
    }
    b.finish_and_clear();
}
