//! The vegetation renderer: per node one range of instances in a page of the instance pool
//! (groups are sub-ranges of it), drawn as instanced plant meshes, billboards sampling the
//! species atlas, or group-billboard quads sampling the node's impostor layer. Each group of each
//! drawn node is one indirect record; one multi-draw per render state and page draws them all
//! (`batches`). An instance finds its node's entry in the node table (two per node: groups
//! replaced on split, groups kept) through its `entry`. Owns the two bakes: the species atlas (at
//! start-up, from the high-detail plant meshes) and each node's impostors (in its upload hook),
//! in `bakes`; a node's upload is in `upload`.

use super::Gpu;
use super::batches::{Batches, Item};
use super::frame::{
    DrawStats, FrameResources, PipelineSpec, pipeline, sampler_entry, srgb_to_linear,
    texture_entry, uniform_entry, uniform_group,
};
use super::gpu_data::MeshVertex;
use super::impostors::ImpostorPages;
use super::light_pool::LightEntry;
use super::node_table::NodeTable;
use super::paged_buffer::PagedBuffer;
use super::scene::{FrameDraws, NodeRenderer, UploadEncoder, close_staging, staging_belt};
use super::suballoc::Lease;
use crate::stream::{NodeWork, Shared};
use crate::terrain::quadtree::QuadTree;
use crate::vegetation::NodeVegetation;
use crate::vegetation::content::VegetationContent;
use crate::vegetation::plants::{self, PlantMeshes, Shape};
use crate::vegetation::representation::{
    CLUSTER_COUNT, CLUSTERS_PER_SIDE, GroupDither, group_dither,
};
use bakes::PendingBakes;
use bytemuck::{Pod, Zeroable};
use glam::DVec3;
use std::time::Instant;
use wgpu::util::{DeviceExt, DrawIndexedIndirectArgs, DrawIndirectArgs};

mod bakes;
mod upload;

/// Staging chunks made with the renderer for the instance uploads (a node's instances are a
/// few KB to a few tens of KB; see [`staging_belt`]).
const INSTANCE_STAGING_PREMADE_CHUNKS: usize = 4;

/// Instances in one page of the instance pool (32 MiB) and pages at most.
const PAGE_INSTANCES: u32 = 1 << 20;
const MAX_INSTANCE_PAGES: usize = 16;
/// Frame-thread time one impostor bake is expected to take (recording its pass) before the first
/// bakes were timed.
const BAKE_RECORD_PRIOR_S: f64 = 0.1e-3;

/// Species looks (shape and colour) the renderer holds; the atlas has one tile per look.
pub const MAX_LOOKS: u32 = 16;
/// Billboard atlas: one tile per look, linear colour + coverage.
const ATLAS_TILE_PX: [u32; 2] = [64, 128];
const ATLAS_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
/// The billboard atlas's normals (n / 2 + 1/2, alpha = coverage).
const NORMAL_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
/// Group billboards: the tile size of a cluster in a node's impostor texture.
const IMPOSTOR_TILE_PX: u32 = 32;
const IMPOSTOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

/// The WGSL constants of `vegetation.wgsl`, from the Rust definitions.
fn wgsl_constants() -> String {
    format!(
        "const MAX_LOOKS: u32 = {MAX_LOOKS}u;\nconst ATLAS_TILES: u32 = {MAX_LOOKS}u;\n\
         const CLUSTERS_PER_SIDE: u32 = {CLUSTERS_PER_SIDE}u;\nconst CLUSTER_COUNT: u32 = {CLUSTER_COUNT}u;"
    )
}

/// The assembled shader source (generated constants + prelude + `vegetation.wgsl`).
pub fn shader_source() -> String {
    super::shader::assemble("vegetation", &wgsl_constants())
}

