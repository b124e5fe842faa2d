//! Section `error`: triangles against measured on-screen error for the grid, the TIN and a
//! CDLOD-style distance selection.

use crate::plot::CurvePoint;
use crate::report::{Report, bar};
use engine::camera::Camera;
use engine::measure::{self, ScreenRegion, ViewError};
use engine::surface::World;
use engine::terrain::bounds::{BoundsCache, NodeBounds};
use engine::terrain::mesh::{self, NodeMesh};
use engine::terrain::quadtree::{NodeKey, QuadTree};
use engine::terrain::select::{SelectParams, Selection, select};
use engine::terrain::tiles::TileCache;
use engine::terrain::tin;

/// Dense error samples per quad for the measured max error: 2 per quad, offset off the vertices
/// and the bounds' check lattice.
const MAX_SAMPLES_PER_QUAD: u32 = 2;

/// The sample key of a node's TIN (grids use their decimation).
const TIN: u8 = u8::MAX;

/// Cached entries (meshes and sample sets together) above which [`MeshCache`] starts over. The
/// finest distance ratios the baseline tuning tries select hundreds of thousands of nodes, whose
/// meshes and samples (about 100 KiB a node) would not fit in memory: a run on the 8 km map
/// passed 21 GiB without this.
const MAX_CACHED_ENTRIES: usize = 40_000;

/// Node meshes (grid and TIN) and their dense error samples, built once and reused across
/// thresholds and bisection steps while they fit under [`MAX_CACHED_ENTRIES`].
#[derive(Default)]
struct MeshCache {
    grid: std::collections::HashMap<NodeKey, NodeMesh>,
    tin: std::collections::HashMap<NodeKey, NodeMesh>,
    /// Keyed by node and what is drawn: the grid's decimation, or [`TIN`].
    samples: std::collections::HashMap<(NodeKey, u8), measure::ErrorSamples>,
}

impl MeshCache {
    /// Starts over when over [`MAX_CACHED_ENTRIES`] (everything here is a pure function of the
    /// node: dropping it costs time, never a different figure).
    fn trim(&mut self) {
        if self.grid.len() + self.tin.len() + self.samples.len() > MAX_CACHED_ENTRIES {
            self.grid.clear();
            self.tin.clear();
            self.samples.clear();
        }
    }

    fn grid(
        &mut self,
        world: &World,
        tree: &QuadTree,
        cache: &mut BoundsCache,
        tiles: &mut TileCache,
        key: NodeKey,
    ) -> &NodeMesh {
        self.grid
            .entry(key)
            .or_insert_with(|| mesh::build_with_tiles(world, tree, cache, tiles, key))
    }

    fn tin(
        &mut self,
        world: &World,
        tree: &QuadTree,
        cache: &mut BoundsCache,
        tiles: &mut TileCache,
        key: NodeKey,
        target: f64,
    ) -> &NodeMesh {
        if !self.tin.contains_key(&key) {
            let g = self.grid(world, tree, cache, tiles, key);
            let t = tin::build(g, target * g.bounds.error_m).0;
            self.tin.insert(key, t);
        }
        &self.tin[&key]
    }
}

/// A view's measured error: on the screen (through the camera's matrices) and in the pixel
/// metric's on-axis model (the former measure, kept for comparison).
#[derive(Debug, Clone, Copy, Default)]
struct Measured {
    triangles: usize,
    screen: ViewError,
    on_axis: ViewError,
}

/// How much a measurement finds: the on-screen max only (tuning the baseline), or everything.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Detail {
    MaxOnly,
    Full,
}

