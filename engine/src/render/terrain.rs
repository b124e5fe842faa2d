//! The terrain renderer: node meshes suballocated from a few large vertex and index buffers
//! (pages), drawn as one multi-draw per mesh page and ground-texture page (each node mesh one
//! indirect record whose first instance is the node's entry in this frame's node table, which
//! lists the drawn nodes in drawing order), filled or as
//! wireframe. The ground's colour is the node's ground texture where the ground kind is
//! registered: its upload hook queues the texture, and `finish_uploads` renders queued textures
//! ([`super::ground`]), coarsest first, within what the frame's GPU budget leaves (carried over
//! frames while one costs more, [`super::texture_credit`]), into layers
//! of the renderer's [`GroundPool`] (the terrain shading is the texture's only reader); a layer
//! is given back when the node's GPU object drops, and a queued texture whose node dropped is
//! never made. Where the owner says which nodes the display needs
//! ([`TerrainRenderer::show_textures_of`]; the viewer: needed for display or drawn), only
//! theirs are made; a prefetched node's waits until the display needs it, so prefetch costs no
//! texture time and no texture memory. The owner charges each texture made to its node's bytes
//! in the cache budget ([`TerrainRenderer::take_made_textures`]). So a node is drawn as soon as
//! its mesh is uploaded: until its own texture is made it shows its nearest resident
//! ancestor's (coarser, the same place), or the legend colours. Close up, the materials' own
//! detail below the finest texel multiplies it ([`super::ground_detail`]). Without ground
//! textures, the map's ground-type legend colours the vertices (with procedural grain close
//! up).

use super::Gpu;
use super::batch_timer::{BatchTimer, ItemCost};
use super::batches::{Batches, Item};
use super::bulk_forget::BulkForget;
use super::frame::{
    DrawStats, FrameResources, PipelineSpec, pipeline, sampler_entry, srgb_to_linear,
    texture_entry, uint_texture_entry, uniform_entry,
};
use super::ground::{GROUND_TEXTURE_FORMAT, GroundTexturer};
use super::ground_detail::GroundDetail;
use super::ground_pool::{GroundPool, GroundSlot, LayerMips, layers_per_page};
use super::node_table::NodeTable;
use super::scene::{FrameDraws, NodeRenderer, UploadEncoder, close_staging, staging_belt};
use super::suballoc::{Lease, Suballocator};
use super::texture_credit::TextureCredit;
use crate::ground::content::{GroundContent, NodeGround};
use crate::ground::layout::{BORDER, SIDE, texel_m};
use crate::stream::{DisplayNodes, NodeWork, Shared};
use crate::surface::World;
use crate::terrain::mesh::{DrawnList, GPU_VERTEX_BYTES, MAX_DECIMATION, NodeMesh, grid_indices};
use crate::terrain::quadtree::{NodeKey, QuadTree};
use glam::DVec3;
use std::sync::{Arc, OnceLock, Weak};
use std::time::Instant;
use wgpu::util::{DeviceExt, DrawIndexedIndirectArgs};

/// Vertices in one page of the mesh pool: 3,435 grid nodes (1,221 vertices each), 64 MiB
/// (within the 256 MiB every adapter allows a buffer). Each page a frame's nodes are in is one
/// more multi-draw (with pages of 858 nodes, the flyover at 720p on lavapipe had three open and
/// drew 21 terrain batches; with these, one page and 2).
const PAGE_VERTICES: u32 = 4 << 20;
/// Indices one page leases to meshes with triangles of their own (grid meshes lease none: they
/// draw the grid's lists, kept once after these): 16 MiB, a few hundred such meshes.
const PAGE_INDICES: u32 = 4 << 20;
/// Pages at most (far more than a cache budget keeps resident).
const MAX_PAGES: usize = 64;

/// Cap of the registered renderer's ground-texture pool. A backstop: pages are made as layers
/// are needed, and the layers in use are bounded by the node-cache budget (every texture made
/// counts in its node's bytes, `ground::content::TEXTURE_BYTES`), which the viewer can change
/// while running.
pub const GROUND_POOL_CAP_BYTES: usize = 4 << 30;

/// Ground types the colour table holds (the map legend has at most this many).
pub const GROUND_TYPES: usize = 256;

/// The assembled shader source (generated constants + prelude + `terrain.wgsl`).
pub fn shader_source() -> String {
    super::shader::assemble(
        "terrain",
        &format!(
            "const GROUND_TYPES: u32 = {GROUND_TYPES}u;\nconst GROUND_SIDE: u32 = {SIDE}u;\n\
             const GROUND_BORDER: u32 = {BORDER}u;\nconst DETAIL_PERIOD_M: f32 = {:?};",
            super::frame::DETAIL_PERIOD_M as f32
        ),
    )
}

