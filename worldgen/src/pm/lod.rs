//! Index lists of a progressive mesh at any level: in one pass from the stateless data, or by
//! per-instance edits from the level it had (the seed's "separate triangle list for each
//! instance ... edited as they gain and lose detail").

use super::data::PmMesh;

impl PmMesh {
    /// Wedges alive at level `p` (1-based, clamped to the valid range).
    pub fn wedges_at(&self, p: usize) -> usize {
        self.levels[self.clamp_level(p) - 1].wedges as usize
    }

    /// Triangles drawn at level `p`.
    pub fn triangles_at(&self, p: usize) -> usize {
        self.levels[self.clamp_level(p) - 1].triangles as usize
    }

    /// The finest level that draws at most `triangles` triangles (level 1 draws none).
    pub fn finest_with_at_most(&self, triangles: usize) -> usize {
        self.levels
            .iter()
            .rposition(|l| l.triangles as usize <= triangles)
            .map_or(1, |i| i + 1)
    }

    /// `p` clamped to `1..=levels`.
    pub fn clamp_level(&self, p: usize) -> usize {
        p.clamp(1, self.levels.len().max(1))
    }

    /// The wedge that stands for wedge `w` while only the first `live` wedges are alive: `w`'s
    /// collapse chain followed until it reaches one.
    pub fn live_wedge(&self, mut w: u32, live: u32) -> u32 {
        while w >= live {
            w = self.collapse_to[w as usize];
        }
        w
    }

    /// The index list of level `p` in one pass: each corner of the first `triangles_at(p)`
    /// triangles follows its collapse chain until it reaches a live wedge.
    pub fn indices_at(&self, p: usize, out: &mut Vec<u32>) {
        out.clear();
        let live = self.wedges_at(p) as u32;
        let n = self.triangles_at(p);
        out.extend(
            self.triangles[..n]
                .iter()
                .flatten()
                .map(|&w| self.live_wedge(w, live)),
        );
    }
}

/// The edits between neighbouring levels, derived once per PM (shared by all instances).
#[derive(Debug, Clone, Default)]
pub struct PmEdits {
    /// Edits of the step from level `p` to `p - 1` are `edits[start[p - 2]..start[p - 1]]`
    /// for `p >= 2`: (slot in the index list, wedge at level p, wedge at level p - 1).
    start: Vec<u32>,
    edits: Vec<(u32, u32, u32)>,
    /// Every triangle's corners at the last level that draws it.
    last_corners: Vec<u32>,
}

impl PmEdits {
    /// Derives the edits by walking from full detail down to one position.
    pub fn new(pm: &PmMesh) -> Self {
        let np = pm.level_count();
        let mut current: Vec<u32> = pm.triangles.iter().flatten().copied().collect();
        let mut pos_slots: Vec<Vec<u32>> = vec![Vec::new(); np];
        for (slot, &w) in current.iter().enumerate() {
            pos_slots[pm.wedge_position[w as usize] as usize].push(slot as u32);
        }
        let mut out = PmEdits {
            start: vec![0; np.saturating_sub(1) + 1],
            edits: Vec::new(),
            last_corners: current.clone(),
        };
        let mut per_step: Vec<Vec<(u32, u32, u32)>> = vec![Vec::new(); np];
        for p in (2..=np).rev() {
            let keep = pm.triangles_at(p - 1) * 3;
            let slots = std::mem::take(&mut pos_slots[p - 1]);
            let mut step = Vec::new();
            for slot in slots {
                if (slot as usize) >= keep {
                    continue;
                }
                let from = current[slot as usize];
                let to = pm.collapse_to[from as usize];
                current[slot as usize] = to;
                step.push((slot, from, to));
                pos_slots[pm.wedge_position[to as usize] as usize].push(slot);
            }
            // Triangles that vanish here keep their corners of level p (their slots were edited
            // by every earlier step and are skipped by this one).
            let drawn = pm.triangles_at(p) * 3;
            out.last_corners[keep..drawn].copy_from_slice(&current[keep..drawn]);
            step.sort_unstable();
            per_step[p - 1] = step;
        }
        for p in 2..=np {
            out.edits.extend_from_slice(&per_step[p - 1]);
            out.start[p - 1] = out.edits.len() as u32;
        }
        out
    }

    fn step(&self, p: usize) -> &[(u32, u32, u32)] {
        &self.edits[self.start[p - 2] as usize..self.start[p - 1] as usize]
    }

    /// Bytes held (for the memory tables).
    pub fn bytes(&self) -> usize {
        self.start.len() * 4 + self.edits.len() * 12 + self.last_corners.len() * 4
    }
}

/// One drawn object's index list at its current level.
#[derive(Debug, Clone)]
pub struct PmInstance {
    level: usize,
    indices: Vec<u32>,
}

impl PmInstance {
    /// An instance at level `p`, built in one pass.
    pub fn new(pm: &PmMesh, p: usize) -> Self {
        let level = pm.clamp_level(p);
        let mut indices = Vec::new();
        pm.indices_at(level, &mut indices);
        PmInstance { level, indices }
    }

    pub fn level(&self) -> usize {
        self.level
    }

    pub fn indices(&self) -> &[u32] {
        &self.indices
    }

    /// Moves to level `p` by editing the index list one step at a time; returns the number of
    /// index writes.
    pub fn set_level(&mut self, pm: &PmMesh, edits: &PmEdits, p: usize) -> usize {
        let target = pm.clamp_level(p);
        let mut writes = 0;
        while self.level > target {
            for &(slot, _, to) in edits.step(self.level) {
                self.indices[slot as usize] = to;
            }
            writes += edits.step(self.level).len();
            self.level -= 1;
            self.indices.truncate(pm.triangles_at(self.level) * 3);
        }
        while self.level < target {
            let lo = pm.triangles_at(self.level) * 3;
            let hi = pm.triangles_at(self.level + 1) * 3;
            self.indices.extend_from_slice(&edits.last_corners[lo..hi]);
            writes += hi - lo;
            self.level += 1;
            for &(slot, from, _) in edits.step(self.level) {
                self.indices[slot as usize] = from;
            }
            writes += edits.step(self.level).len();
        }
        writes
    }
}

/// Level lookup by error in O(log levels): `prefix_min[p - 1]` is the smallest stored error of
/// levels 1..=p, which never increases with p, so the coarsest level whose own error is within a
/// bound is found by binary search (errors need not be monotone along the levels).
#[derive(Debug, Clone, Default)]
pub struct ErrorIndex {
    prefix_min: Vec<f32>,
}

impl ErrorIndex {
    pub fn new(pm: &PmMesh) -> Self {
        let mut m = f32::INFINITY;
        ErrorIndex {
            prefix_min: pm
                .levels
                .iter()
                .map(|l| {
                    m = m.min(l.error);
                    m
                })
                .collect(),
        }
    }

    /// The coarsest level `p >= min_level` whose stored error is at most `max_error` (the full
    /// level, error 0, always qualifies).
    pub fn coarsest_within(&self, pm: &PmMesh, max_error: f32, min_level: usize) -> usize {
        let floor = pm.clamp_level(min_level);
        let first = self.prefix_min.partition_point(|&e| e > max_error) + 1;
        let p = first.clamp(1, pm.level_count().max(1));
        if p >= floor {
            return p;
        }
        // Below the floor: the coarsest level at or above it within the bound.
        (floor..=pm.level_count())
            .find(|&q| pm.levels[q - 1].error <= max_error)
            .unwrap_or(pm.level_count())
    }
}
