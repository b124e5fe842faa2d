//! Map format v1 end to end: generation determinism, the committed tiny map, write/load round
//! trips, and a matrix of malformed maps that must each give their specific error (never a
//! panic, never a half-loaded map).

use std::path::Path;
use tests::{copy_dir, hash_dir, tiny_map_dir, tiny_map_params};
use worldgen::Map;
use worldgen::generate::{GenerateParams, generate};
use worldgen::map::{Decal, DecalKind, MapError};
use worldgen::progress::Silent;

fn generate_into(p: &GenerateParams, dir: &Path) -> Map {
    let map = generate(p, &Silent, &mut Vec::new()).expect("generate");
    map.write(dir).expect("write map");
    map
}

#[test]
fn regenerating_the_committed_tiny_map_gives_identical_files() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("tiny");
    generate_into(&tiny_map_params(), &out);
    let committed = tiny_map_dir();
    let names = tests::files_under(&committed);
    assert!(
        names.len() >= 8,
        "committed tiny map looks incomplete: {names:?}"
    );
    for n in &names {
        let a = std::fs::read(committed.join(n)).unwrap();
        let b = std::fs::read(out.join(n))
            .unwrap_or_else(|e| panic!("regenerated map lacks {n:?}: {e}"));
        assert!(
            a == b,
            "{n:?} differs from the committed file; regenerate with the command in maps/README.md"
        );
    }
    assert_eq!(
        tests::files_under(&out),
        names,
        "regeneration wrote a different set of files"
    );
}

#[test]
fn generation_bytes_do_not_depend_on_thread_count() {
    let tmp = tempfile::tempdir().unwrap();
    let mut hashes = Vec::new();
    for threads in [1, 2, 3] {
        let p = GenerateParams {
            name: "det".into(),
            seed: 42,
            size_m: 768.0,
            spacing_m: 4.0,
            threads,
        };
        let dir = tmp.path().join(format!("t{threads}"));
        generate_into(&p, &dir);
        hashes.push(hash_dir(&dir));
    }
    assert!(
        hashes.windows(2).all(|w| w[0] == w[1]),
        "hashes differ by thread count: {hashes:x?}"
    );
    // And the seed matters.
    let other = tmp.path().join("other");
    generate_into(
        &GenerateParams {
            name: "det".into(),
            seed: 43,
            size_m: 768.0,
            spacing_m: 4.0,
            threads: 2,
        },
        &other,
    );
    assert_ne!(hash_dir(&other), hashes[0]);
}

#[test]
fn write_then_load_round_trips_exactly() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("m");
    let map = generate_into(
        &GenerateParams {
            name: "rt".into(),
            seed: 3,
            size_m: 512.0,
            spacing_m: 4.0,
            threads: 0,
        },
        &dir,
    );
    let loaded = Map::load(&dir).expect("load");
    assert_eq!(loaded, map);
    assert!(
        !loaded.decals.is_empty(),
        "generated map should have roads/paths"
    );
    assert!(
        !loaded.trees.is_empty(),
        "generated map should have large trees"
    );
    // Sampling agrees with the grid at sample positions, and stays finite beyond the borders.
    let s = map.manifest.heights.spacing_m;
    for (i, j) in [(0usize, 0usize), (5, 9), (128, 128), (64, 3)] {
        let want = f64::from(map.heights.get(i, j));
        assert!((map.height_bilinear_m(i as f64 * s, j as f64 * s) - want).abs() < 1e-4);
        assert!((map.height_bicubic_m(i as f64 * s, j as f64 * s) - want).abs() < 1e-4);
    }
    assert!(map.height_bicubic_m(-1e6, 1e9).is_finite());
}

#[test]
fn rewriting_replaces_the_folder_atomically() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("m");
    generate_into(
        &GenerateParams {
            name: "a".into(),
            seed: 1,
            size_m: 256.0,
            spacing_m: 4.0,
            threads: 0,
        },
        &dir,
    );
    std::fs::write(dir.join("stale.txt"), "left from before").unwrap();
    generate_into(
        &GenerateParams {
            name: "b".into(),
            seed: 2,
            size_m: 256.0,
            spacing_m: 4.0,
            threads: 0,
        },
        &dir,
    );
    assert!(!dir.join("stale.txt").exists());
    assert_eq!(Map::load(&dir).unwrap().manifest.name, "b");
    let leftovers: Vec<_> = std::fs::read_dir(tmp.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(
        leftovers.len(),
        1,
        "staging folder left behind: {leftovers:?}"
    );
}

