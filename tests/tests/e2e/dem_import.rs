//! Real elevation data through `worldgen::dem` into a map that loads: the SRTM tile near
//! Gothenburg (85% flat sea at 0 m, a hard case downstream) and the Puget Sound PNG.

use worldgen::Map;
use worldgen::classify;
use worldgen::dem::{ImportParams, import};

fn params(path: std::path::PathBuf) -> ImportParams {
    ImportParams::new(path)
}

#[test]
fn srtm_tile_imports_and_loads_with_flat_sea() {
    let path = tests::test_data("dem/N57E011.hgt");
    let (map, report) = import(&params(path), &mut Vec::new()).expect("import");
    assert_eq!(report.source_samples, [1201, 1201]);
    assert_eq!(report.voids_filled, 0);
    // 3 arc-seconds: ~92.6 m north-south, ~49.8 m east-west at 57.5 N; resampled to the finer.
    assert!(
        (report.source_spacing_m[1] - 92.61).abs() < 0.01,
        "{report:?}"
    );
    // Resampled to the engine's lattice, at least as fine as the finer source spacing.
    assert_eq!(report.spacing_m, 32.0, "{report:?}");
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("n57");
    map.write(&dir).unwrap();
    let loaded = Map::load(&dir).expect("imported map must load");
    assert_eq!(loaded, map);
    let s = loaded.summary();
    assert!(
        (-10.0..=-5.0).contains(&s.height_min_m) && (160.0..=165.0).contains(&s.height_max_m),
        "{s}"
    );
    // The sea stays exactly flat (no interpolation ripples), and is classified as water.
    let zeros = loaded
        .heights
        .grid()
        .expect("heights in memory")
        .data()
        .iter()
        .filter(|&&h| h == 0.0)
        .count();
    let frac = zeros as f64
        / loaded
            .heights
            .grid()
            .expect("heights in memory")
            .data()
            .len() as f64;
    assert!(frac > 0.80, "only {frac:.3} of samples are exactly 0 m");
    let ground = loaded.ground.grid().expect("ground in memory").data();
    let water = ground.iter().filter(|&&g| g == classify::WATER).count() as f64;
    assert!(water / ground.len() as f64 > 0.80);
    // No vegetation in the sea.
    for d in &loaded.densities {
        let (w, h) = (d.density.width(), d.density.height());
        let stride = (loaded.heights.width() - 1) / (w - 1);
        for y in 0..h {
            for x in 0..w {
                if loaded.ground.get(x * stride, y * stride) == classify::WATER {
                    assert_eq!(
                        d.density.get(x, y),
                        0,
                        "{} grows in the sea",
                        d.spec.species
                    );
                }
            }
        }
    }
}

#[test]
fn void_samples_are_filled_and_counted() {
    let path = tests::test_data("dem/N57E011.hgt");
    let tmp = tempfile::tempdir().unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    // Punch a 10x10 void block into the tile (rows 600.., columns 700..).
    for r in 600..610 {
        for c in 700..710 {
            let i = (r * 1201 + c) * 2;
            bytes[i..i + 2].copy_from_slice(&i16::MIN.to_be_bytes());
        }
    }
    let p = tmp.path().join("N57E011.hgt");
    std::fs::write(&p, &bytes).unwrap();
    let (map, report) = import(&params(p.clone()), &mut Vec::new()).unwrap();
    assert_eq!(report.voids_filled, 100);
    let (lo, hi) = map.heights.grid().expect("heights in memory").min_max();
    assert!(
        lo > -10.0 && hi < 170.0,
        "filled values out of the data range: {lo}..{hi}"
    );
    // All voids is an error that names the file.
    let void_tile: Vec<u8> = std::iter::repeat_n(i16::MIN.to_be_bytes(), 1201 * 1201)
        .flatten()
        .collect();
    std::fs::write(&p, void_tile).unwrap();
    let err = import(&params(p.clone()), &mut Vec::new())
        .unwrap_err()
        .to_string();
    assert!(err.contains("N57E011.hgt") && err.contains("void"), "{err}");
    // A file of the wrong length is refused with the expected sizes.
    std::fs::write(&p, [0u8; 1000]).unwrap();
    let err = import(&params(p), &mut Vec::new()).unwrap_err().to_string();
    assert!(err.contains("2884802"), "{err}");
}

/// A latitude outside +-85 degrees (or not finite) is refused by name, not turned into a
/// misleading size error.
#[test]
fn out_of_range_latitude_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("tile.hgt");
    std::fs::write(&p, vec![0u8; 2_884_802]).unwrap();
    for lat in [91.0, -90.0, f64::NAN, f64::INFINITY] {
        let mut params = params(p.clone());
        params.latitude_deg = Some(lat);
        let err = import(&params, &mut Vec::new()).unwrap_err().to_string();
        assert!(
            err.contains("latitude") && err.contains("tile.hgt"),
            "{lat}: {err}"
        );
    }
    // Control: the same file at a valid latitude gets past the check.
    let mut ok = params(p);
    ok.latitude_deg = Some(57.0);
    if let Err(e) = import(&ok, &mut Vec::new()) {
        assert!(!e.to_string().contains("latitude"), "{e}");
    }
}

