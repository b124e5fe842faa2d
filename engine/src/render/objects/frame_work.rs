//! The objects renderer's per-frame work on instances: each instance's GPU entry at its
//! chosen level (geomorphs included), a node's merged far mesh where the metric accepts it,
//! and the texture cache's plan, levels and the frame's draw data.

use super::{
    Choice, DrawIndirectArgs, DrawItem, DrawUniform, FrameDraws, Gpu, HlodGpu, InstanceGpu, Item,
    Key, Morph, NodeObjects, ObjectsRenderer, PmInstance, PmModel, PoolSettings, Pools,
    ScreenBound, Shown, draw_buffer, draw_group, hlod,
};

impl ObjectsRenderer {
    /// Instance `id`'s GPU entry for this frame: made at the chosen level (an instance without
    /// an entry was not drawn in the last frames, so nothing on the screen changes shape; the
    /// first frame of a large map would otherwise draw every house of its root node at full
    /// detail) or remade at the chosen level on another chain option, its level moved towards
    /// `choice` (geomorphing when MORPH is on). None when the index pages are full.
    pub(super) fn update_instance(
        &mut self,
        gpu: &Gpu,
        draws: &FrameDraws<'_>,
        id: u32,
        drawn_model: &PmModel,
        choice: Choice,
    ) -> Option<Shown> {
        let new_entry = |pools: &mut Pools, level: usize| {
            let pm = &drawn_model.pm;
            let indices = pools
                .indices
                .lease(&gpu.device, (pm.triangles.len() * 3) as u32)?;
            Some(InstanceGpu {
                option: choice.option,
                lod: PmInstance::new(pm, level),
                indices,
                uploaded_level: 0,
                last_frame: 0,
                morph: None,
                morph_to: None,
            })
        };
        let entry = match self.instances.entry(id) {
            std::collections::hash_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::hash_map::Entry::Vacant(e) => {
                let Some(i) = new_entry(&mut self.pools, choice.level) else {
                    self.stats.pool_full += 1;
                    return None;
                };
                e.insert(i)
            }
        };
        if entry.option != choice.option {
            // Another chain level: its own vertices, so a new list (switched at once).
            let Some(i) = new_entry(&mut self.pools, choice.level) else {
                self.stats.pool_full += 1;
                return None;
            };
            *entry = i;
        }
        entry.last_frame = self.frame_no;
        let changed = entry.update_level(
            gpu,
            drawn_model,
            choice.level,
            draws.view.pm_lod.morph_s,
            draws.dt_s,
            &mut self.pools,
        );
        self.stats.level_changes += u32::from(changed);
        // The morph page and first target of a morphing instance (page 0 otherwise).
        let (morph_page, morph_base) = entry
            .morph_to
            .as_ref()
            .filter(|_| entry.morph.is_some())
            .map_or((0, 0), |l| (l.page, l.start[0]));
        Some(Shown {
            level: entry.lod.level(),
            index_count: entry.lod.indices().len() as u32,
            morph: entry.morph.map_or([0.0; 4], |m| {
                [
                    m.lo as f32,
                    m.hi as f32,
                    m.t.min(1.0),
                    f32::from(u8::from(m.refine)),
                ]
            }),
            morph_page,
            morph_base,
            page: entry.indices.page,
            first_index: entry.indices.start[0],
        })
    }