/// One node's mesh on the GPU: its ranges in a page of the mesh pool (given back when
/// dropped).
pub struct TerrainNodeGpu {
    /// World position of the node's south-west corner (vertices are relative to it).
    pub origin_m: [f64; 2],
    /// World-space box of the mesh, skirts included.
    pub aabb_m: (DVec3, DVec3),
    /// Part 0: vertices, part 1: the mesh's own indices (relative to its first vertex; none
    /// for a grid mesh, which draws the grid's lists every page keeps).
    mesh: Lease,
    /// Per decimation (0 ..= `MAX_DECIMATION`): first index in the page and count of the
    /// triangles drawn with it (a mesh not laid out as a grid draws all of them each time).
    ranges: [[u32; 2]; DECIMATIONS],
    /// The node's ground texture and its texture coordinates per metre, once made (the queue
    /// of textures to make holds a weak reference).
    ground: Arc<OnceLock<(GroundSlot, f32)>>,
    pub bytes: usize,
}

impl std::fmt::Debug for TerrainNodeGpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "TerrainNodeGpu({} bytes)", self.bytes)
    }
}

/// Index ranges a node mesh has on the GPU, one per decimation.
const DECIMATIONS: usize = MAX_DECIMATION as usize + 1;
/// A terrain vertex ([`GPU_VERTEX_BYTES`]) is its position (three f32, metres from the node's
/// south-west corner, z absolute) and its shading word (`terrain::mesh::pack_shading`). A
/// page's vertex buffer holds the positions of its `PAGE_VERTICES` vertices, then their
/// shading words (from [`SHADING_OFFSET`]), bound as two vertex streams ([`VERTEX_LAYOUTS`]).
const POSITION_BYTES: u64 = 12;
const SHADING_OFFSET: u64 = PAGE_VERTICES as u64 * POSITION_BYTES;
/// The terrain shader's `TerrainVertexIn`: location 0 the position, 1 the shading word.
const VERTEX_LAYOUTS: [Option<wgpu::VertexBufferLayout<'static>>; 2] = [
    Some(wgpu::VertexBufferLayout {
        array_stride: POSITION_BYTES,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &wgpu::vertex_attr_array![0 => Float32x3],
    }),
    Some(wgpu::VertexBufferLayout {
        array_stride: 4,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &wgpu::vertex_attr_array![1 => Uint32],
    }),
];
/// Staging chunks made with the renderer, more than the first frames' bursts of node meshes
/// fill (a grid node's vertices are 20 KB; see [`staging_belt`]).
const MESH_STAGING_PREMADE_CHUNKS: usize = 16;

impl TerrainNodeGpu {
    /// First index (in the page) and index count drawn with `decimation`.
    fn range(&self, decimation: u8) -> [u32; 2] {
        self.ranges[usize::from(decimation).min(DECIMATIONS - 1)]
    }

    /// The node's ground-texture layer, if it has been made.
    pub fn ground_slot(&self) -> Option<&GroundSlot> {
        self.ground.get().map(|g| &g.0)
    }
}

/// A node texture waiting to be made: the node, what it draws, and where the texture goes
/// (gone when the node's GPU object dropped: then it is not made).
struct PendingTexture {
    key: NodeKey,
    pieces: NodeGround,
    target: Weak<OnceLock<(GroundSlot, f32)>>,
}

/// The ground texture drawn node `key` shows, and the node's south-west corner in metres from
/// that of the texture's node: its own, else while it is not made its nearest resident
/// ancestor's that is (the same ground, coarser), else none.
fn shown_texture<'a>(
    node: &'a TerrainNodeGpu,
    key: NodeKey,
    draws: &FrameDraws<'a>,
) -> Option<(&'a (GroundSlot, f32), [f32; 2])> {
    if let Some(own) = node.ground.get() {
        return Some((own, [0.0; 2]));
    }
    key.ancestors().find_map(|a| {
        let i = draws.ancestors.binary_search_by_key(&a, |d| d.key).ok()?;
        let up = draws.ancestors[i].work.gpu.get::<TerrainNodeGpu>()?;
        let g = up.ground.get()?;
        let corner_m = [
            (node.origin_m[0] - up.origin_m[0]) as f32,
            (node.origin_m[1] - up.origin_m[1]) as f32,
        ];
        Some((g, corner_m))
    })
}

/// The sRGB colours of the map's ground legend, in legend order.
pub fn legend_srgb(world: &World) -> Vec<[u8; 3]> {
    world
        .map
        .manifest
        .ground
        .legend
        .iter()
        .map(|g| g.color)
        .collect()
}

