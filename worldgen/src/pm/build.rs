//! The offline collapse order: repeated half-edge collapses u -> v (u's wedges move onto v's
//! position, which survives unchanged) until one position is left.
//!
//! Three costs, chosen per build:
//! - [`CostKind::LongestEdge`], the seed's: the longest edge of the triangles that vanish; the
//!   direction (which end survives) keeps the corner: the smoother end (lower `State::cornerness`) is
//!   removed.
//! - [`CostKind::Quadric`] (Garland-Heckbert, half-edge form): the squared distance of v from the
//!   planes accumulated at u, with border and seam edges adding perpendicular constraint planes.
//! - [`CostKind::Melax`]: edge length x curvature (Melax 1998), borders held by a curvature of 1.
//!
//! Every cost forbids collapses that flip a moving triangle's normal while another collapse is
//! available; such collapses are taken only when nothing else remains (flagged in the output).
//! When no triangle is left, isolated positions (the last points of disconnected parts) collapse
//! onto the surviving position, so every mesh reaches one vertex.

use super::geom::{area_normal, v3};
use super::mesh::TriMesh;
use glam::DVec3;
use std::cmp::Ordering;

/// Which cost orders the collapses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CostKind {
    LongestEdge,
    Quadric,
    Melax,
}

impl CostKind {
    pub const ALL: [CostKind; 3] = [CostKind::LongestEdge, CostKind::Quadric, CostKind::Melax];

    /// Name used on the command line and in files and tables.
    pub fn name(self) -> &'static str {
        match self {
            CostKind::LongestEdge => "longest-edge",
            CostKind::Quadric => "quadric",
            CostKind::Melax => "melax",
        }
    }

    /// Code stored in PM files.
    pub fn code(self) -> u8 {
        match self {
            CostKind::LongestEdge => 0,
            CostKind::Quadric => 1,
            CostKind::Melax => 2,
        }
    }

    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|c| c.code() == code)
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|c| c.name() == name)
    }
}

/// A moving triangle whose normal turns by more than acos(FLIP_COS) (about 75 degrees) counts as
/// flipped: such folds are where the surface error jumps.
const FLIP_COS: f64 = 0.25;

/// Flag of a collapse that had to flip a triangle normal (nothing else was left).
pub const FLAG_FLIPPED: u8 = 1;
/// Flag of a collapse of an isolated position (no triangle touched it).
pub const FLAG_ISOLATED: u8 = 2;

/// One half-edge collapse: position `removed` moves onto `kept`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Collapse {
    pub removed: u32,
    pub kept: u32,
    /// The cost that ordered it (units depend on the cost kind).
    pub cost: f64,
    pub flags: u8,
}

/// The full collapse order of a mesh.
#[derive(Debug, Clone)]
pub struct CollapseOrder {
    pub kind: CostKind,
    /// `positions - 1` collapses (none for an empty mesh).
    pub collapses: Vec<Collapse>,
    /// Where each wedge goes when its position is removed (`u32::MAX` for the survivor's wedges).
    pub wedge_target: Vec<u32>,
    /// The step (1-based index into `collapses`) at which each triangle vanishes.
    pub triangle_step: Vec<u32>,
    /// The last position standing.
    pub survivor: u32,
}

/// Symmetric 4x4 quadric stored as its 10 upper-triangle entries, plus the total weight of its
/// planes: the cost is the weighted *mean* squared plane distance, so a region of small triangles
/// is not cheap to move far (a plain area-weighted sum makes thin features vanish early).
#[derive(Debug, Clone, Copy, Default)]
struct Quadric([f64; 10], f64);

impl Quadric {
    /// `w * (n.p + d)^2` for a unit normal `n`.
    fn plane(n: DVec3, d: f64, w: f64) -> Self {
        Quadric(
            [
                w * n.x * n.x,
                w * n.x * n.y,
                w * n.x * n.z,
                w * n.x * d,
                w * n.y * n.y,
                w * n.y * n.z,
                w * n.y * d,
                w * n.z * n.z,
                w * n.z * d,
                w * d * d,
            ],
            w,
        )
    }
    fn add(&mut self, o: &Quadric) {
        for k in 0..10 {
            self.0[k] += o.0[k];
        }
        self.1 += o.1;
    }
    fn eval(&self, p: DVec3) -> f64 {
        let q = &self.0;
        let (x, y, z) = (p.x, p.y, p.z);
        (q[0] * x * x
            + q[4] * y * y
            + q[7] * z * z
            + 2.0 * (q[1] * x * y + q[2] * x * z + q[5] * y * z)
            + 2.0 * (q[3] * x + q[6] * y + q[8] * z)
            + q[9])
            .max(0.0)
            / self.1.max(f64::MIN_POSITIVE)
    }
}

