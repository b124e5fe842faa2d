//! The light-grid pool: one 3D texture (`Rgba8Unorm`: sky visibility, the canopy's
//! transmittance toward the sun, the sun's margin over the terrain horizon, the ground's
//! bounce) of
//! [`POOL_TILES`] x [`POOL_TILES`] tiles, each a grid's `COLUMNS x COLUMNS x LAYERS` samples,
//! bound in the frame group (binding 1, the layer heights at 3) so that every renderer's
//! shaders read it (`node_light` in the prelude). The shaders filter trilinearly inside a tile
//! from eight loaded samples, with weights from the coordinates inside the tile (clamped to its
//! sample centres, so neighbouring tiles never bleed in): a grid's values draw the same
//! whichever tile it leased, which a sampler's filter at normalized coordinates did not quite
//! (its weights depend on where in the texture the tile lies).
//!
//! A grid's tile is leased by the first node drawn with it ([`LightPool::lease`]) and shared
//! by every node the grid shades; it returns to the pool when the last [`LightLease`] drops
//! (with the nodes' GPU objects). A relit grid is written again into the same tile.

use super::bulk_forget::BulkForget;
use crate::lighting::content::SharedGrid;
use crate::lighting::grid::{COLUMNS, LAYERS};
use crate::terrain::quadtree::{NodeKey, QuadTree};
use rustc_hash::FxHashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, Weak};

/// Tiles along each side of the pool texture: 2,304 grids resident at once (80 MB), those of
/// as many drawn-since-loaded nodes at the grid level or coarser (finer nodes share their
/// ancestor's; prefetched nodes hold none until drawn). A grid that finds the pool full is
/// drawn fully lit until a tile frees (logged once, each try counted in `LightPool::refused`).
pub const POOL_TILES: u32 = 48;
/// Texels of one tile along x and y.
const TILE: u32 = COLUMNS as u32;
/// Bytes of one texel (one sample).
pub const TEXEL_BYTES: u32 = 4;

/// Mirrors the prelude's `LightInfo`: the layer heights above the ground (m, [`LAYERS`] of
/// them, the rest repeat the last), the pool's tiles per side and the ground's albedo.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub struct LightInfo {
    pub layers_m: [[f32; 4]; 2],
    /// x: tiles per side, yzw: unused.
    pub tiles: [f32; 4],
    /// rgb: the map's mean ground albedo (linear), the colour of the light the terrain bounces
    /// (a grid sample's bounce times it and the sun's colour); w: unused.
    pub ground_albedo: [f32; 4],
}

// The prelude's `LightInfo` holds eight layer heights.
const _: () = assert!(LAYERS <= 8, "LightInfo.layers_m holds 8 heights");

/// `LightLease::written` before the first write.
const NOT_WRITTEN: u64 = u64::MAX;

/// A grid's tile, held by the nodes it shades.
#[derive(Debug)]
pub struct LightLease {
    pub tile: u32,
    pub grid: Arc<SharedGrid>,
    /// The grid version written into the tile.
    written: AtomicU64,
    free: Arc<Mutex<Vec<u32>>>,
}

impl Drop for LightLease {
    fn drop(&mut self) {
        if let Ok(mut free) = self.free.lock() {
            free.push(self.tile);
        }
    }
}

impl LightLease {
    /// Whether the tile holds the grid (some version of it).
    pub fn written(&self) -> bool {
        self.written.load(Ordering::Acquire) != NOT_WRITTEN
    }

    /// The grid version the tile holds ([`SharedGrid::version`]), if written.
    pub fn written_version(&self) -> Option<u64> {
        Some(self.written.load(Ordering::Acquire)).filter(|&v| v != NOT_WRITTEN)
    }

