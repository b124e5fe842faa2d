//! Stateless, hash-based noise. Written by hand (rather than using a noise crate) because the
//! engine must re-evaluate exactly the same values per 16 m tile, far from the origin, in any
//! order: every value here is a pure function of (seed, integer lattice point) with no tables
//! built at start-up and no trigonometry whose last bit could differ between platforms.

use std::f64::consts::FRAC_1_SQRT_2;

/// Mixes a seed and two integers into 64 well-distributed bits (SplitMix64 finaliser steps).
#[inline]
pub fn hash3(seed: u64, a: i64, b: i64) -> u64 {
    let mut z = seed ^ 0x9E37_79B9_7F4A_7C15;
    z = mix(z ^ (a as u64).wrapping_mul(0xD6E8_FEB8_6659_FD93));
    z = mix(z ^ (b as u64).wrapping_mul(0xA076_1D64_78BD_642F));
    z
}

#[inline]
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Maps 64 hash bits to a float in [0, 1).
#[inline]
pub fn unit(h: u64) -> f64 {
    (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// A uniform float in [0, 1) for (seed, a, b).
#[inline]
pub fn unit3(seed: u64, a: i64, b: i64) -> f64 {
    unit(hash3(seed, a, b))
}

/// 16 unit directions, evenly spaced (cos, sin of k * 22.5 degrees), as literals so no
/// platform trigonometry is involved. Used as noise gradients and wherever a hashed direction
/// is needed.
pub const DIRECTIONS_16: [(f64, f64); 16] = [
    (1.0, 0.0),
    (0.923_879_532_511_286_7, 0.382_683_432_365_089_8),
    (FRAC_1_SQRT_2, FRAC_1_SQRT_2),
    (0.382_683_432_365_089_8, 0.923_879_532_511_286_7),
    (0.0, 1.0),
    (-0.382_683_432_365_089_8, 0.923_879_532_511_286_7),
    (-FRAC_1_SQRT_2, FRAC_1_SQRT_2),
    (-0.923_879_532_511_286_7, 0.382_683_432_365_089_8),
    (-1.0, 0.0),
    (-0.923_879_532_511_286_7, -0.382_683_432_365_089_8),
    (-FRAC_1_SQRT_2, -FRAC_1_SQRT_2),
    (-0.382_683_432_365_089_8, -0.923_879_532_511_286_7),
    (0.0, -1.0),
    (0.382_683_432_365_089_8, -0.923_879_532_511_286_7),
    (FRAC_1_SQRT_2, -FRAC_1_SQRT_2),
    (0.923_879_532_511_286_7, -0.382_683_432_365_089_8),
];

/// A cheap hash of a lattice corner, enough to pick one of 16 gradients (one multiply-xorshift
/// round; the full [`hash3`] is twice the cost and this is the innermost loop of the terrain).
#[inline]
fn corner_hash(seed: u64, a: i64, b: i64) -> u64 {
    let mut h = seed
        ^ (a as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (b as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    h = (h ^ (h >> 31)).wrapping_mul(0xD6E8_FEB8_6659_FD93);
    h ^ (h >> 32)
}

/// The quintic fade `6t^5 - 15t^4 + 10t^3` (C2 at lattice points), shared by the noises here
/// and the engine's periodic material noise.
#[inline]
pub fn fade(t: f64) -> f64 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

/// Periodic value noise in [0, 1) on a tile of `texels` x `texels`: `cells` lattice cells
/// across it, sampled at the centre of texel (`i`, `j`), corner values hashed from their indices
/// modulo `cells` (so the tile repeats without a seam).
pub fn periodic_value(seed: u64, texels: u32, cells: u32, i: u32, j: u32) -> f64 {
    let per = f64::from(texels) / f64::from(cells);
    let (x, y) = ((f64::from(i) + 0.5) / per, (f64::from(j) + 0.5) / per);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (fade(x - x0), fade(y - y0));
    let corner = |a: f64, b: f64| {
        let wrap = |v: f64| i64::from((v as u32) % cells);
        unit3(seed, wrap(a), wrap(b))
    };
    let bottom = corner(x0, y0) + fx * (corner(x0 + 1.0, y0) - corner(x0, y0));
    let top = corner(x0, y0 + 1.0) + fx * (corner(x0 + 1.0, y0 + 1.0) - corner(x0, y0 + 1.0));
    bottom + fy * (top - bottom)
}

/// Gradient noise in about [-1, 1] with unit lattice spacing; C2 (quintic fade).
pub fn gradient(seed: u64, x: f64, y: f64) -> f64 {
    let x0 = crate::sample::floor_small(x);
    let y0 = crate::sample::floor_small(y);
    let (ix, iy) = (x0 as i64, y0 as i64);
    let g = |cx: i64, cy: i64| DIRECTIONS_16[(corner_hash(seed, cx, cy) >> 60) as usize];
    let corners = [g(ix, iy), g(ix + 1, iy), g(ix, iy + 1), g(ix + 1, iy + 1)];
    let (fx, fy) = (x - x0, y - y0);
    blend(corners, fx, fy, fade(fx), fade(fy))
}

/// The noise value inside one lattice cell from its corner gradients (south-west, south-east,
/// north-west, north-east), the position's fractions and their fades.
#[inline]
fn blend(g: [(f64, f64); 4], fx: f64, fy: f64, u: f64, v: f64) -> f64 {
    blend_terms(g.map(|g| g.0), y_terms(g, fy), fx, u, v)
}

/// The y parts of [`blend`]'s four dot products (gradient times offset from its corner).
#[inline]
fn y_terms(g: [(f64, f64); 4], fy: f64) -> [f64; 4] {
    [
        g[0].1 * fy,
        g[1].1 * fy,
        g[2].1 * (fy - 1.0),
        g[3].1 * (fy - 1.0),
    ]
}

/// [`gradient`] at every point of the lattice `xs` x `ys` (row-major, one row per `ys` entry),
/// equal to it point by point: fractions and fades are computed once per column and row, and
/// each noise-lattice corner's gradient once.
pub fn gradient_lattice(seed: u64, xs: &[f64], ys: &[f64]) -> Vec<f64> {
    let axis = |v: &[f64]| -> Vec<(i64, f64, f64)> {
        v.iter()
            .map(|&t| {
                let t0 = crate::sample::floor_small(t);
                (t0 as i64, t - t0, fade(t - t0))
            })
            .collect()
    };
    let (cols, rows) = (axis(xs), axis(ys));
    let corners = |a: &[(i64, f64, f64)]| {
        crate::sample::stencil_indices(&a.iter().map(|c| c.0).collect::<Vec<_>>(), 2)
    };
    let ((cx, first_x), (cy, first_y)) = (corners(&cols), corners(&rows));
    let cw = cx.len();
    let corner: Vec<(f64, f64)> = cy
        .iter()
        .flat_map(|&y| cx.iter().map(move |&x| (x, y)))
        .map(|(x, y)| DIRECTIONS_16[(corner_hash(seed, x, y) >> 60) as usize])
        .collect();
    let mut out = Vec::with_capacity(xs.len() * ys.len());
    // Per row, each used noise cell's corner gradients and the y parts of `blend`'s dot
    // products, computed once for the row's points in the cell (`blend` computes the same).
    let mut used = first_x.clone();
    used.sort_unstable();
    used.dedup();
    let mut cells: Vec<([f64; 4], [f64; 4])> = vec![([0.0; 4], [0.0; 4]); cw.saturating_sub(1)];
    for (&(_, fy, v), &r) in rows.iter().zip(&first_y) {
        for &c in &used {
            let k = r * cw + c;
            let g = [corner[k], corner[k + 1], corner[k + cw], corner[k + cw + 1]];
            cells[c] = (g.map(|g| g.0), y_terms(g, fy));
        }
        out.extend(cols.iter().zip(&first_x).map(|(&(_, fx, u), &c)| {
            let (gx, y) = cells[c];
            blend_terms(gx, y, fx, u, v)
        }));
    }
    out
}

/// [`blend`] from the corner gradients' x parts `gx` and the y parts of the four dot products
/// `y` ([`y_terms`]): the dot products are `gx * (fx or fx - 1) + y`, then blended.
#[inline]
fn blend_terms(gx: [f64; 4], y: [f64; 4], fx: f64, u: f64, v: f64) -> f64 {
    let n00 = gx[0] * fx + y[0];
    let n10 = gx[1] * (fx - 1.0) + y[1];
    let n01 = gx[2] * fx + y[2];
    let n11 = gx[3] * (fx - 1.0) + y[3];
    let a = n00 + u * (n10 - n00);
    let b = n01 + u * (n11 - n01);
    // sqrt(2) scales the theoretical range of 2-D gradient noise to about [-1, 1].
    (a + v * (b - a)) * std::f64::consts::SQRT_2
}

/// Fractional Brownian motion: `octaves` layers of gradient noise, frequency x2 and amplitude
/// x`gain` per octave, normalised to about [-1, 1].
pub fn fbm(seed: u64, x: f64, y: f64, octaves: u32, gain: f64) -> f64 {
    let (mut sum, mut amp, mut norm, mut freq) = (0.0, 1.0, 0.0, 1.0);
    for o in 0..octaves {
        sum += amp
            * gradient(
                seed.wrapping_add(u64::from(o) * 0x51_7CC1),
                x * freq,
                y * freq,
            );
        norm += amp;
        amp *= gain;
        freq *= 2.0;
    }
    sum / norm
}

/// Ridged multifractal noise in [0, 1]: sharp crests where the base noise crosses zero, with
/// finer octaves weighted by the previous octave (crests get detail, valleys stay smooth).
pub fn ridged(seed: u64, x: f64, y: f64, octaves: u32) -> f64 {
    let (mut sum, mut amp, mut norm, mut freq, mut weight) = (0.0, 1.0, 0.0, 1.0, 1.0);
    for o in 0..octaves {
        let n = gradient(
            seed.wrapping_add(u64::from(o) * 0x2545_F491),
            x * freq,
            y * freq,
        );
        let r = (1.0 - n.abs()).max(0.0);
        let r = r * r * weight;
        weight = (r * 2.0).clamp(0.0, 1.0);
        sum += r * amp;
        norm += amp;
        amp *= 0.5;
        freq *= 2.0;
    }
    sum / norm
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gradient_lattice_equals_gradient_point_by_point() {
        // Irregular, unsorted coordinates across cell borders and the origin, both signs.
        let xs: Vec<f64> = (0..57).map(|i| f64::from(i) * 0.37 - 9.1).collect();
        let ys: Vec<f64> = (0..23)
            .map(|j| 4.2 - f64::from(j * j % 17) * 0.61)
            .collect();
        // And a sparse one: a few points millions of noise cells apart.
        let far: Vec<f64> = (0..5).map(|i| f64::from(i) * 3.7e6 - 5.0e6).collect();
        for (xs, ys) in [(&xs, &ys), (&far, &far)] {
            let got = gradient_lattice(11, xs, ys);
            assert_eq!(got.len(), xs.len() * ys.len());
            for (j, &y) in ys.iter().enumerate() {
                for (i, &x) in xs.iter().enumerate() {
                    assert_eq!(got[j * xs.len() + i], gradient(11, x, y), "at ({x}, {y})");
                }
            }
        }
    }

    #[test]
    fn gradient_noise_is_bounded_and_continuous() {
        let mut max_abs: f64 = 0.0;
        for i in 0..20_000 {
            let x = f64::from(i) * 0.0137 - 50.0;
            let y = f64::from(i) * 0.0291 + 7.0;
            let n = gradient(7, x, y);
            max_abs = max_abs.max(n.abs());
            // Lipschitz-style continuity: a tiny step changes the value by a tiny amount.
            assert!((gradient(7, x + 1e-6, y) - n).abs() < 1e-4);
        }
        assert!(max_abs <= 1.01, "gradient noise out of range: {max_abs}");
        assert!(max_abs > 0.4, "gradient noise suspiciously flat: {max_abs}");
    }

    #[test]
    fn noise_is_zero_on_lattice_points_and_seed_dependent() {
        assert_eq!(gradient(1, 3.0, -4.0), 0.0);
        assert_ne!(gradient(1, 3.3, -4.6), gradient(2, 3.3, -4.6));
        let r = ridged(3, 0.37, 0.91, 5);
        assert!((0.0..=1.0).contains(&r));
    }

    #[test]
    fn hash_is_well_spread() {
        let mut buckets = [0u32; 16];
        for a in 0..64 {
            for b in 0..64 {
                buckets[(unit3(5, a, b) * 16.0) as usize] += 1;
            }
        }
        for &c in &buckets {
            assert!((200..=312).contains(&c), "bucket count {c} far from 256");
        }
    }
}