// ---- malformed maps ----------------------------------------------------------------------

/// A fresh copy of the committed tiny map in a temp folder.
fn broken_copy() -> (tempfile::TempDir, std::path::PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("bad");
    copy_dir(&tiny_map_dir(), &dir);
    (tmp, dir)
}

fn edit_manifest(dir: &Path, f: impl FnOnce(&mut toml::Table)) {
    let p = dir.join("map.toml");
    let mut t: toml::Table = toml::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
    f(&mut t);
    std::fs::write(&p, toml::to_string(&t).unwrap()).unwrap();
}

fn table<'a>(t: &'a mut toml::Table, key: &str) -> &'a mut toml::Table {
    t.get_mut(key).and_then(toml::Value::as_table_mut).unwrap()
}

/// Loads the broken map and checks the error names `file` and contains every `words`.
fn expect_error(dir: &Path, file: &str, words: &[&str]) -> MapError {
    let err = Map::load(dir).expect_err("a malformed map must not load");
    let msg = err.to_string();
    assert!(
        msg.contains(file),
        "error does not name the file {file}: {msg}"
    );
    for w in words {
        assert!(msg.contains(w), "error lacks {w:?}: {msg}");
    }
    err
}

#[test]
fn malformed_truncated_exr() {
    let (_t, dir) = broken_copy();
    let p = dir.join("heights.exr");
    let bytes = std::fs::read(&p).unwrap();
    std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
    let e = expect_error(&dir, "heights.exr", &["heights.file", "OpenEXR"]);
    assert!(matches!(e, MapError::BadLayerFile { .. }), "{e:?}");
}

#[test]
fn malformed_nan_height() {
    let (_t, dir) = broken_copy();
    let mut map = Map::load(&dir).unwrap();
    let hg = map.heights.grid_mut().expect("heights in memory");
    hg.set(17, 23, f32::NAN);
    map.write(&dir).unwrap();
    let e = expect_error(&dir, "heights.exr", &["column 17", "row 23", "NaN"]);
    assert!(
        matches!(e, MapError::BadHeight { x: 17, y: 23, .. }),
        "{e:?}"
    );
}

#[test]
fn malformed_wrong_dimensions_in_manifest() {
    let (_t, dir) = broken_copy();
    edit_manifest(&dir, |t| {
        table(t, "heights").insert("width".into(), 130.into());
    });
    let e = expect_error(&dir, "map.toml", &["heights.width", "130", "129"]);
    assert!(matches!(e, MapError::InvalidField { .. }), "{e:?}");
}

#[test]
fn malformed_layer_file_size_disagrees_with_manifest() {
    let (_t, dir) = broken_copy();
    // A consistent manifest (257 samples at 2 m) over a file that holds 129 x 129.
    edit_manifest(&dir, |t| {
        let h = table(t, "heights");
        h.insert("width".into(), 257.into());
        h.insert("height".into(), 257.into());
        h.insert("spacing_m".into(), 2.0.into());
    });
    let e = expect_error(&dir, "heights.exr", &["129x129", "257x257"]);
    assert!(matches!(e, MapError::LayerSize { .. }), "{e:?}");
}

#[test]
fn malformed_unknown_version() {
    let (_t, dir) = broken_copy();
    edit_manifest(&dir, |t| {
        t.insert("version".into(), 4.into());
    });
    let e = expect_error(&dir, "map.toml", &["version", "4"]);
    assert!(
        matches!(e, MapError::UnknownVersion { found: 4, .. }),
        "{e:?}"
    );
    // Older maps (version 1 before the Poisson tile, 2 before towns) say so and how to fix it.
    for old in [1, 2] {
        let (_t, dir) = broken_copy();
        edit_manifest(&dir, |t| {
            t.insert("version".into(), old.into());
        });
        expect_error(
            &dir,
            "map.toml",
            &["version", &old.to_string(), "regenerate"],
        );
    }
}

