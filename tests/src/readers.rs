//! Every reader of untrusted input, each with a valid seed file of its format in a scratch
//! folder: the committed tiny map's files (map.toml, EXR heights, PNG layers, CSV lists,
//! decals, poisson.csv, house PMs and textures), a material PNG, a camera path, a GeoTIFF, an OBJ
//! mesh and a glTF model. Shared by the bounded fuzz test (`tests/tests/readers_fuzz.rs`) and the cargo-fuzz
//! targets (`tests/fuzz/`).

use crate::mutate::Format;
use std::path::{Path, PathBuf};
use worldgen::map::{Building, Manifest, building_models, layers, lists, manifest};

/// One reader: the file it reads (relative to the fixture folder), how that file is mutated,
/// and the call.
pub struct Reader {
    pub name: &'static str,
    pub file: PathBuf,
    pub format: Format,
    read: fn(&Fixture, &Path) -> Result<(), String>,
}

/// The scratch folder with a seed file for every reader, and the context the map readers take.
pub struct Fixture {
    dir: tempfile::TempDir,
    manifest: Manifest,
    buildings: Vec<Building>,
    readers: Vec<Reader>,
}

fn err(e: impl std::fmt::Display) -> String {
    e.to_string()
}

impl Fixture {
    /// Copies the tiny map and writes the other seed files.
    pub fn new() -> Self {
        let dir = tempfile::tempdir().expect("scratch folder");
        let root = dir.path();
        crate::copy_dir(&crate::tiny_map_dir(), root);
        let map = worldgen::Map::load(root).expect("tiny map loads");
        write_material(&root.join("material.png"));
        std::fs::copy(
            crate::workspace_root().join("docs/views/town_200m.path"),
            root.join("camera.path"),
        )
        .expect("copy a camera path");
        write_geotiff(&root.join("dem.tif"));
        write_obj(&root.join("house.obj"));
        std::fs::write(
            root.join("chain.gltf"),
            crate::gltf_fixture::gltf_with_chain(4, false, false),
        )
        .expect("write glTF");
        let m = &map.manifest;
        let house = building_models::path(Path::new(""), &map.buildings[0].type_name);
        let texture = format!(
            "{}/{}",
            building_models::FOLDER,
            map.buildings[0].facade_texture
        );
        let r = |name, file: &str, format, read| Reader {
            name,
            file: PathBuf::from(file),
            format,
            read,
        };
        let readers = vec![
            r("map.toml", "map.toml", Format::Text, |_, p| {
                manifest::read(p).map(drop).map_err(err)
            }),
            r("heights EXR", &m.heights.file, Format::Binary, |f, _| {
                layers::read_heights(f.dir(), &f.manifest)
                    .map(drop)
                    .map_err(err)
            }),
            r("ground PNG", &m.ground.file, Format::Png, |f, _| {
                layers::read_ground(f.dir(), &f.manifest)
                    .map(drop)
                    .map_err(err)
            }),
            r("density PNG", &m.vegetation[0].file, Format::Png, |f, _| {
                let spec = f.manifest.vegetation[0].grid();
                layers::read_gray8(f.dir(), "vegetation[0].file", &spec)
                    .map(drop)
                    .map_err(err)
            }),
            r("trees CSV", &m.trees.file, Format::Text, |f, p| {
                lists::read_trees(p, &f.manifest).map(drop).map_err(err)
            }),
            r("decals TOML", &m.decals.file, Format::Text, |f, p| {
                lists::read_decals(p, &f.manifest).map(drop).map_err(err)
            }),
            r("buildings CSV", &m.buildings.file, Format::Text, |f, p| {
                lists::read_buildings(p, &f.manifest).map(drop).map_err(err)
            }),
            r("poisson CSV", &m.poisson.file, Format::Text, |f, p| {
                lists::read_poisson(p, f.manifest.poisson.min_distance)
                    .map(drop)
                    .map_err(err)
            }),
            r("house PM", &house.to_string_lossy(), Format::Pm, |f, _| {
                building_models::read(f.dir(), &f.buildings)
                    .map(drop)
                    .map_err(err)
            }),
            r("house texture PNG", &texture, Format::Png, |f, _| {
                building_models::read_textures(f.dir(), &f.buildings)
                    .map(drop)
                    .map_err(err)
            }),
            r("material PNG", "material.png", Format::Png, |_, p| {
                worldgen::map::material_image::read(p, "ground.legend[0].material")
                    .map(drop)
                    .map_err(err)
            }),
            r("camera path", "camera.path", Format::Text, |_, p| {
                engine::flight::CameraPath::load(p).map(drop).map_err(err)
            }),
            r("GeoTIFF", "dem.tif", Format::Binary, |_, p| {
                worldgen::geotiff::read(p, None, 1.0).map(drop).map_err(err)
            }),
            r("OBJ mesh", "house.obj", Format::Text, |_, p| {
                worldgen::pm::load_mesh(p).map(drop).map_err(err)
            }),
            r("glTF model", "chain.gltf", Format::Text, |_, p| {
                worldgen::pm::gltf_input::load(p).map(drop).map_err(err)
            }),
        ];
        Self {
            manifest: map.manifest.clone(),
            buildings: map.buildings,
            dir,
            readers,
        }
    }

