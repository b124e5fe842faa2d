//! A baked map's surface error grids ([`MapErrorPyramid`]) as page files, read page by page
//! through the world's page cache instead of whole at the open (341 MiB on a 32 km map).
//!
//! `worldgen bake` writes each grid `k` as `pages/derived/surface_error.<k>.pages`: one row of
//! samples per row of blocks, each block's `[z_min, z_max, error, finer error]` as four f32
//! samples, keyed by the surface's key ([`super::map_error_cache::surface_key`]); and
//! `pages/derived/surface_error.levels`, the grids' shape: a [`worldgen::pages::checked_file`] of
//! magic `TVS-SELV` whose payload is (little-endian) the origin (2 f64), grid 0's vertex spacing
//! f64, the grid count u32 and per grid its blocks per row and rows (2 u32).
//!
//! A block whose page cannot be read is not served ([`MapErrorPyramid::block_at`] gives `None`),
//! so the nodes over it measure their bounds on the surface at run time, as on a map without
//! grids: true bounds, only slower; the fault is recorded once with its file and page.

use super::levels::{self, PageFaults};
use super::map_error::{Level, MapErrorPyramid};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use worldgen::pages::{PageCache, PageError, checked_file};

/// What happens without a page of the grids (for the fault's log line).
pub(super) const FAULT: &str = "the nodes over it measure their bounds on the surface instead";

const MAGIC: &[u8; 8] = b"TVS-SELV";
const VERSION: u32 = 1;
const NAME: &str = "surface_error";

/// The file of the grids' shape in a map's `pages` folder.
pub fn levels_path(pages_dir: &Path) -> PathBuf {
    pages_dir.join("derived").join(format!("{NAME}.levels"))
}

impl MapErrorPyramid {
    /// Writes the grids (all in memory) as page files of `page_side` under `pages_dir/derived`,
    /// keyed by `key`, and their shape file last.
    pub fn write_pages(&self, pages_dir: &Path, page_side: u32, key: u64) -> Result<(), PageError> {
        let mut meta = Vec::new();
        for v in [self.origin_m[0], self.origin_m[1], self.spacing_m] {
            meta.extend_from_slice(&v.to_le_bytes());
        }
        meta.extend_from_slice(&(self.levels.len() as u32).to_le_bytes());
        for (k, l) in self.levels.iter().enumerate() {
            let path = levels::level_path(pages_dir, NAME, k);
            if l.paged.is_some() {
                return Err(PageError::Request {
                    path,
                    problem: "a paged grid cannot be baked again; open the map without its pages"
                        .into(),
                });
            }
            meta.extend_from_slice(&(l.per_row as u32).to_le_bytes());
            meta.extend_from_slice(&(l.rows as u32).to_le_bytes());
            if l.blocks.is_empty() {
                continue;
            }
            let samples: Vec<f32> = l.blocks.iter().flatten().copied().collect();
            let grid =
                worldgen::Grid::from_vec(4 * l.per_row, l.rows, samples).ok_or_else(|| {
                    PageError::Request {
                        path: path.clone(),
                        problem: "a grid's blocks do not fill its rows".into(),
                    }
                })?;
            worldgen::pages::bake::write_grid(&path, &grid, page_side, key)?;
        }
        checked_file::write(&levels_path(pages_dir), MAGIC, VERSION, key, &meta)
    }

    /// Opens the grids baked under `pages_dir` for `key`: their shape file read whole, grids
    /// of one page read into memory, the others registered with `cache` (faults recorded in
    /// `faults`). Refused, naming the file, when a file is missing, damaged, or of another
    /// surface.
    pub fn open_pages(
        pages_dir: &Path,
        key: u64,
        cache: &Arc<PageCache>,
        faults: &Arc<PageFaults>,
    ) -> Result<Self, PageError> {
        let shape = levels_path(pages_dir);
        let data = checked_file::read(&shape, MAGIC, VERSION, key, "surface error grids' shape")?;
        let bad = |problem: &str| PageError::Header {
            path: shape.clone(),
            problem: problem.into(),
        };
        let mut at = 0;
        let mut take = |n: usize| {
            let s = data.get(at..at + n);
            at += n;
            s.ok_or_else(|| bad("cut short; bake the map again"))
        };
        let u32_of = |s: &[u8]| u32::from_le_bytes(s.try_into().expect("4 bytes"));
        let f64_of = |s: &[u8]| f64::from_le_bytes(s.try_into().expect("8 bytes"));
        let origin_m = [f64_of(take(8)?), f64_of(take(8)?)];
        let spacing_m = f64_of(take(8)?);
        let count = u32_of(take(4)?) as usize;
        if count > 64 {
            return Err(bad("holds too many grids"));
        }
        let mut levels_out = Vec::with_capacity(count);
        for k in 0..count {
            let (per_row, rows) = (u32_of(take(4)?) as usize, u32_of(take(4)?) as usize);
            let paged = if per_row * rows == 0 {
                None
            } else {
                let path = levels::level_path(pages_dir, NAME, k);
                Some(levels::open_level(
                    &path,
                    (4 * per_row, rows),
                    key,
                    cache,
                    faults,
                )?)
            };
            levels_out.push(Level {
                per_row,
                rows,
                blocks: Vec::new(),
                paged,
            });
        }
        Ok(Self {
            origin_m,
            spacing_m,
            levels: levels_out,
        })
    }
}
