//! The many-body World: handles, add/remove, batch updates, teleports, thread pools, against
//! the brute-force oracle.

use frcd_geom::{DQuat, DVec3, Pose, TriMesh, shapes};
use frcd_obb::{BuildOptions, ObbTree, Request, World, WorldError, WorldOptions, collide, oracle};
use rand::{Rng, SeedableRng, rngs::StdRng};
use std::sync::Arc;

fn random_pose(rng: &mut StdRng, spread: f64) -> Pose {
    let axis = DVec3::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    )
    .normalize_or(DVec3::X);
    Pose::new(
        DVec3::new(
            rng.random_range(-spread..spread),
            rng.random_range(-spread..spread),
            rng.random_range(-spread..spread),
        ),
        DQuat::from_axis_angle(axis, rng.random_range(0.0..6.3)),
    )
}

fn cube() -> Arc<ObbTree> {
    Arc::new(ObbTree::build(
        &shapes::cuboid(DVec3::ONE),
        &BuildOptions::default(),
    ))
}

#[test]
fn handles_are_generational_and_per_world() {
    let t = cube();
    let mut w = World::new(WorldOptions::default());
    let a = w.add_body(t.clone(), Pose::IDENTITY, false).unwrap();
    let b = w.add_body(t.clone(), Pose::IDENTITY, false).unwrap();
    assert_eq!(w.len(), 2);
    w.remove_body(a).unwrap();
    assert_eq!(w.len(), 1);
    assert!(!w.contains(a));
    assert_eq!(
        w.set_pose(a, Pose::IDENTITY),
        Err(WorldError::UnknownBody { id: a })
    );
    assert!(matches!(
        w.remove_body(a),
        Err(WorldError::UnknownBody { .. })
    ));
    // The slot is reused with a new generation: the old handle still does not reach it.
    let c = w.add_body(t.clone(), Pose::IDENTITY, false).unwrap();
    assert_eq!(c.index(), a.index());
    assert_ne!(c, a);
    assert_eq!(c.generation(), a.generation() + 1);
    assert!(w.pose(a).is_none() && w.pose(c).is_some());
    // A handle of another world.
    let mut other = World::new(WorldOptions::default());
    let o = other.add_body(t.clone(), Pose::IDENTITY, false).unwrap();
    assert_eq!(o.index(), 0);
    assert_eq!(
        w.set_pose(o, Pose::IDENTITY),
        Err(WorldError::ForeignBody { id: o })
    );
    assert_eq!(w.exclude_pair(b, b), Err(WorldError::SelfPair { id: b }));
    let ids: Vec<_> = w.bodies().collect();
    assert_eq!(ids, vec![c, b]);
    // Contact found between c and b (both at the origin), excluded once asked.
    assert_eq!(w.step().contacts.len(), 1);
    w.exclude_pair(c, b).unwrap();
    assert!(w.step().contacts.is_empty());
    // Removing b forgets the exclusion: a new body in b's slot is tested against c.
    w.remove_body(b).unwrap();
    let d = w.add_body(t, Pose::IDENTITY, false).unwrap();
    assert_eq!(d.index(), b.index());
    let r = w.step();
    assert_eq!((r.contacts[0].a, r.contacts[0].b), (c, d));
}

#[test]
fn batch_updates_are_all_or_nothing() {
    let t = cube();
    let mut w = World::new(WorldOptions::default());
    let a = w.add_body(t.clone(), Pose::IDENTITY, false).unwrap();
    let b = w.add_body(t, Pose::IDENTITY, false).unwrap();
    let far = Pose::from_translation(DVec3::new(10.0, 0.0, 0.0));
    let bad = Pose {
        translation: DVec3::new(f64::INFINITY, 0.0, 0.0),
        rotation: DQuat::IDENTITY,
    };
    let e = w.set_poses(&[(a, far), (b, bad)]).unwrap_err();
    assert!(
        matches!(e, WorldError::InvalidPose { id, .. } if id == b),
        "{e}"
    );
    assert_eq!(w.pose(a), Some(Pose::IDENTITY), "nothing moved");
    w.set_poses(&[(a, far), (b, Pose::IDENTITY)]).unwrap();
    assert_eq!(w.pose(a), Some(far));
    assert!(w.step().contacts.is_empty());
}

