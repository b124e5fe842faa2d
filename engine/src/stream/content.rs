//! Node content as plug-ins. A [`ContentKind`] (terrain, vegetation, later ground textures,
//! light grids, buildings) names itself, lists the CPU [`Phase`]s that make its [`Payload`] for a
//! node, and may scale the split metric where it blocks the view. The scheduler knows only these
//! traits: it runs the phases of every registered kind in registration order, keeps the payloads
//! in the node's [`NodeWork`], and counts their bytes in the cache budget. The GPU side of a
//! kind (upload and draw hooks) is a `render::NodeRenderer` registered next to it.

use super::Shared;
use crate::surface::{Rect, World};
use crate::terrain::bounds::NodeBounds;
use crate::terrain::quadtree::NodeKey;
use crate::terrain::tiles::{Tile, TileKey};
use glam::DVec3;
use std::any::{Any, TypeId};
use std::sync::Arc;

/// Where a phase runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PhaseKind {
    /// On a worker thread.
    Cpu,
    /// On the owner (render) thread, under the per-frame GPU budget.
    Gpu,
}

/// The work of one phase: reads the shared state and the node's earlier results, writes its own.
pub type PhaseFn = Arc<dyn Fn(&Shared, &mut NodeWork) + Send + Sync>;

/// One step of preparing a node.
#[derive(Clone)]
pub struct Phase {
    pub name: &'static str,
    pub kind: PhaseKind,
    pub run: PhaseFn,
}

impl Phase {
    /// A phase that runs on a worker thread.
    pub fn cpu(
        name: &'static str,
        run: impl Fn(&Shared, &mut NodeWork) + Send + Sync + 'static,
    ) -> Self {
        Self {
            name,
            kind: PhaseKind::Cpu,
            run: Arc::new(run),
        }
    }

    /// A phase that runs on the owner thread under the GPU budget.
    pub fn gpu(
        name: &'static str,
        run: impl Fn(&Shared, &mut NodeWork) + Send + Sync + 'static,
    ) -> Self {
        Self {
            name,
            kind: PhaseKind::Gpu,
            run: Arc::new(run),
        }
    }
}

impl std::fmt::Debug for Phase {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} ({:?})", self.name, self.kind)
    }
}

/// What one content kind keeps for a node once prepared.
pub trait Payload: Any + Send + Sync + std::fmt::Debug {
    /// Bytes the node keeps resident for this payload (its GPU data), counted in the node-cache
    /// budget.
    fn bytes(&self) -> usize;
}

/// One kind of node content. Register it with the streamer (`Streamer::new`) and its renderer
/// with the viewer; nothing else changes.
pub trait ContentKind: Any + Send + Sync + std::fmt::Debug {
    /// A short name (phase names and statistics).
    fn name(&self) -> &'static str;

    /// The CPU phases that make this kind's payload of a node, in order. They run on workers
    /// after the phases of the kinds registered before this one (so they may read those
    /// payloads), and put their result with [`NodeWork::put`].
    fn phases(self: Arc<Self>) -> Vec<Phase>;

    /// Given the streamer's world once, when the streamer is made (shared, not copied). A kind
    /// with work of its own off the node jobs, such as the light threads, keeps it. Default:
    /// nothing.
    fn attach_world(&self, _world: &Arc<World>) {}

    /// Told where the camera is at every streaming update (a kind with background work of its
    /// own, such as the light grids, does the nearest first). Default: nothing.
    fn observe_camera(&self, _camera_m: DVec3) {}

    /// Told the nodes the frame draws, at every streaming update once its draw list is made (a
    /// kind with background work of its own, such as the light grids, does the drawn nodes'
    /// work first). Default: nothing.
    fn observe_drawn(&self, _drawn: &[super::DrawNode]) {}

    /// How visible (0..=1) the top of a node at `rect` (highest point `z_max_m`, at `dist_m`) is
    /// from `camera_m` through this content; selection multiplies a node's projected error by it
    /// when `StreamSettings::vegetation_occlusion` is on. 1: this content blocks nothing.
    /// Called while the selection holds the bounds store's lock: it must not read
    /// `Shared::bounds`.
    fn visibility(
        &self,
        _shared: &Shared,
        _camera_m: DVec3,
        _rect: Rect,
        _z_max_m: f64,
        _dist_m: f64,
    ) -> f64 {
        1.0
    }
}

/// A node's content while it is being prepared, and once prepared.
#[derive(Debug)]
pub struct NodeWork {
    pub key: NodeKey,
    pub bounds: Option<NodeBounds>,
    /// Tiles held by this job (released when the job's CPU phases end, finished or cancelled).
    pub tiles: Vec<(TileKey, Arc<Tile>)>,
    /// One payload per content kind that produced one (at most one of each type), each with
    /// its type's id: a lookup compares ids in place, with no call through each payload's
    /// vtable (renderers look up every drawn node's payloads every frame).
    payloads: Vec<(TypeId, Box<dyn Payload>)>,
    /// Set by the GPU phase: bytes that went to the GPU.
    pub uploaded_bytes: usize,
    /// Set by the GPU phase: the GPU seconds its upload hooks expect the work they recorded
    /// to take (e.g. rendering a ground texture); counts in the per-frame GPU budget.
    pub gpu_estimate_s: f64,
    /// The frame thread's time in the node's GPU phases, upload hooks included (s).
    pub gpu_phases_s: f64,
    /// The node's GPU objects, set by the renderers' upload hooks, dropped with the node.
    pub gpu: GpuSlots,
}

impl NodeWork {
    pub fn new(key: NodeKey) -> Self {
        Self {
            key,
            bounds: None,
            tiles: Vec::new(),
            payloads: Vec::new(),
            uploaded_bytes: 0,
            gpu_estimate_s: 0.0,
            gpu_phases_s: 0.0,
            gpu: GpuSlots::default(),
        }
    }

    /// Stores a payload (replacing one of the same type).
    pub fn put<T: Payload>(&mut self, payload: T) {
        let id = TypeId::of::<T>();
        self.payloads.retain(|(t, _)| *t != id);
        self.payloads.push((id, Box::new(payload)));
    }

    /// The payload of type `T`, if a phase stored one.
    pub fn get<T: Payload>(&self) -> Option<&T> {
        let id = TypeId::of::<T>();
        let (_, p) = self.payloads.iter().find(|(t, _)| *t == id)?;
        (p.as_ref() as &dyn Any).downcast_ref::<T>()
    }

    /// Bytes this node keeps resident (all payloads).
    pub fn bytes(&self) -> usize {
        self.payloads.iter().map(|(_, p)| p.bytes()).sum()
    }
}

/// GPU objects of one node, one per renderer, of types only the renderers know (the streaming
/// system stays free of wgpu).
/// Each object is kept with its type's id, as the payloads are.
#[derive(Default)]
pub struct GpuSlots(Vec<(TypeId, Box<dyn Any + Send + Sync>)>);

impl std::fmt::Debug for GpuSlots {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "GpuSlots({} set)", self.0.len())
    }
}

impl GpuSlots {
    /// Stores a renderer's object for the node (replacing one of the same type).
    pub fn put<T: Any + Send + Sync>(&mut self, object: T) {
        let id = TypeId::of::<T>();
        self.0.retain(|(t, _)| *t != id);
        self.0.push((id, Box::new(object)));
    }

    /// The stored object of type `T`.
    pub fn get<T: Any>(&self) -> Option<&T> {
        let id = TypeId::of::<T>();
        let (_, o) = self.0.iter().find(|(t, _)| *t == id)?;
        o.downcast_ref::<T>()
    }
}
