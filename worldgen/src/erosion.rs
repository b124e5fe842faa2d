//! Hydraulic (particle/droplet) and thermal erosion on a height grid.
//!
//! Hydraulic: droplets start at hashed positions, run downhill with inertia, pick up sediment
//! up to a capacity proportional to slope x speed x water, and drop it where they slow down
//! (in the spirit of Beyer 2015, "Implementation of a method for hydraulic erosion"). It is
//! sequential, so its result does not depend on the thread count. Thermal: material slides from
//! a cell to lower neighbours where the drop exceeds the talus slope; every cell's new height is
//! computed from the old grid (Jacobi), so rows can run in parallel with identical results.

use crate::Grid;
use crate::noise;
use crate::par;
use crate::progress::Progress;

/// Droplet parameters (heights in metres, distances in cells).
#[derive(Debug, Clone, Copy)]
pub struct Hydraulic {
    pub droplets: usize,
    pub max_steps: usize,
    pub inertia: f64,
    pub capacity: f64,
    pub min_capacity: f64,
    pub erode: f64,
    pub deposit: f64,
    pub evaporate: f64,
    pub gravity: f64,
    /// Largest height change a single droplet step may make (m); keeps the grid stable.
    pub max_change_m: f64,
}

impl Hydraulic {
    /// Sensible parameters for a grid of `cells` samples.
    pub fn for_cells(cells: usize) -> Self {
        Self {
            droplets: cells / 6,
            max_steps: 48,
            inertia: 0.1,
            capacity: 6.0,
            min_capacity: 0.01,
            erode: 0.3,
            deposit: 0.3,
            evaporate: 0.02,
            gravity: 4.0,
            max_change_m: 1.0,
        }
    }
}

/// A grid stored in 32 x 32 blocks (4 KiB of f32, one page each) instead of rows. A droplet's
/// path stays within a few blocks, where in rows every step north or south lands a whole row
/// (a page or more) away: on large maps the row layout makes erosion miss the cache and the TLB
/// on almost every step. Same values, same order of operations: the result is bit-identical.
struct Blocked {
    blocks_per_row: usize,
    data: Vec<f32>,
}

const BLOCK_SHIFT: usize = 5;
const BLOCK_MASK: usize = (1 << BLOCK_SHIFT) - 1;

impl Blocked {
    fn from_grid(g: &Grid<f32>) -> Self {
        let blocks_per_row = g.width().div_ceil(1 << BLOCK_SHIFT);
        let rows = g.height().div_ceil(1 << BLOCK_SHIFT);
        let mut b = Self {
            blocks_per_row,
            data: vec![0.0; (blocks_per_row * rows) << (2 * BLOCK_SHIFT)],
        };
        for y in 0..g.height() {
            for x in 0..g.width() {
                b.set(x, y, g.get(x, y));
            }
        }
        b
    }

    fn copy_to(&self, g: &mut Grid<f32>) {
        for y in 0..g.height() {
            for x in 0..g.width() {
                g.set(x, y, self.get(x, y));
            }
        }
    }

    fn index(&self, x: usize, y: usize) -> usize {
        let block = (y >> BLOCK_SHIFT) * self.blocks_per_row + (x >> BLOCK_SHIFT);
        (block << (2 * BLOCK_SHIFT)) | ((y & BLOCK_MASK) << BLOCK_SHIFT) | (x & BLOCK_MASK)
    }

    fn get(&self, x: usize, y: usize) -> f32 {
        self.data[self.index(x, y)]
    }

    fn set(&mut self, x: usize, y: usize, v: f32) {
        let i = self.index(x, y);
        self.data[i] = v;
    }
}

