//! The GPU side (wgpu 30). Everything else in the engine is CPU data; this module turns it into
//! pictures.
//!
//! - [`Gpu`]: instance, adapter, device and queue, with an error that says which Debian packages
//!   provide a software adapter when none is found.
//! - [`terrain::TerrainRenderer`]: long-lived pipelines for terrain nodes, sky and debug lines,
//!   per-node GPU buffers ([`terrain::TerrainNodeGpu`]) created by the streaming GPU phase, and
//!   per-frame draw data (camera-relative node offsets, dither intervals).
//! - [`Target`]: an offscreen colour + depth target with PNG readback (headless frames, tests,
//!   screenshots).
//!
//! Depth is reversed-Z `Depth32Float` with an infinite far plane: clear to 0, test `Greater`.
//! Positions reach the GPU camera-relative: node origin minus camera in f64, then f32.

pub mod gpu_data;

pub mod terrain;

use std::path::Path;

/// Colour format of every target (sRGB, so shading happens in linear space).
pub const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
/// Reversed-Z depth.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter found ({0}). For a software adapter install the Debian packages \
         `mesa-vulkan-drivers libvulkan1` (lavapipe); `WGPU_BACKEND=vulkan` or `gl` picks a backend"
    )]
    NoAdapter(String),
    #[error("the GPU adapter {adapter} refused to create a device: {reason}")]
    Device { adapter: String, reason: String },
    #[error("reading the rendered frame back failed: {0}")]
    Readback(String),
    #[error("writing {path}: {reason}")]
    WritePng { path: String, reason: String },
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
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("engine device"),
            required_features: features,
            required_limits: wgpu::Limits::downlevel_defaults().using_resolution(adapter.limits()),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device {
            adapter: adapter.get_info().name,
            reason: e.to_string(),
        })?;
        Ok(Self {
            instance,
            adapter,
            device,
            queue,
            wireframe,
            timestamps,
        })
    }

    pub fn adapter_name(&self) -> String {
        let i = self.adapter.get_info();
        format!("{} ({:?}, {})", i.name, i.backend, i.driver)
    }
}

/// An offscreen colour + depth target.
pub struct Target {
    pub size: [u32; 2],
    pub format: wgpu::TextureFormat,
    pub color: wgpu::Texture,
    /// The view the terrain draws through (sRGB).
    pub color_view: wgpu::TextureView,
    /// A view in the texture's own format (for overlays such as egui that want a linear one).
    pub plain_view: wgpu::TextureView,
    pub depth_view: wgpu::TextureView,
}

impl Target {
    /// A target of `size` pixels in `format` (RGBA or BGRA, 8 bits).
    pub fn new(device: &wgpu::Device, size: [u32; 2], format: wgpu::TextureFormat) -> Self {
        Self::with_srgb_view(device, size, format)
    }

    /// A target stored in `format` whose `color_view` is the sRGB variant of it (the same when
    /// `format` is already sRGB) and `plain_view` the format itself.
    pub fn with_srgb_view(
        device: &wgpu::Device,
        size: [u32; 2],
        format: wgpu::TextureFormat,
    ) -> Self {
        let srgb = format.add_srgb_suffix();
        let extent = wgpu::Extent3d {
            width: size[0],
            height: size[1],
            depth_or_array_layers: 1,
        };
        let color = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("offscreen colour"),
            size: extent,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[srgb],
        });
        let color_view = color.create_view(&wgpu::TextureViewDescriptor {
            format: Some(srgb),
            ..Default::default()
        });
        let plain_view = color.create_view(&wgpu::TextureViewDescriptor::default());
        let depth_view = depth_view(device, size, "offscreen depth");
        Self {
            size,
            format,
            color,
            color_view,
            plain_view,
            depth_view,
        }
    }

    /// Copies the colour target to the CPU: RGBA8 rows, top row first.
    pub fn read_rgba(&self, gpu: &Gpu) -> Result<Vec<u8>, GpuError> {
        let [w, h] = self.size;
        let row = (w * 4).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
            * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let buffer = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: u64::from(row) * u64::from(h),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut enc = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("readback copy"),
            });
        enc.copy_texture_to_buffer(
            self.color.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row),
                    rows_per_image: Some(h),
                },
            },
            wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
        );
        gpu.queue.submit([enc.finish()]);
        let slice = buffer.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        gpu.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        rx.recv()
            .map_err(|e| GpuError::Readback(e.to_string()))?
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        let data = slice
            .get_mapped_range()
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        let mut out = Vec::with_capacity((w * h * 4) as usize);
        for y in 0..h as usize {
            out.extend_from_slice(&data[y * row as usize..][..(w * 4) as usize]);
        }
        if matches!(
            self.format,
            wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb
        ) {
            for px in out.chunks_exact_mut(4) {
                px.swap(0, 2);
            }
        }
        drop(data);
        buffer.unmap();
        Ok(out)
    }
}

