//! Ground textures as a node-content kind: the CPU phase `ground pieces` finds the decal pieces
//! a node's texture draws (from the spatial index, [`super::pieces::node_decals`]) and the ground
//! type of each of its texels ([`super::types`]), and stores them as the node's [`NodeGround`]. The texture itself is rendered on the GPU by the terrain
//! renderer's upload hook (the terrain shading is its only reader, so the terrain renderer owns
//! the layer pool it lives in) and freed with the node's GPU objects.

use super::decal_index::DecalIndex;
use super::layout::{MIP_LEVELS, SIDE};
use super::pieces::{NodeDecals, node_decals};
use super::types::{NodeTypes, TexelCells};
use crate::stream::{ContentKind, NodeWork, Payload, Phase, Shared};
use crate::surface::World;
use crate::terrain::quadtree::{NodeKey, QuadTree};
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
    /// The ground type of each texel.
    pub types: NodeTypes,
}

impl NodeGround {
    /// What node `key`'s texture draws of `world`, its decals found through `index`.
    pub fn new(world: &World, index: &DecalIndex, tree: &QuadTree, key: NodeKey) -> Self {
        let ground = &world.map.manifest.ground;
        let cells = TexelCells::new(tree, key, world.map.manifest.origin_m, ground.spacing_m);
        let last_type = (ground.legend.len().clamp(1, 256) - 1) as u8;
        Self {
            decals: node_decals(&world.map.decals, index, tree, key),
            types: NodeTypes::resolve(&world.map.ground, &world.ground_levels, &cells, last_type),
        }
    }
}

impl Payload for NodeGround {
    /// The pieces' and types' bytes; the texture's are counted when it is made
    /// ([`TEXTURE_BYTES`]).
    fn bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + std::mem::size_of_val(self.decals.segments.as_slice())
            + std::mem::size_of_val(self.decals.areas.as_slice())
            + self.types.bytes()
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
                w.put(NodeGround::new(&s.world, &self.index, &s.tree, w.key));
            },
        )]
    }
}
