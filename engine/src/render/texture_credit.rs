//! The share of the per-frame GPU budget that queued node textures may spend, carried across
//! frames: a texture that costs more than one frame leaves is made once enough frames' shares
//! add up (on lavapipe one costs several milliseconds), so the budget holds on average instead
//! of being overrun by one texture every frame; a small share is always given, so textures
//! never starve behind the frame's other uploads.

/// The share of each frame's time that queued textures may always use (s), even when the
/// frame's other uploads left less.
pub const TEXTURE_MIN_SHARE_S: f64 = 1e-3;

/// Budget carried from frame to frame while textures wait.
#[derive(Debug, Default, Clone, Copy)]
pub struct TextureCredit {
    /// Left unspent by earlier frames while a texture waited (at most one texture's cost).
    carried_s: f64,
}

impl TextureCredit {
    /// The credit of a frame that left `time_left_s` of its budget: its share and what earlier
    /// frames carried over.
    pub fn start(&self, time_left_s: f64) -> f64 {
        self.carried_s + time_left_s.max(TEXTURE_MIN_SHARE_S)
    }

    /// Ends the frame with `credit_s` unspent: carried over (up to one texture's cost,
    /// `per_texture_s`) while textures still wait, dropped when none does.
    pub fn end(&mut self, credit_s: f64, per_texture_s: f64, waiting: bool) {
        self.carried_s = if waiting {
            credit_s.clamp(0.0, per_texture_s)
        } else {
            0.0
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Textures made per frame over `frames` frames, each leaving `left_s`, textures costing
    /// `cost_s`, with `queued` waiting at the start.
    fn made_per_frame(left_s: f64, cost_s: f64, queued: usize, frames: usize) -> Vec<usize> {
        let (mut credit, mut queued) = (TextureCredit::default(), queued);
        (0..frames)
            .map(|_| {
                let mut c = credit.start(left_s);
                let mut made = 0;
                while queued > 0 && cost_s <= c {
                    c -= cost_s;
                    queued -= 1;
                    made += 1;
                }
                credit.end(c, cost_s, queued > 0);
                made
            })
            .collect()
    }

    /// A texture that costs three frames' shares is made every third frame: the budget holds
    /// on average (binary fractions of a second, so the sums are exact).
    #[test]
    fn a_costly_texture_waits_for_several_frames_shares() {
        let made = made_per_frame(1.0 / 256.0, 3.0 / 256.0, 100, 30);
        assert_eq!(made.iter().sum::<usize>(), 10, "{made:?}");
        assert!(made.iter().all(|&m| m <= 1), "{made:?}");
    }

    /// Cheap textures: as many a frame as its share pays for, and no credit piles up while
    /// nothing waits (a burst after an idle spell stays within one frame's share).
    #[test]
    fn cheap_textures_fill_each_frame_and_idle_frames_save_nothing() {
        let (share, cost) = (1.0 / 256.0, 1.0 / 1024.0);
        assert_eq!(made_per_frame(share, cost, 100, 3), vec![4, 4, 4]);
        let mut credit = TextureCredit::default();
        for _ in 0..100 {
            let c = credit.start(share);
            credit.end(c, cost, false);
        }
        assert_eq!(credit.start(share), share);
    }

    /// With nothing left by the frame's other uploads, textures still get their minimum share:
    /// 50 frames of 1 ms pay for 10 textures of 4.73 ms.
    #[test]
    fn textures_never_starve() {
        let made = made_per_frame(-0.002, 4.7321e-3, 100, 50);
        assert_eq!(made.iter().sum::<usize>(), 10, "{made:?}");
    }
}