/// Mirrors `PlantInstanceIn` in `vegetation.wgsl` (32 bytes, one per item or cluster quad).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct PlantInstance {
    /// x, y relative to the node's south-west corner; z absolute ground height (m).
    pub position: [f32; 3],
    pub height_m: f32,
    pub radius_m: f32,
    pub yaw_rad: f32,
    /// Index into the plant looks (species); for a cluster quad, its impostor layer *
    /// `CLUSTER_COUNT` + the cluster's tile.
    pub look: u32,
    /// Drawn instances: the node-table entry (2 x node slot, + 1 in groups kept through
    /// splits); group members in the impostor bake: their cluster.
    pub entry: u32,
}

const _: () = assert!(
    std::mem::size_of::<PlantInstance>() == crate::vegetation::representation::INSTANCE_BYTES
);

impl PlantInstance {
    /// Per-instance attributes at locations 3..=8.
    const ATTRIBUTES: [wgpu::VertexAttribute; 6] = wgpu::vertex_attr_array![
        3 => Float32x3, 4 => Float32, 5 => Float32, 6 => Float32, 7 => Uint32, 8 => Uint32
    ];

    pub(super) const LAYOUT: wgpu::VertexBufferLayout<'static> = wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<Self>() as u64,
        step_mode: wgpu::VertexStepMode::Instance,
        attributes: &Self::ATTRIBUTES,
    };
}

/// Mirrors `Cluster` in `vegetation.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct ClusterUniform {
    centre_bottom_half: [f32; 4],
    height: [f32; 4],
}

/// How a group is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PlantDraw {
    Mesh,
    Billboard,
    /// Cluster quads sampling the node's impostor texture.
    Impostor,
}

/// One instance group of a node on the GPU.
#[derive(Debug, Clone, Copy)]
struct PlantGroupGpu {
    first: u32,
    count: u32,
    shape: Shape,
    kind: PlantDraw,
    /// Drawn the same way at every finer level: drawn through the node's splits.
    kept: bool,
}

/// A node's vegetation on the GPU: its instance range, node-table slot and impostor layer (all
/// given back when dropped) and its groups.
pub struct PlantsGpu {
    origin_m: [f64; 2],
    instances: Lease,
    slot: Lease,
    /// The node's group-billboard layer (8 x 8 cluster tiles), when it has group members.
    impostors: Option<Lease>,
    /// Ranges relative to the node's first instance.
    groups: Vec<PlantGroupGpu>,
    /// World-space box of the items (ground to tree tops).
    pub aabb_m: (DVec3, DVec3),
    pub bytes: usize,
    low_detail: bool,
}

impl std::fmt::Debug for PlantsGpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "PlantsGpu({} groups, {} bytes)",
            self.groups.len(),
            self.bytes
        )
    }
}

/// What a run of the frame's draws shares: pipeline, shape, instance page, impostor page.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum BatchKey {
    Mesh {
        shape: usize,
        low_detail: bool,
        page: u32,
    },
    Billboard {
        page: u32,
    },
    Impostor {
        page: u32,
        layers: u32,
    },
}

/// Vegetation pipelines, the shared plant shapes, the species atlas, this frame's plan.
pub struct VegetationRenderer {
    plant_mesh: wgpu::RenderPipeline,
    billboard: wgpu::RenderPipeline,
    impostor: wgpu::RenderPipeline,
    group_bake: wgpu::RenderPipeline,
    shape_vertices: wgpu::Buffer,
    shape_indices: wgpu::Buffer,
    meshes: PlantMeshes,
    /// Shape per look index (species).
    shapes: Vec<Shape>,
    /// Atlas, sampler and looks (plant meshes and billboards).
    atlas_group: wgpu::BindGroup,
    /// The atlas as a plain texture + sampler (sampled by the impostor bake).
    atlas_texture_group: wgpu::BindGroup,
    /// The frame resources' group 0 (bound by the impostor bakes, recorded where the frame
    /// resources are not at hand).
    frame_group: wgpu::BindGroup,
    cluster_layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    /// Plant instances: one range per node, in pages of [`PAGE_INSTANCES`].
    instances: PagedBuffer,
    impostors: ImpostorPages,
    table: NodeTable,
    batches: Batches<BatchKey>,
    /// This frame's counts (set by `prepare`).
    frame_stats: DrawStats,
    merged: bool,
    bakes: PendingBakes,
    /// The instances' staging memory (copied out of by commands in the upload encoder).
    staging: wgpu::util::StagingBelt,
}