/// Random adds, removes, moves, batch moves and teleports; every step equals the oracle over
/// every live pair (not both static).
#[test]
fn random_edits_match_the_oracle() {
    let meshes: Vec<TriMesh> = vec![
        shapes::icosphere(1.0, 1),
        shapes::cuboid(DVec3::new(2.0, 0.3, 0.3)),
        shapes::cuboid(DVec3::new(0.5, 0.5, 0.5)),
    ];
    let trees: Vec<Arc<ObbTree>> = meshes
        .iter()
        .map(|m| Arc::new(ObbTree::build(m, &BuildOptions::default())))
        .collect();
    let mut rng = StdRng::seed_from_u64(17);
    let mut w = World::new(WorldOptions::default());
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    w.set_thread_pool(Some(Arc::new(pool)));
    // (handle, mesh, static)
    let mut live: Vec<(frcd_obb::BodyId, usize, bool)> = Vec::new();
    let mut removed = Vec::new();
    let mut contacts_seen = 0;
    for step in 0..40 {
        for _ in 0..rng.random_range(0..6) {
            match rng.random_range(0..10) {
                0..=2 => {
                    let m = rng.random_range(0..meshes.len());
                    let s = rng.random_range(0..5) == 0;
                    let id = w
                        .add_body(trees[m].clone(), random_pose(&mut rng, 4.0), s)
                        .unwrap();
                    live.push((id, m, s));
                }
                3 if !live.is_empty() => {
                    let k = rng.random_range(0..live.len());
                    let (id, _, _) = live.swap_remove(k);
                    w.remove_body(id).unwrap();
                    removed.push(id);
                }
                4 if !live.is_empty() => {
                    let k = rng.random_range(0..live.len());
                    w.teleport(live[k].0, random_pose(&mut rng, 4.0)).unwrap();
                }
                5 if !live.is_empty() => {
                    let batch: Vec<_> = live
                        .iter()
                        .filter(|_| rng.random_range(0..3) == 0)
                        .map(|&(id, _, _)| {
                            let p = w.pose(id).unwrap();
                            (
                                id,
                                Pose::new(p.translation + DVec3::new(0.1, -0.05, 0.0), p.rotation),
                            )
                        })
                        .collect();
                    w.set_poses(&batch).unwrap();
                }
                _ if !live.is_empty() => {
                    let k = rng.random_range(0..live.len());
                    let id = live[k].0;
                    let p = w.pose(id).unwrap();
                    let q = Pose::new(
                        p.translation + DVec3::new(0.2, 0.1, -0.1),
                        p.rotation * DQuat::from_rotation_z(0.1),
                    );
                    w.set_pose(id, q).unwrap();
                }
                _ => {}
            }
        }
        for id in &removed {
            assert!(!w.contains(*id));
        }
        let mut expected = Vec::new();
        let mut sorted = live.clone();
        sorted.sort_by_key(|x| x.0);
        for (i, &(ia, ma, sa)) in sorted.iter().enumerate() {
            for &(ib, mb, sb) in &sorted[i + 1..] {
                if sa && sb {
                    continue;
                }
                let pairs = oracle::pairs(
                    &meshes[ma],
                    &w.pose(ia).unwrap(),
                    &meshes[mb],
                    &w.pose(ib).unwrap(),
                );
                if !pairs.is_empty() {
                    expected.push((ia, ib, pairs));
                }
            }
        }
        let r = w.step();
        let got: Vec<_> = r
            .contacts
            .iter()
            .map(|c| (c.a, c.b, c.pairs.to_vec()))
            .collect();
        assert_eq!(got, expected, "step {step}");
        contacts_seen += got.len();
        assert_eq!(w.last_step().contacts.len(), expected.len());
    }
    assert!(contacts_seen > 10, "the scene interferes: {contacts_seen}");
}

#[test]
fn overlapping_pairs_with_a_margin_keep_every_close_pair() {
    let t = cube();
    let mut w = World::new(WorldOptions::default());
    let a = w.add_body(t.clone(), Pose::IDENTITY, false).unwrap();
    // Cubes of side 2 centred 2.3 apart along a diagonal: gap 0.3 on x and y, distance 0.3·√2.
    let b = w
        .add_body(t, Pose::from_translation(DVec3::new(2.3, 2.3, 0.0)), false)
        .unwrap();
    assert!(w.overlapping_pairs(0.0).is_empty());
    assert!(w.overlapping_pairs(0.29).is_empty());
    assert_eq!(w.overlapping_pairs(0.31), vec![(a, b)]);
}

