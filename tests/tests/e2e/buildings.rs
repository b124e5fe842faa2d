//! Procedural building meshes: closed and outward-facing, enclosing
//! exactly the volume their dimensions give, deterministic, with facade seams, and ready to be
//! progressive meshes.

use glam::DVec3;
use std::collections::HashMap;
use worldgen::building_mesh::{BuildingSpec, Roof, building_mesh};
use worldgen::pm::mesh::Corner;
use worldgen::pm::{CostKind, PmMesh, TriMesh, obj};

fn spec(roof: Roof, width_m: f64, depth_m: f64, storeys: u32, seed: u64) -> BuildingSpec {
    BuildingSpec {
        width_m,
        depth_m,
        storeys,
        storey_m: 3.0,
        roof,
        roof_pitch_deg: 35.0,
        seed,
    }
}

/// Enclosed volume by the divergence theorem over the welded positions (this test's own sum).
fn signed_volume(mesh: &TriMesh) -> f64 {
    let p = |w: u32| {
        let q = mesh.positions[mesh.wedge_position[w as usize] as usize];
        DVec3::new(f64::from(q[0]), f64::from(q[1]), f64::from(q[2]))
    };
    mesh.triangles
        .iter()
        .map(|t| p(t[0]).dot(p(t[1]).cross(p(t[2]))) / 6.0)
        .sum()
}

#[test]
fn building_meshes_are_closed_outward_and_enclose_their_exact_volume() {
    for roof in [Roof::Gable, Roof::Hip] {
        for (w, d, storeys) in [
            (10.0, 8.0, 2),
            (6.0, 6.0, 1),
            (7.0, 11.0, 3),
            (32.0, 12.0, 6),
        ] {
            for seed in 0..3 {
                let s = spec(roof, w, d, storeys, seed);
                let name = format!(
                    "{} {w} x {d} m, {storeys} storeys, seed {seed}",
                    roof.name()
                );
                let b = building_mesh(&s).expect("valid spec");
                let (mesh, report) = TriMesh::weld(&b.triangles);
                assert_eq!(
                    (report.degenerate_dropped, report.duplicates_dropped),
                    (0, 0),
                    "{name}: degenerate or repeated triangles"
                );
                let n = mesh.triangles.len();
                assert!((200..=20_000).contains(&n), "{name}: {n} triangles");
                // Closed and consistently oriented: every directed edge between positions once,
                // and its reverse once.
                let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
                for t in mesh.position_triangles() {
                    for k in 0..3 {
                        *edges.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
                    }
                }
                for (&(a, b), &count) in &edges {
                    assert!(
                        count == 1 && edges.get(&(b, a)) == Some(&1),
                        "{name}: edge {a}-{b} used {count} times, its reverse {:?}",
                        edges.get(&(b, a))
                    );
                }
                // Outward and whole: the enclosed volume is the one the dimensions give.
                let v = signed_volume(&mesh);
                assert!(
                    (v - b.volume_m3).abs() <= 1e-4 * b.volume_m3,
                    "{name}: enclosed {v:.3} m3, expected {:.3}",
                    b.volume_m3
                );
                // Facade UVs split at the corners, flat normals at every crease.
                assert!(mesh.wedge_position.len() > mesh.positions.len());
            }
        }
    }
}

#[test]
fn building_meshes_are_deterministic_and_refuse_bad_specs() {
    let s = spec(Roof::Hip, 12.0, 9.0, 3, 7);
    let a = building_mesh(&s).expect("valid").triangles;
    assert_eq!(a, building_mesh(&s).expect("valid").triangles);
    let other = building_mesh(&BuildingSpec { seed: 8, ..s }).expect("valid");
    assert_ne!(a, other.triangles, "the seed changes the windows");
    for (bad, field) in [
        (BuildingSpec { storeys: 0, ..s }, "storeys"),
        (
            BuildingSpec {
                width_m: f64::NAN,
                ..s
            },
            "width_m",
        ),
        (BuildingSpec { depth_m: 1.0, ..s }, "depth_m"),
        (
            BuildingSpec {
                roof_pitch_deg: 80.0,
                ..s
            },
            "roof_pitch_deg",
        ),
    ] {
        let err = building_mesh(&bad).expect_err(field);
        assert!(err.contains(field), "{err:?} does not name {field}");
    }
    // The OBJ text reads back to the same corners, bit for bit.
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("house.obj");
    let back: Vec<[Corner; 3]> = obj::parse(&obj::to_text(&a), &path).expect("OBJ reads back");
    assert_eq!(back, a);
}

#[test]
fn a_building_is_a_progressive_mesh_down_to_one_vertex() {
    let b = building_mesh(&spec(Roof::Gable, 10.0, 8.0, 2, 1)).expect("valid");
    let (mesh, _) = TriMesh::weld(&b.triangles);
    let (pm, _) = PmMesh::build(&mesh, CostKind::Quadric, 0.005, &mut |_, _, _| {});
    crate::pm::check_levels("building", &pm);
    // A quarter of the triangles keeps the house within about its window depth (0.15 m of a
    // 16 m diagonal), a tenth within 5 % (the creased facade seams do not hold back cheap
    // collapses: with them as strict seams the chimney and a gable went first, 17 %).
    for (share, limit) in [(4, 0.02), (10, 0.05)] {
        let p = pm.finest_with_at_most(mesh.triangles.len() / share);
        let error = f64::from(pm.levels[p - 1].error) / f64::from(mesh.diagonal());
        assert!(
            error < limit,
            "1/{share} of the triangles: stored error {error:.4} of the diagonal"
        );
    }
}
