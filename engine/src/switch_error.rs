//! The image error of vegetation's representation switches, measured on rendered frames. When
//! a node splits, its items change how they are drawn (mesh, billboard, group billboard, left
//! out; [the ladder](mod@crate::vegetation::representation)). The selection draws a node with
//! vegetation no nearer than where its vegetation error `ERROR_PER_SPACING * spacing` projects
//! to tau on the axis of the view (off the axis the on-screen bound only keeps it farther). So the worst the
//! switch can show is at that distance: the camera stands there, the node's items of one
//! transition are drawn as the node draws them and as its four children draw them (the
//! vegetation renderer alone, on an empty frame), and the two silhouettes are compared
//! ([`crate::silhouette::distance`]). The items' ground points count as covered on both sides:
//! an item that one side leaves out, or that covers no pixel centre on one side (a sub-pixel
//! item the raster misses), is measured as collapsing to where it stands (its size on the
//! screen), not as far as the nearest other item. Elsewhere a ground point lies inside both
//! silhouettes (at the foot of the item) and changes nothing.

use crate::camera::Camera;
use crate::measure::ScreenProjection;
use crate::render::scene::{DrawnNode, FrameDraws, Scene, UploadEncoder};
use crate::render::vegetation::VegetationRenderer;
use crate::render::{COLOR_FORMAT, Gpu, Target, frame::ViewOptions};
use crate::silhouette::{self, Mask, SilhouetteDistance};
use crate::stream::NodeWork;
use crate::surface::World;
use crate::terrain::quadtree::{NodeKey, QuadTree};
use crate::vegetation::representation::ERROR_PER_SPACING;
use crate::vegetation::{Item, NodeVegetation, Placer, Representation};
use crate::vegetation::{node_vegetation, representation};
use glam::{DVec2, DVec3};

/// How an item's drawing changes when its node splits: as the node draws it and as its
/// children do (`None`: left out).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct Transition {
    pub coarse: Option<Representation>,
    pub fine: Option<Representation>,
}

impl Transition {
    /// "billboard -> mesh" and the like, coarse first.
    pub fn label(&self) -> String {
        let name = |r: Option<Representation>| match r {
            Some(Representation::Mesh) => "mesh",
            Some(Representation::Billboard) => "billboard",
            Some(Representation::Group) => "group billboard",
            None => "left out",
        };
        format!("{} -> {}", name(self.coarse), name(self.fine))
    }
}

/// One measured switch.
#[derive(Debug, Clone, PartialEq)]
pub struct SwitchError {
    pub key: NodeKey,
    /// The node's mesh spacing (its children's is half).
    pub spacing_m: f64,
    pub transition: Transition,
    /// The transition's items in the node and in its children (the same items where both
    /// draw them).
    pub items: [usize; 2],
    /// Where the camera stood: compass direction from the node (0 south, the billboards' baked
    /// view; 90 east) and horizontal distance to the node's rectangle.
    pub azimuth_deg: f64,
    pub distance_m: f64,
    pub tau_px: f64,
    pub silhouette: SilhouetteDistance,
}

/// The nearest distance at which the selection may draw a node of mesh spacing `spacing_m`
/// with vegetation at threshold `tau_px` (its vegetation error on the view's axis at tau).
pub fn switch_distance_m(spacing_m: f64, cam_k_px: f64, tau_px: f64) -> f64 {
    ERROR_PER_SPACING * spacing_m * cam_k_px / tau_px
}

/// A vegetation renderer on its own and an offscreen target, for drawing nodes' items.
pub struct SwitchRig {
    scene: Scene,
    target: Target,
    fovy_rad: f64,
    /// The view measured, and how many times as finely (per side) it is drawn.
    viewport_px: [u32; 2],
    supersample: u32,
}

impl std::fmt::Debug for SwitchRig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "SwitchRig({:?} px drawn {}x)",
            self.viewport_px, self.supersample
        )
    }
}

