//! What every renderer shares: the frame uniforms (camera, sun, sky, fog, debug mode) in bind
//! group 0, the layout of bind group 1 (a renderer's node table: camera-relative origin, dither
//! interval and level per node, see `node_table`), the view options and draw statistics, and the
//! pipeline and pass helpers.

use super::DEPTH_FORMAT;
use super::gpu_data::FrameUniforms;
use super::light_pool::LightPool;
use crate::camera::Camera;
use crate::lighting::Sun;
use glam::{DVec3, Vec3};

/// Period (m) of the ground's fine detail pattern (`terrain.wgsl`): the camera position is sent
/// modulo this, and the pattern repeats with it (64 m, far beyond where it shows).
pub const DETAIL_PERIOD_M: f64 = 64.0;

/// Debug views and per-view switches.
#[derive(Debug, Clone, Copy, PartialEq)]
#[allow(
    clippy::struct_excessive_bools,
    reason = "independent on/off switches of the viewer's panel"
)]
pub struct ViewOptions {
    pub wireframe: bool,
    pub color_by_level: bool,
    pub show_bounds: bool,
    /// Draw the sky gradient (off: the clear colour shows wherever nothing was drawn).
    pub sky: bool,
    /// Clear colour (linear RGBA) behind everything.
    pub clear: [f64; 4],
    /// Distance fog: density per metre and largest amount (depth cueing, never hiding).
    pub fog_per_m: f32,
    pub fog_max: f32,
    /// Draw the terrain (off: only what stands on it, for measures of its image).
    pub terrain: bool,
    /// Draw vegetation.
    pub plants: bool,
    /// Draw progressive-mesh objects (houses, `--object` copies).
    pub objects: bool,
    /// Issue each renderer's draws as one multi-draw per batch where the adapter supports it
    /// (off: one draw call per node item, the fallback path; the pixels are the same).
    pub merged_draws: bool,
    /// How the ground is shown (debug views of the ground textures).
    pub ground_view: GroundView,
    /// The sun (its light's direction; the light grids are made for the same sun).
    pub sun: Sun,
    /// Debug view: everything grey, lit by the light grids alone (sky and sun visibility).
    pub lighting_only: bool,
    /// Debug view: the light grids' values, unshaded and without fog (red: sky visibility,
    /// green: sun visibility, blue: the ground's bounce; 1, 1, 0 where a node has no grid yet).
    pub light_values: bool,
    /// Level choice of progressive-mesh objects (STRENGTH, MINVERTS, ZDISP, fixed level, MORPH;
    /// their tau is the streamer's).
    pub pm_lod: crate::objects::lod::PmLodSettings,
    /// Debug view: objects coloured by the share of their positions drawn (MLMODE).
    pub pm_color_by_lod: bool,
    /// Debug view: textured objects tinted by the mip level resident in the texture cache
    /// (red full resolution, then orange, yellow, green, cyan, blue, violet coarser).
    pub texture_mip_view: bool,
    /// Draw a node's merged far mesh of its houses where the pixel metric accepts it (HLOD);
    /// off: every house on its own.
    pub hlod: bool,
    /// GPU-ratio diagnostic: the terrain's draws (same batches, skirts and cross-fade dithers)
    /// with a flat fragment shader like the one-draw reference's, so that pass / reference
    /// splits into what the geometry costs and what the shading costs.
    pub flat_terrain: bool,
}

/// Debug views of the ground.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum GroundView {
    /// Lit and fogged, from the node's ground texture (vertex colours where it has none).
    #[default]
    Shaded,
    /// Coloured by ground-texture texels per pixel ([`texels_per_pixel_of`] reads it back):
    /// red where a texel covers several pixels (blurred), yellow at one, green where a pixel
    /// covers several texels; nodes without a texture grey.
    TexelDensity,
    /// The ground texture alone: no light, no fog.
    TextureOnly,
}

