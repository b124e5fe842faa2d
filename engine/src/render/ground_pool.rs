//! The pool node ground textures live in (owned by the terrain renderer): layers
//! of a few `SIDE x SIDE` texture arrays (pages of at most [`LAYERS_PER_PAGE`], or
//! [`MAX_LAYERS_PER_PAGE`] where the device allows ([`layers_per_page`]), created as needed, as
//! many layers as the byte budget holds), one layer leased per node and given back when the
//! lease drops (with the node's GPU objects, on eviction). A layer's view and the bind group
//! of its mip levels are made once, the first time the layer is leased, and kept with the
//! page (a node texture then creates no GPU object).
//!
//! The first page holds [`FIRST_PAGE_LAYERS`], the later ones the largest number ([`page_layers`]):
//! a view's first textures do not wait for memory for thousands (an adapter clears a texture
//! array whole before it is first sampled: on a CPU adapter, seconds for the largest page), and a
//! view that needs more has them in one more page (each page a drawn node's texture is in is one
//! more terrain multi-draw).

use super::ground::{GROUND_PAGE_FORMAT, GROUND_TEXTURE_FORMAT};
use super::suballoc::{Lease, Suballocator};
use crate::ground::layout::{MIP_LEVELS, SIDE};

/// Layers per texture array by default (wgpu's default limit on array layers).
pub const LAYERS_PER_PAGE: u32 = 256;
/// Layers per texture array at most: the limit of most desktop adapters (lavapipe's and
/// NVIDIA's among them). Fewer, larger pages mean fewer terrain batches: the drawn nodes'
/// textures are spread over fewer pages, and each page a node's texture is in is one more
/// multi-draw.
pub const MAX_LAYERS_PER_PAGE: u32 = 2048;

/// Layers of the first page (the later ones hold the largest number).
pub const FIRST_PAGE_LAYERS: u32 = 128;

/// Bytes of one layer (RGBA8 with its mip levels).
pub const LAYER_BYTES: usize = crate::ground::content::TEXTURE_BYTES;

/// Layers per page for a pool of `budget_bytes` on `device`: as many as its array-layer limit
/// allows, up to [`MAX_LAYERS_PER_PAGE`] and not more than the budget holds (at least one).
pub fn layers_per_page(device: &wgpu::Device, budget_bytes: usize) -> u32 {
    let by_budget = u32::try_from(budget_bytes / LAYER_BYTES).unwrap_or(u32::MAX);
    device
        .limits()
        .max_texture_array_layers
        .min(MAX_LAYERS_PER_PAGE)
        .min(by_budget)
        .max(1)
}

/// A node's layer: the lease (given back on drop), the view of its level 0 to render into and
/// the bindings of its mip levels (`GroundTexturer::record_mips`).
pub struct GroundSlot {
    lease: Lease,
    pub view: wgpu::TextureView,
    pub mips: LayerMips,
}

/// A layer's bindings for the mip pass: its level 0 through the sRGB view (read) and levels
/// 1 - 3 through [`GROUND_PAGE_FORMAT`] views (written).
#[derive(Clone, Debug)]
pub struct LayerMips(pub(super) wgpu::BindGroup);

/// What a layer's slots share: made once per layer.
#[derive(Clone)]
struct LayerViews {
    view: wgpu::TextureView,
    mips: LayerMips,
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
    /// Per page, per layer: its view and mip bindings, once leased.
    layers: Vec<Vec<Option<LayerViews>>>,
    /// The layout of the mip pass's bindings (`GroundTexturer::mip_layout`).
    mip_layout: wgpu::BindGroupLayout,
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
    /// A pool of at most `budget_bytes` of texture pages of [`LAYERS_PER_PAGE`] (at least one
    /// page), whose layers' mip levels are bound through `mip_layout`.
    pub fn new(budget_bytes: usize, mip_layout: &wgpu::BindGroupLayout) -> Self {
        Self::with_pages_of(budget_bytes, LAYERS_PER_PAGE, mip_layout)
    }