#[test]
fn malformed_poisson_tile() {
    use std::fmt::Write as _;
    let (_t, dir) = broken_copy();
    let good = std::fs::read_to_string(dir.join("poisson.csv")).unwrap();
    let mut lines: Vec<&str> = good.lines().collect();
    // A point outside the unit tile, named by line.
    lines[5] = "1.5,0.25";
    std::fs::write(dir.join("poisson.csv"), lines.join("\n")).unwrap();
    expect_error(&dir, "poisson.csv", &["line 6", "outside the unit tile"]);
    // Two points too close: the spacing the manifest promises is checked.
    let mut lines: Vec<String> = good.lines().map(str::to_owned).collect();
    let p: Vec<f64> = lines[2].split(',').map(|v| v.parse().unwrap()).collect();
    lines.push(format!("{},{}", p[0], (p[1] + 0.001) % 1.0));
    std::fs::write(dir.join("poisson.csv"), lines.join("\n")).unwrap();
    expect_error(
        &dir,
        "poisson.csv",
        &[
            "closer than poisson.min_distance",
            &format!("{}", lines.len() - 2),
        ],
    );
    // Crafted files cannot stall the loader: far more points than fit the spacing are refused
    // by count, and a clustered file that fits the count stops at the first close pair (the
    // old all-pairs check in one grid cell took quadratic time).
    let mut huge = String::from("tvs-poisson 1\nx,y\n");
    for i in 0..2_000_000u32 {
        let _ = writeln!(huge, "0.5,{}", 0.5 + f64::from(i) * 1e-12);
    }
    std::fs::write(dir.join("poisson.csv"), &huge).unwrap();
    expect_error(&dir, "poisson.csv", &["2000000 points cannot be", "apart"]);
    let mut clustered = String::from("tvs-poisson 1\nx,y\n");
    for i in 0..1000u32 {
        let _ = writeln!(clustered, "{},0.5", 0.5 + f64::from(i) * 1e-9);
    }
    std::fs::write(dir.join("poisson.csv"), &clustered).unwrap();
    expect_error(&dir, "poisson.csv", &["points 1 and 2", "closer than"]);
    // Too few points, a bad header, a field that is not a number, a bad manifest field.
    std::fs::write(dir.join("poisson.csv"), "tvs-poisson 1\nx,y\n0.5,0.5\n").unwrap();
    expect_error(&dir, "poisson.csv", &["at least"]);
    std::fs::write(dir.join("poisson.csv"), "tvs-poisson 7\nx,y\n").unwrap();
    expect_error(&dir, "poisson.csv", &["line 1", "tvs-poisson 1"]);
    std::fs::write(dir.join("poisson.csv"), "tvs-poisson 1\nx,y\n0.5,x\n").unwrap();
    expect_error(&dir, "poisson.csv", &["line 3", "y"]);
    let (_t, dir) = broken_copy();
    edit_manifest(&dir, |t| {
        t["poisson"]
            .as_table_mut()
            .unwrap()
            .insert("min_distance".into(), 0.9.into());
    });
    expect_error(&dir, "map.toml", &["poisson.min_distance"]);
}

#[test]
fn malformed_wrong_format_name() {
    let (_t, dir) = broken_copy();
    edit_manifest(&dir, |t| {
        t.insert("format".into(), "some-other-map".into());
    });
    let e = expect_error(&dir, "map.toml", &["format", "tvs-map"]);
    assert!(matches!(e, MapError::WrongFormat { .. }), "{e:?}");
}

#[test]
fn malformed_missing_layer() {
    let (_t, dir) = broken_copy();
    std::fs::remove_file(dir.join("density_bush.png")).unwrap();
    let e = expect_error(&dir, "density_bush.png", &["listed in map.toml"]);
    assert!(matches!(e, MapError::Io { .. }), "{e:?}");
}

#[test]
fn malformed_negative_and_zero_spacing() {
    for spacing in [-4.0, 0.0] {
        let (_t, dir) = broken_copy();
        edit_manifest(&dir, |t| {
            table(t, "heights").insert("spacing_m".into(), spacing.into());
        });
        let e = expect_error(&dir, "map.toml", &["heights.spacing_m", "positive"]);
        assert!(matches!(e, MapError::InvalidField { .. }), "{e:?}");
    }
}

