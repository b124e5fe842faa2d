//! The terrain renderer: node meshes suballocated from a few large vertex and index buffers
//! (pages), drawn as one multi-draw per page (each node mesh one indirect record whose first
//! instance is the node's slot in the node table), filled or as wireframe, coloured by the map's
//! ground-type legend.

use super::Gpu;
use super::batches::{Batches, Item};
use super::frame::{
    DrawStats, FrameResources, PipelineSpec, pipeline, srgb_to_linear, uniform_entry, uniform_group,
};
use super::gpu_data::MeshVertex;
use super::node_table::NodeTable;
use super::scene::{FrameDraws, NodeRenderer};
use super::suballoc::{Lease, Suballocator};
use crate::stream::{NodeWork, Shared};
use crate::terrain::mesh::NodeMesh;
use crate::terrain::quadtree::QuadTree;
use glam::DVec3;
use wgpu::util::{DeviceExt, DrawIndexedIndirectArgs};

/// Vertices and indices in one page of the mesh pool: 858 grid nodes (1,221 vertices and
/// 6,912 indices each), 28 + 24 MiB.
const PAGE_VERTICES: u32 = 1 << 20;
const PAGE_INDICES: u32 = 6 << 20;
/// Pages at most (far more than a cache budget keeps resident).
const MAX_PAGES: usize = 64;

/// Ground types the colour table holds (the map legend has at most this many).
pub const GROUND_TYPES: usize = 256;

/// The assembled shader source (generated constants + prelude + `terrain.wgsl`).
pub fn shader_source() -> String {
    super::shader::assemble(
        "terrain",
        &format!("const GROUND_TYPES: u32 = {GROUND_TYPES}u;"),
    )
}

/// One node's mesh on the GPU: its ranges in a page of the mesh pool and its node-table slot
/// (both given back when dropped).
pub struct TerrainNodeGpu {
    /// World position of the node's south-west corner (vertices are relative to it).
    pub origin_m: [f64; 2],
    /// World-space box of the mesh, skirts included.
    pub aabb_m: (DVec3, DVec3),
    /// Part 0: vertices, part 1: indices (relative to the node's first vertex).
    mesh: Lease,
    slot: Lease,
    pub bytes: usize,
}

impl std::fmt::Debug for TerrainNodeGpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "TerrainNodeGpu({} bytes)", self.bytes)
    }
}

impl TerrainNodeGpu {
    pub fn triangles(&self) -> u32 {
        self.mesh.len[1] / 3
    }
}

/// One page of the mesh pool.
struct MeshPage {
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
}

/// A terrain batch: whether its nodes are in a cross-fade (drawn dithered, after the others),
/// and their mesh page.
type BatchKey = (bool, u32);