    /// The node-table numbers of node `key` shaded by this grid: tile, columns per metre and
    /// the node's south-west corner in the grid's columns ([`NO_LIGHT`]'s before the grid is
    /// written).
    pub fn entry(&self, tree: &QuadTree, key: NodeKey) -> [f32; 4] {
        if !self.written() {
            return NO_LIGHT.grid;
        }
        let grid = tree.rect(self.grid.key);
        let node = tree.rect(key);
        let per_m = (COLUMNS - 1) as f64 / (grid.max[0] - grid.min[0]);
        [
            self.tile as f32,
            per_m as f32,
            ((node.min[0] - grid.min[0]) * per_m) as f32,
            ((node.min[1] - grid.min[1]) * per_m) as f32,
        ]
    }
}

/// A node's light numbers for its node-table entry (`Node.light` and `Node.more.zw` in the
/// prelude).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightEntry {
    /// [`LightLease::entry`].
    pub grid: [f32; 4],
    /// The node's sides toward a coarser grid (a [`crate::lighting::seams::SideSteps`] code)
    /// and its width in the grid's columns (`lighting::seams`).
    pub seam: [f32; 2],
}

/// The node-table numbers of a node without a grid (the shaders light it fully).
pub const NO_LIGHT: LightEntry = LightEntry {
    grid: [-1.0, 0.0, 0.0, 0.0],
    seam: [0.0, 0.0],
};

pub struct LightPool {
    texture: wgpu::Texture,
    pub view: wgpu::TextureView,
    pub info: wgpu::Buffer,
    free: Arc<Mutex<Vec<u32>>>,
    leases: Mutex<Leases>,
    /// Lease tries that found no free tile (the node drawn fully lit that frame), for
    /// statistics.
    pub refused: AtomicU64,
    /// This frame's node-table numbers of each drawn node's light grid, in the order of
    /// `FrameDraws::drawn`, then of each drawn-through ancestor's, in the order of
    /// `FrameDraws::ancestors` (found once by the lighting renderer's `prepare`, which runs
    /// first; read by the other renderers through [`Self::drawn_entry`] and
    /// [`Self::ancestor_entry`]), each with its node's key.
    pub(super) drawn_entries: Vec<(NodeKey, LightEntry)>,
    pub(super) ancestor_entries: Vec<(NodeKey, LightEntry)>,
}

/// The `i`-th of `entries` when it is `key`'s; a list made for another draw list (a bug:
/// debug builds stop here) gives [`NO_LIGHT`].
fn entry_of(entries: &[(NodeKey, LightEntry)], i: usize, key: NodeKey) -> LightEntry {
    match entries.get(i) {
        Some(&(k, entry)) if k == key => entry,
        Some(&(k, _)) => {
            debug_assert_eq!(k, key, "light entry {i} belongs to another node");
            NO_LIGHT
        }
        None => NO_LIGHT,
    }
}

impl std::fmt::Debug for LightPool {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "LightPool({} leased)", self.leased())
    }
}