/// Texels per pixel encoded by [`GroundView::TexelDensity`]: green channel (linear) =
/// `log2(texels per pixel) / 8 + 1/2`, red = `1 - green`, blue 0. The inverse, or None for a
/// pixel that is not a textured ground pixel.
pub fn texels_per_pixel_of(linear_rgb: [f32; 3]) -> Option<f32> {
    let [r, g, b] = linear_rgb;
    ((r + g - 1.0).abs() < 0.03 && b < 0.01).then(|| ((g - 0.5) * 8.0).exp2())
}

impl ViewOptions {
    /// The shaders' debug mode: 1 colour by level, 2 texel density, 3 ground texture only,
    /// 4 lighting only, 5 light-grid values, 0 none.
    pub fn debug_mode(&self) -> f32 {
        match (self.color_by_level, self.ground_view) {
            (true, _) => 1.0,
            (false, _) if self.light_values => 5.0,
            (false, _) if self.lighting_only => 4.0,
            (false, GroundView::Shaded) => 0.0,
            (false, GroundView::TexelDensity) => 2.0,
            (false, GroundView::TextureOnly) => 3.0,
        }
    }

    /// Whether this frame's batches are recorded as multi-draws on `gpu` (else as plain loops).
    pub fn multi_draw(&self, gpu: &super::Gpu) -> bool {
        self.merged_draws && gpu.multi_draw
    }
}

impl Default for ViewOptions {
    fn default() -> Self {
        Self {
            wireframe: false,
            color_by_level: false,
            show_bounds: false,
            sky: true,
            clear: [0.0, 0.0, 0.0, 1.0],
            fog_per_m: 1.0 / 25_000.0,
            fog_max: 0.35,
            terrain: true,
            plants: true,
            objects: true,
            merged_draws: true,
            ground_view: GroundView::Shaded,
            sun: Sun::default(),
            lighting_only: false,
            light_values: false,
            pm_lod: crate::objects::lod::PmLodSettings::default(),
            pm_color_by_lod: false,
            texture_mip_view: false,
            hlod: true,
            flat_terrain: false,
        }
    }
}

/// What one frame drew.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DrawStats {
    /// Terrain draw calls recorded (a multi-draw counts once) and the node items they draw
    /// (one per node mesh); triangles; nodes culled (outside the frustum or an empty interval).
    pub draw_calls: u32,
    pub items: u32,
    pub triangles: u64,
    pub culled: u32,
    /// Vegetation: instances drawn (meshes and billboards), draw calls recorded and the items
    /// they draw (one per node and instance group), mesh triangles.
    pub plant_instances: u64,
    pub plant_draw_calls: u32,
    pub plant_items: u32,
    pub plant_triangles: u64,
    /// Of the instances: group-billboard quads (each stands for a cluster of items).
    pub group_billboards: u64,
    /// Progressive-mesh objects: items (instances and merged far meshes), the draw calls they
    /// take (one per item, or one multi-draw per texture pair and page), and triangles.
    pub object_items: u32,
    pub object_draw_calls: u32,
    pub object_triangles: u64,
    /// Triangles the drawn objects would have at full detail.
    pub object_full_triangles: u64,
    /// Objects drawn from an `MSFT_lod` chain level.
    pub object_chain_draws: u32,
    /// Of the object draws: merged far meshes of a node's houses (HLOD).
    pub object_hlod_draws: u32,
    /// The texture cache: bytes of the slots holding textures, bytes the drawn
    /// textures would take at full resolution, drawn textures with no level resident (drawn in
    /// their mean colour), uploads and bytes uploaded this frame.
    pub texture_resident_bytes: u64,
    pub texture_full_bytes: u64,
    pub texture_misses: u32,
    /// Drawn textures resident coarser than the level they need (budget or uploads short).
    pub texture_coarser: u32,
    pub texture_uploads: u32,
    pub texture_upload_bytes: u64,
}

