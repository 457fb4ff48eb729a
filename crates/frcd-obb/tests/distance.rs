//! `frcd_obb::distance` against the brute-force oracle and exact labels.

use frcd_geom::{DQuat, DVec3, Pose, TriMesh, shapes};
use frcd_obb::distance::{
    DistanceCache, DistanceRequest, distance, distance_below, distance_cached, within,
    within_counted,
};
use frcd_obb::{BuildOptions, ObbTree, oracle};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn meshes() -> Vec<TriMesh> {
    vec![
        shapes::icosphere(0.5, 1),
        shapes::cuboid(DVec3::new(0.5, 0.3, 0.2)),
        shapes::torus(0.4, 0.1, 12, 6).expect("torus"),
        shapes::cylinder(0.2, 0.4, 10, 2).expect("cylinder"),
    ]
}

fn random_pose(rng: &mut StdRng, spread: f64) -> Pose {
    let t = DVec3::new(
        rng.random_range(-spread..spread),
        rng.random_range(-spread..spread),
        rng.random_range(-spread..spread),
    );
    let q = DQuat::from_xyzw(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    )
    .normalize();
    Pose::new(t, q)
}

fn tree(m: &TriMesh, leaf: u32) -> ObbTree {
    ObbTree::build(
        m,
        &BuildOptions {
            max_leaf_triangles: leaf,
            ..BuildOptions::default()
        },
    )
}

/// Distance from `p` (world) to triangle `t` of mesh `m` placed at `pose`.
fn off_triangle(m: &TriMesh, t: u32, pose: &Pose, p: DVec3) -> f64 {
    let tri = m.triangles().nth(t as usize).expect("triangle index");
    let local = pose.inverse().transform_point(p);
    let c = oracle::closest_point_on_triangle(local, tri.v[0], tri.v[1], tri.v[2]);
    local.distance(c)
}

#[test]
fn distance_matches_the_oracle_with_points_on_the_triangles() {
    let mut rng = StdRng::seed_from_u64(12);
    let ms = meshes();
    let mut checked = 0;
    for leaf in [1, 4] {
        let trees: Vec<ObbTree> = ms.iter().map(|m| tree(m, leaf)).collect();
        for round in 0..60 {
            let i = round % ms.len();
            let j = (round / 2 + leaf as usize) % ms.len();
            let spread = [0.3, 0.8, 2.0][round % 3];
            let pa = random_pose(&mut rng, spread);
            let pb = random_pose(&mut rng, spread);
            let d = distance(&trees[i], &pa, &trees[j], &pb, &DistanceRequest::default());
            let o = oracle::distance(&ms[i], &pa, &ms[j], &pb);
            assert!(
                (d.distance - o.distance).abs() <= 1e-12,
                "round {round} leaf {leaf}: frcd {} oracle {}",
                d.distance,
                o.distance
            );
            assert!(d.error_bound > 0.0 && d.error_bound < 1e-13);
            let (ta, tb) = d.triangles;
            assert!(off_triangle(&ms[i], ta, &pa, d.points[0]) <= 1e-12);
            assert!(off_triangle(&ms[j], tb, &pb, d.points[1]) <= 1e-12);
            assert!((d.points[0].distance(d.points[1]) - d.distance).abs() <= 1e-12);
            checked += 1;
        }
    }
    assert_eq!(checked, 120);
}

#[test]
fn within_agrees_with_exact_labels_around_the_distance() {
    let mut rng = StdRng::seed_from_u64(5);
    let ms = meshes();
    let trees: Vec<ObbTree> = ms.iter().map(|m| tree(m, 1)).collect();
    let (mut yes, mut no) = (0, 0);
    for round in 0..24 {
        let i = round % ms.len();
        let j = (round + 1) % ms.len();
        let pa = random_pose(&mut rng, 0.8);
        let pb = random_pose(&mut rng, 0.8);
        let d = distance(&trees[i], &pa, &trees[j], &pb, &DistanceRequest::default()).distance;
        for tol in [
            0.0,
            d * (1.0 - 1e-9),
            d - 1e-14,
            d,
            d + 1e-14,
            d * (1.0 + 1e-9),
            0.5 * d,
        ] {
            let tol = tol.max(0.0);
            let got = within(&trees[i], &pa, &trees[j], &pb, tol);
            let label = oracle::within_exact(&ms[i], &pa, &ms[j], &pb, tol);
            assert_eq!(got, label, "round {round} d {d} tol {tol}");
            if got {
                yes += 1;
            } else {
                no += 1;
            }
        }
        // The distance brackets the exact decision.
        assert!(within(&trees[i], &pa, &trees[j], &pb, d + 1e-12));
        if d > 1e-12 {
            assert!(!within(&trees[i], &pa, &trees[j], &pb, d - 1e-12));
        }
    }
    assert!(yes > 10 && no > 10, "yes {yes} no {no}");
}

