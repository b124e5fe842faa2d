//! Texture slots of power-of-two sizes under a memory budget (seed 000's texture cache).
//!
//! Textures are square with power-of-two edges and full mip chains. A **slot** of edge `2^e`
//! holds one texture at the level whose edge is `2^e`, with all its coarser levels (so the GPU
//! can still filter); its bytes are `bytes_per_texel x (4^0 + ... + 4^e)`. Slots are made when
//! needed and kept when freed (a free slot is reused by the next texture of its size); every
//! slot alive, free or not, counts against the budget.
//!
//! Each frame the drawn textures are [`TexturePool::request`]ed with the level they need
//! ([`super::mip`]) and an importance (their on-screen area; a texture on several objects sums
//! them). [`TexturePool::end_frame`] then decides:
//!
//! 1. **Targets.** Every requested texture at its needed level. While the targets' slots would
//!    not fit the budget, the texture with the smallest `importance x 2^(levels already lost)`
//!    loses one level (a quarter of its bytes): the least visible lose resolution first, and a
//!    texture that has lost levels is weighted up before it loses another. When every target is
//!    at its coarsest level and the budget is still short, the least important get no slot
//!    (they are misses, drawn with their fallback colour).
//! 2. **Changes**, in order: textures going coarser (they free memory), then missing textures,
//!    then textures going finer, each group most important first, until the per-frame upload
//!    budget is spent (at least one upload a frame, so a large texture is never starved). A
//!    change first gives up the texture's old slot, then takes a free slot of the target size,
//!    else makes room by destroying free slots of other sizes and evicting the least recently
//!    used textures not drawn this frame; a change that cannot find room waits.
//!
//! The result is a [`Plan`]: slot destructions, creations and uploads, in the order the GPU side
//! applies them; the memory alive never exceeds the budget between any two of them.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// Largest texture edge accepted, as a power of two (32,768 texels).
pub const MAX_EDGE_LOG2: u32 = 15;

/// A texture registered with the pool.
pub type TextureId = u32;

/// A slot: its size (edge `2^edge_log2` texels) and its index among the slots of that size.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct SlotId {
    pub edge_log2: u32,
    pub index: u32,
}

/// How the pool is sized.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoolSettings {
    /// Bytes of all slots alive, at most.
    pub budget_bytes: u64,
    /// Bytes uploaded a frame, at most (one upload a frame is always allowed).
    pub upload_bytes_per_frame: u64,
    /// Smallest slot edge, as a power of two: a texture's coarsest cached level has this edge.
    pub min_edge_log2: u32,
    pub bytes_per_texel: u32,
}

impl Default for PoolSettings {
    fn default() -> Self {
        PoolSettings {
            budget_bytes: 64 << 20,
            upload_bytes_per_frame: 4 << 20,
            min_edge_log2: 4,
            bytes_per_texel: 4,
        }
    }
}

/// Bytes of a slot of edge `2^edge_log2` with all its coarser levels.
pub fn slot_bytes(edge_log2: u32, bytes_per_texel: u32) -> u64 {
    let texels: u64 = (0..=edge_log2).map(|e| 1u64 << (2 * e)).sum();
    texels * u64::from(bytes_per_texel)
}

/// Why a texture was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PoolError {
    #[error("texture edge 2^{edge_log2} is outside 2^{min}..=2^{max} texels")]
    EdgeOutOfRange { edge_log2: u32, min: u32, max: u32 },
}

/// One step for the GPU side.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Op {
    /// Release the slot's memory.
    Destroy(SlotId),
    /// Allocate an empty slot.
    Create(SlotId),
    /// Write `texture`'s level `level` and all coarser ones into `slot` (its edge is the
    /// level's edge).
    Upload {
        texture: TextureId,
        level: u32,
        slot: SlotId,
    },
}

/// What one frame changes on the GPU.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Plan {
    pub ops: Vec<Op>,
}

