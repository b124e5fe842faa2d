//! The speed-against-error plot (PNG via plotters).

use anyhow::{Context, Result, bail};
use std::path::Path;

pub(crate) struct CurvePoint {
    pub(crate) method: &'static str,
    pub(crate) triangles: f64,
    pub(crate) max_px: f64,
}

/// Loads a system font for plot labels (plotters' ab_glyph backend needs one in memory).
fn register_font() -> bool {
    for p in [
        "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
        "/usr/share/fonts/TTF/DejaVuSans.ttf",
    ] {
        if let Ok(bytes) = std::fs::read(p) {
            let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
            return plotters::style::register_font(
                "sans-serif",
                plotters::style::FontStyle::Normal,
                bytes,
            )
            .is_ok();
        }
    }
    false
}

pub(crate) fn write_plot(path: &Path, curve: &[CurvePoint]) -> Result<()> {
    use plotters::prelude::*;
    if curve.is_empty() {
        return Ok(());
    }
    if !register_font() {
        bail!("no DejaVuSans.ttf found for plot labels (Debian package fonts-dejavu-core)");
    }
    let (w, h) = (900u32, 600u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE)?;
        let tmax = curve.iter().map(|c| c.triangles).fold(1.0, f64::max) * 1.3;
        let tmin = curve
            .iter()
            .map(|c| c.triangles)
            .fold(f64::INFINITY, f64::min)
            .max(1.0)
            / 1.3;
        let emax = curve.iter().map(|c| c.max_px).fold(0.1, f64::max) * 1.2;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                "Triangles against measured max pixel error",
                ("sans-serif", 22),
            )
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(60)
            .build_cartesian_2d((tmin..tmax).log_scale(), 0.0..emax)?;
        chart
            .configure_mesh()
            .x_desc("triangles per frame")
            .y_desc("measured max error (px)")
            .draw()?;
        for (i, method) in ["grid (ours)", "TIN (ours)", "CDLOD-style distance"]
            .iter()
            .enumerate()
        {
            let color = Palette99::pick(i).to_rgba();
            let pts: Vec<(f64, f64)> = curve
                .iter()
                .filter(|c| c.method == *method)
                .map(|c| (c.triangles, c.max_px))
                .collect();
            chart
                .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))?
                .label(*method)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
                });
            chart.draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))?;
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
        root.present()?;
    }
    write_png(path, &buf, w, h)
}

fn write_png(path: &Path, rgb: &[u8], w: u32, h: u32) -> Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let f = std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(f), w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.write_header()?.write_image_data(rgb)?;
    Ok(())
}

/// Progressive meshes: measured error (fraction of the diagonal) against triangles, log-log, one
/// line per cost and meshoptimizer, for one mesh.
pub(crate) fn write_pm_plot(path: &Path, mesh: &str, curves: &[crate::pm::PmCurve]) -> Result<()> {
    use plotters::prelude::*;
    let curves: Vec<_> = curves.iter().filter(|c| c.label.contains(mesh)).collect();
    let pts = || {
        curves
            .iter()
            .flat_map(|c| c.points.iter())
            .filter(|p| p.1.is_finite() && p.1 > 0.0 && p.0 > 0.0)
    };
    if pts().next().is_none() {
        return Ok(());
    }
    if !register_font() {
        bail!("no DejaVuSans.ttf found for plot labels (Debian package fonts-dejavu-core)");
    }
    let (w, h) = (900u32, 600u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE)?;
        let tmin = pts().map(|p| p.0).fold(f64::INFINITY, f64::min) / 1.3;
        let tmax = pts().map(|p| p.0).fold(1.0, f64::max) * 1.3;
        let emin = pts().map(|p| p.1).fold(f64::INFINITY, f64::min) / 1.5;
        let emax = pts().map(|p| p.1).fold(0.0, f64::max) * 1.5;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!("{mesh}: measured two-sided error against triangles"),
                ("sans-serif", 22),
            )
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(70)
            .build_cartesian_2d((tmin..tmax).log_scale(), (emin..emax).log_scale())?;
        chart
            .configure_mesh()
            .x_desc("triangles")
            .y_desc("Hausdorff distance / diagonal")
            .draw()?;
        for (i, c) in curves.iter().enumerate() {
            let color = Palette99::pick(i).to_rgba();
            let p: Vec<(f64, f64)> = c
                .points
                .iter()
                .copied()
                .filter(|p| p.1.is_finite() && p.1 > 0.0 && p.0 > 0.0)
                .collect();
            chart
                .draw_series(LineSeries::new(p.clone(), color.stroke_width(2)))?
                .label(c.label.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
                });
            chart.draw_series(p.iter().map(|&q| Circle::new(q, 4, color.filled())))?;
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
        root.present()?;
    }
    write_png(path, &buf, w, h)
}
