//! Shader assembly: every renderer's WGSL is `constants + prelude + its own file`. The constants
//! are generated from the Rust definitions (cluster counts, atlas tiles, ...), so both sides
//! share one definition; the prelude holds the frame and node bindings, the mesh vertex, dither,
//! fog and shading. Release builds embed the files; debug builds read them from disk when present
//! (edit a shader and rerun without rebuilding).

/// The shared prelude.
pub const PRELUDE: &str = include_str!("../../../shaders/prelude.inc.wgsl");

/// The embedded renderer files, by name.
const FILES: [(&str, &str); 6] = [
    ("sky", include_str!("../../../shaders/sky.wgsl")),
    ("ground", include_str!("../../../shaders/ground.wgsl")),
    ("reference", include_str!("../../../shaders/reference.wgsl")),
    ("terrain", include_str!("../../../shaders/terrain.wgsl")),
    (
        "vegetation",
        include_str!("../../../shaders/vegetation.wgsl"),
    ),
    ("objects", include_str!("../../../shaders/objects.wgsl")),
];

fn file_text(name: &str, file: &'static str) -> std::borrow::Cow<'static, str> {
    #[cfg(debug_assertions)]
    {
        let p = format!("{}/../shaders/{name}.wgsl", env!("CARGO_MANIFEST_DIR"));
        if let Ok(s) = std::fs::read_to_string(p) {
            return s.into();
        }
    }
    let _ = name;
    file.into()
}

fn prelude_text() -> std::borrow::Cow<'static, str> {
    file_text("prelude.inc", PRELUDE)
}

/// The prelude's own constants (the light grids' shape).
fn prelude_constants() -> String {
    use crate::lighting::grid::{COLUMNS, LAYERS, SUN_DIAMETER_RAD, SUN_MARGIN_RANGE_RAD};
    format!(
        "const LIGHT_COLUMNS: u32 = {COLUMNS}u;\nconst LIGHT_LAYERS: u32 = {LAYERS}u;\n\
         const LIGHT_MARGIN_RANGE_RAD: f32 = {SUN_MARGIN_RANGE_RAD:?};\n\
         const SUN_DIAMETER_RAD: f32 = {SUN_DIAMETER_RAD:?};\n"
    )
}

/// The assembled source of renderer file `name` with its generated `constants` (WGSL `const`
/// lines). An unknown name gives the prelude alone.
pub fn assemble(name: &str, constants: &str) -> String {
    let body = FILES
        .iter()
        .find(|(n, _)| *n == name)
        .map_or_else(String::new, |(n, f)| file_text(n, f).into_owned());
    format!(
        "// ---- generated constants ----\n{}{constants}\n// ---- prelude.inc.wgsl ----\n{}\n// ---- {name}.wgsl ----\n{body}",
        prelude_constants(),
        prelude_text()
    )
}

/// A shader module of an assembled `source` (see [`assemble`]) for renderer file `name`.
pub fn module(device: &wgpu::Device, name: &str, source: &str) -> wgpu::ShaderModule {
    device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(&format!("{name}.wgsl")),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    })
}
