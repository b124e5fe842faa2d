//! GeoTIFF import (`worldgen import-dem x.tif`): every supported layout, sample type and
//! compression written here with the `tiff` encoder and read back exactly; georeferencing
//! (projected metres and feet, pixel-is-point, south-up, geographic degrees against published
//! degree lengths); GDAL nodata voids; and every refusal naming its tag.

use std::io::Cursor;
use std::path::{Path, PathBuf};
use tiff::encoder::colortype::{self, ColorType};
use tiff::encoder::compression::{CompressionAlgorithm, Deflate, Lzw, Packbits};
use tiff::encoder::{Compression, DeflateLevel, TiffEncoder, TiffValue};
use tiff::tags::Tag;
use worldgen::dem::{DemError, ImportParams, import};

pub(super) const W: u32 = 40;
pub(super) const H: u32 = 30;

/// The test raster: sample (col, row from the north), integer-valued so that every sample type
/// holds it exactly; 20..=219 so that it fits 8 bits.
pub(super) fn height(col: u32, row: u32) -> f64 {
    f64::from((col * 5 + row * 3 + (col * row) % 11) % 200 + 20)
}

fn raster() -> Vec<f64> {
    (0..H)
        .flat_map(|r| (0..W).map(move |c| height(c, r)))
        .collect()
}

/// GeoTIFF tags to write: pixel size + tie point or a full transform, GeoKeys, nodata.
#[derive(Clone, Default)]
pub(super) struct Geo {
    pub(super) scale: Option<[f64; 3]>,
    pub(super) tie: Option<Vec<f64>>,
    pub(super) transform: Option<[f64; 16]>,
    pub(super) keys: Vec<(u16, u16)>,
    pub(super) nodata: Option<String>,
}

/// 2 m pixels, north-west corner at (500000, 6400000) in projected metres.
pub(super) fn utm() -> Geo {
    Geo {
        scale: Some([2.0, 2.0, 0.0]),
        tie: Some(vec![0.0, 0.0, 0.0, 500_000.0, 6_400_000.0, 0.0]),
        keys: vec![(1024, 1), (3076, 9001)],
        ..Geo::default()
    }
}

fn write_geo<W: std::io::Write + std::io::Seek, K: tiff::encoder::TiffKind>(
    dir: &mut tiff::encoder::DirectoryEncoder<'_, W, K>,
    geo: &Geo,
) {
    if let Some(s) = geo.scale {
        dir.write_tag(Tag::ModelPixelScaleTag, &s[..]).unwrap();
    }
    if let Some(t) = &geo.tie {
        dir.write_tag(Tag::ModelTiepointTag, &t[..]).unwrap();
    }
    if let Some(m) = geo.transform {
        dir.write_tag(Tag::ModelTransformationTag, &m[..]).unwrap();
    }
    if !geo.keys.is_empty() {
        let mut v: Vec<u16> = vec![1, 1, 0, geo.keys.len() as u16];
        for &(id, value) in &geo.keys {
            v.extend([id, 0, 1, value]);
        }
        dir.write_tag(Tag::GeoKeyDirectoryTag, &v[..]).unwrap();
    }
    if let Some(n) = &geo.nodata {
        dir.write_tag(Tag::GdalNodata, n.as_str()).unwrap();
    }
}

/// A strip-organised GeoTIFF (7 rows per strip) through the encoder's image writer.
pub(super) fn write_strips<C: ColorType>(
    path: &Path,
    compression: Compression,
    w: u32,
    h: u32,
    data: &[C::Inner],
    geo: &Geo,
) where
    [C::Inner]: TiffValue,
{
    let mut bytes = Cursor::new(Vec::new());
    {
        let mut enc = TiffEncoder::new(&mut bytes)
            .unwrap()
            .with_compression(compression);
        let mut img = enc.new_image::<C>(w, h).unwrap();
        img.rows_per_strip(7).unwrap();
        write_geo(img.encoder(), geo);
        img.write_data(data).unwrap();
    }
    std::fs::write(path, bytes.into_inner()).unwrap();
}