/// One page of the mesh pool.
struct MeshPage {
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
}

/// A terrain batch: whether its nodes are in a cross-fade (drawn dithered, after the others),
/// their mesh page and their ground-texture page ([`NO_TEXTURE`] for nodes without one).
type BatchKey = (bool, u32, u32);

/// GPU time a node texture is expected to take before the first measurement (and on adapters
/// without timestamp queries): about 3x what an NVIDIA H100 takes, a quarter of lavapipe's
/// on 2 cores (`nodebench --only textures`).
const TEXTURE_GPU_PRIOR_S: f64 = 0.5e-3;

/// Frame-thread time a node texture (recording its passes) is expected to take before the first
/// batch was timed.
const TEXTURE_FRAME_THREAD_PRIOR_S: f64 = 0.1e-3;

/// The ground page of nodes without a ground texture.
const NO_TEXTURE: u32 = u32::MAX;

/// Node ground textures: the pass that renders them, the layer pool they live in, the textures
/// waiting to be made, the mip levels due, and bind group 2 per pool page.
struct GroundTextures {
    texturer: GroundTexturer,
    tree: QuadTree,
    /// Textures waiting to be made, in arrival order.
    pending: Vec<PendingTexture>,
    /// When dropped nodes' textures are forgotten.
    forget: BulkForget,
    pool: GroundPool,
    /// The map's decals (the nodes' pieces refer to them by index).
    decals: Vec<worldgen::map::Decal>,
    /// The mip bindings of the textures recorded this frame (their mip levels are recorded in
    /// one pass after them).
    mips_due: Vec<LayerMips>,
    /// GPU time per node texture (timestamp queries around each submitted batch).
    timer: BatchTimer,
    /// The frame thread's time per node texture: recording it (the submission of the frame's
    /// deferred work, where wgpu encodes the passes, is counted by the scene).
    frame_thread: ItemCost,
    groups: Vec<wgpu::BindGroup>,
    /// Nodes left without a texture because the pool was full.
    refused: u64,
    /// The textures' share of the frame budget, carried across frames.
    credit: TextureCredit,
    /// The nodes whose textures are made (the display's), or every uploaded node's when
    /// `None` (an owner without a display, e.g. tests rendering nodes directly).
    shown: Option<DisplayNodes>,
    /// Nodes whose textures were made since the owner last took them.
    made: Vec<NodeKey>,
}

impl GroundTextures {
    /// Whether `key`'s texture is made now (else it waits in the queue).
    fn shown(&self, key: NodeKey) -> bool {
        self.shown.as_ref().is_none_or(|s| s.contains(&key))
    }

    /// Forgets the queued textures of dropped nodes in bulk ([`BulkForget`]; a texture the
    /// display needs is forgotten as soon as it comes up, but a prefetched node may drop
    /// without ever being needed), so a frame does not visit every queued texture.
    fn forget_dropped(&mut self) {
        let pending = &mut self.pending;
        self.forget.sweep_if_due(pending.len(), || {
            pending.retain(|p| p.target.strong_count() > 0);
            pending.len()
        });
    }
}

/// Terrain pipelines, the mesh pool, the node table and this frame's batches.
pub struct TerrainRenderer {
    /// Nodes in a cross-fade: the fragment shader discards the pixels outside their dither
    /// interval.
    fill: wgpu::RenderPipeline,
    /// Nodes not fading: the same pixels without the dither test, so the shader has no
    /// `discard` and hidden fragments fail the depth test before shading.
    solid: wgpu::RenderPipeline,
    /// `fill` and `solid` with a flat fragment shader (`ViewOptions::flat_terrain`: the same
    /// draws, dithers and skirts without the shading, to split the GPU ratio).
    flat_fill: wgpu::RenderPipeline,
    flat_solid: wgpu::RenderPipeline,
    wire: Option<wgpu::RenderPipeline>,
    /// Group 2 for nodes without a ground texture (legend colours, a one-layer dummy page).
    colors: wgpu::BindGroup,
    group_layout: wgpu::BindGroupLayout,
    colors_buffer: wgpu::Buffer,
    sampler: wgpu::Sampler,
    /// The materials' detail below the finest node texel (stand-ins without ground textures).
    detail: GroundDetail,
    ground: Option<GroundTextures>,
    pool: Suballocator,
    pages: Vec<MeshPage>,
    grid_ranges: GridRanges,
    /// The node meshes' staging memory (copied out of by commands in the upload encoder).
    staging: wgpu::util::StagingBelt,
    table: NodeTable,
    batches: Batches<BatchKey>,
    triangles: u64,
    culled: u32,
    /// This frame's batches are recorded as multi-draws (else as plain loops).
    merged: bool,
    /// Drawn nodes this frame that show an ancestor's ground texture, and that show none
    /// (legend colours), their own not made yet.
    pub borrowed_textures: usize,
    pub untextured: usize,
}

