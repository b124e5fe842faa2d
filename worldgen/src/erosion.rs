//! Hydraulic (particle/droplet) and thermal erosion on a height grid.
//!
//! Hydraulic: droplets start at hashed positions, run downhill with inertia, pick up sediment
//! up to a capacity proportional to slope x speed x water, and drop it where they slow down
//! (in the spirit of Beyer 2015, "Implementation of a method for hydraulic erosion"). Droplets
//! run tile by tile in four phases, the tiles of a phase in parallel on disjoint windows, so
//! its result does not depend on the thread count. Thermal: material slides from
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

/// Side (cells) of the tiles droplets are grouped by: at least twice a droplet's reach, so tiles
/// of one phase (every second tile in x and y) have disjoint windows.
fn tile_cells(p: &Hydraulic) -> usize {
    (2 * reach_cells(p)).next_power_of_two().max(128)
}

/// How far (cells) from its start a droplet can read or write: one cell per step, plus the
/// bilinear neighbour and a cell of margin.
fn reach_cells(p: &Hydraulic) -> usize {
    p.max_steps + 2
}

/// The part of the height and flow grids a tile's droplets can reach (the tile and a halo of
/// `reach_cells` around it, clipped to the grid), copied out so that the droplets work in a few
/// hundred KiB that stay in the cache. Indexed with grid coordinates.
struct Window {
    x0: usize,
    y0: usize,
    width: usize,
    height: usize,
    cells: Vec<f32>,
    flow: Vec<f32>,
}

impl Window {
    fn copy_from(heights: &Grid<f32>, flow: &Grid<f32>, x: [usize; 2], y: [usize; 2]) -> Self {
        let (width, height) = (x[1] - x[0], y[1] - y[0]);
        let mut w = Self {
            x0: x[0],
            y0: y[0],
            width,
            height,
            cells: Vec::with_capacity(width * height),
            flow: Vec::with_capacity(width * height),
        };
        for gy in y[0]..y[1] {
            let row = gy * heights.width();
            w.cells
                .extend_from_slice(&heights.data()[row + x[0]..row + x[1]]);
            w.flow
                .extend_from_slice(&flow.data()[row + x[0]..row + x[1]]);
        }
        w
    }

    fn copy_to(&self, heights: &mut Grid<f32>, flow: &mut Grid<f32>) {
        let grid_width = heights.width();
        for wy in 0..self.height {
            let row = (self.y0 + wy) * grid_width + self.x0;
            let src = wy * self.width..(wy + 1) * self.width;
            heights.data_mut()[row..row + self.width].copy_from_slice(&self.cells[src.clone()]);
            flow.data_mut()[row..row + self.width].copy_from_slice(&self.flow[src]);
        }
    }

    fn index(&self, x: usize, y: usize) -> usize {
        debug_assert!(
            x >= self.x0 && x < self.x0 + self.width,
            "x {x} outside the window"
        );
        debug_assert!(
            y >= self.y0 && y < self.y0 + self.height,
            "y {y} outside the window"
        );
        (y - self.y0) * self.width + (x - self.x0)
    }

    fn get(&self, x: usize, y: usize) -> f32 {
        self.cells[self.index(x, y)]
    }

    fn add(&mut self, x: usize, y: usize, v: f32) {
        let i = self.index(x, y);
        self.cells[i] += v;
    }

    fn add_flow(&mut self, x: usize, y: usize) {
        let i = self.index(x, y);
        self.flow[i] += 1.0;
    }
}