/// A reversed-Z depth view of `size`.
pub fn depth_view(device: &wgpu::Device, size: [u32; 2], label: &str) -> wgpu::TextureView {
    device
        .create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d {
                width: size[0],
                height: size[1],
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: DEPTH_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            view_formats: &[],
        })
        .create_view(&wgpu::TextureViewDescriptor::default())
}

/// Writes RGBA8 rows (top first) as a PNG.
pub fn write_png(path: &Path, size: [u32; 2], rgba: &[u8]) -> Result<(), GpuError> {
    let err = |reason: String| GpuError::WritePng {
        path: path.display().to_string(),
        reason,
    };
    let file = std::fs::File::create(path).map_err(|e| err(e.to_string()))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), size[0], size[1]);
    enc.set_color(png::ColorType::Rgba);
    enc.set_depth(png::BitDepth::Eight);
    let mut w = enc.write_header().map_err(|e| err(e.to_string()))?;
    w.write_image_data(rgba).map_err(|e| err(e.to_string()))?;
    w.finish().map_err(|e| err(e.to_string()))
}

/// GPU time of a span of commands from timestamp queries, read back without stalling: the
/// result of one frame arrives a frame or more later.
pub struct GpuTimer {
    queries: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    read: wgpu::Buffer,
    period_ns: f64,
    /// 0: idle, 1: written into an encoder, 2: mapping requested, 3: mapped.
    state: std::sync::Arc<std::sync::atomic::AtomicU8>,
    /// The latest measurement (ms).
    pub last_ms: Option<f64>,
}

impl GpuTimer {
    /// A timer when the device has timestamp queries inside encoders, else None.
    pub fn new(gpu: &Gpu) -> Option<Self> {
        if !gpu.timestamps {
            return None;
        }
        let buffer = |label: &str, usage: wgpu::BufferUsages| {
            gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: 16,
                usage,
                mapped_at_creation: false,
            })
        };
        Some(Self {
            queries: gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("frame timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            }),
            resolve: buffer(
                "timestamp resolve",
                wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            ),
            read: buffer(
                "timestamp readback",
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            ),
            period_ns: f64::from(gpu.queue.get_timestamp_period()),
            state: std::sync::Arc::new(std::sync::atomic::AtomicU8::new(0)),
            last_ms: None,
        })
    }

    /// Collects a finished measurement, if any (call once per frame before `begin`).
    pub fn harvest(&mut self, gpu: &Gpu) {
        use std::sync::atomic::Ordering;
        if self.state.load(Ordering::Acquire) == 2 {
            let _ = gpu.device.poll(wgpu::PollType::Poll);
        }
        if self.state.load(Ordering::Acquire) == 3 {
            if let Ok(view) = self.read.slice(..).get_mapped_range() {
                let t: [u64; 2] = [
                    u64::from_le_bytes(view[0..8].try_into().unwrap_or_default()),
                    u64::from_le_bytes(view[8..16].try_into().unwrap_or_default()),
                ];
                drop(view);
                self.last_ms = Some(t[1].saturating_sub(t[0]) as f64 * self.period_ns * 1e-6);
            }
            self.read.unmap();
            self.state.store(0, Ordering::Release);
        }
    }

    /// Writes the start timestamp when the timer is free; returns whether it did.
    pub fn begin(&self, enc: &mut wgpu::CommandEncoder) -> bool {
        use std::sync::atomic::Ordering;
        if self.state.load(Ordering::Acquire) != 0 {
            return false;
        }
        enc.write_timestamp(&self.queries, 0);
        self.state.store(1, Ordering::Release);
        true
    }

    /// Writes the end timestamp and the copy to the readback buffer.
    pub fn end(&self, enc: &mut wgpu::CommandEncoder) {
        enc.write_timestamp(&self.queries, 1);
        enc.resolve_query_set(&self.queries, 0..2, &self.resolve, 0);
        enc.copy_buffer_to_buffer(&self.resolve, 0, &self.read, 0, 16);
    }

    /// Requests the readback; call after the encoder holding `end` was submitted.
    pub fn after_submit(&self) {
        use std::sync::atomic::Ordering;
        if self.state.load(Ordering::Acquire) != 1 {
            return;
        }
        self.state.store(2, Ordering::Release);
        let state = std::sync::Arc::clone(&self.state);
        self.read
            .slice(..)
            .map_async(wgpu::MapMode::Read, move |r| {
                state.store(if r.is_ok() { 3 } else { 0 }, Ordering::Release);
            });
    }
}