/// Clearance against the brute-force oracle: every pair within its threshold (world threshold,
/// one pair with its own) is reported with the oracle's distance, interfering pairs with 0, and
/// no other pair.
#[test]
fn clearance_matches_the_oracle() {
    let meshes: Vec<TriMesh> = vec![
        shapes::icosphere(1.0, 1),
        shapes::cuboid(DVec3::new(1.5, 0.3, 0.3)),
    ];
    let trees: Vec<Arc<ObbTree>> = meshes
        .iter()
        .map(|m| Arc::new(ObbTree::build(m, &BuildOptions::default())))
        .collect();
    let mut rng = StdRng::seed_from_u64(5);
    let mut w = World::new(WorldOptions::default());
    assert!(matches!(
        w.set_clearance(Some(-1.0)),
        Err(WorldError::InvalidClearance { .. })
    ));
    let threshold = 0.4;
    w.set_clearance(Some(threshold)).unwrap();
    let mut ids = Vec::new();
    for i in 0..14 {
        let id = w
            .add_body(trees[i % 2].clone(), random_pose(&mut rng, 3.5), i == 0)
            .unwrap();
        ids.push(id);
    }
    w.set_pair_clearance(ids[1], ids[2], Some(3.0)).unwrap();
    w.set_pair_clearance(ids[3], ids[4], Some(0.0)).unwrap();
    let (mut close, mut touching) = (0, 0);
    for step in 0..4 {
        for (k, &id) in ids.iter().enumerate().skip(1) {
            let p = w.pose(id).unwrap();
            let q = Pose::new(
                p.translation + DVec3::new(0.1, -0.1, 0.05) * ((k + step) % 3) as f64,
                p.rotation * DQuat::from_rotation_x(0.2),
            );
            w.set_pose(id, q).unwrap();
        }
        let got: Vec<_> = w.step().clearances.to_vec();
        let mut expected = Vec::new();
        for i in 0..ids.len() {
            for j in i + 1..ids.len() {
                let t = match (i, j) {
                    (1, 2) => 3.0,
                    (3, 4) => 0.0,
                    _ => threshold,
                };
                let (pa, pb) = (w.pose(ids[i]).unwrap(), w.pose(ids[j]).unwrap());
                let (ma, mb) = (&meshes[i % 2], &meshes[j % 2]);
                let d = oracle::distance(ma, &pa, mb, &pb);
                let hit = !oracle::pairs(ma, &pa, mb, &pb).is_empty();
                if (d.distance - t).abs() < 1e-9 {
                    // Too close to the threshold for a float oracle: the exact one decides.
                    if !hit && !oracle::within_exact(ma, &pa, mb, &pb, t) {
                        continue;
                    }
                } else if !hit && d.distance > t {
                    continue;
                }
                expected.push((i, j, if hit { 0.0 } else { d.distance }, hit));
            }
        }
        assert_eq!(
            got.len(),
            expected.len(),
            "step {step}: {got:?} vs {expected:?}"
        );
        for (g, e) in got.iter().zip(&expected) {
            assert_eq!((g.a, g.b), (ids[e.0], ids[e.1]));
            assert_eq!(g.interfering, e.3);
            assert!((g.distance - e.2).abs() < 1e-12, "{g:?} vs {e:?}");
            // The points lie on the reported triangles, as far apart as reported.
            let (pa, pb) = (w.pose(g.a).unwrap(), w.pose(g.b).unwrap());
            let ta = meshes[e.0 % 2].triangle(g.triangles.0 as usize);
            let tb = meshes[e.1 % 2].triangle(g.triangles.1 as usize);
            let qa = pa.inverse().transform_point(g.points[0]);
            let qb = pb.inverse().transform_point(g.points[1]);
            let on = |t: &frcd_geom::Triangle, q: DVec3| {
                let c = oracle::closest_point_on_triangle(q, t.v[0], t.v[1], t.v[2]);
                (c - q).length() < 1e-9
            };
            assert!(on(&ta, qa) && on(&tb, qb), "{g:?}");
            if !g.interfering {
                assert!(((g.points[0] - g.points[1]).length() - g.distance).abs() < 1e-9);
            }
            close += 1;
            touching += g.interfering as usize;
        }
    }
    assert!(close > touching && touching > 0, "{close} {touching}");
}

/// The broad phase against all pairs of boxes: scenes strung along x, y and z and filling a
/// cube (the sweep axis follows the spread, with hysteresis), bodies moving a little, jumping,
/// teleported, removed and added, static ones among them, and a margin.
#[test]
fn overlapping_pairs_equal_all_pairs_of_boxes_along_any_axis() {
    let trees = [
        cube(),
        Arc::new(ObbTree::build(
            &shapes::cuboid(DVec3::new(1.5, 0.2, 0.4)),
            &BuildOptions::default(),
        )),
    ];
    let mut rng = StdRng::seed_from_u64(41);
    let mut w = World::new(WorldOptions::default());
    let spread_of = |layout: usize| match layout {
        0 => DVec3::new(120.0, 6.0, 6.0),
        1 => DVec3::new(6.0, 120.0, 6.0),
        2 => DVec3::new(6.0, 6.0, 120.0),
        _ => DVec3::splat(14.0),
    };
    let place = |rng: &mut StdRng, spread: DVec3| {
        let c = DVec3::new(
            rng.random_range(0.0..spread.x),
            rng.random_range(0.0..spread.y),
            rng.random_range(0.0..spread.z),
        );
        Pose::new(
            c,
            DQuat::from_axis_angle(
                DVec3::new(0.3, 0.5, 0.8).normalize(),
                rng.random_range(0.0..6.0),
            ),
        )
    };
    let mut ids = Vec::new();
    for k in 0..300 {
        let pose = place(&mut rng, spread_of(0));
        ids.push(w.add_body(trees[k % 2].clone(), pose, k % 17 == 0).unwrap());
    }
    let mut checked = 0;
    for step in 0..40 {
        let layout = step / 10;
        let spread = spread_of(layout);
        // At each new layout every body jumps there (a switch of the sweep axis).
        for (k, &id) in ids.iter().enumerate() {
            let pose = if step % 10 == 0 {
                place(&mut rng, spread)
            } else {
                let p = w.pose(id).unwrap();
                Pose::new(
                    p.translation + DVec3::splat(0.1 * ((k + step) % 3) as f64 - 0.1),
                    p.rotation,
                )
            };
            if k % 23 == 5 {
                w.teleport(id, pose).unwrap();
            } else {
                w.set_pose(id, pose).unwrap();
            }
        }
        if step % 7 == 3 {
            let gone = ids.swap_remove(rng.random_range(0..ids.len()));
            w.remove_body(gone).unwrap();
            let pose = place(&mut rng, spread);
            ids.push(w.add_body(trees[step % 2].clone(), pose, false).unwrap());
        }
        let margin = [0.0, 0.3][step % 2];
        let got = w.overlapping_pairs(margin);
        let want = all_pairs_within(&w, margin);
        assert_eq!(got, want, "step {step}");
        checked += want.len();
    }
    assert!(checked > 400, "the scenes overlap: {checked} pairs");
}

