//! Several GeoTIFF tiles imported as one map (`worldgen import-dem a.tif b.tif ...`): the
//! tiles of a raster, given in any order, import exactly as the whole raster; a missing tile is
//! filled and counted as voids; tiles off the lattice, of another pixel size or without a
//! projected position are refused naming the file.

use super::geotiff::{Geo, H, W, height, run, utm, write_strips};
use std::path::{Path, PathBuf};
use tiff::encoder::Compression;
use tiff::encoder::colortype;
use worldgen::dem::{ImportParams, import};

/// Writes the test raster's columns `c0..=c1` and rows `r0..=r1` (from the north) as a
/// GeoTIFF tile placed where they lie in the whole raster (`shift_m` added to its position,
/// `pixel_m` its pixel size).
fn tile(path: &Path, [c0, c1]: [u32; 2], [r0, r1]: [u32; 2], shift_m: f64, pixel_m: f64) {
    let data: Vec<u16> = (r0..=r1)
        .flat_map(|r| (c0..=c1).map(move |c| height(c, r) as u16))
        .collect();
    let whole = utm();
    let tie = whole.tie.expect("utm has a tie point");
    let geo = Geo {
        scale: Some([pixel_m, pixel_m, 0.0]),
        tie: Some(vec![
            0.0,
            0.0,
            0.0,
            tie[3] + f64::from(c0) * 2.0 + shift_m,
            tie[4] - f64::from(r0) * 2.0,
            0.0,
        ]),
        ..whole
    };
    write_strips::<colortype::Gray16>(
        path,
        Compression::Uncompressed,
        c1 - c0 + 1,
        r1 - r0 + 1,
        &data,
        &geo,
    );
}

fn mosaic(paths: &[PathBuf]) -> Result<(worldgen::Map, worldgen::dem::ImportReport), String> {
    let mut p = ImportParams::new(paths[0].clone());
    p.mosaic = paths[1..].to_vec();
    import(&p, &mut Vec::new()).map_err(|e| e.to_string())
}

/// The four quarters of the raster (sharing their border row and column, as SRTM tiles do),
/// in a scrambled order, import as the whole raster does: same heights bit for bit, same origin.
#[test]
fn the_tiles_of_a_raster_import_as_the_whole_raster() {
    let tmp = tempfile::tempdir().unwrap();
    let whole = tmp.path().join("whole.tif");
    let data: Vec<u16> = (0..H)
        .flat_map(|r| (0..W).map(move |c| height(c, r) as u16))
        .collect();
    write_strips::<colortype::Gray16>(&whole, Compression::Uncompressed, W, H, &data, &utm());
    let (expected, _) = run(&whole).expect("the whole raster imports");
    let quarters = [
        ([0, 20], [0, 14]),
        ([20, W - 1], [0, 14]),
        ([0, 20], [14, H - 1]),
        ([20, W - 1], [14, H - 1]),
    ];
    let paths: Vec<PathBuf> = quarters
        .iter()
        .enumerate()
        .map(|(i, &(c, r))| {
            let p = tmp.path().join(format!("q{i}.tif"));
            tile(&p, c, r, 0.0, 2.0);
            p
        })
        .collect();
    for order in [[0, 1, 2, 3], [3, 1, 0, 2], [2, 3, 1, 0]] {
        let given: Vec<PathBuf> = order.iter().map(|&i| paths[i].clone()).collect();
        let (map, report) = mosaic(&given).expect("the tiles import");
        assert_eq!(map.heights, expected.heights, "order {order:?}");
        assert_eq!(map.manifest.origin_m, expected.manifest.origin_m);
        assert_eq!(report.voids_filled, 0);
        assert!(
            report.georeference.contains("mosaic of 4"),
            "{}",
            report.georeference
        );
    }
    // Without the south-east quarter the map still covers the whole rectangle (the other three
    // reach its corners); what no tile covers is filled and counted.
    let (map, report) = mosaic(&paths[..3]).expect("three tiles import");
    assert_eq!(
        (map.heights.width(), map.heights.height()),
        (expected.heights.width(), expected.heights.height())
    );
    assert_eq!(report.voids_filled, ((W - 1 - 20) * (H - 1 - 14)) as usize);
}

/// Writes a test file at a path.
type Writer = Box<dyn Fn(&Path)>;

/// A tile half a pixel off the lattice, one of another pixel size, one without a projected
/// position and a file that is not a GeoTIFF are refused, naming the file.
#[test]
fn tiles_that_do_not_share_the_lattice_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let first = tmp.path().join("first.tif");
    tile(&first, [0, 20], [0, 14], 0.0, 2.0);
    let cases: Vec<(&str, Writer, &str)> = vec![
        (
            "shifted.tif",
            Box::new(|p| tile(p, [20, W - 1], [0, 14], 1.0, 2.0)),
            "not on",
        ),
        (
            "coarser.tif",
            Box::new(|p| tile(p, [20, W - 1], [0, 14], 0.0, 4.0)),
            "spacing",
        ),
        (
            "plain.tif",
            Box::new(|p| {
                let data: Vec<u16> = vec![100; 16];
                write_strips::<colortype::Gray16>(
                    p,
                    Compression::Uncompressed,
                    4,
                    4,
                    &data,
                    &Geo::default(),
                );
            }),
            "georeferencing",
        ),
        (
            "heights.png",
            Box::new(|p| std::fs::write(p, b"not a tiff").unwrap()),
            "GeoTIFF files",
        ),
    ];
    for (name, write, expected) in cases {
        let p = tmp.path().join(name);
        write(&p);
        let err = mosaic(&[first.clone(), p.clone()]).expect_err(name);
        assert!(
            err.contains(name) && err.contains(expected),
            "{name}: {err}"
        );
    }
}
