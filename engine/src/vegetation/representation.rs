//! The representation ladder: how an item is drawn in a node of a given mesh spacing (mesh,
//! billboard, group billboard, left out), a node's instance groups, and the kept-groups rule
//! (which groups a node draws when it is drawn itself and when it is an ancestor of drawn
//! nodes).

use super::placement::{Item, Kind, Placer, layer_max};
use crate::surface::{Rect, World};
use crate::terrain::quadtree::{NodeKey, QuadTree};
use glam::DVec3;

/// How an item is drawn in a node.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Representation {
    /// Full 3D mesh.
    Mesh,
    /// One camera-facing textured quad.
    Billboard,
    /// Part of an impostor that stands for several items of the node.
    Group,
}

/// The vegetation error of a node that has vegetation, per metre of its mesh spacing: the
/// selection splits while `max(terrain error, ERROR_PER_SPACING * spacing)` projects above
/// the user's threshold. Where a node is shown, its distance is at least `error * K / tau`, so an
/// item of height `h = q * spacing` projects to at most `q * tau / ERROR_PER_SPACING` pixels:
/// at 0.125 a billboard (q < 2.5) is at most 20 tau px tall (40 px at the default 2 px), a
/// group-billboard member (q < 0.6) at most 4.8 tau px, and a removed item (q < 0.15) at most
/// 1.2 tau px, so nothing near the camera is a billboard and removal is below about tau.
pub const ERROR_PER_SPACING: f64 = 0.125;

/// Whether any species' density layer is above zero somewhere in `rect` (large trees follow the
/// same layers in generated maps).
pub fn has_vegetation(world: &World, rect: Rect) -> bool {
    (0..world.map.densities.len()).any(|l| layer_max(world, l, rect) > 0)
}

/// Item height over node mesh spacing at and above which an item is a mesh.
pub const MESH_RATIO: f64 = 2.5;
/// ... a billboard.
pub const BILLBOARD_RATIO: f64 = 0.6;
/// ... part of a group billboard; below it the item is left out (smallest species first).
pub const GROUP_RATIO: f64 = 0.15;

/// The representation of an item of `kind` and height `height_m` in a node of mesh spacing
/// `spacing_m` (`None`: left out). A node of a given size shows the same vegetation detail at any
/// setting, like its terrain: the user's threshold only moves where nodes split. Grass clumps
/// exist only in the finest nodes.
pub fn representation(
    kind: Kind,
    height_m: f64,
    spacing_m: f64,
    finest: bool,
) -> Option<Representation> {
    if kind == Kind::GrassClump {
        return finest.then_some(Representation::Mesh);
    }
    let q = height_m / spacing_m;
    if q >= MESH_RATIO {
        Some(Representation::Mesh)
    } else if q >= BILLBOARD_RATIO {
        Some(Representation::Billboard)
    } else if q >= GROUP_RATIO {
        Some(Representation::Group)
    } else {
        None
    }
}

/// Instances of one render state in one node.
#[derive(Debug, Clone, PartialEq)]
pub struct InstanceGroup {
    pub species: u16,
    pub representation: Representation,
    /// True when some finer level draws these items differently, so they are drawn via this
    /// node only while it is not split (its descendants hold their own versions); false when
    /// every finer level draws them the same way: then they are drawn via this node always, even
    /// while it is split, and no descendant holds them.
    pub replaced_on_split: bool,
    pub items: Vec<Item>,
}

/// A node's vegetation, grouped by (species, representation, replaced on split), with what
/// drawing needs precomputed in the vegetation phase (off the render thread).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NodeVegetation {
    pub groups: Vec<InstanceGroup>,
    /// World-space box of all items (ground to tree tops); None without items.
    pub items_box_m: Option<(DVec3, DVec3)>,
    /// Group billboards: the node's group members bucketed into clusters.
    pub clusters: Clusters,
}

/// Group billboards: clusters per node side (an 8 x 8 grid over the node).
pub const CLUSTERS_PER_SIDE: u32 = 8;
/// Clusters per node.
pub const CLUSTER_COUNT: usize = (CLUSTERS_PER_SIDE * CLUSTERS_PER_SIDE) as usize;