/// Priority key: tier (0 normal, 1 flips a normal), then cost, then the removed end's cornerness.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Key {
    tier: u8,
    cost: f64,
    tie: f64,
}

impl Key {
    fn cmp_key(&self, o: &Self) -> Ordering {
        self.tier
            .cmp(&o.tier)
            .then(self.cost.total_cmp(&o.cost))
            .then(self.tie.total_cmp(&o.tie))
    }
}

/// Seams whose faces meet at this angle or more are creases, not texture seams on a smooth
/// surface (quadric cost).
const CREASE_DEGREES: f64 = 30.0;

/// Tier of a collapse that moves a border or seam vertex off its feature (quadric).
const TIER_FEATURE: u8 = 1;
/// Tier of a collapse that flips a moving triangle.
const TIER_FLIP: u8 = 2;

/// One heap entry: a position, its best collapse target and that collapse's key.
#[derive(Debug, Clone, Copy, PartialEq)]
struct HeapEntry {
    key: Key,
    pos: u32,
    target: u32,
}

impl HeapEntry {
    /// Heap order: key, then the lower position (deterministic).
    fn less(&self, o: &Self) -> bool {
        match self.key.cmp_key(&o.key) {
            Ordering::Less => true,
            Ordering::Greater => false,
            Ordering::Equal => (self.pos, self.target) < (o.pos, o.target),
        }
    }
}

/// An indexed binary min-heap of positions by their best collapse: one entry per position,
/// updated in place (no stale entries to skip). Entries hold their keys, so sifting reads the
/// heap array only.
struct PosHeap {
    heap: Vec<HeapEntry>,
    slot: Vec<u32>,
}

const NO_SLOT: u32 = u32::MAX;

impl PosHeap {
    fn new(n: usize) -> Self {
        PosHeap {
            heap: Vec::with_capacity(n),
            slot: vec![NO_SLOT; n],
        }
    }

    fn swap(&mut self, i: usize, j: usize) {
        self.heap.swap(i, j);
        self.slot[self.heap[i].pos as usize] = i as u32;
        self.slot[self.heap[j].pos as usize] = j as u32;
    }

    fn up(&mut self, mut i: usize) {
        while i > 0 {
            let parent = (i - 1) / 2;
            if !self.heap[i].less(&self.heap[parent]) {
                break;
            }
            self.swap(i, parent);
            i = parent;
        }
    }

    fn down(&mut self, mut i: usize) {
        loop {
            let (l, r) = (2 * i + 1, 2 * i + 2);
            let mut m = i;
            if l < self.heap.len() && self.heap[l].less(&self.heap[m]) {
                m = l;
            }
            if r < self.heap.len() && self.heap[r].less(&self.heap[m]) {
                m = r;
            }
            if m == i {
                break;
            }
            self.swap(i, m);
            i = m;
        }
    }

    /// Inserts or updates position `p`'s entry (nothing moves when it is unchanged).
    fn set(&mut self, p: u32, key: Key, target: u32) {
        let entry = HeapEntry {
            key,
            pos: p,
            target,
        };
        let s = self.slot[p as usize];
        if s == NO_SLOT {
            self.heap.push(entry);
            let i = self.heap.len() - 1;
            self.slot[p as usize] = i as u32;
            self.up(i);
        } else if self.heap[s as usize] != entry {
            self.heap[s as usize] = entry;
            self.up(s as usize);
            self.down(self.slot[p as usize] as usize);
        }
    }

    fn remove(&mut self, p: u32) {
        let s = self.slot[p as usize];
        if s == NO_SLOT {
            return;
        }
        let i = s as usize;
        let last = self.heap.len() - 1;
        self.swap(i, last);
        self.heap.pop();
        self.slot[p as usize] = NO_SLOT;
        if i < self.heap.len() {
            self.up(i);
            self.down(self.slot[self.heap[i].pos as usize] as usize);
        }
    }

