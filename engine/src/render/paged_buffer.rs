//! Same-sized GPU buffers ("pages") whose element ranges are leased through a [`Suballocator`]:
//! the buffer side of seed 002's merged buffers for a renderer whose items each need one range
//! in one buffer (a node's plant instances, an object's index list, its geomorph targets, a
//! node's merged far mesh). A page
//! is created when the allocator opens it; a range is given back when its [`Lease`] drops.

use super::suballoc::{Lease, Suballocator};

pub struct PagedBuffer {
    label: &'static str,
    usage: wgpu::BufferUsages,
    element_bytes: u64,
    pool: Suballocator,
    pages: Vec<wgpu::Buffer>,
}

impl PagedBuffer {
    /// Pages of `page_elements` elements of `element_bytes` bytes, at most `max_pages`;
    /// `usage` gets `COPY_DST` added.
    pub fn new(
        label: &'static str,
        usage: wgpu::BufferUsages,
        element_bytes: u64,
        page_elements: u32,
        max_pages: usize,
    ) -> Self {
        Self {
            label,
            usage: usage | wgpu::BufferUsages::COPY_DST,
            element_bytes,
            pool: Suballocator::new(&[page_elements], max_pages),
            pages: Vec::new(),
        }
    }

    /// A range of `len` elements (None when it is larger than a page or every page is full);
    /// its page exists on return.
    pub fn lease(&mut self, device: &wgpu::Device, len: u32) -> Option<Lease> {
        let lease = self.pool.lease(&[len])?;
        self.open_pages(device);
        Some(lease)
    }

    /// Creates the pages the allocator has opened (page 0 at least).
    pub fn open_pages(&mut self, device: &wgpu::Device) {
        while self.pages.len() < self.pool.pages().max(1) {
            let n = self.pages.len();
            self.pages
                .push(device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(&format!("{} page {n}", self.label)),
                    size: u64::from(self.pool.capacity(n, 0)) * self.element_bytes,
                    usage: self.usage,
                    mapped_at_creation: false,
                }));
        }
    }

    /// The buffers of the pages opened so far.
    pub fn pages(&self) -> &[wgpu::Buffer] {
        &self.pages
    }

    /// Writes `bytes` into the lease's page from `offset` elements past the lease's start.
    pub fn write(&self, queue: &wgpu::Queue, lease: &Lease, offset: u32, bytes: &[u8]) {
        if bytes.is_empty() {
            return;
        }
        let (page, at) = self.target(lease, offset, bytes.len());
        queue.write_buffer(page, at, bytes);
    }

    /// [`Self::write`] through staging belt `belt`, the copy recorded into `encoder`.
    pub fn write_staged(
        &self,
        belt: &mut wgpu::util::StagingBelt,
        encoder: &mut wgpu::CommandEncoder,
        lease: &Lease,
        offset: u32,
        bytes: &[u8],
    ) {
        let Some(size) = wgpu::BufferSize::new(bytes.len() as u64) else {
            return;
        };
        let (page, at) = self.target(lease, offset, bytes.len());
        belt.write_buffer(encoder, page, at, size)
            .slice(..)
            .copy_from_slice(bytes);
    }

    /// The page and byte offset of a write of `len` bytes `offset` elements past the lease's
    /// start.
    fn target(&self, lease: &Lease, offset: u32, len: usize) -> (&wgpu::Buffer, u64) {
        debug_assert!(
            len as u64 <= u64::from(lease.len[0] - offset.min(lease.len[0])) * self.element_bytes,
            "a write past its lease"
        );
        (
            &self.pages[lease.page as usize],
            u64::from(lease.start[0] + offset) * self.element_bytes,
        )
    }
}