/// The frame uniforms and bind group and the node-table layout, shared by all renderers.
pub struct FrameResources {
    /// The colour format every renderer draws into (sRGB).
    pub color_format: wgpu::TextureFormat,
    buffer: wgpu::Buffer,
    /// Group 0: the frame uniforms.
    pub layout: wgpu::BindGroupLayout,
    pub group: wgpu::BindGroup,
    /// Group 1: a renderer's node table (a read-only storage array, vertex stage).
    pub node_layout: wgpu::BindGroupLayout,
    /// The light-grid pool (group 0, bindings 1 to 3).
    pub light: LightPool,
    camera_m: DVec3,
}

impl std::fmt::Debug for FrameResources {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "FrameResources({:?})", self.color_format)
    }
}

/// A uniform-buffer layout entry.
/// A read-only storage-buffer binding.
pub fn storage_entry(binding: u32, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only: true },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

pub fn uniform_entry(
    binding: u32,
    dynamic: bool,
    visibility: wgpu::ShaderStages,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: dynamic,
            min_binding_size: None,
        },
        count: None,
    }
}

/// A filterable float texture layout entry (fragment stage) of `dimension`.
pub fn texture_entry(
    binding: u32,
    dimension: wgpu::TextureViewDimension,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable: true },
            view_dimension: dimension,
            multisampled: false,
        },
        count: None,
    }
}

/// A 2D unsigned-integer texture layout entry (fragment stage; read with `textureLoad`).
pub fn uint_texture_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Uint,
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        count: None,
    }
}

/// A filtering sampler layout entry (fragment stage).
pub fn sampler_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
        count: None,
    }
}

/// A bind group holding one uniform buffer at `binding`.
pub fn uniform_group(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    binding: u32,
    buffer: &wgpu::Buffer,
) -> wgpu::BindGroup {
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout,
        entries: &[wgpu::BindGroupEntry {
            binding,
            resource: buffer.as_entire_binding(),
        }],
    })
}

