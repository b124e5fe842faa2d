//! The registry of node-content kinds: the one place where a kind is added. Each entry pairs
//! the CPU side (a [`ContentKind`] in the kind's own folder) with its renderer's constructor (a
//! [`NodeRenderer`] in `render/`). The streamer runs the kinds' phases in this order and the
//! viewer draws their renderers in this order (after the sky, before debug lines).
//!
//! Adding a kind (say `ground/`): write `ground/` with its `ContentKind` and payload, write
//! `render/ground.rs` with its `NodeRenderer`, and add one line below. The scheduler, the
//! viewer and the other renderers stay as they are.

use crate::ground::content::GroundContent;
use crate::lighting::content::LightingContent;
use crate::lighting::grid::Sun;
use crate::objects::content::ObjectsContent;
use crate::objects::set::ObjectSet;
use crate::render::Gpu;
use crate::render::frame::FrameResources;
use crate::render::scene::NodeRenderer;
use crate::stream::{ContentKind, Shared};
use crate::surface::World;
use crate::terrain::content::TerrainContent;
use crate::vegetation::content::VegetationContent;
use std::sync::Arc;

/// Makes a kind's renderer (at viewer start-up, from the streamer's shared state).
pub type RendererFactory = fn(&Gpu, &FrameResources, &Shared) -> Box<dyn NodeRenderer>;

/// One registered kind.
pub struct Registration {
    pub kind: Arc<dyn ContentKind>,
    /// None for a kind another renderer draws with (ground textures: the terrain renderer).
    pub renderer: Option<RendererFactory>,
}

impl std::fmt::Debug for Registration {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Registration({})", self.kind.name())
    }
}

fn entry(kind: impl ContentKind, renderer: Option<RendererFactory>) -> Registration {
    Registration {
        kind: Arc::new(kind),
        renderer,
    }
}

/// Every node-content kind, in phase and drawing order.
pub fn registered(world: &World) -> Vec<Registration> {
    let vegetation = VegetationContent::new(world);
    let canopy = Arc::clone(&vegetation.canopy);
    let mut kinds = vec![
        // First, so the other renderers' upload hooks find the node's grid lease (their
        // `prepare` reads it); it draws nothing.
        entry(
            LightingContent::new(world, canopy, Sun::default()),
            Some(crate::render::lighting::LightingRenderer::create),
        ),
        entry(
            TerrainContent,
            Some(crate::render::terrain::TerrainRenderer::create),
        ),
        // Drawn by the terrain renderer: its upload hook renders the texture, its shading
        // samples it.
        entry(GroundContent::new(world), None),
        entry(
            vegetation,
            Some(crate::render::vegetation::VegetationRenderer::create),
        ),
    ];
    // The map's houses, when it has any.
    if !world.map.buildings.is_empty() {
        kinds.push(entry(
            ObjectsContent {
                set: Arc::new(ObjectSet::from_buildings(
                    &world.map.buildings,
                    &world.map.building_models,
                    &world.map.building_textures,
                )),
            },
            Some(crate::render::objects::ObjectsRenderer::create),
        ));
    }
    kinds
}

/// The CPU side of every registered kind (for a streamer without a renderer).
pub fn content_kinds(world: &World) -> Vec<Arc<dyn ContentKind>> {
    registered(world).into_iter().map(|r| r.kind).collect()
}