/// Statistics of the last frame.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PoolStats {
    /// Textures requested this frame.
    pub drawn: usize,
    /// Bytes of slots holding a texture.
    pub resident_bytes: u64,
    /// Bytes of all slots alive (holding a texture or free).
    pub allocated_bytes: u64,
    /// Bytes if every drawn texture were resident at full resolution.
    pub full_resolution_bytes: u64,
    /// Bytes of the drawn textures at the levels they need.
    pub needed_bytes: u64,
    /// Drawn textures with no level resident after this frame's plan (drawn in their fallback
    /// colour).
    pub misses: usize,
    /// Drawn textures resident at a coarser level than they need (budget or uploads pending).
    pub coarser_than_needed: usize,
    pub uploads: usize,
    pub upload_bytes: u64,
    /// Textures that lost their slot to make room (least recently used first, drawn ones only
    /// after a budget cut).
    pub evictions: usize,
}

#[derive(Debug, Clone, Copy)]
struct Resident {
    slot: SlotId,
    level: u32,
}

#[derive(Debug, Clone)]
struct Texture {
    edge_log2: u32,
    resident: Option<Resident>,
    last_used_frame: u64,
    /// This frame's request: the finest level asked for and the summed importance.
    want: Option<(u32, f64)>,
}

/// A min-heap entry of the budget fit: `key` = importance x 2^(levels lost).
#[derive(Debug, PartialEq)]
struct Loss {
    key: f64,
    /// Position in the frame's request list.
    i: usize,
}

impl Eq for Loss {}

impl Ord for Loss {
    fn cmp(&self, other: &Self) -> Ordering {
        // Reversed: BinaryHeap is a max-heap.
        other.key.total_cmp(&self.key).then(other.i.cmp(&self.i))
    }
}

impl PartialOrd for Loss {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// The slots of one size.
#[derive(Debug, Clone, Default)]
struct SizeClass {
    /// Free slots alive.
    free: Vec<u32>,
    /// Indexes of destroyed slots, reused before new ones.
    dead: Vec<u32>,
    next_index: u32,
}

/// The texture cache's bookkeeping.
#[derive(Debug, Clone)]
pub struct TexturePool {
    settings: PoolSettings,
    textures: Vec<Texture>,
    classes: Vec<SizeClass>,
    requested: Vec<TextureId>,
    allocated_bytes: u64,
    resident_bytes: u64,
    frame: u64,
    stats: PoolStats,
}

impl TexturePool {
    pub fn new(settings: PoolSettings) -> Self {
        TexturePool {
            settings,
            textures: Vec::new(),
            classes: vec![SizeClass::default(); MAX_EDGE_LOG2 as usize + 1],
            requested: Vec::new(),
            allocated_bytes: 0,
            resident_bytes: 0,
            frame: 0,
            stats: PoolStats::default(),
        }
    }

    pub fn settings(&self) -> &PoolSettings {
        &self.settings
    }

    /// Registers a texture of edge `2^edge_log2` texels.
    pub fn add_texture(&mut self, edge_log2: u32) -> Result<TextureId, PoolError> {
        let min = self.settings.min_edge_log2;
        if !(min..=MAX_EDGE_LOG2).contains(&edge_log2) {
            return Err(PoolError::EdgeOutOfRange {
                edge_log2,
                min,
                max: MAX_EDGE_LOG2,
            });
        }
        self.textures.push(Texture {
            edge_log2,
            resident: None,
            last_used_frame: 0,
            want: None,
        });
        Ok((self.textures.len() - 1) as TextureId)
    }

    pub fn texture_count(&self) -> usize {
        self.textures.len()
    }

    /// The coarsest level the pool keeps of a texture (its edge is the smallest slot edge).
    pub fn coarsest_level(&self, texture: TextureId) -> u32 {
        self.textures[texture as usize].edge_log2 - self.settings.min_edge_log2
    }

    /// Bytes of a slot of edge `2^edge_log2` under these settings.
    pub fn slot_bytes(&self, edge_log2: u32) -> u64 {
        slot_bytes(edge_log2, self.settings.bytes_per_texel)
    }

