//! The light-grid kind's renderer: it draws nothing itself. Its upload hook gives a node with a
//! grid an empty [`NodeLightGpu`]; the first frame the node is drawn (or drawn through, as an
//! ancestor) `prepare` leases the pool tile of the grid that shades it
//! ([`super::light_pool::LightPool::lease`]), so nodes that are only prefetched hold no tile,
//! and a drawn node that found the pool full tries again each frame. The terrain, vegetation and
//! object renderers put the node's light entry (found once a frame here, read through
//! `LightPool::drawn_entry`) into their node-table entries: until a node's grid arrives, the
//! nearest drawn-through ancestor's written grid (coarser columns, the same values at them),
//! fully lit without one. `prepare` writes a grid's tile when its lease is taken, and the
//! tiles of the leased grids among those the light threads stored since the last frame (first
//! computations and relights after a sun change; the light kind lists their keys).
//! Each frame it also finds the drawn nodes that blend toward a coarser neighbour's grid
//! (`lighting::seams`); it runs before the other renderers'.

use super::Gpu;
use super::frame::{DrawStats, FrameResources};
use super::light_pool::{LightEntry, LightLease, NO_LIGHT};
use super::scene::{FrameDraws, NodeRenderer, UploadEncoder};
use super::terrain::legend_srgb;
use crate::color::srgb_to_linear;
use crate::lighting::content::{GridsStored, LightingContent, NodeLight};
use crate::lighting::grid::layer_heights_m;
use crate::lighting::seams::{coarser_sides, node_columns};
use crate::stream::{NodeWork, Shared};
use crate::surface::World;
use crate::terrain::quadtree::{NodeKey, QuadTree};
use rustc_hash::FxHashMap;
use std::sync::{Arc, OnceLock};

/// A node's lease on its grid's pool tile (in the node's `GpuSlots`): empty until the node is
/// first drawn with a free tile in the pool.
#[derive(Debug, Default)]
pub struct NodeLightGpu(OnceLock<Arc<LightLease>>);

impl NodeLightGpu {
    /// The node's lease, once taken.
    pub fn lease(&self) -> Option<&Arc<LightLease>> {
        self.0.get()
    }
}

/// The node-table numbers of node `key` shaded by grid lease `l` (its own, or an ancestor's,
/// read at that grid's columns, which are every 2nd, 4th ... of its own: the same values
/// there), blending toward coarser neighbours on the sides `steps` codes.
fn light_entry(l: &LightLease, tree: &QuadTree, key: NodeKey, steps: u16) -> LightEntry {
    LightEntry {
        grid: l.entry(tree, key),
        seam: [
            f32::from(steps),
            node_columns(key.level, l.grid.key.level) as f32,
        ],
    }
}

/// The value of `key`'s nearest ancestor in `by_key`.
fn nearest_ancestor<T>(key: NodeKey, by_key: &FxHashMap<NodeKey, T>) -> Option<&T> {
    key.ancestors().find_map(|a| by_key.get(&a))
}

/// The map's mean ground albedo (linear RGB): its legend colours weighted by the samples of
/// each ground type in the coarsest of the ground layer's levels (at most 256 samples a side,
/// a regular subsample of the layer: a few pages read at the open whatever the map's size), or
/// in the layer itself where it has none (a layer of at most 2 x 2 samples).
pub fn mean_ground_albedo(world: &World) -> [f32; 3] {
    let legend = legend_srgb(world);
    let ground = world.ground_levels.coarsest().unwrap_or(&world.map.ground);
    let mut counts = [0u64; 256];
    for &t in ground.region(0, 0, ground.width(), ground.height()).data() {
        counts[usize::from(t)] += 1;
    }
    let cells = &counts[..legend.len().min(counts.len())];
    let total = cells.iter().sum::<u64>().max(1) as f64;
    let mut out = [0.0f32; 3];
    for (srgb, &n) in legend.iter().zip(cells) {
        for (o, &v) in out.iter_mut().zip(srgb) {
            *o += (srgb_to_linear(v) * n as f64 / total) as f32;
        }
    }
    out
}

