//! The benchmark report: rows (section, metric, value, unit, params) printed as a Markdown table
//! and written as JSON with a machine block; progress bars and a throughput helper.

use indicatif::{ProgressBar, ProgressStyle};
use std::fmt::Write as _;
use std::time::Instant;

#[derive(serde::Serialize)]
pub(crate) struct Row {
    section: String,
    metric: String,
    value: f64,
    unit: String,
    params: String,
}

pub(crate) struct Report {
    pub(crate) rows: Vec<Row>,
}

impl Report {
    pub(crate) fn add(
        &mut self,
        section: &str,
        metric: &str,
        value: f64,
        unit: &str,
        params: &str,
    ) {
        self.rows.push(Row {
            section: section.into(),
            metric: metric.into(),
            value,
            unit: unit.into(),
            params: params.into(),
        });
    }

    /// p50 / p95 / p99 / max rows of a list of per-item durations (seconds).
    pub(crate) fn timings(&mut self, section: &str, what: &str, secs: Vec<f64>, params: &str) {
        self.quantiles(section, secs, &[0.5, 0.95, 0.99, 1.0], params, |q| {
            format!("{what} {q}")
        });
    }

    /// Rows (µs) of the `quantiles` (1 is the max) of per-item durations (seconds), each named
    /// `name("p50")`, `name("max")` ...; none when there are no durations.
    pub(crate) fn quantiles(
        &mut self,
        section: &str,
        mut secs: Vec<f64>,
        quantiles: &[f64],
        params: &str,
        name: impl Fn(&str) -> String,
    ) {
        if secs.is_empty() {
            return;
        }
        secs.sort_by(f64::total_cmp);
        for &q in quantiles {
            let label = if q >= 1.0 {
                "max".to_string()
            } else {
                format!("p{}", (q * 100.0).round())
            };
            let value = apps::percentile(&secs, q) * 1e6;
            self.add(section, &name(&label), value, "µs", params);
        }
    }

    /// The rows as a Markdown table.
    pub(crate) fn markdown(&self) -> String {
        let mut out =
            String::from("| section | metric | value | unit | params |\n|---|---|---:|---|---|\n");
        for r in &self.rows {
            let v = if r.value.abs() >= 100.0 || r.value == r.value.round() {
                format!("{:.0}", r.value)
            } else {
                format!("{:.3}", r.value)
            };
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} | {} |",
                r.section, r.metric, v, r.unit, r.params
            );
        }
        out
    }

    /// The benchmark document: how it was made, the machine, and every row of this one run.
    pub(crate) fn document(
        &self,
        command: &str,
        summary: &str,
        machine: &serde_json::Value,
    ) -> String {
        let field = |k: &str| {
            machine
                .get(k)
                .map_or_else(|| "?".to_string(), ToString::to_string)
        };
        format!(
            "# Benchmarks\n\nWritten by `nodebench` from one run; do not edit by hand, run it again:\n\n\
             ```sh\n{command}\n```\n\n{summary}\n\n\
             Machine: {} cores, CPU {}, {} worker thread(s) for throughput rows, adapter {}.\n\n\
             Per-item times are on one core (p50/p95/p99/max). \"Measured error\" is measured on \
             the screen: the finest surface's point and the drawn mesh's point above or below it, \
             projected through the camera's matrices, and the length in pixels of the part of the \
             segment between them on the screen, at the sample points of every drawn node (the max \
             over 2 x 2 samples per quad, p99.9 and mean over a coarser lattice), never the engine's \
             own bound. Rows marked \"the metric's on-axis model\" take |mesh - surface| K / distance \
             instead, which the screen exceeds off its axis.\n\n{}",
            field("cores"),
            field("cpu"),
            field("workers"),
            field("adapter"),
            self.markdown()
        )
    }
}

pub(crate) fn bar(len: u64, msg: &str) -> ProgressBar {
    let b = ProgressBar::new(len);
    b.set_style(
        ProgressStyle::with_template("{msg:24} [{bar:30}] {pos}/{len} ETA {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    b.set_message(msg.to_string());
    b
}

/// Items per second with `workers` threads each doing `per_worker` calls of `f`.
pub(crate) fn throughput(workers: usize, per_worker: usize, f: &(dyn Fn(usize) + Sync)) -> f64 {
    let t0 = Instant::now();
    std::thread::scope(|s| {
        for w in 0..workers {
            s.spawn(move || {
                for i in 0..per_worker {
                    f(w * per_worker + i);
                }
            });
        }
    });
    (workers * per_worker) as f64 / t0.elapsed().as_secs_f64()
}

pub(crate) fn machine_block(workers: usize, adapter: Option<&str>) -> serde_json::Value {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())
        })
        .unwrap_or_else(|| "unknown".into());
    serde_json::json!({
        "cores": std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get),
        "workers": workers,
        "cpu": cpu,
        "adapter": adapter.unwrap_or("none (no gpu section)"),
    })
}