    /// Changes the per-frame upload budget (bytes; one upload a frame is always allowed).
    pub fn set_upload_budget(&mut self, bytes: u64) {
        self.settings.upload_bytes_per_frame = bytes;
    }

    /// Changes the budget; the next [`Self::end_frame`] gets under it.
    pub fn set_budget(&mut self, budget_bytes: u64) {
        self.settings.budget_bytes = budget_bytes;
    }

    /// Asks for `texture` at `level` (clamped to its coarsest) this frame, with `importance`
    /// (on-screen area in pixels, say; summed over a frame's requests).
    pub fn request(&mut self, texture: TextureId, level: u32, importance: f64) {
        let coarsest = self.coarsest_level(texture);
        let t = &mut self.textures[texture as usize];
        let level = level.min(coarsest);
        let importance = importance.max(0.0);
        t.want = Some(match t.want {
            None => {
                self.requested.push(texture);
                (level, importance)
            }
            Some((l, i)) => (l.min(level), i + importance),
        });
    }

    /// The slot and level a texture is resident at.
    pub fn resident(&self, texture: TextureId) -> Option<(SlotId, u32)> {
        self.textures[texture as usize]
            .resident
            .map(|r| (r.slot, r.level))
    }

    /// Free slots alive, by size.
    pub fn free_slots(&self) -> Vec<SlotId> {
        let mut out = Vec::new();
        for (e, c) in self.classes.iter().enumerate() {
            out.extend(c.free.iter().map(|&index| SlotId {
                edge_log2: e as u32,
                index,
            }));
        }
        out
    }

    pub fn allocated_bytes(&self) -> u64 {
        self.allocated_bytes
    }

    pub fn stats(&self) -> &PoolStats {
        &self.stats
    }

    /// Decides this frame's residency (module docs) and clears the requests.
    pub fn end_frame(&mut self) -> Plan {
        self.frame += 1;
        let requested = std::mem::take(&mut self.requested);
        let targets = self.fit_targets(&requested);
        let mut plan = Plan::default();
        let mut stats = PoolStats {
            drawn: requested.len(),
            ..PoolStats::default()
        };
        for &id in &requested {
            let t = &mut self.textures[id as usize];
            t.last_used_frame = self.frame;
            stats.full_resolution_bytes += slot_bytes(t.edge_log2, self.settings.bytes_per_texel);
            let need = t.want.map_or(0, |w| w.0);
            stats.needed_bytes += slot_bytes(t.edge_log2 - need, self.settings.bytes_per_texel);
        }
        // Changes: coarser first, then missing, then finer; most important first in each.
        let mut changes: Vec<(u8, f64, TextureId, u32)> = Vec::new();
        for (&id, &target) in requested.iter().zip(&targets) {
            let t = &self.textures[id as usize];
            let Some(level) = target else { continue };
            let group = match t.resident {
                Some(r) if r.level == level => continue,
                Some(r) if r.level < level => 0,
                None => 1,
                Some(_) => 2,
            };
            changes.push((group, t.want.map_or(0.0, |w| w.1), id, level));
        }
        changes.sort_by(|a, b| a.0.cmp(&b.0).then(b.1.total_cmp(&a.1)).then(a.2.cmp(&b.2)));
        let mut evictable = self.evictable(&requested, &targets);
        let mut upload_left = self.settings.upload_bytes_per_frame;
        for &(_, _, id, level) in &changes {
            let edge = self.textures[id as usize].edge_log2 - level;
            let bytes = self.slot_bytes(edge);
            if stats.uploads > 0 && bytes > upload_left {
                continue;
            }
            if !self.change(id, level, &mut evictable, &mut plan, &mut stats) {
                continue;
            }
            stats.uploads += 1;
            stats.upload_bytes += bytes;
            upload_left = upload_left.saturating_sub(bytes);
        }
        self.enforce_budget(&requested, &mut evictable, &mut plan, &mut stats);
        for &id in &requested {
            let t = &mut self.textures[id as usize];
            let need = t.want.take().map_or(0, |w| w.0);
            match t.resident {
                None => stats.misses += 1,
                Some(r) if r.level > need => stats.coarser_than_needed += 1,
                Some(_) => {}
            }
        }
        stats.resident_bytes = self.resident_bytes;
        stats.allocated_bytes = self.allocated_bytes;
        self.stats = stats;
        plan
    }

