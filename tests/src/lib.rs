//! End-to-end test crate: worldgen -> map folder -> engine. Shared helpers for the tests in
//! `tests/tests/`.

use std::path::{Path, PathBuf};

/// The workspace root (the folder holding `Cargo.toml`, `maps/`, `shaders/`).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

/// `../shared` beside the workspace: real meshes and elevation data.
pub fn shared_dir() -> PathBuf {
    workspace_root().join("..").join("shared")
}

/// True when running under CI (`CI` set to anything but empty/"false"/"0").
pub fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| !v.is_empty() && v != "false" && v != "0")
}

/// Path of a file in `../shared/data`, or None (with a printed reason) when the folder is
/// absent outside CI. In CI the shared folder is always present, so its absence fails the test.
pub fn shared_data(rel: &str) -> Option<PathBuf> {
    let p = shared_dir().join("data").join(rel);
    if p.exists() {
        return Some(p);
    }
    assert!(
        !in_ci(),
        "{} is missing, but CI always has ../shared",
        p.display()
    );
    println!(
        "skipping: {} not found (../shared is absent outside CI)",
        p.display()
    );
    None
}

/// The committed tiny test map.
pub fn tiny_map_dir() -> PathBuf {
    workspace_root().join("maps").join("tiny")
}

/// Parameters that produced the committed tiny map (see maps/README.md).
pub fn tiny_map_params() -> worldgen::generate::GenerateParams {
    worldgen::generate::GenerateParams {
        name: "tiny".into(),
        seed: 7,
        size_m: 512.0,
        spacing_m: 4.0,
        threads: 0,
    }
}

/// Copies every file of folder `from` into a new folder `to`.
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("create copy folder");
    for e in std::fs::read_dir(from).expect("read map folder") {
        let e = e.expect("dir entry");
        std::fs::copy(e.path(), to.join(e.file_name())).expect("copy file");
    }
}

/// FNV-1a over the names and bytes of every file in a folder, in name order.
pub fn hash_dir(dir: &Path) -> u64 {
    let mut names: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("read dir")
        .map(|e| e.expect("entry").path())
        .collect();
    names.sort();
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut feed = |bytes: &[u8]| {
        for &b in bytes {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    };
    for n in names {
        feed(
            n.file_name()
                .map(std::ffi::OsStr::as_encoded_bytes)
                .unwrap_or_default(),
        );
        feed(&std::fs::read(&n).expect("read file"));
    }
    h
}