/// Many bodies filling a volume (where the broad phase lays out a grid instead of sweeping),
/// with a few large ones among them and a margin: the same pairs as all pairs of boxes.
#[test]
fn overlapping_pairs_of_a_crowded_volume_equal_all_pairs_of_boxes() {
    let small = cube();
    let large = Arc::new(ObbTree::build(
        &shapes::cuboid(DVec3::new(16.0, 0.5, 0.5)),
        &BuildOptions::default(),
    ));
    let mut rng = StdRng::seed_from_u64(7);
    let mut w = World::new(WorldOptions::default());
    let mut ids = Vec::new();
    for k in 0..1600 {
        let c = DVec3::new(
            rng.random_range(0.0..30.0),
            rng.random_range(0.0..30.0),
            rng.random_range(-1e6..-1e6 + 30.0),
        );
        let tree = if k % 200 == 0 {
            large.clone()
        } else {
            small.clone()
        };
        let pose = Pose::new(c, DQuat::from_rotation_z(rng.random_range(0.0..1.5)));
        ids.push(w.add_body(tree, pose, k % 31 == 0).unwrap());
    }
    let mut checked = 0;
    for step in 0..4 {
        for &id in &ids {
            let p = w.pose(id).unwrap();
            let d = DVec3::new(0.05, -0.03, 0.02) * step as f64;
            w.set_pose(id, Pose::new(p.translation + d, p.rotation))
                .unwrap();
        }
        let margin = [0.0, 0.25, 1.0, 0.0][step];
        let got = w.overlapping_pairs(margin);
        let want = all_pairs_within(&w, margin);
        assert_eq!(got, want, "step {step}");
        checked += want.len();
    }
    assert!(checked > 2000, "the volume is crowded: {checked} pairs");
}

/// The broad phase's kept candidates: each step a few bodies drift out of their grown boxes
/// (re-inserted one by one), a few wobble inside them, one teleports, and bodies come and go
/// (slots reused); some steps move most bodies (a fresh rebuild). Every step equals all pairs
/// of boxes, with the slack at 0, 10 and 100 percent, and the counters show each path ran.
#[test]
fn kept_candidates_equal_all_pairs_through_drift_teleports_and_removals() {
    let trees = [
        cube(),
        Arc::new(ObbTree::build(
            &shapes::cuboid(DVec3::new(3.0, 0.3, 0.3)),
            &BuildOptions::default(),
        )),
    ];
    for slack in [0, 10, 100] {
        let mut rng = StdRng::seed_from_u64(5 + slack as u64);
        let mut w = World::new(WorldOptions {
            box_slack_percent: slack,
            ..WorldOptions::default()
        });
        let place = |rng: &mut StdRng| {
            Pose::new(
                DVec3::new(
                    rng.random_range(0.0..30.0),
                    rng.random_range(0.0..30.0),
                    rng.random_range(0.0..30.0),
                ),
                DQuat::from_rotation_z(rng.random_range(0.0..3.0)),
            )
        };
        let mut ids: Vec<_> = (0..600)
            .map(|k| {
                let p = place(&mut rng);
                w.add_body(trees[usize::from(k % 9 == 0)].clone(), p, k % 41 == 0)
                    .unwrap()
            })
            .collect();
        let mut checked = 0;
        for step in 0..30 {
            let everyone = step % 10 == 9;
            for (k, &id) in ids.iter().enumerate() {
                let p = w.pose(id).unwrap();
                let d = if everyone || k % 37 == step % 37 {
                    // Out of the grown box (of the cubes, at least).
                    DVec3::new(0.9, -0.4, 0.3) * (1.0 + 2.0 * f64::from(slack) / 100.0)
                } else if k % 3 == 0 {
                    // Inside it (at 10 %).
                    DVec3::new(0.004, 0.0, -0.003) * (step % 2) as f64
                } else {
                    continue;
                };
                w.set_pose(id, Pose::new(p.translation + d, p.rotation))
                    .unwrap();
            }
            let k = rng.random_range(0..ids.len());
            w.teleport(ids[k], place(&mut rng)).unwrap();
            if step % 3 == 1 {
                let gone = ids.swap_remove(rng.random_range(0..ids.len()));
                w.remove_body(gone).unwrap();
                let p = place(&mut rng);
                ids.push(w.add_body(trees[step % 2].clone(), p, false).unwrap());
            }
            let margin = if step < 20 { 0.0 } else { 0.4 };
            let got = w.overlapping_pairs(margin);
            let want = all_pairs_within(&w, margin);
            assert_eq!(got, want, "slack {slack} %, step {step}");
            checked += want.len();
        }
        let stats = w.broad_stats();
        assert!(checked > 1000, "the scene overlaps: {checked} pairs");
        assert!(stats.reinserted > 200, "slack {slack} %: {stats:?}");
        assert!(stats.tree_builds >= 1, "slack {slack} %: {stats:?}");
        // Grown boxes: the first step, the margin change and the three steps that move
        // everyone. Tight boxes: also every step where a third of the bodies wobble.
        let rebuilds = if slack == 0 { 10..=20 } else { 4..=6 };
        assert!(
            rebuilds.contains(&stats.rebuilds),
            "slack {slack} %: {stats:?}"
        );
    }
}