    /// Step 1: the level each requested texture gets (`None`: no slot this frame).
    fn fit_targets(&self, requested: &[TextureId]) -> Vec<Option<u32>> {
        let bpt = self.settings.bytes_per_texel;
        let mut targets: Vec<Option<u32>> = requested
            .iter()
            .map(|&id| self.textures[id as usize].want.map(|w| w.0))
            .collect();
        let mut total: u64 = requested
            .iter()
            .zip(&targets)
            .map(|(&id, t)| slot_bytes(self.textures[id as usize].edge_log2 - t.unwrap_or(0), bpt))
            .sum();
        let budget = self.settings.budget_bytes;
        if total <= budget {
            return targets;
        }
        let mut heap: BinaryHeap<Loss> = requested
            .iter()
            .enumerate()
            .map(|(i, &id)| Loss {
                key: self.textures[id as usize].want.map_or(0.0, |w| w.1),
                i,
            })
            .collect();
        let mut at_coarsest = Vec::new();
        while total > budget {
            let Some(loss) = heap.pop() else { break };
            let id = requested[loss.i];
            let level = targets[loss.i].unwrap_or(0);
            if level >= self.coarsest_level(id) {
                at_coarsest.push(loss);
                continue;
            }
            let edge = self.textures[id as usize].edge_log2 - level;
            total -= slot_bytes(edge, bpt) - slot_bytes(edge - 1, bpt);
            targets[loss.i] = Some(level + 1);
            heap.push(Loss {
                key: loss.key * 2.0,
                i: loss.i,
            });
        }
        // Everything at its coarsest and still over: the least important go without
        // (`at_coarsest` was filled least important first).
        for loss in at_coarsest {
            if total <= budget {
                break;
            }
            let edge =
                self.textures[requested[loss.i] as usize].edge_log2 - targets[loss.i].unwrap_or(0);
            total -= slot_bytes(edge, bpt);
            targets[loss.i] = None;
        }
        targets
    }

    /// Resident textures whose slots may be taken: not drawn this frame (least recently used
    /// first), then drawn ones that got no target; reversed, so `pop` gives the next victim.
    fn evictable(&self, requested: &[TextureId], targets: &[Option<u32>]) -> Vec<TextureId> {
        let mut not_drawn: Vec<TextureId> = (0..self.textures.len() as TextureId)
            .filter(|&id| {
                let t = &self.textures[id as usize];
                t.resident.is_some() && t.want.is_none()
            })
            .collect();
        not_drawn.sort_by_key(|&id| (self.textures[id as usize].last_used_frame, id));
        let dropped = requested
            .iter()
            .zip(targets)
            .filter(|(id, t)| t.is_none() && self.textures[**id as usize].resident.is_some())
            .map(|(&id, _)| id);
        let mut order: Vec<TextureId> = not_drawn.into_iter().chain(dropped).collect();
        order.reverse();
        order
    }

    /// Moves `id` to `level` in a slot of that size; false (nothing changed) when no room.
    fn change(
        &mut self,
        id: TextureId,
        level: u32,
        evictable: &mut Vec<TextureId>,
        plan: &mut Plan,
        stats: &mut PoolStats,
    ) -> bool {
        let edge = self.textures[id as usize].edge_log2 - level;
        let bytes = self.slot_bytes(edge);
        let own = self.textures[id as usize]
            .resident
            .map_or(0, |r| self.slot_bytes(r.slot.edge_log2));
        let reclaimable: u64 = self.free_bytes()
            + evictable
                .iter()
                .filter_map(|&v| self.textures[v as usize].resident)
                .map(|r| self.slot_bytes(r.slot.edge_log2))
                .sum::<u64>();
        let headroom = self
            .settings
            .budget_bytes
            .saturating_sub(self.allocated_bytes);
        if self.classes[edge as usize].free.is_empty() && bytes > headroom + reclaimable + own {
            return false;
        }
        self.release(id);
        let slot = match self.classes[edge as usize].free.pop() {
            Some(index) => SlotId {
                edge_log2: edge,
                index,
            },
            None => self.make_slot(edge, evictable, plan, stats),
        };
        self.resident_bytes += bytes;
        self.textures[id as usize].resident = Some(Resident { slot, level });
        plan.ops.push(Op::Upload {
            texture: id,
            level,
            slot,
        });
        true
    }