    fn peek(&self) -> Option<(u32, Key, u32)> {
        let e = self.heap.first()?;
        Some((e.pos, e.key, e.target))
    }
}

/// Per-position facts shared by the evaluation of all its candidate collapses.
struct Context {
    corner: f64,
    on_border: bool,
    on_seam: bool,
}

/// Reused buffers (no allocation per evaluation).
#[derive(Default)]
struct Scratch {
    neighbours: Vec<u32>,
    uses: Vec<u32>,
    vanish: Vec<DVec3>,
    moving: Vec<DVec3>,
}

struct State<'a> {
    mesh: &'a TriMesh,
    kind: CostKind,
    pos: Vec<DVec3>,
    tri_w: Vec<[u32; 3]>,
    /// The positions of `tri_w` (kept in step: read far more often than written).
    tri_p: Vec<[u32; 3]>,
    tri_alive: Vec<bool>,
    pos_tris: Vec<Vec<u32>>,
    pos_wedges: Vec<Vec<u32>>,
    pos_alive: Vec<bool>,
    quadric: Vec<Quadric>,
    /// Quadric cost: positions on a smooth (not creased) seam, see [`initial_quadrics`].
    smooth_seam: Vec<bool>,
}

impl State<'_> {
    fn tri_pos(&self, t: u32) -> [u32; 3] {
        self.tri_p[t as usize]
    }

    fn neighbours(&self, u: u32) -> Vec<u32> {
        let mut out = Vec::with_capacity(8);
        self.neighbours_into(u, &mut out);
        out
    }

    fn neighbours_into(&self, u: u32, out: &mut Vec<u32>) {
        out.clear();
        for &t in &self.pos_tris[u as usize] {
            for p in self.tri_pos(t) {
                if p != u && !out.contains(&p) {
                    out.push(p);
                }
            }
        }
    }

    /// The neighbours of `u` into `out`, and whether one of u's edges is an open border (used
    /// by exactly one triangle), in one pass over u's triangles.
    fn neighbours_and_border(&self, u: u32, out: &mut Vec<u32>, uses: &mut Vec<u32>) -> bool {
        out.clear();
        uses.clear();
        for &t in &self.pos_tris[u as usize] {
            for p in self.tri_pos(t) {
                if p == u {
                    continue;
                }
                if let Some(i) = out.iter().position(|&x| x == p) {
                    uses[i] += 1;
                } else {
                    out.push(p);
                    uses.push(1);
                }
            }
        }
        uses.contains(&1)
    }

    /// How much of a corner `u` is: the largest deviation of a triangle normal from the mean
    /// normal (0 on a plane, up to 2), plus 1 on an open border, plus 1 on a seam.
    fn cornerness(&self, u: u32, on_border: bool) -> f64 {
        let tris = &self.pos_tris[u as usize];
        let mut mean = DVec3::ZERO;
        let mut normals = Vec::with_capacity(tris.len());
        for &t in tris {
            let [a, b, c] = self.tri_pos(t).map(|p| self.pos[p as usize]);
            let n = area_normal(a, b, c);
            mean += n;
            normals.push(n.normalize_or_zero());
        }
        let mean = mean.normalize_or_zero();
        let mut c = normals
            .iter()
            .map(|n| 1.0 - n.dot(mean))
            .fold(0.0f64, f64::max);
        if on_border {
            c += 1.0;
        }
        if self.pos_wedges[u as usize].len() > 1 {
            c += 1.0;
        }
        c
    }

    /// The key of collapsing u onto v. `corner_u` is u's [`State::cornerness`] (longest-edge
    /// cost only), `border_u` whether u lies on an open border, `edge_kind` whether (u, v) is a
    /// border or seam edge, `seam_u` whether u has several wedges.
    fn evaluate(
        &self,
        u: u32,
        v: u32,
        ctx: &Context,
        scratch: &mut Scratch,
        check_flips: bool,
    ) -> Key {
        let pu = self.pos[u as usize];
        let pv = self.pos[v as usize];
        let mut flips = false;
        let mut longest = 0.0f64;
        scratch.vanish.clear();
        scratch.moving.clear();
        let mut vanish_count = 0usize;
        // The quadric needs the triangles only for the flip test and the feature rule.
        let scan = check_flips || self.kind != CostKind::Quadric || ctx.on_border || ctx.on_seam;
        let tris: &[u32] = if scan {
            &self.pos_tris[u as usize]
        } else {
            &[]
        };
        for &t in tris {
            let tp = self.tri_pos(t);
            let [a, b, c] = tp.map(|p| self.pos[p as usize]);
            let n0 = area_normal(a, b, c);
            if tp.contains(&v) {
                vanish_count += 1;
                if self.kind == CostKind::LongestEdge {
                    longest = longest
                        .max((b - a).length_squared())
                        .max((c - b).length_squared())
                        .max((a - c).length_squared());
                }
                if self.kind == CostKind::Melax {
                    scratch.vanish.push(n0.normalize_or_zero());
                }
            } else {
                if check_flips && !flips {
                    let moved = tp.map(|p| if p == u { pv } else { self.pos[p as usize] });
                    let n1 = area_normal(moved[0], moved[1], moved[2]);
                    let l0 = n0.length_squared();
                    if l0 > 0.0 {
                        let d = n0.dot(n1);
                        if d <= 0.0 || d * d <= FLIP_COS * FLIP_COS * l0 * n1.length_squared() {
                            flips = true;
                        }
                    }
                }
                if self.kind == CostKind::Melax {
                    scratch.moving.push(n0.normalize_or_zero());
                }
            }
        }
        let mut tier = if flips { TIER_FLIP } else { 0 };
        let cost = match self.kind {
            CostKind::LongestEdge => longest.sqrt(),
            CostKind::Quadric => {
                // Border and seam vertices move only along their border or seam (they may
                // still leave it once nothing else is left).
                if (ctx.on_border || ctx.on_seam) && !self.is_feature_edge(u, v, vanish_count) {
                    tier = tier.max(TIER_FEATURE);
                }
                self.quadric[u as usize].eval(pv)
            }
            CostKind::Melax => {
                let mut curvature = 0.0f64;
                for n in scratch.moving.iter().chain(&scratch.vanish) {
                    let mut least = 1.0f64;
                    for s in &scratch.vanish {
                        least = least.min((1.0 - n.dot(*s)) / 2.0);
                    }
                    curvature = curvature.max(least);
                }
                // Melax's border rule: a border vertex moving along an interior edge would pull
                // the border in; treat it as fully curved.
                if ctx.on_border && vanish_count > 1 {
                    curvature = 1.0;
                }
                (pu - pv).length() * curvature
            }
        };
        Key {
            tier,
            cost,
            tie: ctx.corner,
        }
    }

    /// True when (u, v) is an open border edge (one triangle) or a seam edge (u's wedges differ
    /// between the triangles on either side).
    fn is_feature_edge(&self, u: u32, v: u32, triangles_on_edge: usize) -> bool {
        if triangles_on_edge == 1 {
            return true;
        }
        let mut wedge: Option<(u32, u32)> = None;
        for &t in &self.pos_tris[u as usize] {
            let tw = self.tri_w[t as usize];
            let mut wu = None;
            let mut wv = None;
            for w in tw {
                let p = self.mesh.wedge_position[w as usize];
                if p == u {
                    wu = Some(w);
                } else if p == v {
                    wv = Some(w);
                }
            }
            if let (Some(a), Some(b)) = (wu, wv) {
                match wedge {
                    None => wedge = Some((a, b)),
                    Some(x) if x != (a, b) => return true,
                    Some(_) => {}
                }
            }
        }
        false
    }

    /// The cheapest collapse of `u`; flips are tested only with `check_flips` (otherwise when
    /// the collapse is about to be made).
    fn best(&self, u: u32, scratch: &mut Scratch, check_flips: bool) -> Option<(Key, u32)> {
        let mut neighbours = std::mem::take(&mut scratch.neighbours);
        let border_u = self.neighbours_and_border(u, &mut neighbours, &mut scratch.uses);
        let ctx = Context {
            corner: if self.kind == CostKind::LongestEdge {
                self.cornerness(u, border_u)
            } else {
                0.0
            },
            on_border: border_u,
            // The quadric's seam rule holds only on smooth seams.
            on_seam: self.pos_wedges[u as usize].len() > 1
                && (self.kind != CostKind::Quadric || self.smooth_seam[u as usize]),
        };
        let mut best: Option<(Key, u32)> = None;
        for &v in &neighbours {
            let k = self.evaluate(u, v, &ctx, scratch, check_flips);
            let better = match &best {
                None => true,
                Some((b, bv)) => match k.cmp_key(b) {
                    Ordering::Less => true,
                    Ordering::Equal => v < *bv,
                    Ordering::Greater => false,
                },
            };
            if better {
                best = Some((k, v));
            }
        }
        scratch.neighbours = neighbours;
        best
    }

    /// Performs the half-edge collapse u -> v: maps u's wedges, removes the triangles on the
    /// edge, moves the rest onto v.
    fn collapse(
        &mut self,
        u: u32,
        v: u32,
        step: u32,
        wedge_target: &mut [u32],
        triangle_step: &mut [u32],
    ) {
        // Split u's triangles into vanishing and moving.
        let tris_u = std::mem::take(&mut self.pos_tris[u as usize]);
        let mut vanish = Vec::new();
        let mut moving = Vec::new();
        for &t in &tris_u {
            if self.tri_pos(t).contains(&v) {
                vanish.push(t);
            } else {
                moving.push(t);
            }
        }
        // Map every wedge of u onto a wedge of v: the one it meets across a vanishing triangle,
        // else the one with the closest attributeself.
        let wedges_u = std::mem::take(&mut self.pos_wedges[u as usize]);
        for &w in &wedges_u {
            let mut target = None;
            for &t in &vanish {
                let tw = self.tri_w[t as usize];
                if tw.contains(&w) {
                    target = tw
                        .iter()
                        .copied()
                        .find(|&x| self.mesh.wedge_position[x as usize] == v);
                    break;
                }
            }
            let target = target.unwrap_or_else(|| {
                *self.pos_wedges[v as usize]
                    .iter()
                    .min_by(|&&a, &&b| {
                        attribute_distance(self.mesh, w, a)
                            .total_cmp(&attribute_distance(self.mesh, w, b))
                            .then(a.cmp(&b))
                    })
                    .expect("a live position keeps at least one wedge")
            });
            wedge_target[w as usize] = target;
        }
        for &t in &vanish {
            self.tri_alive[t as usize] = false;
            triangle_step[t as usize] = step;
            for p in self.tri_pos(t) {
                if p != u {
                    self.pos_tris[p as usize].retain(|&x| x != t);
                }
            }
        }
        for &t in &moving {
            let tw = &mut self.tri_w[t as usize];
            for w in tw.iter_mut() {
                if self.mesh.wedge_position[*w as usize] == u {
                    *w = wedge_target[*w as usize];
                }
            }
            for p in &mut self.tri_p[t as usize] {
                if *p == u {
                    *p = v;
                }
            }
            self.pos_tris[v as usize].push(t);
        }
        if self.kind == CostKind::Quadric {
            let qu = self.quadric[u as usize];
            self.quadric[v as usize].add(&qu);
        }
        self.pos_alive[u as usize] = false;
    }

    /// Whether collapsing u onto v turns a moving triangle by more than the flip angle.
    fn flips(&self, u: u32, v: u32) -> bool {
        let pv = self.pos[v as usize];
        self.pos_tris[u as usize].iter().any(|&t| {
            let tp = self.tri_pos(t);
            if tp.contains(&v) {
                return false;
            }
            let [a, b, c] = tp.map(|p| self.pos[p as usize]);
            let n0 = area_normal(a, b, c);
            let moved = tp.map(|p| if p == u { pv } else { self.pos[p as usize] });
            let n1 = area_normal(moved[0], moved[1], moved[2]);
            let l0 = n0.length_squared();
            let d = n0.dot(n1);
            l0 > 0.0 && (d <= 0.0 || d * d <= FLIP_COS * FLIP_COS * l0 * n1.length_squared())
        })
    }
}

