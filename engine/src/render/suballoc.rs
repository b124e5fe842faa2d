//! Suballocation of a few large GPU resources (seed 002's merged per-node buffers): each page of
//! a pool holds one or more parts (a vertex and an index buffer, an instance buffer, the layers
//! of a texture array), and a node leases one range in every part of the same page, so one bind
//! or one multi-draw serves every node of the page. Plain data, no wgpu: the renderers own the
//! resources and create a page's resources when [`Suballocator::lease`] opens it.
//!
//! Ranges are found first fit, lowest address first (nodes stay packed at the front of the first
//! pages), and freed when the [`Lease`] drops, which happens when the streamer evicts the node
//! (its GPU objects drop with its payload).

use std::sync::{Arc, Mutex, PoisonError};

/// First-fit allocator of element ranges within `capacity` elements.
#[derive(Debug, Clone)]
pub struct RangeAllocator {
    /// Free ranges as (start, length), sorted by start, never adjacent (coalesced).
    free: Vec<(u32, u32)>,
}

impl RangeAllocator {
    pub fn new(capacity: u32) -> Self {
        Self {
            free: if capacity > 0 {
                vec![(0, capacity)]
            } else {
                Vec::new()
            },
        }
    }

    /// The start of a free range of `len` elements (lowest that fits), now taken.
    pub fn alloc(&mut self, len: u32) -> Option<u32> {
        if len == 0 {
            return Some(0);
        }
        let i = self.free.iter().position(|&(_, l)| l >= len)?;
        let (start, l) = self.free[i];
        if l == len {
            self.free.remove(i);
        } else {
            self.free[i] = (start + len, l - len);
        }
        Some(start)
    }

    /// Gives back `len` elements at `start` (taken by [`Self::alloc`]).
    pub fn free(&mut self, start: u32, len: u32) {
        if len == 0 {
            return;
        }
        let i = self.free.partition_point(|&(s, _)| s < start);
        let joins_prev = i > 0 && {
            let (s, l) = self.free[i - 1];
            s + l == start
        };
        let joins_next = i < self.free.len() && start + len == self.free[i].0;
        match (joins_prev, joins_next) {
            (true, true) => {
                let next_len = self.free[i].1;
                self.free[i - 1].1 += len + next_len;
                self.free.remove(i);
            }
            (true, false) => self.free[i - 1].1 += len,
            (false, true) => self.free[i] = (start, len + self.free[i].1),
            (false, false) => self.free.insert(i, (start, len)),
        }
    }

    /// Free elements in total.
    pub fn free_len(&self) -> u64 {
        self.free.iter().map(|&(_, l)| u64::from(l)).sum()
    }
}

/// Per page, one allocator per part.
type Pages = Arc<Mutex<Vec<Vec<RangeAllocator>>>>;

/// Pages of `parts.len()` parts, `capacity[p][k]` elements in part k of page p, opened in
/// order as needed.
#[derive(Debug, Clone)]
pub struct Suballocator {
    capacity: Vec<Vec<u32>>,
    pages: Pages,
}

/// Ranges in one page, one per part, given back when dropped.
#[derive(Debug)]
pub struct Lease {
    pub page: u32,
    /// First element in each part.
    pub start: Vec<u32>,
    /// Elements in each part.
    pub len: Vec<u32>,
    pages: Pages,
}

impl Drop for Lease {
    fn drop(&mut self) {
        let mut pages = self.pages.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(parts) = pages.get_mut(self.page as usize) {
            for ((a, &s), &l) in parts.iter_mut().zip(&self.start).zip(&self.len) {
                a.free(s, l);
            }
        }
    }
}

impl Suballocator {
    /// At most `max_pages` pages of `capacity` each.
    pub fn new(capacity: &[u32], max_pages: usize) -> Self {
        Self::with_pages(vec![capacity.to_vec(); max_pages])
    }

    /// Pages of the capacities `capacity` (per page, one entry per part), opened in that order.
    pub fn with_pages(capacity: Vec<Vec<u32>>) -> Self {
        Self {
            capacity,
            pages: Arc::default(),
        }
    }