    /// A slot of edge `2^edge` taken out of the free lists or made, making room first (the
    /// caller checked that room can be made).
    fn make_slot(
        &mut self,
        edge: u32,
        evictable: &mut Vec<TextureId>,
        plan: &mut Plan,
        stats: &mut PoolStats,
    ) -> SlotId {
        let bytes = self.slot_bytes(edge);
        while self.allocated_bytes + bytes > self.settings.budget_bytes {
            if let Some(slot) = self.largest_free() {
                self.destroy(slot, plan);
                continue;
            }
            let Some(victim) = evictable.pop() else { break };
            if self.textures[victim as usize].resident.is_none() {
                continue;
            }
            stats.evictions += 1;
            // A victim of the wanted size hands its slot over (taken back off the free list).
            if let Some(slot) = self.release(victim)
                && slot.edge_log2 == edge
            {
                self.classes[edge as usize].free.pop();
                return slot;
            }
        }
        let class = &mut self.classes[edge as usize];
        let index = class.dead.pop().unwrap_or_else(|| {
            class.next_index += 1;
            class.next_index - 1
        });
        let slot = SlotId {
            edge_log2: edge,
            index,
        };
        self.allocated_bytes += bytes;
        plan.ops.push(Op::Create(slot));
        slot
    }

    /// Gets allocated memory under the budget after a budget change: free slots first, then
    /// textures not drawn, then the least important drawn ones.
    fn enforce_budget(
        &mut self,
        requested: &[TextureId],
        evictable: &mut Vec<TextureId>,
        plan: &mut Plan,
        stats: &mut PoolStats,
    ) {
        let mut drawn: Vec<TextureId> = requested.to_vec();
        drawn.sort_by(|&a, &b| {
            let ia = self.textures[a as usize].want.map_or(0.0, |w| w.1);
            let ib = self.textures[b as usize].want.map_or(0.0, |w| w.1);
            ib.total_cmp(&ia).then(b.cmp(&a))
        });
        while self.allocated_bytes > self.settings.budget_bytes {
            if let Some(slot) = self.largest_free() {
                self.destroy(slot, plan);
            } else if let Some(victim) = evictable.pop().or_else(|| drawn.pop()) {
                if self.release(victim).is_some() {
                    stats.evictions += 1;
                }
            } else {
                break;
            }
        }
    }

    /// Takes a texture out of its slot (which becomes free); returns the slot.
    fn release(&mut self, id: TextureId) -> Option<SlotId> {
        let r = self.textures[id as usize].resident.take()?;
        self.resident_bytes -= self.slot_bytes(r.slot.edge_log2);
        self.classes[r.slot.edge_log2 as usize]
            .free
            .push(r.slot.index);
        Some(r.slot)
    }

    fn free_bytes(&self) -> u64 {
        self.classes
            .iter()
            .enumerate()
            .map(|(e, c)| c.free.len() as u64 * self.slot_bytes(e as u32))
            .sum()
    }

    fn largest_free(&self) -> Option<SlotId> {
        self.classes.iter().enumerate().rev().find_map(|(e, c)| {
            c.free.last().map(|&index| SlotId {
                edge_log2: e as u32,
                index,
            })
        })
    }