impl FrameResources {
    pub fn new(device: &wgpu::Device, color_format: wgpu::TextureFormat) -> Self {
        let vf = wgpu::ShaderStages::VERTEX_FRAGMENT;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("frame layout"),
            entries: &[
                uniform_entry(0, false, vf),
                wgpu::BindGroupLayoutEntry {
                    visibility: vf,
                    ..texture_entry(1, wgpu::TextureViewDimension::D3)
                },
                uniform_entry(3, false, vf),
            ],
        });
        let node_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("node table layout"),
            entries: &[
                storage_entry(0, wgpu::ShaderStages::VERTEX),
                storage_entry(1, wgpu::ShaderStages::VERTEX),
            ],
        });
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frame uniforms"),
            size: std::mem::size_of::<FrameUniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let light = LightPool::new(device);
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("frame group"),
            layout: &layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: buffer.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&light.view),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: light.info.as_entire_binding(),
                },
            ],
        });
        Self {
            color_format,
            buffer,
            layout,
            group,
            node_layout,
            light,
            camera_m: DVec3::ZERO,
        }
    }

    /// Frame uniforms for a camera: the view rotation and an infinite reversed-Z projection.
    pub fn uniforms(cam: &Camera, view: &ViewOptions) -> FrameUniforms {
        let f = cam.forward.as_vec3();
        let u = cam.up.as_vec3();
        let view_m = glam::camera::rh::view::look_to_mat4(Vec3::ZERO, f, u);
        // WebGPU convention: NDC z in [0, 1], y up; reversed-Z with an infinite far plane.
        let proj = glam::camera::rh::proj::directx::perspective_infinite_reverse(
            cam.fovy_rad as f32,
            cam.aspect() as f32,
            cam.near_m as f32,
        );
        let clip_from_rel = proj * view_m;
        let sun = view.sun.toward().as_vec3();
        FrameUniforms {
            clip_from_rel: clip_from_rel.to_cols_array_2d(),
            rel_from_clip: clip_from_rel.inverse().to_cols_array_2d(),
            sun_dir: [sun.x, sun.y, sun.z, 0.0],
            sun_color: [1.0, 0.93, 0.82, 0.0],
            sky_zenith: [0.16, 0.32, 0.66, 1.0],
            sky_horizon: [0.62, 0.72, 0.84, 1.0],
            fog: [view.fog_per_m, view.fog_max, view.debug_mode(), 0.0],
            camera_wrap: [
                cam.position_m.x.rem_euclid(DETAIL_PERIOD_M) as f32,
                cam.position_m.y.rem_euclid(DETAIL_PERIOD_M) as f32,
                0.0,
                0.0,
            ],
        }
    }

    /// Writes the frame uniforms (bakes write their own camera before their pass).
    pub fn write_uniforms(&self, queue: &wgpu::Queue, cam: &Camera, view: &ViewOptions) {
        queue.write_buffer(
            &self.buffer,
            0,
            bytemuck::bytes_of(&Self::uniforms(cam, view)),
        );
    }

    /// Starts a frame: writes the frame uniforms and keeps the camera for [`Self::offset_m`].
    pub fn begin(&mut self, queue: &wgpu::Queue, cam: &Camera, view: &ViewOptions) {
        self.write_uniforms(queue, cam, view);
        self.camera_m = cam.position_m;
    }

    /// This frame's [`node_offset_m`] of a node whose south-west corner is `origin_m`.
    pub fn offset_m(&self, origin_m: [f64; 2]) -> [f32; 3] {
        node_offset_m(origin_m, self.camera_m)
    }

    /// A pipeline layout of the frame group, the node group (or a gap) and `extra` groups.
    pub fn pipeline_layout(
        &self,
        device: &wgpu::Device,
        label: &str,
        node: bool,
        extra: &[Option<&wgpu::BindGroupLayout>],
    ) -> wgpu::PipelineLayout {
        let mut groups = vec![Some(&self.layout), node.then_some(&self.node_layout)];
        groups.extend_from_slice(extra);
        device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &groups,
            immediate_size: 0,
        })
    }
}

/// Where a node's vertices are placed relative to the camera: node origin (south-west corner,
/// z = 0) minus the camera, in f64, then f32. Vertices are f32 relative to their node, so a
/// drawn position is `offset + vertex` with small numbers only, however far from the world
/// origin (the renderer's only f64 -> f32 step for node geometry).
pub fn node_offset_m(origin_m: [f64; 2], camera_m: DVec3) -> [f32; 3] {
    [
        (origin_m[0] - camera_m.x) as f32,
        (origin_m[1] - camera_m.y) as f32,
        (-camera_m.z) as f32,
    ]
}

/// Reversed-Z depth state.
pub fn depth_state(write: bool, compare: wgpu::CompareFunction) -> wgpu::DepthStencilState {
    wgpu::DepthStencilState {
        format: DEPTH_FORMAT,
        depth_write_enabled: Some(write),
        depth_compare: Some(compare),
        stencil: wgpu::StencilState::default(),
        bias: wgpu::DepthBiasState::default(),
    }
}

/// What differs between the engine's render pipelines (all: no blending, no MSAA, no culling).
#[derive(Debug, Clone)]
pub struct PipelineSpec<'a> {
    pub label: &'a str,
    pub vs: &'a str,
    pub fs: &'a str,
    pub buffers: &'a [Option<wgpu::VertexBufferLayout<'a>>],
    pub topology: wgpu::PrimitiveTopology,
    pub polygon_mode: wgpu::PolygonMode,
    pub depth: wgpu::DepthStencilState,
    pub format: wgpu::TextureFormat,
    /// A second colour target (`@location(1)`): the normals of the vegetation bakes.
    pub second_format: Option<wgpu::TextureFormat>,
}

