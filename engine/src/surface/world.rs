//! Map access in f64 world coordinates and the finest terrain surface.
//!
//! `height_m(x, y) = G(x, y) + A(x, y) * D(x, y) + E(x, y)` where `G` is the map's C1 bicubic
//! height, `A` the detail amplitude of the ground types (bilinear between ground samples, so it
//! is continuous; zero on and next to roads and paths), `D` three octaves of gradient noise with
//! wavelengths 8, 4 and 2 m (|D| <= 1) and `E` the decal shaping (flattened roads, raised rock
//! patches; see [`super::decals`]).
//! Detail is evaluated in map-local coordinates, so the same map placed at another origin gives
//! the same surface.

use super::amplitude::{self, Amplitude, NearRoads};
use super::levels::PageFaults;
use super::max_pyramid::MaxPyramid;
use super::pyramids::Pyramids;
use super::stride_levels::{self, HeightLevels, StrideLevels};
use crate::surface::decals::{DecalBounds, DecalField};
use std::borrow::Cow;
use std::path::Path;
use std::sync::Arc;
use worldgen::map::Heights;
use worldgen::noise;
use worldgen::pages::{PageCache, PageError};
use worldgen::{Grid, Map};

/// Detail-noise octaves: (wavelength m, weight). The weights sum to 1, so |D| <= 1.
pub const DETAIL_OCTAVES: [(f64, f64); 3] = [(8.0, 4.0 / 7.0), (4.0, 2.0 / 7.0), (2.0, 1.0 / 7.0)];

/// Upper bound of |grad| of `worldgen::noise::gradient` per lattice unit. Measured: 2.909 over
/// 4 million random points; 3.5 keeps a 20% margin. `gradient_noise_bound_holds` re-measures it.
pub const GRADIENT_NOISE_LIPSCHITZ: f64 = 3.5;

/// Upper bound of the Frobenius norm of the Hessian of `worldgen::noise::gradient` per lattice
/// unit squared. Measured: 14.34 over 3 million random points; 18 keeps a 25% margin.
/// `gradient_noise_hessian_bound_holds` re-measures it.
pub const GRADIENT_NOISE_HESSIAN: f64 = 18.0;

/// A map opened for the runtime.
#[derive(Debug, Clone)]
pub struct World {
    pub map: Map,
    /// The legend's detail amplitude (m) per ground type, and the ground samples near roads
    /// whose amplitude is scaled down ([`super::amplitude`]).
    legend_amplitude_m: Vec<f32>,
    near_roads: NearRoads,
    detail_seed: u64,
    /// The per-cell max-pyramids of the region bounds (computed, or paged from a bake).
    pyramids: Pyramids,
    /// The page cache of a baked map's paged pyramid levels and surface error grids, and the
    /// page faults met.
    pub page_cache: Option<Arc<PageCache>>,
    /// A baked map's `pages` folder.
    pub pages_dir: Option<std::path::PathBuf>,
    pub page_faults: Arc<PageFaults>,
    /// Decal shaping E.
    pub decals: DecalField,
    /// Keys of what is derived from the map (what a bake is checked against).
    keys: DerivedKeys,
    /// Interpolation error of F per block of the grids of spacing `hs 2^k` (computed at load).
    pub map_error: super::map_error::MapErrorPyramid,
    /// Max-pyramid of the map's height samples.
    pub heights_max: super::height_max::HeightMax,
    /// Paged heights' coarse levels (a baked map's), for coarse lattices; empty otherwise.
    height_levels: HeightLevels,
    /// The ground types at every `2^k`-th sample, for the coarsest nodes' texture texels and
    /// the map's mean ground albedo: a baked map's paged, computed otherwise.
    pub ground_levels: StrideLevels<u8>,
    /// The parts of a baked map's derived data that its open did not read from the bake (their
    /// files missing, damaged, or baked for another map or engine; each logged): computed
    /// instead, or, for the coarse height levels, done without.
    pub computed_at_open: Vec<&'static str>,
    /// A folder where data derived from this map may be kept between runs (the light grids'
    /// sky pages, [`crate::lighting::sky_pages`]); `None` (the default) keeps none.
    pub derived_dir: Option<std::path::PathBuf>,
}

/// Keys of the data derived from a map, each a [`worldgen::pages::SourceKey`] of its inputs
/// and of the code that derives it.
#[derive(Debug, Clone, Copy, Default)]
struct DerivedKeys {
    /// The heights' own key ([`Heights::key`]), also that of their coarse levels.
    heights: u64,
    decals: u64,
    amplitude: u64,
    pyramids: u64,
}