/// A tiled GeoTIFF (16x16 tiles, the edge tiles padded) written through the encoder's directory
/// writer and compression algorithms; `compression_tag` is what the file claims.
#[allow(clippy::too_many_arguments)]
fn write_tiles(
    path: &Path,
    compression_tag: u16,
    bits: u16,
    sample_format: u16,
    sample_bytes: &dyn Fn(u32, u32) -> Vec<u8>,
    geo: &Geo,
) {
    const T: u32 = 16;
    let (tx, ty) = (W.div_ceil(T), H.div_ceil(T));
    let mut file = Cursor::new(Vec::new());
    {
        let mut enc = TiffEncoder::new(&mut file).unwrap();
        let mut dir = enc.image_directory().unwrap();
        let (mut offsets, mut counts) = (Vec::new(), Vec::new());
        for j in 0..ty {
            for i in 0..tx {
                let mut raw = Vec::new();
                for r in 0..T {
                    for c in 0..T {
                        let (col, row) = (i * T + c, j * T + r);
                        if col < W && row < H {
                            raw.extend(sample_bytes(col, row));
                        } else {
                            raw.extend(vec![0u8; usize::from(bits / 8)]);
                        }
                    }
                }
                let mut packed = Vec::new();
                match compression_tag {
                    5 => Lzw.write_to(&mut packed, &raw).unwrap(),
                    8 => Deflate::default().write_to(&mut packed, &raw).unwrap(),
                    32773 => Packbits.write_to(&mut packed, &raw).unwrap(),
                    _ => {
                        packed.clone_from(&raw);
                        raw.len() as u64
                    }
                };
                offsets.push(dir.write_data(&packed[..]).unwrap() as u32);
                counts.push(packed.len() as u32);
            }
        }
        dir.write_tag(Tag::ImageWidth, W).unwrap();
        dir.write_tag(Tag::ImageLength, H).unwrap();
        dir.write_tag(Tag::BitsPerSample, bits).unwrap();
        dir.write_tag(Tag::SampleFormat, sample_format).unwrap();
        dir.write_tag(Tag::Compression, compression_tag).unwrap();
        dir.write_tag(Tag::PhotometricInterpretation, 1u16).unwrap();
        dir.write_tag(Tag::SamplesPerPixel, 1u16).unwrap();
        dir.write_tag(Tag::TileWidth, T).unwrap();
        dir.write_tag(Tag::TileLength, T).unwrap();
        dir.write_tag(Tag::TileOffsets, &offsets[..]).unwrap();
        dir.write_tag(Tag::TileByteCounts, &counts[..]).unwrap();
        write_geo(&mut dir, geo);
        dir.finish().unwrap();
    }
    std::fs::write(path, file.into_inner()).unwrap();
}

pub(super) fn run(path: &Path) -> Result<(worldgen::Map, worldgen::dem::ImportReport), DemError> {
    import(&ImportParams::new(path.to_path_buf()), &mut Vec::new())
}

/// Every map sample equals the raster (`offset` added) exactly, north row 0 on top.
fn assert_exact(map: &worldgen::Map, offset: f64, what: &str) {
    assert_eq!(
        (map.heights.width(), map.heights.height()),
        (W as usize, H as usize),
        "{what}"
    );
    for r in 0..H {
        for c in 0..W {
            let got = map.heights.get(c as usize, (H - 1 - r) as usize);
            assert_eq!(
                f64::from(got),
                height(c, r) + offset,
                "{what}: sample ({c}, {r})"
            );
        }
    }
}

