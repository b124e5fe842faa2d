//! The GPU side (wgpu 30). Everything else in the engine is CPU data; this module turns it into
//! pictures.
//!
//! - [`Gpu`]: instance, adapter, device and queue, with an error that says which Debian packages
//!   provide a software adapter when none is found.
//! - [`scene`]: the [`scene::NodeRenderer`] trait (upload, prepare, draw hooks) and the
//!   [`scene::Scene`] that holds the renderers in drawing order.
//! - [`frame`]: what all renderers share: frame uniforms (group 0), the node-table layout
//!   (group 1), view options, draw statistics, pipeline and pass helpers.
//! - Merged draws (seed 002): [`suballoc`] (node geometry suballocated from a few large
//!   buffers; [`paged_buffer`] the pages of one such buffer), [`node_table`] (per-node data as
//!   one storage array per renderer, a row per node drawn this frame), [`batches`] (a frame's draws as one multi-draw per render
//!   state and page, a plain loop as fallback).
//! - One renderer per kind of thing drawn: [`sky`] (sky, node-bounds lines), [`terrain`],
//!   [`vegetation`] (with its atlas and impostor bakes). Each owns its pipelines, its per-node
//!   GPU objects and its `gpu_data` structs; [`gpu_data`] holds the structs of the shared prelude.
//! - [`shader`]: WGSL assembly (generated constants + prelude + the renderer's file).
//! - [`Target`]: an offscreen colour + depth target with PNG readback (headless frames, tests,
//!   screenshots); [`GpuTimer`]: timestamp queries read back without stalling.
//!
//! Depth is reversed-Z `Depth32Float` with an infinite far plane: clear to 0, test `Greater`.
//! Positions reach the GPU camera-relative: node origin minus camera in f64, then f32.

pub mod batch_timer;
pub mod batches;
mod bulk_forget;
pub mod frame;
pub mod gpu_data;
pub mod ground;
pub mod ground_detail;
pub mod ground_pool;
pub mod impostors;
pub mod light_pool;
pub mod lighting;
pub mod node_table;
pub mod objects;
pub mod paged_buffer;
pub mod reference;
pub mod scene;
pub mod shader;
pub mod sky;
pub mod suballoc;
mod target;
pub mod terrain;
pub mod texture_credit;
pub mod texture_pool;
mod timer;
pub mod vegetation;

pub use target::{Target, depth_view, read_texels, texture_view_2d, write_png};
pub use timer::GpuTimer;

/// Colour format of every target (sRGB, so shading happens in linear space).
pub const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
/// Reversed-Z depth.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter found: install the Debian packages `mesa-vulkan-drivers libvulkan1` \
         for a software Vulkan adapter (lavapipe; `./flyover` installs them), or a GPU driver; \
         `WGPU_BACKEND=vulkan` or `gl` picks a backend (wgpu: {0})"
    )]
    NoAdapter(String),
    #[error("the GPU adapter {adapter} refused to create a device: {reason}")]
    Device { adapter: String, reason: String },
    #[error("reading the rendered frame back failed: {0}")]
    Readback(String),
    #[error("writing {path}: {reason}")]
    WritePng { path: String, reason: String },
}

/// The limits the device asks for: WebGPU's downlevel defaults with the adapter's texture sizes
/// and its array-layer limit up to [`ground_pool::MAX_LAYERS_PER_PAGE`] (larger ground-texture
/// pages, fewer terrain batches).
fn limits(adapter: &wgpu::Adapter) -> wgpu::Limits {
    let available = adapter.limits();
    let mut limits = wgpu::Limits::downlevel_defaults().using_resolution(available.clone());
    limits.max_texture_array_layers = available
        .max_texture_array_layers
        .min(ground_pool::MAX_LAYERS_PER_PAGE)
        .max(limits.max_texture_array_layers);
    limits
}

/// Whether `adapter` is a CPU rasteriser (lavapipe), whose "GPU" memory is the process's RAM.
pub fn is_cpu_adapter(adapter: &wgpu::Adapter) -> bool {
    adapter.get_info().device_type == wgpu::DeviceType::Cpu
}

/// A device and its queue.
pub struct Gpu {
    pub instance: wgpu::Instance,
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    /// Whether `PolygonMode::Line` (wireframe) is available.
    pub wireframe: bool,
    /// Whether timestamp queries inside passes are available.
    pub timestamps: bool,
    /// Whether multi-draw indirect with a non-zero first instance is available (else merged
    /// batches are recorded as plain loops of the same draws, see `batches`).
    pub multi_draw: bool,
    /// Anisotropy clamp for textures seen at grazing angles: 8, or 1 (plain trilinear) on a CPU
    /// adapter. llvmpipe (Mesa 22) filters anisotropically with an elliptical filter that visits
    /// every texel of the pixel's footprint in the chosen mip level, computed from the
    /// coordinates' own derivatives (explicit gradients do not bound it); a distant node texture
    /// under a few pixels then costs seconds per frame.
    pub anisotropy: u16,
}

impl std::fmt::Debug for Gpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Gpu({})", self.adapter_name())
    }
}

impl Gpu {
    /// A device without a window (offscreen rendering).
    pub fn new_headless() -> Result<Self, GpuError> {
        // Vulkan/Metal/DX12 unless WGPU_BACKEND says otherwise (GL probing only adds noise).
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = wgpu::Backends::PRIMARY;
        let instance = wgpu::Instance::new(desc.with_env());
        Self::with_instance(instance, None)
    }

    /// A device for `instance`, compatible with `surface` when given.
    pub fn with_instance(
        instance: wgpu::Instance,
        surface: Option<&wgpu::Surface<'_>>,
    ) -> Result<Self, GpuError> {
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: surface,
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let available = adapter.features();
        let mut features = wgpu::Features::empty();
        let wireframe = available.contains(wgpu::Features::POLYGON_MODE_LINE);
        if wireframe {
            features |= wgpu::Features::POLYGON_MODE_LINE;
        }
        let timestamps = available.contains(
            wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS,
        );
        if timestamps {
            features |=
                wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS;
        }
        let multi_draw = available.contains(wgpu::Features::INDIRECT_FIRST_INSTANCE)
            && adapter
                .get_downlevel_capabilities()
                .flags
                .contains(wgpu::DownlevelFlags::INDIRECT_EXECUTION);
        if multi_draw {
            features |= wgpu::Features::INDIRECT_FIRST_INSTANCE;
        }
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("engine device"),
            required_features: features,
            required_limits: limits(&adapter),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device {
            adapter: adapter.get_info().name,
            reason: e.to_string(),
        })?;
        let anisotropy = if is_cpu_adapter(&adapter) { 1 } else { 8 };
        Ok(Self {
            instance,
            adapter,
            device,
            queue,
            wireframe,
            timestamps,
            multi_draw,
            anisotropy,
        })
    }

    pub fn adapter_name(&self) -> String {
        let i = self.adapter.get_info();
        format!("{} ({:?}, {})", i.name, i.backend, i.driver)
    }
}

/// Every renderer's assembled shader source, by file name (for validation).
pub fn shader_sources() -> Vec<(&'static str, String)> {
    vec![
        ("sky", sky::shader_source()),
        ("ground", ground::shader_source()),
        ("reference", reference::shader_source()),
        ("terrain", terrain::shader_source()),
        ("vegetation", vegetation::shader_source()),
        ("objects", objects::shader_source()),
    ]
}