impl<'a> PipelineSpec<'a> {
    /// Filled triangle lists with reversed-Z depth test and write, into `format`.
    pub fn triangles(
        label: &'a str,
        vs: &'a str,
        fs: &'a str,
        buffers: &'a [Option<wgpu::VertexBufferLayout<'a>>],
        format: wgpu::TextureFormat,
    ) -> Self {
        Self {
            label,
            vs,
            fs,
            buffers,
            topology: wgpu::PrimitiveTopology::TriangleList,
            polygon_mode: wgpu::PolygonMode::Fill,
            depth: depth_state(true, wgpu::CompareFunction::Greater),
            format,
            second_format: None,
        }
    }
}

/// A render pipeline of `module` with `layout` as `spec` says.
pub fn pipeline(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    layout: &wgpu::PipelineLayout,
    spec: &PipelineSpec<'_>,
) -> wgpu::RenderPipeline {
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(spec.label),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some(spec.vs),
            compilation_options: wgpu::PipelineCompilationOptions::default(),
            buffers: spec.buffers,
        },
        primitive: wgpu::PrimitiveState {
            topology: spec.topology,
            cull_mode: None,
            polygon_mode: spec.polygon_mode,
            ..Default::default()
        },
        depth_stencil: Some(spec.depth.clone()),
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some(spec.fs),
            compilation_options: wgpu::PipelineCompilationOptions::default(),
            targets: &[spec.format]
                .into_iter()
                .chain(spec.second_format)
                .map(|format| {
                    Some(wgpu::ColorTargetState {
                        format,
                        blend: None,
                        write_mask: wgpu::ColorWrites::ALL,
                    })
                })
                .collect::<Vec<_>>(),
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// A bake pass: colour targets (one, or two where a bake writes normals too) cleared to
/// transparent, reversed-Z depth cleared to 0 (far).
pub fn bake_pass<'e>(
    enc: &'e mut wgpu::CommandEncoder,
    label: &str,
    colors: &[&wgpu::TextureView],
    depth: &wgpu::TextureView,
) -> wgpu::RenderPass<'e> {
    let attachments: Vec<_> = colors
        .iter()
        .map(|&view| {
            Some(wgpu::RenderPassColorAttachment {
                view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                    store: wgpu::StoreOp::Store,
                },
            })
        })
        .collect();
    enc.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &attachments,
        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
            view: depth,
            depth_ops: Some(wgpu::Operations {
                load: wgpu::LoadOp::Clear(0.0),
                store: wgpu::StoreOp::Discard,
            }),
            stencil_ops: None,
        }),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

/// sRGB-encoded 8-bit to linear, as the f32 uniforms hold it ([`crate::color`]).
pub fn srgb_to_linear(c: u8) -> f32 {
    crate::color::srgb_to_linear(c) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The matrix the frame draws with is the camera's own ([`Camera::clip_from_rel`], which the
    /// on-screen error measure projects with), built in f32: they agree to f32 rounding.
    #[test]
    fn the_frame_draws_with_the_cameras_matrix() {
        for (fovy_deg, size) in [
            (60.0, [1280, 720]),
            (90.0, [1680, 720]),
            (120.0, [320, 180]),
        ] {
            let cam = Camera::look_at(
                DVec3::new(10.0, -20.0, 300.0),
                DVec3::new(500.0, 400.0, 0.0),
                f64::to_radians(fovy_deg),
                size,
            );
            let frame = FrameResources::uniforms(&cam, &ViewOptions::default()).clip_from_rel;
            let camera = cam.clip_from_rel().as_mat4().to_cols_array_2d();
            for (fc, cc) in frame.iter().zip(camera) {
                for (f, c) in fc.iter().zip(cc) {
                    assert!(
                        (f - c).abs() <= 1e-5 * c.abs().max(1.0),
                        "{frame:?} {camera:?}"
                    );
                }
            }
        }
    }
}