fn compressions() -> [(Compression, &'static str); 4] {
    [
        (Compression::Uncompressed, "none"),
        (Compression::Lzw, "LZW"),
        (Compression::Deflate(DeflateLevel::Balanced), "Deflate"),
        (Compression::Packbits, "PackBits"),
    ]
}

/// A sample type's name, what the test raster was offset by, and its writer.
type Case = (&'static str, f64, Box<dyn Fn()>);

#[test]
fn every_sample_type_and_compression_in_strips_imports_exactly() {
    let tmp = tempfile::tempdir().unwrap();
    let v = raster();
    let geo = utm();
    for (comp, name) in compressions() {
        let p = tmp.path().join(format!("strips_{name}.tif"));
        let cases: Vec<Case> = vec![
            ("u8", 0.0, {
                let d: Vec<u8> = v.iter().map(|&x| x as u8).collect();
                let (p, g) = (p.clone(), geo.clone());
                Box::new(move || write_strips::<colortype::Gray8>(&p, comp, W, H, &d, &g))
            }),
            ("u16", 0.0, {
                let d: Vec<u16> = v.iter().map(|&x| x as u16 * 100).collect();
                let (p, g) = (p.clone(), geo.clone());
                Box::new(move || write_strips::<colortype::Gray16>(&p, comp, W, H, &d, &g))
            }),
            ("u32", 0.0, {
                let d: Vec<u32> = v.iter().map(|&x| x as u32).collect();
                let (p, g) = (p.clone(), geo.clone());
                Box::new(move || write_strips::<colortype::Gray32>(&p, comp, W, H, &d, &g))
            }),
            ("i8", -100.0, {
                let d: Vec<i8> = v.iter().map(|&x| (x - 100.0) as i8).collect();
                let (p, g) = (p.clone(), geo.clone());
                Box::new(move || write_strips::<colortype::GrayI8>(&p, comp, W, H, &d, &g))
            }),
            ("i16", -100.0, {
                let d: Vec<i16> = v.iter().map(|&x| (x - 100.0) as i16).collect();
                let (p, g) = (p.clone(), geo.clone());
                Box::new(move || write_strips::<colortype::GrayI16>(&p, comp, W, H, &d, &g))
            }),
            ("i32", -100.0, {
                let d: Vec<i32> = v.iter().map(|&x| (x - 100.0) as i32).collect();
                let (p, g) = (p.clone(), geo.clone());
                Box::new(move || write_strips::<colortype::GrayI32>(&p, comp, W, H, &d, &g))
            }),
            ("f32", -0.5, {
                let d: Vec<f32> = v.iter().map(|&x| x as f32 - 0.5).collect();
                let (p, g) = (p.clone(), geo.clone());
                Box::new(move || write_strips::<colortype::Gray32Float>(&p, comp, W, H, &d, &g))
            }),
            ("f64", -0.25, {
                let d: Vec<f64> = v.iter().map(|&x| x - 0.25).collect();
                let (p, g) = (p.clone(), geo.clone());
                Box::new(move || write_strips::<colortype::Gray64Float>(&p, comp, W, H, &d, &g))
            }),
        ];
        for (ty, offset, write) in cases {
            write();
            let what = format!("{ty} strips, {name}");
            let (map, report) = run(&p).unwrap_or_else(|e| panic!("{what}: {e}"));
            if ty == "u16" {
                // u16 holds the raster in centimetres: check through the vertical scale.
                let mut params = ImportParams::new(p.clone());
                params.vertical_scale_m = 0.01;
                let (map, _) = import(&params, &mut Vec::new()).unwrap();
                assert_exact(&map, 0.0, &what);
            } else {
                assert_exact(&map, offset, &what);
            }
            assert_eq!(report.source_samples, [W as usize, H as usize], "{what}");
            assert_eq!(report.source_spacing_m, [2.0, 2.0], "{what}");
            assert_eq!(report.voids_filled, 0, "{what}");
            // Pixel is area: the first sample is at the centre of the corner pixel.
            let south_y = 6_400_000.0 - 2.0 * f64::from(H) + 1.0;
            assert_eq!(report.origin_m, [500_001.0, south_y], "{what}");
            assert_eq!(map.manifest.origin_m, report.origin_m, "{what}");
            assert_eq!(map.manifest.size_m, [78.0, 58.0], "{what}");
        }
    }
}

#[test]
fn tiled_rasters_of_every_compression_import_exactly() {
    let tmp = tempfile::tempdir().unwrap();
    let geo = utm();
    for (tag, name) in [
        (1u16, "none"),
        (5, "LZW"),
        (8, "Deflate"),
        (32773, "PackBits"),
    ] {
        let p = tmp.path().join(format!("tiles_{name}.tif"));
        write_tiles(
            &p,
            tag,
            16,
            2,
            &|c, r| ((height(c, r) - 100.0) as i16).to_ne_bytes().to_vec(),
            &geo,
        );
        let (map, _) = run(&p).unwrap_or_else(|e| panic!("i16 tiles, {name}: {e}"));
        assert_exact(&map, -100.0, &format!("i16 tiles, {name}"));
        write_tiles(
            &p,
            tag,
            32,
            3,
            &|c, r| (height(c, r) as f32 + 0.75).to_ne_bytes().to_vec(),
            &geo,
        );
        let (map, _) = run(&p).unwrap_or_else(|e| panic!("f32 tiles, {name}: {e}"));
        assert_exact(&map, 0.75, &format!("f32 tiles, {name}"));
    }
}

#[test]
fn gdal_nodata_samples_become_counted_filled_voids() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("voids.tif");
    let holes: Vec<(u32, u32)> = (0..12).map(|i| (3 + i * 3, 4 + (i * 7) % 20)).collect();
    let is_hole = |c: u32, r: u32| holes.contains(&(c, r));
    let ints: Vec<i16> = (0..H)
        .flat_map(|r| (0..W).map(move |c| (r, c)))
        .map(|(r, c)| {
            if is_hole(c, r) {
                -9999
            } else {
                height(c, r) as i16
            }
        })
        .collect();
    let mut geo = utm();
    geo.nodata = Some("-9999".into());
    write_strips::<colortype::GrayI16>(&p, Compression::Lzw, W, H, &ints, &geo);
    let (map, report) = run(&p).unwrap();
    assert_eq!(report.voids_filled, holes.len());
    for r in 0..H {
        for c in 0..W {
            let got = f64::from(map.heights.get(c as usize, (H - 1 - r) as usize));
            if is_hole(c, r) {
                // Filled from the valid neighbours: within their range.
                let near: Vec<f64> = (r.saturating_sub(1)..=(r + 1).min(H - 1))
                    .flat_map(|nr| {
                        (c.saturating_sub(1)..=(c + 1).min(W - 1)).map(move |nc| (nc, nr))
                    })
                    .filter(|&(nc, nr)| !is_hole(nc, nr))
                    .map(|(nc, nr)| height(nc, nr))
                    .collect();
                let lo = near.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = near.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                assert!(
                    (lo - 1e-3..=hi + 1e-3).contains(&got),
                    "hole ({c}, {r}) filled with {got}, neighbours {lo}..{hi}"
                );
            } else {
                assert_eq!(got, height(c, r), "({c}, {r})");
            }
        }
    }
    // GDAL's float nodata (the lowest f32, written as a double) on a float raster.
    let floats: Vec<f32> = (0..H)
        .flat_map(|r| (0..W).map(move |c| (r, c)))
        .map(|(r, c)| {
            if is_hole(c, r) {
                f32::MIN
            } else {
                height(c, r) as f32
            }
        })
        .collect();
    geo.nodata = Some("-3.4028234663852886e+38".into());
    write_strips::<colortype::Gray32Float>(
        &p,
        Compression::Deflate(DeflateLevel::Fast),
        W,
        H,
        &floats,
        &geo,
    );
    let (_, report) = run(&p).unwrap();
    assert_eq!(report.voids_filled, holes.len());
    // All void: refused, naming the file.
    let all = vec![-9999i16; (W * H) as usize];
    geo.nodata = Some("-9999".into());
    write_strips::<colortype::GrayI16>(&p, Compression::Uncompressed, W, H, &all, &geo);
    let err = run(&p).unwrap_err();
    assert!(matches!(err, DemError::AllVoid { .. }), "{err}");
    assert!(err.to_string().contains("voids.tif"), "{err}");
}

/// Published lengths of a degree on WGS84 (e.g. the NGA/USGS tables reproduced in geodesy
/// references): (latitude, metres per degree of latitude, metres per degree of longitude).
const DEGREE_LENGTHS: [(f64, f64, f64); 4] = [
    (0.0, 110_574.3, 111_319.5),
    (30.0, 110_852.4, 96_486.3),
    (45.0, 111_132.1, 78_847.0),
    (60.0, 111_412.3, 55_800.0),
];

#[test]
fn degree_lengths_match_published_tables() {
    for (lat, m_lat, m_lon) in DEGREE_LENGTHS {
        let [a, b] = worldgen::geotiff::metres_per_degree(lat);
        assert!(
            (a - m_lat).abs() < 1.0,
            "{lat} N: {a} m per degree latitude, want {m_lat}"
        );
        assert!(
            (b - m_lon).abs() < 1.0,
            "{lat} N: {b} m per degree longitude, want {m_lon}"
        );
    }
}

#[test]
fn geographic_rasters_are_converted_at_their_centre_latitude() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("geo.tif");
    // 1 arc-second pixels from 11 E, with the raster's centre at 45 N.
    let arcsec = 1.0 / 3600.0;
    let north = 45.0 + 0.5 * f64::from(H) * arcsec;
    let geo = Geo {
        scale: Some([arcsec, arcsec, 0.0]),
        tie: Some(vec![0.0, 0.0, 0.0, 11.0, north, 0.0]),
        keys: vec![(1024, 2), (2054, 9102)],
        ..Geo::default()
    };
    let d: Vec<i16> = raster().iter().map(|&x| x as i16).collect();
    write_strips::<colortype::GrayI16>(&p, Compression::Uncompressed, W, H, &d, &geo);
    let (_, report) = run(&p).unwrap();
    // At 45 N: 111,132 m per degree of latitude, 78,847 of longitude (published, above).
    let [dx, dy] = report.source_spacing_m;
    assert!((dx - 78_847.0 / 3600.0).abs() < 0.01, "{dx}");
    assert!((dy - 111_132.1 / 3600.0).abs() < 0.01, "{dy}");
    assert!(
        report.georeference.contains("geographic"),
        "{}",
        report.georeference
    );
    // Near the poles the conversion is refused by latitude.
    let polar = Geo {
        tie: Some(vec![0.0, 0.0, 0.0, 11.0, 89.0, 0.0]),
        ..geo
    };
    write_strips::<colortype::GrayI16>(&p, Compression::Uncompressed, W, H, &d, &polar);
    let err = run(&p).unwrap_err().to_string();
    assert!(err.contains("latitude") && err.contains("geo.tif"), "{err}");
}

