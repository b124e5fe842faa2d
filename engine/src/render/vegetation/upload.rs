//! A node's vegetation uploaded: its instances into a page of the instance pool, its groups'
//! draw records, its node-table slot and, for group billboards, its impostor layer and bake.

use super::{
    ClusterUniform, PlantDraw, PlantGroupGpu, PlantInstance, PlantsGpu, Shape, VegetationRenderer,
};
use crate::render::Gpu;
use crate::render::scene::UploadEncoder;
use crate::terrain::quadtree::{NodeKey, QuadTree};
use crate::vegetation::representation::CLUSTER_COUNT;
use crate::vegetation::{NodeVegetation, Representation};
use bytemuck::Zeroable;

impl VegetationRenderer {
    /// Uploads a node's vegetation (None when it has none, or when the instance pool, the
    /// impostor pages or the node table are full). Group-billboard members are baked, cluster
    /// by cluster, into the node's impostor layer (a render pass recorded and submitted with the
    /// frame's other bakes when the uploads finish); the node then draws one quad per cluster
    /// instead of its members.
    pub fn upload_node(
        &mut self,
        gpu: &Gpu,
        tree: &QuadTree,
        key: NodeKey,
        veg: &NodeVegetation,
        copies: &mut UploadEncoder<'_>,
    ) -> Option<PlantsGpu> {
        let aabb_m = veg.items_box_m?;
        let o = tree.rect(key).min;
        let Some(slot) = self.table.lease() else {
            log::warn!("vegetation node table full: node {key:?} has no plants drawn");
            return None;
        };
        let first_entry = self.table.first_entry(&slot);
        let instance = |it: &crate::vegetation::Item, entry: u32| PlantInstance {
            position: [
                (it.x_m - o[0]) as f32,
                (it.y_m - o[1]) as f32,
                it.z_m as f32,
            ],
            height_m: it.height_m,
            radius_m: it.radius_m,
            yaw_rad: it.yaw_rad,
            look: u32::from(it.species),
            entry,
        };
        let mut data: Vec<PlantInstance> = Vec::with_capacity(veg.instances());
        let mut groups = Vec::with_capacity(veg.groups.len());
        let mut members: Vec<PlantInstance> = Vec::new();
        for g in &veg.groups {
            if g.representation == Representation::Group {
                let at = members.len();
                members.extend(
                    g.items
                        .iter()
                        .zip(&veg.clusters.member_clusters[at..])
                        .map(|(it, &c)| instance(it, u32::from(c))),
                );
                continue;
            }
            let first = data.len() as u32;
            let entry = first_entry + u32::from(!g.replaced_on_split);
            data.extend(g.items.iter().map(|it| instance(it, entry)));
            groups.push(PlantGroupGpu {
                first,
                count: g.items.len() as u32,
                shape: self
                    .shapes
                    .get(usize::from(g.species))
                    .copied()
                    .unwrap_or(Shape::Bush),
                kind: if g.representation == Representation::Mesh {
                    PlantDraw::Mesh
                } else {
                    PlantDraw::Billboard
                },
                kept: !g.replaced_on_split,
            });
        }
        let mut impostors = None;
        let mut texture_bytes = 0;
        if !members.is_empty() {
            let Some((layer, layer_views)) = self.impostors.lease(&gpu.device, &self.sampler)
            else {
                log::warn!("impostor pages full: node {key:?} has no plants drawn");
                return None;
            };
            // Cluster quads: centre, bottom, half width, height; `look` = layer and tile.
            let mut uniforms = [ClusterUniform::zeroed(); CLUSTER_COUNT];
            let first = data.len() as u32;
            let entry = first_entry + u32::from(veg.clusters.kept);
            for (c, b) in veg.clusters.boxes.iter().enumerate() {
                let Some(b) = b else { continue };
                uniforms[c] = ClusterUniform {
                    centre_bottom_half: [
                        b.centre_m[0] as f32,
                        b.centre_m[1] as f32,
                        b.bottom_m as f32,
                        b.half_width_m as f32,
                    ],
                    height: [b.height_m as f32, 0.0, 0.0, 0.0],
                };
                data.push(PlantInstance {
                    position: [
                        b.centre_m[0] as f32,
                        b.centre_m[1] as f32,
                        b.bottom_m as f32,
                    ],
                    height_m: b.height_m as f32,
                    radius_m: b.half_width_m as f32,
                    yaw_rad: 0.0,
                    look: layer.start[0] * CLUSTER_COUNT as u32 + c as u32,
                    entry,
                });
            }
            groups.push(PlantGroupGpu {
                first,
                count: data.len() as u32 - first,
                shape: Shape::Bush,
                kind: PlantDraw::Impostor,
                kept: veg.clusters.kept,
            });
            self.bake_impostors(key, &uniforms, &members, layer_views);
            impostors = Some(layer);
            texture_bytes = self.impostors.layer_bytes();
        }
        let Some(instances) = self.instances.lease(&gpu.device, data.len() as u32) else {
            log::warn!("plant instance pool full: node {key:?} has no plants drawn");
            return None;
        };
        self.instances.write_staged(
            &mut self.staging,
            copies.get(&gpu.device),
            &instances,
            0,
            bytemuck::cast_slice(&data),
        );
        Some(PlantsGpu {
            origin_m: o,
            instances,
            slot,
            impostors,
            groups,
            aabb_m,
            bytes: data.len() * std::mem::size_of::<PlantInstance>() + texture_bytes,
            low_detail: tree.spacing_m(key.level) >= 1.0,
        })
    }
}
