//! Plot helpers shared by the binaries: a system font for labels, PNG output, and a log-log
//! error-against-triangles chart (progressive meshes in nodebench and lod-error).

use anyhow::{Context, Result, bail};
use std::path::Path;

/// Loads a system font for plot labels (plotters' ab_glyph backend needs one in memory).
pub fn register_font() -> bool {
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

/// Writes an RGB8 buffer as a PNG, creating the folder.
pub fn write_png(path: &Path, rgb: &[u8], w: u32, h: u32) -> Result<()> {
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

/// A named line of a log-log chart: (triangles, error) points.
#[derive(Debug, Clone)]
pub struct Curve {
    pub label: String,
    pub points: Vec<(f64, f64)>,
}

/// Error against triangles, log-log, one line per curve (points with a non-positive or
/// infinite coordinate are left out). Writes nothing when no point remains.
pub fn write_loglog(path: &Path, title: &str, y_desc: &str, curves: &[&Curve]) -> Result<()> {
    use plotters::prelude::*;
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
            .caption(title, ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(70)
            .build_cartesian_2d((tmin..tmax).log_scale(), (emin..emax).log_scale())?;
        chart
            .configure_mesh()
            .x_desc("triangles")
            .y_desc(y_desc)
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
