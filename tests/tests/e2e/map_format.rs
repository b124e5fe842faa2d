//! Map format v1 end to end: generation determinism, the committed tiny map, write/load round
//! trips, and a matrix of malformed maps that must each give their specific error (never a
//! panic, never a half-loaded map).

use std::path::Path;
use tests::{copy_dir, hash_dir, tiny_map_dir, tiny_map_params};
use worldgen::Map;
use worldgen::generate::{GenerateParams, generate};
use worldgen::map::MapError;
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
    let mut names: Vec<_> = std::fs::read_dir(&committed)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    names.sort();
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
    let regenerated = std::fs::read_dir(&out).unwrap().count();
    assert_eq!(
        regenerated,
        names.len(),
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
    map.heights.set(17, 23, f32::NAN);
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
        t.insert("version".into(), 3.into());
    });
    let e = expect_error(&dir, "map.toml", &["version", "3"]);
    assert!(
        matches!(e, MapError::UnknownVersion { found: 3, .. }),
        "{e:?}"
    );
    // A version-1 map (before the Poisson tile) says so and how to fix it.
    let (_t, dir) = broken_copy();
    edit_manifest(&dir, |t| {
        t.insert("version".into(), 1.into());
    });
    expect_error(&dir, "map.toml", &["version", "1", "regenerate"]);
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
    map.ground.set(3, 4, 42);
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