impl std::fmt::Debug for VegetationRenderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "VegetationRenderer({} looks)", self.shapes.len())
    }
}

/// The atlas's bind group: albedo (binding 0), sampler (1), normals (5), and the looks (2)
/// where `looks` is given.
fn texture_group(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    [albedo, normals]: [&wgpu::TextureView; 2],
    sampler: &wgpu::Sampler,
    looks: Option<&wgpu::Buffer>,
) -> wgpu::BindGroup {
    let mut entries = vec![
        wgpu::BindGroupEntry {
            binding: 0,
            resource: wgpu::BindingResource::TextureView(albedo),
        },
        wgpu::BindGroupEntry {
            binding: 1,
            resource: wgpu::BindingResource::Sampler(sampler),
        },
        wgpu::BindGroupEntry {
            binding: 5,
            resource: wgpu::BindingResource::TextureView(normals),
        },
    ];
    if let Some(b) = looks {
        entries.push(wgpu::BindGroupEntry {
            binding: 2,
            resource: b.as_entire_binding(),
        });
    }
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout,
        entries: &entries,
    })
}

/// A triangle-list pipeline of `module`: `names` label, vertex and fragment entry points, into
/// `format` and, for a bake, its normals target `second`.
fn triangles_pipeline(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    layout: &wgpu::PipelineLayout,
    (names, buffers): ([&str; 3], &[Option<wgpu::VertexBufferLayout<'_>>]),
    (format, second): (wgpu::TextureFormat, Option<wgpu::TextureFormat>),
) -> wgpu::RenderPipeline {
    let [label, vs, fs] = names;
    pipeline(
        device,
        module,
        layout,
        &PipelineSpec {
            second_format: second,
            ..PipelineSpec::triangles(label, vs, fs, buffers, format)
        },
    )
}

/// A texture that a bake renders into and renderers then sample.
fn bake_target(
    device: &wgpu::Device,
    label: &str,
    size: [u32; 2],
    format: wgpu::TextureFormat,
) -> wgpu::TextureView {
    let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
    super::texture_view_2d(device, label, size, format, usage)
}

/// The shared plant-shape vertex and index buffers.
fn shape_buffers(device: &wgpu::Device, meshes: &PlantMeshes) -> (wgpu::Buffer, wgpu::Buffer) {
    let vertices: Vec<MeshVertex> = meshes
        .vertices
        .iter()
        .map(|v| MeshVertex {
            position: v.position,
            normal: v.normal,
            tag: v.part,
        })
        .collect();
    let vb = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("plant shape vertices"),
        contents: bytemuck::cast_slice(&vertices),
        usage: wgpu::BufferUsages::VERTEX,
    });
    let ib = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("plant shape indices"),
        contents: bytemuck::cast_slice(&meshes.indices),
        usage: wgpu::BufferUsages::INDEX,
    });
    (vb, ib)
}

/// Per look (species): rgb linear colour and w shape, and the shapes.
fn looks(species_names: &[String]) -> ([[f32; 4]; MAX_LOOKS as usize], Vec<Shape>) {
    let mut looks = [[0.3f32, 0.45, 0.2, 2.0]; MAX_LOOKS as usize];
    let mut shapes = Vec::new();
    for (i, name) in species_names.iter().take(MAX_LOOKS as usize).enumerate() {
        let (shape, c) = plants::look(name);
        looks[i] = [
            srgb_to_linear(c[0]),
            srgb_to_linear(c[1]),
            srgb_to_linear(c[2]),
            shape as u32 as f32,
        ];
        shapes.push(shape);
    }
    (looks, shapes)
}

