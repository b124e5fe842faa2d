//! The part of the map's ground layer the terrain shader reads for the materials' detail below
//! the finest node texel: a window of cells around the camera, moved when the camera nears its
//! edge, so the GPU holds a fixed few hundred KiB whatever the map's size.
//!
//! The detail shows only where a pixel is smaller than the finest node texel (a few
//! centimetres), that is within a few hundred metres of the camera; the window reaches at least
//! [`REACH_M`] from the camera in every direction (or the whole map), and the shader shows no
//! detail outside it.

use worldgen::map::GroundTypes;

/// The window's side (m) where the map is larger: twice [`REACH_M`] beyond the quarter of a
/// side the camera may move before the window follows.
pub const SIDE_M: f64 = 2048.0;
/// The least distance (m) from the camera to the window's edge, away from the map's edges.
pub const REACH_M: f64 = SIDE_M / 4.0;
/// Bounds of the window's side in cells (at most 4 MiB on the GPU).
const SIDE_CELLS: (usize, usize) = (256, 4096);

/// A window of ground cells: `side` cells from cell `first` (east, north).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TypeWindow {
    pub first: [usize; 2],
    pub side: [usize; 2],
    /// The map's cells per side.
    map: [usize; 2],
}

impl TypeWindow {
    /// The window over a ground layer of `map` cells `spacing_m` apart for a camera at
    /// `camera_cells` (ground-cell coordinates): centred on the camera, inside the map.
    pub fn around(map: [usize; 2], spacing_m: f64, camera_cells: [f64; 2]) -> Self {
        let want = ((SIDE_M / spacing_m).ceil() as usize).clamp(SIDE_CELLS.0, SIDE_CELLS.1);
        let side = map.map(|n| n.min(want));
        Self {
            first: Self::first_for(map, side, camera_cells),
            side,
            map,
        }
    }

    fn first_for(map: [usize; 2], side: [usize; 2], camera_cells: [f64; 2]) -> [usize; 2] {
        [0, 1].map(|a| {
            let start = camera_cells[a] - side[a] as f64 / 2.0;
            (start.max(0.0).round() as usize).min(map[a] - side[a])
        })
    }

    /// The window for a camera at `camera_cells`: along each axis, this one's place while the
    /// camera is more than a quarter side from its edges, otherwise centred on the camera (as
    /// far as the map allows).
    pub fn follow(&self, camera_cells: [f64; 2]) -> Self {
        let centred = Self::first_for(self.map, self.side, camera_cells);
        let first = [0, 1].map(|a| {
            let margin = self.side[a] as f64 / 4.0;
            let lo = self.first[a] as f64 + margin;
            let hi = (self.first[a] + self.side[a]) as f64 - margin;
            if (lo..=hi).contains(&camera_cells[a]) {
                self.first[a]
            } else {
                centred[a]
            }
        });
        Self { first, ..*self }
    }

    /// The map's cells per side.
    pub fn map_cells(&self) -> [usize; 2] {
        self.map
    }

    /// The window's cells of `ground`, rows south to north.
    pub fn cells(&self, ground: &GroundTypes) -> Vec<u8> {
        let [x0, y0] = self.first;
        let [w, h] = self.side;
        ground.region(x0, y0, w, h).data().to_vec()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The window keeps at least `REACH_M` around the camera wherever the camera goes, moves
    /// only when the camera nears its edge, and stays inside the map.
    #[test]
    fn the_window_reaches_around_the_camera_and_follows_it() {
        let map = [8193, 4097];
        let spacing_m = 4.0;
        let reach = REACH_M / spacing_m;
        let mut w = TypeWindow::around(map, spacing_m, [100.0, 4000.0]);
        assert_eq!(w.side, [512, 512]);
        let mut moves = 0;
        for k in 0..4000 {
            let camera = [2.0 * k as f64, 2048.0 + 2000.0 * (k as f64 / 300.0).sin()];
            let next = w.follow(camera);
            moves += usize::from(next != w);
            w = next;
            for a in 0..2 {
                assert!(w.first[a] + w.side[a] <= map[a]);
                let lo = w.first[a] as f64;
                let hi = (w.first[a] + w.side[a]) as f64;
                let reaches = (camera[a] - lo >= reach || w.first[a] == 0)
                    && (hi - camera[a] >= reach || w.first[a] + w.side[a] == map[a]);
                assert!(reaches, "camera {camera:?}, window {w:?}");
            }
        }
        assert!((20..400).contains(&moves), "{moves} moves in 4000 steps");
    }

    /// A small map is one window, and its cells are the map's.
    #[test]
    fn a_small_map_is_one_window() {
        let mut g = worldgen::Grid::new(65, 33, 0u8);
        g.set(64, 32, 7);
        g.set(3, 1, 2);
        let w = TypeWindow::around([65, 33], 4.0, [10.0, 10.0]);
        assert_eq!((w.first, w.side), ([0, 0], [65, 33]));
        assert_eq!(w.follow([60.0, 30.0]), w);
        let cells = w.cells(&g.into());
        assert_eq!((cells[65 * 32 + 64], cells[65 + 3]), (7, 2));
    }
}