/// Incoherent motion: runs of steps in which every body jumps anew (the second step of a run
/// on finds its pairs with the bodies' own boxes), broken by calm steps, steps where nothing
/// moves, bodies coming and going and a margin change in the middle of a run. Every step
/// equals all pairs of boxes, and the counters show the tight rebuilds ran (none for a single
/// jump, which keeps grown boxes for the calm steps after it) and that the first calm step after
/// a run rebuilds the grown-box candidates.
#[test]
fn incoherent_runs_find_pairs_with_tight_boxes_and_calm_steps_recover() {
    let mut rng = StdRng::seed_from_u64(77);
    let mut w = World::new(WorldOptions::default());
    let tree = cube();
    let place = |rng: &mut StdRng| {
        Pose::new(
            DVec3::new(
                rng.random_range(0.0..25.0),
                rng.random_range(0.0..25.0),
                rng.random_range(0.0..25.0),
            ),
            DQuat::from_rotation_z(rng.random_range(0.0..3.0)),
        )
    };
    let mut ids: Vec<_> = (0..400)
        .map(|_| w.add_body(tree.clone(), place(&mut rng), false).unwrap())
        .collect();
    // Per step: J jump (every body anew), C calm (a third wobble inside their grown boxes),
    // S still (nothing moves).
    let plan = "JCCJJJJSCCJJJJJSSCCJJCJJJCC";
    let mut checked = 0;
    let mut calm_rebuilds = Vec::new();
    for (step, what) in plan.chars().enumerate() {
        match what {
            'J' => {
                for &id in &ids {
                    w.set_pose(id, place(&mut rng)).unwrap();
                }
            }
            'C' => {
                for &id in ids.iter().skip(step % 3).step_by(3) {
                    let p = w.pose(id).unwrap();
                    let d = DVec3::new(0.01, -0.005, 0.0) * if step % 2 == 0 { 1.0 } else { -1.0 };
                    w.set_pose(id, Pose::new(p.translation + d, p.rotation))
                        .unwrap();
                }
            }
            _ => {}
        }
        if step == 12 || step == 22 {
            // Bodies come and go in the middle of a run.
            for _ in 0..5 {
                let gone = ids.swap_remove(rng.random_range(0..ids.len()));
                w.remove_body(gone).unwrap();
            }
            for _ in 0..3 {
                ids.push(w.add_body(tree.clone(), place(&mut rng), false).unwrap());
            }
        }
        let margin = if step < 13 { 0.0 } else { 0.3 };
        let rebuilds = w.broad_stats().rebuilds;
        let got = w.overlapping_pairs(margin);
        let want = all_pairs_within(&w, margin);
        assert_eq!(got, want, "step {step} ({what})");
        checked += want.len();
        if what == 'C' {
            calm_rebuilds.push((step, w.broad_stats().rebuilds - rebuilds));
        }
        if what == 'S' {
            // Nothing moved: no work, whatever the candidates were found with.
            assert_eq!(w.broad_stats().rebuilds, rebuilds, "step {step}");
        }
    }
    let stats = w.broad_stats();
    assert!(checked > 3000, "the scene overlaps: {checked} pairs");
    // Runs JJJJ (steps 3-6), JJJJJ (10-14), JJ (19-20), JJJ (22-24): each run's first jump
    // rebuilds with grown boxes, the later ones with tight boxes; the margin change at step 13
    // rebuilds with grown boxes and starts the count again, so step 14 is a first jump too:
    // 3 + 2 + 1 + 2.
    assert_eq!(stats.tight_rebuilds, 8, "{stats:?}");
    // A calm step rebuilds (grown boxes again) exactly when the candidates before it were
    // tight: after step 6 (a still step between), 20 and 24; not after step 0's first
    // rebuild, nor after step 14's grown-box rebuild.
    let want = [
        (1, 0),
        (2, 0),
        (8, 1),
        (9, 0),
        (17, 0),
        (18, 0),
        (21, 1),
        (25, 1),
        (26, 0),
    ];
    assert_eq!(calm_rebuilds, want);
}