fn height_and_gradient(g: &Blocked, x: f64, y: f64) -> (f64, f64, f64) {
    let (ix, iy) = (x.floor() as usize, y.floor() as usize);
    let (fx, fy) = (x - ix as f64, y - iy as f64);
    let h00 = f64::from(g.get(ix, iy));
    let h10 = f64::from(g.get(ix + 1, iy));
    let h01 = f64::from(g.get(ix, iy + 1));
    let h11 = f64::from(g.get(ix + 1, iy + 1));
    let gx = (h10 - h00) * (1.0 - fy) + (h11 - h01) * fy;
    let gy = (h01 - h00) * (1.0 - fx) + (h11 - h10) * fx;
    let h = h00 * (1.0 - fx) * (1.0 - fy)
        + h10 * fx * (1.0 - fy)
        + h01 * (1.0 - fx) * fy
        + h11 * fx * fy;
    (h, gx, gy)
}

fn add_bilinear(g: &mut Blocked, x: f64, y: f64, amount: f64) {
    let (ix, iy) = (x.floor() as usize, y.floor() as usize);
    let (fx, fy) = (x - ix as f64, y - iy as f64);
    for (dx, dy, w) in [
        (0, 0, (1.0 - fx) * (1.0 - fy)),
        (1, 0, fx * (1.0 - fy)),
        (0, 1, (1.0 - fx) * fy),
        (1, 1, fx * fy),
    ] {
        let v = g.get(ix + dx, iy + dy);
        g.set(ix + dx, iy + dy, v + (amount * w) as f32);
    }
}

/// Runs droplet erosion in place and returns a flow grid (droplet visits per sample), which
/// marks valleys and stream beds for moisture.
pub fn hydraulic(
    heights: &mut Grid<f32>,
    seed: u64,
    p: &Hydraulic,
    progress: &dyn Progress,
) -> Grid<f32> {
    let (w, h) = (heights.width(), heights.height());
    let mut flow_grid = Grid::new(w, h, 0.0f32);
    if w < 3 || h < 3 {
        return flow_grid;
    }
    let mut flow = Blocked::from_grid(&flow_grid);
    let mut cells = Blocked::from_grid(heights);
    let (max_x, max_y) = ((w - 1) as f64, (h - 1) as f64);
    progress.begin("hydraulic erosion", p.droplets as u64);
    for i in 0..p.droplets {
        if i % 4096 == 4095 {
            progress.advance(4096);
        }
        let hash = noise::hash3(seed ^ 0xE205, i as i64, 0);
        let mut x = noise::unit(hash) * (max_x - 1.0);
        let mut y = noise::unit(hash.rotate_left(32)) * (max_y - 1.0);
        let (mut dx, mut dy) = (0.0f64, 0.0f64);
        let (mut speed, mut water, mut sediment) = (1.0f64, 1.0f64, 0.0f64);
        for _ in 0..p.max_steps {
            let (h0, gx, gy) = height_and_gradient(&cells, x, y);
            flow.set(
                x as usize,
                y as usize,
                flow.get(x as usize, y as usize) + 1.0,
            );
            dx = dx * p.inertia - gx * (1.0 - p.inertia);
            dy = dy * p.inertia - gy * (1.0 - p.inertia);
            let len = (dx * dx + dy * dy).sqrt();
            if len < 1e-12 {
                break;
            }
            dx /= len;
            dy /= len;
            let (nx, ny) = (x + dx, y + dy);
            if nx < 0.0 || ny < 0.0 || nx >= max_x || ny >= max_y {
                break;
            }
            let (h1, _, _) = height_and_gradient(&cells, nx, ny);
            let dh = h1 - h0;
            let capacity = (-dh).max(p.min_capacity) * speed * water * p.capacity;
            if sediment > capacity || dh > 0.0 {
                // Fill the pit we are climbing out of, or drop the excess.
                let amount = if dh > 0.0 {
                    dh.min(sediment)
                } else {
                    (sediment - capacity) * p.deposit
                };
                let amount = amount.min(p.max_change_m);
                sediment -= amount;
                add_bilinear(&mut cells, x, y, amount);
            } else {
                let amount = ((capacity - sediment) * p.erode)
                    .min(-dh)
                    .min(p.max_change_m);
                sediment += amount;
                add_bilinear(&mut cells, x, y, -amount);
            }
            speed = (speed * speed + dh.abs() * p.gravity).sqrt().min(20.0);
            water *= 1.0 - p.evaporate;
            x = nx;
            y = ny;
        }
    }
    progress.end();
    cells.copy_to(heights);
    flow.copy_to(&mut flow_grid);
    flow_grid
}