/// One cluster's quad: positions relative to the node's south-west corner, z absolute (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClusterBox {
    pub centre_m: [f64; 2],
    pub bottom_m: f64,
    /// Half the wider of the x and y spans, so a turned quad still covers the members.
    pub half_width_m: f64,
    pub height_m: f64,
}

/// A node's group members bucketed into an 8 x 8 grid of clusters; each cluster is baked into
/// one tile of the node's impostor texture and drawn as one camera-facing quad.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Clusters {
    /// Per cluster (row-major from the south-west): its quad, None when empty. Empty when the
    /// node has no group members.
    pub boxes: Vec<Option<ClusterBox>>,
    /// The cluster of each group member, in the order of the groups' items.
    pub member_clusters: Vec<u8>,
    /// Whether the members are kept through the node's splits (no member group is replaced).
    pub kept: bool,
}

impl Clusters {
    /// Buckets the members of the `Group` groups of a node at `rect`.
    fn of(groups: &[InstanceGroup], rect: Rect) -> Self {
        let o = rect.min;
        let side = rect.max[0] - rect.min[0];
        let n = CLUSTERS_PER_SIDE as usize;
        // Per cluster: x range, y range (relative), bottom and top (absolute).
        let mut spans = vec![
            [
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY
            ];
            n * n
        ];
        let mut out = Self {
            kept: true,
            ..Self::default()
        };
        for g in groups
            .iter()
            .filter(|g| g.representation == Representation::Group)
        {
            out.kept &= !g.replaced_on_split;
            for it in &g.items {
                let cell = |v: f64| (((v / side) * n as f64) as usize).min(n - 1);
                let c = cell(it.y_m - o[1]) * n + cell(it.x_m - o[0]);
                let b = &mut spans[c];
                let r = f64::from(it.radius_m);
                b[0] = b[0].min(it.x_m - o[0] - r);
                b[1] = b[1].max(it.x_m - o[0] + r);
                b[2] = b[2].min(it.y_m - o[1] - r);
                b[3] = b[3].max(it.y_m - o[1] + r);
                b[4] = b[4].min(it.z_m);
                b[5] = b[5].max(it.z_m + f64::from(it.height_m));
                out.member_clusters.push(c as u8);
            }
        }
        if !out.member_clusters.is_empty() {
            out.boxes = spans
                .iter()
                .map(|b| {
                    (b[0] <= b[1]).then(|| ClusterBox {
                        centre_m: [0.5 * (b[0] + b[1]), 0.5 * (b[2] + b[3])],
                        bottom_m: b[4],
                        half_width_m: 0.5 * (b[1] - b[0]).max(b[3] - b[2]),
                        height_m: b[5] - b[4],
                    })
                })
                .collect();
        }
        out
    }
}

/// The world-space box of the items of `groups` (as far around as their shapes reach, 1 m below
/// the ground to the top).
fn items_box(groups: &[InstanceGroup]) -> Option<(DVec3, DVec3)> {
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for it in groups.iter().flat_map(|g| &g.items) {
        let r = f64::from(it.radius_m) * super::plants::REACH;
        lo = lo.min(DVec3::new(it.x_m - r, it.y_m - r, it.z_m - 1.0));
        hi = hi.max(DVec3::new(
            it.x_m + r,
            it.y_m + r,
            it.z_m + f64::from(it.height_m),
        ));
    }
    (lo.x <= hi.x).then_some((lo, hi))
}

/// Which dither interval a group is drawn with this frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GroupDither {
    /// The node's own interval (it fades with the node).
    Own,
    /// The full interval: the group is kept through the node's splits and drawn via the node
    /// while it is an ancestor of drawn nodes.
    Full,
}

/// The kept-groups rule, the one place it is written: a group that is not replaced on split is
/// drawn in full while its node is an ancestor of drawn nodes (its descendants do not hold it);
/// otherwise a group is drawn with its node's interval while the node itself is drawn.
pub fn group_dither(
    replaced_on_split: bool,
    node_drawn: bool,
    node_is_ancestor: bool,
) -> Option<GroupDither> {
    if !replaced_on_split && node_is_ancestor {
        Some(GroupDither::Full)
    } else if node_drawn {
        Some(GroupDither::Own)
    } else {
        None
    }
}