/// A slack beyond `MAX_BOX_SLACK_PERCENT` acts as that maximum: the same pairs and the same
/// broad-phase work as at the maximum (without the cap, grown boxes as large as the scene would
/// keep about every pair of bodies as a candidate).
#[test]
fn a_huge_slack_acts_as_the_maximum() {
    let make = |slack| {
        World::new(WorldOptions {
            box_slack_percent: slack,
            ..WorldOptions::default()
        })
    };
    let (mut capped, mut huge) = (make(frcd_obb::MAX_BOX_SLACK_PERCENT), make(u32::MAX));
    let mut rng = StdRng::seed_from_u64(9);
    let mut ids = Vec::new();
    for _ in 0..200 {
        let p = random_pose(&mut rng, 12.0);
        ids.push((
            capped.add_body(cube(), p, false).unwrap(),
            huge.add_body(cube(), p, false).unwrap(),
        ));
    }
    for step in 0..10 {
        for (k, &(a, b)) in ids.iter().enumerate() {
            if k % 4 == step % 4 {
                let p = random_pose(&mut rng, 12.0);
                capped.set_pose(a, p).unwrap();
                huge.set_pose(b, p).unwrap();
            }
        }
        let got = huge.overlapping_pairs(0.1);
        assert_eq!(got, all_pairs_within(&huge, 0.1), "step {step}");
        // Handles carry their world: compare slots.
        let slots = |v: Vec<(frcd_obb::BodyId, frcd_obb::BodyId)>| -> Vec<(u32, u32)> {
            v.into_iter().map(|(a, b)| (a.index(), b.index())).collect()
        };
        assert_eq!(
            slots(got),
            slots(capped.overlapping_pairs(0.1)),
            "step {step}"
        );
    }
    assert_eq!(huge.broad_stats(), capped.broad_stats());
}

/// `overlapping_boxes` against all pairs: boxes of mixed sizes (a few long ones) filling a
/// cube (the grid) and strung along z (the sweep), with and without a margin.
#[test]
fn overlapping_boxes_equal_all_pairs() {
    use frcd_geom::Aabb;
    let mut rng = StdRng::seed_from_u64(3);
    for (n, spread) in [
        (1800, DVec3::splat(25.0)),
        (400, DVec3::new(3.0, 3.0, 150.0)),
    ] {
        let boxes: Vec<Aabb> = (0..n)
            .map(|k| {
                let c = DVec3::new(
                    rng.random_range(0.0..spread.x),
                    rng.random_range(0.0..spread.y),
                    rng.random_range(0.0..spread.z),
                );
                let half = if k % 97 == 0 {
                    DVec3::new(12.0, 0.4, 0.4)
                } else if k % 211 == 3 {
                    // Inverted (min > max): still paired by the formula, never a panic.
                    DVec3::new(-0.5, 0.6, 0.6)
                } else if k % 23 == 7 {
                    // Inverted along z, the strung boxes' sweep axis: a box sorted before it
                    // may start past its end (the sweep once paired those).
                    DVec3::new(0.6, 0.6, -0.5)
                } else {
                    DVec3::new(
                        rng.random_range(0.1..0.9),
                        rng.random_range(0.1..0.9),
                        rng.random_range(0.1..0.9),
                    )
                };
                Aabb::new(c - half, c + half)
            })
            .collect();
        for margin in [0.0, 0.3] {
            let mut want = Vec::new();
            for i in 0..n {
                for j in i + 1..n {
                    if boxes_within(&boxes[i], &boxes[j], margin) {
                        want.push((i as u32, j as u32));
                    }
                }
            }
            let got = frcd_obb::overlapping_boxes(&boxes, margin);
            assert_eq!(got, want, "{n} boxes, margin {margin}");
            assert!(want.len() > n / 4, "{n} boxes overlap: {}", want.len());
        }
    }
    assert!(frcd_obb::overlapping_boxes(&[], 0.0).is_empty());
}