    /// Draws node `node_index`'s merged far mesh instead of its houses when it has one on the
    /// GPU, the view allows it and the pixel metric accepts its error ([`hlod::accepts`]).
    pub(super) fn hlod_item(
        &mut self,
        draws: &FrameDraws<'_>,
        screen: &ScreenBound,
        node_index: usize,
        objects: &NodeObjects,
        light: [f32; 4],
        uniforms: &mut Vec<DrawUniform>,
    ) -> bool {
        let node = &draws.drawn[node_index];
        let camera = draws.camera;
        let (Some(h), Some(gpu_mesh)) = (&objects.hlod, node.work.gpu.get::<HlodGpu>()) else {
            return false;
        };
        if !draws.view.hlod || !hlod::accepts(h, &draws.view.pm_lod, draws.tau_px, screen) {
            return false;
        }
        if !draws.frustum.intersects_aabb(h.lo_m, h.hi_m) {
            return true;
        }
        let rel = (h.origin_m - camera.position_m).as_vec3();
        uniforms.push(DrawUniform {
            rel_from_model: glam::Mat4::from_translation(rel).to_cols_array_2d(),
            normal_from_model: glam::Mat4::IDENTITY.to_cols_array_2d(),
            fade: [
                node.dither[0],
                node.dither[1],
                f32::from(node.key.level),
                0.0,
            ],
            albedo: [1.0; 4],
            morph: [0.0; 4],
            light,
            base_local: [0.0; 4],
            base_rel: rel.extend(0.0).to_array(),
            // Vertex colours (w = 1), no texture level.
            tex: [-1.0, -1.0, 0.0, 1.0],
            roof_albedo: [1.0; 4],
            pool: [0; 4],
        });
        let vertex_count = gpu_mesh.vertices.len[0];
        self.items.push(DrawItem {
            instance: 0,
            option: 0,
            index_count: vertex_count,
            full_triangles: h.full_triangles as u32,
            key: Key {
                hlod: true,
                slots: [None; 2],
                page: gpu_mesh.vertices.page,
                morph_page: 0,
            },
            args: Item::Plain(DrawIndirectArgs {
                vertex_count,
                instance_count: 1,
                first_vertex: gpu_mesh.vertices.start[0],
                first_instance: uniforms.len() as u32 - 1,
            }),
        });
        self.stats.triangles += u64::from(vertex_count / 3);
        self.stats.full_triangles += h.full_triangles as u64;
        true
    }

    /// Ends the texture cache's frame (its uploads within what is left of the streamer's
    /// per-frame upload budgets of bytes and time), applies the plan on the GPU and fills the
    /// draws' texture levels.
    pub(super) fn texture_plan(
        &mut self,
        gpu: &Gpu,
        draws: &FrameDraws<'_>,
        uniforms: &mut [DrawUniform],
    ) {
        // Texture uploads share the streamer's per-frame upload budgets, bytes and time, with
        // the nodes'.
        let left = u64::try_from(draws.upload_bytes_left)
            .unwrap_or(u64::MAX)
            .min(
                self.gpu_tex
                    .upload_cost
                    .bytes_within(draws.upload_time_left_s),
            );
        self.tex_pool
            .set_upload_budget(left.min(PoolSettings::default().upload_bytes_per_frame));
        let plan = self.tex_pool.end_frame();
        if self.gpu_tex.apply(gpu, &plan, &self.set.textures) {
            self.groups.clear();
        }
        self.texture_levels(
            uniforms,
            draws.view.texture_mip_view && !draws.view.pm_color_by_lod,
        );
    }

    /// Writes the draw uniforms (growing the buffer when needed) and makes the draw groups.
    pub(super) fn write_uniforms(&mut self, gpu: &Gpu, uniforms: &[DrawUniform]) {
        if uniforms.is_empty() {
            return;
        }
        if uniforms.len() as u64 > self.draw_capacity {
            self.draw_capacity = (uniforms.len() as u64).next_power_of_two();
            self.draw_buffer = draw_buffer(&gpu.device, self.draw_capacity);
            self.groups.clear();
        }
        self.make_groups(gpu);
        gpu.queue
            .write_buffer(&self.draw_buffer, 0, bytemuck::cast_slice(uniforms));
    }

    /// Makes the draw groups this frame's items need (their slots' views, or the fallback).
    pub(super) fn make_groups(&mut self, gpu: &Gpu) {
        for item in &self.items {
            if self.groups.contains_key(&item.key.slots) {
                continue;
            }
            let views = item.key.slots.map(|s| {
                s.and_then(|s| self.gpu_tex.view(s))
                    .unwrap_or(&self.gpu_tex.fallback)
            });
            let group = draw_group(
                &gpu.device,
                &self.draw_layout,
                &self.draw_buffer,
                views,
                &self.gpu_tex.sampler,
            );
            self.groups.insert(item.key.slots, group);
        }
    }