/// Builds meshes for a selection (optionally as TINs) and measures the view's pixel error: the
/// max over dense samples ([`MAX_SAMPLES_PER_QUAD`] per quad), p99.9 and mean over `per_side^2`
/// points per node; on the screen, and with [`Detail::Full`] by screen region and in the
/// on-axis model too.
fn measure_view(
    world: &World,
    tree: &QuadTree,
    ctx: &mut (BoundsCache, TileCache, MeshCache),
    cam: &Camera,
    sel: &Selection,
    per_side: u32,
    tin_target: Option<f64>,
    detail: Detail,
) -> Measured {
    let (cache, tiles, meshes_cache) = ctx;
    meshes_cache.trim();
    let mut meshes = Vec::with_capacity(sel.nodes.len());
    let mut tris = 0;
    let kind = |s: &engine::terrain::select::Selected| {
        if tin_target.is_some() {
            TIN
        } else {
            s.decimation
        }
    };
    for s in &sel.nodes {
        // Each grid node as drawn: through every 2^decimation-th vertex.
        let m = match tin_target {
            Some(f) => meshes_cache
                .tin(world, tree, cache, tiles, s.key, f)
                .clone(),
            None => meshes_cache
                .grid(world, tree, cache, tiles, s.key)
                .decimated(s.decimation),
        };
        tris += m.indices.len() / 3;
        meshes_cache
            .samples
            .entry((s.key, kind(s)))
            .or_insert_with(|| measure::node_error_samples(world, tree, &m, MAX_SAMPLES_PER_QUAD));
        meshes.push(m);
    }
    let mut screen = measure::view_error(world, tree, &meshes, cam, per_side);
    let samples: Vec<_> = sel
        .nodes
        .iter()
        .map(|s| &meshes_cache.samples[&(s.key, kind(s))])
        .collect();
    let dense = measure::view_max_error_px(&samples, cam, detail == Detail::Full);
    screen.max_px = screen.max_px.max(dense.max_px);
    for (r, d) in screen.region_max_px.iter_mut().zip(dense.region_max_px) {
        *r = r.max(d);
    }
    let mut on_axis = ViewError::default();
    if detail == Detail::Full {
        on_axis = measure::view_error_on_axis(world, tree, &meshes, cam, per_side);
        on_axis.max_px = on_axis
            .max_px
            .max(measure::view_max_error_on_axis_px(&samples, cam));
    }
    Measured {
        triangles: tris,
        screen,
        on_axis,
    }
}

/// Selection where each node's error bound is that of its TIN (grid error + exact TIN delta),
/// so the TIN variant is held to the same threshold honestly.
fn select_tin(
    world: &World,
    tree: &QuadTree,
    ctx: &mut (BoundsCache, TileCache, MeshCache),
    cam: &Camera,
    tau: f64,
    target: f64,
) -> Selection {
    // Both closures need the caches, one after the other; the TIN is built only for nodes that
    // survive culling.
    let ctx = std::cell::RefCell::new(ctx);
    let (screen, frustum) = (
        engine::terrain::select::ScreenBound::new(cam),
        cam.frustum(),
    );
    engine::terrain::select::traverse(
        tree,
        cam,
        true,
        |key| ctx.borrow_mut().0.get(world, tree, key),
        |key, _, _, _| {
            let mut c = ctx.borrow_mut();
            let (cache, tiles, meshes) = &mut **c;
            let b = meshes.tin(world, tree, cache, tiles, key, target).bounds;
            engine::terrain::select::projected_error_px(tree, key, &b, &screen, Some(&frustum), 0.0)
                > tau
        },
    )
}

/// The grid selection with the vegetation term left out of the split test (what the terrain
/// alone needs, and how close to tau its bounds let it draw), measured.
fn terrain_only(
    world: &World,
    tree: &QuadTree,
    ctx: &mut (BoundsCache, TileCache, MeshCache),
    cam: &Camera,
    tau: f64,
    per_side: u32,
) -> Measured {
    let mut sel = engine::terrain::select::traverse(
        tree,
        cam,
        true,
        |key| NodeBounds {
            vegetation_error_m: 0.0,
            ..ctx.0.get(world, tree, key)
        },
        |_, _, _, px| px > tau,
    );
    // Drawn like the full selection: each node as coarsely as its ancestors' bounds allow.
    let screen = engine::terrain::select::ScreenBound::new(cam);
    engine::terrain::select::decimate(&mut sel, tree, &screen, tau, |k| {
        Some(ctx.0.get(world, tree, k))
    });
    measure_view(world, tree, ctx, cam, &sel, per_side, None, Detail::Full)
}