impl LightPool {
    pub fn new(device: &wgpu::Device) -> Self {
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("light-grid pool"),
            size: wgpu::Extent3d {
                width: TILE * POOL_TILES,
                height: TILE * POOL_TILES,
                depth_or_array_layers: LAYERS as u32,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D3,
            format: wgpu::TextureFormat::Rgba8Unorm,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        let info = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("light-grid info"),
            size: std::mem::size_of::<LightInfo>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Self {
            texture,
            view,
            info,
            free: Arc::new(Mutex::new((0..POOL_TILES * POOL_TILES).rev().collect())),
            leases: Mutex::new(Leases::default()),
            refused: AtomicU64::new(0),
            drawn_entries: Vec::new(),
            ancestor_entries: Vec::new(),
        }
    }

    /// Writes the layer heights the grids use (the same for every grid of a map) and the
    /// map's mean ground albedo (linear RGB).
    pub fn set_map(&self, queue: &wgpu::Queue, layers_m: &[f64; LAYERS], ground_albedo: [f32; 3]) {
        let mut l = [0.0f32; 8];
        for (i, v) in l.iter_mut().enumerate() {
            *v = layers_m[i.min(LAYERS - 1)] as f32;
        }
        let info = LightInfo {
            layers_m: [[l[0], l[1], l[2], l[3]], [l[4], l[5], l[6], l[7]]],
            tiles: [POOL_TILES as f32, 0.0, 0.0, 0.0],
            ground_albedo: [ground_albedo[0], ground_albedo[1], ground_albedo[2], 0.0],
        };
        queue.write_buffer(&self.info, 0, bytemuck::bytes_of(&info));
    }

    /// The tile of `grid` (leased now if no node holds it yet; written by [`Self::refresh`] once
    /// the grid is computed), or None when the pool is full.
    pub fn lease(&self, grid: &Arc<SharedGrid>) -> Option<Arc<LightLease>> {
        let mut leases = self.leases.lock().expect("leases lock");
        if let Some(l) = leases.by_key.get(&grid.key).and_then(Weak::upgrade)
            && Arc::ptr_eq(&l.grid, grid)
        {
            return Some(l);
        }
        let tile = self.free.lock().expect("pool lock").pop();
        let Some(tile) = tile else {
            if self.refused.fetch_add(1, Ordering::Relaxed) == 0 {
                log::warn!(
                    "light-grid pool full ({} grids): grids without a tile are drawn fully lit until one frees",
                    POOL_TILES * POOL_TILES
                );
            }
            return None;
        };
        let lease = Arc::new(LightLease {
            tile,
            grid: Arc::clone(grid),
            written: AtomicU64::new(NOT_WRITTEN),
            free: Arc::clone(&self.free),
        });
        leases.insert(grid.key, Arc::downgrade(&lease));
        Some(lease)
    }

    /// Writes the lease's grid if it arrived or changed since (a relight).
    pub fn refresh(&self, queue: &wgpu::Queue, lease: &LightLease) {
        let version = lease.grid.version();
        if lease.written.load(Ordering::Acquire) == version {
            return;
        }
        let Some(grid) = lease.grid.grid() else {
            return;
        };
        let mut texels = Vec::with_capacity(grid.sky.len() * TEXEL_BYTES as usize);
        let samples = grid.sky.iter().zip(&grid.sun).zip(&grid.sun_margin);
        for (((&sky, &sun), &margin), &bounce) in samples.zip(&grid.bounce) {
            texels.extend([sky, sun, margin, bounce]);
        }
        queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &self.texture,
                mip_level: 0,
                origin: wgpu::Origin3d {
                    x: (lease.tile % POOL_TILES) * TILE,
                    y: (lease.tile / POOL_TILES) * TILE,
                    z: 0,
                },
                aspect: wgpu::TextureAspect::All,
            },
            &texels,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(TILE * TEXEL_BYTES),
                rows_per_image: Some(TILE),
            },
            wgpu::Extent3d {
                width: TILE,
                height: TILE,
                depth_or_array_layers: LAYERS as u32,
            },
        );
        lease.written.store(version, Ordering::Release);
    }

    /// Writes the grid of node `key`'s live lease, if any, when it arrived or changed since
    /// ([`Self::refresh`]), whether or not a node holding it is drawn this frame.
    pub fn refresh_key(&self, queue: &wgpu::Queue, key: NodeKey) {
        let lease = self
            .leases
            .lock()
            .expect("leases lock")
            .by_key
            .get(&key)
            .and_then(Weak::upgrade);
        if let Some(lease) = lease {
            self.refresh(queue, &lease);
        }
    }

    /// This frame's light-grid numbers of the `i`-th drawn node, `key` ([`NO_LIGHT`] without
    /// the lighting renderer).
    pub fn drawn_entry(&self, i: usize, key: NodeKey) -> LightEntry {
        entry_of(&self.drawn_entries, i, key)
    }

    /// This frame's light-grid numbers of the `i`-th drawn-through ancestor, `key`.
    pub fn ancestor_entry(&self, i: usize, key: NodeKey) -> LightEntry {
        entry_of(&self.ancestor_entries, i, key)
    }

    /// Grids holding a tile now.
    pub fn leased(&self) -> usize {
        let leases = self.leases.lock().expect("leases lock");
        leases
            .by_key
            .values()
            .filter(|l| l.strong_count() > 0)
            .count()
    }
}

