//! Branch and bound on a block's error bounds: where the between-points term makes a check
//! cell's bound loose (coarse levels, where the map surface curves a lot inside one check cell;
//! noisy detail at fine levels), the cell is split in four and measured again, worst cell
//! first, until the worst cell left is within [`SLACK`] of the largest error actually measured in
//! the block, or the block's split budget is spent.
//!
//! Three meshes are bounded at once: the node's own, its four children's (vertices every
//! second check point), and the grandchildren's (the check triangles themselves, exact
//! vertices), whose bound also covers deeper descendants: their triangles lie inside the check
//! triangles with legs at most half a check cell, where their error is at most
//! `between(cell, c / 2)`.
//!
//! Why it stays a proof: a cell split in two along each side has sub-triangles with the same
//! diagonal direction, so they tile the cell's check triangles and lie inside one triangle of
//! each of the three meshes; the argument of [`super::bounds`] holds for each sub-cell with legs
//! `size` and the check cell's region bounds (valid on any part of it). A block's bound is the
//! largest bound over the cells left (split or not), never a guess.

use super::bounds::{CHECK_SUBDIV, interpolate_grid};
use super::quadtree::NODE_QUADS;
use crate::surface::world::{RegionBounds, World};
use std::collections::BinaryHeap;

/// A block is refined until its worst cell's bound is at most this factor over the largest
/// error measured in it.
pub const SLACK: f64 = 1.1;
/// Most splits per block (five surface evaluations each) where the check lattice is finer than
/// a quarter of the map's height cells, and where it is coarser (few nodes, each covering much
/// of the screen, where the map surface's curvature inside a check cell makes bounds loose).
/// Fine nodes: 8 splits per block instead of 64 left the triangles drawn at tau 1, 2 and 4 px
/// within 0.1 % (nodebench `selection`, default map) and made their bounds about 20 % cheaper;
/// splits are the costliest evaluations of a node's measurement (one point at a time).
pub const SPLITS_PER_BLOCK: usize = 8;
pub const SPLITS_PER_COARSE_BLOCK: usize = 512;

/// Errors bounded per cell: own mesh, children's meshes, grandchildren's and deeper.
pub type Errors = [f64; 3];

/// A square cell of the check lattice or a part of one, with its corners' measured errors.
#[derive(Debug, Clone, Copy)]
pub struct Cell {
    /// Minimum corner and side, in check-lattice units from the node's minimum corner.
    pub x0: f64,
    pub y0: f64,
    pub size: f64,
    /// Errors at the corners (x0, y0), (x0 + size, y0), (x0, y0 + size), (x0 + size, y0 + size).
    pub corners: [Errors; 4],
    /// Region bounds of the check cell it lies in.
    pub region: RegionBounds,
}

/// What refinement needs of a node: the surface, the node's placement, its meshes' vertex
/// heights and which descendants exist.
pub struct Refiner<'a> {
    pub world: &'a World,
    pub origin_m: [f64; 2],
    /// Check-lattice spacing (m).
    pub check_m: f64,
    /// The node's vertex heights ((n + 1)^2), its four children's together ((2n + 1)^2) and the
    /// check lattice's (the grandchildren's), as f32 like the meshes.
    pub vertices: Vec<f32>,
    pub child_vertices: Vec<f32>,
    pub lattice_vertices: Vec<f32>,
    /// Deepest descendant level below the node: 0 (a leaf), 1, 2, or 3 and more.
    pub depth_below: u8,
    /// Most splits per block.
    pub splits_per_block: usize,
}

