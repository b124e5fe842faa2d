//! The terrain error a rendered frame shows. The selection may leave a node coarser than tau
//! where something in front hides it (splitting less behind dense vegetation); whether that
//! shows is a question about pixels, so it is answered from a rendered frame: the viewer is
//! settled at a camera, the frame is drawn, its depth buffer read back, and the drawn nodes'
//! meshes (as drawn: their decimation) measured on the screen over the samples the frame shows
//! ([`crate::measure::view_error_shown_px`]) and over all samples on the screen.

use crate::camera::Camera;
use crate::lighting::content::LightingContent;
use crate::measure::{self, DepthImage, ViewError};
use crate::objects::content::ObjectsContent;
use crate::render::{COLOR_FORMAT, Gpu, Target};
use crate::stream::StreamSettings;
use crate::surface::World;
use crate::terrain::bounds::BoundsCache;
use crate::terrain::mesh;
use crate::terrain::tiles::TileCache;
use crate::viewer::Viewer;
use std::time::Instant;

/// Dense error samples per mesh quad (off the vertices and the bounds' check lattice).
pub const SAMPLES_PER_QUAD: u32 = 2;

/// A rendered view's terrain error.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ShownError {
    /// Terrain nodes drawn and their triangles (as drawn, after decimation).
    pub drawn_nodes: usize,
    pub triangles: usize,
    /// Over every sample of the drawn meshes on the screen, hidden or not.
    pub all: ViewError,
    /// Over the samples the frame shows.
    pub shown: ViewError,
    /// Samples on the screen that something drawn in front hides.
    pub hidden_samples: u64,
}

/// A viewer of `world` for [`settled_view_error`] at threshold `tau_px` with `workers` node
/// workers, splitting less behind vegetation when `vegetation_occlusion`: the registered kinds
/// less the light grids (they change no depth) and the houses (they would hide terrain, so
/// without them the check can only count more samples as shown).
pub fn check_viewer(
    gpu: &Gpu,
    world: &World,
    tau_px: f64,
    workers: usize,
    vegetation_occlusion: bool,
) -> Viewer {
    let mut kinds = crate::kinds::registered(world);
    kinds.retain(|k| ![LightingContent::NAME, ObjectsContent::NAME].contains(&k.kind.name()));
    let settings = StreamSettings {
        vegetation_occlusion,
        workers,
        tau_px,
        ..StreamSettings::default()
    };
    Viewer::with_kinds(gpu, COLOR_FORMAT, world.clone(), settings, &kinds)
}

/// Streams `viewer` at `cam` until its view is settled (every wanted node drawn, no job in
/// flight, node textures made; at most `timeout_s`), then draws a few frames into `target`
/// (which must be `cam`'s viewport size) so fades end and background light grids arrive.
pub fn settle(
    gpu: &Gpu,
    viewer: &mut Viewer,
    target: &Target,
    cam: &Camera,
    timeout_s: f64,
) -> Result<(), String> {
    if target.size != cam.viewport_px {
        return Err(format!(
            "the target is {:?} px but the camera's viewport {:?} px",
            target.size, cam.viewport_px
        ));
    }
    let t0 = Instant::now();
    while !viewer.stream_only(gpu, cam, 0.05) {
        if t0.elapsed().as_secs_f64() > timeout_s {
            return Err(format!(
                "the view did not settle in {timeout_s} s: {:?}",
                viewer.outstanding()
            ));
        }
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    for _ in 0..10 {
        if let Some(l) = viewer.lighting() {
            l.wait_idle();
        }
        viewer.render_offscreen(gpu, target, cam, 0.1)?;
    }
    Ok(())
}

/// Streams `viewer` at `cam` until its view is settled (every wanted node drawn, no job in
/// flight, node textures made; at most `timeout_s`), draws a few more frames so fades end and
/// background light grids arrive, reads the last frame's depth from `target` (which must be
/// `cam`'s viewport size) and measures the drawn terrain's error on the screen: over all its
/// samples and over those the frame shows.
pub fn settled_view_error(
    gpu: &Gpu,
    viewer: &mut Viewer,
    target: &Target,
    cam: &Camera,
    timeout_s: f64,
) -> Result<ShownError, String> {
    settle(gpu, viewer, target, cam, timeout_s)?;
    let z = target
        .read_depth(gpu)
        .map_err(|e| format!("reading the frame's depth: {e}"))?;
    let depth = DepthImage::from_reversed_z(target.size, &z, cam.near_m);
    let world = &viewer.streamer.shared.world;
    let tree = &viewer.streamer.shared.tree;
    let (mut cache, mut tiles) = (BoundsCache::new(), TileCache::new());
    let mut samples = Vec::new();
    let mut triangles = 0;
    for d in viewer.streamer.draw_list() {
        let m = mesh::build_with_tiles(world, tree, &mut cache, &mut tiles, d.key)
            .decimated(d.decimation);
        triangles += m.indices.len() / 3;
        samples.push(measure::node_error_samples(
            world,
            tree,
            &m,
            SAMPLES_PER_QUAD,
        ));
    }
    let refs: Vec<_> = samples.iter().collect();
    let (shown, hidden_samples) = measure::view_error_shown_px(&refs, cam, &depth);
    Ok(ShownError {
        drawn_nodes: samples.len(),
        triangles,
        all: measure::view_max_error_px(&refs, cam, true),
        shown,
        hidden_samples,
    })
}
