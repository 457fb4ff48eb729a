//! Every fitting rule's box holds every vertex, whatever the triangles.

use frcd_geom::fit::{FitMethod, fit_obb};
use frcd_geom::{DVec3, Triangle};
use proptest::prelude::*;

fn vec3(r: f64) -> impl Strategy<Value = DVec3> {
    (-r..r, -r..r, -r..r).prop_map(|(x, y, z)| DVec3::new(x, y, z))
}

proptest! {
    #[test]
    fn boxes_hold_all_vertices(
        tris in prop::collection::vec((vec3(10.0), vec3(10.0), vec3(10.0)), 1..30),
        offset in vec3(1e7),
        scale in prop::sample::select(vec![1e-6, 1.0, 1e4]),
    ) {
        let tris: Vec<Triangle> = tris
            .iter()
            .map(|(a, b, c)| Triangle::new(*a * scale + offset, *b * scale + offset, *c * scale + offset))
            .collect();
        for method in [FitMethod::VertexCovariance, FitMethod::AreaWeighted, FitMethod::HullSurface] {
            let obb = fit_obb(&tris, method);
            prop_assert!(obb.half_extents.is_finite() && obb.center.is_finite());
            // Orthonormal, right-handed axes.
            let a = obb.axes;
            prop_assert!((a.determinant() - 1.0).abs() < 1e-9);
            for t in &tris {
                for p in t.v {
                    prop_assert!(obb.contains_point(p), "{:?} misses {:?}", method, p);
                }
            }
        }
    }
}