/// The pages of plant instances (a node leases one range).
fn instance_pages() -> PagedBuffer {
    PagedBuffer::new(
        "plant instances",
        // Copied from by the GPU reference (`render::reference`).
        wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_SRC,
        std::mem::size_of::<PlantInstance>() as u64,
        PAGE_INSTANCES,
        MAX_INSTANCE_PAGES,
    )
}

impl VegetationRenderer {
    /// Pipelines, plant shapes and the species atlas, baked for `species_names` (look index =
    /// species index, at most [`MAX_LOOKS`]).
    pub fn new(gpu: &Gpu, frame: &FrameResources, species_names: &[String]) -> Self {
        let device = &gpu.device;
        let module = super::shader::module(device, "vegetation", &shader_source());
        let layout = |label: &str, entries: &[wgpu::BindGroupLayoutEntry]| {
            device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some(label),
                entries,
            })
        };
        let looks_entry = uniform_entry(2, false, wgpu::ShaderStages::VERTEX);
        let atlas = [
            texture_entry(0, wgpu::TextureViewDimension::D2),
            sampler_entry(1),
            texture_entry(5, wgpu::TextureViewDimension::D2),
        ];
        let atlas_layout = layout(
            "vegetation atlas + looks layout",
            &[atlas[0], atlas[1], atlas[2], looks_entry],
        );
        let texture_layout = layout("vegetation texture layout", &atlas);
        let looks_layout = layout("vegetation looks layout", &[looks_entry]);
        let cluster_entry = uniform_entry(1, true, wgpu::ShaderStages::VERTEX);
        let cluster_layout = layout("impostor cluster layout", &[cluster_entry]);
        let drawn_layout =
            frame.pipeline_layout(device, "vegetation layout", true, &[Some(&atlas_layout)]);
        let impostors = ImpostorPages::new(
            device,
            CLUSTERS_PER_SIDE * IMPOSTOR_TILE_PX,
            IMPOSTOR_FORMAT,
        );
        let impostor_layout = frame.pipeline_layout(
            device,
            "group billboard layout",
            true,
            &[Some(&impostors.layout)],
        );
        let bake_layout = frame.pipeline_layout(
            device,
            "billboard bake layout",
            false,
            &[Some(&looks_layout)],
        );
        let group_bake_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("impostor bake layout"),
            bind_group_layouts: &[
                Some(&frame.layout),
                Some(&cluster_layout),
                Some(&texture_layout),
            ],
            immediate_size: 0,
        });
        let format = (frame.color_format, None);
        let make = |layout: &wgpu::PipelineLayout,
                    names: [&str; 3],
                    buffers: &[Option<wgpu::VertexBufferLayout<'_>>],
                    formats| {
            triangles_pipeline(device, &module, layout, (names, buffers), formats)
        };
        let mesh_buffers = [Some(MeshVertex::LAYOUT), Some(PlantInstance::LAYOUT)];
        let quads = [Some(PlantInstance::LAYOUT)];
        let plant_mesh = make(
            &drawn_layout,
            ["plant meshes", "vs_plant", "fs_plant"],
            &mesh_buffers,
            format,
        );
        let billboard = make(
            &drawn_layout,
            ["plant billboards", "vs_billboard", "fs_billboard"],
            &quads,
            format,
        );
        let impostor = make(
            &impostor_layout,
            ["plant group billboards", "vs_billboard", "fs_impostor"],
            &quads,
            format,
        );
        let bake = make(
            &bake_layout,
            ["billboard bake", "vs_bake", "fs_bake"],
            &mesh_buffers,
            (ATLAS_FORMAT, Some(NORMAL_FORMAT)),
        );
        let group_bake = make(
            &group_bake_layout,
            ["impostor bake", "vs_group_bake", "fs_group_bake"],
            &quads,
            (IMPOSTOR_FORMAT, Some(IMPOSTOR_FORMAT)),
        );
        let meshes = PlantMeshes::generate();
        let (shape_vertices, shape_indices) = shape_buffers(device, &meshes);
        let (looks, shapes) = looks(species_names);
        let looks_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("plant looks"),
            contents: bytemuck::cast_slice(&looks),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let atlas_size = [ATLAS_TILE_PX[0] * MAX_LOOKS, ATLAS_TILE_PX[1]];
        let atlas_views = [
            bake_target(device, "billboard atlas", atlas_size, ATLAS_FORMAT),
            bake_target(device, "billboard normals", atlas_size, NORMAL_FORMAT),
        ];
        let atlas_pair = [&atlas_views[0], &atlas_views[1]];
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("vegetation sampler"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        let looks_group = uniform_group(device, "plant looks", &looks_layout, 2, &looks_buffer);
        let renderer = Self {
            plant_mesh,
            billboard,
            impostor,
            group_bake,
            shape_vertices,
            shape_indices,
            meshes,
            shapes,
            atlas_group: texture_group(
                device,
                "billboard atlas",
                &atlas_layout,
                atlas_pair,
                &sampler,
                Some(&looks_buffer),
            ),
            frame_group: frame.group.clone(),
            atlas_texture_group: texture_group(
                device,
                "billboard atlas texture",
                &texture_layout,
                atlas_pair,
                &sampler,
                None,
            ),
            cluster_layout,
            sampler,
            instances: instance_pages(),
            impostors,
            table: NodeTable::by_slot(device, frame, "vegetation node table", 2),
            batches: Batches::new(),
            frame_stats: DrawStats::default(),
            merged: false,
            bakes: PendingBakes::new(),
            staging: staging_belt(device, INSTANCE_STAGING_PREMADE_CHUNKS),
        };
        renderer.bake_atlas(gpu, frame, &bake, &looks_group, atlas_pair, atlas_size);
        renderer
    }

    /// The registered constructor: looks from the vegetation kind's species.
    pub fn create(gpu: &Gpu, frame: &FrameResources, shared: &Shared) -> Box<dyn NodeRenderer> {
        let names: Vec<String> = shared
            .kind::<VegetationContent>()
            .map(|v| v.placer.species.iter().map(|s| s.name.clone()).collect())
            .unwrap_or_default();
        Box::new(Self::new(gpu, frame, &names))
    }

    /// Adds the draws of node `p` (at `level`, dither interval `dither`) whose groups' dither
    /// rule wants `wanted` (`drawn`: the node is drawn; `is_ancestor`: it is an ancestor of drawn
    /// nodes), and sets the node-table entries they read.
    #[allow(clippy::too_many_arguments, reason = "one node's draw context")]
    fn plan_node(
        &mut self,
        frame: &FrameResources,
        p: &PlantsGpu,
        (level, light): (u8, LightEntry),
        dither: [f32; 2],
        drawn: bool,
        is_ancestor: bool,
        wanted: GroupDither,
    ) {
        let first_entry = self.table.first_entry(&p.slot);
        let base = p.instances.start[0];
        let page = p.instances.page;
        let interval = match wanted {
            GroupDither::Own => dither,
            GroupDither::Full => [0.0, 1.0],
        };
        // The node's two entries (groups replaced on split, kept groups), each set once.
        let mut entry_set = [false; 2];
        for g in &p.groups {
            if group_dither(!g.kept, drawn, is_ancestor) != Some(wanted) {
                continue;
            }
            if !std::mem::replace(&mut entry_set[usize::from(g.kept)], true) {
                let entry = first_entry + u32::from(g.kept);
                let row = NodeTable::row(frame, p.origin_m, level, interval, [0.0; 4], light);
                self.table.set(entry, row);
            }
            let first_instance = base + g.first;
            let quads = |key| {
                (
                    key,
                    Item::Plain(DrawIndirectArgs {
                        vertex_count: 6,
                        instance_count: g.count,
                        first_vertex: 0,
                        first_instance,
                    }),
                )
            };
            let (key, item) = match g.kind {
                PlantDraw::Billboard => quads(BatchKey::Billboard { page }),
                PlantDraw::Impostor => {
                    let Some(layer) = &p.impostors else { continue };
                    self.frame_stats.group_billboards += u64::from(g.count);
                    quads(BatchKey::Impostor {
                        page,
                        layers: layer.page,
                    })
                }
                PlantDraw::Mesh => {
                    let shape = g.shape as usize;
                    let (first, count, base_vertex) =
                        self.meshes.ranges[shape][usize::from(p.low_detail)];
                    self.frame_stats.plant_triangles += u64::from(count / 3) * u64::from(g.count);
                    (
                        BatchKey::Mesh {
                            shape,
                            low_detail: p.low_detail,
                            page,
                        },
                        Item::Indexed(DrawIndexedIndirectArgs {
                            index_count: count,
                            instance_count: g.count,
                            first_index: first,
                            base_vertex,
                            first_instance,
                        }),
                    )
                }
            };
            self.frame_stats.plant_instances += u64::from(g.count);
            self.batches.push(key, item);
        }
    }
}

