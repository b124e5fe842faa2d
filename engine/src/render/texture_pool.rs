//! The GPU side of the texture cache ([`crate::texcache::pool`]): one 2D texture per slot (edge
//! `2^e`, every mip level down to 1 x 1, sRGB), made, filled and dropped as the cache's plans
//! say. An upload writes the texture's chain from the planned level down into the slot's levels.

use super::Gpu;
use crate::texcache::pool::{Op, Plan, SlotId};
use crate::texcache::upload_cost::UploadCost;
use std::collections::HashMap;
use worldgen::house_textures::MipChain;

/// Slot textures and a 1 x 1 white texture for draws whose texture is not resident.
pub struct GpuTexturePool {
    slots: HashMap<SlotId, (wgpu::Texture, wgpu::TextureView)>,
    pub fallback: wgpu::TextureView,
    pub sampler: wgpu::Sampler,
    /// Frame-thread cost of an uploaded byte (the texture writes of recent plans).
    pub upload_cost: UploadCost,
}

fn slot_texture(device: &wgpu::Device, edge: u32, levels: u32) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some("texture cache slot"),
        size: wgpu::Extent3d {
            width: edge,
            height: edge,
            depth_or_array_layers: 1,
        },
        mip_level_count: levels,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba8UnormSrgb,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    })
}

impl GpuTexturePool {
    pub fn new(gpu: &Gpu) -> Self {
        let white = slot_texture(&gpu.device, 1, 1);
        gpu.queue.write_texture(
            white.as_image_copy(),
            &[255; 4],
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(4),
                rows_per_image: Some(1),
            },
            wgpu::Extent3d {
                width: 1,
                height: 1,
                depth_or_array_layers: 1,
            },
        );
        let sampler = gpu.device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("texture cache sampler"),
            address_mode_u: wgpu::AddressMode::Repeat,
            address_mode_v: wgpu::AddressMode::Repeat,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            ..Default::default()
        });
        GpuTexturePool {
            slots: HashMap::new(),
            fallback: white.create_view(&wgpu::TextureViewDescriptor::default()),
            sampler,
            upload_cost: UploadCost::default(),
        }
    }

    /// The view of a slot alive.
    pub fn view(&self, slot: SlotId) -> Option<&wgpu::TextureView> {
        self.slots.get(&slot).map(|(_, v)| v)
    }

    /// Applies a plan in order; `chains[t]` is texture `t`'s mip chain. Returns whether a slot
    /// was destroyed or made (bind groups naming slots must then be made again).
    pub fn apply(&mut self, gpu: &Gpu, plan: &Plan, chains: &[MipChain]) -> bool {
        let mut changed = false;
        let (mut upload_s, mut upload_bytes) = (0.0f64, 0usize);
        for op in &plan.ops {
            match *op {
                Op::Destroy(slot) => {
                    self.slots.remove(&slot);
                    changed = true;
                }
                Op::Create(slot) => {
                    let texture =
                        slot_texture(&gpu.device, 1 << slot.edge_log2, slot.edge_log2 + 1);
                    let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
                    self.slots.insert(slot, (texture, view));
                    changed = true;
                }
                Op::Upload {
                    texture,
                    level,
                    slot,
                } => {
                    let Some((target, _)) = self.slots.get(&slot) else {
                        continue;
                    };
                    let chain = &chains[texture as usize];
                    let t0 = std::time::Instant::now();
                    for (mip, data) in chain.levels[level as usize..].iter().enumerate() {
                        let edge = chain.edge(level + mip as u32);
                        gpu.queue.write_texture(
                            wgpu::TexelCopyTextureInfo {
                                texture: target,
                                mip_level: mip as u32,
                                origin: wgpu::Origin3d::ZERO,
                                aspect: wgpu::TextureAspect::All,
                            },
                            data,
                            wgpu::TexelCopyBufferLayout {
                                offset: 0,
                                bytes_per_row: Some(edge * 4),
                                rows_per_image: Some(edge),
                            },
                            wgpu::Extent3d {
                                width: edge,
                                height: edge,
                                depth_or_array_layers: 1,
                            },
                        );
                        upload_bytes += data.len();
                    }
                    upload_s += t0.elapsed().as_secs_f64();
                }
            }
        }
        self.upload_cost.record(upload_bytes, upload_s);
        changed
    }
}