#[derive(Debug, Default)]
pub struct LightingRenderer {
    /// Drawn nodes without their own grid and without an ancestor's this frame (drawn fully
    /// lit).
    pub unlit_drawn: usize,
    /// Drawn nodes without their own grid this frame, shaded by an ancestor's coarser one.
    pub coarse_lit_drawn: usize,
    /// The keys of the grids the light threads stored since the last `prepare`.
    stored: Option<GridsStored>,
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
            return Box::new(Self {
                stored: Some(kind.grids_stored()),
                ..Self::default()
            });
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
        _frame: &FrameResources,
        _tree: &QuadTree,
        work: &mut NodeWork,
        _copies: &mut UploadEncoder<'_>,
    ) -> usize {
        let Some(light) = work.get::<NodeLight>() else {
            return 0;
        };
        // The tile is leased when the node is first drawn (`prepare`); the grid's bytes count
        // here, in the frame that made the node ready.
        let owns = light.owns;
        work.gpu.put(NodeLightGpu::default());
        if owns {
            crate::lighting::content::GRID_GPU_BYTES
        } else {
            0
        }
    }

    fn prepare(&mut self, gpu: &Gpu, frame: &mut FrameResources, draws: &FrameDraws<'_>) {
        // The tiles of the live leases whose grids were stored since the last frame, drawn
        // or not (a grid stored meanwhile is listed for the next frame). Then the nodes drawn
        // (or drawn through): a lease for those without one yet (the first frame they are
        // drawn, or again each frame while the pool is full), its tile written if its grid is
        // computed.
        for key in self
            .stored
            .as_ref()
            .map(GridsStored::take)
            .unwrap_or_default()
        {
            frame.light.refresh_key(&gpu.queue, key);
        }
        // Each drawn, then drawn-through, node's lease, looked up once.
        let leases: Vec<Option<&Arc<LightLease>>> = draws
            .drawn
            .iter()
            .chain(draws.ancestors)
            .map(|d| {
                let slot = d.work.gpu.get::<NodeLightGpu>()?;
                if slot.lease().is_none()
                    && let Some(light) = d.work.get::<NodeLight>()
                    && let Some(lease) = frame.light.lease(&light.grid)
                {
                    frame.light.refresh(&gpu.queue, &lease);
                    // `prepare` is the only writer, so the slot is still empty.
                    let _ = slot.0.set(lease);
                }
                slot.lease()
            })
            .collect();
        let (drawn_leases, ancestor_leases) = leases.split_at(draws.drawn.len());
        let lit: Vec<_> = draws
            .drawn
            .iter()
            .zip(drawn_leases)
            .filter(|(_, l)| l.is_some())
            .map(|(d, _)| d.key)
            .collect();
        let seams = coarser_sides(draws.tree, &lit);
        // Each drawn (or drawn-through) node's entry: its own grid once written, else the
        // nearest drawn-through ancestor's written grid, if any (drawn fully lit otherwise).
        let written: FxHashMap<NodeKey, &Arc<LightLease>> = draws
            .ancestors
            .iter()
            .zip(ancestor_leases)
            .filter_map(|(a, l)| l.filter(|l| l.written()).map(|l| (a.key, l)))
            .collect();
        (self.unlit_drawn, self.coarse_lit_drawn) = (0, 0);
        let light = &mut frame.light;
        light.drawn_entries.clear();
        light.ancestor_entries.clear();
        for ((d, is_drawn), lease) in draws
            .drawn
            .iter()
            .map(|d| (d, true))
            .chain(draws.ancestors.iter().map(|a| (a, false)))
            .zip(&leases)
        {
            let entry = match lease.filter(|l| l.written()) {
                Some(l) => {
                    let steps = seams.get(&d.key).map_or(0, |s| s.0);
                    light_entry(l, draws.tree, d.key, steps)
                }
                // An ancestor's grid blends no seams (its sides' steps are for its own nodes).
                None => {
                    if let Some(l) = nearest_ancestor(d.key, &written) {
                        self.coarse_lit_drawn += usize::from(is_drawn);
                        light_entry(l, draws.tree, d.key, 0)
                    } else {
                        self.unlit_drawn += usize::from(is_drawn);
                        NO_LIGHT
                    }
                }
            };
            if is_drawn {
                light.drawn_entries.push((d.key, entry));
            } else {
                light.ancestor_entries.push((d.key, entry));
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
