//! The image error of progressive-mesh objects (houses) at the levels the pixel metric chooses
//! ([`crate::objects::lod`]), measured on rendered frames: a settled view's objects are drawn
//! alone (no terrain, vegetation or sky, so nothing hides them and a part that slips behind a
//! hill is measured by how far it moved, not by how far the next object is), once at their
//! chosen levels (with merged far meshes where the view options allow them) and once each at
//! full detail on its own, and the two silhouettes are compared
//! ([`crate::silhouette::distance`]), each object's centre and the vertices of the levels drawn
//! counting as covered (`centres`, `drawn_vertices`): a level within its error may fold a
//! part into a sliver no pixel centre falls in, and that part has moved by no more than its
//! error, not vanished.

use crate::camera::Camera;
use crate::measure::ScreenProjection;
use crate::objects::content::ObjectsContent;
use crate::objects::set::model_to_world;
use crate::render::frame::ViewOptions;
use crate::render::objects::ObjectsRenderer;
use crate::render::{Gpu, Target};
use crate::shown_error::settle;
use crate::silhouette::{self, Mask, SilhouetteDistance};
use crate::viewer::Viewer;
use glam::DVec3;

/// A view's object image error.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ObjectImageError {
    pub silhouette: SilhouetteDistance,
    /// Object triangles drawn at the chosen levels and at full detail.
    pub triangles: [u64; 2],
}

/// The pixels of the objects' centres (their bounding spheres'): an object that a level draws
/// thinner than a pixel (a far house legally reduced to a sliver, or drawn by no pixel centre)
/// is measured as collapsing to its centre, not as far as the nearest other object.
fn centres(viewer: &Viewer, cam: &Camera) -> Mask {
    let mut m = Mask::empty(cam.viewport_px);
    let Some(objects) = viewer.streamer.shared.kind::<ObjectsContent>() else {
        return m;
    };
    let proj = ScreenProjection::new(cam);
    for inst in &objects.set.instances {
        if let Some(at) = proj.pixel_of(objects.set.sphere(inst).0) {
            m.mark(at);
        }
    }
    m
}

/// The pixels of the vertices of every object the last frame drew on its own, at the level it
/// drew: a level may fold a thin part (a chimney) into a sliver within its error that covers no
/// pixel centre; its vertices still mark where it is. (Objects drawn in a merged far mesh are
/// marked by their centres only.)
fn drawn_vertices(viewer: &Viewer, cam: &Camera) -> Mask {
    let mut m = Mask::empty(cam.viewport_px);
    let (Some(renderer), Some(objects)) = (
        viewer.scene.renderer::<ObjectsRenderer>(),
        viewer.streamer.shared.kind::<ObjectsContent>(),
    ) else {
        return m;
    };
    let proj = ScreenProjection::new(cam);
    let mut idx = Vec::new();
    for (id, choice) in renderer.choices() {
        let inst = &objects.set.instances[id as usize];
        let model = &objects.set.models[inst.model as usize];
        let pm = &model.option(choice.option).pm;
        pm.indices_at(choice.level, &mut idx);
        for &w in &idx {
            let p = pm.positions[pm.wedge_position[w as usize] as usize];
            let world = model_to_world(
                DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])),
                inst,
                model,
            );
            if let Some(at) = proj.pixel_of(world) {
                m.mark(at);
            }
        }
    }
    m
}

/// Settles `viewer` at `cam` (at most `timeout_s`) and measures its objects' image error at
/// their chosen levels against full detail, drawing into `target` (`cam`'s viewport size).
/// The viewer's view options are restored afterwards.
pub fn chosen_against_full(
    gpu: &Gpu,
    viewer: &mut Viewer,
    target: &Target,
    cam: &Camera,
    timeout_s: f64,
) -> Result<ObjectImageError, String> {
    settle(gpu, viewer, target, cam, timeout_s)?;
    let kept = viewer.view;
    let draw = |viewer: &mut Viewer, f: &dyn Fn(&mut ViewOptions)| {
        f(&mut viewer.view);
        let st = viewer.render_offscreen(gpu, target, cam, 0.0);
        viewer.view = kept;
        let st = st?;
        let z = target
            .read_depth(gpu)
            .map_err(|e| format!("reading the frame's depth: {e}"))?;
        Ok::<_, String>((z, st.object_triangles))
    };
    let alone = |v: &mut ViewOptions| {
        v.terrain = false;
        v.plants = false;
        v.sky = false;
    };
    let (chosen, chosen_tris) = draw(viewer, &alone)?;
    let chosen_points = drawn_vertices(viewer, cam);
    let (full, full_tris) = draw(viewer, &|v| {
        alone(v);
        v.pm_lod.fixed_fraction = Some(1.0);
        v.hlod = false;
    })?;
    let full_points = drawn_vertices(viewer, cam);
    let centres = centres(viewer, cam);
    let a = Mask::from_reversed_z(target.size, &chosen)?
        .union(&centres)
        .union(&chosen_points);
    let b = Mask::from_reversed_z(target.size, &full)?
        .union(&centres)
        .union(&full_points);
    Ok(ObjectImageError {
        silhouette: silhouette::distance(&a, &b)?,
        triangles: [chosen_tris, full_tris],
    })
}
