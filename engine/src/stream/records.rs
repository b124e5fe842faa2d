//! An append-only list whose growth never stalls the thread that appends: records live in
//! fixed chunks (growing never copies them), and the next chunk's memory is written once on the
//! list's helper thread before it is needed, so the appending thread never takes its page
//! faults.
//! With the heap on transparent huge pages (`apps::heap`) a first touch of a fresh 2 MiB page
//! costs the faulting thread milliseconds (the kernel zeroes, and may compact, a huge page):
//! the frame thread's copy of the known bounds took two such 6 - 7 ms stalls in a 300-frame
//! flight before this.

use std::sync::mpsc::{Receiver, SyncSender, TryRecvError, sync_channel};

/// Records per chunk (a power of two; the record's index splits into chunk and slot).
pub const CHUNK_RECORDS: usize = 4096;

/// A chunk: capacity [`CHUNK_RECORDS`], never reallocated.
type Chunk<T> = Vec<T>;

/// The list; `T: Copy` (records are plain data, written once by `fill` to fault pages in).
#[derive(Debug)]
pub struct Records<T: Copy + Send + 'static> {
    chunks: Vec<Chunk<T>>,
    /// The next chunk, made resident by the helper thread (which waits until it is taken,
    /// then makes another; it ends when the list is dropped). None without a helper (the
    /// system refused a thread): chunks are then made on the appending thread.
    spare: Option<Receiver<Chunk<T>>>,
    fill: T,
}

/// An empty chunk whose memory has been written (so it is resident).
fn resident_chunk<T: Copy>(fill: T) -> Chunk<T> {
    let mut c = Vec::with_capacity(CHUNK_RECORDS);
    c.resize(CHUNK_RECORDS, fill);
    c.clear();
    c
}

/// The helper thread: resident chunks, one at a time, each handed over when taken; returns
/// once the list is gone.
fn make_chunks<T: Copy>(send: &SyncSender<Chunk<T>>, fill: T) {
    while send.send(resident_chunk(fill)).is_ok() {}
}

impl<T: Copy + Send + 'static> Records<T> {
    /// An empty list and its helper thread; `fill` is the value chunks are written with
    /// before use (never read).
    pub fn new(fill: T) -> Self {
        let (send, spare) = sync_channel(0);
        let helper = std::thread::Builder::new()
            .name("records chunks".into())
            .spawn(move || make_chunks(&send, fill));
        Self {
            chunks: Vec::new(),
            spare: helper.is_ok().then_some(spare),
            fill,
        }
    }

    pub fn len(&self) -> usize {
        self.chunks
            .last()
            .map_or(0, |c| (self.chunks.len() - 1) * CHUNK_RECORDS + c.len())
    }

    /// Appends `record` at index `len()`. When the last chunk is full, the helper's spare
    /// becomes the next one (made here only when the helper is not done with it yet).
    pub fn push(&mut self, record: T) {
        if self.chunks.last().is_none_or(|c| c.len() == CHUNK_RECORDS) {
            let ready = match self.spare.as_ref().map(Receiver::try_recv) {
                Some(Ok(chunk)) => Some(chunk),
                Some(Err(TryRecvError::Empty)) => None,
                Some(Err(TryRecvError::Disconnected)) | None => {
                    self.spare = None;
                    None
                }
            };
            let chunk = ready.unwrap_or_else(|| resident_chunk(self.fill));
            self.chunks.push(chunk);
        }
        if let Some(c) = self.chunks.last_mut() {
            c.push(record);
        }
    }

    /// Record `i` (panics when `i >= len()`).
    pub fn get(&self, i: usize) -> &T {
        &self.chunks[i / CHUNK_RECORDS][i % CHUNK_RECORDS]
    }

    /// Record `i`, mutable (panics when `i >= len()`).
    pub fn get_mut(&mut self, i: usize) -> &mut T {
        &mut self.chunks[i / CHUNK_RECORDS][i % CHUNK_RECORDS]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Records keep their indices and values across many chunks, and a chunk is never moved
    /// once records are in it (its first record's address stays).
    #[test]
    fn records_keep_their_place_across_chunks() {
        let mut r = Records::new((0u64, 0u32));
        let mut first_addresses = Vec::new();
        let n = 3 * CHUNK_RECORDS + 17;
        for i in 0..n {
            r.push((i as u64 * 3, i as u32));
            if i % CHUNK_RECORDS == 0 {
                first_addresses.push(std::ptr::from_ref(r.get(i)));
            }
        }
        assert_eq!(r.len(), n);
        for i in 0..n {
            assert_eq!(*r.get(i), (i as u64 * 3, i as u32));
        }
        for (k, &a) in first_addresses.iter().enumerate() {
            assert_eq!(
                std::ptr::from_ref(r.get(k * CHUNK_RECORDS)),
                a,
                "chunk {k} moved"
            );
        }
        r.get_mut(5).1 = 99;
        assert_eq!(r.get(5).1, 99);
    }
}
