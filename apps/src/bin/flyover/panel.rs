//! The egui panel: detail level, workers, memory budget, debug views and live statistics.

use engine::lighting::Sun;
use engine::render::Gpu;
use engine::render::frame::{GroundView, ViewOptions};
use engine::stream::PopDebtWindow;
use engine::viewer::FrameStats;

/// The panel's settings, applied to the streamer each frame.
pub(crate) struct Ui {
    pub(crate) tau: f64,
    /// Vertical field of view, degrees.
    pub(crate) fov_deg: f64,
    pub(crate) workers: usize,
    pub(crate) budget_mib: usize,
    pub(crate) fixed_level: Option<u8>,
    pub(crate) frozen: bool,
    pub(crate) occlusion: bool,
    pub(crate) slider_rect: [f32; 4],
    /// The sun the sliders show (applied with `Viewer::set_sun` when it changes).
    pub(crate) sun: Sun,
}

pub(crate) fn panel(
    ui: &mut egui::Ui,
    st_ui: &mut Ui,
    view: &mut ViewOptions,
    (s, pop_debt): (&FrameStats, &PopDebtWindow),
    frame_ms: f64,
    gpu: &Gpu,
    extra: &str,
) {
    ui.heading("Detail");
    let r = ui.add(
        egui::Slider::new(&mut st_ui.tau, 0.5..=16.0)
            .logarithmic(true)
            .text("pixel error τ (px)"),
    );
    st_ui.slider_rect = [r.rect.min.x, r.rect.min.y, r.rect.max.x, r.rect.max.y];
    ui.add(
        egui::Slider::new(&mut st_ui.fov_deg, apps::FOV_DEG_RANGE)
            .text("field of view (deg, vertical)"),
    );
    ui.add(egui::Slider::new(&mut st_ui.workers, 1..=32).text("workers (restarts streaming)"));
    ui.add(egui::Slider::new(&mut st_ui.budget_mib, 32..=8192).text("node cache MiB"));
    ui.separator();
    ui.heading("Sun");
    ui.add(
        egui::Slider::new(&mut st_ui.sun.azimuth_deg, 0.0..=360.0).text("azimuth (deg from north)"),
    );
    ui.add(egui::Slider::new(&mut st_ui.sun.elevation_deg, -10.0..=90.0).text("elevation (deg)"));
    ui.label("light grids are relit in the background, nearest first");
    ui.separator();
    ui.heading("Debug views");
    let mut fixed = st_ui.fixed_level.is_some();
    if gpu.wireframe {
        ui.checkbox(&mut view.wireframe, "wireframe");
    } else {
        ui.label("wireframe: not supported by this adapter");
    }
    ui.checkbox(&mut view.color_by_level, "colour by level");
    ui.checkbox(
        &mut view.lighting_only,
        "lighting only (grey, light grids alone)",
    );
    ui.checkbox(
        &mut view.light_values,
        "light-grid values (red sky, green sun, blue bounce)",
    );
    ui.horizontal(|ui| {
        ui.label("ground:");
        ui.radio_value(&mut view.ground_view, GroundView::Shaded, "lit");
        ui.radio_value(
            &mut view.ground_view,
            GroundView::TexelDensity,
            "texel density",
        );
        ui.radio_value(
            &mut view.ground_view,
            GroundView::TextureOnly,
            "texture only",
        );
    });
    ui.checkbox(&mut view.show_bounds, "node bounds");
    ui.checkbox(&mut view.plants, "vegetation");
    ui.checkbox(
        &mut view.merged_draws,
        "merged draws (off: one draw per item)",
    );
    ui.checkbox(
        &mut st_ui.occlusion,
        "split less behind dense vegetation (error may show)",
    );
    object_controls(ui, view);
    ui.checkbox(&mut st_ui.frozen, "freeze culling camera");
    ui.checkbox(&mut fixed, "fixed level");
    if fixed {
        let mut l = st_ui.fixed_level.unwrap_or(6);
        ui.add(egui::Slider::new(&mut l, 0..=12).text("level"));
        st_ui.fixed_level = Some(l);
    } else {
        st_ui.fixed_level = None;
    }
    ui.separator();
    ui.heading("Statistics");
    ui.label(format!(
        "{:.1} fps, frame {frame_ms:.1} ms (CPU: update {:.2}, uploads {:.2}, encode {:.2} ms)",
        1000.0 / frame_ms.max(1e-3),
        s.update_ms,
        s.upload_ms,
        s.encode_ms
    ));
    ui.collapsing("encode by part (ms)", |ui| encode_parts(ui, s));
    ui.label(match (gpu.timestamps, s.gpu_terrain_ms) {
        (true, Some(ms)) => format!("GPU: terrain pass {ms:.2} ms (timestamp queries)"),
        (true, None) => "GPU: waiting for the first timestamps".to_string(),
        (false, _) => "GPU time: timestamps not supported by this adapter".to_string(),
    });
    ui.label(format!(
        "triangles {}  draw calls {} ({} node meshes)  nodes {}",
        s.triangles, s.draw_calls, s.items, s.drawn_nodes
    ));
    ui.label(format!(
        "vegetation: {} instances, {} draw calls ({} groups), {} mesh triangles",
        s.plant_instances, s.plant_draw_calls, s.plant_items, s.plant_triangles
    ));
    if s.object_items > 0 {
        ui.label(format!(
            "objects: {} drawn in {} draw calls ({} from MSFT_lod chain levels, {} merged far meshes), {} triangles ({:.1} % of {} at full detail)",
            s.object_items,
            s.object_draw_calls,
            s.object_chain_draws,
            s.object_hlod_draws,
            s.object_triangles,
            100.0 * s.object_triangles as f64 / s.object_full_triangles.max(1) as f64,
            s.object_full_triangles
        ));
    }
    if s.texture_full_bytes > 0 {
        ui.label(format!(
            "texture cache: {:.1} MiB resident, {:.1} MiB if every drawn texture were full resolution ({:.1}x saved), {} misses, {} coarser than needed, {} uploads ({:.2} MiB) this frame",
            s.texture_resident_bytes as f64 / f64::from(1 << 20),
            s.texture_full_bytes as f64 / f64::from(1 << 20),
            s.texture_full_bytes as f64 / s.texture_resident_bytes.max(1) as f64,
            s.texture_misses,
            s.texture_coarser,
            s.texture_uploads,
            s.texture_upload_bytes as f64 / f64::from(1 << 20),
        ));
    }
    ui.label(format!("nodes per level {:?}", s.nodes_per_level));
    ui.label(format!(
        "jobs: queued {} running {} waiting GPU {} cancelled {}",
        s.jobs_queued, s.jobs_running, s.jobs_waiting_gpu, s.jobs_cancelled_total
    ));
    ui.label(format!(
        "memory: tiles {:.1} MiB, drawn node buffers {:.1} MiB, node cache {:.1} MiB",
        s.tiles_bytes as f64 / 1_048_576.0,
        s.node_buffers_bytes as f64 / 1_048_576.0,
        s.cache_bytes as f64 / 1_048_576.0
    ));
    ui.label(format!(
        "pop debt, last {:.0} s: {:.1} % of frames show a drawn node over τ (worst by {:.2} px); \
         now {} nodes the display wants not shown yet",
        pop_debt.window_s(),
        100.0 * pop_debt.share(),
        pop_debt.worst_px(),
        s.pop_debt_nodes
    ));
    ui.label(format!(
        "light grids: {} drawn nodes shaded by an ancestor's coarser grid (their own not made \
         yet), {} without any (drawn fully lit)",
        s.coarse_lit_nodes, s.unlit_nodes
    ));
    ui.label(format!(
        "ground textures: {} drawn nodes show an ancestor's (their own not made yet), {} none",
        s.borrowed_textures, s.untextured_nodes
    ));
    ui.label(extra);
}