impl SwitchRig {
    /// A rig measuring `placer`'s species in a view of `viewport_px` at vertical field of view
    /// `fovy_rad`, drawn `supersample` times as finely per side (distances are given in the
    /// view's pixels: the raster's quantization is `1 / supersample` of one).
    pub fn new(
        gpu: &Gpu,
        placer: &Placer,
        viewport_px: [u32; 2],
        fovy_rad: f64,
        supersample: u32,
    ) -> Self {
        let mut scene = Scene::new(gpu, COLOR_FORMAT);
        let names: Vec<String> = placer.species.iter().map(|s| s.name.clone()).collect();
        let renderer = VegetationRenderer::new(gpu, &scene.frame, &names);
        scene.push(Box::new(renderer));
        let supersample = supersample.max(1);
        let drawn_px = [viewport_px[0] * supersample, viewport_px[1] * supersample];
        Self {
            scene,
            target: Target::new(&gpu.device, drawn_px, COLOR_FORMAT),
            fovy_rad,
            viewport_px,
            supersample,
        }
    }

    /// Measures every transition the items of `key` make when it splits, at threshold `tau_px`,
    /// from each of `azimuths_deg` (nothing for a node of the finest level).
    pub fn measure_node(
        &mut self,
        gpu: &Gpu,
        world: &World,
        placer: &Placer,
        tree: &QuadTree,
        key: NodeKey,
        tau_px: f64,
        azimuths_deg: &[f64],
    ) -> Result<Vec<SwitchError>, String> {
        if key.level >= tree.max_level {
            return Ok(Vec::new());
        }
        let s_m = tree.spacing_m(key.level);
        let child_finest = key.level + 1 == tree.max_level;
        let transition = |it: &Item| {
            let kind = placer.species[usize::from(it.species)].kind;
            let h = f64::from(it.height_m);
            Transition {
                coarse: representation(kind, h, s_m, false),
                fine: representation(kind, h, s_m * 0.5, child_finest),
            }
        };
        let coarse = node_vegetation(world, placer, tree, key);
        let children = key.children();
        let fine: Vec<NodeVegetation> = children
            .iter()
            .map(|&c| node_vegetation(world, placer, tree, c))
            .collect();
        let mut transitions: Vec<Transition> = std::iter::once(&coarse)
            .chain(&fine)
            .flat_map(|v| v.groups.iter().flat_map(|g| &g.items))
            .map(transition)
            .filter(|t| t.coarse != t.fine)
            .collect();
        transitions.sort();
        transitions.dedup();
        let mut out = Vec::new();
        for t in transitions {
            let keep = |it: &Item| transition(it) == t;
            let mut coarse_work = NodeWork::new(key);
            let only = coarse.only(tree.rect(key), keep);
            let coarse_items: Vec<Item> =
                only.groups.iter().flat_map(|g| g.items.clone()).collect();
            coarse_work.put(only);
            let mut fine_items = Vec::new();
            let mut fine_works: Vec<NodeWork> = children
                .iter()
                .zip(&fine)
                .map(|(&c, v)| {
                    let only = v.only(tree.rect(c), keep);
                    fine_items.extend(only.groups.iter().flat_map(|g| g.items.iter().copied()));
                    let mut w = NodeWork::new(c);
                    w.put(only);
                    w
                })
                .collect();
            self.upload(
                gpu,
                tree,
                std::iter::once(&mut coarse_work).chain(&mut fine_works),
            );
            let all_items: Vec<&Item> = coarse_items.iter().chain(&fine_items).collect();
            for &az in azimuths_deg {
                let (cam, distance_m) = self.camera(tree, key, &all_items, tau_px, az);
                let mut a =
                    self.draw(gpu, tree, &cam, tau_px, std::slice::from_ref(&coarse_work))?;
                let mut b = self.draw(gpu, tree, &cam, tau_px, &fine_works)?;
                let mut grounds = Mask::empty(a.size_px);
                let proj = ScreenProjection::new(&cam);
                for it in &all_items {
                    if let Some(p) = proj.pixel_of(DVec3::new(it.x_m, it.y_m, it.z_m)) {
                        grounds.mark(p);
                    }
                }
                a = a.union(&grounds);
                b = b.union(&grounds);
                out.push(SwitchError {
                    key,
                    spacing_m: s_m,
                    transition: t,
                    items: [coarse_items.len(), fine_items.len()],
                    azimuth_deg: az,
                    distance_m,
                    tau_px,
                    silhouette: silhouette::distance(&a, &b)?.in_pixels_of(self.supersample),
                });
            }
        }
        Ok(out)
    }

