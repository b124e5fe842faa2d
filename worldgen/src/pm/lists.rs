//! Per-position lists of triangles for the collapse order, in one arena: a list is a run of
//! the arena with room to grow; a list that outgrows its run moves to the end with twice the
//! room. One allocation instead of one per position, and the lists of positions with nearby
//! indices lie next to each other in memory.

/// The lists, indexed by position.
#[derive(Debug, Clone, Default)]
pub(super) struct Lists {
    start: Vec<u32>,
    len: Vec<u32>,
    room: Vec<u32>,
    arena: Vec<u32>,
}

impl Lists {
    /// Empty lists with room for `sizes[p]` items (plus `spare`) at position p.
    pub(super) fn with_room(sizes: &[u32], spare: u32) -> Self {
        let mut start = Vec::with_capacity(sizes.len());
        let mut room = Vec::with_capacity(sizes.len());
        let mut at = 0u32;
        for &n in sizes {
            start.push(at);
            room.push(n + spare);
            at += n + spare;
        }
        Lists {
            start,
            len: vec![0; sizes.len()],
            room,
            arena: vec![0; at as usize],
        }
    }

    pub(super) fn get(&self, p: u32) -> &[u32] {
        let s = self.start[p as usize] as usize;
        &self.arena[s..s + self.len[p as usize] as usize]
    }

    pub(super) fn push(&mut self, p: u32, x: u32) {
        let i = p as usize;
        if self.len[i] == self.room[i] {
            let (old, n) = (self.start[i] as usize, self.len[i] as usize);
            let room = (2 * self.room[i]).max(4);
            let new = self.arena.len();
            self.arena.resize(new + room as usize, 0);
            self.arena.copy_within(old..old + n, new);
            self.start[i] = new as u32;
            self.room[i] = room;
        }
        self.arena[(self.start[i] + self.len[i]) as usize] = x;
        self.len[i] += 1;
    }

    /// Removes every `x` from p's list, keeping the order of the rest.
    pub(super) fn remove(&mut self, p: u32, x: u32) {
        let i = p as usize;
        let s = self.start[i] as usize;
        let n = self.len[i] as usize;
        let mut kept = 0;
        for k in 0..n {
            let y = self.arena[s + k];
            if y != x {
                self.arena[s + kept] = y;
                kept += 1;
            }
        }
        self.len[i] = kept as u32;
    }

    pub(super) fn clear(&mut self, p: u32) {
        self.len[p as usize] = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_grow_past_their_room_and_keep_order_like_vectors() {
        let sizes = [2u32, 0, 3, 1];
        let mut lists = Lists::with_room(&sizes, 1);
        let mut model: Vec<Vec<u32>> = vec![Vec::new(); sizes.len()];
        // A fixed pseudo-random sequence of pushes, removals and clears.
        let mut state = 12345u32;
        for step in 0..2000u32 {
            state = state.wrapping_mul(1_103_515_245).wrapping_add(12_345);
            let p = (state >> 16) % sizes.len() as u32;
            let x = (state >> 8) % 7;
            match step % 9 {
                0..=5 => {
                    lists.push(p, x);
                    model[p as usize].push(x);
                }
                6 | 7 => {
                    lists.remove(p, x);
                    model[p as usize].retain(|&y| y != x);
                }
                _ => {
                    lists.clear(p);
                    model[p as usize].clear();
                }
            }
            for (q, m) in model.iter().enumerate() {
                assert_eq!(lists.get(q as u32), m.as_slice(), "step {step}, list {q}");
            }
        }
    }
}
