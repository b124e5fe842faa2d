//! What the terrain shader needs to show the ground below the finest ground texel: the
//! materials' own texels (3.1 cm) instead of the magnified node texture alone. Near the camera
//! the shader multiplies the node texture by the material's detail: its luminance at the
//! pixel's own scale over its luminance at the finest node texel's scale, so only what the node
//! texture cannot hold is added, it is 1 where a pixel is a texel or larger, and it fades in by
//! metres per pixel only (no node or level border can show). The material is the ground type's
//! at the pixel (the map's ground layer, with the node texture's noise-perturbed borders), read
//! from a window of the layer around the camera ([`crate::ground::type_window`]) that follows
//! it.
//! Nearer still (pixels under [`BUMP_PX_M`]) the material's detail height, stored in the
//! materials' alpha, bends the shading normal: the gradient of the height mip at the pixel's
//! scale, so the bumps smooth out with distance before they fade by pixel size.
//!
//! Bindings 3 to 6 of the terrain's group 2: the materials array, the ground layer's window, a
//! repeating sampler and a small uniform (`DetailUniform`), rewritten each frame from the camera.

use super::Gpu;
use crate::camera::Camera;
use crate::ground::materials::{MATERIAL_TEXELS, MATERIAL_TILE_M, MAX_RELIEF_M};
use crate::ground::type_window::TypeWindow;
use crate::surface::World;
use std::sync::Arc;

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
    /// The ground cell of the window's texel (0, 0), and the window's side in cells.
    window_first: [i32; 2],
    window_side: [i32; 2],
    /// The ground layer's cells per side.
    map_cells: [i32; 2],
    pad2: [f32; 2],
}

/// Pixels up to this size see the ground materials' detail height as bumps of the ground's
/// normal, in full up to a quarter of it (m). At 720p and a 60-degree view that is out to about
/// 60 m, in full to 15 m; farther, centimetre relief is below a pixel.
pub const BUMP_PX_M: f64 = 0.1;

/// The detail bindings and the map numbers the uniform is made of.
pub struct GroundDetail {
    pub materials: wgpu::TextureView,
    /// The window of the ground layer (`R8Uint`, row 0 south).
    window_texture: wgpu::Texture,
    pub ground_types: wgpu::TextureView,
    pub sampler: wgpu::Sampler,
    pub buffer: wgpu::Buffer,
    map_origin_m: [f64; 2],
    ground_spacing_m: f64,
    types: u32,
    finest_texel_m: f64,
    /// The map whose ground layer the window shows (none for the stand-in), and where the
    /// window is (none before the first frame).
    world: Option<Arc<World>>,
    window: Option<TypeWindow>,
}

impl std::fmt::Debug for GroundDetail {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "GroundDetail(finest texel {} m)", self.finest_texel_m)
    }
}

impl GroundDetail {
    /// Detail from `materials` (a 2D array, one layer per ground type, `MATERIAL_TEXELS`
    /// texels over `MATERIAL_TILE_M`, full mip chain; `types` layers) for `world`'s ground
    /// layer; the finest node texel is `finest_texel_m`.
    pub fn new(
        gpu: &Gpu,
        materials: wgpu::TextureView,
        types: u32,
        world: &Arc<World>,
        finest_texel_m: f64,
    ) -> Self {
        let ground = &world.map.manifest.ground;
        let map = [world.map.ground.width(), world.map.ground.height()];
        let side = TypeWindow::around(map, ground.spacing_m, [0.0; 2]).side;
        let mut detail = Self::with_window(
            gpu,
            materials,
            window_texture(gpu, side.map(|s| s as u32)),
            (world.map.manifest.origin_m, ground.spacing_m, types),
            finest_texel_m,
        );
        detail.world = Some(Arc::clone(world));
        detail
    }

    fn with_window(
        gpu: &Gpu,
        materials: wgpu::TextureView,
        window_texture: wgpu::Texture,
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
            ground_types: window_texture.create_view(&wgpu::TextureViewDescriptor::default()),
            window_texture,
            sampler,
            buffer,
            map_origin_m,
            ground_spacing_m,
            types,
            finest_texel_m,
            world: None,
            window: None,
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
        Self::with_window(
            gpu,
            texture(
                "no ground materials",
                wgpu::TextureFormat::Rgba8UnormSrgb,
                true,
            ),
            window_texture(gpu, [1, 1]),
            ([0.0; 2], 1.0, 1),
            0.0,
        )
    }

    /// Moves the window of the ground layer with the camera at `camera_cells` (ground-cell
    /// coordinates) when it nears the window's edge, writing the new window's cells; the
    /// window in use.
    fn follow(&mut self, queue: &wgpu::Queue, camera_cells: [f64; 2]) -> Option<TypeWindow> {
        let world = self.world.as_ref()?;
        let ground = &world.map.ground;
        let next = match self.window {
            Some(w) => w.follow(camera_cells),
            None => TypeWindow::around(
                [ground.width(), ground.height()],
                self.ground_spacing_m,
                camera_cells,
            ),
        };
        if self.window != Some(next) {
            let [w, h] = next.side.map(|s| s as u32);
            queue.write_texture(
                self.window_texture.as_image_copy(),
                &next.cells(ground),
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(w),
                    rows_per_image: Some(h),
                },
                wgpu::Extent3d {
                    width: w,
                    height: h,
                    depth_or_array_layers: 1,
                },
            );
            self.window = Some(next);
        }
        Some(next)
    }

    /// Writes this frame's uniform for `camera`.
    pub fn write(&mut self, queue: &wgpu::Queue, camera: &Camera) {
        let p = camera.position_m;
        let (dx, dy) = (p.x - self.map_origin_m[0], p.y - self.map_origin_m[1]);
        let camera_cells = [dx / self.ground_spacing_m, dy / self.ground_spacing_m];
        // Without a map (the stand-in) the window is empty: no detail anywhere.
        let window = self.follow(queue, camera_cells);
        let (window_first, window_side, map_cells) = window.map_or(([0; 2], [0; 2], [1; 2]), |w| {
            (
                w.first.map(|v| v as i32),
                w.side.map(|v| v as i32),
                w.map_cells().map(|v| v as i32),
            )
        });
        let material_texel_m = MATERIAL_TILE_M / f64::from(MATERIAL_TEXELS);
        let u = DetailUniform {
            camera_cells: camera_cells.map(|c| c as f32),
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
            window_first,
            window_side,
            map_cells,
            pad2: [0.0; 2],
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

/// A texture for a window of `side` ground cells (`R8Uint`, row 0 south).
fn window_texture(gpu: &Gpu, side: [u32; 2]) -> wgpu::Texture {
    gpu.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("ground types around the camera"),
        size: wgpu::Extent3d {
            width: side[0].max(1),
            height: side[1].max(1),
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::R8Uint,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    })
}
