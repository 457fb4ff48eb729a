//! Pose algebra and bounding-volume containment.

use frcd_geom::{Aabb, DMat3, DQuat, DVec3, Obb, Pose, Sphere};
use proptest::prelude::*;

fn vec3(r: f64) -> impl Strategy<Value = DVec3> {
    (-r..r, -r..r, -r..r).prop_map(|(x, y, z)| DVec3::new(x, y, z))
}

fn quat() -> impl Strategy<Value = DQuat> {
    (-1.0..1.0f64, -1.0..1.0f64, -1.0..1.0f64, -1.0..1.0f64)
        .prop_filter("non-zero", |(a, b, c, d)| {
            a * a + b * b + c * c + d * d > 1e-3
        })
        .prop_map(|(a, b, c, d)| DQuat::from_xyzw(a, b, c, d).normalize())
}

fn pose(r: f64) -> impl Strategy<Value = Pose> {
    (vec3(r), quat()).prop_map(|(t, q)| Pose::new(t, q))
}

fn close(a: DVec3, b: DVec3, scale: f64) -> bool {
    (a - b).length() <= 1e-12 * scale.max(1.0)
}

proptest! {
    #[test]
    fn compose_applies_right_then_left(a in pose(100.0), b in pose(100.0), p in vec3(10.0)) {
        let direct = a.transform_point(b.transform_point(p));
        prop_assert!(close(a.compose(&b).transform_point(p), direct, 1e3));
        prop_assert!(close((a * b).transform_point(p), direct, 1e3));
    }

    #[test]
    fn compose_is_associative(a in pose(100.0), b in pose(100.0), c in pose(100.0), p in vec3(10.0)) {
        let l = a.compose(&b).compose(&c).transform_point(p);
        let r = a.compose(&b.compose(&c)).transform_point(p);
        prop_assert!(close(l, r, 1e3));
    }

    #[test]
    fn inverse_undoes(a in pose(1e6), p in vec3(10.0)) {
        prop_assert!(close(a.inverse().transform_point(a.transform_point(p)), p, 1e6));
        let id = a.compose(&a.inverse());
        prop_assert!(close(id.translation, DVec3::ZERO, 1e6));
        prop_assert!((id.rotation.dot(DQuat::IDENTITY).abs() - 1.0).abs() < 1e-12);
        prop_assert!(a.inverse().is_valid());
        prop_assert!(close(a.transform_vector(DVec3::X), a.rotation_matrix().x_axis, 1.0));
    }

    #[test]
    fn relative_to_is_frame_inverse_compose(a in pose(1e6), b in pose(1e6), p in vec3(10.0)) {
        let rel = b.relative_to(&a);
        let via = a.inverse().compose(&b);
        prop_assert!(close(rel.transform_point(p), via.transform_point(p), 1e6));
        // Mapping back: a ∘ rel == b.
        prop_assert!(close(a.compose(&rel).transform_point(p), b.transform_point(p), 1e6));
        prop_assert!(rel.is_valid());
    }

    #[test]
    fn aabb_transformed_contains_transformed_corners(
        c in vec3(1e6), h in (0.0..10.0f64, 0.0..10.0f64, 0.0..10.0f64), a in pose(1e6)
    ) {
        let b = Aabb::new(c - DVec3::new(h.0, h.1, h.2), c + DVec3::new(h.0, h.1, h.2));
        let t = b.transformed(&a);
        for i in 0..8 {
            let corner = DVec3::new(
                if i & 1 == 0 { b.min.x } else { b.max.x },
                if i & 2 == 0 { b.min.y } else { b.max.y },
                if i & 4 == 0 { b.min.z } else { b.max.z },
            );
            prop_assert!(t.contains_point(a.transform_point(corner)));
        }
    }

    #[test]
    fn aabb_transformed_cancelling_offsets(c in vec3(1e7), h in 0.0..1.0f64, q in quat()) {
        // A box far from its frame's origin, posed back next to the world origin: the rounding
        // of the large terms must be covered even though the result is small.
        let b = Aabb::new(c - DVec3::splat(h), c + DVec3::splat(h));
        let pose = Pose::new(-(q * c), q);
        let t = b.transformed(&pose);
        for i in 0..8 {
            let corner = DVec3::new(
                if i & 1 == 0 { b.min.x } else { b.max.x },
                if i & 2 == 0 { b.min.y } else { b.max.y },
                if i & 4 == 0 { b.min.z } else { b.max.z },
            );
            prop_assert!(t.contains_point(pose.transform_point(corner)));
        }
    }

    #[test]
    fn obb_from_points_holds_them(pts in prop::collection::vec(vec3(1e5), 1..40), q in quat(), off in vec3(1e7)) {
        let pts: Vec<DVec3> = pts.iter().map(|p| *p + off).collect();
        let obb = Obb::from_points_with_axes(&pts, DMat3::from_quat(q));
        for p in &pts {
            prop_assert!(obb.contains_point(*p));
            prop_assert!(obb.aabb().contains_point(*p));
        }
        let s = Sphere::from_points(&pts);
        for p in &pts {
            prop_assert!(p.distance(s.center) <= s.radius);
        }
    }
}

#[test]
fn aabb_basics() {
    let a = Aabb::from_points(&[DVec3::ZERO, DVec3::ONE]);
    let b = Aabb::new(DVec3::splat(1.0), DVec3::splat(2.0));
    assert!(a.intersects(&b)); // touching counts
    assert_eq!(a.intersection(&b).volume(), 0.0);
    assert!(!a.intersects(&b.inflated(-0.1)));
    assert_eq!(a.union(&b).volume(), 8.0);
    assert!(Aabb::EMPTY.is_empty());
    assert_eq!(Aabb::EMPTY.transformed(&Pose::IDENTITY), Aabb::EMPTY);
    assert_eq!(Aabb::from_points(&[]), Aabb::EMPTY);
}