impl std::fmt::Debug for TerrainRenderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "TerrainRenderer({} pages, {:?})",
            self.pages.len(),
            self.table
        )
    }
}

impl TerrainRenderer {
    /// Pipelines for `legend_srgb` ground colours (the map's legend, at most [`GROUND_TYPES`]).
    pub fn new(gpu: &Gpu, frame: &FrameResources, legend_srgb: &[[u8; 3]]) -> Self {
        let device = &gpu.device;
        let module = super::shader::module(device, "terrain", &shader_source());
        let colors_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("terrain ground layout"),
            entries: &[
                uniform_entry(0, false, wgpu::ShaderStages::VERTEX),
                texture_entry(1, wgpu::TextureViewDimension::D2Array),
                sampler_entry(2),
                texture_entry(3, wgpu::TextureViewDimension::D2Array),
                uint_texture_entry(4),
                sampler_entry(5),
                uniform_entry(6, false, wgpu::ShaderStages::FRAGMENT),
            ],
        });
        let layout = frame.pipeline_layout(
            device,
            "terrain pipeline layout",
            true,
            &[Some(&colors_layout)],
        );
        let buffers = VERTEX_LAYOUTS;
        let spec = PipelineSpec::triangles(
            "terrain fill",
            "vs_main",
            "fs_main",
            &buffers,
            frame.color_format,
        );
        let fill = pipeline(device, &module, &layout, &spec);
        let solid = pipeline(
            device,
            &module,
            &layout,
            &PipelineSpec {
                label: "terrain solid",
                fs: "fs_solid",
                ..spec.clone()
            },
        );
        // The GPU-ratio diagnostic's pipelines: the same draws with a flat fragment shader.
        let flat_fill = pipeline(
            device,
            &module,
            &layout,
            &PipelineSpec {
                label: "terrain flat fill",
                fs: "fs_flat",
                ..spec.clone()
            },
        );
        let flat_solid = pipeline(
            device,
            &module,
            &layout,
            &PipelineSpec {
                label: "terrain flat solid",
                fs: "fs_flat_solid",
                ..spec.clone()
            },
        );
        let wire = gpu.wireframe.then(|| {
            pipeline(
                device,
                &module,
                &layout,
                &PipelineSpec {
                    label: "terrain wireframe",
                    polygon_mode: wgpu::PolygonMode::Line,
                    ..spec.clone()
                },
            )
        });
        let mut table = vec![[0.5f32, 0.5, 0.5, 1.0]; GROUND_TYPES];
        for (c, l) in table.iter_mut().zip(legend_srgb) {
            *c = [
                srgb_to_linear(l[0]),
                srgb_to_linear(l[1]),
                srgb_to_linear(l[2]),
                1.0,
            ];
        }
        let colors_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("ground colours"),
            contents: bytemuck::cast_slice(&table),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("node ground texture sampler"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            anisotropy_clamp: gpu.anisotropy,
            ..Default::default()
        });
        let dummy = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("no ground texture"),
            size: wgpu::Extent3d {
                width: 1,
                height: 1,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: GROUND_TEXTURE_FORMAT,
            usage: wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        });
        let detail = GroundDetail::none(gpu);
        let colors = ground_group(
            device,
            &colors_layout,
            &colors_buffer,
            &dummy,
            &sampler,
            &detail,
        );
        Self {
            fill,
            solid,
            flat_fill,
            flat_solid,
            wire,
            colors,
            group_layout: colors_layout,
            colors_buffer,
            sampler,
            detail,
            ground: None,
            pool: Suballocator::new(&[PAGE_VERTICES, PAGE_INDICES], MAX_PAGES),
            staging: staging_belt(device, MESH_STAGING_PREMADE_CHUNKS),
            pages: Vec::new(),
            grid_ranges: GridRanges::new(),
            table: NodeTable::by_draw(device, frame, "terrain node table"),
            batches: Batches::new(),
            triangles: 0,
            culled: 0,
            merged: false,
            borrowed_textures: 0,
            untextured: 0,
        }
    }

    /// The same renderer drawing nodes with ground textures: it renders the texture of every
    /// uploaded node that has a [`NodeGround`] payload into a layer of a pool of at most
    /// `pool_budget_bytes`.
    #[must_use]
    pub fn with_ground_textures(
        mut self,
        gpu: &Gpu,
        world: &Arc<World>,
        pool_budget_bytes: usize,
    ) -> Self {
        let texturer = GroundTexturer::new(gpu, world);
        let (materials, types) = texturer.detail_sources();
        let tree = QuadTree::new(world.origin_m(), world.size_m());
        self.detail =
            GroundDetail::new(gpu, materials, types, world, texel_m(&tree, tree.max_level));
        self.ground = Some(GroundTextures {
            pool: GroundPool::with_pages_of(
                pool_budget_bytes,
                layers_per_page(&gpu.device, pool_budget_bytes),
                texturer.mip_layout(),
            ),
            texturer,
            tree,
            pending: Vec::new(),
            forget: BulkForget::default(),
            decals: world.map.decals.clone(),
            mips_due: Vec::new(),
            timer: BatchTimer::new(gpu, TEXTURE_GPU_PRIOR_S),
            frame_thread: ItemCost::new(TEXTURE_FRAME_THREAD_PRIOR_S),
            credit: TextureCredit::default(),
            groups: Vec::new(),
            refused: 0,
            shown: None,
            made: Vec::new(),
        });
        self
    }

    /// Layers of the ground-texture pool in use and bytes of its pages (zeros without ground
    /// textures).
    pub fn ground_pool_use(&self) -> (usize, usize) {
        self.ground
            .as_ref()
            .map_or((0, 0), |g| (g.pool.layers_in_use(), g.pool.bytes()))
    }

    /// Node textures queued and not made yet that the display needs (their nodes still
    /// resident or not); prefetched nodes' textures wait, uncounted.
    pub fn textures_pending(&self) -> usize {
        self.ground
            .as_ref()
            .map_or(0, |g| g.pending.iter().filter(|p| g.shown(p.key)).count())
    }

    /// Node textures queued, made for no node yet, whether the display needs them or not and
    /// whether their nodes are resident or not (those of dropped nodes are forgotten in bulk
    /// once the queue has doubled).
    pub fn textures_queued(&self) -> usize {
        self.ground.as_ref().map_or(0, |g| g.pending.len())
    }

    /// From now on makes the textures of `keys` only (the nodes the display needs: needed for
    /// display or drawn), or of every uploaded node with `None` (the default). The others
    /// stay queued until they are in the set or their nodes drop.
    pub fn show_textures_of(&mut self, keys: Option<DisplayNodes>) {
        if let Some(g) = self.ground.as_mut() {
            g.shown = keys;
        }
    }

    /// The nodes whose textures were made since the last call
    /// ([`crate::ground::content::TEXTURE_BYTES`] each, for the owner to count in the cache
    /// budget).
    pub fn take_made_textures(&mut self) -> Vec<NodeKey> {
        self.ground
            .as_mut()
            .map_or_else(Vec::new, |g| std::mem::take(&mut g.made))
    }

    /// Renders node `key`'s ground texture into a new pool layer (recorded into `deferred`, the
    /// scene's deferred work, made only when a texture is recorded). None without ground
    /// textures or when the pool is full.
    fn render_ground(
        &mut self,
        gpu: &Gpu,
        deferred: &mut UploadEncoder<'_>,
        key: NodeKey,
        pieces: &NodeGround,
    ) -> Option<(GroundSlot, f32)> {
        let g = self.ground.as_mut()?;
        let tree = &g.tree;
        let Some(slot) = g.pool.lease(&gpu.device) else {
            g.refused += 1;
            if g.refused == 1 {
                log::warn!(
                    "ground texture pool full: nodes show an ancestor's texture or legend colours"
                );
            }
            return None;
        };
        while g.groups.len() < g.pool.pages() {
            let page = g.pool.page(g.groups.len() as u32)?;
            g.groups.push(ground_group(
                &gpu.device,
                &self.group_layout,
                &self.colors_buffer,
                page,
                &self.sampler,
                &self.detail,
            ));
        }
        let enc = deferred.get(&gpu.device);
        g.timer.item(gpu, enc);
        g.texturer
            .record(gpu, enc, &slot.view, tree, key, pieces, &g.decals);
        g.mips_due.push(slot.mips.clone());
        let uv_per_m = 1.0 / (texel_m(tree, key.level) * f64::from(SIDE));
        Some((slot, uv_per_m as f32))
    }

    /// The registered constructor: colours from the map's legend, ground textures when the
    /// ground kind is registered (pool cap [`GROUND_POOL_CAP_BYTES`]).
    pub fn create(gpu: &Gpu, frame: &FrameResources, shared: &Shared) -> Box<dyn NodeRenderer> {
        let renderer = Self::new(gpu, frame, &legend_srgb(&shared.world));
        if shared.kind::<GroundContent>().is_none() {
            return Box::new(renderer);
        }
        Box::new(renderer.with_ground_textures(gpu, &shared.world, GROUND_POOL_CAP_BYTES))
    }

    /// Uploads one node mesh (vertices relative to its south-west corner, z absolute) into the
    /// mesh pool. None when the pool or the node table is full (the node is then not drawn).
    pub fn upload_mesh(
        &mut self,
        device: &wgpu::Device,
        tree: &QuadTree,
        mesh: &NodeMesh,
        copies: &mut UploadEncoder<'_>,
    ) -> Option<TerrainNodeGpu> {
        // A grid mesh draws the grid's index lists every page keeps (`GridRanges`): only its
        // vertices are uploaded. Another mesh uploads its own indices too.
        let own = mesh.own_gpu_indices();
        let lengths = [mesh.positions.len() as u32, own.len() as u32];
        let (Some(position_size), Some(shading_size)) = (
            wgpu::BufferSize::new(u64::from(lengths[0]) * POSITION_BYTES),
            wgpu::BufferSize::new(u64::from(lengths[0]) * 4),
        ) else {
            log::warn!("terrain mesh of node {:?} is empty: not drawn", mesh.key);
            return None;
        };
        if mesh.shading.len() != mesh.positions.len() {
            log::warn!(
                "terrain mesh of node {:?} has {} shading words for {} vertices: not drawn",
                mesh.key,
                mesh.shading.len(),
                mesh.positions.len()
            );
            return None;
        }
        let Some(lease) = self.pool.lease(&lengths) else {
            log::warn!("terrain mesh pool full: node {:?} is not drawn", mesh.key);
            return None;
        };
        let copies = copies.get(device);
        self.open_pages(device, copies);
        let ranges: [[u32; 2]; DECIMATIONS] =
            std::array::from_fn(|d| match mesh.drawn_list(d as u8) {
                DrawnList::Grid(steps) => self.grid_ranges.ranges[usize::from(steps)],
                DrawnList::Own => [lease.start[1], lengths[1]],
            });
        // The positions, shading words (and own indices) are copied straight into the staging
        // belt's memory (no staging buffer made and freed per write, whose fresh pages cost a
        // page fault each).
        let page = &self.pages[lease.page as usize];
        self.staging
            .write_buffer(
                copies,
                &page.vertices,
                u64::from(lease.start[0]) * POSITION_BYTES,
                position_size,
            )
            .copy_from_slice(bytemuck::cast_slice(&mesh.positions));
        self.staging
            .write_buffer(
                copies,
                &page.vertices,
                SHADING_OFFSET + u64::from(lease.start[0]) * 4,
                shading_size,
            )
            .copy_from_slice(bytemuck::cast_slice(&mesh.shading));
        if let Some(index_size) = wgpu::BufferSize::new(u64::from(lengths[1]) * 4) {
            self.staging
                .write_buffer(
                    copies,
                    &page.indices,
                    u64::from(lease.start[1]) * 4,
                    index_size,
                )
                .copy_from_slice(bytemuck::cast_slice(own));
        }
        Some(TerrainNodeGpu {
            origin_m: mesh.origin_m,
            aabb_m: mesh.aabb_m(tree),
            mesh: lease,
            ranges,
            ground: Arc::new(OnceLock::new()),
            bytes: mesh.gpu_bytes(),
        })
    }

    /// Makes the pages the pool has opened and this renderer not yet, each with the grid's
    /// index lists after its leased indices (copied by `copies`).
    fn open_pages(&mut self, device: &wgpu::Device, copies: &mut wgpu::CommandEncoder) {
        while self.pages.len() < self.pool.pages() {
            let n = self.pages.len();
            let buffer = |what: &str, bytes: u64, usage| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(&format!("terrain page {n} {what}")),
                    size: bytes,
                    usage: usage | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            };
            let grid = &self.grid_ranges.indices;
            let page = MeshPage {
                vertices: buffer(
                    "vertices",
                    u64::from(PAGE_VERTICES) * GPU_VERTEX_BYTES as u64,
                    wgpu::BufferUsages::VERTEX,
                ),
                indices: buffer(
                    "indices",
                    (u64::from(PAGE_INDICES) + grid.len() as u64) * 4,
                    wgpu::BufferUsages::INDEX,
                ),
            };
            if let Some(size) = wgpu::BufferSize::new(grid.len() as u64 * 4) {
                self.staging
                    .write_buffer(copies, &page.indices, u64::from(PAGE_INDICES) * 4, size)
                    .copy_from_slice(bytemuck::cast_slice(grid));
            }
            self.pages.push(page);
        }
    }
}

