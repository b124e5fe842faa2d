//! The light-grid kind's renderer: it draws nothing itself. Its upload hook gives a node the
//! pool tile of the grid that shades it ([`super::light_pool::LightPool::lease`]) and stores
//! the lease as the node's [`NodeLightGpu`]; the terrain, vegetation and object renderers put
//! [`light_entry`] into their node-table entries (fully lit until the grid arrives). Each
//! frame `prepare` writes the tiles of drawn grids that arrived or were relit since (a sun
//! change), nearest first as the light thread makes them, and finds the drawn nodes that blend
//! toward a coarser neighbour's grid (`lighting::seams`); it runs before the other renderers'.

use super::Gpu;
use super::frame::{DrawStats, FrameResources};
use super::light_pool::{LightEntry, LightLease, NO_LIGHT};
use super::scene::{FrameDraws, NodeRenderer};
use super::terrain::legend_srgb;
use crate::color::srgb_to_linear;
use crate::lighting::content::{LightingContent, NodeLight};
use crate::lighting::grid::{grid_level, layer_heights_m};
use crate::lighting::seams::{coarser_sides, node_columns};
use crate::stream::{NodeWork, Shared};
use crate::surface::World;
use crate::terrain::quadtree::QuadTree;
use std::sync::Arc;

/// A node's lease on its grid's pool tile (in the node's `GpuSlots`).
#[derive(Debug, Clone)]
pub struct NodeLightGpu(pub Arc<LightLease>);

/// The node-table numbers of `work`'s light grid this frame, [`NO_LIGHT`] without one.
pub fn light_entry(frame: &FrameResources, tree: &QuadTree, work: &NodeWork) -> LightEntry {
    let Some(l) = work.gpu.get::<NodeLightGpu>() else {
        return NO_LIGHT;
    };
    let grid = l.0.entry(tree, work.key);
    if grid == NO_LIGHT.grid {
        return NO_LIGHT;
    }
    let steps = frame.light.seams.get(&work.key).map_or(0, |s| s.0);
    LightEntry {
        grid,
        seam: [
            f32::from(steps),
            node_columns(work.key.level, grid_level(tree)) as f32,
        ],
    }
}

/// The map's mean ground albedo (linear RGB): its legend colours weighted by the cells of each
/// ground type.
pub fn mean_ground_albedo(world: &World) -> [f32; 3] {
    let legend = legend_srgb(world);
    let mut cells = vec![0u64; legend.len()];
    for &t in world.map.ground.data() {
        if let Some(c) = cells.get_mut(usize::from(t)) {
            *c += 1;
        }
    }
    let total = cells.iter().sum::<u64>().max(1) as f64;
    let mut out = [0.0f32; 3];
    for (srgb, &n) in legend.iter().zip(&cells) {
        for (o, &v) in out.iter_mut().zip(srgb) {
            *o += (srgb_to_linear(v) * n as f64 / total) as f32;
        }
    }
    out
}

#[derive(Debug, Default)]
pub struct LightingRenderer {
    /// Drawn nodes still without their grid this frame (drawn fully lit).
    pub unlit_drawn: usize,
}

impl LightingRenderer {
    /// The renderer; writes the grids' layer heights and the map's mean ground albedo into the
    /// pool's uniform.
    pub fn create(gpu: &Gpu, frame: &FrameResources, shared: &Shared) -> Box<dyn NodeRenderer> {
        if let Some(kind) = shared.kind::<LightingContent>() {
            frame.light.set_map(
                &gpu.queue,
                &layer_heights_m(kind.canopy()),
                mean_ground_albedo(&shared.world),
            );
        }
        Box::new(Self::default())
    }
}

impl NodeRenderer for LightingRenderer {
    fn name(&self) -> &'static str {
        "lighting"
    }

    fn upload(
        &mut self,
        _gpu: &Gpu,
        frame: &FrameResources,
        _tree: &QuadTree,
        work: &mut NodeWork,
    ) -> usize {
        let Some(light) = work.get::<NodeLight>() else {
            return 0;
        };
        let owns = light.owns;
        let Some(lease) = frame.light.lease(&light.grid) else {
            return 0;
        };
        work.gpu.put(NodeLightGpu(lease));
        if owns {
            crate::lighting::content::GRID_GPU_BYTES
        } else {
            0
        }
    }

    fn prepare(&mut self, gpu: &Gpu, frame: &mut FrameResources, draws: &FrameDraws<'_>) {
        self.unlit_drawn = 0;
        let lit: Vec<_> = draws
            .drawn
            .iter()
            .filter(|d| d.work.gpu.get::<NodeLightGpu>().is_some())
            .map(|d| d.key)
            .collect();
        frame.light.seams = coarser_sides(draws.tree, &lit);
        for d in draws.drawn.iter().chain(draws.ancestors) {
            if let Some(l) = d.work.gpu.get::<NodeLightGpu>() {
                frame.light.refresh(&gpu.queue, &l.0);
            }
        }
        for d in draws.drawn {
            if d.work
                .gpu
                .get::<NodeLightGpu>()
                .is_none_or(|l| !l.0.written())
            {
                self.unlit_drawn += 1;
            }
        }
    }

    fn draw(
        &self,
        _pass: &mut wgpu::RenderPass<'_>,
        _frame: &FrameResources,
        _draws: &FrameDraws<'_>,
        _stats: &mut DrawStats,
    ) {
    }
}
