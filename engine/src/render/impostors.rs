//! Group-billboard impostor textures, suballocated: each node's impostor image (8 x 8 cluster
//! tiles) is one layer of a texture array page, so the cluster quads of every node in a page
//! are drawn by one multi-draw with one bind group (`vegetation.wgsl`, `fs_impostor`). A page
//! is two arrays: albedo and coverage, and the normals the quads are lit with when drawn (so a
//! sun change needs no new bake).

use super::frame::{sampler_entry, texture_entry};
use super::suballoc::{Lease, Suballocator};

/// Layers in one page (256 x 256 RGBA8 albedo and as much normal each: 128 MiB a page).
pub const LAYERS_PER_PAGE: u32 = 256;
/// Pages at most (created when needed; the cache budget, which counts every layer, is what
/// bounds them in practice: 256 pages would be 32 GiB).
const MAX_PAGES: usize = 256;

struct Page {
    /// Albedo and coverage, then normals.
    textures: [wgpu::Texture; 2],
    group: wgpu::BindGroup,
    /// Each layer's two views (bake targets), made at its first lease and kept for the next.
    layer_views: Vec<Option<[wgpu::TextureView; 2]>>,
}

/// The pages, their layer allocator and the bind-group layout (albedo array at binding 3,
/// normal array at binding 4, sampler at binding 1) that the impostor pipeline uses as group 2.
pub struct ImpostorPages {
    pool: Suballocator,
    pages: Vec<Page>,
    pub layout: wgpu::BindGroupLayout,
    /// The bakes' depth buffer (one layer's size, reused by every bake).
    pub bake_depth: wgpu::TextureView,
    side_px: u32,
    format: wgpu::TextureFormat,
}

impl std::fmt::Debug for ImpostorPages {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "ImpostorPages({} pages, {} layers used)",
            self.pages.len(),
            self.pool.used(0)
        )
    }
}

impl ImpostorPages {
    /// Layers of `side_px` x `side_px` texels in `format` (albedo and normals alike).
    pub fn new(device: &wgpu::Device, side_px: u32, format: wgpu::TextureFormat) -> Self {
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("impostor pages layout"),
            entries: &[
                texture_entry(3, wgpu::TextureViewDimension::D2Array),
                texture_entry(4, wgpu::TextureViewDimension::D2Array),
                sampler_entry(1),
            ],
        });
        Self {
            pool: Suballocator::new(&[LAYERS_PER_PAGE], MAX_PAGES),
            pages: Vec::new(),
            layout,
            bake_depth: super::depth_view(device, [side_px; 2], "impostor bake depth"),
            side_px,
            format,
        }
    }

    /// A layer for a node's impostors and views of it to bake into, albedo and normals (None
    /// when all pages are full). The lease gives the layer back when dropped.
    pub fn lease(
        &mut self,
        device: &wgpu::Device,
        sampler: &wgpu::Sampler,
    ) -> Option<(Lease, [wgpu::TextureView; 2])> {
        let lease = self.pool.lease(&[1])?;
        while self.pages.len() < self.pool.pages() {
            let label = format!("impostor page {}", self.pages.len());
            let textures = ["albedo", "normals"].map(|what| {
                device.create_texture(&wgpu::TextureDescriptor {
                    label: Some(&format!("{label} {what}")),
                    size: wgpu::Extent3d {
                        width: self.side_px,
                        height: self.side_px,
                        depth_or_array_layers: LAYERS_PER_PAGE,
                    },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: self.format,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                        | wgpu::TextureUsages::TEXTURE_BINDING,
                    view_formats: &[],
                })
            });
            let views = textures.each_ref().map(|t| {
                t.create_view(&wgpu::TextureViewDescriptor {
                    dimension: Some(wgpu::TextureViewDimension::D2Array),
                    ..Default::default()
                })
            });
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(&label),
                layout: &self.layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 3,
                        resource: wgpu::BindingResource::TextureView(&views[0]),
                    },
                    wgpu::BindGroupEntry {
                        binding: 4,
                        resource: wgpu::BindingResource::TextureView(&views[1]),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: wgpu::BindingResource::Sampler(sampler),
                    },
                ],
            });
            self.pages.push(Page {
                textures,
                group,
                layer_views: vec![None; LAYERS_PER_PAGE as usize],
            });
        }
        let page = &mut self.pages[lease.page as usize];
        let layer = lease.start[0];
        let layer_views = page.layer_views[layer as usize].get_or_insert_with(|| {
            page.textures.each_ref().map(|t| {
                t.create_view(&wgpu::TextureViewDescriptor {
                    label: Some("impostor layer"),
                    dimension: Some(wgpu::TextureViewDimension::D2),
                    base_array_layer: layer,
                    array_layer_count: Some(1),
                    ..Default::default()
                })
            })
        });
        let layer_views = layer_views.clone();
        Some((lease, layer_views))
    }

    /// The bind group of page `page`.
    pub fn group(&self, page: u32) -> &wgpu::BindGroup {
        &self.pages[page as usize].group
    }

    /// Bytes of one layer (albedo and normals).
    pub fn layer_bytes(&self) -> usize {
        (self.side_px * self.side_px * 4 * 2) as usize
    }
}