    /// Destroys a free slot.
    fn destroy(&mut self, slot: SlotId, plan: &mut Plan) {
        let class = &mut self.classes[slot.edge_log2 as usize];
        class.free.retain(|&i| i != slot.index);
        class.dead.push(slot.index);
        self.allocated_bytes -= self.slot_bytes(slot.edge_log2);
        plan.ops.push(Op::Destroy(slot));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pool(budget_bytes: u64) -> TexturePool {
        TexturePool::new(PoolSettings {
            budget_bytes,
            upload_bytes_per_frame: u64::MAX,
            min_edge_log2: 4,
            bytes_per_texel: 4,
        })
    }

    #[test]
    fn the_least_visible_lose_resolution_first() {
        // Four 256-texel textures; the budget holds two at full resolution and two a level down.
        let full = slot_bytes(8, 4);
        let half = slot_bytes(7, 4);
        let mut p = pool(2 * full + 2 * half);
        let ids: Vec<TextureId> = (0..4).map(|_| p.add_texture(8).unwrap()).collect();
        // Importance 8 loses a level (key 8 -> 16), then 10 does (10 -> 20): the budget is met.
        for (&id, importance) in ids.iter().zip([10.0, 1000.0, 8.0, 500.0]) {
            p.request(id, 0, importance);
        }
        p.end_frame();
        let levels: Vec<u32> = ids.iter().map(|&id| p.resident(id).unwrap().1).collect();
        assert_eq!(levels, [1, 0, 1, 0]);
        assert_eq!(p.stats().coarser_than_needed, 2);
        assert!(p.allocated_bytes() <= 2 * full + 2 * half);
    }

    #[test]
    fn a_lost_level_weighs_a_texture_up_before_it_loses_another() {
        // Two textures of importance 1 and 3: the first loses a level (key 1 -> 2), then the
        // second (3 -> 6), then the first again (2 -> 4).
        let mut p = pool(slot_bytes(6, 4) + slot_bytes(7, 4));
        let a = p.add_texture(8).unwrap();
        let b = p.add_texture(8).unwrap();
        p.request(a, 0, 1.0);
        p.request(b, 0, 3.0);
        p.end_frame();
        assert_eq!(p.resident(a).unwrap().1, 2);
        assert_eq!(p.resident(b).unwrap().1, 1);
    }

    #[test]
    fn textures_not_drawn_are_evicted_least_recently_used_first() {
        let mut p = pool(3 * slot_bytes(8, 4));
        let ids: Vec<TextureId> = (0..4).map(|_| p.add_texture(8).unwrap()).collect();
        for &id in &ids[..3] {
            p.request(id, 0, 1.0);
            p.end_frame();
        }
        // ids[0] is the least recently used: the fourth texture takes its slot.
        p.request(ids[3], 0, 1.0);
        let plan = p.end_frame();
        assert!(p.resident(ids[0]).is_none());
        assert!(ids[1..].iter().all(|&id| p.resident(id).is_some()));
        assert_eq!(p.stats().evictions, 1);
        // Same size: the slot is reused, nothing made or destroyed.
        assert_eq!(plan.ops.len(), 1, "{plan:?}");
    }

    #[test]
    fn uploads_wait_for_the_per_frame_budget() {
        let mut p = TexturePool::new(PoolSettings {
            budget_bytes: u64::MAX,
            upload_bytes_per_frame: slot_bytes(8, 4),
            min_edge_log2: 4,
            bytes_per_texel: 4,
        });
        let ids: Vec<TextureId> = (0..3).map(|_| p.add_texture(8).unwrap()).collect();
        for frame in 1..=3 {
            for (&id, importance) in ids.iter().zip([1.0, 3.0, 2.0]) {
                p.request(id, 0, importance);
            }
            p.end_frame();
            assert_eq!(p.stats().uploads, 1);
            assert_eq!(p.stats().misses, 3 - frame);
        }
        // Most important first.
        assert!(p.resident(ids[1]).is_some());
    }

    #[test]
    fn edges_outside_the_slot_sizes_are_refused() {
        let mut p = pool(1 << 20);
        assert_eq!(
            p.add_texture(3),
            Err(PoolError::EdgeOutOfRange {
                edge_log2: 3,
                min: 4,
                max: MAX_EDGE_LOG2
            })
        );
        assert!(p.add_texture(16).is_err());
    }
}
