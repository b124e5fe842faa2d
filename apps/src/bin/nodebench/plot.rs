//! The speed-against-error plot (PNG via plotters).

use anyhow::{Result, bail};
use std::path::Path;

pub(crate) struct CurvePoint {
    pub(crate) method: &'static str,
    pub(crate) triangles: f64,
    pub(crate) max_px: f64,
}

pub(crate) fn write_plot(path: &Path, curve: &[CurvePoint]) -> Result<()> {
    use plotters::prelude::*;
    if curve.is_empty() {
        return Ok(());
    }
    if !apps::plot::register_font() {
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
                "Triangles against measured on-screen max pixel error",
                ("sans-serif", 22),
            )
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(60)
            .build_cartesian_2d((tmin..tmax).log_scale(), 0.0..emax)?;
        chart
            .configure_mesh()
            .x_desc("triangles per frame")
            .y_desc("on-screen max error (px)")
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
    apps::plot::write_png(path, &buf, w, h)
}
