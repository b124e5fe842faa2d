//! The objects kind: each node's payload lists the instances standing inside its rectangle (any
//! level: the drawn node that covers an instance draws it, and both nodes of a cross-fade draw
//! it with their dither), and on wide nodes their merged far mesh ([`super::hlod`]).

use super::hlod::{self, NodeHlod};
use super::set::ObjectSet;
use super::texturing;
use crate::stream::{ContentKind, NodeWork, Payload, Phase, Shared};
use std::sync::Arc;

/// Content kind `objects`.
#[derive(Debug)]
pub struct ObjectsContent {
    pub set: Arc<ObjectSet>,
}

/// A node's instances (indices into [`ObjectSet::instances`]) and, on nodes of at least
/// [`HLOD_MIN_SIDE_M`] with two or more, their merged far mesh.
#[derive(Debug)]
pub struct NodeObjects {
    pub set: Arc<ObjectSet>,
    pub instances: Vec<u32>,
    pub hlod: Option<NodeHlod>,
}

/// Nodes at least this wide (m) merge their houses into a far mesh (their error budget is then
/// at least 4 m, drawn beyond about a kilometre at tau 2 and 720p).
pub const HLOD_MIN_SIDE_M: f64 = 128.0;

impl Payload for NodeObjects {
    fn bytes(&self) -> usize {
        self.instances.len() * 4
            + self
                .hlod
                .as_ref()
                .map_or(0, |h| std::mem::size_of_val(h.vertices.as_slice()))
    }
}

impl ObjectsContent {
    pub const NAME: &'static str = "objects";
}

impl ContentKind for ObjectsContent {
    fn name(&self) -> &'static str {
        Self::NAME
    }

    fn phases(self: Arc<Self>) -> Vec<Phase> {
        vec![Phase::cpu(
            "objects",
            move |shared: &Shared, work: &mut NodeWork| {
                let rect = shared.tree.rect(work.key);
                let instances: Vec<u32> = self
                    .set
                    .instances
                    .iter()
                    .enumerate()
                    .filter(|(_, i)| rect.contains(i.position_m.x, i.position_m.y))
                    .map(|(k, _)| k as u32)
                    .collect();
                if !instances.is_empty() {
                    let side_m = rect.max[0] - rect.min[0];
                    let hlod = (side_m >= HLOD_MIN_SIDE_M)
                        .then(|| {
                            let means = texturing::mean_colors(&self.set);
                            hlod::build(
                                &self.set,
                                &instances,
                                rect.min,
                                hlod::error_budget_m(side_m),
                                &means,
                            )
                        })
                        .flatten();
                    work.put(NodeObjects {
                        set: Arc::clone(&self.set),
                        instances,
                        hlod,
                    });
                }
            },
        )]
    }
}
