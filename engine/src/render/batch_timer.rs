//! Cost per item of work done in batches (node ground textures, impostor bakes: several per
//! submission): GPU time from timestamp queries around whole batches, and the frame thread's
//! time from the wall time of recording a batch, so that the per-frame budget
//! can count both before the work is done.

use super::{Gpu, GpuTimer};

/// Weight of a new batch's per-item time in the running estimate.
const NEW_WEIGHT: f64 = 0.25;

/// A running estimate of seconds per item from whole batches' times.
#[derive(Debug, Clone, Copy)]
pub struct ItemCost {
    estimate_s: f64,
}

impl ItemCost {
    /// Starts at `prior_s` per item.
    pub fn new(prior_s: f64) -> Self {
        Self {
            estimate_s: prior_s,
        }
    }

    /// Seconds one item is expected to take.
    pub fn per_item_s(&self) -> f64 {
        self.estimate_s
    }

    /// Follows a batch of `items` that took `total_s` (nothing when it held none).
    pub fn observe(&mut self, total_s: f64, items: usize) {
        if items > 0 {
            let sample = total_s / items as f64;
            self.estimate_s += NEW_WEIGHT * (sample - self.estimate_s);
        }
    }
}

/// A running estimate of GPU seconds per item.
pub struct BatchTimer {
    timer: Option<GpuTimer>,
    /// Items recorded into the open batch, and whether the timer started in it.
    open_items: usize,
    open_timed: bool,
    /// Items of the batch whose measurement is on its way back.
    measured_items: usize,
    cost: ItemCost,
}

impl std::fmt::Debug for BatchTimer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "BatchTimer({:.1} µs per item)", self.per_item_s() * 1e6)
    }
}

impl BatchTimer {
    /// An estimate that starts at `prior_s` per item and follows measurements where the
    /// adapter has timestamp queries (else it stays at the prior).
    pub fn new(gpu: &Gpu, prior_s: f64) -> Self {
        Self {
            timer: GpuTimer::new(gpu),
            open_items: 0,
            open_timed: false,
            measured_items: 0,
            cost: ItemCost::new(prior_s),
        }
    }

    /// GPU seconds one item is expected to take.
    pub fn per_item_s(&self) -> f64 {
        self.cost.per_item_s()
    }

    /// Call before recording an item into `enc`; the first item of a batch starts the timer
    /// when it is free (a finished measurement is collected first).
    pub fn item(&mut self, gpu: &Gpu, enc: &mut wgpu::CommandEncoder) {
        if self.open_items == 0
            && let Some(t) = self.timer.as_mut()
        {
            t.harvest(gpu);
            if let Some(ms) = t.last_ms.take() {
                self.cost.observe(ms * 1e-3, self.measured_items);
            }
            self.open_timed = t.begin(enc);
        }
        self.open_items += 1;
    }

    /// Call with the batch's encoder just before it is finished and submitted.
    pub fn before_submit(&self, enc: &mut wgpu::CommandEncoder) {
        if self.open_timed
            && let Some(t) = &self.timer
        {
            t.end(enc);
        }
    }

    /// Call after the batch was submitted.
    pub fn after_submit(&mut self) {
        if self.open_timed
            && let Some(t) = &self.timer
        {
            t.after_submit();
            self.measured_items = self.open_items;
        }
        self.open_items = 0;
        self.open_timed = false;
    }
}

#[cfg(test)]
mod tests {
    use super::ItemCost;

    /// The estimate follows whole batches per item, a quarter of the way each time, and a
    /// batch of no items leaves it where it was.
    #[test]
    fn item_cost_follows_batches_per_item() {
        let mut c = ItemCost::new(1e-3);
        c.observe(8e-3, 2);
        assert!((c.per_item_s() - (1e-3 + 0.25 * 3e-3)).abs() < 1e-12);
        let before = c.per_item_s();
        c.observe(5.0, 0);
        assert_eq!(c.per_item_s().to_bits(), before.to_bits());
        for _ in 0..100 {
            c.observe(0.3e-3 * 3.0, 3);
        }
        assert!((c.per_item_s() - 0.3e-3).abs() < 1e-9);
    }
}