#[test]
fn touching_and_crossing_meshes_are_at_distance_zero() {
    let cube = shapes::cuboid(DVec3::splat(0.5));
    let t = tree(&cube, 1);
    // Face to face, exactly touching.
    let pb = Pose::from_translation(DVec3::new(1.0, 0.0, 0.0));
    let d = distance(&t, &Pose::IDENTITY, &t, &pb, &DistanceRequest::default());
    assert_eq!(d.distance, 0.0);
    assert!(within(&t, &Pose::IDENTITY, &t, &pb, 0.0));
    // Overlapping.
    let pb = Pose::new(DVec3::new(0.7, 0.2, 0.1), DQuat::from_rotation_z(0.3));
    let d = distance(&t, &Pose::IDENTITY, &t, &pb, &DistanceRequest::default());
    assert_eq!(d.distance, 0.0);
    assert!(d.points[0].distance(d.points[1]) < 1e-12);
    assert!(within(&t, &Pose::IDENTITY, &t, &pb, 0.0));
    // One ulp apart: not within 0, within the gap.
    let gap = 1.0f64.next_up() - 1.0;
    let pb = Pose::from_translation(DVec3::new(1.0f64.next_up(), 0.0, 0.0));
    assert!(!within(&t, &Pose::IDENTITY, &t, &pb, 0.0));
    assert!(within(&t, &Pose::IDENTITY, &t, &pb, gap));
    assert!(!within(&t, &Pose::IDENTITY, &t, &pb, gap.next_down()));
    let d = distance(&t, &Pose::IDENTITY, &t, &pb, &DistanceRequest::default());
    assert!((d.distance - gap).abs() <= d.error_bound);
}

#[test]
fn huge_world_offsets_cost_no_precision() {
    let ms = meshes();
    let ta = tree(&ms[0], 1);
    let tb = tree(&ms[2], 1);
    let mut rng = StdRng::seed_from_u64(9);
    for _ in 0..10 {
        let pa = random_pose(&mut rng, 0.5);
        let pb = random_pose(&mut rng, 0.5);
        let near = distance(&ta, &pa, &tb, &pb, &DistanceRequest::default());
        let shift = Pose::from_translation(DVec3::new(1e6, -2e6, 3e5));
        let (fa, fb) = (shift * pa, shift * pb);
        let far = distance(&ta, &fa, &tb, &fb, &DistanceRequest::default());
        // Only the relative pose matters: same up to the rounding of composing the poses.
        assert!((near.distance - far.distance).abs() < 1e-9);
        let o = oracle::distance(&ms[0], &fa, &ms[2], &fb);
        assert!((far.distance - o.distance).abs() <= 1e-12);
    }
}

#[test]
fn relative_and_absolute_error_keep_their_promise() {
    let mut rng = StdRng::seed_from_u64(77);
    let ms = meshes();
    let trees: Vec<ObbTree> = ms.iter().map(|m| tree(m, 1)).collect();
    // Triangle pairs tested: exact, then each request. A single query may test a few more
    // with an allowance (the dives and the certificate take other paths), not the whole set.
    let mut work = [0u64; 4];
    for round in 0..30 {
        let (i, j) = (round % 4, (round + 2) % 4);
        let pa = random_pose(&mut rng, 1.5);
        let pb = random_pose(&mut rng, 1.5);
        let exact = distance(&trees[i], &pa, &trees[j], &pb, &DistanceRequest::default());
        work[0] += exact.counters.tri_tests;
        for (k, r) in [
            DistanceRequest {
                rel_err: 0.1,
                abs_err: 0.0,
            },
            DistanceRequest {
                rel_err: 0.0,
                abs_err: 0.05,
            },
            DistanceRequest {
                rel_err: 0.5,
                abs_err: 0.1,
            },
        ]
        .into_iter()
        .enumerate()
        {
            let d = distance(&trees[i], &pa, &trees[j], &pb, &r);
            work[k + 1] += d.counters.tri_tests;
            let truth = exact.distance;
            assert!(d.distance >= truth - 2.0 * exact.error_bound);
            assert!(d.distance <= truth * (1.0 + r.rel_err) + r.abs_err + 2.0 * exact.error_bound);
            assert!(off_triangle(&ms[i], d.triangles.0, &pa, d.points[0]) <= 1e-12);
        }
    }
    for k in 1..4 {
        assert!(work[k] <= work[0], "request {k}: {work:?}");
    }
}