/// How far the finest surface can stray from its linear interpolation over a small region,
/// split into the map part G and the detail part H (see `bounds`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegionBounds {
    /// Bound of |grad G|.
    pub slope_g: f64,
    /// Bound of |grad H|.
    pub slope_h: f64,
    /// Bound of the Hessian norm of G (None where the region leaves the map).
    pub curvature_g: Option<f64>,
    /// Bound of the Hessian norm of H (None where the region crosses a ground-cell border).
    pub curvature_h: Option<f64>,
    /// Largest detail amplitude, so |H| <= this.
    pub amplitude_max_m: f64,
    /// Bounds of the decal shaping E (C1 everywhere, so both always hold).
    pub decal: DecalBounds,
}

impl RegionBounds {
    /// A bound of `|Lin F(p) - F(p)|` inside a right triangle with legs `c` whose vertices lie in
    /// the region, where `F = G + H + E` and the parts' bounds add. Each part takes the smallest
    /// of its valid bounds: first order `slope c / sqrt(2)`, second order `curvature c^2 / 4`
    /// (see `terrain::bounds`), and for the detail and the decal shaping also zero order
    /// `2 max |part|` (the interpolant stays within the part's range over the triangle).
    pub fn between_m(&self, c: f64) -> f64 {
        let reach = c * std::f64::consts::FRAC_1_SQRT_2;
        let second = |m2: Option<f64>| m2.map_or(f64::INFINITY, |m| m * c * c * 0.25);
        let g = (self.slope_g * reach).min(second(self.curvature_g));
        let h = (self.slope_h * reach)
            .min(second(self.curvature_h))
            .min(2.0 * self.amplitude_max_m);
        let e = (self.decal.slope * reach)
            .min(second(Some(self.decal.curvature)))
            .min(2.0 * self.decal.magnitude_m);
        g + h + e
    }
}

/// A rectangle in world metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rect {
    pub min: [f64; 2],
    pub max: [f64; 2],
}

impl Rect {
    /// Whether (`x_m`, `y_m`) lies in the half-open rectangle (min included, max excluded), so
    /// a point belongs to one node of a level.
    pub fn contains(&self, x_m: f64, y_m: f64) -> bool {
        x_m >= self.min[0] && x_m < self.max[0] && y_m >= self.min[1] && y_m < self.max[1]
    }
}

impl World {
    /// Heap bytes of what the world keeps, by part (approximate for hash maps: entries times
    /// their size, without the tables' spare capacity).
    pub fn memory_bytes(&self) -> Vec<(&'static str, usize)> {
        let grid = |w: usize, h: usize, b: usize| w * h * b;
        let m = &self.map;
        let heights = m
            .heights
            .grid()
            .map_or(0, |g| grid(g.width(), g.height(), 4));
        let layers = heights
            + m.ground.held_bytes()
            + self.ground_levels.held_bytes()
            + m.densities
                .iter()
                .map(|d| grid(d.density.width(), d.density.height(), 1))
                .sum::<usize>();
        let pyramids = self.pyramids.bytes() + self.heights_max.bytes();
        let resident_pages = self
            .page_cache
            .as_ref()
            .map_or(0, |c| c.stats().resident_bytes);
        vec![
            (
                "map layers held whole (densities, and the heights and ground types with their levels unless paged)",
                layers,
            ),
            (
                "ground amplitude near roads (elsewhere the ground types')",
                self.near_roads.bytes(),
            ),
            (
                "slope, curvature, amplitude and height max-pyramids",
                pyramids,
            ),
            (
                "height, ground type, max-pyramid and surface error grid pages resident",
                resident_pages,
            ),
            (
                "decal field (a baked map's: index and resident tiles)",
                self.decals.heap_bytes(),
            ),
            ("surface error grids", self.map_error.bytes()),
        ]
    }

    /// Opens `map`, computing the map-error grids ([`super::map_error`]) on all cores (seconds
    /// on an 8 km map; [`World::with_error_cache`] keeps them in a file). The stream opens maps
    /// with [`crate::terrain::precomputed::open`], which adds the 32 m nodes' grid.
    pub fn new(map: Map) -> Self {
        let mut world = Self::without_error_grids(map);
        world.compute_error_grids();
        world
    }

    /// Computes the map-error grids of this world's surface.
    pub(crate) fn compute_error_grids(&mut self) {
        let t0 = std::time::Instant::now();
        self.map_error = super::map_error::MapErrorPyramid::new(self);
        log::info!(
            "surface error of {} coarse grids computed in {:.2} s",
            self.map_error.level_count(),
            t0.elapsed().as_secs_f64()
        );
    }

