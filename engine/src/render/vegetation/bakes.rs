//! The vegetation renderer's two bakes: every look's billboard image (the species atlas, at
//! start-up, from the high-detail plant meshes) and a node's group-billboard members baked into
//! its impostor layer (asked for by the nodes' uploads and recorded together when the uploads
//! finish).

use super::{
    ATLAS_TILE_PX, BAKE_RECORD_PRIOR_S, ClusterUniform, MAX_LOOKS, PlantInstance,
    VegetationRenderer,
};
use crate::render::batch_timer::ItemCost;
use crate::render::frame::{FrameResources, bake_pass};
use crate::render::scene::UploadEncoder;
use crate::render::{Gpu, depth_view};
use crate::terrain::quadtree::NodeKey;
use crate::vegetation::representation::CLUSTER_COUNT;
use wgpu::util::DeviceExt;

/// Impostor bakes asked for by this frame's uploads, recorded together when the uploads finish
/// (into the scene's one submission of deferred work, not one per node). Every bake's clusters
/// and members go into two buffers shared by all of them, written once per submission: a bake
/// costs its pass, not two new buffers and a bind group.
pub(super) struct PendingBakes {
    pub(super) asked: Vec<BakeAsk>,
    /// One block of [`CLUSTER_COUNT`] clusters per bake, and every bake's members, in order.
    clusters: Vec<ClusterUniform>,
    members: Vec<PlantInstance>,
    /// The shared buffers (grown to the largest submission so far), with the clusters' bind
    /// group (a dynamic offset picks a bake's block).
    buffers: Option<BakeBuffers>,
    /// The frame thread's time per bake when they are recorded: each upload that bakes charges
    /// it to the frame's budget beforehand.
    pub(super) record: ItemCost,
    /// What the uploads of the bakes asked for since they were last recorded charged the
    /// budget.
    pub(super) charged_s: f64,
    /// The most bakes recorded together (one submission) so far.
    most_together: usize,
}

/// One asked-for bake: the node (for the pass's label), its layer's two views, its members.
pub(super) struct BakeAsk {
    key: NodeKey,
    views: [wgpu::TextureView; 2],
    members: std::ops::Range<u32>,
}

struct BakeBuffers {
    clusters: wgpu::Buffer,
    members: wgpu::Buffer,
    group: wgpu::BindGroup,
}

/// Bytes of one bake's cluster block (a multiple of every adapter's uniform offset alignment,
/// 256 at most).
const CLUSTER_BLOCK_BYTES: u64 = (CLUSTER_COUNT * std::mem::size_of::<ClusterUniform>()) as u64;
const _: () = assert!(CLUSTER_BLOCK_BYTES.is_multiple_of(256));

impl PendingBakes {
    pub(super) fn new() -> Self {
        Self {
            asked: Vec::new(),
            clusters: Vec::new(),
            members: Vec::new(),
            buffers: None,
            record: ItemCost::new(BAKE_RECORD_PRIOR_S),
            charged_s: 0.0,
            most_together: 0,
        }
    }

    /// Grows the shared buffers (to a power of two) to hold what is asked for now.
    fn grow_buffers(&mut self, device: &wgpu::Device, layout: &wgpu::BindGroupLayout) {
        let need = [
            (self.clusters.len() * std::mem::size_of::<ClusterUniform>()) as u64,
            (self.members.len() * std::mem::size_of::<PlantInstance>()) as u64,
        ];
        let fits = self
            .buffers
            .as_ref()
            .is_some_and(|b| b.clusters.size() >= need[0] && b.members.size() >= need[1].max(1));
        if !fits {
            let have = self
                .buffers
                .as_ref()
                .map_or([0, 0], |b| [b.clusters.size(), b.members.size()]);
            let size = |i: usize| {
                need[i]
                    .max(have[i])
                    .max(CLUSTER_BLOCK_BYTES)
                    .next_power_of_two()
            };
            let buffer = |label, size, usage| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size,
                    usage: usage | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            };
            let clusters = buffer("impostor clusters", size(0), wgpu::BufferUsages::UNIFORM);
            let members = buffer("impostor members", size(1), wgpu::BufferUsages::VERTEX);
            let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("impostor clusters"),
                layout,
                entries: &[wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &clusters,
                        offset: 0,
                        size: wgpu::BufferSize::new(CLUSTER_BLOCK_BYTES),
                    }),
                }],
            });
            self.buffers = Some(BakeBuffers {
                clusters,
                members,
                group,
            });
        }
    }
}

