//! How far apart two renderings' silhouettes are on the screen: the coverage masks of two
//! depth images and the distance in pixels from each pixel one covers and the other does not to
//! the nearest pixel the other covers (a Hausdorff distance between the two covered sets, exact
//! Euclidean, through a distance transform). CPU only: the masks come from depth read back
//! from any rendering.

/// The pixels a rendering covers: depth written (reversed Z: anything above the cleared 0).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Mask {
    pub size_px: [u32; 2],
    /// Row-major from the top-left.
    pub covered: Vec<bool>,
}

impl Mask {
    /// An empty mask of `size_px`.
    pub fn empty(size_px: [u32; 2]) -> Self {
        Self {
            size_px,
            covered: vec![false; size_px[0] as usize * size_px[1] as usize],
        }
    }

    /// The pixels of a reversed-Z depth image (cleared to 0, far) that something was drawn at.
    pub fn from_reversed_z(size_px: [u32; 2], depth: &[f32]) -> Result<Self, String> {
        let n = size_px[0] as usize * size_px[1] as usize;
        if depth.len() != n {
            return Err(format!(
                "a depth image of {size_px:?} px has {n} values, not {}",
                depth.len()
            ));
        }
        Ok(Self {
            size_px,
            covered: depth.iter().map(|&z| z > 0.0).collect(),
        })
    }

    /// Covered pixels.
    pub fn count(&self) -> usize {
        self.covered.iter().filter(|&&c| c).count()
    }

    /// Marks the pixel holding the point `at_px` (x right, y down; ignored off the image).
    pub fn mark(&mut self, at_px: [f64; 2]) {
        let [w, h] = self.size_px;
        if at_px[0] >= 0.0 && at_px[1] >= 0.0 {
            let (x, y) = (at_px[0] as u32, at_px[1] as u32);
            if x < w && y < h {
                self.covered[(y * w + x) as usize] = true;
            }
        }
    }

    /// Covered by this mask or by `other` (same size).
    pub fn union(&self, other: &Mask) -> Mask {
        debug_assert_eq!(self.size_px, other.size_px);
        Mask {
            size_px: self.size_px,
            covered: self
                .covered
                .iter()
                .zip(&other.covered)
                .map(|(&a, &b)| a || b)
                .collect(),
        }
    }
}

/// The squared Euclidean distance in pixels from every pixel to the nearest covered pixel of
/// `mask` (infinity where it covers none): the separable exact transform of Felzenszwalb and
/// Huttenlocher (2012), a column pass then a lower envelope of parabolas along each row.
pub fn squared_distance_px2(mask: &Mask) -> Vec<f64> {
    let [w, h] = [mask.size_px[0] as usize, mask.size_px[1] as usize];
    let mut d = vec![f64::INFINITY; w * h];
    // Columns: distance to the nearest covered pixel above or below.
    for x in 0..w {
        let mut last: Option<usize> = None;
        for y in 0..h {
            if mask.covered[y * w + x] {
                last = Some(y);
            }
            if let Some(l) = last {
                d[y * w + x] = ((y - l) * (y - l)) as f64;
            }
        }
        last = None;
        for y in (0..h).rev() {
            if mask.covered[y * w + x] {
                last = Some(y);
            }
            if let Some(l) = last {
                let below = ((l - y) * (l - y)) as f64;
                if below < d[y * w + x] {
                    d[y * w + x] = below;
                }
            }
        }
    }
    // Rows: the lower envelope of the parabolas (q - x)^2 + f(q).
    let mut f = vec![0.0; w];
    let mut v = vec![0usize; w];
    let mut z = vec![0.0f64; w + 1];
    for y in 0..h {
        let row = &mut d[y * w..(y + 1) * w];
        f.copy_from_slice(row);
        let finite: Vec<usize> = (0..w).filter(|&q| f[q].is_finite()).collect();
        if finite.is_empty() {
            continue;
        }
        let mut k = 0usize;
        v[0] = finite[0];
        z[0] = f64::NEG_INFINITY;
        z[1] = f64::INFINITY;
        let meet = |q: usize, p: usize| {
            let (qf, pf) = (q as f64, p as f64);
            ((f[q] + qf * qf) - (f[p] + pf * pf)) / (2.0 * (qf - pf))
        };
        for &q in &finite[1..] {
            let mut s = meet(q, v[k]);
            while s <= z[k] {
                k -= 1;
                s = meet(q, v[k]);
            }
            k += 1;
            v[k] = q;
            z[k] = s;
            z[k + 1] = f64::INFINITY;
        }
        k = 0;
        for (x, out) in row.iter_mut().enumerate() {
            let xf = x as f64;
            while z[k + 1] < xf {
                k += 1;
            }
            let dx = xf - v[k] as f64;
            *out = dx * dx + f[v[k]];
        }
    }
    d
}