    /// Uploads the nodes' vegetation and bakes their group billboards.
    fn upload<'w>(
        &mut self,
        gpu: &Gpu,
        tree: &QuadTree,
        works: impl Iterator<Item = &'w mut NodeWork>,
    ) {
        let mut enc = UploadEncoder::Own(None);
        for w in works {
            self.scene.upload_into(gpu, tree, w, &mut enc);
        }
        self.scene.finish_uploads(gpu, &mut enc, f64::INFINITY);
        if enc.finish(&gpu.queue) {
            self.scene.after_deferred_submit();
        }
    }

    /// The camera at the switch distance of `key` at `tau_px`, seen from `azimuth_deg`, at the
    /// middle height of the items' ground, looking level at the node's centre; and its
    /// horizontal distance to the node's rectangle.
    fn camera(
        &self,
        tree: &QuadTree,
        key: NodeKey,
        items: &[&Item],
        tau_px: f64,
        azimuth_deg: f64,
    ) -> (Camera, f64) {
        let r = tree.rect(key);
        let centre = DVec2::new(r.min[0] + r.max[0], r.min[1] + r.max[1]) * 0.5;
        let half_m = (r.max[0] - r.min[0]) * 0.5;
        let (lo, hi) = items
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), it| {
                (lo.min(it.z_m), hi.max(it.z_m))
            });
        let z_m = if lo <= hi { (lo + hi) * 0.5 } else { 0.0 };
        let probe = Camera::look_at(DVec3::ZERO, DVec3::Y, self.fovy_rad, self.viewport_px);
        let want_m = switch_distance_m(tree.spacing_m(key.level), probe.k_px(), tau_px);
        let a = azimuth_deg.to_radians();
        let dir = DVec2::new(a.sin(), -a.cos());
        // How far out along `dir` the rectangle is `want_m` away (monotone: bisection).
        let rect_distance = |t: f64| {
            let d = (dir * t).abs() - DVec2::splat(half_m);
            d.max(DVec2::ZERO).length()
        };
        let (mut lo_t, mut hi_t) = (0.0, half_m * 2.0 + want_m);
        for _ in 0..80 {
            let mid = 0.5 * (lo_t + hi_t);
            if rect_distance(mid) < want_m {
                lo_t = mid;
            } else {
                hi_t = mid;
            }
        }
        let eye = centre + dir * hi_t;
        let cam = Camera::look_at(
            DVec3::new(eye.x, eye.y, z_m),
            DVec3::new(centre.x, centre.y, z_m),
            self.fovy_rad,
            self.target.size,
        );
        (cam, rect_distance(hi_t))
    }

    /// Draws `works` (their vegetation only, each node fully faded in) at `cam` and returns what
    /// the frame covers.
    fn draw(
        &mut self,
        gpu: &Gpu,
        tree: &QuadTree,
        cam: &Camera,
        tau_px: f64,
        works: &[NodeWork],
    ) -> Result<Mask, String> {
        let drawn: Vec<DrawnNode<'_>> = works.iter().map(DrawnNode::faded_in).collect();
        let view = ViewOptions {
            sky: false,
            ..ViewOptions::default()
        };
        let frustum = cam.frustum();
        let draws = FrameDraws {
            camera: cam,
            frustum: &frustum,
            view: &view,
            tree,
            drawn: &drawn,
            ancestors: &[],
            dt_s: 0.0,
            tau_px,
            upload_bytes_left: 0,
            upload_time_left_s: 0.0,
        };
        let mut enc = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("switch error frame"),
            });
        self.scene.render(
            gpu,
            &mut enc,
            &self.target.color_view,
            &self.target.depth_view,
            &draws,
        );
        gpu.queue.submit([enc.finish()]);
        let z = self
            .target
            .read_depth(gpu)
            .map_err(|e| format!("reading the frame's depth: {e}"))?;
        Mask::from_reversed_z(self.target.size, &z)
    }
}
