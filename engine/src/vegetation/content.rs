//! Vegetation as a node-content kind: the node's instance groups, and the canopy's line-of-sight
//! visibility for splitting less behind dense vegetation.

use super::{Canopy, NodeVegetation, Placer, node_vegetation};
use crate::stream::{ContentKind, NodeWork, Payload, Phase, Shared};
use crate::surface::{Rect, World};
use glam::DVec3;
use std::sync::Arc;

/// The vegetation kind (phase `vegetation`; payload [`NodeVegetation`]). Holds the placement
/// tables and the canopy model, built once from the map.
#[derive(Debug)]
pub struct VegetationContent {
    pub placer: Placer,
    /// Shared with the light-grid kind.
    pub canopy: Arc<Canopy>,
}

impl VegetationContent {
    pub fn new(world: &World) -> Self {
        let placer = Placer::new(world);
        let canopy = Arc::new(Canopy::new(world, &placer));
        Self { placer, canopy }
    }
}

impl Payload for NodeVegetation {
    fn bytes(&self) -> usize {
        self.gpu_bytes()
    }
}

impl ContentKind for VegetationContent {
    fn name(&self) -> &'static str {
        "vegetation"
    }

    fn phases(self: Arc<Self>) -> Vec<Phase> {
        vec![Phase::cpu(
            "vegetation",
            move |s: &Shared, w: &mut NodeWork| {
                w.put(node_vegetation(&s.world, &self.placer, &s.tree, w.key));
            },
        )]
    }

    fn visibility(
        &self,
        s: &Shared,
        camera_m: DVec3,
        rect: Rect,
        z_max_m: f64,
        dist_m: f64,
    ) -> f64 {
        self.canopy
            .error_factor(&s.world, camera_m, rect, z_max_m, dist_m)
    }
}
