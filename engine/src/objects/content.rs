//! The objects kind: each node's payload lists the instances standing inside its rectangle (any
//! level: the drawn node that covers an instance draws it, and both nodes of a cross-fade draw
//! it with their dither).

use super::set::ObjectSet;
use crate::stream::{ContentKind, NodeWork, Payload, Phase, Shared};
use std::sync::Arc;

/// Content kind `objects`.
#[derive(Debug)]
pub struct ObjectsContent {
    pub set: Arc<ObjectSet>,
}

/// A node's instances (indices into [`ObjectSet::instances`]).
#[derive(Debug)]
pub struct NodeObjects {
    pub set: Arc<ObjectSet>,
    pub instances: Vec<u32>,
}

impl Payload for NodeObjects {
    fn bytes(&self) -> usize {
        self.instances.len() * 4
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
                    work.put(NodeObjects {
                        set: Arc::clone(&self.set),
                        instances,
                    });
                }
            },
        )]
    }
}
