//! Maps for the unit tests.

/// The repository's tiny map (`maps/tiny`, committed), loaded.
pub(crate) fn tiny_map() -> worldgen::Map {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../maps/tiny");
    worldgen::Map::load(&dir).expect("the tiny map loads")
}
