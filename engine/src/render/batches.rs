//! A frame's draws of one renderer, merged: each item (one node mesh, one node's instance group)
//! is an indirect-draw record under a batch key (the render state and the pool page it reads);
//! [`Batches::upload`] sorts them by key (stably: items of a key keep their order) into one
//! indirect buffer, and each run of equal keys is recorded as one `multi_draw_*_indirect` call,
//! or, on adapters without it (or with `ViewOptions::merged_draws` off), as a plain loop of the
//! same draws. Both paths draw the same items in the same order.

use super::Gpu;
use wgpu::util::{DrawIndexedIndirectArgs, DrawIndirectArgs};

/// One draw item.
#[derive(Debug, Clone, Copy)]
pub enum Item {
    Indexed(DrawIndexedIndirectArgs),
    Plain(DrawIndirectArgs),
}

/// Consecutive items of one key and one kind (indexed or not), at `first` in their array.
#[derive(Debug, Clone, Copy)]
pub struct Run<K> {
    pub key: K,
    indexed: bool,
    first: u32,
    count: u32,
}

impl<K> Run<K> {
    /// Items in the run.
    pub fn items(&self) -> u32 {
        self.count
    }
}

#[derive(Debug)]
pub struct Batches<K> {
    items: Vec<(K, Item)>,
    indexed: Vec<DrawIndexedIndirectArgs>,
    plain: Vec<DrawIndirectArgs>,
    runs: Vec<Run<K>>,
    /// The records as bytes (kept between frames to reuse its allocation).
    staging: Vec<u8>,
    buffer: Option<wgpu::Buffer>,
    /// Bytes before the plain records in `buffer`.
    plain_offset: u64,
}

impl<K: Ord + Copy> Default for Batches<K> {
    fn default() -> Self {
        Self::new()
    }
}

const INDEXED_BYTES: u64 = 20;
const PLAIN_BYTES: u64 = 16;

impl<K: Ord + Copy> Batches<K> {
    pub fn new() -> Self {
        Self {
            items: Vec::new(),
            indexed: Vec::new(),
            plain: Vec::new(),
            runs: Vec::new(),
            staging: Vec::new(),
            buffer: None,
            plain_offset: 0,
        }
    }

    /// Starts a frame.
    pub fn clear(&mut self) {
        self.items.clear();
        self.indexed.clear();
        self.plain.clear();
        self.runs.clear();
    }

    pub fn push(&mut self, key: K, item: Item) {
        self.items.push((key, item));
    }

    /// Sorts the items into runs and writes the indirect buffer (grown when needed).
    pub fn upload(&mut self, gpu: &Gpu) {
        self.items.sort_by_key(|&(k, _)| k);
        for &(key, item) in &self.items {
            let (indexed, first) = match item {
                Item::Indexed(a) => {
                    self.indexed.push(a);
                    (true, self.indexed.len() as u32 - 1)
                }
                Item::Plain(a) => {
                    self.plain.push(a);
                    (false, self.plain.len() as u32 - 1)
                }
            };
            match self.runs.last_mut() {
                Some(r) if r.key == key && r.indexed == indexed => r.count += 1,
                _ => self.runs.push(Run {
                    key,
                    indexed,
                    first,
                    count: 1,
                }),
            }
        }
        self.plain_offset = self.indexed.len() as u64 * INDEXED_BYTES;
        let bytes = self.plain_offset + self.plain.len() as u64 * PLAIN_BYTES;
        if bytes == 0 {
            return;
        }
        if self.buffer.as_ref().is_none_or(|b| b.size() < bytes) {
            self.buffer = Some(gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("indirect draws"),
                size: bytes.next_power_of_two(),
                usage: wgpu::BufferUsages::INDIRECT | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }));
        }
        let Some(buffer) = &self.buffer else { return };
        self.staging.clear();
        for a in &self.indexed {
            self.staging.extend_from_slice(a.as_bytes());
        }
        for a in &self.plain {
            self.staging.extend_from_slice(a.as_bytes());
        }
        gpu.queue.write_buffer(buffer, 0, &self.staging);
    }

    /// This frame's items, in key order once uploaded.
    pub fn items(&self) -> &[(K, Item)] {
        &self.items
    }

    /// This frame's runs, in key order.
    pub fn runs(&self) -> &[Run<K>] {
        &self.runs
    }

    /// Records one run (its render state already set): one multi-draw call when `merged`,
    /// else one draw call per item. Returns the draw calls recorded.
    pub fn record(&self, pass: &mut wgpu::RenderPass<'_>, run: &Run<K>, merged: bool) -> u32 {
        let range = run.first as usize..(run.first + run.count) as usize;
        if merged && let Some(buffer) = &self.buffer {
            if run.indexed {
                let offset = u64::from(run.first) * INDEXED_BYTES;
                pass.multi_draw_indexed_indirect(buffer, offset, run.count);
            } else {
                let offset = self.plain_offset + u64::from(run.first) * PLAIN_BYTES;
                pass.multi_draw_indirect(buffer, offset, run.count);
            }
            return 1;
        }
        if run.indexed {
            for a in &self.indexed[range] {
                pass.draw_indexed(
                    a.first_index..a.first_index + a.index_count,
                    a.base_vertex,
                    a.first_instance..a.first_instance + a.instance_count,
                );
            }
        } else {
            for a in &self.plain[range] {
                pass.draw(
                    a.first_vertex..a.first_vertex + a.vertex_count,
                    a.first_instance..a.first_instance + a.instance_count,
                );
            }
        }
        run.count
    }
}
