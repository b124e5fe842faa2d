//! GPU time of a span of commands from timestamp queries, without stalling.

use super::Gpu;

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
