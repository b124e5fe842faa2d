//! A static bounding-volume hierarchy over triangles for closest-point queries: the "distance to
//! the full mesh" half of the two-sided error. Written here because the crates that offer it
//! (parry3d) bring a second linear-algebra library; this is ~100 lines over glam.

use super::geom::point_triangle_distance_sq;
use glam::DVec3;

#[derive(Debug, Clone, Copy)]
struct Node {
    lo: DVec3,
    hi: DVec3,
    /// Leaf: first triangle in `order`; inner: index of the left child (right = left + 1).
    first: u32,
    /// Leaf: triangle count (> 0); inner: 0.
    count: u32,
}

/// Closest-point hierarchy over a fixed triangle set.
#[derive(Debug, Clone)]
pub struct TriangleBvh {
    tris: Vec<[DVec3; 3]>,
    order: Vec<u32>,
    nodes: Vec<Node>,
}

const LEAF_SIZE: usize = 4;

fn box_distance_sq(p: DVec3, lo: DVec3, hi: DVec3) -> f64 {
    let d = (lo - p).max(p - hi).max(DVec3::ZERO);
    d.length_squared()
}

impl TriangleBvh {
    /// Builds the hierarchy (median split on the longest axis of the centroid bounds).
    pub fn new(tris: Vec<[DVec3; 3]>) -> Self {
        let mut order: Vec<u32> = (0..tris.len() as u32).collect();
        let centroids: Vec<DVec3> = tris.iter().map(|t| (t[0] + t[1] + t[2]) / 3.0).collect();
        let mut bvh = TriangleBvh {
            tris,
            order: Vec::new(),
            nodes: Vec::new(),
        };
        if bvh.tris.is_empty() {
            return bvh;
        }
        bvh.nodes.push(Node {
            lo: DVec3::ZERO,
            hi: DVec3::ZERO,
            first: 0,
            count: 0,
        });
        let mut stack = vec![(0usize, 0usize, order.len())];
        while let Some((node, start, end)) = stack.pop() {
            let mut lo = DVec3::splat(f64::INFINITY);
            let mut hi = DVec3::splat(f64::NEG_INFINITY);
            let mut clo = lo;
            let mut chi = hi;
            for &t in &order[start..end] {
                for v in bvh.tris[t as usize] {
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
                clo = clo.min(centroids[t as usize]);
                chi = chi.max(centroids[t as usize]);
            }
            if end - start <= LEAF_SIZE {
                bvh.nodes[node] = Node {
                    lo,
                    hi,
                    first: start as u32,
                    count: (end - start) as u32,
                };
                continue;
            }
            let ext = chi - clo;
            let axis = if ext.x >= ext.y && ext.x >= ext.z {
                0
            } else if ext.y >= ext.z {
                1
            } else {
                2
            };
            let mid = start + (end - start) / 2;
            order[start..end].select_nth_unstable_by(mid - start, |&a, &b| {
                centroids[a as usize][axis].total_cmp(&centroids[b as usize][axis])
            });
            let left = bvh.nodes.len();
            bvh.nodes.push(bvh.nodes[node]);
            bvh.nodes.push(bvh.nodes[node]);
            bvh.nodes[node] = Node {
                lo,
                hi,
                first: left as u32,
                count: 0,
            };
            stack.push((left, start, mid));
            stack.push((left + 1, mid, end));
        }
        bvh.order = order;
        bvh
    }

    /// Squared distance to the nearest triangle if it is at most `bound_sq`, else `bound_sq`.
    pub fn distance_sq_below(&self, p: DVec3, bound_sq: f64) -> f64 {
        self.walk(p, bound_sq, false).0
    }

    /// True when some triangle lies within `r_sq` (squared) of `p`: stops at the first one.
    pub fn any_within(&self, p: DVec3, r_sq: f64) -> bool {
        self.walk(p, r_sq, true).1
    }

    /// Nearest-first traversal: the smallest squared distance at most `bound_sq` (else
    /// `bound_sq`) and whether one was found; with `first`, stops at the first one found.
    fn walk(&self, p: DVec3, bound_sq: f64, first: bool) -> (f64, bool) {
        let mut best = bound_sq;
        let mut found = false;
        if self.nodes.is_empty() {
            return (best, found);
        }
        let mut stack = [0u32; 64];
        let mut top = 1usize;
        while top > 0 {
            top -= 1;
            let node = self.nodes[stack[top] as usize];
            if box_distance_sq(p, node.lo, node.hi) > best {
                continue;
            }
            if node.count > 0 {
                let s = node.first as usize;
                for &t in &self.order[s..s + node.count as usize] {
                    let [a, b, c] = self.tris[t as usize];
                    let d = point_triangle_distance_sq(p, a, b, c);
                    if d <= best {
                        best = d;
                        found = true;
                        if first {
                            return (best, found);
                        }
                    }
                }
                continue;
            }
            // Visit the nearer child first (pushed last).
            let l = node.first as usize;
            let dl = box_distance_sq(p, self.nodes[l].lo, self.nodes[l].hi);
            let dr = box_distance_sq(p, self.nodes[l + 1].lo, self.nodes[l + 1].hi);
            let (near, far) = if dl <= dr { (l, l + 1) } else { (l + 1, l) };
            if top + 2 <= stack.len() {
                stack[top] = far as u32;
                stack[top + 1] = near as u32;
                top += 2;
            }
        }
        (best, found)
    }

    /// The largest distance from any of `points` to the triangles: exact, but only the points
    /// that could raise the running maximum are measured in full.
    pub fn max_distance(&self, points: impl IntoIterator<Item = DVec3>) -> f64 {
        let mut worst_sq = 0.0f64;
        for p in points {
            if worst_sq > 0.0 && self.any_within(p, worst_sq) {
                continue;
            }
            worst_sq = worst_sq.max(self.distance_sq_below(p, f64::INFINITY));
        }
        worst_sq.sqrt()
    }
}
