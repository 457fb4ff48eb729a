//! `intersection_segment`: right topology on every degenerate family, points on both triangles.
use frcd_geom::DVec3;
use frcd_tritri::{Contact, Triangle, intersection_segment};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

#[path = "../../../benches/src/tritri_oracle.rs"]
mod oracle;

fn t(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> Triangle {
    Triangle::new(DVec3::from(a), DVec3::from(b), DVec3::from(c))
}

/// Distance from `p` to the closed triangle (brute force over the plane projection and edges).
fn dist(p: DVec3, tr: &Triangle) -> f64 {
    let [a, b, c] = tr.v;
    let seg = |x: DVec3, y: DVec3| {
        let d = y - x;
        let l = d.length_squared();
        let u = if l > 0.0 {
            ((p - x).dot(d) / l).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (x + d * u - p).length()
    };
    let mut best = seg(a, b).min(seg(b, c)).min(seg(c, a));
    let n = (b - a).cross(c - a);
    if n.length_squared() > 0.0 {
        let n = n.normalize();
        let q = p - n * n.dot(p - a);
        let inside = [(a, b), (b, c), (c, a)]
            .iter()
            .all(|&(x, y)| (y - x).cross(q - x).dot(n) >= -1e-12);
        if inside {
            best = best.min(n.dot(p - a).abs());
        }
    }
    best
}

fn points(c: &Contact) -> Vec<DVec3> {
    match c {
        Contact::Point(p) => vec![*p],
        Contact::Segment(p, q) => vec![*p, *q],
        Contact::Polygon(v) => v.clone(),
    }
}

fn check_on_both(a: &Triangle, b: &Triangle, tol: f64) -> Option<Contact> {
    let c = intersection_segment(a, b);
    assert_eq!(
        c.is_some(),
        oracle::lp_intersects(&a.v, &b.v),
        "{a:?} {b:?}"
    );
    if let Some(c) = &c {
        for p in points(c) {
            assert!(
                dist(p, a) <= tol && dist(p, b) <= tol,
                "{p:?} not on both: {a:?} {b:?} {c:?}"
            );
        }
    }
    c
}

#[test]
fn kinds_on_hand_made_pairs() {
    let base = t([0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]);
    // Transversal: a segment.
    let c = check_on_both(
        &base,
        &t([0.5, 0.5, -1.0], [0.5, 0.5, 1.0], [1.0, 0.2, 1.0]),
        1e-12,
    )
    .unwrap();
    assert!(matches!(c, Contact::Segment(..)), "{c:?}");
    // Vertex on face: a point, the vertex itself.
    let c = check_on_both(
        &base,
        &t([0.5, 0.5, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]),
        0.0,
    )
    .unwrap();
    assert_eq!(c, Contact::Point(DVec3::new(0.5, 0.5, 0.0)));
    // Shared edge (folded): the edge.
    let c = check_on_both(
        &base,
        &t([2.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, -1.0, 1.0]),
        0.0,
    )
    .unwrap();
    match c {
        Contact::Segment(p, q) => {
            let mut e = [p, q];
            e.sort_by(|x, y| x.x.total_cmp(&y.x));
            assert_eq!(e, [DVec3::ZERO, DVec3::new(2.0, 0.0, 0.0)]);
        }
        other => panic!("{other:?}"),
    }
    // Coplanar overlap: a polygon with positive area.
    let c = check_on_both(
        &base,
        &t([0.5, 0.5, 0.0], [3.0, 0.5, 0.0], [0.5, 3.0, 0.0]),
        1e-12,
    )
    .unwrap();
    match c {
        Contact::Polygon(v) => assert!(v.len() >= 3),
        other => panic!("{other:?}"),
    }
    // Coplanar, touching at a vertex only.
    let c = check_on_both(
        &base,
        &t([2.0, 0.0, 0.0], [3.0, 0.0, 0.0], [3.0, 1.0, 0.0]),
        1e-12,
    )
    .unwrap();
    assert_eq!(c, Contact::Point(DVec3::new(2.0, 0.0, 0.0)));
    // Segment triangle through the face, point triangle on it.
    let c = check_on_both(
        &base,
        &t([0.2, 0.2, -1.0], [0.2, 0.2, 1.0], [0.2, 0.2, 0.0]),
        1e-12,
    )
    .unwrap();
    assert_eq!(c, Contact::Point(DVec3::new(0.2, 0.2, 0.0)));
    let p = [0.3, 0.4, 0.0];
    assert_eq!(
        check_on_both(&base, &t(p, p, p), 0.0),
        Some(Contact::Point(DVec3::from(p)))
    );
    // Disjoint.
    assert_eq!(
        check_on_both(
            &base,
            &t([0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]),
            0.0
        ),
        None
    );
}

#[test]
fn random_touching_pairs_have_contacts_on_both() {
    let mut rng = StdRng::seed_from_u64(5);
    for i in 0..2000 {
        let r = |rng: &mut StdRng| {
            DVec3::new(
                rng.random_range(-2..=2) as f64,
                rng.random_range(-2..=2) as f64,
                rng.random_range(-2..=2) as f64 * (i % 4 != 0) as i32 as f64,
            )
        };
        let a = Triangle::new(r(&mut rng), r(&mut rng), r(&mut rng));
        let b = Triangle::new(r(&mut rng), r(&mut rng), r(&mut rng));
        check_on_both(&a, &b, 1e-9);
    }
}