/// The grids' leases by grid key, dropped ones among them until they are forgotten in bulk
/// ([`BulkForget`]): a new lease does not visit every lease.
#[derive(Debug)]
struct Leases<T = LightLease> {
    by_key: FxHashMap<NodeKey, Weak<T>>,
    forget: BulkForget,
}

impl<T> Default for Leases<T> {
    fn default() -> Self {
        Self {
            by_key: FxHashMap::default(),
            forget: BulkForget::default(),
        }
    }
}

impl<T> Leases<T> {
    fn insert(&mut self, key: NodeKey, lease: Weak<T>) {
        let by_key = &mut self.by_key;
        self.forget.sweep_if_due(by_key.len(), || {
            by_key.retain(|_, l| l.strong_count() > 0);
            by_key.len()
        });
        self.by_key.insert(key, lease);
    }
}

#[cfg(test)]
mod tests {
    use super::super::bulk_forget::MIN_ENTRIES;
    use super::*;

    fn entry(x: f32) -> LightEntry {
        LightEntry {
            grid: [x, 0.0, 0.0, 0.0],
            seam: [0.0, 0.0],
        }
    }

    /// Two neighbouring nodes.
    fn two_keys() -> (NodeKey, NodeKey) {
        let a = NodeKey {
            level: 3,
            ix: 1,
            iy: 2,
        };
        (a, NodeKey { ix: 2, ..a })
    }

    /// A node reads its own entry by its place in the draw list; past the list's end (no
    /// lighting renderer) it is drawn fully lit.
    #[test]
    fn a_drawn_node_reads_its_own_light_entry() {
        let (a, b) = two_keys();
        let entries = [(a, entry(1.0)), (b, entry(2.0))];
        assert_eq!(entry_of(&entries, 0, a), entry(1.0));
        assert_eq!(entry_of(&entries, 1, b), entry(2.0));
        assert_eq!(entry_of(&entries, 2, b), NO_LIGHT);
        assert_eq!(entry_of(&[], 0, a), NO_LIGHT);
    }

    /// Dropped leases are forgotten in bulk: over 10,000 leases of distinct grids, each dropped
    /// after the next few are taken, the map never holds more than twice the live ones at the
    /// last sweep (at least 64) plus one, and every live lease is still found by its key.
    #[test]
    fn dropped_leases_are_forgotten_and_live_ones_kept() {
        let mut leases = Leases::<u32>::default();
        let mut live = std::collections::VecDeque::<(NodeKey, Arc<u32>)>::new();
        for i in 0..10_000u32 {
            let key = NodeKey {
                level: 12,
                ix: i % 4096,
                iy: i / 4096,
            };
            let lease = Arc::new(i);
            leases.insert(key, Arc::downgrade(&lease));
            live.push_back((key, lease));
            // 10 to 300 live at once, in waves.
            let keep = 10 + (i as usize / 500 % 3) * 145;
            while live.len() > keep {
                live.pop_front();
            }
            assert!(
                leases.by_key.len() <= 2 * 300usize.max(MIN_ENTRIES) + 1,
                "{} entries with {} live",
                leases.by_key.len(),
                live.len()
            );
            for (k, l) in &live {
                let found = leases.by_key.get(k).and_then(Weak::upgrade);
                assert_eq!(found.as_deref(), Some(&**l), "lease {k:?} lost");
            }
        }
        // Without forgetting, every one of the 10,000 would still be there.
        assert!(leases.by_key.len() < 1_000);
    }

    /// An entry list made for another draw list is a bug that debug builds stop at.
    #[test]
    #[cfg(debug_assertions)]
    #[should_panic = "belongs to another node"]
    fn an_entry_of_another_node_stops_a_debug_build() {
        let (a, b) = two_keys();
        let _ = entry_of(&[(a, entry(1.0))], 0, b);
    }
}