/// The distance between two silhouettes.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SilhouetteDistance {
    /// The largest distance from a pixel one mask covers to the nearest pixel the other covers
    /// (infinity when one covers something and the other nothing).
    pub max_px: f64,
    /// The 99th percentile of that distance over the pixels covered by one mask and not the
    /// other (0 when there are none).
    pub p99_px: f64,
    /// Pixels covered by exactly one of the masks.
    pub differing_px: usize,
    /// Pixels each mask covers.
    pub covered_px: [usize; 2],
}

impl SilhouetteDistance {
    /// The distances in pixels of an image `factor` times as wide and high (a measure made on
    /// a supersampled frame, given in the pixels of the frame it stands for).
    pub fn in_pixels_of(self, factor: u32) -> Self {
        let f = f64::from(factor.max(1));
        Self {
            max_px: self.max_px / f,
            p99_px: self.p99_px / f,
            ..self
        }
    }
}

/// The symmetric distance between the silhouettes of `a` and `b` (same size): every pixel `a`
/// covers and `b` does not, measured to the nearest pixel `b` covers, and the other way round.
pub fn distance(a: &Mask, b: &Mask) -> Result<SilhouetteDistance, String> {
    if a.size_px != b.size_px {
        return Err(format!(
            "masks of {:?} and {:?} px cannot be compared",
            a.size_px, b.size_px
        ));
    }
    let (to_a, to_b) = (squared_distance_px2(a), squared_distance_px2(b));
    let mut away: Vec<f64> = Vec::new();
    for i in 0..a.covered.len() {
        match (a.covered[i], b.covered[i]) {
            (true, false) => away.push(to_b[i].sqrt()),
            (false, true) => away.push(to_a[i].sqrt()),
            _ => {}
        }
    }
    away.sort_by(f64::total_cmp);
    let p99_px = if away.is_empty() {
        0.0
    } else {
        away[((away.len() - 1) as f64 * 0.99).round() as usize]
    };
    Ok(SilhouetteDistance {
        max_px: away.last().copied().unwrap_or(0.0),
        p99_px,
        differing_px: away.len(),
        covered_px: [a.count(), b.count()],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn disc(size: [u32; 2], centre: [f64; 2], radius: f64) -> Mask {
        let mut m = Mask::empty(size);
        for y in 0..size[1] {
            for x in 0..size[0] {
                let (dx, dy) = (f64::from(x) - centre[0], f64::from(y) - centre[1]);
                m.covered[(y * size[0] + x) as usize] = dx * dx + dy * dy <= radius * radius;
            }
        }
        m
    }

    #[test]
    fn transform_matches_brute_force() {
        // Scattered points on a non-square image: every pixel's nearest point by brute force.
        let size = [37u32, 23u32];
        let mut m = Mask::empty(size);
        let pts = [[3u32, 4u32], [30, 2], [17, 20], [36, 22], [0, 15]];
        for p in pts {
            m.covered[(p[1] * size[0] + p[0]) as usize] = true;
        }
        let d = squared_distance_px2(&m);
        for y in 0..size[1] {
            for x in 0..size[0] {
                let want = pts
                    .iter()
                    .map(|p| {
                        let (dx, dy) = (
                            f64::from(x) - f64::from(p[0]),
                            f64::from(y) - f64::from(p[1]),
                        );
                        dx * dx + dy * dy
                    })
                    .fold(f64::INFINITY, f64::min);
                assert_eq!(d[(y * size[0] + x) as usize], want, "pixel ({x}, {y})");
            }
        }
        assert!(
            squared_distance_px2(&Mask::empty(size))
                .iter()
                .all(|v| v.is_infinite())
        );
    }

    #[test]
    fn a_shifted_silhouette_is_as_far_as_the_shift() {
        let size = [64, 48];
        let a = disc(size, [30.0, 24.0], 10.0);
        let same = distance(&a, &a).unwrap();
        assert_eq!((same.max_px, same.differing_px), (0.0, 0));
        // Moved 4 px to the right: the leading and trailing crescents are at most 4 px from the
        // other disc (a pixel lattice rounds the edge, hence the half pixel).
        let b = disc(size, [34.0, 24.0], 10.0);
        let d = distance(&a, &b).unwrap();
        assert!((3.5..=4.5).contains(&d.max_px), "{d:?}");
        assert!(d.p99_px <= d.max_px && d.differing_px > 0);
        // Something against nothing is infinitely far.
        assert!(
            distance(&a, &Mask::empty(size))
                .unwrap()
                .max_px
                .is_infinite()
        );
        assert!(distance(&a, &Mask::empty([1, 1])).is_err());
    }

    #[test]
    fn depth_gives_coverage() {
        let m = Mask::from_reversed_z([2, 2], &[0.0, 0.5, 0.0, 1e-7]).unwrap();
        assert_eq!(m.covered, vec![false, true, false, true]);
        assert!(Mask::from_reversed_z([2, 2], &[0.0; 3]).is_err());
    }
}