impl Refiner<'_> {
    /// Error bounds over a cell, each 0 where that mesh does not exist.
    pub fn cell_bounds(&self, c: &Cell) -> Errors {
        let mut corner_max = [0.0f64; 3];
        for e in &c.corners {
            for t in 0..3 {
                corner_max[t] = corner_max[t].max(e[t]);
            }
        }
        let half = if self.depth_below >= 3 {
            c.region.between_m(0.5 * self.check_m)
        } else {
            0.0
        };
        self.bounds(corner_max, c.region.between_m(c.size * self.check_m), half)
    }

    /// Error bounds over a cell from its corners' largest errors per mesh, its between-points
    /// bound `between`, and `between_half`, the between-points bound for half a check cell
    /// (deeper descendants; read only where they exist).
    pub fn bounds(&self, corner_max: Errors, between: f64, between_half: f64) -> Errors {
        let mut out = [0.0f64; 3];
        for (t, o) in out.iter_mut().enumerate() {
            if self.depth_below as usize >= t {
                *o = corner_max[t] + between;
            }
        }
        if self.depth_below >= 3 {
            out[2] = out[2].max(between_half);
        }
        out
    }

    /// The errors of the three meshes at a point in check-lattice units.
    fn errors_at(&self, gx: f64, gy: f64) -> Errors {
        let n = NODE_QUADS as usize;
        let sub = f64::from(CHECK_SUBDIV);
        let f = self.world.height_m(
            self.origin_m[0] + gx * self.check_m,
            self.origin_m[1] + gy * self.check_m,
        );
        let own = interpolate_grid(&self.vertices, n, gx / sub, gy / sub);
        let children =
            interpolate_grid(&self.child_vertices, 2 * n, 2.0 * gx / sub, 2.0 * gy / sub);
        let grand = interpolate_grid(&self.lattice_vertices, n * CHECK_SUBDIV as usize, gx, gy);
        [own, children, grand].map(|m| (m - f).abs())
    }

    /// The four quarters of a cell, with five new evaluations.
    fn split(&self, c: &Cell) -> [Cell; 4] {
        let h = c.size * 0.5;
        let (x0, y0) = (c.x0, c.y0);
        let [e00, e10, e01, e11] = c.corners;
        let at = |x: f64, y: f64| self.errors_at(x, y);
        let (s, w, m) = (at(x0 + h, y0), at(x0, y0 + h), at(x0 + h, y0 + h));
        let (e, n) = (at(x0 + c.size, y0 + h), at(x0 + h, y0 + c.size));
        let cell = |x0: f64, y0: f64, corners| Cell {
            x0,
            y0,
            size: h,
            corners,
            ..*c
        };
        [
            cell(x0, y0, [e00, s, w, m]),
            cell(x0 + h, y0, [s, e10, m, e]),
            cell(x0, y0 + h, [w, m, e01, n]),
            cell(x0 + h, y0 + h, [m, e, n, e11]),
        ]
    }

    /// The block's error bounds from its loose cells (those whose bound may exceed
    /// `measured * SLACK`), `measured` being the largest error measured in the block so far.
    /// Cells are split worst first.
    pub fn refine_block(&self, cells: Vec<Cell>, mut measured: f64) -> Errors {
        let mut store = cells;
        let key = |b: Errors| b.iter().copied().fold(0.0, f64::max).to_bits();
        let mut heap: BinaryHeap<(u64, usize)> = store
            .iter()
            .enumerate()
            .map(|(i, c)| (key(self.cell_bounds(c)), i))
            .collect();
        let mut out = [0.0f64; 3];
        let mut splits = 0;
        while let Some((bound, i)) = heap.pop() {
            if f64::from_bits(bound) <= measured * SLACK || splits >= self.splits_per_block {
                // Every cell left is at most this one: take their bounds as they are.
                for c in std::iter::once(i).chain(heap.drain().map(|(_, i)| i)) {
                    let b = self.cell_bounds(&store[c]);
                    for t in 0..3 {
                        out[t] = out[t].max(b[t]);
                    }
                }
                break;
            }
            splits += 1;
            for q in self.split(&store[i]) {
                for e in q.corners {
                    for (t, v) in e.iter().enumerate() {
                        if self.depth_below as usize >= t {
                            measured = measured.max(*v);
                        }
                    }
                }
                store.push(q);
                heap.push((key(self.cell_bounds(&q)), store.len() - 1));
            }
        }
        out
    }
}