    /// Ranges of `len[k]` elements in part k, all in the first page where they fit (a new page
    /// when none has room). None when a length exceeds a part's capacity in every page or all
    /// pages are full. `len` has one entry per part.
    pub fn lease(&self, len: &[u32]) -> Option<Lease> {
        let fits = |capacity: &Vec<u32>| {
            assert_eq!(len.len(), capacity.len(), "one length per part");
            len.iter().zip(capacity).all(|(l, c)| l <= c)
        };
        if !self.capacity.iter().any(fits) {
            return None;
        }
        let mut pages = self.pages.lock().unwrap_or_else(PoisonError::into_inner);
        let try_page = |parts: &mut Vec<RangeAllocator>| -> Option<Vec<u32>> {
            let mut start = Vec::with_capacity(len.len());
            for (a, &l) in parts.iter_mut().zip(len) {
                let Some(s) = a.alloc(l) else {
                    for (b, (&s, &l)) in parts.iter_mut().zip(start.iter().zip(len)) {
                        b.free(s, l);
                    }
                    return None;
                };
                start.push(s);
            }
            Some(start)
        };
        for (p, parts) in pages.iter_mut().enumerate() {
            if let Some(start) = try_page(parts) {
                return Some(self.make(p, start, len));
            }
        }
        // Pages too small for the request are opened on the way to one that fits.
        while let Some(capacity) = self.capacity.get(pages.len()) {
            let mut parts: Vec<RangeAllocator> =
                capacity.iter().map(|&c| RangeAllocator::new(c)).collect();
            let start = try_page(&mut parts);
            pages.push(parts);
            if let Some(start) = start {
                return Some(self.make(pages.len() - 1, start, len));
            }
        }
        None
    }

    fn make(&self, page: usize, start: Vec<u32>, len: &[u32]) -> Lease {
        Lease {
            page: page as u32,
            start,
            len: len.to_vec(),
            pages: Arc::clone(&self.pages),
        }
    }

    /// Pages opened so far (their resources must exist before a lease in them is used).
    pub fn pages(&self) -> usize {
        self.pages
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .len()
    }

    /// Elements in part k of page `page` (0 where there is no such page).
    pub fn capacity(&self, page: usize, part: usize) -> u32 {
        self.capacity.get(page).map_or(0, |c| c[part])
    }

    /// Elements in use in part k over all pages.
    pub fn used(&self, part: usize) -> u64 {
        let pages = self.pages.lock().unwrap_or_else(PoisonError::into_inner);
        pages
            .iter()
            .zip(&self.capacity)
            .map(|(p, c)| u64::from(c[part]) - p[part].free_len())
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_are_first_fit_and_coalesce_when_freed() {
        let mut a = RangeAllocator::new(100);
        let x = a.alloc(30).expect("fits");
        let y = a.alloc(30).expect("fits");
        let z = a.alloc(30).expect("fits");
        assert_eq!((x, y, z), (0, 30, 60));
        assert_eq!(a.alloc(20), None, "only 10 left");
        a.free(y, 30);
        assert_eq!(a.alloc(10), Some(30), "first fit: the hole");
        a.free(30, 10);
        a.free(x, 30);
        a.free(z, 30);
        assert_eq!(a.free_len(), 100);
        assert_eq!(a.alloc(100), Some(0), "all coalesced into one range");
    }

    #[test]
    fn leases_share_a_page_across_parts_and_open_pages_when_full() {
        let s = Suballocator::new(&[10, 40], 2);
        let a = s.lease(&[6, 10]).expect("page 0");
        let b = s.lease(&[6, 10]).expect("page 1: part 0 of page 0 is full");
        assert_eq!((a.page, b.page), (0, 1));
        assert_eq!((a.start.clone(), b.start.clone()), (vec![0, 0], vec![0, 0]));
        // Part 1 of page 0 had room but part 0 did not: nothing of page 0 may stay taken.
        assert_eq!(s.used(1), 20);
        assert!(s.lease(&[6, 1]).is_none(), "two pages at most");
        assert!(s.lease(&[11, 1]).is_none(), "larger than a page");
        drop(a);
        let c = s.lease(&[4, 40]).expect("page 0 is free again");
        assert_eq!(c.page, 0);
        assert_eq!(s.used(0), 10);
        drop((b, c));
        assert_eq!((s.used(0), s.used(1)), (0, 0));
    }

    #[test]
    fn pages_of_growing_capacity_open_in_order() {
        let s = Suballocator::with_pages(vec![vec![2], vec![4], vec![8]]);
        let a: Vec<Lease> = (0..2).map(|_| s.lease(&[1]).expect("page 0")).collect();
        assert!(a.iter().all(|l| l.page == 0));
        let b = s.lease(&[3]).expect("page 1");
        assert_eq!((b.page, s.pages()), (1, 2));
        // Only the last page holds 5: page 2 opens (page 1 has 1 left).
        let c = s.lease(&[5]).expect("page 2");
        assert_eq!((c.page, s.pages()), (2, 3));
        assert!(s.lease(&[9]).is_none(), "larger than every page");
        assert_eq!(s.used(0), 2 + 3 + 5);
        assert_eq!((s.capacity(1, 0), s.capacity(3, 0)), (4, 0));
    }

    #[test]
    fn a_request_only_a_later_page_holds_opens_the_pages_before_it() {
        let s = Suballocator::with_pages(vec![vec![2], vec![8]]);
        let a = s.lease(&[5]).expect("page 1");
        assert_eq!((a.page, s.pages()), (1, 2));
        let b = s.lease(&[2]).expect("page 0, opened on the way");
        assert_eq!(b.page, 0);
        assert!(s.lease(&[4]).is_none(), "page 1 has 3 left, page 0 none");
    }
}