#[test]
fn puget_sound_png_imports_with_vertical_scale() {
    let path = tests::test_data("dem/ps_height_1k.png");
    let mut p = params(path.clone());
    let err = import(&p, &mut Vec::new()).unwrap_err().to_string();
    assert!(err.contains("--spacing-m"), "{err}");
    p.spacing_m = Some(160.0);
    p.vertical_scale_m = 0.1;
    let (map, _) = import(&p, &mut Vec::new()).expect("import");
    assert_eq!(map.manifest.size_m, [163_840.0, 163_840.0]);
    let (lo, hi) = map.heights.grid().expect("heights in memory").min_max();
    assert!(lo == 0.0 && (4379.0..=4380.0).contains(&hi), "{lo}..{hi}");
}

#[test]
fn single_channel_exr_imports_with_nan_voids() {
    // The committed tiny map's heights as an EXR (written by the map writer), with a NaN void.
    let tmp = tempfile::tempdir().unwrap();
    let mut map = worldgen::Map::load(&tests::tiny_map_dir()).unwrap();
    let original = map.heights.clone();
    let hg = map.heights.grid_mut().expect("heights in memory");
    hg.set(60, 70, f32::NAN);
    // Write only the height layer, through a scratch map folder.
    let scratch = tmp.path().join("scratch");
    map.write(&scratch).unwrap();
    let exr = tmp.path().join("heights.exr");
    std::fs::copy(scratch.join("heights.exr"), &exr).unwrap();
    let mut p = params(exr.clone());
    let err = import(&p, &mut Vec::new()).unwrap_err().to_string();
    assert!(err.contains("--spacing-m"), "{err}");
    p.spacing_m = Some(4.0);
    let (imported, report) = import(&p, &mut Vec::new()).expect("import");
    assert_eq!(report.voids_filled, 1);
    assert_eq!(imported.manifest.size_m, [512.0, 512.0]);
    // Every sample but the void is exact; the void is filled from its neighbours.
    let (imported, original) = (
        imported.heights.grid().expect("heights in memory"),
        original.grid().expect("heights in memory"),
    );
    for (i, (&a, &b)) in imported.data().iter().zip(original.data()).enumerate() {
        if i == 70 * 129 + 60 {
            assert!((a - b).abs() < 5.0, "filled void {a} far from {b}");
        } else {
            assert_eq!(a, b, "sample {i}");
        }
    }
    // A file that is not an EXR names itself.
    std::fs::write(&exr, b"not an exr").unwrap();
    let err = import(&p, &mut Vec::new()).unwrap_err().to_string();
    assert!(
        err.contains("heights.exr") && err.contains("OpenEXR"),
        "{err}"
    );
}

/// Two SRTM tiles side by side join into one map: the real tile and, east of it, its mirror
/// image, which repeats the tile's east column as its own west column as real neighbours do.
/// The mosaic has 2,401 x 1,201 source samples at the tile's own spacing (both lie at one
/// latitude), and its western columns are the single tile's import sample for sample (up to
/// the seam, where the resampling sees the neighbour). A tile of another resolution
/// and one whose name carries no position are refused, naming the file.
#[test]
fn srtm_tiles_side_by_side_import_as_one_map() {
    let tmp = tempfile::tempdir().unwrap();
    let west = tmp.path().join("N57E011.hgt");
    std::fs::copy(tests::test_data("dem/N57E011.hgt"), &west).unwrap();
    let bytes = std::fs::read(&west).unwrap();
    let mirrored: Vec<u8> = bytes
        .chunks_exact(1201 * 2)
        .flat_map(|row| {
            row.chunks_exact(2)
                .rev()
                .flatten()
                .copied()
                .collect::<Vec<u8>>()
        })
        .collect();
    let east = tmp.path().join("N57E012.hgt");
    std::fs::write(&east, &mirrored).unwrap();
    let (one, one_report) = import(&params(west.clone()), &mut Vec::new()).expect("one tile");
    let mut p = params(west.clone());
    p.mosaic = vec![east.clone()];
    let (two, report) = import(&p, &mut Vec::new()).expect("two tiles");
    assert_eq!(report.source_samples, [2401, 1201]);
    assert_eq!(report.source_spacing_m, one_report.source_spacing_m);
    assert_eq!(report.voids_filled, 0);
    assert!(
        report.georeference.contains("mosaic of 2 SRTM tiles"),
        "{}",
        report.georeference
    );
    assert_eq!(two.heights.height(), one.heights.height());
    assert_eq!(two.heights.width() - 1, 2 * (one.heights.width() - 1));
    // Resampled to the same lattice: a map column whose stencil (4 source columns, the limiter
    // 2) stays west of the seam (source column 1,200) is the one-tile map's column.
    let step = 1200.0 / (one.heights.width() - 1) as f64;
    let west_columns = (0..one.heights.width())
        .take_while(|&x| x as f64 * step + 2.0 < 1199.0)
        .count();
    assert!(west_columns > 1800, "{west_columns}");
    for y in 0..one.heights.height() {
        for x in 0..west_columns {
            assert_eq!(two.heights.get(x, y), one.heights.get(x, y), "({x}, {y})");
        }
    }
    // Refusals name the file.
    let fine = tmp.path().join("N57E013.hgt");
    std::fs::write(&fine, vec![0u8; 3601 * 3601 * 2]).unwrap();
    let nameless = tmp.path().join("tile.hgt");
    std::fs::copy(&west, &nameless).unwrap();
    for (other, expected) in [(&fine, "arc-second"), (&nameless, "no latitude")] {
        let mut p = params(west.clone());
        p.mosaic = vec![other.clone()];
        let err = import(&p, &mut Vec::new())
            .expect_err("refused")
            .to_string();
        assert!(
            err.contains(&*other.to_string_lossy()) && err.contains(expected),
            "{err}"
        );
    }
}
