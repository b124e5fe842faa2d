//! sRGB transfer functions (IEC 61966-2-1), shared by worldgen (house texture mip chains) and
//! the engine (materials, legend colours into linear uniforms).

/// sRGB-encoded 8-bit to linear in [0, 1].
pub fn srgb_to_linear(c: u8) -> f64 {
    let c = f64::from(c) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear (clamped to [0, 1]) to sRGB-encoded 8-bit, rounded.
pub fn linear_to_srgb(c: f64) -> u8 {
    let c = c.clamp(0.0, 1.0);
    let s = if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every 8-bit value survives the round trip.
    #[test]
    fn round_trip_is_exact_on_8_bit_values() {
        for c in 0..=255u8 {
            assert_eq!(linear_to_srgb(srgb_to_linear(c)), c);
        }
    }
}