#[test]
fn malformed_absurd_size_is_refused_before_allocation() {
    let (_t, dir) = broken_copy();
    edit_manifest(&dir, |t| {
        let h = table(t, "heights");
        h.insert("width".into(), 1_000_000_000.into());
        h.insert("height".into(), 1_000_000_000.into());
    });
    // If this allocated 10^18 samples it would abort the test process, not return an error.
    let e = expect_error(&dir, "map.toml", &["1000000000x1000000000", "limit"]);
    assert!(matches!(e, MapError::TooLarge { .. }), "{e:?}");
}

#[test]
fn malformed_density_out_of_range() {
    let (_t, dir) = broken_copy();
    edit_manifest(&dir, |t| {
        let veg = t
            .get_mut("vegetation")
            .and_then(toml::Value::as_array_mut)
            .unwrap();
        veg[0]
            .as_table_mut()
            .unwrap()
            .insert("max_density_per_m2".into(), (-1.0).into());
    });
    let e = expect_error(
        &dir,
        "map.toml",
        &["vegetation[0].max_density_per_m2", "-1"],
    );
    assert!(matches!(e, MapError::InvalidField { .. }), "{e:?}");
    // Denser than the species' minimum distance allows.
    let (_t2, dir2) = broken_copy();
    edit_manifest(&dir2, |t| {
        let veg = t
            .get_mut("vegetation")
            .and_then(toml::Value::as_array_mut)
            .unwrap();
        veg[0]
            .as_table_mut()
            .unwrap()
            .insert("max_density_per_m2".into(), 50.0.into());
    });
    expect_error(
        &dir2,
        "map.toml",
        &["vegetation[0].max_density_per_m2", "apart"],
    );
}

#[test]
fn malformed_empty_tree_list_file() {
    let (_t, dir) = broken_copy();
    std::fs::write(dir.join("trees.csv"), "").unwrap();
    let e = expect_error(&dir, "trees.csv", &["line 1", "empty", "tvs-trees 1"]);
    assert!(matches!(e, MapError::ListLine { line: 1, .. }), "{e:?}");
}

#[test]
fn malformed_tree_rows() {
    let (_t, dir) = broken_copy();
    let header = "tvs-trees 1\nspecies,x_m,y_m,height_m,crown_radius_m\n";
    std::fs::write(
        dir.join("trees.csv"),
        format!("{header}0,10,10,20,3\n9,10,10,20,3\n"),
    )
    .unwrap();
    expect_error(&dir, "trees.csv", &["line 4", "species 9"]);
    std::fs::write(dir.join("trees.csv"), format!("{header}0,10,abc,20,3\n")).unwrap();
    expect_error(&dir, "trees.csv", &["line 3", "y_m"]);
    std::fs::write(dir.join("trees.csv"), format!("{header}0,-50,10,20,3\n")).unwrap();
    expect_error(&dir, "trees.csv", &["outside the world"]);
}

#[test]
fn malformed_garbage_manifest() {
    let (_t, dir) = broken_copy();
    std::fs::write(dir.join("map.toml"), b"\x00\x01 this is = = not toml [[[").unwrap();
    let e = expect_error(&dir, "map.toml", &[]);
    assert!(
        matches!(e, MapError::Io { .. } | MapError::ManifestSyntax { .. }),
        "{e:?}"
    );
    std::fs::write(
        dir.join("map.toml"),
        "format = \"tvs-map\"\nversion = 1\nname = [",
    )
    .unwrap();
    let e = expect_error(&dir, "map.toml", &["not a valid manifest"]);
    assert!(matches!(e, MapError::ManifestSyntax { .. }), "{e:?}");
}

#[test]
fn malformed_misspelled_manifest_field() {
    let (_t, dir) = broken_copy();
    edit_manifest(&dir, |t| {
        let h = table(t, "heights");
        let v = h.remove("spacing_m").unwrap();
        h.insert("spacing".into(), v);
    });
    expect_error(&dir, "map.toml", &["spacing"]);
}

#[test]
fn malformed_ground_type_outside_legend() {
    let (_t, dir) = broken_copy();
    let mut map = Map::load(&dir).unwrap();
    map.ground
        .grid_mut()
        .expect("ground in memory")
        .set(3, 4, 42);
    map.write(&dir).unwrap();
    let e = expect_error(&dir, "ground.png", &["column 3", "row 4", "type 42"]);
    assert!(
        matches!(e, MapError::GroundTypeOutOfRange { value: 42, .. }),
        "{e:?}"
    );
}