fn height_and_gradient(g: &Window, x: f64, y: f64) -> (f64, f64, f64) {
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

fn add_bilinear(g: &mut Window, x: f64, y: f64, amount: f64) {
    let (ix, iy) = (x.floor() as usize, y.floor() as usize);
    let (fx, fy) = (x - ix as f64, y - iy as f64);
    for (dx, dy, w) in [
        (0, 0, (1.0 - fx) * (1.0 - fy)),
        (1, 0, fx * (1.0 - fy)),
        (0, 1, (1.0 - fx) * fy),
        (1, 1, fx * fy),
    ] {
        g.add(ix + dx, iy + dy, (amount * w) as f32);
    }
}

/// Droplet `i`'s start (cells), from the seed alone.
fn droplet_start(seed: u64, i: usize, max_x: f64, max_y: f64) -> (f64, f64) {
    let hash = noise::hash3(seed ^ 0xE205, i as i64, 0);
    let x = noise::unit(hash) * (max_x - 1.0);
    let y = noise::unit(hash.rotate_left(32)) * (max_y - 1.0);
    (x, y)
}

/// Runs droplet erosion in place and returns a flow grid (droplet visits per sample), which
/// marks valleys and stream beds for moisture.
///
/// Droplets are grouped by the tile their start falls in, in their index order within a tile.
/// The tiles run in four phases (even/odd column x even/odd row); within a phase no two tiles'
/// droplets can reach the same cell, so the phase's tiles run on `threads` threads, each on a
/// cached copy of its window, and the result does not depend on the thread count. A map of one
/// tile (up to 129 samples a side) erodes exactly as one sequential pass over all droplets.
pub fn hydraulic(
    heights: &mut Grid<f32>,
    seed: u64,
    p: &Hydraulic,
    threads: usize,
    progress: &dyn Progress,
) -> Grid<f32> {
    let (w, h) = (heights.width(), heights.height());
    let mut flow = Grid::new(w, h, 0.0f32);
    if w < 3 || h < 3 {
        return flow;
    }
    let (max_x, max_y) = ((w - 1) as f64, (h - 1) as f64);
    let tile = tile_cells(p);
    let reach = reach_cells(p);
    let (tiles_x, tiles_y) = (w.div_ceil(tile), h.div_ceil(tile));
    let tile_of = |i: usize| {
        let (x, y) = droplet_start(seed, i, max_x, max_y);
        (y as usize / tile) * tiles_x + x as usize / tile
    };
    // Counting sort of the droplet indices by start tile (stable: index order within a tile).
    let mut first = vec![0u32; tiles_x * tiles_y + 1];
    for i in 0..p.droplets {
        first[tile_of(i) + 1] += 1;
    }
    for t in 0..tiles_x * tiles_y {
        first[t + 1] += first[t];
    }
    let mut fill = first.clone();
    let mut order = vec![0u32; p.droplets];
    for i in 0..p.droplets {
        let t = tile_of(i);
        order[fill[t] as usize] = i as u32;
        fill[t] += 1;
    }
    drop(fill);

    progress.begin("hydraulic erosion", p.droplets as u64);
    let grids = std::sync::Mutex::new((heights, &mut flow));
    for phase in 0..4 {
        let tiles: Vec<usize> = (0..tiles_x * tiles_y)
            .filter(|t| (t % tiles_x) % 2 == phase % 2 && (t / tiles_x) % 2 == phase / 2)
            .filter(|&t| first[t + 1] > first[t])
            .collect();
        let next = std::sync::atomic::AtomicUsize::new(0);
        std::thread::scope(|scope| {
            for _ in 0..threads.clamp(1, tiles.len().max(1)) {
                scope.spawn(|| {
                    loop {
                        let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(&t) = tiles.get(k) else { break };
                        let (tx, ty) = (t % tiles_x, t / tiles_x);
                        let span = |start: usize, side: usize| {
                            [
                                (start * tile).saturating_sub(reach),
                                ((start + 1) * tile + reach).min(side),
                            ]
                        };
                        // Windows of one phase are disjoint: copying in and out in any order
                        // gives the same grids.
                        let mut window = {
                            let g = grids
                                .lock()
                                .unwrap_or_else(std::sync::PoisonError::into_inner);
                            Window::copy_from(g.0, g.1, span(tx, w), span(ty, h))
                        };
                        let droplets = &order[first[t] as usize..first[t + 1] as usize];
                        for &i in droplets {
                            run_droplet(&mut window, seed, i as usize, (max_x, max_y), p);
                        }
                        let mut g = grids
                            .lock()
                            .unwrap_or_else(std::sync::PoisonError::into_inner);
                        let (hs, fl) = &mut *g;
                        window.copy_to(hs, fl);
                        progress.advance(droplets.len() as u64);
                    }
                });
            }
        });
    }
    progress.end();
    flow
}

/// One droplet from its start until it stops, leaves the grid or runs out of steps.
fn run_droplet(cells: &mut Window, seed: u64, i: usize, (max_x, max_y): (f64, f64), p: &Hydraulic) {
    let (mut x, mut y) = droplet_start(seed, i, max_x, max_y);
    let (mut dx, mut dy) = (0.0f64, 0.0f64);
    let (mut speed, mut water, mut sediment) = (1.0f64, 1.0f64, 0.0f64);
    for _ in 0..p.max_steps {
        let (h0, gx, gy) = height_and_gradient(cells, x, y);
        cells.add_flow(x as usize, y as usize);
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
        let (h1, _, _) = height_and_gradient(cells, nx, ny);
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
            add_bilinear(cells, x, y, amount);
        } else {
            let amount = ((capacity - sediment) * p.erode)
                .min(-dh)
                .min(p.max_change_m);
            sediment += amount;
            add_bilinear(cells, x, y, -amount);
        }
        speed = (speed * speed + dh.abs() * p.gravity).sqrt().min(20.0);
        water *= 1.0 - p.evaporate;
        x = nx;
        y = ny;
    }
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
    fn tiled_hydraulic_erosion_does_not_depend_on_the_thread_count() {
        // 5 x 3 tiles of 128 cells: droplets cross tile borders into the halos.
        let (w, h) = (600, 300);
        let mut base = Grid::new(w, h, 0.0f32);
        for y in 0..h {
            for x in 0..w {
                let (fx, fy) = (x as f32 * 0.05, y as f32 * 0.07);
                base.set(x, y, 40.0 * fx.sin() * fy.cos() + 0.2 * x as f32);
            }
        }
        let p = Hydraulic::for_cells(w * h);
        let mut one = base.clone();
        let flow_one = hydraulic(&mut one, 3, &p, 1, &Silent);
        for threads in [2, 5] {
            let mut many = base.clone();
            let flow_many = hydraulic(&mut many, 3, &p, threads, &Silent);
            assert_eq!(one, many, "heights differ with {threads} threads");
            assert_eq!(flow_one, flow_many, "flow differs with {threads} threads");
        }
        // Every droplet visits at least its start: the flow counts them all.
        let visits: f64 = flow_one.data().iter().map(|&v| f64::from(v)).sum();
        assert!(
            visits >= p.droplets as f64,
            "{visits} visits for {} droplets",
            p.droplets
        );
        assert_ne!(one, base, "nothing eroded");
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
        let fa = hydraulic(&mut a, 9, &p, 1, &Silent);
        let fb = hydraulic(&mut b, 9, &p, 3, &Silent);
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