/// What section error measures beyond our grid at the first view setting: the TIN and the tuned
/// CDLOD-style baseline (the speed-against-error curve); other view settings measure the grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Extent {
    WithBaselines,
    GridOnly,
}

/// The rows of one variant's measured error at one threshold, over the cameras: triangles per
/// frame, on-screen max / p99.9 / mean and max by region, and (when `on_axis`) the on-axis
/// model's max and mean.
#[derive(Debug, Default)]
struct Totals {
    triangles: f64,
    screen_max: f64,
    screen_p999: f64,
    screen_mean: f64,
    region_max: [f64; 3],
    axis_max: f64,
    axis_mean: f64,
}

impl Totals {
    fn add(&mut self, m: &Measured, cameras: usize) {
        let n = cameras as f64;
        self.triangles += m.triangles as f64 / n;
        self.screen_max = self.screen_max.max(m.screen.max_px);
        self.screen_p999 = self.screen_p999.max(m.screen.p999_px);
        self.screen_mean += m.screen.mean_px / n;
        for (r, v) in self.region_max.iter_mut().zip(m.screen.region_max_px) {
            *r = r.max(v);
        }
        self.axis_max = self.axis_max.max(m.on_axis.max_px);
        self.axis_mean += m.on_axis.mean_px / n;
    }

    /// Rows for variant `what` (e.g. "grid"): the on-screen ones, and the on-axis ones when
    /// `on_axis`.
    fn rows(&self, r: &mut Report, what: &str, params: &str, on_axis: bool) {
        r.add(
            "error",
            &format!("{what} triangles per frame"),
            self.triangles,
            "triangles",
            params,
        );
        for (name, value) in [
            ("max", self.screen_max),
            ("p99.9", self.screen_p999),
            ("mean", self.screen_mean),
        ] {
            r.add(
                "error",
                &format!("{what} on-screen measured {name} error"),
                value,
                "px",
                params,
            );
        }
        for region in ScreenRegion::ALL {
            r.add(
                "error",
                &format!("{what} on-screen max error, {}", region.name()),
                self.region_max[region as usize],
                "px",
                params,
            );
        }
        if on_axis {
            r.add(
                "error",
                &format!("{what} measured max error (the metric's on-axis model)"),
                self.axis_max,
                "px",
                params,
            );
            r.add(
                "error",
                &format!("{what} measured mean error (the metric's on-axis model)"),
                self.axis_mean,
                "px",
                params,
            );
        }
    }
}