    /// The world with empty map-error grids (every node's bounds measured at run time), for a
    /// caller that fills them ([`crate::terrain::precomputed::compute`]) or needs none.
    pub fn without_error_grids(map: Map) -> Self {
        Self::build(map, None)
    }

    /// The world with empty map-error grids whose derived data is read from the bake of the
    /// map in `pages_dir`: the max-pyramids page by page through a page cache of
    /// `budget_bytes`, the decal field tile by tile under a budget of its own of
    /// `budget_bytes`, the ground amplitude grid whole. Each is computed as without pages (and
    /// the reason logged) where its file is missing or does not match.
    pub fn paged_without_error_grids(map: Map, pages_dir: &Path, budget_bytes: usize) -> Self {
        Self::build(map, Some((pages_dir, budget_bytes)))
    }

    /// A key of the map's content as the surface reads it (heights, ground types, the
    /// legend's amplitudes, decals, placement), from the keys taken at open.
    pub(crate) fn derived_key(&self) -> u64 {
        let mut k = worldgen::pages::SourceKey::new(0x5E77_0000);
        for v in [self.keys.decals, self.keys.amplitude] {
            k.update(&v.to_le_bytes());
        }
        k.finish()
    }

    /// Writes what this world derives from its map under `pages_dir/derived` (`worldgen
    /// bake`): the max-pyramids as page files of `page_side`, the ground amplitude near roads,
    /// the decal field as a tile file.
    pub fn write_derived_pages(&self, pages_dir: &Path, page_side: u32) -> Result<(), PageError> {
        self.pyramids
            .write(&self.heights_max, pages_dir, page_side, self.keys.pyramids)?;
        let heights = whole_heights(&self.map.heights);
        stride_levels::write(
            &heights,
            self.keys.heights,
            stride_levels::HEIGHTS,
            pages_dir,
            page_side,
        )?;
        stride_levels::write(
            &self.map.ground.whole_or_filled("ground types"),
            self.map.ground.key(),
            stride_levels::GROUND_TYPES,
            pages_dir,
            page_side,
        )?;
        self.near_roads
            .write(&amplitude::near_roads_path(pages_dir), self.keys.amplitude)?;
        // An older bake's whole amplitude grid, no longer read.
        let old_grid = pages_dir.join("derived").join("amplitude.pages");
        if let Err(e) = std::fs::remove_file(&old_grid)
            && e.kind() != std::io::ErrorKind::NotFound
        {
            log::warn!("{}: not removed: {e}", old_grid.display());
        }
        self.decals
            .write_tiles(&super::decal_bake::tiles_path(pages_dir), self.keys.decals)
    }

