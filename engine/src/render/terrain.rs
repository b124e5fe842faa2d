//! The terrain renderer: node meshes (one vertex and index buffer per node), filled or as
//! wireframe, coloured by the map's ground-type legend.

use super::Gpu;
use super::frame::{
    DrawStats, FrameResources, PipelineSpec, pipeline, srgb_to_linear, uniform_entry, uniform_group,
};
use super::gpu_data::MeshVertex;
use super::scene::{FrameDraws, NodeRenderer};
use crate::stream::{NodeWork, Shared};
use crate::terrain::mesh::NodeMesh;
use crate::terrain::quadtree::QuadTree;
use glam::DVec3;
use wgpu::util::DeviceExt;

/// Ground types the colour table holds (the map legend has at most this many).
pub const GROUND_TYPES: usize = 256;

/// The assembled shader source (generated constants + prelude + `terrain.wgsl`).
pub fn shader_source() -> String {
    super::shader::assemble(
        "terrain",
        &format!("const GROUND_TYPES: u32 = {GROUND_TYPES}u;"),
    )
}

/// One node's mesh on the GPU.
pub struct TerrainNodeGpu {
    /// World position of the node's south-west corner (vertices are relative to it).
    pub origin_m: [f64; 2],
    /// World-space box of the mesh, skirts included.
    pub aabb_m: (DVec3, DVec3),
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    index_count: u32,
    pub bytes: usize,
}

impl std::fmt::Debug for TerrainNodeGpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "TerrainNodeGpu({} bytes)", self.bytes)
    }
}

impl TerrainNodeGpu {
    pub fn triangles(&self) -> u32 {
        self.index_count / 3
    }
}

/// Terrain pipelines and this frame's visible nodes.
pub struct TerrainRenderer {
    fill: wgpu::RenderPipeline,
    wire: Option<wgpu::RenderPipeline>,
    colors: wgpu::BindGroup,
    /// This frame: (index into the drawn nodes, node-uniform offset).
    visible: Vec<(usize, u32)>,
    culled: u32,
}

impl std::fmt::Debug for TerrainRenderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "TerrainRenderer({} visible)", self.visible.len())
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
            wire,
            colors,
            visible: Vec::new(),
            culled: 0,
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

    /// Uploads one node mesh (vertices relative to its south-west corner, z absolute).
    pub fn upload_mesh(device: &wgpu::Device, tree: &QuadTree, mesh: &NodeMesh) -> TerrainNodeGpu {
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
        let label = format!("node {}/{}/{}", mesh.key.level, mesh.key.ix, mesh.key.iy);
        let vb = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(&format!("{label} vertices")),
            contents: bytemuck::cast_slice(&vertices),
            usage: wgpu::BufferUsages::VERTEX,
        });
        let ib = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(&format!("{label} indices")),
            contents: bytemuck::cast_slice(&mesh.indices),
            usage: wgpu::BufferUsages::INDEX,
        });
        TerrainNodeGpu {
            origin_m: mesh.origin_m,
            aabb_m: mesh.aabb_m(tree),
            vertices: vb,
            indices: ib,
            index_count: mesh.indices.len() as u32,
            bytes: vertices.len() * std::mem::size_of::<MeshVertex>() + mesh.indices.len() * 4,
        }
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
        let node = Self::upload_mesh(&gpu.device, tree, mesh);
        let bytes = node.bytes;
        work.gpu.put(node);
        bytes
    }

    fn prepare(&mut self, _gpu: &Gpu, frame: &mut FrameResources, draws: &FrameDraws<'_>) {
        self.visible.clear();
        for (i, d) in draws.drawn.iter().enumerate() {
            let Some(node) = d.work.gpu.get::<TerrainNodeGpu>() else {
                continue;
            };
            if d.dither[1] > d.dither[0]
                && draws.frustum.intersects_aabb(node.aabb_m.0, node.aabb_m.1)
            {
                self.visible
                    .push((i, frame.push_node(node.origin_m, d.key.level, d.dither)));
            }
        }
        self.culled = (draws.drawn.len() - self.visible.len()) as u32;
    }

    fn draw(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        frame: &FrameResources,
        draws: &FrameDraws<'_>,
        stats: &mut DrawStats,
    ) {
        stats.culled += self.culled;
        let pipeline = match (&self.wire, draws.view.wireframe) {
            (Some(w), true) => w,
            _ => &self.fill,
        };
        pass.set_pipeline(pipeline);
        pass.set_bind_group(2, &self.colors, &[]);
        for &(i, offset) in &self.visible {
            let Some(node) = draws.drawn[i].work.gpu.get::<TerrainNodeGpu>() else {
                continue;
            };
            frame.bind_node(pass, offset);
            pass.set_vertex_buffer(0, node.vertices.slice(..));
            pass.set_index_buffer(node.indices.slice(..), wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..node.index_count, 0, 0..1);
            stats.draw_calls += 1;
            stats.triangles += u64::from(node.triangles());
        }
    }
}