#[test]
fn feet_pixel_is_point_and_south_up_transforms_are_honoured() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("ft.tif");
    let d: Vec<u16> = raster().iter().map(|&x| x as u16).collect();
    // Projected feet, heights in feet, samples at the tie point itself (pixel is point).
    let geo = Geo {
        scale: Some([10.0, 10.0, 0.0]),
        tie: Some(vec![0.0, 0.0, 0.0, 1000.0, 5000.0, 0.0]),
        keys: vec![(1024, 1), (1025, 2), (3076, 9002), (4099, 9002)],
        ..Geo::default()
    };
    write_strips::<colortype::Gray16>(&p, Compression::Lzw, W, H, &d, &geo);
    let (map, report) = run(&p).unwrap();
    assert!(
        (report.source_spacing_m[0] - 3.048).abs() < 1e-9,
        "{report:?}"
    );
    let south_ft = 5000.0 - 10.0 * f64::from(H - 1);
    assert!((report.origin_m[0] - 304.8).abs() < 1e-9, "{report:?}");
    assert!(
        (report.origin_m[1] - south_ft * 0.3048).abs() < 1e-9,
        "{report:?}"
    );
    // Resampled from 3.048 m to the 2 m lattice over the same extent: the corners are the
    // corner samples, and every sample lies within the range of the source cell it falls in
    // (in metres), which the limited bicubic guarantees.
    let (mw, mh) = (map.heights.width() - 1, map.heights.height() - 1);
    for (c, r, x, y) in [(0, 0, 0, mh), (W - 1, H - 1, mw, 0), (0, H - 1, 0, 0)] {
        let got = f64::from(map.heights.get(x, y));
        assert!(
            (got - height(c, r) * 0.3048).abs() < 1e-3,
            "({c}, {r}): {got}"
        );
    }
    let (fx, fy) = (f64::from(W - 1) / mw as f64, f64::from(H - 1) / mh as f64);
    for y in 0..=mh {
        for x in 0..=mw {
            // The source cell: columns from the west, rows from the south (as the map's).
            let (c0, s0) = (
                (x as f64 * fx).floor() as u32,
                (y as f64 * fy).floor() as u32,
            );
            let cell: Vec<f64> = [(0, 0), (1, 0), (0, 1), (1, 1)]
                .iter()
                .map(|&(dc, ds)| {
                    let south = (s0 + ds).min(H - 1);
                    height((c0 + dc).min(W - 1), H - 1 - south) * 0.3048
                })
                .collect();
            let (lo, hi) = cell
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                    (l.min(v), h.max(v))
                });
            let got = f64::from(map.heights.get(x, y));
            assert!(
                (lo - 1e-3..=hi + 1e-3).contains(&got),
                "map sample ({x}, {y}): {got} outside its source cell's {lo}..{hi}"
            );
        }
    }
    // A transform whose rows go north (positive y step): row 0 of the file is the south edge.
    let mut m = [0.0; 16];
    (m[0], m[3], m[5], m[7], m[15]) = (2.0, 100.0, 2.0, 200.0, 1.0);
    let south_up = Geo {
        transform: Some(m),
        keys: vec![(1024, 1)],
        ..Geo::default()
    };
    let d: Vec<i16> = raster().iter().map(|&x| x as i16).collect();
    write_strips::<colortype::GrayI16>(&p, Compression::Uncompressed, W, H, &d, &south_up);
    let (map, report) = run(&p).unwrap();
    assert_eq!(report.origin_m, [101.0, 201.0]);
    for (c, r) in [(0, 0), (5, 20), (W - 1, H - 1)] {
        assert_eq!(
            f64::from(map.heights.get(c as usize, r as usize)),
            height(c, r),
            "south-up ({c}, {r})"
        );
    }
}

