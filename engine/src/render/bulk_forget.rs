//! When a collection that keeps entries of dropped nodes (weak references, say) is swept:
//! once it has doubled since the last sweep (and holds at least [`MIN_ENTRIES`]). So it holds
//! at most about twice the live entries at the last sweep, and adding an entry or going
//! through the live ones does not visit every dropped one. Used by the ground-texture queue
//! and the light-grid leases.

/// Entries below which nothing is swept.
pub const MIN_ENTRIES: usize = 64;

/// The length a collection had after its last sweep.
#[derive(Debug, Default, Clone, Copy)]
pub struct BulkForget {
    swept_len: usize,
}

impl BulkForget {
    /// Runs `sweep` (which forgets the dropped entries and returns the length left) when a
    /// collection of `len` entries is due.
    pub fn sweep_if_due(&mut self, len: usize, sweep: impl FnOnce() -> usize) {
        if len >= 2 * self.swept_len.max(MIN_ENTRIES) {
            self.swept_len = sweep();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A collection that grows by one entry at a time is swept exactly when it reaches twice
    /// what the last sweep left (64 at least), neither earlier nor later: with three quarters
    /// of it dropped at each sweep, and with none.
    #[test]
    fn a_sweep_is_due_once_the_collection_has_doubled() {
        for keep_one_in in [1usize, 4] {
            let mut f = BulkForget::default();
            let (mut len, mut left, mut sweeps) = (0usize, 0usize, 0);
            for _ in 0..2_000 {
                len += 1;
                let before = len;
                let mut swept = false;
                f.sweep_if_due(len, || {
                    swept = true;
                    len /= keep_one_in;
                    len
                });
                let due_at = 2 * left.max(MIN_ENTRIES);
                assert_eq!(
                    swept,
                    before == due_at,
                    "{before} entries, {left} left last time"
                );
                if swept {
                    left = len;
                    sweeps += 1;
                }
            }
            assert!(sweeps >= 4, "{sweeps} sweeps");
        }
    }
}