/// The grid's index lists ([`grid_indices`], decimations 0 ..= `MAX_DECIMATION` one after
/// another), which every page keeps after its `PAGE_INDICES` leased indices, and where each
/// decimation's list is in a page (first index, count).
struct GridRanges {
    ranges: [[u32; 2]; DECIMATIONS],
    indices: Vec<u32>,
}

impl GridRanges {
    fn new() -> Self {
        let mut indices = Vec::new();
        let ranges = std::array::from_fn(|d| {
            let list = &grid_indices(d as u8).indices;
            let first = PAGE_INDICES + indices.len() as u32;
            indices.extend_from_slice(list);
            [first, list.len() as u32]
        });
        Self { ranges, indices }
    }
}

impl NodeRenderer for TerrainRenderer {
    fn name(&self) -> &'static str {
        "terrain"
    }

    fn upload(
        &mut self,
        gpu: &Gpu,
        _frame: &FrameResources,
        tree: &QuadTree,
        work: &mut NodeWork,
        copies: &mut UploadEncoder<'_>,
    ) -> usize {
        let Some(mesh) = work.get::<NodeMesh>() else {
            return 0;
        };
        let Some(node) = self.upload_mesh(&gpu.device, tree, mesh, copies) else {
            return 0;
        };
        if let Some(pieces) = work.get::<NodeGround>()
            && let Some(g) = self.ground.as_mut()
        {
            g.pending.push(PendingTexture {
                key: work.key,
                pieces: pieces.clone(),
                target: Arc::downgrade(&node.ground),
            });
        }
        let bytes = node.bytes;
        work.gpu.put(node);
        bytes
    }

    fn close_uploads(&mut self) {
        close_staging(&mut self.staging);
    }

    fn finish_uploads(
        &mut self,
        gpu: &Gpu,
        deferred: &mut UploadEncoder<'_>,
        time_left_s: f64,
    ) -> f64 {
        let Some(g) = self.ground.as_mut() else {
            return 0.0;
        };
        g.forget_dropped();
        // Only the textures the display needs are looked at (the rest of the queue, mostly
        // prefetched nodes', waits untouched): coarsest first (they stand in for the finer
        // ones), in arrival order within a level. The queue itself stays in arrival order.
        let mut queue = std::mem::take(&mut g.pending);
        let mut order: Vec<usize> = (0..queue.len())
            .filter(|&i| g.shown(queue[i].key))
            .collect();
        order.sort_by_key(|&i| queue[i].key.level);
        let gpu_per_texture_s = g.timer.per_item_s();
        let per_texture_s = gpu_per_texture_s + g.frame_thread.per_item_s();
        let mut made = 0;
        // The frame thread's time in the textures themselves (recording their passes and mips);
        // going through the queue is not per texture and is left out of the estimate.
        let mut textures_s = 0.0;
        // Queue entries done with: made, or their node dropped.
        let mut done = vec![false; queue.len()];
        // Whether a texture the display needs waits for the budget (the credit carries over).
        let mut shown_waiting = false;
        // This frame's share and what earlier frames carried over.
        let mut credit_s = g.credit.start(time_left_s);
        for i in order {
            let p = &queue[i];
            let Some(target) = p.target.upgrade() else {
                done[i] = true;
                continue;
            };
            if per_texture_s > credit_s {
                shown_waiting = true;
                continue;
            }
            let t = Instant::now();
            let texture = self.render_ground(gpu, deferred, p.key, &p.pieces);
            textures_s += t.elapsed().as_secs_f64();
            credit_s -= per_texture_s;
            done[i] = true;
            if let Some(texture) = texture {
                // Only this queue sets a node's texture, once.
                let _ = target.set(texture);
                made += 1;
                if let Some(g) = self.ground.as_mut() {
                    g.made.push(p.key);
                }
            }
        }
        let mut i = 0;
        queue.retain(|_| {
            i += 1;
            !done[i - 1]
        });
        let Some(g) = self.ground.as_mut() else {
            return 0.0;
        };
        g.credit.end(credit_s, per_texture_s, shown_waiting);
        g.pending = queue;
        let t = Instant::now();
        if !g.mips_due.is_empty() {
            let enc = deferred.get(&gpu.device);
            g.texturer.record_mips(enc, &g.mips_due);
            g.mips_due.clear();
            g.timer.before_submit(enc);
            g.texturer.write_recorded(gpu);
        }
        textures_s += t.elapsed().as_secs_f64();
        g.frame_thread.observe(textures_s, made);
        made as f64 * gpu_per_texture_s
    }

    fn after_deferred_submit(&mut self) {
        if let Some(g) = self.ground.as_mut() {
            g.timer.after_submit();
        }
    }

    fn prepare(&mut self, gpu: &Gpu, frame: &mut FrameResources, draws: &FrameDraws<'_>) {
        self.detail.write(&gpu.queue, draws.camera);
        self.batches.clear();
        self.triangles = 0;
        self.merged = draws.view.multi_draw(gpu);
        self.borrowed_textures = 0;
        self.untextured = 0;
        let mut visible = 0;
        for (i, d) in draws.drawn.iter().enumerate() {
            let Some(node) = d.work.gpu.get::<TerrainNodeGpu>() else {
                continue;
            };
            if d.dither[1] > d.dither[0]
                && draws.frustum.intersects_aabb(node.aabb_m.0, node.aabb_m.1)
            {
                let shown = self
                    .ground
                    .is_some()
                    .then(|| shown_texture(node, d.key, draws))
                    .flatten();
                if self.ground.is_some() && node.ground.get().is_none() {
                    if shown.is_some() {
                        self.borrowed_textures += 1;
                    } else {
                        self.untextured += 1;
                    }
                }
                let (page, extra) = match shown {
                    Some((g, corner_m)) => {
                        let extra = [g.0.layer() as f32, g.1, corner_m[0], corner_m[1]];
                        (g.0.page(), extra)
                    }
                    None => (NO_TEXTURE, [-1.0, 0.0, 0.0, 0.0]),
                };
                let light = frame.light.drawn_entry(i, d.key);
                // The table holds this frame's drawn nodes in drawing order (a few hundred
                // entries written, not one per resident node).
                let row = NodeTable::row(frame, node.origin_m, d.key.level, d.dither, extra, light);
                let Some(entry) = self.table.push(row) else {
                    continue;
                };
                let m = &node.mesh;
                let fading = d.dither[0] > 0.0 || d.dither[1] < 1.0;
                let [first_index, index_count] = node.range(d.decimation);
                self.batches.push(
                    (fading, m.page, page),
                    Item::Indexed(DrawIndexedIndirectArgs {
                        index_count,
                        instance_count: 1,
                        first_index,
                        base_vertex: m.start[0] as i32,
                        first_instance: entry,
                    }),
                );
                self.triangles += u64::from(index_count / 3);
                visible += 1;
            }
        }
        self.culled = (draws.drawn.len() - visible) as u32;
        self.table.flush(&gpu.queue);
        self.batches.upload(gpu);
    }

    fn draw(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        _frame: &FrameResources,
        draws: &FrameDraws<'_>,
        stats: &mut DrawStats,
    ) {
        stats.culled += self.culled;
        if !draws.view.terrain {
            return;
        }
        let wire = self.wire.as_ref().filter(|_| draws.view.wireframe);
        let (fill, solid) = if draws.view.flat_terrain {
            (&self.flat_fill, &self.flat_solid)
        } else {
            (&self.fill, &self.solid)
        };
        pass.set_bind_group(1, &self.table.group, &[]);
        let mut bound: Option<bool> = None;
        let mut bound_ground = None;
        for run in self.batches.runs() {
            let (fading, page, ground) = run.key;
            if bound_ground != Some(ground) {
                let group = self
                    .ground
                    .as_ref()
                    .and_then(|g| g.groups.get(ground as usize))
                    .unwrap_or(&self.colors);
                pass.set_bind_group(2, group, &[]);
                bound_ground = Some(ground);
            }
            if bound != Some(fading) {
                pass.set_pipeline(match (wire, fading) {
                    (Some(w), _) => w,
                    (None, true) => fill,
                    (None, false) => solid,
                });
                bound = Some(fading);
            }
            let page = &self.pages[page as usize];
            pass.set_vertex_buffer(0, page.vertices.slice(..SHADING_OFFSET));
            pass.set_vertex_buffer(1, page.vertices.slice(SHADING_OFFSET..));
            pass.set_index_buffer(page.indices.slice(..), wgpu::IndexFormat::Uint32);
            stats.draw_calls += self.batches.record(pass, run, self.merged);
            stats.items += run.items();
        }
        stats.triangles += self.triangles;
    }
}

/// Group 2 of the terrain pipelines: the legend colours, a ground-texture page, its sampler.
fn ground_group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    colors: &wgpu::Buffer,
    page: &wgpu::Texture,
    sampler: &wgpu::Sampler,
    detail: &GroundDetail,
) -> wgpu::BindGroup {
    let view = page.create_view(&wgpu::TextureViewDescriptor {
        label: Some("ground texture page"),
        format: Some(GROUND_TEXTURE_FORMAT),
        usage: Some(wgpu::TextureUsages::TEXTURE_BINDING),
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        ..Default::default()
    });
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("terrain ground group"),
        layout,
        entries: &[
            [
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: colors.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&view),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::Sampler(sampler),
                },
            ]
            .as_slice(),
            detail.entries().as_slice(),
        ]
        .concat(),
    })
}