#[test]
fn malformed_density_png_of_wrong_colour_type() {
    let (_t, dir) = broken_copy();
    let map = Map::load(&dir).unwrap();
    let spec = &map.manifest.vegetation[1];
    let f = std::fs::File::create(dir.join(&spec.file)).unwrap();
    let mut enc = png::Encoder::new(f, spec.width, spec.height);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut w = enc.write_header().unwrap();
    w.write_image_data(&vec![0u8; (spec.width * spec.height * 3) as usize])
        .unwrap();
    w.finish().unwrap();
    let e = expect_error(&dir, &spec.file, &["vegetation[1].file", "Grayscale"]);
    assert!(matches!(e, MapError::BadLayerFile { .. }), "{e:?}");
}

#[test]
fn malformed_decal_and_path_escape() {
    let (_t, dir) = broken_copy();
    std::fs::write(
        dir.join("decals.toml"),
        "format = \"tvs-decals\"\nversion = 1\n[[decal]]\nkind = \"road\"\nwidth_m = 6.0\nfalloff_m = 1.0\nheight_offset_m = 0.0\npoints = [[1.0, 1.0, 0.0]]\n",
    )
    .unwrap();
    expect_error(&dir, "decals.toml", &["decal[0].points", "at least 2"]);
    let (_t2, dir2) = broken_copy();
    edit_manifest(&dir2, |t| {
        table(t, "heights").insert("file".into(), "../../etc/passwd".into());
    });
    expect_error(&dir2, "map.toml", &["heights.file", "plain file name"]);
}

// ---- material images ---------------------------------------------------------------------

/// Writes an 8-bit PNG of `color` type with `channels` bytes per texel.
fn write_test_png(path: &Path, w: u32, h: u32, color: png::ColorType, texel: &[u8]) {
    let file = std::fs::File::create(path).unwrap();
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w, h);
    enc.set_color(color);
    enc.set_depth(png::BitDepth::Eight);
    let data: Vec<u8> = (0..w * h).flat_map(|_| texel.iter().copied()).collect();
    let mut writer = enc.write_header().unwrap();
    writer.write_image_data(&data).unwrap();
    writer.finish().unwrap();
}

/// Names `file` as legend entry 2's material.
fn name_material(dir: &Path, file: &str) {
    edit_manifest(dir, |t| {
        let legend = table(t, "ground")
            .get_mut("legend")
            .and_then(toml::Value::as_array_mut)
            .unwrap();
        legend[2]
            .as_table_mut()
            .unwrap()
            .insert("material".into(), file.into());
    });
}

/// A map naming a material image loads it, writes it back unchanged, and the engine's material
/// for that type is made from the image (its texels are the image's colour), the others not.
#[test]
fn a_named_material_image_loads_round_trips_and_makes_the_material() {
    let (_t, dir) = broken_copy();
    write_test_png(
        &dir.join("stone.png"),
        64,
        64,
        png::ColorType::Rgb,
        &[90, 80, 200],
    );
    name_material(&dir, "stone.png");
    let map = Map::load(&dir).expect("a valid material image loads");
    let image = map.materials[2].as_ref().expect("entry 2 has its image");
    assert_eq!(image.side, 64);
    assert!(image.rgba.iter().all(|p| *p == [90, 80, 200, 255]));
    assert!(
        map.materials
            .iter()
            .enumerate()
            .all(|(i, m)| (i == 2) == m.is_some())
    );
    let tmp = tempfile::tempdir().unwrap();
    let again = tmp.path().join("again");
    map.write(&again).expect("write");
    assert_eq!(Map::load(&again).expect("reload"), map);
    let mats = engine::ground::materials::materials(&map.manifest.ground.legend, &map.materials, 1);
    assert!(mats[2].albedo_srgb.iter().all(|p| *p == [90, 80, 200, 255]));
    assert!(
        mats[1]
            .albedo_srgb
            .iter()
            .any(|p| *p != mats[1].albedo_srgb[0])
    );
}