    /// After the frame's texture plan: each textured draw's resident levels (or -1 and the
    /// textures' mean colours), the debug tint flag, and its slots.
    pub(super) fn texture_levels(&mut self, uniforms: &mut [DrawUniform], mip_view: bool) {
        for (item, u) in self.items.iter_mut().zip(uniforms.iter_mut()) {
            if item.key.hlod {
                continue;
            }
            let inst = &self.set.instances[item.instance as usize];
            let Some(textures) = inst.textures else {
                continue;
            };
            let resident = textures.map(|t| self.tex_pool.resident(t));
            item.key.slots = resident.map(|r| r.map(|(slot, _)| slot));
            let level = |k: usize| resident[k].map_or(-1.0, |(_, l)| l as f32);
            u.tex = [level(0), level(1), f32::from(u8::from(mip_view)), 0.0];
            if u.fade[3] < 0.5 {
                let [f, r] = textures.map(|t| self.tex_means[t as usize]);
                u.albedo = [f[0], f[1], f[2], 1.0];
                u.roof_albedo = [r[0], r[1], r[2], 1.0];
            } else {
                // Coloured by LOD: no textures.
                u.tex = [-1.0, -1.0, 0.0, 0.0];
            }
        }
    }
}

impl InstanceGpu {
    /// Moves the instance towards `level`: at once, or by a geomorph of `morph_s` seconds
    /// (advanced by `dt_s`; at once as well when the morph pages are full); rewrites the GPU
    /// index list when the shown level changed (returns whether it did).
    pub(super) fn update_level(
        &mut self,
        gpu: &Gpu,
        model: &PmModel,
        level: usize,
        morph_s: f64,
        dt_s: f64,
        pools: &mut Pools,
    ) -> bool {
        let pm = &model.pm;
        // Advance a geomorph; a finished shrink switches to its coarser list.
        if let Some(m) = self.morph.as_mut() {
            m.t += (dt_s / morph_s.max(1e-9)) as f32;
            if m.t >= 1.0 || morph_s <= 0.0 {
                if !m.refine {
                    self.lod.set_level(pm, &model.edits, m.target);
                }
                self.morph = None;
            }
        }
        if self.morph.is_none() && level != self.lod.level() {
            if self.morph_to.is_none() && morph_s > 0.0 {
                let wedges = pm.wedge_position.len().max(1) as u32;
                self.morph_to = pools.morph.lease(&gpu.device, 2 * wedges);
                pools.morph_groups(&gpu.device);
            }
            if let (Some(targets), true) = (&self.morph_to, morph_s > 0.0) {
                let refine = level > self.lod.level();
                let coarse = level.min(self.lod.level());
                let lo = pm.wedges_at(coarse) as u32;
                let hi = pm.wedges_at(level.max(self.lod.level())) as u32;
                let to: Vec<[f32; 4]> = (lo..hi)
                    .flat_map(|w0| {
                        let w = pm.live_wedge(w0, lo);
                        let q = pm.positions[pm.wedge_position[w as usize] as usize];
                        let n = model.normals[w as usize];
                        [[q[0], q[1], q[2], 1.0], [n[0], n[1], n[2], 0.0]]
                    })
                    .collect();
                pools
                    .morph
                    .write(&gpu.queue, targets, 2 * lo, bytemuck::cast_slice(&to));
                if refine {
                    self.lod.set_level(pm, &model.edits, level);
                }
                self.morph = Some(Morph {
                    lo,
                    hi,
                    t: 0.0,
                    refine,
                    target: level,
                });
            } else {
                self.lod.set_level(pm, &model.edits, level);
            }
        }
        let shown = self.lod.level();
        if self.uploaded_level == shown {
            return false;
        }
        pools.indices.write(
            &gpu.queue,
            &self.indices,
            0,
            bytemuck::cast_slice(self.lod.indices()),
        );
        self.uploaded_level = shown;
        true
    }
}
