//! Section `pm`: the progressive-mesh builder on the shared meshes. Build throughput of each
//! cost and of meshoptimizer's `simplify` (the measured reference), the measured two-sided error
//! at 50, 10, 1 and 0.1 % of the triangles for each, the per-instance index rebuild rate and the
//! bytes of PM data per input triangle. Errors are measured with the same dense two-sided
//! Hausdorff measurement for every method (`worldgen::pm::measure`), relative to the diagonal.

use crate::report::{Report, bar};
use std::path::Path;
use std::time::Instant;
use worldgen::pm::build::collapse_order;
use worldgen::pm::measure::{hausdorff, level_soup, mesh_soup, soup};
use worldgen::pm::{CostKind, PmEdits, PmInstance, PmMesh, TriMesh, file, obj};

/// Shares of the input triangles at which errors are compared (the table rows).
const TABLE_SHARES: [f64; 4] = [0.5, 0.1, 0.01, 0.001];
/// Extra shares for the plot.
const PLOT_SHARES: [f64; 3] = [0.25, 0.03, 0.003];
/// Measurement sample spacing, fraction of the diagonal.
const MEASURE_FRACTION: f64 = 0.001;
/// Runs of each collapse order; the row gives the median (this machine's speed varies from run
/// to run) and the range.
const ORDER_RUNS: usize = 5;
/// Error-bound sample spacing of the builds (the `worldgen pm` default).
const BOUND_FRACTION: f64 = 0.005;

pub(crate) use apps::plot::Curve as PmCurve;

fn meshopt_simplify(mesh: &TriMesh, target_triangles: usize) -> (Vec<[f32; 3]>, Vec<u32>, f64) {
    let verts: Vec<[f32; 3]> = (0..mesh.wedge_position.len() as u32)
        .map(|w| mesh.wedge_xyz(w))
        .collect();
    let bytes: Vec<u8> = verts
        .iter()
        .flatten()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let indices: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    let Ok(adapter) = meshopt::VertexDataAdapter::new(&bytes, 12, 0) else {
        return (verts, Vec::new(), 0.0);
    };
    let t0 = Instant::now();
    let out = meshopt::simplify(
        &indices,
        &adapter,
        target_triangles * 3,
        1.0,
        meshopt::SimplifyOptions::None,
        None,
    );
    let secs = t0.elapsed().as_secs_f64();
    (verts, out, secs)
}

