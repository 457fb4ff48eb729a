//! Coordinates near the top of the f64 range: the top volume's sphere distance and transformed
//! box overflow there (or turn NaN through `0 · ∞`), and such a figure must never reject a
//! touching pair. Each case is checked against the exact oracle.

use frcd_geom::fit::FitMethod;
use frcd_geom::{DVec3, Pose, TriMesh};
use frcd_obb::{BuildOptions, Mode, ObbTree, Request, SplitMethod, collide, oracle};

fn all_pairs(a: &TriMesh, b: &TriMesh, leaf: u32, fit: FitMethod) -> (Vec<(u32, u32)>, bool) {
    let opts = BuildOptions {
        fit,
        max_leaf_triangles: leaf,
        split: SplitMethod::SurfaceCost,
    };
    let (ta, tb) = (ObbTree::build(a, &opts), ObbTree::build(b, &opts));
    let all = Request {
        mode: Mode::AllPairs,
        ..Request::default()
    };
    let first = collide(
        &ta,
        &Pose::IDENTITY,
        &tb,
        &Pose::IDENTITY,
        &Request::default(),
    );
    let r = collide(&ta, &Pose::IDENTITY, &tb, &Pose::IDENTITY, &all);
    (r.pairs, first.collide)
}

fn check(a: &TriMesh, b: &TriMesh, what: &str) {
    let want = oracle::pairs(a, &Pose::IDENTITY, b, &Pose::IDENTITY);
    assert!(!want.is_empty(), "{what}: the case must touch");
    for fit in [
        FitMethod::VertexCovariance,
        FitMethod::AreaWeighted,
        FitMethod::HullSurface,
    ] {
        for leaf in 1..=2 {
            let (got, first) = all_pairs(a, b, leaf, fit);
            assert_eq!(got, want, "{what}: {fit:?}, leaf {leaf}");
            assert!(first, "{what}: first contact, {fit:?}, leaf {leaf}");
        }
    }
}

/// The `mesh_tree` fuzz target's input (`fuzz/regressions/mesh_tree/wrong-pairs-c61a04ae`):
/// two point triangles, one at `z ≈ −1.8·10³⁰⁸`. The box centre `(min + max) / 2` overflowed
/// to −∞, the rotation's zeros made it NaN, and the top volume rejected the mesh against
/// itself.
#[test]
fn point_triangles_at_the_top_of_the_range_touch_themselves() {
    let v = vec![
        DVec3::new(8.1027e-320, 1.5051e-319, -5.610686944379092e303),
        DVec3::new(
            3.31246905e-316,
            9.65289394275573e-310,
            -1.7976931348622648e308,
        ),
    ];
    let mesh = TriMesh::new(v, vec![[0, 0, 0], [1, 1, 1]]).expect("finite points");
    check(&mesh, &mesh, "point triangles");
}

/// A triangle 4·10²⁰⁰ in size and a small one through it near its far corner: the top
/// volume's squared distances overflow, so the sphere's radius and the distance between the
/// spheres' centres are both ∞, and nothing may reject the touching pair.
#[test]
fn touching_bodies_whose_sphere_distance_overflows_are_kept() {
    let s = 4e200;
    let a = TriMesh::new(
        vec![
            DVec3::ZERO,
            DVec3::new(s, 0.0, 0.0),
            DVec3::new(0.0, s, 0.0),
        ],
        vec![[0, 1, 2]],
    )
    .expect("finite");
    // A small triangle through A's plane near its corner (s, 0, 0).
    let c = DVec3::new(0.9 * s, 0.01 * s, 0.0);
    let h = 0.01 * s;
    let b = TriMesh::new(
        vec![
            c + DVec3::new(0.0, 0.0, -h),
            c + DVec3::new(0.0, 0.0, h),
            c + DVec3::new(h, h, 0.0),
        ],
        vec![[0, 1, 2]],
    )
    .expect("finite");
    check(&a, &b, "sphere distance overflow");
}