/// Two crowded clusters far apart: the grid's cells are then many next to its entries (the
/// entries are sorted, not counted into cells), and the pairs still equal all pairs.
#[test]
fn overlapping_boxes_of_far_clusters_equal_all_pairs() {
    use frcd_geom::Aabb;
    let mut rng = StdRng::seed_from_u64(11);
    let boxes: Vec<Aabb> = (0..2200)
        .map(|k| {
            let offset = if k % 2 == 0 { 0.0 } else { 1e5 };
            let c = DVec3::new(
                offset + rng.random_range(0.0..12.0),
                rng.random_range(0.0..12.0),
                rng.random_range(0.0..12.0),
            );
            Aabb::new(c - DVec3::splat(0.6), c + DVec3::splat(0.6))
        })
        .collect();
    let mut want = Vec::new();
    for i in 0..boxes.len() {
        for j in i + 1..boxes.len() {
            if boxes_within(&boxes[i], &boxes[j], 0.1) {
                want.push((i as u32, j as u32));
            }
        }
    }
    assert!(
        want.len() > 2200,
        "the clusters are crowded: {}",
        want.len()
    );
    assert_eq!(frcd_obb::overlapping_boxes(&boxes, 0.1), want);
}

/// Whether two boxes are within `margin` of each other on every axis, written as the broad
/// phase writes it (`min - max > margin` is apart), so the comparison is exact.
fn boxes_within(a: &frcd_geom::Aabb, b: &frcd_geom::Aabb, margin: f64) -> bool {
    !(0..3).any(|k| a.min[k] - b.max[k] > margin || b.min[k] - a.max[k] > margin)
}

/// `World::overlapping_pairs` by brute force: every tested pair of live bodies whose boxes are
/// within `margin`, as `(lower slot, higher slot)`, sorted.
fn all_pairs_within(w: &World, margin: f64) -> Vec<(frcd_obb::BodyId, frcd_obb::BodyId)> {
    let live: Vec<_> = w.bodies().collect();
    let mut want = Vec::new();
    for (i, &a) in live.iter().enumerate() {
        for &b in &live[i + 1..] {
            let (ba, bb) = (w.body_aabb(a).unwrap(), w.body_aabb(b).unwrap());
            if boxes_within(&ba, &bb, margin) && w.is_pair_tested(a, b) {
                want.push(if a.index() < b.index() {
                    (a, b)
                } else {
                    (b, a)
                });
            }
        }
    }
    want.sort_unstable_by_key(|&(a, b)| (a.index(), b.index()));
    want
}

/// A pose whose quaternion is a little off unit length (within what `Pose::is_valid` and the
/// World accept) must give the World the same contacts as `collide` with the same poses: the
/// broad phase's world boxes and the narrow phase must map a body by the same rigid motion.
/// The quaternion `(0, 0, 0, s)`, `s² = 1 + 9·10⁻¹⁰`, turns nothing, but `q * v` scales by `s²`:
/// a body whose triangles sit 1,000 units from its own origin got a world box shifted by about
/// 10⁻⁶ from its triangles, and the World missed a contact `collide` reported (this test failed
/// so before `Pose::rigid`). The same with the off-unit quaternion on the frame body A, whose
/// inverse scaled the relative translation.
#[test]
fn nearly_unit_quaternions_keep_world_boxes_around_their_bodies() {
    let cube = shapes::cuboid(DVec3::splat(0.5));
    let a = Arc::new(ObbTree::build(&cube, &BuildOptions::default()));
    let far = cube.transformed(&Pose::new(DVec3::new(1000.0, 0.0, 0.0), DQuat::IDENTITY));
    let b = Arc::new(ObbTree::build(&far, &BuildOptions::default()));
    let s = (1.0f64 + 9e-10).sqrt();
    let off = DQuat::from_xyzw(0.0, 0.0, 0.0, s);
    for (qa, qb) in [(DQuat::IDENTITY, off), (off, DQuat::IDENTITY), (off, off)] {
        for overlap in [1e-7, 1e-8, 0.0, -1e-7] {
            // A's cube spans x in [1999.5, 2000.5], B's (1,000 from its origin) is placed to
            // overlap it by `overlap` (a gap when negative).
            let pose_a = Pose {
                translation: DVec3::new(2000.0, 0.0, 0.0),
                rotation: qa,
            };
            let pose_b = Pose {
                translation: DVec3::new(2000.5 - 999.5 - overlap, 0.0, 0.0),
                rotation: qb,
            };
            assert!(pose_a.is_valid() && pose_b.is_valid());
            let direct = collide(&a, &pose_a, &b, &pose_b, &Request::default()).collide;
            assert_eq!(direct, overlap >= 0.0, "overlap {overlap:e}");
            let mut world = World::new(WorldOptions::default());
            world.add_body(a.clone(), pose_a, false).unwrap();
            world.add_body(b.clone(), pose_b, false).unwrap();
            let stepped = !world.step().contacts.is_empty();
            assert_eq!(stepped, direct, "overlap {overlap:e}, {qa:?} {qb:?}");
        }
    }
}