    fn build(map: Map, pages: Option<(&Path, usize)>) -> Self {
        let t0 = std::time::Instant::now();
        let heights_key = map.heights.key();
        let mut keys = DerivedKeys {
            heights: heights_key,
            decals: DecalField::bake_key(&map, heights_key),
            ..DerivedKeys::default()
        };
        // Paged heights bring the page cache and the record of faults they were opened with.
        let paging = map.heights.paged().map(|p| p.paging().clone());
        let page_faults = paging
            .as_ref()
            .map_or_else(Arc::default, |p| Arc::clone(&p.faults));
        let mut computed_at_open = Vec::new();
        let decals = pages
            .and_then(|(dir, budget_bytes)| {
                let path = super::decal_bake::tiles_path(dir);
                let origin = map.manifest.origin_m;
                let faults = Arc::clone(&page_faults);
                let opened =
                    DecalField::open_tiles(&path, keys.decals, origin, budget_bytes, faults);
                from_bake(&mut computed_at_open, "decal field", opened)
            })
            .unwrap_or_else(|| {
                DecalField::new(
                    &map.decals,
                    map.manifest.origin_m,
                    map.manifest.size_m,
                    |x, y| map.height_bicubic_m(x, y),
                )
            });
        let t1 = std::time::Instant::now();
        keys.amplitude = amplitude::key(&map, keys.decals);
        let legend_amplitude_m = amplitude::legend_m(&map);
        // The whole amplitude grid, where it had to be computed (kept for the pyramids).
        let mut whole_amplitude = None;
        let baked_near = pages.and_then(|(dir, _)| {
            let (w, h) = (map.ground.width(), map.ground.height());
            let path = amplitude::near_roads_path(dir);
            from_bake(
                &mut computed_at_open,
                "ground amplitude near roads",
                NearRoads::read(&path, keys.amplitude, w, h),
            )
        });
        let near_roads = baked_near.unwrap_or_else(|| {
            let grid = amplitude::grid(&map, &decals);
            let ground = map.ground.whole_or_filled("ground types");
            let near = NearRoads::new(&grid, &ground, &legend_amplitude_m);
            whole_amplitude = Some(grid);
            near
        });
        let t2 = std::time::Instant::now();
        let detail_seed = u64::from_str_radix(&map.manifest.seed, 16).unwrap_or(0) ^ 0xDE7A_11ED;
        let (hs, gs) = (
            map.manifest.heights.spacing_m,
            map.manifest.ground.spacing_m,
        );
        keys.pyramids = Pyramids::key(heights_key, hs, keys.amplitude, gs);
        let page_cache = pages.map(|(_, budget_bytes)| {
            paging.as_ref().map_or_else(
                || Arc::new(PageCache::new(budget_bytes)),
                |p| Arc::clone(&p.cache),
            )
        });
        let paged = pages
            .zip(page_cache.as_ref())
            .and_then(|((dir, _), cache)| {
                let heights = [map.heights.width(), map.heights.height()];
                let ground = [map.ground.width(), map.ground.height()];
                let opened =
                    Pyramids::open(dir, heights, ground, keys.pyramids, cache, &page_faults);
                from_bake(&mut computed_at_open, "max-pyramids", opened)
            });
        let (pyramids, heights_max) = paged.unwrap_or_else(|| {
            let grid = whole_amplitude
                .take()
                .unwrap_or_else(|| amplitude::grid(&map, &decals));
            Pyramids::compute(&whole_heights(&map.heights), hs, &grid, gs)
        });
        let mut height_levels = HeightLevels::default();
        if let Some(p) = map.heights.paged() {
            // Nothing stands below a patch of terrain whose page cannot be read.
            let n = [p.width() as i64, p.height() as i64];
            let fill = heights_max.max_in([0, n[0] - 1], [0, n[1] - 1]);
            p.set_fill(fill);
            if let Some((dir, _)) = pages {
                let samples = [p.width(), p.height()];
                match HeightLevels::open(
                    dir,
                    stride_levels::HEIGHTS,
                    samples,
                    heights_key,
                    p.paging(),
                ) {
                    Ok(levels) => {
                        levels.set_fill(fill);
                        height_levels = levels;
                    }
                    Err(e) => {
                        log::warn!("{e}: coarse nodes read the heights' own pages instead");
                        computed_at_open.push("coarse height levels");
                    }
                }
            }
        }
        let ground_levels = ground_levels(&map, pages.map(|(dir, _)| dir), &mut computed_at_open);
        log::info!(
            "world opened: decal field {:.2} s, ground amplitude {:.2} s, max-pyramids {:.2} s",
            (t1 - t0).as_secs_f64(),
            (t2 - t1).as_secs_f64(),
            t2.elapsed().as_secs_f64()
        );
        Self {
            map,
            legend_amplitude_m,
            near_roads,
            detail_seed,
            pyramids,
            page_cache,
            pages_dir: pages.map(|(dir, _)| dir.to_path_buf()),
            page_faults,
            decals,
            keys,
            derived_dir: None,
            map_error: super::map_error::MapErrorPyramid::default(),
            heights_max,
            height_levels,
            ground_levels,
            computed_at_open,
        }
    }

    pub fn origin_m(&self) -> [f64; 2] {
        self.map.manifest.origin_m
    }

    pub fn size_m(&self) -> [f64; 2] {
        self.map.manifest.size_m
    }

    /// Detail amplitude (m) at a world position (bilinear, clamped).
    fn amplitude_at(&self, x_m: f64, y_m: f64) -> f64 {
        let at = worldgen::sample::GridPlacement {
            origin_m: self.origin_m(),
            spacing_m: self.map.manifest.ground.spacing_m,
        };
        worldgen::sample::bilinear(&self.amplitude(), at, x_m, y_m)
    }

