//! A renderer's node table (bind group 1): this frame's rows of [`NodeEntry`] (camera-relative
//! origin, dither interval, level, light), one per entry the renderer sets, in the order set,
//! so a frame writes as many rows as it draws nodes, not one per resident node.
//!
//! Two ways to find a row:
//! - **by draw** ([`NodeTable::by_draw`], terrain): [`NodeTable::push`] returns the row, which
//!   the draw passes as its `first_instance`; the shader reads `nodes[instance_index]`.
//! - **by slot** ([`NodeTable::by_slot`], vegetation): a node's GPU object leases a slot of
//!   `entries_per_slot` entries at upload (given back when dropped); its instances carry their
//!   entry, fixed at upload. [`NodeTable::set`] gives an entry this frame's row, and the table
//!   also writes each entry's row (`row_of_entry`, 4 bytes an entry, up to the highest entry
//!   set); the shader reads `nodes[row_of_entry[entry]]`.
//!
//! Either way the per-node data needs no per-draw binding, and draws of many nodes merge.

use super::frame::FrameResources;
use super::gpu_data::NodeEntry;
use super::light_pool::LightEntry;
use super::suballoc::{Lease, Suballocator};

/// Node slots a by-slot table holds (resident nodes of one renderer), and the rows a table
/// holds per entry per slot (2 MiB of rows at one entry per slot).
pub const TABLE_SLOTS: u32 = 1 << 15;

pub struct NodeTable {
    /// By slot: the node slots (none for a by-draw table).
    slots: Option<Suballocator>,
    entries_per_slot: u32,
    /// This frame's rows, in the order set (at most `row_capacity`, the buffer's).
    rows: Vec<NodeEntry>,
    row_capacity: usize,
    /// By slot: the entry each row is for (so an entry set twice in a frame keeps one row).
    entry_of_row: Vec<u32>,
    /// By slot: each entry's row this frame (valid where `entry_of_row` points back).
    row_of_entry: Vec<u32>,
    /// By slot: entries up to here were set this frame.
    entries_set: usize,
    buffer: wgpu::Buffer,
    /// `row_of_entry` on the GPU (4 bytes, unread, for a by-draw table).
    rows_of_entries: wgpu::Buffer,
    /// Bind group 1 of the renderer's pipelines.
    pub group: wgpu::BindGroup,
}

impl std::fmt::Debug for NodeTable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.slots {
            Some(s) => write!(f, "NodeTable({} slots used)", s.used(0)),
            None => write!(f, "NodeTable(by draw)"),
        }
    }
}

impl NodeTable {
    /// A table whose rows are found by draw ([`Self::push`]).
    pub fn by_draw(device: &wgpu::Device, frame: &FrameResources, label: &str) -> Self {
        Self::new(device, frame, label, 1, false)
    }

    /// A table whose rows are found by the entries of leased slots ([`Self::lease`],
    /// [`Self::set`]), `entries_per_slot` per slot.
    pub fn by_slot(
        device: &wgpu::Device,
        frame: &FrameResources,
        label: &str,
        entries_per_slot: u32,
    ) -> Self {
        Self::new(device, frame, label, entries_per_slot, true)
    }

    fn new(
        device: &wgpu::Device,
        frame: &FrameResources,
        label: &str,
        entries_per_slot: u32,
        by_slot: bool,
    ) -> Self {
        let rows = (TABLE_SLOTS * entries_per_slot) as usize;
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: (rows * std::mem::size_of::<NodeEntry>()) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let entries = if by_slot { rows } else { 1 };
        let rows_of_entries = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: (entries * 4) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout: &frame.node_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: buffer.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: rows_of_entries.as_entire_binding(),
                },
            ],
        });
        let by_slot_len = if by_slot { rows } else { 0 };
        Self {
            slots: by_slot.then(|| Suballocator::new(&[TABLE_SLOTS], 1)),
            entries_per_slot,
            rows: Vec::with_capacity(rows),
            row_capacity: rows,
            entry_of_row: Vec::with_capacity(by_slot_len),
            row_of_entry: vec![0; by_slot_len],
            entries_set: 0,
            buffer,
            rows_of_entries,
            group,
        }
    }

    /// By slot: a slot for a newly uploaded node (None when all [`TABLE_SLOTS`] are taken, and
    /// always for a by-draw table).
    pub fn lease(&self) -> Option<Lease> {
        self.slots.as_ref()?.lease(&[1])
    }

    /// The first entry of a leased slot.
    pub fn first_entry(&self, slot: &Lease) -> u32 {
        slot.start[0] * self.entries_per_slot
    }

    /// The row of the node at `origin_m` (south-west corner) drawn at `level` with dither
    /// interval `dither`, four numbers only its renderer reads (`extra`; terrain: the
    /// ground-texture layer it shows, texture coordinates per metre and its corner in that
    /// texture's node, m) and its light grid (`light`: `lighting::light_entry`), for
    /// [`Self::push`] or [`Self::set`].
    pub fn row(
        frame: &FrameResources,
        origin_m: [f64; 2],
        level: u8,
        dither: [f32; 2],
        extra: [f32; 4],
        light: LightEntry,
    ) -> NodeEntry {
        let [x, y, z] = frame.offset_m(origin_m);
        NodeEntry {
            offset_lo: [x, y, z, dither[0]],
            hi_level: [dither[1], f32::from(level), extra[0], extra[1]],
            light: light.grid,
            more: [extra[2], extra[3], light.seam[0], light.seam[1]],
        }
    }

    /// By draw: appends `row` as this frame's next row; returns its index, the draw's
    /// `first_instance`, or None when the table is full.
    pub fn push(&mut self, row: NodeEntry) -> Option<u32> {
        if self.rows.len() >= self.row_capacity {
            return None;
        }
        let index = u32::try_from(self.rows.len()).ok()?;
        self.rows.push(row);
        Some(index)
    }

    /// By slot: gives entry `entry` (of a leased slot) `row` for this frame; set again in the
    /// same frame, it keeps its row with the new fields.
    pub fn set(&mut self, entry: u32, row: NodeEntry) {
        let e = entry as usize;
        let at = self.row_of_entry[e] as usize;
        if self.entry_of_row.get(at) == Some(&entry) {
            self.rows[at] = row;
            return;
        }
        // At most one row per entry, so the rows never outgrow their buffer.
        self.row_of_entry[e] = self.rows.len() as u32;
        self.rows.push(row);
        self.entry_of_row.push(entry);
        self.entries_set = self.entries_set.max(e + 1);
    }

    /// Writes this frame's rows (and, by slot, the rows of the entries up to the highest set)
    /// and starts the next frame.
    pub fn flush(&mut self, queue: &wgpu::Queue) {
        if !self.rows.is_empty() {
            queue.write_buffer(&self.buffer, 0, bytemuck::cast_slice(&self.rows));
        }
        if self.entries_set > 0 {
            queue.write_buffer(
                &self.rows_of_entries,
                0,
                bytemuck::cast_slice(&self.row_of_entry[..self.entries_set]),
            );
        }
        self.rows.clear();
        self.entry_of_row.clear();
        self.entries_set = 0;
    }
}