    /// A pool of at most `budget_bytes` of pages of up to `layers_per_page` layers (at least
    /// one page; see [`layers_per_page`] for what a device allows), [`page_layers`] each.
    pub fn with_pages_of(
        budget_bytes: usize,
        layers_per_page: u32,
        mip_layout: &wgpu::BindGroupLayout,
    ) -> Self {
        let pages = page_layers(budget_bytes, layers_per_page)
            .into_iter()
            .map(|layers| vec![layers])
            .collect();
        Self {
            alloc: Suballocator::with_pages(pages),
            pages: Vec::new(),
            layers: Vec::new(),
            mip_layout: mip_layout.clone(),
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
                        depth_or_array_layers: self.alloc.capacity(self.pages.len(), 0),
                    },
                    mip_level_count: MIP_LEVELS,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: GROUND_PAGE_FORMAT,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                        | wgpu::TextureUsages::TEXTURE_BINDING
                        | wgpu::TextureUsages::STORAGE_BINDING
                        | wgpu::TextureUsages::COPY_SRC,
                    view_formats: &[GROUND_TEXTURE_FORMAT],
                }));
        }
        while self.layers.len() < self.pages.len() {
            let layers = self.alloc.capacity(self.layers.len(), 0);
            self.layers.push(vec![None; layers as usize]);
        }
        let (page, layer) = (lease.page as usize, lease.start[0]);
        let views = self.layers[page][layer as usize]
            .get_or_insert_with(|| layer_views(device, &self.pages[page], layer, &self.mip_layout))
            .clone();
        Some(GroundSlot {
            lease,
            view: views.view,
            mips: views.mips,
        })
    }

    /// Pages made so far.
    pub fn pages(&self) -> usize {
        self.pages.len()
    }

    /// The texture of page `page` (for readback; sample it through a view of
    /// [`GROUND_TEXTURE_FORMAT`]).
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
        (0..self.pages.len())
            .map(|p| self.alloc.capacity(p, 0) as usize * LAYER_BYTES)
            .sum()
    }
}

/// The layers of each page a pool of `budget_bytes` may open, pages of at most `largest`:
/// [`FIRST_PAGE_LAYERS`] (or `largest`, if fewer), then `largest`, the last page what is left
/// of the budget: as many layers as the budget holds (and one page at least).
pub fn page_layers(budget_bytes: usize, largest: u32) -> Vec<u32> {
    let budget_layers = budget_bytes / LAYER_BYTES;
    let largest = largest.max(1);
    let mut pages = vec![FIRST_PAGE_LAYERS.min(largest)];
    let mut total = pages[0] as usize;
    while total < budget_layers {
        let next = (budget_layers - total).min(largest as usize) as u32;
        pages.push(next);
        total += next as usize;
    }
    pages
}

/// Layer `layer` of `page`: the sRGB view of its level 0 and the bind group of its mip pass.
fn layer_views(
    device: &wgpu::Device,
    page: &wgpu::Texture,
    layer: u32,
    mip_layout: &wgpu::BindGroupLayout,
) -> LayerViews {
    // Each view allows what its format supports: the sRGB one is rendered into and read, the
    // linear ones are written by the mip pass.
    let level = |mip: u32, format: wgpu::TextureFormat, usage: wgpu::TextureUsages| {
        page.create_view(&wgpu::TextureViewDescriptor {
            label: Some("ground texture layer"),
            format: Some(format),
            usage: Some(usage),
            dimension: Some(wgpu::TextureViewDimension::D2),
            base_array_layer: layer,
            array_layer_count: Some(1),
            base_mip_level: mip,
            mip_level_count: Some(1),
            ..Default::default()
        })
    };
    let view = level(
        0,
        GROUND_TEXTURE_FORMAT,
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
    );
    let written: Vec<wgpu::TextureView> = (1..MIP_LEVELS)
        .map(|mip| {
            level(
                mip,
                GROUND_PAGE_FORMAT,
                wgpu::TextureUsages::STORAGE_BINDING,
            )
        })
        .collect();
    let entries: Vec<wgpu::BindGroupEntry> = std::iter::once(&view)
        .chain(&written)
        .zip(0..)
        .map(|(v, binding)| wgpu::BindGroupEntry {
            binding,
            resource: wgpu::BindingResource::TextureView(v),
        })
        .collect();
    let mips = LayerMips(device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("ground texture mips"),
        layout: mip_layout,
        entries: &entries,
    }));
    LayerViews { view, mips }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_small_first_page_then_the_largest_within_the_budget() {
        let layers = |n: usize| n * LAYER_BYTES;
        assert_eq!(
            page_layers(layers(4096), 1024),
            vec![128, 1024, 1024, 1024, 896]
        );
        // The budget's layers, no more: the last page holds what is left.
        assert_eq!(page_layers(layers(2000), 2000), vec![128, 1872]);
        assert_eq!(page_layers(layers(2176), 2048), vec![128, 2048]);
        assert_eq!(page_layers(layers(384), 256), vec![128, 256]);
        assert_eq!(
            page_layers(layers(100), 2048),
            vec![128],
            "one page at least"
        );
        assert_eq!(
            page_layers(layers(1000), 64),
            [vec![64; 15], vec![40]].concat()
        );
    }
}