fn attribute_distance(mesh: &TriMesh, a: u32, b: u32) -> f64 {
    let mut d = 0.0;
    if !mesh.uvs.is_empty() {
        let (x, y) = (mesh.uvs[a as usize], mesh.uvs[b as usize]);
        d += ((x[0] - y[0]) as f64).powi(2) + ((x[1] - y[1]) as f64).powi(2);
    }
    if !mesh.normals.is_empty() {
        let (x, y) = (mesh.normals[a as usize], mesh.normals[b as usize]);
        d += (0..3).map(|k| ((x[k] - y[k]) as f64).powi(2)).sum::<f64>();
    }
    d
}

/// One triangle's side of an edge: its wedges at the lower and higher position, and its normal.
type EdgeSide = (u32, u32, DVec3);

/// Initial quadrics: face planes weighted by the square root of the triangle's area (so the
/// weight grows linearly with size, as meshoptimizer does; plain area weights let fine regions
/// and silhouettes go early), plus planes through open-border and attribute-seam edges,
/// perpendicular to the face, weighted `BORDER_WEIGHT` / `SEAM_WEIGHT` x edge length (the same
/// linear scale). Seams weigh little: they matter for textures, not for the geometric error, and
/// the move-along-the-seam rule in [`State::evaluate`] already keeps them. The two weights were
/// chosen on the shared meshes (bunny: borders; spot: seams) and are reported in nodebench.
///
/// Also returns, per position, whether it lies on a *smooth* seam: a seam edge whose two faces
/// meet at less than [`CREASE_DEGREES`]. Only those keep the move-along-the-seam rule: a seam
/// on a sharp crease (a building's corners, eaves and window insets, where facade textures
/// meet) is held by the face planes on both sides, and the rule would only rank its cheap
/// collapses after costly ones elsewhere.
fn initial_quadrics(mesh: &TriMesh, pos: &[DVec3]) -> (Vec<Quadric>, Vec<bool>) {
    const BORDER_WEIGHT: f64 = 10.0;
    const SEAM_WEIGHT: f64 = 0.1;
    let crease_cos = CREASE_DEGREES.to_radians().cos();
    let mut q = vec![Quadric::default(); pos.len()];
    let mut smooth_seam = vec![false; pos.len()];
    // (edge, the wedges and normal of one side) for every triangle side; sorted by edge below
    // (stably, so each edge's sides keep triangle order) to find borders and seams.
    let mut edges: Vec<((u32, u32), EdgeSide)> = Vec::with_capacity(3 * mesh.triangles.len());
    for t in &mesh.triangles {
        let p = t.map(|w| mesh.wedge_position[w as usize]);
        let [a, b, c] = p.map(|i| pos[i as usize]);
        let n2 = area_normal(a, b, c);
        let area = n2.length() / 2.0;
        let n = n2.normalize_or_zero();
        let plane = Quadric::plane(n, -n.dot(a), area.sqrt());
        for &i in &p {
            q[i as usize].add(&plane);
        }
        for k in 0..3 {
            let (i, j) = (p[k], p[(k + 1) % 3]);
            let key = (i.min(j), i.max(j));
            let (wi, wj) = if i < j {
                (t[k], t[(k + 1) % 3])
            } else {
                (t[(k + 1) % 3], t[k])
            };
            edges.push((key, (wi, wj, n)));
        }
    }
    edges.sort_by_key(|e| e.0);
    for group in edges.chunk_by(|x, y| x.0 == y.0) {
        let key = group[0].0;
        let side0 = group[0].1;
        let border = group.len() == 1;
        let seam = group.iter().any(|(_, s)| s.0 != side0.0 || s.1 != side0.1);
        if !border && !seam {
            continue;
        }
        let sharp = group.len() == 2 && group[0].1.2.dot(group[1].1.2) < crease_cos;
        if seam && !sharp {
            smooth_seam[key.0 as usize] = true;
            smooth_seam[key.1 as usize] = true;
        }
        let (a, b) = (pos[key.0 as usize], pos[key.1 as usize]);
        let e = b - a;
        for (_, s) in group {
            let m = e.cross(s.2).normalize_or_zero();
            if m == DVec3::ZERO {
                continue;
            }
            let weight = if border { BORDER_WEIGHT } else { SEAM_WEIGHT };
            let plane = Quadric::plane(m, -m.dot(a), weight * e.length());
            q[key.0 as usize].add(&plane);
            q[key.1 as usize].add(&plane);
        }
    }
    (q, smooth_seam)
}

