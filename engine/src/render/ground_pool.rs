//! The pool node ground textures live in (owned by the terrain renderer): layers
//! of a few `SIDE x SIDE` texture arrays (pages of [`LAYERS_PER_PAGE`], created as needed, at
//! most as many as the byte budget allows), one layer leased per node and given back when the
//! lease drops (with the node's GPU objects, on eviction).

use super::ground::GROUND_TEXTURE_FORMAT;
use super::suballoc::{Lease, Suballocator};
use crate::ground::layout::{MIP_LEVELS, SIDE};

/// Layers per texture array (wgpu's default limit on array layers).
pub const LAYERS_PER_PAGE: u32 = 256;
/// Bytes of one layer (RGBA8 with its mip levels).
pub const LAYER_BYTES: usize = crate::ground::content::TEXTURE_BYTES;

/// A node's layer: the lease (given back on drop), the view of its level 0 to render into and
/// the views of its smaller mip levels (1, 2, ...).
pub struct GroundSlot {
    lease: Lease,
    pub view: wgpu::TextureView,
    pub mips: Vec<wgpu::TextureView>,
}

impl std::fmt::Debug for GroundSlot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "GroundSlot(page {}, layer {})",
            self.page(),
            self.layer()
        )
    }
}

impl GroundSlot {
    pub fn page(&self) -> u32 {
        self.lease.page
    }

    pub fn layer(&self) -> u32 {
        self.lease.start[0]
    }
}

/// Texture-array pages and their layer allocator.
pub struct GroundPool {
    alloc: Suballocator,
    pages: Vec<wgpu::Texture>,
}

impl std::fmt::Debug for GroundPool {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "GroundPool({} pages, {} layers in use)",
            self.pages.len(),
            self.layers_in_use()
        )
    }
}

impl GroundPool {
    /// A pool of at most `budget_bytes` of texture pages (at least one page).
    pub fn new(budget_bytes: usize) -> Self {
        let page_bytes = LAYER_BYTES * LAYERS_PER_PAGE as usize;
        Self {
            alloc: Suballocator::new(&[LAYERS_PER_PAGE], (budget_bytes / page_bytes).max(1)),
            pages: Vec::new(),
        }
    }

    /// A free layer (a new page is made when all are taken and the budget allows), or None when
    /// the pool is full.
    pub fn lease(&mut self, device: &wgpu::Device) -> Option<GroundSlot> {
        let lease = self.alloc.lease(&[1])?;
        while self.pages.len() < self.alloc.pages() {
            self.pages
                .push(device.create_texture(&wgpu::TextureDescriptor {
                    label: Some(&format!("ground texture page {}", self.pages.len())),
                    size: wgpu::Extent3d {
                        width: SIDE,
                        height: SIDE,
                        depth_or_array_layers: LAYERS_PER_PAGE,
                    },
                    mip_level_count: MIP_LEVELS,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: GROUND_TEXTURE_FORMAT,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                        | wgpu::TextureUsages::TEXTURE_BINDING
                        | wgpu::TextureUsages::COPY_SRC,
                    view_formats: &[],
                }));
        }
        let page = &self.pages[lease.page as usize];
        let level = |mip: u32| {
            page.create_view(&wgpu::TextureViewDescriptor {
                label: Some("ground texture layer"),
                dimension: Some(wgpu::TextureViewDimension::D2),
                base_array_layer: lease.start[0],
                array_layer_count: Some(1),
                base_mip_level: mip,
                mip_level_count: Some(1),
                ..Default::default()
            })
        };
        let view = level(0);
        let mips = (1..MIP_LEVELS).map(level).collect();
        Some(GroundSlot { lease, view, mips })
    }

    /// Pages made so far.
    pub fn pages(&self) -> usize {
        self.pages.len()
    }

    /// The texture of page `page` (for sampling and readback).
    pub fn page(&self, page: u32) -> Option<&wgpu::Texture> {
        self.pages.get(page as usize)
    }

    /// Layers leased now.
    pub fn layers_in_use(&self) -> usize {
        self.alloc.used(0) as usize
    }

    /// Bytes of the pages made so far (never above the budget, rounded down to whole pages,
    /// and at least one page).
    pub fn bytes(&self) -> usize {
        self.pages.len() * LAYERS_PER_PAGE as usize * LAYER_BYTES
    }
}