    /// The ground amplitude raster as the interpolators read it.
    fn amplitude(&self) -> Amplitude<'_> {
        Amplitude {
            ground: &self.map.ground,
            legend_m: &self.legend_amplitude_m,
            near_roads: &self.near_roads,
        }
    }

    /// Detail noise D in [-1, 1] at a map-local position.
    fn detail(&self, lx: f64, ly: f64) -> f64 {
        DETAIL_OCTAVES
            .iter()
            .enumerate()
            .map(|(i, &(wavelength, weight))| {
                weight
                    * noise::gradient(
                        self.detail_seed.wrapping_add(i as u64),
                        lx / wavelength,
                        ly / wavelength,
                    )
            })
            .sum()
    }

    /// The finest surface height (m) at a world position.
    pub fn height_m(&self, x_m: f64, y_m: f64) -> f64 {
        let o = self.origin_m();
        let a = self.amplitude_at(x_m, y_m);
        let d = if a > 0.0 {
            a * self.detail(x_m - o[0], y_m - o[1])
        } else {
            0.0
        };
        let g = self
            .level_samples(&[x_m], &[y_m])
            .map_or_else(|| self.map.height_bicubic_m(x_m, y_m), |v| v[0]);
        g + d + self.decals.offset_m(x_m, y_m)
    }

    /// The heights part `G` on the lattice `xs` x `ys` read from the coarsest baked level of
    /// the paged heights that holds it (every point on a height sample: `G` is the sample,
    /// [`super::stride_levels`]); `None` where the heights are not paged or the lattice is not
    /// on such samples.
    fn level_samples(&self, xs: &[f64], ys: &[f64]) -> Option<Vec<f64>> {
        if self.height_levels.is_empty() {
            return None;
        }
        let (o, hs) = (self.origin_m(), self.map.manifest.heights.spacing_m);
        let (w, h) = (self.map.heights.width(), self.map.heights.height());
        let gx = stride_levels::on_samples(xs, o[0], hs, w)?;
        let gy = stride_levels::on_samples(ys, o[1], hs, h)?;
        self.height_levels.samples(&gx, &gy)
    }

    /// [`Self::height_m`] at every point of the lattice `xs` x `ys` (row-major, one row per
    /// `ys` entry), equal to it point by point and several times cheaper per point on dense
    /// lattices: each part (`G`, the detail amplitude and noise octaves, `E`) does its per-column
    /// and per-row work once ([`worldgen::sample::bicubic_lattice`],
    /// [`worldgen::noise::gradient_lattice`], [`DecalField::offsets_on_lattice`]).
    /// On lattices coarser than the height grid the decal part is evaluated point by point.
    pub fn heights_on_lattice(&self, xs: &[f64], ys: &[f64]) -> Vec<f64> {
        let hs = self.map.manifest.heights.spacing_m;
        let sparse = |v: &[f64]| {
            let (lo, hi) = v
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &t| {
                    (a.min(t), b.max(t))
                });
            hi - lo > hs * v.len() as f64
        };
        let o = self.origin_m();
        let ground = worldgen::sample::GridPlacement {
            origin_m: o,
            spacing_m: self.map.manifest.ground.spacing_m,
        };
        let amplitude = worldgen::sample::bilinear_lattice(&self.amplitude(), ground, xs, ys);
        let at = self.map.height_placement();
        let g = match &self.map.heights {
            Heights::Grid(h) => worldgen::sample::bicubic_lattice(h, at, xs, ys),
            Heights::Paged(h) => self
                .level_samples(xs, ys)
                .unwrap_or_else(|| worldgen::sample::bicubic_lattice(h, at, xs, ys)),
        };
        // The decal part reads a dense patch of its 0.5 m samples under the lattice: on a sparse
        // lattice that patch would be far larger than the lattice, so it is evaluated per point.
        let e = if sparse(xs) || sparse(ys) {
            ys.iter()
                .flat_map(|&y| xs.iter().map(move |&x| self.decals.offset_m(x, y)))
                .collect()
        } else {
            self.decals.offsets_on_lattice(xs, ys)
        };
        let octaves: Vec<(f64, Vec<f64>)> = DETAIL_OCTAVES
            .iter()
            .enumerate()
            .map(|(i, &(wavelength, weight))| {
                let local = |v: &[f64], o: f64| -> Vec<f64> {
                    v.iter().map(|t| (t - o) / wavelength).collect()
                };
                let seed = self.detail_seed.wrapping_add(i as u64);
                let n = noise::gradient_lattice(seed, &local(xs, o[0]), &local(ys, o[1]));
                (weight, n)
            })
            .collect();
        (0..xs.len() * ys.len())
            .map(|k| {
                let a = amplitude[k];
                let d = if a > 0.0 {
                    a * octaves.iter().map(|(w, n)| w * n[k]).sum::<f64>()
                } else {
                    0.0
                };
                g[k] + d + e[k]
            })
            .collect()
    }

    /// Ground type index at a world position (nearest ground sample).
    pub fn ground_type(&self, x_m: f64, y_m: f64) -> u8 {
        self.map.ground_type_at(x_m, y_m)
    }

    /// Proven bounds of the surface's parts over `rect` (see [`RegionBounds`]).
    pub fn region_bounds(&self, rect: Rect) -> RegionBounds {
        let o = self.origin_m();
        let size = self.size_m();
        let hs = self.map.manifest.heights.spacing_m;
        let gs = self.map.manifest.ground.spacing_m;
        let inside = rect.min[0] >= o[0]
            && rect.min[1] >= o[1]
            && rect.max[0] <= o[0] + size[0]
            && rect.max[1] <= o[1] + size[1];
        // One ground cell: the rectangle may touch the cell's border but not cross it.
        let one_cell = |lo: f64, hi: f64, o: f64| {
            let (a, b) = (((lo - o) / gs).floor(), ((hi - o) / gs).ceil());
            b - a <= 1.0
        };
        let in_one_ground_cell =
            one_cell(rect.min[0], rect.max[0], o[0]) && one_cell(rect.min[1], rect.max[1], o[1]);
        RegionBounds {
            slope_g: f64::from(self.cells_max(rect, hs, &self.pyramids.slope_g)),
            slope_h: f64::from(self.cells_max(rect, gs, &self.pyramids.slope_detail)),
            curvature_g: inside.then(|| f64::from(self.cells_max(rect, hs, &self.pyramids.curv_g))),
            curvature_h: (inside && in_one_ground_cell)
                .then(|| f64::from(self.cells_max(rect, gs, &self.pyramids.curv_detail))),
            amplitude_max_m: f64::from(self.cells_max(rect, gs, &self.pyramids.amp_max)),
            decal: self.decals.region_bounds(rect.min, rect.max),
        }
    }

    /// Cell spacing (m) of the height and ground grids.
    pub fn cell_spacings_m(&self) -> (f64, f64) {
        (
            self.map.manifest.heights.spacing_m,
            self.map.manifest.ground.spacing_m,
        )
    }

    /// [`Self::region_bounds`] for a rectangle known to lie inside one height cell, one ground
    /// cell and one decal block, and inside the map: direct lookups.
    pub fn cell_region_bounds(&self, rect: Rect) -> RegionBounds {
        let o = self.origin_m();
        let (hs, gs) = self.cell_spacings_m();
        // The centre picks the cells that contain the rectangle.
        let (cx, cy) = (
            (rect.min[0] + rect.max[0]) * 0.5 - o[0],
            (rect.min[1] + rect.max[1]) * 0.5 - o[1],
        );
        let (hx, hy) = ((cx / hs) as usize, (cy / hs) as usize);
        let (gx, gy) = ((cx / gs) as usize, (cy / gs) as usize);
        let l0 = |p: &MaxPyramid, x: usize, y: usize| {
            f64::from(p.levels[0].get(x.min(p.width() - 1), y.min(p.height() - 1)))
        };
        RegionBounds {
            slope_g: l0(&self.pyramids.slope_g, hx, hy),
            slope_h: l0(&self.pyramids.slope_detail, gx, gy),
            curvature_g: Some(l0(&self.pyramids.curv_g, hx, hy)),
            curvature_h: Some(l0(&self.pyramids.curv_detail, gx, gy)),
            amplitude_max_m: l0(&self.pyramids.amp_max, gx, gy),
            decal: self.decals.region_bounds(rect.min, rect.max),
        }
    }

    /// Max of a per-cell field over the cells a rectangle touches.
    fn cells_max(&self, rect: Rect, spacing: f64, p: &MaxPyramid) -> f32 {
        let o = self.origin_m();
        let to = |v: f64, o: f64, n: usize| {
            ((v - o) / spacing).floor().clamp(0.0, (n - 1) as f64) as usize
        };
        // A point on a cell border touches both cells; widen by a hair so both are counted.
        let e = spacing * 1e-9;
        p.max_in(
            to(rect.min[0] - e, o[0], p.width()),
            to(rect.max[0] + e, o[0], p.width()),
            to(rect.min[1] - e, o[1], p.height()),
            to(rect.max[1] + e, o[1], p.height()),
        )
    }
}