/// Computes the full collapse order of `mesh` with cost `kind`. `progress` is called with the
/// number of collapses done so far (every 1024).
pub fn collapse_order(
    mesh: &TriMesh,
    kind: CostKind,
    progress: &mut dyn FnMut(usize),
) -> CollapseOrder {
    let np = mesh.positions.len();
    let pos: Vec<DVec3> = mesh.positions.iter().map(|&p| v3(p)).collect();
    let mut pos_tris = vec![Vec::new(); np];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        for &w in tri {
            pos_tris[mesh.wedge_position[w as usize] as usize].push(t as u32);
        }
    }
    let mut pos_wedges = vec![Vec::new(); np];
    for (w, &p) in mesh.wedge_position.iter().enumerate() {
        pos_wedges[p as usize].push(w as u32);
    }
    let (quadric, smooth_seam) = if kind == CostKind::Quadric {
        initial_quadrics(mesh, &pos)
    } else {
        (Vec::new(), Vec::new())
    };
    let mut s = State {
        mesh,
        kind,
        pos,
        tri_w: mesh.triangles.clone(),
        tri_p: mesh.position_triangles(),
        tri_alive: vec![true; mesh.triangles.len()],
        pos_tris,
        pos_wedges,
        pos_alive: vec![true; np],
        quadric,
        smooth_seam,
    };
    let mut wedge_target = vec![u32::MAX; mesh.wedge_position.len()];
    let mut triangle_step = vec![0u32; mesh.triangles.len()];
    let mut collapses: Vec<Collapse> = Vec::with_capacity(np.saturating_sub(1));
    let mut heap = PosHeap::new(np);
    let mut scratch = Scratch::default();
    // Whether a position's entry was evaluated with flip tests (else they run on pop).
    let mut checked = vec![false; np];
    let refresh =
        |s: &State<'_>, heap: &mut PosHeap, scratch: &mut Scratch, p: u32, check: bool| match s
            .best(p, scratch, check)
        {
            Some((key, v)) => heap.set(p, key, v),
            None => heap.remove(p),
        };
    for u in 0..np as u32 {
        refresh(&s, &mut heap, &mut scratch, u, false);
    }

    let mut alive = np;
    while alive > 1 {
        let Some((u, key, v)) = heap.peek() else {
            break;
        };
        if !checked[u as usize] && s.flips(u, v) {
            // The cheapest collapse of u flips a triangle: rank u by its best collapse with
            // flips tested (a flipping one only when every one of u's flips).
            checked[u as usize] = true;
            refresh(&s, &mut heap, &mut scratch, u, true);
            continue;
        }
        heap.remove(u);
        let step = collapses.len() as u32 + 1;
        // Only v and u's neighbours see their triangles change: every other position keeps its
        // triangles, its quadric and its neighbours' positions (v does not move), so its best
        // collapse stays what it was and is not evaluated again.
        let touched = s.neighbours(u);
        s.collapse(u, v, step, &mut wedge_target, &mut triangle_step);
        alive -= 1;
        collapses.push(Collapse {
            removed: u,
            kept: v,
            cost: key.cost,
            flags: if key.tier >= TIER_FLIP {
                FLAG_FLIPPED
            } else {
                0
            },
        });
        for p in touched {
            checked[p as usize] = false;
            refresh(&s, &mut heap, &mut scratch, p, false);
        }
        if collapses.len().is_multiple_of(1024) {
            progress(collapses.len());
        }
    }
    // Isolated leftovers (last points of disconnected parts): onto the survivor, farthest first.
    let mut left: Vec<u32> = (0..np as u32)
        .filter(|&p| s.pos_alive[p as usize])
        .collect();
    let survivor = if left.is_empty() {
        0
    } else {
        let (lo, hi) = mesh.bounds();
        let centre = (v3(lo) + v3(hi)) / 2.0;
        let keep = *left
            .iter()
            .min_by(|&&a, &&b| {
                (s.pos[a as usize] - centre)
                    .length_squared()
                    .total_cmp(&(s.pos[b as usize] - centre).length_squared())
                    .then(a.cmp(&b))
            })
            .expect("non-empty");
        left.retain(|&p| p != keep);
        let pk = s.pos[keep as usize];
        left.sort_by(|&a, &b| {
            (s.pos[b as usize] - pk)
                .length_squared()
                .total_cmp(&(s.pos[a as usize] - pk).length_squared())
                .then(a.cmp(&b))
        });
        let keep_wedge = s.pos_wedges[keep as usize][0];
        for u in left {
            for &w in &s.pos_wedges[u as usize] {
                wedge_target[w as usize] = keep_wedge;
            }
            collapses.push(Collapse {
                removed: u,
                kept: keep,
                cost: (s.pos[u as usize] - pk).length(),
                flags: FLAG_ISOLATED,
            });
        }
        keep
    };
    progress(collapses.len());
    CollapseOrder {
        kind,
        collapses,
        wedge_target,
        triangle_step,
        survivor,
    }
}
