//! Offscreen targets: a colour + reversed-Z depth target with PNG readback (headless frames,
//! tests, screenshots).

use super::{DEPTH_FORMAT, Gpu, GpuError};
use std::path::Path;

/// An offscreen colour + depth target.
pub struct Target {
    pub size: [u32; 2],
    pub format: wgpu::TextureFormat,
    pub color: wgpu::Texture,
    /// The view the terrain draws through (sRGB).
    pub color_view: wgpu::TextureView,
    /// A view in the texture's own format (for overlays such as egui that want a linear one).
    pub plain_view: wgpu::TextureView,
    /// Reversed-Z depth (1 at the near plane, 0 at infinity), readable with
    /// [`Target::read_depth`].
    pub depth: wgpu::Texture,
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
        let depth = texture_2d(
            device,
            "offscreen depth",
            size,
            DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        );
        let depth_view = depth.create_view(&wgpu::TextureViewDescriptor::default());
        Self {
            size,
            format,
            color,
            color_view,
            plain_view,
            depth,
            depth_view,
        }
    }

    /// Copies the colour target to the CPU: RGBA8 rows, top row first.
    pub fn read_rgba(&self, gpu: &Gpu) -> Result<Vec<u8>, GpuError> {
        let mut out = read_texels(gpu, self.color.as_image_copy(), self.size)?;
        if matches!(
            self.format,
            wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb
        ) {
            for px in out.chunks_exact_mut(4) {
                px.swap(0, 2);
            }
        }
        Ok(out)
    }

    /// Copies the depth target to the CPU: one reversed-Z value per pixel (1 at the near plane,
    /// 0 where nothing was drawn), rows top first.
    pub fn read_depth(&self, gpu: &Gpu) -> Result<Vec<f32>, GpuError> {
        let bytes = read_texels(
            gpu,
            wgpu::TexelCopyTextureInfo {
                texture: &self.depth,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::DepthOnly,
            },
            self.size,
        )?;
        Ok(bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect())
    }
}

/// Copies `size` texels of a 4-byte-per-texel texture from `source` (a mip level and, through
/// its origin's z, an array layer) to the CPU: rows of `size[0] * 4` bytes, top row first.
pub fn read_texels(
    gpu: &Gpu,
    source: wgpu::TexelCopyTextureInfo<'_>,
    [w, h]: [u32; 2],
) -> Result<Vec<u8>, GpuError> {
    let row =
        (w * 4).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
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
        source,
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
    drop(data);
    buffer.unmap();
    Ok(out)
}

/// A reversed-Z depth view of `size`.
pub fn depth_view(device: &wgpu::Device, size: [u32; 2], label: &str) -> wgpu::TextureView {
    texture_view_2d(
        device,
        label,
        size,
        DEPTH_FORMAT,
        wgpu::TextureUsages::RENDER_ATTACHMENT,
    )
}

/// A view of a new single-mip 2D texture.
pub fn texture_view_2d(
    device: &wgpu::Device,
    label: &str,
    size: [u32; 2],
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::TextureView {
    texture_2d(device, label, size, format, usage)
        .create_view(&wgpu::TextureViewDescriptor::default())
}

/// A new single-mip 2D texture.
fn texture_2d(
    device: &wgpu::Device,
    label: &str,
    size: [u32; 2],
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: size[0],
            height: size[1],
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
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
