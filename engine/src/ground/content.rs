//! Ground textures as a node-content kind: the CPU phase `ground pieces` finds the decal pieces
//! a node's texture draws (from the spatial index, [`super::pieces::node_decals`]) and stores
//! them as the node's [`NodeGround`]. The texture itself is rendered on the GPU by the terrain
//! renderer's upload hook (the terrain shading is its only reader, so the terrain renderer owns
//! the layer pool it lives in) and freed with the node's GPU objects.

use super::decal_index::DecalIndex;
use super::layout::{MIP_LEVELS, SIDE};
use super::pieces::{NodeDecals, node_decals};
use crate::stream::{ContentKind, NodeWork, Payload, Phase, Shared};
use crate::surface::World;
use std::sync::Arc;

/// Bytes of one node texture on the GPU (`SIDE x SIDE` RGBA8 and its [`MIP_LEVELS`] - 1
/// smaller levels), counted in the node-cache budget once the renderer has made it (the
/// viewer charges it to the node, [`crate::stream::Streamer::charge`]): a node the display
/// never needs (prefetched, then passed by) gets none.
pub const TEXTURE_BYTES: usize = {
    let mut bytes = 0;
    let mut level = 0;
    while level < MIP_LEVELS {
        bytes += ((SIDE >> level) * (SIDE >> level) * 4) as usize;
        level += 1;
    }
    bytes
};

/// The ground kind's payload of a node: what its texture draws.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct NodeGround {
    pub decals: NodeDecals,
}

impl Payload for NodeGround {
    /// The pieces' bytes; the texture's are counted when it is made ([`TEXTURE_BYTES`]).
    fn bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + std::mem::size_of_val(self.decals.segments.as_slice())
            + std::mem::size_of_val(self.decals.areas.as_slice())
    }
}

/// The ground-texture kind (phase `ground pieces`; payload [`NodeGround`]). Holds the decal
/// index, built once from the map.
#[derive(Debug)]
pub struct GroundContent {
    pub index: DecalIndex,
}

impl GroundContent {
    /// The kind's registered name.
    pub const NAME: &'static str = "ground";

    pub fn new(world: &World) -> Self {
        Self {
            index: DecalIndex::new(&world.map.decals, world.origin_m(), world.size_m()),
        }
    }
}

impl ContentKind for GroundContent {
    fn name(&self) -> &'static str {
        Self::NAME
    }

    fn phases(self: Arc<Self>) -> Vec<Phase> {
        vec![Phase::cpu(
            "ground pieces",
            move |s: &Shared, w: &mut NodeWork| {
                let decals = node_decals(&s.world.map.decals, &self.index, &s.tree, w.key);
                w.put(NodeGround { decals });
            },
        )]
    }
}