/// `set_poses` (which computes four world boxes at once) leaves a World exactly as one
/// `set_pose` per update does: the same poses, the same boxes bit for bit, the same pairs and
/// contacts. The batches name some bodies twice (in the same group of four and across
/// groups), repeat unchanged poses, use off-unit quaternions, and leave remainders of one to
/// three updates; the bodies use meshes of different sizes.
#[test]
fn batched_poses_equal_one_update_at_a_time() {
    let mut rng = StdRng::seed_from_u64(0xB0C5);
    let trees = [
        cube(),
        Arc::new(ObbTree::build(
            &shapes::icosphere(0.7, 1),
            &BuildOptions::default(),
        )),
        Arc::new(ObbTree::build(
            &shapes::cuboid(DVec3::new(3.0, 0.2, 0.5)),
            &BuildOptions::default(),
        )),
    ];
    let (mut batched, mut single) = (
        World::new(WorldOptions::default()),
        World::new(WorldOptions::default()),
    );
    let mut ids = Vec::new();
    for k in 0..23 {
        let pose = random_pose(&mut rng, 6.0);
        let a = batched
            .add_body(trees[k % 3].clone(), pose, k % 7 == 0)
            .unwrap();
        let b = single
            .add_body(trees[k % 3].clone(), pose, k % 7 == 0)
            .unwrap();
        ids.push((a, b));
    }
    for step in 0..40 {
        let len = rng.random_range(0..(ids.len() + 6));
        let mut batch_a = Vec::new();
        let mut batch_b = Vec::new();
        for _ in 0..len {
            let (a, b) = ids[rng.random_range(0..ids.len())];
            let pose = match rng.random_range(0..4) {
                // The pose it has (nothing moves).
                0 => batched.pose(a).unwrap(),
                // A quaternion off unit length, inside the World's tolerance.
                1 => {
                    let p = random_pose(&mut rng, 6.0);
                    Pose {
                        translation: p.translation,
                        rotation: p.rotation * (1.0 + 3e-10),
                    }
                }
                _ => random_pose(&mut rng, 6.0),
            };
            batch_a.push((a, pose));
            batch_b.push((b, pose));
        }
        // A body named twice in a row, inside one group of four.
        if let [.., (a, _), (b, _)] = batch_a[..] {
            let again = random_pose(&mut rng, 6.0);
            batch_a.push((a, again));
            batch_a.push((b, again));
            let n = batch_b.len();
            let (a2, b2) = (batch_b[n - 2].0, batch_b[n - 1].0);
            batch_b.push((a2, again));
            batch_b.push((b2, again));
        }
        batched.set_poses(&batch_a).unwrap();
        for &(b, pose) in &batch_b {
            single.set_pose(b, pose).unwrap();
        }
        for &(a, b) in &ids {
            assert_eq!(batched.pose(a), single.pose(b), "step {step}");
            let (ba, bb) = (batched.body_aabb(a).unwrap(), single.body_aabb(b).unwrap());
            assert_eq!(
                (
                    ba.min.to_array().map(f64::to_bits),
                    ba.max.to_array().map(f64::to_bits)
                ),
                (
                    bb.min.to_array().map(f64::to_bits),
                    bb.max.to_array().map(f64::to_bits)
                ),
                "step {step}: the box of {a:?}"
            );
        }
        let index = |w: &World, list: Vec<_>| -> Vec<(usize, usize)> {
            let order: Vec<_> = w.bodies().collect();
            let at = |id| order.iter().position(|&x| x == id).unwrap();
            list.into_iter().map(|(x, y)| (at(x), at(y))).collect()
        };
        let pa = batched.overlapping_pairs(0.0);
        let pb = single.overlapping_pairs(0.0);
        assert_eq!(index(&batched, pa), index(&single, pb), "step {step}");
        let ca = batched.step().contacts.len();
        let cb = single.step().contacts.len();
        assert_eq!(ca, cb, "step {step}");
    }
}

/// `overlapping_pairs_into` gives what `overlapping_pairs` gives, into the caller's list
/// (cleared first, its allocation kept), through moves, removals and additions.
#[test]
fn pairs_into_a_kept_list_equal_the_returned_ones() {
    let mut rng = StdRng::seed_from_u64(0x1470);
    let mut w = World::new(WorldOptions::default());
    let mut ids: Vec<_> = (0..60)
        .map(|_| {
            w.add_body(cube(), random_pose(&mut rng, 5.0), false)
                .unwrap()
        })
        .collect();
    let mut kept = vec![(ids[0], ids[1]); 500];
    for step in 0..30 {
        for &id in ids.iter().step_by(1 + step % 4) {
            w.set_pose(id, random_pose(&mut rng, 5.0)).unwrap();
        }
        if step % 7 == 3 {
            w.remove_body(ids.swap_remove(step % ids.len())).unwrap();
            ids.push(
                w.add_body(cube(), random_pose(&mut rng, 5.0), false)
                    .unwrap(),
            );
        }
        let margin = [0.0, 0.3][step % 2];
        let capacity = kept.capacity();
        w.overlapping_pairs_into(margin, &mut kept);
        let returned = w.overlapping_pairs(margin);
        assert_eq!(kept, returned, "step {step}");
        assert!(!returned.is_empty(), "step {step}: the scene has pairs");
        assert_eq!(
            kept.capacity(),
            capacity,
            "the list is reused, not replaced"
        );
    }
}