/// One drawn group's instances in this frame (for the GPU reference): `count` instances from
/// `first` in instance page `page`, each drawn as the plant-shape triangles `mesh` (first
/// index, index count, base vertex) or, when None, as one camera-facing quad.
#[derive(Debug, Clone, Copy)]
pub struct InstanceRun {
    pub page: u32,
    pub first: u32,
    pub count: u32,
    pub mesh: Option<(u32, u32, i32)>,
}

impl VegetationRenderer {
    /// What `prepare` chose to draw this frame, one entry per drawn group.
    pub fn frame_instances(&self) -> impl Iterator<Item = InstanceRun> + '_ {
        self.batches.items().iter().map(|&(key, item)| {
            let page = match key {
                BatchKey::Mesh { page, .. }
                | BatchKey::Billboard { page }
                | BatchKey::Impostor { page, .. } => page,
            };
            match item {
                Item::Indexed(a) => InstanceRun {
                    page,
                    first: a.first_instance,
                    count: a.instance_count,
                    mesh: Some((a.first_index, a.index_count, a.base_vertex)),
                },
                Item::Plain(a) => InstanceRun {
                    page,
                    first: a.first_instance,
                    count: a.instance_count,
                    mesh: None,
                },
            }
        })
    }

    /// The instance pages [`InstanceRun::page`] indexes.
    pub fn instance_pages(&self) -> &[wgpu::Buffer] {
        self.instances.pages()
    }

    /// The plant shapes' vertex and index buffers ([`InstanceRun::mesh`] ranges).
    pub fn shape_buffers(&self) -> (&wgpu::Buffer, &wgpu::Buffer) {
        (&self.shape_vertices, &self.shape_indices)
    }

    /// The node table the instances' entries index (group 1 of the frame layout).
    pub fn node_table(&self) -> &wgpu::BindGroup {
        &self.table.group
    }
}

