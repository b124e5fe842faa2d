//! What a texture upload costs the frame thread, so that texture uploads can be held to the
//! time the streamer's per-frame GPU budget leaves: the seconds per byte of recent uploads,
//! smoothed, and from it the bytes that fit in a given time.

/// Weight of the newest measurement in the smoothed cost per byte.
const SMOOTHING: f64 = 0.25;

/// The smoothed frame-thread cost of an uploaded byte.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct UploadCost {
    seconds_per_byte: Option<f64>,
}

impl UploadCost {
    /// A frame's uploads: `bytes` written in `seconds` of the frame thread.
    pub fn record(&mut self, bytes: usize, seconds: f64) {
        if bytes == 0 || !seconds.is_finite() || seconds < 0.0 {
            return;
        }
        let now = seconds / bytes as f64;
        self.seconds_per_byte = Some(
            self.seconds_per_byte
                .map_or(now, |c| c + SMOOTHING * (now - c)),
        );
    }

    /// Bytes expected to fit in `seconds` (none for no time left; unbounded before anything
    /// was measured or when uploads measured as free, where the byte budget alone holds).
    pub fn bytes_within(&self, seconds: f64) -> u64 {
        match self.seconds_per_byte {
            Some(c) if c > 0.0 => {
                let bytes = seconds.max(0.0) / c;
                if bytes >= u64::MAX as f64 {
                    u64::MAX
                } else {
                    bytes as u64
                }
            }
            _ => u64::MAX,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unmeasured_cost_leaves_the_byte_budget_alone() {
        let c = UploadCost::default();
        assert_eq!(c.bytes_within(0.0), u64::MAX);
        assert_eq!(c.bytes_within(1.0), u64::MAX);
    }

    #[test]
    fn bytes_follow_the_measured_rate_and_time_left() {
        let mut c = UploadCost::default();
        // 1 MiB in 1 ms: 1 GiB/s.
        c.record(1 << 20, 1e-3);
        assert_eq!(c.bytes_within(0.0), 0);
        assert_eq!(c.bytes_within(-1.0), 0);
        let in_2ms = c.bytes_within(2e-3);
        assert!(
            (in_2ms as f64 - 2.0 * f64::from(1 << 20)).abs() < 2.0,
            "{in_2ms}"
        );
        assert_eq!(c.bytes_within(f64::INFINITY), u64::MAX);
        // A slower upload moves the estimate a quarter of the way: 1 MiB in 5 ms.
        c.record(1 << 20, 5e-3);
        let per_ms = c.bytes_within(1e-3) as f64 / f64::from(1 << 20);
        assert!((per_ms - 1.0 / 2.0).abs() < 1e-6, "{per_ms} MiB per ms");
        // Nothing uploaded, or a broken clock, changes nothing.
        let before = c;
        c.record(0, 1.0);
        c.record(1, f64::NAN);
        assert_eq!(c, before);
    }
}