/// Section error for the cameras `cams` (whose field of view and aspect `view` names): our grid
/// selection measured on the screen at each threshold, the former on-axis bound's selection
/// measured the same way, the terrain-only split, and with [`Extent::WithBaselines`] the TIN and
/// the tuned CDLOD-style baseline, returning the speed-against-error curve (on-screen max).
pub(crate) fn section_error(
    world: &World,
    tree: &QuadTree,
    cams: &[Camera],
    view: &str,
    extent: Extent,
    r: &mut Report,
    quick: bool,
) -> Vec<CurvePoint> {
    let taus: &[f64] = if quick {
        &[2.0, 8.0]
    } else {
        &[0.5, 1.0, 2.0, 4.0, 8.0]
    };
    let n_cams = if quick { 1 } else { 4 };
    let step = (cams.len() / n_cams).max(1);
    let all = cams;
    let cams: Vec<Camera> = all.iter().step_by(step).take(n_cams).copied().collect();
    // The baseline is tuned on other cameras of the same flight (half a step further) and scored
    // on the same cameras as ours, so it is not fitted to the views it is judged on.
    let tune_cams: Vec<Camera> = all
        .iter()
        .skip((step / 2).max(1))
        .step_by(step)
        .take(n_cams)
        .copied()
        .collect();
    let per_side = if quick { 12 } else { 24 };
    let tin_target = 0.5;
    let baselines = extent == Extent::WithBaselines;
    let mut ctx = (BoundsCache::new(), TileCache::new(), MeshCache::default());
    let mut curve = Vec::new();
    let b = bar((taus.len() * cams.len()) as u64, "speed vs error");
    for &tau in taus {
        let params = format!(
            "tau {tau} px, {view}, {} cameras, max over {MAX_SAMPLES_PER_QUAD}² samples per quad, \
             p99.9 and mean over {per_side}² per node",
            cams.len()
        );
        let (mut grid, mut axis_bound, mut terrain, mut tin) = (
            Totals::default(),
            Totals::default(),
            Totals::default(),
            Totals::default(),
        );
        let full = |world, tree, ctx: &mut _, cam, sel: &Selection, tin| {
            measure_view(world, tree, ctx, cam, sel, per_side, tin, Detail::Full)
        };
        for cam in &cams {
            let p = SelectParams::culled(tau, tree);
            let sel = select(world, tree, &mut ctx.0, cam, p);
            grid.add(&full(world, tree, &mut ctx, cam, &sel, None), cams.len());
            let former = SelectParams {
                off_axis: false,
                ..p
            };
            let sel = select(world, tree, &mut ctx.0, cam, former);
            axis_bound.add(&full(world, tree, &mut ctx, cam, &sel, None), cams.len());
            terrain.add(
                &terrain_only(world, tree, &mut ctx, cam, tau, per_side),
                cams.len(),
            );
            if baselines {
                let sel_t = select_tin(world, tree, &mut ctx, cam, tau, tin_target);
                let m = full(world, tree, &mut ctx, cam, &sel_t, Some(tin_target));
                tin.add(&m, cams.len());
            }
            b.inc(1);
        }
        grid.rows(r, "grid", &params, true);
        axis_bound.rows(r, "grid with the on-axis bound", &params, true);
        r.add(
            "error",
            "grid, terrain error only: triangles per frame",
            terrain.triangles,
            "triangles",
            &params,
        );
        r.add(
            "error",
            "grid, terrain error only: on-screen measured max error",
            terrain.screen_max,
            "px",
            &params,
        );
        if !baselines {
            continue;
        }
        tin.rows(r, "TIN", &params, false);
        let nc = cams.len() as f64;
        let g_max = grid.screen_max;
        let baseline = tune_baseline(
            world,
            tree,
            &mut ctx,
            (&tune_cams, &cams),
            per_side,
            g_max,
            quick,
        );
        let best = baseline.scored;
        let hi = baseline.ratio;
        // The baseline's rows claim "at most our measured max error" only where it holds on
        // the scored cameras; otherwise the params say that it misses.
        let verdict = baseline.verdict(g_max);
        let bparams = format!(
            "{params}, ratio {hi:.2} tuned on {} other cameras, {verdict}",
            tune_cams.len()
        );
        for (what, value, unit) in [
            (
                "CDLOD-style triangles per frame",
                best.0 as f64 / nc,
                "triangles",
            ),
            ("CDLOD-style on-screen measured max error", best.1, "px"),
            ("CDLOD-style on-screen measured mean error", best.2, "px"),
            (
                "CDLOD-style meets our on-screen measured max error (1 yes, 0 no)",
                f64::from(u8::from(baseline.bracketed && best.1 <= g_max)),
                "bool",
            ),
        ] {
            r.add("error", what, value, unit, &bparams);
        }
        curve.push(CurvePoint {
            method: "grid (ours)",
            triangles: grid.triangles,
            max_px: g_max,
        });
        curve.push(CurvePoint {
            method: "TIN (ours)",
            triangles: tin.triangles,
            max_px: tin.screen_max,
        });
        curve.push(CurvePoint {
            method: "CDLOD-style distance",
            triangles: best.0 as f64 / nc,
            max_px: best.1,
        });
    }
    b.finish_and_clear();
    curve
}