impl NodeRenderer for VegetationRenderer {
    fn name(&self) -> &'static str {
        "vegetation"
    }

    fn upload(
        &mut self,
        gpu: &Gpu,
        _frame: &FrameResources,
        tree: &QuadTree,
        work: &mut NodeWork,
        copies: &mut UploadEncoder<'_>,
    ) -> usize {
        let Some(node) = work
            .get::<NodeVegetation>()
            .and_then(|v| self.upload_node(gpu, tree, work.key, v, copies))
        else {
            return 0;
        };
        if node.impostors.is_some() {
            // Its bake's recording (deferred), counted in this frame's budget.
            let charge_s = self.bakes.record.per_item_s();
            work.gpu_estimate_s += charge_s;
            self.bakes.charged_s += charge_s;
        }
        let bytes = node.bytes;
        work.gpu.put(node);
        bytes
    }

    fn close_uploads(&mut self) {
        close_staging(&mut self.staging);
    }

    /// Records the impostor bakes asked for since the last call into `deferred`; gives back what
    /// their uploads charged the budget, since the caller counts this call's measured time
    /// instead.
    fn finish_uploads(
        &mut self,
        gpu: &Gpu,
        deferred: &mut UploadEncoder<'_>,
        _time_left_s: f64,
    ) -> f64 {
        let t0 = Instant::now();
        let baked = self.bakes.asked.len();
        self.record_bakes(gpu, deferred);
        let b = &mut self.bakes;
        b.record.observe(t0.elapsed().as_secs_f64(), baked);
        -std::mem::take(&mut b.charged_s)
    }

    fn prepare(&mut self, gpu: &Gpu, frame: &mut FrameResources, draws: &FrameDraws<'_>) {
        self.batches.clear();
        self.frame_stats = DrawStats::default();
        self.merged = draws.view.multi_draw(gpu);
        if draws.view.plants {
            let visible = |p: &PlantsGpu| draws.frustum.intersects_aabb(p.aabb_m.0, p.aabb_m.1);
            // Drawn nodes with their own interval, then ancestors' kept groups in full.
            for (i, d) in draws.drawn.iter().enumerate() {
                if let Some(p) = d.work.gpu.get::<PlantsGpu>()
                    && d.dither[1] > d.dither[0]
                    && visible(p)
                {
                    let is_ancestor = draws
                        .ancestors
                        .binary_search_by_key(&d.key, |a| a.key)
                        .is_ok();
                    let node = (d.key.level, frame.light.drawn_entry(i, d.key));
                    self.plan_node(
                        frame,
                        p,
                        node,
                        d.dither,
                        true,
                        is_ancestor,
                        GroupDither::Own,
                    );
                }
            }
            for (i, a) in draws.ancestors.iter().enumerate() {
                if let Some(p) = a.work.gpu.get::<PlantsGpu>()
                    && p.groups.iter().any(|g| g.kept)
                    && visible(p)
                {
                    let node = (a.key.level, frame.light.ancestor_entry(i, a.key));
                    self.plan_node(frame, p, node, [0.0, 1.0], false, true, GroupDither::Full);
                }
            }
        }
        self.table.flush(&gpu.queue);
        self.batches.upload(gpu);
    }

    fn draw(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        _frame: &FrameResources,
        _draws: &FrameDraws<'_>,
        stats: &mut DrawStats,
    ) {
        let fs = &self.frame_stats;
        stats.plant_instances += fs.plant_instances;
        stats.plant_triangles += fs.plant_triangles;
        stats.group_billboards += fs.group_billboards;
        if self.batches.runs().is_empty() {
            return;
        }
        pass.set_bind_group(1, &self.table.group, &[]);
        for run in self.batches.runs() {
            match run.key {
                BatchKey::Billboard { page } => {
                    pass.set_pipeline(&self.billboard);
                    pass.set_bind_group(2, &self.atlas_group, &[]);
                    pass.set_vertex_buffer(0, self.instances.pages()[page as usize].slice(..));
                }
                BatchKey::Impostor { page, layers } => {
                    pass.set_pipeline(&self.impostor);
                    pass.set_bind_group(2, self.impostors.group(layers), &[]);
                    pass.set_vertex_buffer(0, self.instances.pages()[page as usize].slice(..));
                }
                BatchKey::Mesh { page, .. } => {
                    pass.set_pipeline(&self.plant_mesh);
                    pass.set_bind_group(2, &self.atlas_group, &[]);
                    pass.set_vertex_buffer(0, self.shape_vertices.slice(..));
                    pass.set_vertex_buffer(1, self.instances.pages()[page as usize].slice(..));
                    pass.set_index_buffer(self.shape_indices.slice(..), wgpu::IndexFormat::Uint32);
                }
            }
            stats.plant_draw_calls += self.batches.record(pass, run, self.merged);
            stats.plant_items += run.items();
        }
    }
}
