//! Section `tiles`: 16 m tile generation, per tile and throughput.

use crate::report::{Report, bar, throughput};
use engine::surface::World;
use engine::terrain::tiles::{Tile, TileKey};
use std::time::Instant;

fn random_tile(world: &World, i: usize) -> TileKey {
    let s = world.size_m();
    let u = worldgen::noise::unit3(0xB1, i as i64, 0);
    let v = worldgen::noise::unit3(0xB1, i as i64, 1);
    TileKey {
        tx: (u * s[0] / 16.0) as i32,
        ty: (v * s[1] / 16.0) as i32,
    }
}

pub(crate) fn section_tiles(world: &World, r: &mut Report, quick: bool, workers: usize) {
    let n = if quick { 30 } else { 300 };
    let b = bar(n as u64, "tiles");
    let mut times = Vec::with_capacity(n);
    for i in 0..n {
        let t0 = Instant::now();
        std::hint::black_box(Tile::generate(world, random_tile(world, i)));
        times.push(t0.elapsed().as_secs_f64());
        b.inc(1);
    }
    b.finish_and_clear();
    let params = format!(
        "{n} tiles, {} samples each",
        engine::terrain::tiles::TILE_SAMPLES.pow(2)
    );
    r.timings("tiles", "16 m tile generation", times, &params);
    let per = if quick { 10 } else { 100 };
    for w in [1, workers] {
        let tps = throughput(w, per, &|i| {
            std::hint::black_box(Tile::generate(world, random_tile(world, 10_000 + i)));
        });
        r.add(
            "tiles",
            &format!("throughput, {w} worker(s)"),
            tps,
            "tiles/s",
            "",
        );
    }
}