/// Broken material images are refused with an error naming the file and the manifest field.
#[test]
fn malformed_material_images() {
    let field = "ground.legend[2].material";
    // Missing file.
    let (_t, dir) = broken_copy();
    name_material(&dir, "nothere.png");
    let e = expect_error(&dir, "nothere.png", &["material"]);
    assert!(matches!(e, MapError::Io { .. }), "{e:?}");
    // A path out of the map folder.
    let (_t, dir) = broken_copy();
    name_material(&dir, "../stone.png");
    let e = expect_error(&dir, "map.toml", &[field, "plain file name"]);
    assert!(matches!(e, MapError::InvalidField { .. }), "{e:?}");
    // Not a PNG; a truncated PNG.
    let (_t, dir) = broken_copy();
    std::fs::write(dir.join("stone.png"), b"GIF89a not a png at all").unwrap();
    name_material(&dir, "stone.png");
    let e = expect_error(&dir, "stone.png", &[field, "material PNG"]);
    assert!(matches!(e, MapError::BadLayerFile { .. }), "{e:?}");
    let (_t, dir) = broken_copy();
    let p = dir.join("stone.png");
    write_test_png(&p, 128, 128, png::ColorType::Rgba, &[1, 2, 3, 255]);
    let bytes = std::fs::read(&p).unwrap();
    std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
    name_material(&dir, "stone.png");
    expect_error(&dir, "stone.png", &[field, "material PNG"]);
    // Wrong shapes and sample types; a huge header refused before decoding.
    for (w, h, color, texel, words) in [
        (100, 100, png::ColorType::Rgb, &[1u8, 2, 3][..], "100x100"),
        (64, 32, png::ColorType::Rgb, &[1, 2, 3][..], "64x32"),
        (8, 8, png::ColorType::Rgb, &[1, 2, 3][..], "8x8"),
        (2048, 2048, png::ColorType::Grayscale, &[7][..], "2048x2048"),
        (
            64,
            64,
            png::ColorType::Grayscale,
            &[7][..],
            "expected 8-bit RGB or RGBA",
        ),
    ] {
        let (_t, dir) = broken_copy();
        write_test_png(&dir.join("stone.png"), w, h, color, texel);
        name_material(&dir, "stone.png");
        let e = expect_error(&dir, "stone.png", &[field, words]);
        assert!(matches!(e, MapError::BadLayerFile { .. }), "{e:?}");
    }
}

// ---- ground patches ----------------------------------------------------------------------