/// Every height sample, for work on the whole map ([`worldgen::map::MapRaster::whole_or_filled`]).
pub(crate) fn whole_heights(h: &Heights) -> Cow<'_, Grid<f32>> {
    h.whole_or_filled("heights")
}

/// The ground types' levels: a paged map's read through its pages from the bake under
/// `pages_dir` (computed from the whole layer where they cannot be, and noted in `computed`),
/// a map in memory's computed.
fn ground_levels(
    map: &Map,
    pages_dir: Option<&Path>,
    computed: &mut Vec<&'static str>,
) -> StrideLevels<u8> {
    let ground = &map.ground;
    let opened = ground.paged().zip(pages_dir).and_then(|(p, dir)| {
        let samples = [p.width(), p.height()];
        let name = stride_levels::GROUND_TYPES;
        let opened = StrideLevels::open(dir, name, samples, p.key(), p.paging());
        from_bake(computed, "ground type levels", opened)
    });
    opened.unwrap_or_else(|| StrideLevels::compute(&ground.whole_or_filled("ground types")))
}

/// What a bake gave: `Some` if it could be used, else `None` with the reason logged and `what`
/// noted in `computed`.
fn from_bake<T>(
    computed: &mut Vec<&'static str>,
    what: &'static str,
    r: Result<T, PageError>,
) -> Option<T> {
    let got = baked(what, r);
    if got.is_none() {
        computed.push(what);
    }
    got
}

