//! Catmull-Rom (C1 bicubic) patches: proven per-cell bounds of the slope and curvature of the
//! interpolant from its 4 x 4 sample stencil. Used by the finest surface (map heights) and the
//! decal shaping (sparse offset lattice), so both bound their parts the same way.

/// Upper bound of |d2G/dx2| per unit of (largest x second difference / spacing^2) for
/// Catmull-Rom bicubic (likewise y): the row's second derivative is linear between
/// `2 D0 - D1` and `2 D1 - D0` (3 x the largest second difference), times 1.25 across.
pub const BICUBIC_CURVATURE_FACTOR: f64 = 3.0 * 1.25;
/// Upper bound of |d2G/dxdy| per unit of (largest mixed difference / spacing^2): 1.5 x 1.5.
pub const BICUBIC_TWIST_FACTOR: f64 = 1.5 * 1.5;
/// Upper bound of |dG/dx| per unit of (largest x-neighbour sample difference / spacing) for
/// Catmull-Rom bicubic (likewise y): 1.5 (largest sum of the derivative weights on the
/// differences along the axis) x 1.25 (largest sum of |weights| across it).
pub const BICUBIC_SLOPE_FACTOR: f64 = 1.5 * 1.25;

/// Upper bound of |G| per unit of the largest |sample| of the 4 x 4 stencil: the Catmull-Rom
/// weights' absolute values sum to at most 1.25 per axis (at t = 1/2).
pub const BICUBIC_RANGE_FACTOR: f64 = 1.25 * 1.25;

/// A bound of |G| over the Catmull-Rom patch of one cell (stencil as in
/// [`catmull_rom_cell_slope`]).
pub fn catmull_rom_cell_magnitude(p: &impl Fn(i64, i64) -> f64) -> f64 {
    let mut m = 0.0f64;
    for j in -1..=2i64 {
        for i in -1..=2i64 {
            m = m.max(p(i, j).abs());
        }
    }
    BICUBIC_RANGE_FACTOR * m
}

/// A bound of |grad| of the Catmull-Rom patch of one cell whose 4 x 4 stencil is `p(-1..=2,
/// -1..=2)` (sample offsets from the cell's south-west sample).
pub fn catmull_rom_cell_slope(p: &impl Fn(i64, i64) -> f64, spacing_m: f64) -> f64 {
    let (mut dx, mut dy) = (0.0f64, 0.0f64);
    for j in -1..=2i64 {
        for i in -1..=2i64 {
            if i < 2 {
                dx = dx.max((p(i + 1, j) - p(i, j)).abs());
            }
            if j < 2 {
                dy = dy.max((p(i, j + 1) - p(i, j)).abs());
            }
        }
    }
    BICUBIC_SLOPE_FACTOR * dx.hypot(dy) / spacing_m
}

/// A bound of the Frobenius norm of the Hessian of the Catmull-Rom patch of one cell (stencil
/// as in [`catmull_rom_cell_slope`]).
pub fn catmull_rom_cell_curvature(p: &impl Fn(i64, i64) -> f64, spacing_m: f64) -> f64 {
    let s2 = spacing_m * spacing_m;
    let (mut dxx, mut dyy, mut dxy) = (0.0f64, 0.0f64, 0.0f64);
    for j in -1..=2i64 {
        for i in -1..=2i64 {
            if (0..=1).contains(&i) {
                dxx = dxx.max((p(i - 1, j) - 2.0 * p(i, j) + p(i + 1, j)).abs());
            }
            if (0..=1).contains(&j) {
                dyy = dyy.max((p(i, j - 1) - 2.0 * p(i, j) + p(i, j + 1)).abs());
            }
            if i < 2 && j < 2 {
                dxy = dxy.max((p(i + 1, j + 1) - p(i + 1, j) - p(i, j + 1) + p(i, j)).abs());
            }
        }
    }
    let gxx = BICUBIC_CURVATURE_FACTOR * dxx / s2;
    let gyy = BICUBIC_CURVATURE_FACTOR * dyy / s2;
    let gxy = BICUBIC_TWIST_FACTOR * dxy / s2;
    (gxx * gxx + 2.0 * gxy * gxy + gyy * gyy).sqrt()
}
