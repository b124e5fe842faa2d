//! Terrain as a node-content kind: the node's 16 m source tile, then its skirted mesh.

use super::mesh::{self, NodeMesh};
use super::tiles::Tile;
use crate::stream::{ContentKind, NodeWork, Payload, Phase, Shared};
use std::sync::{Arc, PoisonError};

/// The terrain kind (phases `tiles`, `terrain mesh`; payload [`NodeMesh`]).
#[derive(Debug, Default)]
pub struct TerrainContent;

impl Payload for NodeMesh {
    fn bytes(&self) -> usize {
        self.gpu_bytes()
    }
}

impl ContentKind for TerrainContent {
    fn name(&self) -> &'static str {
        "terrain"
    }

    fn phases(self: Arc<Self>) -> Vec<Phase> {
        vec![
            Phase::cpu("tiles", acquire_tile),
            Phase::cpu("terrain mesh", build_mesh),
        ]
    }
}

/// Holds the node's source tile (made when no job holds it yet); released by the core
/// `release tiles` phase or on cancellation.
fn acquire_tile(s: &Shared, w: &mut NodeWork) {
    let Some(tk) = mesh::source_tile(&s.world, &s.tree, w.key) else {
        return;
    };
    let resident = s
        .tiles
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .try_acquire(tk);
    // Generate outside the lock; if another job made it meanwhile, theirs is kept.
    let tile = resident.unwrap_or_else(|| {
        let t = Arc::new(Tile::generate(&s.world, tk));
        s.tiles
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .insert_acquired(t)
    });
    w.tiles.push((tk, tile));
}

fn build_mesh(s: &Shared, w: &mut NodeWork) {
    let tile = w.tiles.first().map(|(_, t)| Arc::clone(t));
    // Skirt depths need the bounds of coarser neighbours: measured (and stored) on demand.
    let mesh = mesh::build(
        &s.world,
        &s.tree,
        &mut |k| s.bounds.get(&s.world, &s.tree, k),
        w.key,
        tile.as_deref(),
    );
    w.put(mesh);
}