/// The error of importing `path`, as text; it must name the file.
fn refusal(path: &Path) -> String {
    let err = run(path).expect_err("must be refused").to_string();
    assert!(
        err.contains(&*path.file_name().unwrap().to_string_lossy()),
        "error does not name the file: {err}"
    );
    err
}

#[test]
fn unsupported_rasters_are_refused_naming_the_tag() {
    let tmp = tempfile::tempdir().unwrap();
    let p: PathBuf = tmp.path().join("refused.tif");
    let d16: Vec<i16> = raster().iter().map(|&x| x as i16).collect();
    let strips = |geo: &Geo| {
        write_strips::<colortype::GrayI16>(&p, Compression::Uncompressed, W, H, &d16, geo);
    };
    // Rotation.
    let mut m = [0.0; 16];
    (m[0], m[1], m[3], m[4], m[5], m[15]) = (2.0, 0.3, 100.0, 0.3, -2.0, 1.0);
    strips(&Geo {
        transform: Some(m),
        ..Geo::default()
    });
    let e = refusal(&p);
    assert!(
        e.contains("ModelTransformationTag (34264)") && e.contains("rotated"),
        "{e}"
    );
    // Control points only.
    strips(&Geo {
        tie: Some(vec![
            0.0, 0.0, 0.0, 1.0, 2.0, 0.0, 39.0, 29.0, 0.0, 80.0, 60.0, 0.0,
        ]),
        ..Geo::default()
    });
    let e = refusal(&p);
    assert!(e.contains("ModelTiepointTag (33922)"), "{e}");
    // Geocentric model, unknown linear unit, unknown vertical unit.
    for (keys, tag) in [
        (vec![(1024, 3)], "GTModelTypeGeoKey (1024)"),
        (
            vec![(1024, 1), (3076, 9005)],
            "ProjLinearUnitsGeoKey (3076)",
        ),
        (vec![(1024, 1), (4099, 9999)], "VerticalUnitsGeoKey (4099)"),
        (
            vec![(1024, 2), (2054, 9105)],
            "GeogAngularUnitsGeoKey (2054)",
        ),
    ] {
        strips(&Geo { keys, ..utm() });
        let e = refusal(&p);
        assert!(e.contains(tag), "{tag}: {e}");
    }
    // No georeferencing: needs --spacing-m, and then imports.
    strips(&Geo::default());
    let e = refusal(&p);
    assert!(
        e.contains("--spacing-m") && e.contains("ModelPixelScaleTag"),
        "{e}"
    );
    let mut with_spacing = ImportParams::new(p.clone());
    with_spacing.spacing_m = Some(5.0);
    let (map, _) = import(&with_spacing, &mut Vec::new()).unwrap();
    // 195 x 145 m of source, resampled to the 4 m lattice: 50 x 37 samples.
    assert_eq!(map.manifest.size_m, [196.0, 144.0]);
    // A nodata tag that is not a number.
    strips(&Geo {
        nodata: Some("none".into()),
        ..utm()
    });
    let e = refusal(&p);
    assert!(e.contains("GDAL_NODATA (42113)"), "{e}");
    // Several bands.
    let rgb: Vec<u8> = raster().iter().flat_map(|&x| [x as u8; 3]).collect();
    write_strips::<colortype::RGB8>(&p, Compression::Uncompressed, W, H, &rgb, &utm());
    let e = refusal(&p);
    assert!(
        e.contains("SamplesPerPixel (277)") && e.contains("is 3"),
        "{e}"
    );
    // 64-bit integers.
    let d64: Vec<u64> = raster().iter().map(|&x| x as u64).collect();
    write_strips::<colortype::Gray64>(&p, Compression::Uncompressed, W, H, &d64, &utm());
    let e = refusal(&p);
    assert!(e.contains("BitsPerSample (258)"), "{e}");
    // Compressions this reader does not take: JPEG and Zstandard claimed by the file.
    for (code, name) in [(7u16, "JPEG"), (50000, "Zstandard")] {
        write_tiles(
            &p,
            code,
            16,
            2,
            &|c, r| (height(c, r) as i16).to_ne_bytes().to_vec(),
            &utm(),
        );
        let e = refusal(&p);
        assert!(e.contains("Compression (259)") && e.contains(name), "{e}");
    }
    // Broken files: truncated, garbage. Errors, never panics.
    write_tiles(
        &p,
        8,
        16,
        2,
        &|c, r| (height(c, r) as i16).to_ne_bytes().to_vec(),
        &utm(),
    );
    let whole = std::fs::read(&p).unwrap();
    for cut in [8, 100, whole.len() / 2, whole.len() - 10] {
        std::fs::write(&p, &whole[..cut]).unwrap();
        refusal(&p);
    }
    std::fs::write(&p, b"II*\0garbage garbage").unwrap();
    refusal(&p);
}

