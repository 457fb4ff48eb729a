//! A CPU-only engine's use of frcd-obb: its render meshes are f32 (`glam::Vec3` or
//! `[f32; 3]`), borrowed into validated f64 meshes without an intermediate copy, one OBB tree
//! per mesh, and exact pair queries between posed bodies.
//!
//! `cargo run -p frcd-example-engine-obb`

use frcd_geom::{DQuat, DVec3, Pose, TriMesh};
use frcd_obb::{BuildOptions, Mode, ObbTree, Request, collide};

/// An engine's unit cube as it would hand it over: f32 positions and u32 triangles.
fn engine_cube() -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let v = (0..8)
        .map(|i| [i & 1, (i >> 1) & 1, (i >> 2) & 1].map(|b| if b == 1 { 0.5f32 } else { -0.5 }))
        .collect();
    // Two triangles per face, outward (counter-clockwise seen from outside).
    #[rustfmt::skip]
    let t = vec![
        [0, 2, 1], [1, 2, 3], // z = -0.5
        [4, 5, 6], [5, 7, 6], // z = +0.5
        [0, 1, 4], [1, 5, 4], // y = -0.5
        [2, 6, 3], [3, 6, 7], // y = +0.5
        [0, 4, 2], [2, 4, 6], // x = -0.5
        [1, 3, 5], [3, 7, 5], // x = +0.5
    ];
    (v, t)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (vertices, triangles) = engine_cube();
    // Borrowed f32 data, widened exactly; bad data would be a typed MeshError, not a panic.
    let mesh = TriMesh::from_f32(&vertices, &triangles)?;
    assert!(mesh.topology().is_closed_oriented_manifold());
    let tree = ObbTree::build(&mesh, &BuildOptions::default());

    let all_pairs = Request {
        mode: Mode::AllPairs,
        ..Request::default()
    };
    // Far from the origin (CAD coordinates): the pair is tested in one body's frame.
    let offset = DVec3::new(1e6, -2e5, 3e4);
    for (label, shift, angle) in [
        ("apart", 1.5, 0.0),
        ("touching face to face", 1.0, 0.0),
        ("overlapping, rotated", 0.8, 0.3),
    ] {
        let a = Pose::from_translation(offset);
        let b = Pose::new(
            offset + DVec3::new(shift, 0.0, 0.0),
            DQuat::from_rotation_z(angle),
        );
        let hit = collide(&tree, &a, &tree, &b, &all_pairs);
        println!(
            "{label:>24}: collide = {}, {} touching triangle pairs (box tests {}, triangle tests {})",
            hit.collide,
            hit.pairs.len(),
            hit.counters.box_tests,
            hit.counters.tri_tests
        );
        assert_eq!(hit.collide, shift <= 1.0, "{label}");
    }
    Ok(())
}