#[test]
fn within_handles_odd_tolerances_and_counts_work() {
    let m = shapes::icosphere(1.0, 1);
    let t = tree(&m, 1);
    let pb = Pose::from_translation(DVec3::new(5.0, 0.0, 0.0));
    assert!(!within(&t, &Pose::IDENTITY, &t, &pb, -1.0));
    assert!(!within(&t, &Pose::IDENTITY, &t, &pb, f64::NAN));
    assert!(within(&t, &Pose::IDENTITY, &t, &pb, f64::INFINITY));
    assert!(within(&t, &Pose::IDENTITY, &t, &pb, 1e300));
    let (r, c) = within_counted(&t, &Pose::IDENTITY, &t, &pb, 3.5);
    assert!(r);
    assert!(c.box_tests > 0 && c.tri_tests > 0);
    // Far apart: the root bound decides.
    let (r, c) = within_counted(&t, &Pose::IDENTITY, &t, &pb, 1.0);
    assert!(!r);
    assert_eq!(c.tri_tests, 0);
}

#[test]
fn warm_start_gives_the_same_distance() {
    let ms = meshes();
    let ta = tree(&ms[2], 1);
    let tb = tree(&ms[0], 1);
    let mut cache = DistanceCache::new();
    let r = DistanceRequest::default();
    for k in 0..40 {
        let s = k as f64 / 40.0;
        let pb = Pose::new(
            DVec3::new(0.9 - 0.5 * s, 0.1, 0.05 * s),
            DQuat::from_rotation_z(0.3 * s),
        );
        let cold = distance(&ta, &Pose::IDENTITY, &tb, &pb, &r);
        let warm = distance_cached(&ta, &Pose::IDENTITY, &tb, &pb, &r, &mut cache);
        assert!((cold.distance - warm.distance).abs() <= cold.error_bound);
        assert_eq!(cache.pair(), Some(warm.triangles));
        assert!(off_triangle(&ms[2], warm.triangles.0, &Pose::IDENTITY, warm.points[0]) <= 1e-12);
    }
    // A cache from other trees is harmless.
    let other = tree(&ms[1], 1);
    let pb = Pose::from_translation(DVec3::new(2.0, 0.0, 0.0));
    let warm = distance_cached(&other, &Pose::IDENTITY, &tb, &pb, &r, &mut cache);
    let cold = distance(&other, &Pose::IDENTITY, &tb, &pb, &r);
    assert!((cold.distance - warm.distance).abs() <= cold.error_bound);
}

#[test]
fn distance_below_finds_every_pair_under_its_limit_and_none_above_it() {
    let mut rng = StdRng::seed_from_u64(31);
    let ms = meshes();
    let trees: Vec<ObbTree> = ms.iter().map(|m| tree(m, 1)).collect();
    let (mut some, mut none) = (0, 0);
    for round in 0..80 {
        let i = round % ms.len();
        let j = (round / 3) % ms.len();
        let pa = random_pose(&mut rng, 1.5);
        let pb = random_pose(&mut rng, 1.5);
        let r = DistanceRequest::default();
        let o = oracle::distance(&ms[i], &pa, &ms[j], &pb);
        for limit in [
            0.0,
            0.5 * o.distance,
            o.distance + 1e-9,
            2.0 * o.distance + 0.1,
        ] {
            match distance_below(&trees[i], &pa, &trees[j], &pb, &r, limit) {
                Some(d) => {
                    some += 1;
                    // The same answer as the unbounded search, within the oracle's tolerance.
                    assert!((d.distance - o.distance).abs() <= 1e-12, "round {round}");
                    assert!(d.distance < limit || (limit == 0.0 && d.distance == 0.0));
                }
                None => {
                    none += 1;
                    // Never `None` while the oracle's distance is below the limit.
                    assert!(
                        o.distance >= limit - 1e-12,
                        "round {round}: {} < {limit}",
                        o.distance
                    );
                    assert!(distance_below(&trees[i], &pa, &trees[j], &pb, &r, f64::NAN).is_none());
                }
            }
        }
    }
    assert!(some > 50 && none > 50, "{some} / {none}");
}