/// The real SRTM tile re-encoded as a GeoTIFF (geographic, 16-bit, SRTM's void value as GDAL
/// nodata, tiled Deflate) imports to the same samples as the `.hgt` reader, with the WGS84
/// spacing within 0.5% of the `.hgt` reader's spherical one.
#[test]
fn srtm_tile_as_geotiff_matches_the_hgt_import() {
    let hgt = tests::test_data("dem/N57E011.hgt");
    let bytes = std::fs::read(&hgt).unwrap();
    let n = 1201u32;
    let samples: Vec<i16> = bytes
        .chunks_exact(2)
        .map(|b| i16::from_be_bytes([b[0], b[1]]))
        .collect();
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("N57E011.tif");
    let step = 3.0 / 3600.0;
    let geo = Geo {
        scale: Some([step, step, 0.0]),
        // Pixel is point: sample (0, 0) is the tile's north-west corner, 58 N 11 E.
        tie: Some(vec![0.0, 0.0, 0.0, 11.0, 58.0, 0.0]),
        keys: vec![(1024, 2), (1025, 2)],
        nodata: Some("-32768".into()),
        ..Geo::default()
    };
    write_strips::<colortype::GrayI16>(
        &p,
        Compression::Deflate(DeflateLevel::Fast),
        n,
        n,
        &samples,
        &geo,
    );
    let (from_tif, tif) = run(&p).unwrap();
    let (from_hgt, hgt_report) = run(&hgt).unwrap();
    assert_eq!(tif.source_samples, hgt_report.source_samples);
    for k in 0..2 {
        let rel = tif.source_spacing_m[k] / hgt_report.source_spacing_m[k] - 1.0;
        assert!(rel.abs() < 0.005, "axis {k}: {tif:?} vs {hgt_report:?}");
    }
    let (a, b) = (
        from_tif
            .heights
            .grid()
            .expect("heights in memory")
            .min_max(),
        from_hgt
            .heights
            .grid()
            .expect("heights in memory")
            .min_max(),
    );
    assert!(
        (a.0 - b.0).abs() < 1.0 && (a.1 - b.1).abs() < 1.0,
        "{a:?} vs {b:?}"
    );
}
