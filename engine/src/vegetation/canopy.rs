//! Line-of-sight extinction through vegetation, for splitting less where the view is blocked.

use super::placement::Placer;
use crate::surface::{Rect, World};

/// Samples along a line of sight for [`Canopy::visibility`].
pub const SIGHT_SAMPLES: usize = 16;

/// A coarse model of how much vegetation blocks a line of sight, for splitting less where the
/// view is blocked (seed 002). Per species: the extinction `density * crown diameter` (1/m) on
/// the density layer's grid, up to the species' typical height above the ground; large trees
/// from the map's list as crown diameters per 8 m cell, up to their mean height.
#[derive(Debug, Clone)]
pub struct Canopy {
    /// Per species with a layer: (extinction grid 1/m, spacing m, height m).
    layers: Vec<(worldgen::Grid<f32>, f64, f64)>,
    origin_m: [f64; 2],
    heights_spacing_m: f64,
    /// The tallest species' height: lines of sight above the ground by more never hit.
    pub top_m: f64,
}

impl Canopy {
    pub fn new(world: &World, placer: &Placer) -> Self {
        let mut layers = Vec::new();
        let mut top = 0.0f64;
        for sp in &placer.species {
            let Some(l) = sp.layer else { continue };
            let layer = &world.map.densities[l];
            let scale = layer.spec.max_density_per_m2 / 255.0 * 2.0 * sp.radius_m;
            let g = &layer.density;
            let mut ext = worldgen::Grid::new(g.width(), g.height(), 0.0f32);
            for y in 0..g.height() {
                for x in 0..g.width() {
                    ext.set(x, y, (f64::from(g.get(x, y)) * scale) as f32);
                }
            }
            top = top.max(sp.height_m);
            layers.push((ext, layer.spec.spacing_m, sp.height_m));
        }
        // Large trees: crown diameters per cell area on an 8 m grid, up to their mean height.
        if !world.map.trees.is_empty() {
            let cell = 8.0;
            let s = world.size_m();
            let (w, h) = (
                (s[0] / cell).ceil() as usize + 1,
                (s[1] / cell).ceil() as usize + 1,
            );
            let mut ext = worldgen::Grid::new(w, h, 0.0f32);
            let o = world.origin_m();
            let mut height_sum = 0.0;
            for t in &world.map.trees {
                let x = (((t.x_m - o[0]) / cell).round() as usize).min(w - 1);
                let y = (((t.y_m - o[1]) / cell).round() as usize).min(h - 1);
                let add = 2.0 * f64::from(t.crown_radius_m) / (cell * cell);
                ext.set(x, y, ext.get(x, y) + add as f32);
                height_sum += f64::from(t.height_m);
            }
            let mean = height_sum / world.map.trees.len() as f64;
            top = top.max(mean);
            layers.push((ext, cell, mean));
        }
        Self {
            layers,
            origin_m: world.origin_m(),
            heights_spacing_m: world.map.manifest.heights.spacing_m,
            top_m: top,
        }
    }

    /// The fraction of the line of sight from `eye` to `target` that vegetation leaves clear,
    /// `exp(-optical depth)`, with the optical depth summed at [`SIGHT_SAMPLES`] midpoints
    /// (ground from the bilinear map heights).
    pub fn visibility(&self, world: &World, eye: glam::DVec3, target: glam::DVec3) -> f64 {
        let d = target - eye;
        let len = d.length();
        if len <= 0.0 || self.layers.is_empty() {
            return 1.0;
        }
        let step = len / SIGHT_SAMPLES as f64;
        let heights = worldgen::sample::GridPlacement {
            origin_m: self.origin_m,
            spacing_m: self.heights_spacing_m,
        };
        let mut depth = 0.0;
        for i in 0..SIGHT_SAMPLES {
            let p = eye + d * ((i as f64 + 0.5) / SIGHT_SAMPLES as f64);
            let above = p.z - worldgen::sample::bilinear(&world.map.heights, heights, p.x, p.y);
            depth += self.extinction_per_m(p.x, p.y, above) * step;
        }
        (-depth).exp()
    }
}

impl Canopy {
    /// The extinction (1/m) at world point (`x_m`, `y_m`) and `above_m` metres above the
    /// ground: the sum over the species layers (and large trees) that reach that high, each
    /// bilinear on its own grid. Zero below the ground and above [`Self::top_m`].
    pub fn extinction_per_m(&self, x_m: f64, y_m: f64, above_m: f64) -> f64 {
        if !(0.0..=self.top_m).contains(&above_m) {
            return 0.0;
        }
        let mut sum = 0.0;
        for (ext, spacing, h) in &self.layers {
            if above_m <= *h {
                let at = worldgen::sample::GridPlacement {
                    origin_m: self.origin_m,
                    spacing_m: *spacing,
                };
                sum += worldgen::sample::bilinear(ext, at, x_m, y_m);
            }
        }
        sum
    }
}

impl Canopy {
    /// The heights (m) up to which each layer (species, large trees) blocks light, ascending.
    pub fn layer_tops_m(&self) -> Vec<f64> {
        let mut v: Vec<f64> = self.layers.iter().map(|l| l.2).collect();
        v.sort_by(f64::total_cmp);
        v.dedup();
        v
    }

    /// An upper bound of [`Self::extinction_per_m`] over the rectangle `min`..`max` (world m)
    /// at any height: per layer the largest grid value whose cell touches the rectangle (a
    /// bilinear value never exceeds its corners; positions outside a grid clamp to its border).
    pub fn max_extinction_in(&self, min: [f64; 2], max: [f64; 2]) -> f64 {
        let mut sum = 0.0;
        for (ext, spacing, _) in &self.layers {
            let range = |axis: usize, len: usize| {
                let to =
                    |v: f64| ((v - self.origin_m[axis]) / spacing).clamp(0.0, (len - 1) as f64);
                (
                    to(min[axis]).floor() as usize,
                    to(max[axis]).ceil() as usize,
                )
            };
            let (x0, x1) = range(0, ext.width());
            let (y0, y1) = range(1, ext.height());
            let mut m = 0.0f64;
            for y in y0..=y1 {
                for x in x0..=x1 {
                    m = m.max(f64::from(ext.get(x, y)));
                }
            }
            sum += m;
        }
        sum
    }
}

impl Canopy {
    /// The factor on a node's projected error for a camera at `eye`: the visibility of the
    /// node's top centre, integrated up to the node's border (its own vegetation does not hide
    /// it), or 1 when the camera is above the canopy or the node is near.
    pub fn error_factor(
        &self,
        world: &World,
        eye: glam::DVec3,
        rect: Rect,
        z_top_m: f64,
        dist_m: f64,
    ) -> f64 {
        let half = 0.5 * (rect.max[0] - rect.min[0]);
        if dist_m <= 2.0 * half || self.layers.is_empty() {
            return 1.0;
        }
        let heights = worldgen::sample::GridPlacement {
            origin_m: self.origin_m,
            spacing_m: self.heights_spacing_m,
        };
        let ground = worldgen::sample::bilinear(&world.map.heights, heights, eye.x, eye.y);
        if eye.z - ground > self.top_m {
            return 1.0;
        }
        let centre = glam::DVec3::new(
            0.5 * (rect.min[0] + rect.max[0]),
            0.5 * (rect.min[1] + rect.max[1]),
            z_top_m,
        );
        let d = centre - eye;
        let flat = d.truncate().length().max(1e-9);
        // Stop at the node's border (approximately: half its side before the centre).
        let end = eye + d * (1.0 - (half / flat).min(1.0));
        self.visibility(world, eye, end)
    }
}