/// Nodes a view of the CDLOD-style baseline may select while tuning (each a 33 x 33 grid: 2,048
/// triangles, so 12,000 nodes are 25 M triangles a frame); a wider ratio is not tried. Without
/// a limit the widest ratios selected most of the 8 km map's million leaf nodes and ran out of
/// 24 GiB of memory.
const MAX_BASELINE_NODES: usize = 12_000;

/// The tuned CDLOD-style baseline: its distance ratio, whether tuning found a ratio that meets
/// the target, and (triangles, max px, mean px) on the scored cameras.
struct Baseline {
    ratio: f64,
    bracketed: bool,
    scored: (usize, f64, f64),
}

impl Baseline {
    /// Whether the baseline reaches our measured max error `ours_px`, in words for the params.
    fn verdict(&self, ours_px: f64) -> String {
        if self.bracketed && self.scored.1 <= ours_px {
            "meets our max error".to_string()
        } else if self.bracketed {
            "MISSES our max error on the scored cameras".to_string()
        } else {
            format!(
                "MISSES: no ratio up to 256 with at most {MAX_BASELINE_NODES} nodes a view \
                 reaches our max error on the tuning cameras"
            )
        }
    }
}

/// Finds the smallest distance ratio whose measured max error on the tuning cameras is at most
/// `target_px` (error falls as the ratio grows): both ends of the bracket are checked and
/// widened when needed, then bisected; the ratio is then scored on the other cameras.
fn tune_baseline(
    world: &World,
    tree: &QuadTree,
    ctx: &mut (BoundsCache, TileCache, MeshCache),
    (tune, score): (&[Camera], &[Camera]),
    per_side: u32,
    target_px: f64,
    quick: bool,
) -> Baseline {
    // (triangles, max px, mean px) over `cams`; None when a view selects more than
    // `node_limit` nodes (the tuning stops widening there: memory, and no useful baseline).
    let mut measure_ratio = |ratio: f64, cams: &[Camera], node_limit: usize| {
        let nc = cams.len().max(1) as f64;
        let (mut tris, mut mx, mut mean) = (0usize, 0.0f64, 0.0f64);
        for cam in cams {
            let sel = measure::select_by_distance(world, tree, &mut ctx.0, cam, ratio);
            if sel.nodes.len() > node_limit {
                return None;
            }
            let m = measure_view(world, tree, ctx, cam, &sel, per_side, None, Detail::MaxOnly);
            tris += m.triangles;
            mx = mx.max(m.screen.max_px);
            mean += m.screen.mean_px / nc;
        }
        Some((tris, mx, mean))
    };
    let meets = |m: Option<(usize, f64, f64)>| m.is_some_and(|m| m.1 <= target_px);
    let (mut lo, mut hi) = (0.25f64, 32.0f64);
    // The upper end must meet the target, the lower end must miss it.
    let mut top = measure_ratio(hi, tune, MAX_BASELINE_NODES);
    while top.is_none() && hi > 1.0 / 64.0 {
        hi *= 0.5;
        top = measure_ratio(hi, tune, MAX_BASELINE_NODES);
    }
    while top.is_some() && !meets(top) && hi < 256.0 {
        let wider = measure_ratio(hi * 2.0, tune, MAX_BASELINE_NODES);
        if wider.is_none() {
            break;
        }
        hi *= 2.0;
        top = wider;
    }
    let bracketed = meets(top);
    lo = lo.min(hi * 0.5);
    while bracketed && meets(measure_ratio(lo, tune, MAX_BASELINE_NODES)) && lo > 1.0 / 64.0 {
        hi = lo;
        lo *= 0.5;
    }
    if bracketed {
        for _ in 0..if quick { 5 } else { 8 } {
            let mid = (lo * hi).sqrt();
            if meets(measure_ratio(mid, tune, MAX_BASELINE_NODES)) {
                hi = mid;
            } else {
                lo = mid;
            }
        }
    }
    Baseline {
        ratio: hi,
        bracketed,
        // Scored at a ratio the tuning views held within the limit: the other cameras of the
        // same flight select about as many nodes.
        scored: measure_ratio(hi, score, usize::MAX).unwrap_or_default(),
    }
}