/// Terrain pipelines, the mesh pool, the node table and this frame's batches.
pub struct TerrainRenderer {
    /// Nodes in a cross-fade: the fragment shader discards the pixels outside their dither
    /// interval.
    fill: wgpu::RenderPipeline,
    /// Nodes not fading: the same pixels without the dither test, so the shader has no
    /// `discard` and hidden fragments fail the depth test before shading.
    solid: wgpu::RenderPipeline,
    wire: Option<wgpu::RenderPipeline>,
    colors: wgpu::BindGroup,
    pool: Suballocator,
    pages: Vec<MeshPage>,
    table: NodeTable,
    batches: Batches<BatchKey>,
    triangles: u64,
    culled: u32,
    /// This frame's batches are recorded as multi-draws (else as plain loops).
    merged: bool,
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
            label: Some("ground colours layout"),
            entries: &[uniform_entry(0, false, wgpu::ShaderStages::VERTEX)],
        });
        let layout = frame.pipeline_layout(
            device,
            "terrain pipeline layout",
            true,
            &[Some(&colors_layout)],
        );
        let buffers = [Some(MeshVertex::LAYOUT)];
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
        let buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("ground colours"),
            contents: bytemuck::cast_slice(&table),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let colors = uniform_group(device, "ground colours", &colors_layout, 0, &buffer);
        Self {
            fill,
            solid,
            wire,
            colors,
            pool: Suballocator::new(&[PAGE_VERTICES, PAGE_INDICES], MAX_PAGES),
            pages: Vec::new(),
            table: NodeTable::new(device, frame, "terrain node table", 1),
            batches: Batches::new(),
            triangles: 0,
            culled: 0,
            merged: false,
        }
    }

    /// The registered constructor: colours from the map's legend.
    pub fn create(gpu: &Gpu, frame: &FrameResources, shared: &Shared) -> Box<dyn NodeRenderer> {
        let legend: Vec<[u8; 3]> = shared
            .world
            .map
            .manifest
            .ground
            .legend
            .iter()
            .map(|g| g.color)
            .collect();
        Box::new(Self::new(gpu, frame, &legend))
    }

    /// Uploads one node mesh (vertices relative to its south-west corner, z absolute) into the
    /// mesh pool. None when the pool or the node table is full (the node is then not drawn).
    pub fn upload_mesh(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        tree: &QuadTree,
        mesh: &NodeMesh,
    ) -> Option<TerrainNodeGpu> {
        let vertices: Vec<MeshVertex> = mesh
            .positions
            .iter()
            .zip(&mesh.normals)
            .zip(&mesh.ground)
            .map(|((p, n), g)| MeshVertex {
                position: *p,
                normal: *n,
                tag: u32::from(*g),
            })
            .collect();
        let lengths = [vertices.len() as u32, mesh.indices.len() as u32];
        let (Some(lease), Some(slot)) = (self.pool.lease(&lengths), self.table.lease()) else {
            log::warn!(
                "terrain mesh pool or node table full: node {:?} is not drawn",
                mesh.key
            );
            return None;
        };
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
            self.pages.push(MeshPage {
                vertices: buffer(
                    "vertices",
                    u64::from(PAGE_VERTICES) * std::mem::size_of::<MeshVertex>() as u64,
                    wgpu::BufferUsages::VERTEX,
                ),
                indices: buffer(
                    "indices",
                    u64::from(PAGE_INDICES) * 4,
                    wgpu::BufferUsages::INDEX,
                ),
            });
        }
        let page = &self.pages[lease.page as usize];
        let vertex_bytes = std::mem::size_of::<MeshVertex>() as u64;
        queue.write_buffer(
            &page.vertices,
            u64::from(lease.start[0]) * vertex_bytes,
            bytemuck::cast_slice(&vertices),
        );
        queue.write_buffer(
            &page.indices,
            u64::from(lease.start[1]) * 4,
            bytemuck::cast_slice(&mesh.indices),
        );
        Some(TerrainNodeGpu {
            origin_m: mesh.origin_m,
            aabb_m: mesh.aabb_m(tree),
            mesh: lease,
            slot,
            bytes: vertices.len() * std::mem::size_of::<MeshVertex>() + mesh.indices.len() * 4,
        })
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
    ) -> usize {
        let Some(mesh) = work.get::<NodeMesh>() else {
            return 0;
        };
        let Some(node) = self.upload_mesh(&gpu.device, &gpu.queue, tree, mesh) else {
            return 0;
        };
        let bytes = node.bytes;
        work.gpu.put(node);
        bytes
    }

    fn prepare(&mut self, gpu: &Gpu, frame: &mut FrameResources, draws: &FrameDraws<'_>) {
        self.batches.clear();
        self.triangles = 0;
        self.merged = draws.view.multi_draw(gpu);
        let mut visible = 0;
        for d in draws.drawn {
            let Some(node) = d.work.gpu.get::<TerrainNodeGpu>() else {
                continue;
            };
            if d.dither[1] > d.dither[0]
                && draws.frustum.intersects_aabb(node.aabb_m.0, node.aabb_m.1)
            {
                let slot = self.table.first_entry(&node.slot);
                self.table
                    .set(frame, slot, node.origin_m, d.key.level, d.dither);
                let m = &node.mesh;
                let fading = d.dither[0] > 0.0 || d.dither[1] < 1.0;
                self.batches.push(
                    (fading, m.page),
                    Item::Indexed(DrawIndexedIndirectArgs {
                        index_count: m.len[1],
                        instance_count: 1,
                        first_index: m.start[1],
                        base_vertex: m.start[0] as i32,
                        first_instance: slot,
                    }),
                );
                self.triangles += u64::from(node.triangles());
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
        let wire = self.wire.as_ref().filter(|_| draws.view.wireframe);
        pass.set_bind_group(1, &self.table.group, &[]);
        pass.set_bind_group(2, &self.colors, &[]);
        let mut bound: Option<bool> = None;
        for run in self.batches.runs() {
            let (fading, page) = run.key;
            if bound != Some(fading) {
                pass.set_pipeline(match (wire, fading) {
                    (Some(w), _) => w,
                    (None, true) => &self.fill,
                    (None, false) => &self.solid,
                });
                bound = Some(fading);
            }
            let page = &self.pages[page as usize];
            pass.set_vertex_buffer(0, page.vertices.slice(..));
            pass.set_index_buffer(page.indices.slice(..), wgpu::IndexFormat::Uint32);
            stats.draw_calls += self.batches.record(pass, run, self.merged);
            stats.items += run.items();
        }
        stats.triangles += self.triangles;
    }
}