/// The frame's encode by part: the draw list, each renderer's deferred GPU work and prepare,
/// recording the pass (renderers under 0.01 ms left out).
fn encode_parts(ui: &mut egui::Ui, s: &FrameStats) {
    ui.label(format!(
        "draw list {:.2}, recording the pass {:.2}",
        s.draw_list_ms, s.render.record_ms
    ));
    for (phase, times) in s.render.phases() {
        let each: Vec<String> = times
            .iter()
            .filter(|&&(_, ms)| ms >= 0.01)
            .map(|(name, ms)| format!("{name} {ms:.2}"))
            .collect();
        ui.label(format!("{phase}: {}", each.join(", ")));
    }
}

/// The progressive-mesh objects' controls (level of detail, debug views, HLOD).
fn object_controls(ui: &mut egui::Ui, view: &mut ViewOptions) {
    ui.label("progressive-mesh objects:");
    ui.checkbox(
        &mut view.pm_color_by_lod,
        "colour objects by LOD (blue coarse .. red full)",
    );
    ui.checkbox(
        &mut view.hlod,
        "merge far houses into one mesh per node (HLOD)",
    );
    ui.checkbox(
        &mut view.texture_mip_view,
        "colour textured objects by mip level (red full .. violet coarse)",
    );
    let mut pm_fixed = view.pm_lod.fixed_fraction.is_some();
    ui.checkbox(&mut pm_fixed, "fixed object LOD");
    if pm_fixed {
        let mut f = view.pm_lod.fixed_fraction.unwrap_or(0.5);
        ui.add(egui::Slider::new(&mut f, 0.0..=1.0).text("share of vertices"));
        view.pm_lod.fixed_fraction = Some(f);
    } else {
        view.pm_lod.fixed_fraction = None;
    }
    ui.add(
        egui::Slider::new(&mut view.pm_lod.strength, 0.1..=10.0)
            .logarithmic(true)
            .text("object LOD strength"),
    );
    ui.add(egui::Slider::new(&mut view.pm_lod.min_vertices, 1..=500).text("object min vertices"));
    ui.add(egui::Slider::new(&mut view.pm_lod.z_disp_m, 0.0..=500.0).text("object ZDISP (m)"));
    ui.add(egui::Slider::new(&mut view.pm_lod.morph_s, 0.0..=2.0).text("object geomorph (s)"));
}

/// A baked map's pages and decal tiles as the panel shows them: what the caches read and hold,
/// and every page or tile that could not be read (its nodes are served without it), by file and
/// page. Empty for a map without pages.
pub(crate) fn map_pages(world: &engine::surface::World) -> String {
    let mib = |b: usize| b as f64 / 1_048_576.0;
    let mut lines = Vec::new();
    if let Some(c) = &world.page_cache {
        let s = c.stats();
        lines.push(format!(
            "map pages: {} read, {:.0} of {:.0} MiB resident",
            s.page_ins,
            mib(s.resident_bytes),
            mib(c.budget_bytes())
        ));
    }
    if let Some(t) = world.decals.tile_stats() {
        lines.push(format!(
            "decal tiles: {} read, {:.0} MiB resident",
            t.tile_ins,
            mib(t.resident_bytes)
        ));
    }
    let faults = world.page_faults.list();
    if !faults.is_empty() {
        lines.push(format!(
            "{} map pages or tiles cannot be read (their nodes are served without them):",
            faults.len()
        ));
        lines.extend(faults.iter().take(4).cloned());
    }
    lines.join("\n")
}
