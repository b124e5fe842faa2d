//! Camera path files (`tvs-camera-path 1`): a round trip, interpolation, and every malformed
//! input refused with the file, the line and the problem.

use engine::flight::{CameraPath, PathKey};
use glam::DVec3;

fn write(dir: &std::path::Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).expect("write the test file");
    p
}

#[test]
fn saved_paths_load_back_and_interpolate() {
    let tmp = tempfile::tempdir().unwrap();
    let path = CameraPath {
        keys: vec![
            PathKey {
                t_s: 0.0,
                position_m: DVec3::new(10.0, 20.0, 30.0),
                forward: DVec3::X,
            },
            PathKey {
                t_s: 2.0,
                position_m: DVec3::new(30.0, 20.0, 50.0),
                forward: DVec3::Y,
            },
        ],
    };
    let p = tmp.path().join("path.txt");
    path.save(&p).expect("save");
    let back = CameraPath::load(&p).expect("load");
    assert_eq!(back.keys.len(), 2);
    assert!((back.keys[1].position_m - DVec3::new(30.0, 20.0, 50.0)).length() < 1e-3);
    assert!((back.duration_s() - 2.0).abs() < 1e-9);
    let mid = back.at(1.0, [64, 36]);
    assert!((mid.position_m - DVec3::new(20.0, 20.0, 40.0)).length() < 1e-3);
    // Clamped at both ends.
    assert!((back.at(-5.0, [64, 36]).position_m - DVec3::new(10.0, 20.0, 30.0)).length() < 1e-3);
    assert!((back.at(9.0, [64, 36]).position_m - DVec3::new(30.0, 20.0, 50.0)).length() < 1e-3);
}

#[test]
fn malformed_paths_are_refused_by_line() {
    let tmp = tempfile::tempdir().unwrap();
    let head = "tvs-camera-path 1\n";
    let cases: [(&str, String, &[&str]); 7] = [
        (
            "magic.txt",
            "camera path\n0 0 0 0 1 0 0\n".into(),
            &["line 1", "tvs-camera-path 1"],
        ),
        (
            "word.txt",
            format!("{head}0 0 0 zero 1 0 0\n"),
            &["line 2", "not a number"],
        ),
        (
            "short.txt",
            format!("{head}0 0 0 0 1 0\n"),
            &["line 2", "7 finite numbers"],
        ),
        (
            "nan.txt",
            format!("{head}0 0 0 NaN 1 0 0\n"),
            &["line 2", "7 finite numbers"],
        ),
        (
            "still.txt",
            format!("{head}0 0 0 0 0 0 0\n"),
            &["line 2", "forward direction is zero"],
        ),
        (
            "time.txt",
            format!("{head}1 0 0 0 1 0 0\n# a comment\n1 5 0 0 1 0 0\n"),
            &["line 4", "does not increase"],
        ),
        ("empty.txt", format!("{head}# nothing\n"), &["no keys"]),
    ];
    for (name, text, want) in cases {
        let p = write(tmp.path(), name, &text);
        let err = CameraPath::load(&p).unwrap_err().to_string();
        assert!(
            err.contains(name),
            "{name}: the error does not name the file: {err}"
        );
        for w in want {
            assert!(err.contains(w), "{name}: expected {w:?} in {err:?}");
        }
    }
    let missing = tmp.path().join("missing.txt");
    let err = CameraPath::load(&missing).unwrap_err().to_string();
    assert!(err.contains("missing.txt"), "{err}");
}