/// Worldgen's closed areas on a 2 km map: all three kinds appear; each keeps off roads and
/// paths (no outline point or centre within the road's half width + 2 m of a centre line) and
/// off water (every outline point above the water level) and off house pads; two areas of a
/// kind never overlap
/// (disjoint boxes); and the vegetation density is zero at a field's centre.
#[test]
fn ground_patches_keep_off_roads_water_and_each_other() {
    let map = tests::generated(&tests::patches_map_params());
    // House pads are checked against their footprints in tests/e2e/towns.rs; patches keep off
    // them too.
    let areas: Vec<_> = map
        .decals
        .iter()
        .filter(|d| d.closed && d.kind != DecalKind::Pad)
        .collect();
    let pads: Vec<_> = map
        .decals
        .iter()
        .filter(|d| d.kind == DecalKind::Pad)
        .collect();
    assert!(!pads.is_empty(), "no houses on a 2 km map");
    let roads: Vec<_> = map.decals.iter().filter(|d| !d.closed).collect();
    assert!(!roads.is_empty(), "no roads to keep off");
    for kind in [DecalKind::Field, DecalKind::Dirt, DecalKind::RockPatch] {
        let n = areas.iter().filter(|d| d.kind == kind).count();
        assert!(n > 0, "no {kind:?} on a 2 km map");
    }
    let bbox = |d: &Decal| {
        d.points.iter().fold(
            ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
            |(lo, hi), p| {
                (
                    [lo[0].min(p[0]), lo[1].min(p[1])],
                    [hi[0].max(p[0]), hi[1].max(p[1])],
                )
            },
        )
    };
    for (i, d) in areas.iter().enumerate() {
        assert!(d.kind.is_area());
        let n = d.points.len() as f64;
        let centre = [
            d.points.iter().map(|p| p[0]).sum::<f64>() / n,
            d.points.iter().map(|p| p[1]).sum::<f64>() / n,
        ];
        for q in d.points.iter().map(|p| [p[0], p[1]]).chain([centre]) {
            for r in &roads {
                for w in r.points.windows(2) {
                    let dist = worldgen::roads::point_segment_distance_m(
                        q,
                        [w[0][0], w[0][1]],
                        [w[1][0], w[1][1]],
                    );
                    assert!(
                        dist > 0.5 * f64::from(r.width_m) + 2.0,
                        "{:?} point {q:?} is {dist} m from a {:?}",
                        d.kind,
                        r.kind
                    );
                }
            }
            for pad in &pads {
                assert!(
                    !worldgen::roads::inside_polygon(q, &pad.points),
                    "{:?} point {q:?} is on a house pad",
                    d.kind
                );
            }
            let h = map.height_bilinear_m(q[0], q[1]);
            assert!(
                h > map.manifest.water_level_m,
                "{:?} point {q:?} under water",
                d.kind
            );
        }
        let (lo, hi) = bbox(d);
        for o in areas[i + 1..].iter().filter(|o| o.kind == d.kind) {
            let (olo, ohi) = bbox(o);
            let apart = lo[0] > ohi[0] || olo[0] > hi[0] || lo[1] > ohi[1] || olo[1] > hi[1];
            assert!(
                apart,
                "two {:?} areas overlap: {lo:?}..{hi:?} and {olo:?}..{ohi:?}",
                d.kind
            );
        }
        if d.kind == DecalKind::Field {
            for layer in &map.densities {
                let s = layer.spec.spacing_m;
                let x = ((centre[0] - map.manifest.origin_m[0]) / s).round() as usize;
                let y = ((centre[1] - map.manifest.origin_m[1]) / s).round() as usize;
                assert_eq!(
                    layer.density.get(x, y),
                    0,
                    "{} grows in the field at {centre:?}",
                    layer.spec.species
                );
            }
        }
    }
    // A map written and read back keeps its areas (decals version 3).
    let tmp = tempfile::tempdir().unwrap();
    map.write(&tmp.path().join("m")).expect("write");
    let again = Map::load(&tmp.path().join("m")).expect("load");
    assert_eq!(again.decals, map.decals);
}

/// A decals file of version 1 still loads (roads, paths, rock patches); a version-1 file with a
/// field, a version-2 file with a pad, or an area kind not marked closed, is refused naming the
/// decal and field.
#[test]
fn decal_versions_and_area_kinds_are_checked() {
    let (_t, dir) = broken_copy();
    let p = dir.join("decals.toml");
    let text = std::fs::read_to_string(&p).unwrap();
    assert!(
        text.contains("version = 3"),
        "the tiny map writes decals version 3"
    );
    assert!(text.contains("\"pad\""), "the tiny map has house pads");
    // Pads need version 3.
    std::fs::write(&p, text.replace("version = 3", "version = 2")).unwrap();
    expect_error(&dir, "decals.toml", &["kind", "\"pad\"", "version 3"]);
    let v1: String = text
        .replace("version = 3", "version = 1")
        .split("[[decal]]")
        .filter(|block| {
            !block.contains("\"field\"")
                && !block.contains("\"dirt\"")
                && !block.contains("\"pad\"")
        })
        .collect::<Vec<_>>()
        .join("[[decal]]");
    std::fs::write(&p, &v1).unwrap();
    Map::load(&dir).expect("a version-1 decal file without the new kinds loads");
    let field = "[[decal]]\nkind = \"field\"\nclosed = true\nwidth_m = 1.0\nfalloff_m = 1.0\n\
                 height_offset_m = 0.0\npoints = [[10.0, 10.0, 5.0], [30.0, 10.0, 5.0], \
                 [30.0, 30.0, 5.0]]\n";
    std::fs::write(&p, format!("{v1}\n{field}")).unwrap();
    expect_error(&dir, "decals.toml", &["kind", "version 2"]);
    let v2 = text.clone();
    std::fs::write(
        &p,
        format!("{v2}\n{}", field.replace("closed = true", "closed = false")),
    )
    .unwrap();
    expect_error(&dir, "decals.toml", &["closed", "field"]);
}