/// Thermal erosion: `iterations` Jacobi sweeps moving material down slopes steeper than
/// `talus_slope` (rise over run). Mass is conserved exactly up to float rounding.
pub fn thermal(
    heights: &mut Grid<f32>,
    spacing_m: f64,
    talus_slope: f64,
    iterations: usize,
    threads: usize,
    progress: &dyn Progress,
) {
    const RATE: f32 = 0.2;
    let (w, h) = (heights.width(), heights.height());
    let talus = (talus_slope * spacing_m) as f32;
    progress.begin("thermal erosion", iterations as u64);
    for _ in 0..iterations {
        let old = heights.clone();
        par::for_each_row(
            heights.data_mut(),
            w,
            threads,
            |y, row| {
                for (x, v) in row.iter_mut().enumerate() {
                    let hc = old.get(x, y);
                    let mut change = 0.0f32;
                    for (nx, ny) in [
                        (x.wrapping_sub(1), y),
                        (x + 1, y),
                        (x, y.wrapping_sub(1)),
                        (x, y + 1),
                    ] {
                        if nx >= w || ny >= h {
                            continue;
                        }
                        let hn = old.get(nx, ny);
                        // Outflow from c to n, and inflow from n to c, each from the old grid.
                        change -= RATE * (hc - hn - talus).max(0.0);
                        change += RATE * (hn - hc - talus).max(0.0);
                    }
                    *v = hc + change;
                }
            },
            &|_| {},
        );
        progress.advance(1);
    }
    progress.end();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::progress::Silent;

    #[test]
    fn thermal_erosion_conserves_mass_and_flattens_spikes() {
        let mut g = Grid::new(9, 9, 0.0f32);
        g.set(4, 4, 100.0);
        let before: f64 = g.data().iter().map(|&v| f64::from(v)).sum();
        thermal(&mut g, 1.0, 0.5, 20, 2, &Silent);
        let after: f64 = g.data().iter().map(|&v| f64::from(v)).sum();
        assert!((before - after).abs() < 1e-3, "mass {before} -> {after}");
        assert!(g.get(4, 4) < 50.0, "spike not reduced: {}", g.get(4, 4));
    }

    #[test]
    fn hydraulic_erosion_is_deterministic_and_carves() {
        let mut a = Grid::new(64, 64, 0.0f32);
        for y in 0..64 {
            for x in 0..64 {
                a.set(x, y, (x as f32 * 0.8) + ((y as f32 - 32.0).abs() * 0.3));
            }
        }
        let mut b = a.clone();
        let orig = a.clone();
        let p = Hydraulic {
            droplets: 2000,
            ..Hydraulic::for_cells(4096)
        };
        let fa = hydraulic(&mut a, 9, &p, &Silent);
        let fb = hydraulic(&mut b, 9, &p, &Silent);
        assert_eq!(a, b);
        assert_eq!(fa, fb);
        assert!(a.data().iter().all(|v| v.is_finite()));
        // It carves: many cells are lowered, some by a real amount, and sediment is deposited.
        let diffs: Vec<f32> = a
            .data()
            .iter()
            .zip(orig.data())
            .map(|(n, o)| n - o)
            .collect();
        let lowered = diffs.iter().filter(|&&d| d < -1e-3).count();
        let deepest = diffs.iter().copied().fold(0.0f32, f32::min);
        let raised = diffs.iter().filter(|&&d| d > 1e-4).count();
        assert!(
            lowered * 100 >= diffs.len(),
            "only {lowered} of {} cells lowered",
            diffs.len()
        );
        assert!(deepest < -0.05, "deepest cut only {deepest} m");
        assert!(raised > 0, "no sediment deposited");
    }
}