    pub fn dir(&self) -> &Path {
        self.dir.path()
    }

    pub fn readers(&self) -> &[Reader] {
        &self.readers
    }

    /// The reader called `name`.
    pub fn reader(&self, name: &str) -> Option<&Reader> {
        self.readers.iter().find(|r| r.name == name)
    }

    /// The reader's seed file (valid).
    pub fn seed(&self, r: &Reader) -> Vec<u8> {
        std::fs::read(self.dir().join(&r.file)).expect("seed file")
    }

    /// Writes `bytes` as the reader's file and runs the reader on it; the error as text.
    pub fn run(&self, r: &Reader, bytes: &[u8]) -> Result<(), String> {
        let path = self.dir().join(&r.file);
        std::fs::write(&path, bytes).expect("write the input");
        (r.read)(self, &path)
    }
}

impl Default for Fixture {
    fn default() -> Self {
        Self::new()
    }
}

fn write_material(path: &Path) {
    let side = 32u32;
    let rgba = (0..side * side)
        .map(|i| [(i % 251) as u8, (i / side * 7) as u8, 90, 255])
        .collect();
    let image = worldgen::map::MaterialImage { side, rgba };
    worldgen::map::material_image::write(path, "material", &image).expect("write material");
}

/// A 24x20 16-bit projected GeoTIFF in LZW strips with a nodata value.
fn write_geotiff(path: &Path) {
    use tiff::encoder::{Compression, TiffEncoder, colortype::GrayI16};
    use tiff::tags::Tag;
    let (w, h) = (24u32, 20u32);
    let data: Vec<i16> = (0..w * h).map(|i| (i % 97) as i16 * 3 - 20).collect();
    let mut bytes = std::io::Cursor::new(Vec::new());
    {
        let mut enc = TiffEncoder::new(&mut bytes)
            .expect("tiff encoder")
            .with_compression(Compression::Lzw);
        let mut img = enc.new_image::<GrayI16>(w, h).expect("tiff image");
        img.rows_per_strip(6).expect("rows per strip");
        let dir = img.encoder();
        dir.write_tag(Tag::ModelPixelScaleTag, &[5.0f64, 5.0, 0.0][..])
            .expect("tag");
        dir.write_tag(
            Tag::ModelTiepointTag,
            &[0.0f64, 0.0, 0.0, 400_000.0, 5_000_000.0, 0.0][..],
        )
        .expect("tag");
        dir.write_tag(
            Tag::GeoKeyDirectoryTag,
            &[1u16, 1, 0, 2, 1024, 0, 1, 1, 3076, 0, 1, 9001][..],
        )
        .expect("tag");
        dir.write_tag(Tag::GdalNodata, "-9999").expect("tag");
        img.write_data(&data).expect("tiff data");
    }
    std::fs::write(path, bytes.into_inner()).expect("write GeoTIFF");
}

fn write_obj(path: &Path) {
    let spec = worldgen::building_mesh::BuildingSpec {
        width_m: 8.0,
        depth_m: 6.0,
        storeys: 1,
        storey_m: 3.0,
        roof: worldgen::building_mesh::Roof::Gable,
        roof_pitch_deg: 35.0,
        seed: 3,
    };
    let mesh = worldgen::building_mesh::building_mesh(&spec).expect("house mesh");
    std::fs::write(path, worldgen::pm::obj::to_text(&mesh.triangles)).expect("write OBJ");
}