/// What a bake gave: `Some` if it could be used, else `None` with the reason logged.
fn baked<T>(what: &str, r: Result<T, PageError>) -> Option<T> {
    r.map_err(|e| log::warn!("{e}: computing the {what} instead"))
        .ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::surface::spline::{catmull_rom_cell_curvature, catmull_rom_cell_slope};

    /// The lattice evaluation equals the point evaluation exactly: on a road (decals active),
    /// across the map's corners (clamped samples, positions outside), with uneven spacing, and
    /// just dense enough to take the lattice path with steps of several noise and decal cells.
    #[test]
    fn heights_on_lattice_equal_height_m_point_by_point() {
        let w = World::without_error_grids(crate::test_maps::tiny_map());
        let (o, size) = (w.origin_m(), w.size_m());
        let road = (0..256 * 256)
            .map(|k| {
                [
                    o[0] + f64::from(k % 256) * 2.0,
                    o[1] + f64::from(k / 256) * 2.0,
                ]
            })
            .find(|p| w.decals.offset_m(p[0], p[1]).abs() > 0.05)
            .expect("the tiny map has roads");
        let even = |from: f64, step: f64, n: u32| -> Vec<f64> {
            (0..n).map(|i| from + f64::from(i) * step).collect()
        };
        let lattices = [
            (
                even(road[0] - 6.0, 0.0625, 193),
                even(road[1] - 6.0, 0.0625, 193),
            ),
            (even(o[0] - 9.0, 0.37, 60), even(o[1] - 5.0, 0.5, 40)),
            (
                even(o[0] + size[0] - 7.0, 0.25, 80),
                even(o[1] + size[1] - 3.0, 1.5, 9),
            ),
            (
                (0..50).map(|i| road[0] + f64::from(i * i) * 0.01).collect(),
                (0..30)
                    .map(|j| road[1] - f64::from(j * 7 % 30) * 0.3)
                    .collect(),
            ),
            // Sparse (decals point by point): a coarse node of a far larger quad tree, and one
            // over the whole map, across its roads.
            (
                even(o[0] - 3.0e5, 4096.5, 129),
                even(o[1] - 1.0e5, 2048.25, 129),
            ),
            (even(o[0] + 3.0, 9.0, 50), even(o[1] + 1.0, 7.5, 60)),
            (
                even(road[0] - 100.0, 3.9, 60),
                even(road[1] - 50.0, 3.3, 30),
            ),
        ];
        let mut on_decals = 0;
        for (xs, ys) in &lattices {
            let got = w.heights_on_lattice(xs, ys);
            for (j, &y) in ys.iter().enumerate() {
                for (i, &x) in xs.iter().enumerate() {
                    assert_eq!(got[j * xs.len() + i], w.height_m(x, y), "at ({x}, {y})");
                    on_decals += usize::from(w.decals.offset_m(x, y) != 0.0);
                }
            }
        }
        assert!(
            on_decals > 1000,
            "only {on_decals} points had a decal offset"
        );
    }

    #[test]
    fn max_pyramid_queries_equal_the_max_over_their_aligned_blocks() {
        let mut g = worldgen::Grid::new(37, 23, 0.0f32);
        for y in 0..23 {
            for x in 0..37 {
                g.set(x, y, (noise::unit3(4, x as i64, y as i64) * 100.0) as f32);
            }
        }
        let p = MaxPyramid::new(g.clone());
        for q in 0..300i64 {
            let xa = (noise::unit3(5, q, 0) * 37.0) as usize;
            let xb = (noise::unit3(5, q, 1) * 37.0) as usize;
            let ya = (noise::unit3(5, q, 2) * 23.0) as usize;
            let yb = (noise::unit3(5, q, 3) * 23.0) as usize;
            let (x0, x1, y0, y1) = (xa.min(xb), xa.max(xb), ya.min(yb), ya.max(yb));
            let mut brute = 0.0f32;
            for y in y0..=y1 {
                for x in x0..=x1 {
                    brute = brute.max(g.get(x, y));
                }
            }
            let got = p.max_in(x0, x1, y0, y1);
            assert!(got >= brute, "pyramid max {got} below true max {brute}");
            // Exactly the max over the aligned level-k blocks that cover the query (the
            // documented "few more cells around"), not merely some upper bound.
            let span = (x1 - x0 + 1).max(y1 - y0 + 1);
            let k = ((usize::BITS - 1 - span.leading_zeros()) as usize).min(p.levels.len() - 1);
            let (bx0, by0) = ((x0 >> k) << k, (y0 >> k) << k);
            let bx1 = ((((x1 >> k) + 1) << k) - 1).min(36);
            let by1 = ((((y1 >> k) + 1) << k) - 1).min(22);
            let mut blocks = 0.0f32;
            for y in by0..=by1 {
                for x in bx0..=bx1 {
                    blocks = blocks.max(g.get(x, y));
                }
            }
            assert_eq!(got, blocks, "query {x0}..={x1} x {y0}..={y1} at level {k}");
        }
    }

    #[test]
    fn gradient_noise_hessian_bound_holds() {
        let g = noise::gradient;
        let h = 1e-4;
        let mut m: f64 = 0.0;
        for i in 0..200_000i64 {
            let x = noise::unit3(21, i, 0) * 64.0 - 32.0;
            let y = noise::unit3(22, i, 0) * 64.0 - 32.0;
            let s = (i % 5) as u64;
            let f = g(s, x, y);
            let fxx = (g(s, x + h, y) - 2.0 * f + g(s, x - h, y)) / (h * h);
            let fyy = (g(s, x, y + h) - 2.0 * f + g(s, x, y - h)) / (h * h);
            let fxy = (g(s, x + h, y + h) - g(s, x + h, y - h) - g(s, x - h, y + h)
                + g(s, x - h, y - h))
                / (4.0 * h * h);
            m = m.max((fxx * fxx + 2.0 * fxy * fxy + fyy * fyy).sqrt());
        }
        assert!(m < GRADIENT_NOISE_HESSIAN, "measured {m} exceeds the bound");
        assert!(m > 8.0, "suspiciously smooth noise: {m}");
    }

    #[test]
    fn gradient_noise_bound_holds() {
        let h = 1e-5;
        let mut max_g: f64 = 0.0;
        for i in 0..200_000i64 {
            let x = noise::unit3(11, i, 0) * 64.0 - 32.0;
            let y = noise::unit3(12, i, 0) * 64.0 - 32.0;
            let s = (i % 5) as u64;
            let gx = (noise::gradient(s, x + h, y) - noise::gradient(s, x - h, y)) / (2.0 * h);
            let gy = (noise::gradient(s, x, y + h) - noise::gradient(s, x, y - h)) / (2.0 * h);
            max_g = max_g.max(gx.hypot(gy));
        }
        assert!(
            max_g < GRADIENT_NOISE_LIPSCHITZ,
            "measured {max_g} exceeds the bound"
        );
        assert!(max_g > 2.0, "suspiciously smooth noise: {max_g}");
    }

    #[test]
    fn catmull_rom_cell_bounds_hold_on_random_grids() {
        // Random grids: finite-difference slope and curvature inside a cell never exceed the
        // cell's bounds.
        for seed in 0..20u64 {
            let mut g = worldgen::Grid::new(6, 6, 0.0f32);
            for y in 0..6 {
                for x in 0..6 {
                    g.set(x, y, (noise::unit3(seed, x as i64, y as i64) * 10.0) as f32);
                }
            }
            let at = worldgen::sample::GridPlacement {
                origin_m: [0.0, 0.0],
                spacing_m: 1.0,
            };
            let f = |x: f64, y: f64| worldgen::sample::bicubic(&g, at, x, y);
            for i in 0..400 {
                let x = 1.0 + 3.0 * noise::unit3(seed, i, 1);
                let y = 1.0 + 3.0 * noise::unit3(seed, i, 2);
                let (cx, cy) = (x.floor() as i64, y.floor() as i64);
                let p = |a: i64, b: i64| f64::from(g.get_clamped(cx + a, cy + b));
                let e = 1e-6;
                let gx = (f(x + e, y) - f(x - e, y)) / (2.0 * e);
                let gy = (f(x, y + e) - f(x, y - e)) / (2.0 * e);
                assert!(gx.hypot(gy) <= catmull_rom_cell_slope(&p, 1.0) + 1e-6);
                let (h, f0) = (1e-3, f(x, y));
                if (x - x.round()).abs() > 2.0 * h && (y - y.round()).abs() > 2.0 * h {
                    let fxx = (f(x + h, y) - 2.0 * f0 + f(x - h, y)) / (h * h);
                    let fyy = (f(x, y + h) - 2.0 * f0 + f(x, y - h)) / (h * h);
                    assert!(fxx.hypot(fyy) <= catmull_rom_cell_curvature(&p, 1.0) + 1e-3);
                }
            }
        }
    }
}