impl VegetationRenderer {
    /// Renders a node's group members into its impostor layer's albedo and normal views
    /// `layer_views` (one tile per cluster, seen from the south).
    pub(super) fn bake_impostors(
        &mut self,
        key: NodeKey,
        clusters: &[ClusterUniform; CLUSTER_COUNT],
        members: &[PlantInstance],
        layer_views: [wgpu::TextureView; 2],
    ) {
        let b = &mut self.bakes;
        let first = b.members.len() as u32;
        b.members.extend_from_slice(members);
        b.clusters.extend_from_slice(clusters);
        b.asked.push(BakeAsk {
            key,
            views: layer_views,
            members: first..b.members.len() as u32,
        });
    }

    /// The most impostor bakes one submission held so far (they share its cluster and
    /// member buffers).
    pub fn most_bakes_submitted_together(&self) -> usize {
        self.bakes.most_together
    }

    /// Records into `deferred` the bakes asked for since the last call (see [`PendingBakes`]).
    pub(super) fn record_bakes(&mut self, gpu: &Gpu, deferred: &mut UploadEncoder<'_>) {
        if self.bakes.asked.is_empty() {
            return;
        }
        let device = &gpu.device;
        let b = &mut self.bakes;
        b.grow_buffers(device, &self.cluster_layout);
        let Some(buffers) = &b.buffers else { return };
        gpu.queue
            .write_buffer(&buffers.clusters, 0, bytemuck::cast_slice(&b.clusters));
        gpu.queue
            .write_buffer(&buffers.members, 0, bytemuck::cast_slice(&b.members));
        let enc = deferred.get(device);
        let member_bytes = std::mem::size_of::<PlantInstance>() as u64;
        for (i, ask) in b.asked.iter().enumerate() {
            let label = format!(
                "node {}/{}/{} impostors",
                ask.key.level, ask.key.ix, ask.key.iy
            );
            let targets = [&ask.views[0], &ask.views[1]];
            let mut pass = bake_pass(enc, &label, &targets, &self.impostors.bake_depth);
            pass.set_pipeline(&self.group_bake);
            pass.set_bind_group(0, &self.frame_group, &[]);
            let offset = i as u64 * CLUSTER_BLOCK_BYTES;
            pass.set_bind_group(1, &buffers.group, &[offset as u32]);
            pass.set_bind_group(2, &self.atlas_texture_group, &[]);
            let bytes = u64::from(ask.members.start) * member_bytes
                ..u64::from(ask.members.end) * member_bytes;
            pass.set_vertex_buffer(0, buffers.members.slice(bytes));
            pass.draw(0..6, 0..ask.members.len() as u32);
        }
        b.most_together = b.most_together.max(b.asked.len());
        b.asked.clear();
        b.clusters.clear();
        b.members.clear();
    }

    /// Renders every look's billboard image from its high-detail mesh into the atlas (seen
    /// from the south): albedo and normals, lit only when drawn.
    pub(super) fn bake_atlas(
        &self,
        gpu: &Gpu,
        frame: &FrameResources,
        bake: &wgpu::RenderPipeline,
        looks_group: &wgpu::BindGroup,
        atlas_views: [&wgpu::TextureView; 2],
        atlas_size: [u32; 2],
    ) {
        let device = &gpu.device;
        let instances: Vec<PlantInstance> = (0..MAX_LOOKS)
            .map(|i| PlantInstance {
                position: [0.0; 3],
                height_m: 1.0,
                radius_m: 1.0,
                yaw_rad: 0.0,
                look: i,
                entry: 0,
            })
            .collect();
        let instance_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("billboard bake instances"),
            contents: bytemuck::cast_slice(&instances),
            usage: wgpu::BufferUsages::VERTEX,
        });
        let depth_view = depth_view(device, atlas_size, "billboard bake depth");
        let mut enc = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("billboard bake"),
        });
        {
            let mut pass = bake_pass(&mut enc, "billboard bake pass", &atlas_views, &depth_view);
            pass.set_pipeline(bake);
            pass.set_bind_group(0, &frame.group, &[]);
            pass.set_bind_group(2, looks_group, &[]);
            pass.set_vertex_buffer(0, self.shape_vertices.slice(..));
            pass.set_vertex_buffer(1, instance_buffer.slice(..));
            pass.set_index_buffer(self.shape_indices.slice(..), wgpu::IndexFormat::Uint32);
            for (i, shape) in self.shapes.iter().enumerate() {
                let [w, h] = ATLAS_TILE_PX;
                pass.set_viewport((i as u32 * w) as f32, 0.0, w as f32, h as f32, 0.0, 1.0);
                let (first, count, base) = self.meshes.ranges[*shape as usize][0];
                pass.draw_indexed(first..first + count, base, i as u32..i as u32 + 1);
            }
        }
        gpu.queue.submit([enc.finish()]);
    }
}
