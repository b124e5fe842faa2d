//! What the terrain shader needs to show the ground below the finest ground texel: the
//! materials' own texels (3.1 cm) instead of the magnified node texture alone. Near the camera
//! the shader multiplies the node texture by the material's detail: its luminance at the
//! pixel's own scale over its luminance at the finest node texel's scale, so only what the node
//! texture cannot hold is added, it is 1 where a pixel is a texel or larger, and it fades in by
//! metres per pixel only (no node or level border can show). The material is the ground type's
//! at the pixel (the map's ground layer, with the node texture's noise-perturbed borders).
//! Nearer still (pixels under [`BUMP_PX_M`]) the material's detail height, stored in the
//! materials' alpha, bends the shading normal: the gradient of the height mip at the pixel's
//! scale, so the bumps smooth out with distance before they fade by pixel size.
//!
//! Bindings 3 to 6 of the terrain's group 2: the materials array, the ground layer, a
//! repeating sampler and a small uniform (`DetailUniform`), rewritten each frame from the camera.

use super::Gpu;
use crate::camera::Camera;
use crate::ground::materials::{MATERIAL_TEXELS, MATERIAL_TILE_M, MAX_RELIEF_M};

/// Per-frame uniforms (mirrors `GroundDetail` in `terrain.wgsl`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct DetailUniform {
    /// Camera position minus the map origin in ground-layer cells, and modulo the material
    /// tile in tiles (the f64 subtraction done here keeps f32 exact enough near the camera).
    camera_cells: [f32; 2],
    camera_tiles: [f32; 2],
    ground_spacing_m: f32,
    ground_types: u32,
    material_tile_m: f32,
    /// Material mip level whose texel is the finest node texel (the detail's reference).
    finest_lod: f32,
    /// The finest node texel (m); 0 turns the detail off (no ground textures).
    finest_texel_m: f32,
    /// Metres of a material height of 1 (alpha 255): [`MAX_RELIEF_M`].
    max_relief_m: f32,
    /// Pixels up to this size (m) see the materials' relief ([`BUMP_PX_M`]).
    bump_px_m: f32,
    pad: f32,
}

/// Pixels up to this size see the ground materials' detail height as bumps of the ground's
/// normal, in full up to a quarter of it (m). At 720p and a 60-degree view that is out to about
/// 60 m, in full to 15 m; farther, centimetre relief is below a pixel.
pub const BUMP_PX_M: f64 = 0.1;

/// The detail bindings and the map numbers the uniform is made of.
pub struct GroundDetail {
    pub materials: wgpu::TextureView,
    pub ground_types: wgpu::TextureView,
    pub sampler: wgpu::Sampler,
    pub buffer: wgpu::Buffer,
    map_origin_m: [f64; 2],
    ground_spacing_m: f64,
    types: u32,
    finest_texel_m: f64,
}

impl std::fmt::Debug for GroundDetail {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "GroundDetail(finest texel {} m)", self.finest_texel_m)
    }
}

impl GroundDetail {
    /// Detail from `materials` (a 2D array, one layer per ground type, `MATERIAL_TEXELS`
    /// texels over `MATERIAL_TILE_M`, full mip chain) for the map's ground layer `ground_types`
    /// (R8Uint, row 0 south), whose cells are `ground_spacing_m` from `map_origin_m`; the finest
    /// node texel is `finest_texel_m`.
    pub fn new(
        gpu: &Gpu,
        materials: wgpu::TextureView,
        ground_types: wgpu::TextureView,
        (map_origin_m, ground_spacing_m, types): ([f64; 2], f64, u32),
        finest_texel_m: f64,
    ) -> Self {
        let sampler = gpu.device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("ground detail sampler"),
            address_mode_u: wgpu::AddressMode::Repeat,
            address_mode_v: wgpu::AddressMode::Repeat,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            ..Default::default()
        });
        let buffer = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("ground detail"),
            size: std::mem::size_of::<DetailUniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Self {
            materials,
            ground_types,
            sampler,
            buffer,
            map_origin_m,
            ground_spacing_m,
            types,
            finest_texel_m,
        }
    }

    /// No detail (terrain without ground textures): 1 x 1 stand-ins, the uniform's texel 0.
    pub fn none(gpu: &Gpu) -> Self {
        let texture = |label: &str, format: wgpu::TextureFormat, array: bool| {
            gpu.device
                .create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size: wgpu::Extent3d {
                        width: 1,
                        height: 1,
                        depth_or_array_layers: 1,
                    },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage: wgpu::TextureUsages::TEXTURE_BINDING,
                    view_formats: &[],
                })
                .create_view(&wgpu::TextureViewDescriptor {
                    dimension: Some(if array {
                        wgpu::TextureViewDimension::D2Array
                    } else {
                        wgpu::TextureViewDimension::D2
                    }),
                    ..Default::default()
                })
        };
        Self::new(
            gpu,
            texture(
                "no ground materials",
                wgpu::TextureFormat::Rgba8UnormSrgb,
                true,
            ),
            texture("no ground types", wgpu::TextureFormat::R8Uint, false),
            ([0.0; 2], 1.0, 1),
            0.0,
        )
    }

    /// Writes this frame's uniform for `camera`.
    pub fn write(&self, queue: &wgpu::Queue, camera: &Camera) {
        let p = camera.position_m;
        let (dx, dy) = (p.x - self.map_origin_m[0], p.y - self.map_origin_m[1]);
        let material_texel_m = MATERIAL_TILE_M / f64::from(MATERIAL_TEXELS);
        let u = DetailUniform {
            camera_cells: [
                (dx / self.ground_spacing_m) as f32,
                (dy / self.ground_spacing_m) as f32,
            ],
            camera_tiles: [
                (dx / MATERIAL_TILE_M).rem_euclid(1.0) as f32,
                (dy / MATERIAL_TILE_M).rem_euclid(1.0) as f32,
            ],
            ground_spacing_m: self.ground_spacing_m as f32,
            ground_types: self.types,
            material_tile_m: MATERIAL_TILE_M as f32,
            finest_lod: (self.finest_texel_m / material_texel_m).log2().max(0.0) as f32,
            finest_texel_m: self.finest_texel_m as f32,
            max_relief_m: MAX_RELIEF_M as f32,
            bump_px_m: BUMP_PX_M as f32,
            pad: 0.0,
        };
        queue.write_buffer(&self.buffer, 0, bytemuck::bytes_of(&u));
    }

    /// Bind-group entries 3 to 6.
    pub fn entries(&self) -> [wgpu::BindGroupEntry<'_>; 4] {
        [
            wgpu::BindGroupEntry {
                binding: 3,
                resource: wgpu::BindingResource::TextureView(&self.materials),
            },
            wgpu::BindGroupEntry {
                binding: 4,
                resource: wgpu::BindingResource::TextureView(&self.ground_types),
            },
            wgpu::BindGroupEntry {
                binding: 5,
                resource: wgpu::BindingResource::Sampler(&self.sampler),
            },
            wgpu::BindGroupEntry {
                binding: 6,
                resource: self.buffer.as_entire_binding(),
            },
        ]
    }
}