/// Bytes of one instance on the GPU (position, height, radius, yaw, species).
pub const INSTANCE_BYTES: usize = 32;

impl NodeVegetation {
    pub fn instances(&self) -> usize {
        self.groups.iter().map(|g| g.items.len()).sum()
    }

    /// Bytes of the node's instance buffer.
    pub fn gpu_bytes(&self) -> usize {
        self.instances() * INSTANCE_BYTES
    }

    /// The same node's vegetation with only the items `keep` accepts (empty groups dropped;
    /// box and clusters made again for what is left), for drawing part of a node on its own.
    pub fn only(&self, rect: Rect, keep: impl Fn(&Item) -> bool) -> Self {
        let groups: Vec<InstanceGroup> = self
            .groups
            .iter()
            .map(|g| InstanceGroup {
                species: g.species,
                representation: g.representation,
                replaced_on_split: g.replaced_on_split,
                items: g.items.iter().filter(|it| keep(it)).copied().collect(),
            })
            .filter(|g| !g.items.is_empty())
            .collect();
        Self {
            items_box_m: items_box(&groups),
            clusters: Clusters::of(&groups, rect),
            groups,
        }
    }
}

/// The vegetation of node `key`: items placed in its rectangle whose representation at this
/// level is not already held (as "not replaced") by an ancestor. A pure function of the key.
pub fn node_vegetation(
    world: &World,
    placer: &Placer,
    tree: &QuadTree,
    key: NodeKey,
) -> NodeVegetation {
    let r = tree.rect(key);
    let s_m = tree.spacing_m(key.level);
    let finest = key.level == tree.max_level;
    let s_finest = tree.spacing_m(tree.max_level);
    let mut groups: Vec<InstanceGroup> = Vec::new();
    for sp in 0..placer.species.len() {
        let kind = placer.species[sp].kind;
        // Skip species that are left out at this level whatever their size (+-25% variation).
        let tallest = if kind == Kind::LargeTree {
            200.0
        } else {
            placer.species[sp].height_m * 1.25
        };
        if representation(kind, tallest, s_m, finest).is_none() {
            continue;
        }
        // How this node draws an item of height `h`: None when it is left out here or when an
        // ancestor draws it. Final: drawn the same way at every finer level (the ladder only
        // moves towards more detail), so the coarsest level showing it that way keeps it for
        // all of them (an ancestor draws it, always). Else (representation, replaced on split).
        let drawn_here = |h: f64| {
            let here = representation(kind, h, s_m, finest)?;
            let fin = representation(kind, h, s_finest, true) == Some(here);
            if key.level > 0 && fin && representation(kind, h, 2.0 * s_m, false) == Some(here) {
                return None;
            }
            Some((here, !fin))
        };
        let mut items = Vec::new();
        placer.place_where(
            world,
            sp,
            r,
            1.0,
            |h| drawn_here(f64::from(h)).is_some(),
            &mut items,
        );
        // The species' items by how this node draws them: most often all one way, and then
        // the list becomes that group's as it is (no copy).
        let class = |it: &Item| drawn_here(f64::from(it.height_m)).expect("kept by this filter");
        while let Some(&first) = items.first() {
            let (here, replaced) = class(&first);
            let (same, rest) = if items.iter().all(|it| class(it) == (here, replaced)) {
                (items, Vec::new())
            } else {
                items
                    .into_iter()
                    .partition(|it| class(it) == (here, replaced))
            };
            groups.push(InstanceGroup {
                species: first.species,
                representation: here,
                replaced_on_split: replaced,
                items: same,
            });
            items = rest;
        }
    }
    groups.sort_by_key(|g| (g.species, g.representation, g.replaced_on_split));
    NodeVegetation {
        items_box_m: items_box(&groups),
        clusters: Clusters::of(&groups, r),
        groups,
    }
}