#[allow(clippy::too_many_lines)]
pub(crate) fn section_pm(meshes: &Path, r: &mut Report, quick: bool) -> Vec<PmCurve> {
    let names: &[&str] = if quick {
        &["cow.obj"]
    } else {
        &["cow.obj", "spot.obj", "stanford-bunny.obj"]
    };
    let mut curves = Vec::new();
    for name in names {
        let path = meshes.join(name);
        let (mesh, _) = match obj::load(&path) {
            Ok(m) => m,
            Err(e) => {
                eprintln!("pm: {e}; mesh left out");
                continue;
            }
        };
        let tris = mesh.triangles.len();
        let diag = mesh.diagonal() as f64;
        let spacing = diag * MEASURE_FRACTION;
        let full = mesh_soup(&mesh);
        let mut shares: Vec<f64> = TABLE_SHARES.iter().chain(&PLOT_SHARES).copied().collect();
        shares.sort_by(|a, b| b.total_cmp(a));
        let b = bar((CostKind::ALL.len() + 1) as u64, &format!("pm {name}"));
        let mut meshopt_err = Vec::new();
        let mut quadric_pm = None;
        for cost in CostKind::ALL {
            let (pm, times) = PmMesh::build(&mesh, cost, BOUND_FRACTION, &mut |_, _, _| {});
            // The order alone, ORDER_RUNS times in all (the build's and more): the median.
            let mut order_s = vec![times.collapse_s];
            for _ in 1..ORDER_RUNS {
                let t0 = Instant::now();
                std::hint::black_box(collapse_order(&mesh, cost, &mut |_| {}));
                order_s.push(t0.elapsed().as_secs_f64());
            }
            order_s.sort_by(f64::total_cmp);
            let median_s = apps::percentile(&order_s, 0.5);
            r.add(
                "pm",
                &format!("{name}: collapse order, {}", cost.name()),
                tris as f64 / median_s.max(1e-9) / 1e6,
                "M input tri/s",
                &format!(
                    "{tris} triangles, one core; the full order down to one vertex; median of {ORDER_RUNS} runs ({:.3}-{:.3} M tri/s)",
                    tris as f64 / order_s[order_s.len() - 1].max(1e-9) / 1e6,
                    tris as f64 / order_s[0].max(1e-9) / 1e6
                ),
            );
            r.add(
                "pm",
                &format!("{name}: error bounds, {}", cost.name()),
                times.error_s,
                "s",
                &format!(
                    "stored per-level error bound, samples every {BOUND_FRACTION} x diagonal, one core"
                ),
            );
            let mut points = Vec::new();
            for &share in &shares {
                let target = ((tris as f64 * share).round() as usize).max(1);
                let p = pm.finest_with_at_most(target);
                let drawn = pm.triangles_at(p);
                let e = hausdorff(&full, &level_soup(&pm, p), spacing) / diag;
                points.push((drawn as f64, e));
                if TABLE_SHARES.contains(&share) {
                    r.add(
                        "pm",
                        &format!("{name}: error at {} %, {}", share * 100.0, cost.name()),
                        e * 100.0,
                        "% of diagonal",
                        &format!(
                            "{} of {tris} triangles, measured two-sided Hausdorff (samples every {MEASURE_FRACTION} x diagonal); stored bound {:.3} %",
                            drawn,
                            100.0 * pm.levels[p - 1].error as f64 / diag
                        ),
                    );
                }
            }
            curves.push(PmCurve {
                label: format!("{} ({name})", cost.name()),
                points,
            });
            if cost == CostKind::Quadric {
                quadric_pm = Some(pm);
            }
            b.inc(1);
        }
        // meshoptimizer: one simplify call per target count.
        let mut points = Vec::new();
        let mut secs_10 = 0.0;
        for &share in &shares {
            let target = ((tris as f64 * share).round() as usize).max(1);
            let (verts, idx, secs) = meshopt_simplify(&mesh, target);
            if (share - 0.1).abs() < 1e-9 {
                secs_10 = secs;
            }
            let e = if idx.is_empty() {
                f64::INFINITY
            } else {
                hausdorff(&full, &soup(&verts, &idx), spacing) / diag
            };
            points.push((idx.len() as f64 / 3.0, e));
            if TABLE_SHARES.contains(&share) {
                r.add(
                    "pm",
                    &format!("{name}: error at {} %, meshoptimizer", share * 100.0),
                    e * 100.0,
                    "% of diagonal",
                    &format!(
                        "{} of {tris} triangles (simplify, target error unlimited), same measurement",
                        idx.len() / 3
                    ),
                );
                meshopt_err.push((share, e, idx.len() / 3));
            }
        }
        curves.push(PmCurve {
            label: format!("meshoptimizer ({name})"),
            points,
        });
        // The same median as the collapse orders'.
        let mut secs = vec![secs_10];
        for _ in 1..ORDER_RUNS {
            secs.push(meshopt_simplify(&mesh, (tris as f64 * 0.1).round() as usize).2);
        }
        secs.sort_by(f64::total_cmp);
        r.add(
            "pm",
            &format!("{name}: meshoptimizer simplify to 10 %"),
            tris as f64 / apps::percentile(&secs, 0.5).max(1e-9) / 1e6,
            "M input tri/s",
            &format!(
                "one call, one core (one level per call, where the PM order gives every level); median of {ORDER_RUNS} runs"
            ),
        );
        // Equal triangle counts: the quadric PM at the level drawing at most what meshoptimizer
        // reached (it may stop short of a target).
        if let Some(pm) = &quadric_pm {
            for (share, m, mn) in &meshopt_err {
                let p = pm.finest_with_at_most(*mn);
                let q = hausdorff(&full, &level_soup(pm, p), spacing) / diag;
                r.add(
                    "pm",
                    &format!(
                        "{name}: quadric / meshoptimizer error at {} %",
                        share * 100.0
                    ),
                    q / m,
                    "x",
                    &format!("{} vs {mn} triangles; target <= 1.2", pm.triangles_at(p)),
                );
            }
        }
        b.inc(1);
        b.finish_and_clear();
        let Some(pm) = quadric_pm else { continue };
        // Per-instance rebuild: one pass at half the levels, and edits walking up and down.
        let half = pm.level_count() / 2;
        let mut idx = Vec::new();
        let reps = if quick { 5 } else { 40 };
        let t0 = Instant::now();
        for _ in 0..reps {
            pm.indices_at(half, &mut idx);
        }
        let one_pass = (idx.len() / 3 * reps) as f64 / t0.elapsed().as_secs_f64();
        r.add(
            "pm",
            &format!("{name}: one-pass index rebuild"),
            one_pass / 1e6,
            "M tri/s",
            &format!(
                "level {half} of {} ({} triangles), quadric",
                pm.level_count(),
                idx.len() / 3
            ),
        );
        let edits = PmEdits::new(&pm);
        let mut inst = PmInstance::new(&pm, pm.level_count());
        let t0 = Instant::now();
        let mut writes = 0usize;
        let mut changed = 0usize;
        for _ in 0..=(reps / 5) {
            writes += inst.set_level(&pm, &edits, 1);
            writes += inst.set_level(&pm, &edits, pm.level_count());
            changed += 2 * (pm.level_count() - 1);
        }
        let secs = t0.elapsed().as_secs_f64();
        r.add(
            "pm",
            &format!("{name}: per-instance edits"),
            changed as f64 / secs / 1e6,
            "M levels/s",
            &format!(
                "all levels down and up, {:.1} index writes per level on average",
                writes as f64 / changed.max(1) as f64
            ),
        );
        let bytes = file::to_bytes(&pm).len();
        r.add(
            "pm",
            &format!("{name}: PM file bytes per input triangle"),
            bytes as f64 / tris as f64,
            "B",
            &format!(
                "{bytes} B file (positions, wedges with attributes, collapse map, triangles, levels); \
                 edits derived at load: {:.1} B per triangle more",
                edits.bytes() as f64 / tris as f64
            ),
        );
    }
    curves
}
