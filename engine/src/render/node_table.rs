//! A renderer's node table: one storage array (bind group 1) of [`NodeEntry`] (camera-relative
//! origin, dither interval, level) per resident node, `entries_per_slot` entries per node slot.
//! A node's GPU object leases its slot at upload and gives it back when dropped; each frame the
//! renderer sets the entries of the nodes it draws and flushes them. Shaders find their entry by
//! the draw's instance index (terrain: `first_instance` = slot) or by the instance's `entry`
//! attribute (vegetation), so the per-node data needs no per-draw binding and draws of many
//! nodes merge.

use super::frame::FrameResources;
use super::gpu_data::NodeEntry;
use super::light_pool::LightEntry;
use super::suballoc::{Lease, Suballocator};

/// Node slots a table holds (resident nodes of one renderer; 4 MiB of entries at 2 per slot).
pub const TABLE_SLOTS: u32 = 1 << 15;

pub struct NodeTable {
    slots: Suballocator,
    entries_per_slot: u32,
    entries: Vec<NodeEntry>,
    /// Entries up to here were set this frame (written by [`Self::flush`]).
    written: usize,
    buffer: wgpu::Buffer,
    /// Bind group 1 of the renderer's pipelines.
    pub group: wgpu::BindGroup,
}

impl std::fmt::Debug for NodeTable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "NodeTable({} slots used)", self.slots.used(0))
    }
}

impl NodeTable {
    pub fn new(
        device: &wgpu::Device,
        frame: &FrameResources,
        label: &str,
        entries_per_slot: u32,
    ) -> Self {
        let entries = (TABLE_SLOTS * entries_per_slot) as usize;
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: (entries * std::mem::size_of::<NodeEntry>()) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout: &frame.node_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: buffer.as_entire_binding(),
            }],
        });
        Self {
            slots: Suballocator::new(&[TABLE_SLOTS], 1),
            entries_per_slot,
            entries: vec![NodeEntry::default(); entries],
            written: 0,
            buffer,
            group,
        }
    }

    /// A slot for a newly uploaded node (None when all [`TABLE_SLOTS`] are taken).
    pub fn lease(&self) -> Option<Lease> {
        self.slots.lease(&[1])
    }

    /// The first entry of a leased slot.
    pub fn first_entry(&self, slot: &Lease) -> u32 {
        slot.start[0] * self.entries_per_slot
    }

    /// Sets entry `index` for this frame: the node at `origin_m` (south-west corner) drawn at
    /// `level` with dither interval `dither`, four numbers only its renderer reads (`extra`;
    /// terrain: the ground-texture layer it shows, texture coordinates per metre and its corner
    /// in that texture's node, m) and its light grid (`light`: `lighting::light_entry`).
    #[allow(clippy::too_many_arguments, reason = "one entry's fields")]
    pub fn set(
        &mut self,
        frame: &FrameResources,
        index: u32,
        origin_m: [f64; 2],
        level: u8,
        dither: [f32; 2],
        extra: [f32; 4],
        light: LightEntry,
    ) {
        let [x, y, z] = frame.offset_m(origin_m);
        let i = index as usize;
        self.entries[i] = NodeEntry {
            offset_lo: [x, y, z, dither[0]],
            hi_level: [dither[1], f32::from(level), extra[0], extra[1]],
            light: light.grid,
            more: [extra[2], extra[3], light.seam[0], light.seam[1]],
        };
        self.written = self.written.max(i + 1);
    }

    /// Writes the entries set this frame (slots are leased lowest first, so this is about the
    /// resident nodes' entries) and starts the next frame.
    pub fn flush(&mut self, queue: &wgpu::Queue) {
        if self.written > 0 {
            queue.write_buffer(
                &self.buffer,
                0,
                bytemuck::cast_slice(&self.entries[..self.written]),
            );
        }
        self.written = 0;
    }
}
