//! GPU tests: every answer compared with the exact CPU oracle (`frcd_obb::oracle`), on the
//! software adapter where no GPU exists. Without any adapter they print `SKIP` and pass, unless
//! `FRCD_REQUIRE_GPU=1`, where they fail.

use frcd_geom::shapes::{self, TorusKnotParams};
use frcd_geom::{Aabb, DQuat, DVec3, Pose, TriMesh};
use frcd_gpgpu::{
    ArenaOptions, BoxScratch, GpuContext, GpuError, GpuMesh, HeadlessOptions, QueryScratch,
};
use frcd_obb::{BuildOptions, ObbTree, oracle};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::sync::OnceLock;

fn require_gpu() -> bool {
    std::env::var("FRCD_REQUIRE_GPU").is_ok_and(|v| v == "1")
}

/// A context with the triangle pass's exact path on (its default on hardware adapters; the
/// software adapter these tests usually run on defaults to the rotated path), so every test
/// below checks the exact path against the oracle; the rotated path has its own tests.
fn new_context() -> Option<GpuContext> {
    match GpuContext::headless() {
        Ok(mut c) => {
            c.set_exact_offsets(true);
            Some(c)
        }
        Err(e) => {
            assert!(
                !require_gpu(),
                "FRCD_REQUIRE_GPU=1 but no usable adapter: {e}"
            );
            println!("SKIP frcd-gpgpu GPU test: {e}");
            None
        }
    }
}

/// One context shared by the tests that do not count submissions.
fn shared() -> Option<&'static GpuContext> {
    static CTX: OnceLock<Option<GpuContext>> = OnceLock::new();
    CTX.get_or_init(new_context).as_ref()
}

fn tree(mesh: &TriMesh) -> ObbTree {
    ObbTree::build(mesh, &BuildOptions::default())
}

/// A random unit axis (Z for the rare near-zero draw).
fn random_axis(rng: &mut StdRng) -> DVec3 {
    DVec3::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    )
    .normalize_or(DVec3::Z)
}

/// `n` random poses (seeded): x and y within ±`xy`, z within ±`z`, any rotation.
fn scattered_poses(seed: u64, n: usize, xy: f64, z: f64) -> Vec<Pose> {
    let mut rng = StdRng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let axis = random_axis(&mut rng);
            Pose::new(
                DVec3::new(
                    rng.random_range(-xy..xy),
                    rng.random_range(-xy..xy),
                    rng.random_range(-z..z),
                ),
                DQuat::from_axis_angle(axis, rng.random_range(0.0..6.0)),
            )
        })
        .collect()
}

struct Body {
    mesh: TriMesh,
    gpu: GpuMesh,
}

fn body(ctx: &GpuContext, mesh: TriMesh) -> Body {
    let gpu = ctx.upload(&tree(&mesh)).expect("upload");
    Body { mesh, gpu }
}

/// Runs the GPU query and the oracle at each pose pair; returns (total pairs, total uncertain).
/// With `check_decided`, also checks that the GPU decided most touching pairs itself (the CPU
/// fallback is the exception, not the rule).
fn agree(
    ctx: &GpuContext,
    a: &Body,
    b: &Body,
    poses: &[(Pose, Pose)],
    scratch: &mut QueryScratch,
    check_decided: bool,
) -> (usize, usize) {
    let mut total = (0, 0);
    let mut decided = 0;
    for (k, (pa, pb)) in poses.iter().enumerate() {
        let gpu = ctx
            .collide(&a.gpu, pa, &b.gpu, pb, scratch)
            .unwrap_or_else(|e| panic!("pose {k}: {e}"));
        let want = oracle::pairs(&a.mesh, pa, &b.mesh, pb);
        if gpu.pairs != want {
            let extra: Vec<_> = gpu.pairs.iter().filter(|p| !want.contains(p)).collect();
            let missing: Vec<_> = want.iter().filter(|p| !gpu.pairs.contains(p)).collect();
            panic!(
                "pose {k} ({pa:?}, {pb:?}): GPU {} pairs, oracle {}; extra {:?}, missing {:?}",
                gpu.pairs.len(),
                want.len(),
                &extra[..extra.len().min(8)],
                &missing[..missing.len().min(8)]
            );
        }
        total.0 += want.len();
        total.1 += gpu.uncertain;
        decided += gpu.gpu_decided;
    }
    if check_decided {
        assert!(
            decided * 2 > total.0,
            "the GPU decided only {decided} of {} touching pairs",
            total.0
        );
    }
    total
}

#[test]
fn icospheres_through_each_other() {
    let Some(ctx) = shared() else { return };
    let a = body(ctx, shapes::icosphere(1.0, 3));
    let b = body(ctx, shapes::icosphere(0.8, 3));
    let poses: Vec<(Pose, Pose)> = (0..9)
        .map(|k| {
            let s = k as f64 / 8.0;
            (
                Pose::IDENTITY,
                Pose::new(
                    DVec3::new(-2.0 + 4.0 * s, 0.13, -0.07),
                    DQuat::from_rotation_z(0.7 * s) * DQuat::from_rotation_x(0.4),
                ),
            )
        })
        .collect();
    let (pairs, _) = agree(ctx, &a, &b, &poses, &mut QueryScratch::default(), true);
    assert!(pairs > 100, "the sweep must produce contacts, got {pairs}");
}

#[test]
fn torus_knots_in_near_contact() {
    let Some(ctx) = shared() else { return };
    let knot = shapes::torus_knot(&TorusKnotParams::default()).expect("knot");
    let a = body(ctx, knot.clone());
    let b = body(ctx, knot);
    // Stacked along z by about two tube radii: grazing contact along many strands, plus
    // tiny rotations that open and close the gaps.
    let r = TorusKnotParams::default().tube_radius;
    let mut poses = Vec::new();
    for (k, dz) in [2.0 * r - 1e-3, 2.0 * r, 2.0 * r + 1e-9, 1.9 * r]
        .into_iter()
        .enumerate()
    {
        let at = Pose::new(DVec3::new(1e5, -2e5, 3e4), DQuat::from_rotation_y(0.2));
        let rel = Pose::new(
            DVec3::new(0.0, 0.0, dz),
            DQuat::from_rotation_z(1e-3 * k as f64),
        );
        poses.push((at, at.compose(&rel)));
    }
    let (pairs, _) = agree(ctx, &a, &b, &poses, &mut QueryScratch::default(), true);
    assert!(pairs > 0);
}

#[test]
fn random_rotations() {
    let Some(ctx) = shared() else { return };
    let a = body(ctx, shapes::icosphere(1.0, 2));
    let b = body(ctx, shapes::torus(0.8, 0.25, 32, 12).expect("torus"));
    let c = body(ctx, shapes::cuboid(DVec3::new(0.9, 0.4, 0.2)));
    let mut rng = StdRng::seed_from_u64(7);
    let mut rot = || {
        let axis = DVec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        let axis = if axis.length() < 1e-3 {
            DVec3::X
        } else {
            axis.normalize()
        };
        (
            axis,
            rng.random_range(0.0..6.3),
            rng.random_range(-1.6..1.6),
        )
    };
    let mut poses = Vec::new();
    for _ in 0..12 {
        let (ax1, an1, _) = rot();
        let (ax2, an2, off) = rot();
        poses.push((
            Pose::new(DVec3::new(0.3, -0.2, 0.1), DQuat::from_axis_angle(ax1, an1)),
            Pose::new(
                DVec3::new(off, 0.5 * off, 0.0),
                DQuat::from_axis_angle(ax2, an2),
            ),
        ));
    }
    let mut scratch = QueryScratch::default();
    let (p1, _) = agree(ctx, &a, &b, &poses, &mut scratch, true);
    let (p2, _) = agree(ctx, &c, &b, &poses, &mut scratch, true);
    let (p3, _) = agree(ctx, &a, &a, &poses, &mut scratch, true);
    assert!(p1 + p2 + p3 > 0);
}

#[test]
fn touching_and_coplanar_configurations_go_to_the_exact_test() {
    let Some(ctx) = shared() else { return };
    let h = DVec3::new(0.5, 0.5, 0.5);
    // Cubes whose local origin is far away: large local coordinates.
    let far = Pose::from_translation(DVec3::new(1000.0, -250.0, 31.0));
    let a = body(ctx, shapes::cuboid(h).transformed(&far));
    let b = body(ctx, shapes::cuboid(h));
    let inv = far;
    let place = |t: DVec3, q: DQuat| (Pose::IDENTITY, inv.compose(&Pose::new(t, q)));
    let poses = vec![
        // Face to face, coplanar contact.
        place(DVec3::new(1.0, 0.0, 0.0), DQuat::IDENTITY),
        // Face to face, shifted half a side: coplanar overlap with crossing edges.
        place(DVec3::new(1.0, 0.5, 0.25), DQuat::IDENTITY),
        // Edge on face.
        place(
            DVec3::new(0.5 + 0.5 * 2f64.sqrt(), 0.0, 0.0),
            DQuat::from_rotation_z(std::f64::consts::FRAC_PI_4),
        ),
        // Apart by one ulp-ish gap.
        place(DVec3::new(1.0 + 1e-12, 0.0, 0.0), DQuat::IDENTITY),
        // Identical boxes (every face coplanar with one of the other's).
        place(DVec3::ZERO, DQuat::IDENTITY),
    ];
    let (pairs, uncertain) = agree(ctx, &a, &b, &poses, &mut QueryScratch::default(), false);
    assert!(pairs > 0);
    assert!(
        uncertain > 0,
        "coplanar contact must reach the CPU's exact test"
    );
}

#[test]
fn random_triangle_soups_all_pairs() {
    // Many small random triangles through each other: almost every configuration the
    // orientation form meets (each permutation branch) is exercised against the exact test.
    let Some(ctx) = shared() else { return };
    let mut rng = StdRng::seed_from_u64(42);
    let mut soup = |n: usize, size: f64| {
        let tris: Vec<[DVec3; 3]> = (0..n)
            .map(|_| {
                let c = DVec3::new(
                    rng.random_range(0.0..1.0),
                    rng.random_range(0.0..1.0),
                    rng.random_range(0.0..1.0),
                );
                let mut v = || {
                    c + size
                        * DVec3::new(
                            rng.random_range(-1.0..1.0),
                            rng.random_range(-1.0..1.0),
                            rng.random_range(-1.0..1.0),
                        )
                };
                [v(), v(), v()]
            })
            .collect();
        TriMesh::from_triangle_soup(&tris).expect("soup")
    };
    let a = body(ctx, soup(400, 0.12));
    let b = body(ctx, soup(400, 0.12));
    let poses = vec![
        (Pose::IDENTITY, Pose::IDENTITY),
        (
            Pose::IDENTITY,
            Pose::new(DVec3::new(0.05, -0.02, 0.1), DQuat::from_rotation_y(0.3)),
        ),
        (
            Pose::from_translation(DVec3::splat(-7.0)),
            Pose::new(DVec3::splat(-7.1), DQuat::from_rotation_x(2.0)),
        ),
    ];
    let (pairs, _) = agree(ctx, &a, &b, &poses, &mut QueryScratch::default(), true);
    assert!(pairs > 500, "{pairs}");
}

#[test]
fn one_submission_and_one_readback_per_query() {
    let Some(ctx) = new_context() else { return };
    let a = body(&ctx, shapes::icosphere(1.0, 3));
    let mut scratch = QueryScratch::with_capacity(1 << 16, 1 << 14);
    let pa = Pose::IDENTITY;
    for k in 0..4 {
        let pb = Pose::from_translation(DVec3::new(0.5 + 0.5 * k as f64, 0.1, 0.0));
        let (s0, r0) = (ctx.submissions(), ctx.readbacks());
        let got = ctx.collide(&a.gpu, &pa, &a.gpu, &pb, &mut scratch).unwrap();
        assert_eq!(ctx.submissions() - s0, 1, "query {k}");
        assert_eq!(ctx.readbacks() - r0, 1, "query {k}");
        assert_eq!((got.submissions, got.readbacks, got.reruns), (1, 1, 0));
        let want = oracle::pairs(&a.mesh, &pa, &a.mesh, &pb);
        assert_eq!(got.pairs, want);
        // (Spheres apart by their bounds are refused before any box test.)
        assert!(want.is_empty() || got.node_pairs_tested >= 1);
    }
}

/// Checks that a batch's level counters add up: each body pair's breadth-first descent is its
/// own, so the batch tests the node pairs of its pairs run one by one (their sum) over as many
/// levels as the deepest; and a scratch whose buffers hold a larger batch's frontiers and
/// counters gives the same batch the same counts and pairs as a fresh one. The levels count
/// and zero their own frontier sizes and dispatch arguments (no control pass between them), so
/// a size left from an earlier level or batch would show here as node pairs tested twice.
fn level_counts_add_up(ctx: &GpuContext, a: &Body, poses: &[(Pose, Pose)]) {
    fn batch<'p>(a: &'p Body, poses: &'p [(Pose, Pose)]) -> Vec<frcd_gpgpu::BodyPair<'p>> {
        poses
            .iter()
            .map(|(pa, pb)| (&a.gpu, pa, &a.gpu, pb))
            .collect()
    }
    let small = &poses[..poses.len() / 2];
    let fresh = ctx
        .collide_batch(&batch(a, small), &mut QueryScratch::default())
        .expect("fresh scratch");
    let (mut tested, mut levels) = (0, 0);
    for (k, (pa, pb)) in small.iter().enumerate() {
        let one = ctx
            .collide(&a.gpu, pa, &a.gpu, pb, &mut QueryScratch::default())
            .expect("one pair");
        assert_eq!(
            one.pairs,
            oracle::pairs(&a.mesh, pa, &a.mesh, pb),
            "pair {k}"
        );
        assert_eq!(one.pairs, fresh.results[k].pairs, "pair {k}");
        tested += one.node_pairs_tested;
        levels = levels.max(one.levels);
    }
    assert!(
        levels >= 3,
        "{levels} levels: too shallow to test the rotation"
    );
    assert_eq!(fresh.node_pairs_tested, tested);
    assert_eq!(fresh.levels, levels);
    let mut used = QueryScratch::default();
    for round in 0..2 {
        let big = ctx.collide_batch(&batch(a, poses), &mut used).expect("big");
        assert!(big.node_pairs_tested > fresh.node_pairs_tested);
        let again = ctx
            .collide_batch(&batch(a, small), &mut used)
            .expect("again");
        assert_eq!(
            (again.node_pairs_tested, again.levels),
            (fresh.node_pairs_tested, fresh.levels),
            "round {round}"
        );
        for (k, (x, y)) in again.results.iter().zip(&fresh.results).enumerate() {
            assert_eq!(x.pairs, y.pairs, "round {round}, pair {k}");
        }
    }
}

#[test]
fn level_counters_add_up_and_reused_scratch_changes_nothing() {
    // The GPU's own levels from the roots: no CPU front (whose budget is the batch's, so a
    // batch's front is not the sum of its pairs' fronts).
    let Some(mut ctx) = new_context() else { return };
    ctx.set_host_front(0);
    let ctx = &ctx;
    let a = body(ctx, shapes::icosphere(1.0, 3));
    let poses: Vec<(Pose, Pose)> = (0..6)
        .map(|k| {
            let s = k as f64 / 6.0;
            let dir = DVec3::new((6.0 * s).cos(), (6.0 * s).sin(), 0.3 - s).normalize();
            (
                Pose::IDENTITY,
                Pose::new((0.6 + 0.2 * s) * dir, DQuat::from_rotation_z(s)),
            )
        })
        .collect();
    level_counts_add_up(ctx, &a, &poses);
}

#[test]
fn overflow_is_detected_and_the_query_rerun() {
    let Some(ctx) = new_context() else { return };
    let a = body(&ctx, shapes::icosphere(1.0, 3));
    let pb = Pose::new(DVec3::new(0.9, 0.2, 0.0), DQuat::from_rotation_y(0.5));
    let want = oracle::pairs(&a.mesh, &Pose::IDENTITY, &a.mesh, &pb);
    assert!(want.len() > 10);
    // Both buffers far too small: frontier of 1 pair, output of 1 pair.
    let mut scratch = QueryScratch::with_capacity(1, 1);
    let s0 = ctx.submissions();
    let got = ctx
        .collide(&a.gpu, &Pose::IDENTITY, &a.gpu, &pb, &mut scratch)
        .unwrap();
    assert_eq!(got.pairs, want, "never a truncated answer");
    assert!(got.reruns >= 1);
    assert_eq!(got.submissions, 1 + got.reruns);
    assert_eq!(got.readbacks, got.submissions);
    assert_eq!(ctx.submissions() - s0, got.submissions as u64);
    let (f, o) = scratch.capacity();
    assert!(f > 1 && o as usize >= want.len());
    // The grown scratch is kept: the same query now needs one submission.
    let again = ctx
        .collide(&a.gpu, &Pose::IDENTITY, &a.gpu, &pb, &mut scratch)
        .unwrap();
    assert_eq!(again.pairs, want);
    assert_eq!((again.submissions, again.reruns), (1, 0));
}

#[test]
fn meshes_split_across_rows_and_layers() {
    // A tiny arena (3 items per row, rounded down to 2, and 4 rows per layer): every mesh spans
    // many rows and layers, and the arena grows (a GPU copy of the old layers) several times
    // while meshes are in use.
    let opts = HeadlessOptions {
        arena: ArenaOptions {
            items_per_row: Some(3),
            rows_per_layer: Some(4),
        },
        ..Default::default()
    };
    let ctx = match GpuContext::headless_with(&opts) {
        Ok(c) => c,
        Err(e) => {
            assert!(
                !require_gpu(),
                "FRCD_REQUIRE_GPU=1 but no usable adapter: {e}"
            );
            println!("SKIP: {e}");
            return;
        }
    };
    let first = body(&ctx, shapes::icosphere(1.0, 2));
    let poses: Vec<(Pose, Pose)> = (0..4)
        .map(|k| {
            (
                Pose::IDENTITY,
                Pose::new(
                    DVec3::new(0.4 * k as f64 + 0.3, 0.2, 0.0),
                    DQuat::from_rotation_x(k as f64),
                ),
            )
        })
        .collect();
    let mut scratch = QueryScratch::default();
    let (before, _) = agree(&ctx, &first, &first, &poses, &mut scratch, true);
    assert!(before > 0);
    // Larger meshes force growth; the first mesh stays valid across it.
    let second = body(&ctx, shapes::icosphere(1.0, 3));
    let third = body(&ctx, shapes::torus(0.8, 0.25, 48, 16).expect("torus"));
    assert_eq!(
        agree(&ctx, &first, &first, &poses, &mut scratch, true).0,
        before
    );
    assert!(agree(&ctx, &second, &third, &poses, &mut scratch, true).0 > 0);
    assert!(agree(&ctx, &first, &second, &poses, &mut scratch, true).0 > 0);
}

/// Issue 10 item 2: every body pair of a frame in one dispatch chain, one submission and one
/// readback; each answer equal to the oracle's for its pair.
#[test]
fn a_frame_of_many_pairs_is_one_submission() {
    let Some(ctx) = new_context() else { return };
    let meshes = [
        shapes::icosphere(1.0, 2),
        shapes::torus(0.8, 0.25, 32, 12).expect("torus"),
        shapes::cuboid(DVec3::new(0.9, 0.4, 0.2)),
    ];
    let bodies: Vec<Body> = meshes.iter().map(|m| body(&ctx, m.clone())).collect();
    let poses = scattered_poses(99, 24, 1.5, 0.5);
    let items: Vec<(usize, usize, usize, usize)> = (0..40)
        .map(|k| (k % 3, (k * 7) % 24, (k / 3) % 3, (k * 5 + 3) % 24))
        .collect();
    let batch: Vec<_> = items
        .iter()
        .map(|&(a, pa, b, pb)| (&bodies[a].gpu, &poses[pa], &bodies[b].gpu, &poses[pb]))
        .collect();
    let mut scratch = QueryScratch::with_capacity(4, 4);
    // Tiny buffers first: the overflow re-run covers the whole batch.
    let got = ctx.collide_batch(&batch, &mut scratch).unwrap();
    assert!(got.reruns > 0);
    let (s0, r0) = (ctx.submissions(), ctx.readbacks());
    let again = ctx.collide_batch(&batch, &mut scratch).unwrap();
    assert_eq!((ctx.submissions() - s0, ctx.readbacks() - r0), (1, 1));
    assert_eq!(
        (again.submissions, again.readbacks, again.reruns),
        (1, 1, 0)
    );
    let mut touching = 0;
    for (k, &(a, pa, b, pb)) in items.iter().enumerate() {
        let want = oracle::pairs(&bodies[a].mesh, &poses[pa], &bodies[b].mesh, &poses[pb]);
        assert_eq!(got.results[k].pairs, want, "pair {k}");
        assert_eq!(again.results[k].pairs, want, "pair {k}");
        touching += usize::from(!want.is_empty());
    }
    assert!(touching > 5 && touching < items.len(), "{touching}");
    assert!(
        ctx.collide_batch(&[], &mut scratch)
            .unwrap()
            .results
            .is_empty()
    );
}

/// A batch of more body pairs than one row of the pose texture holds (512 pairs a row): every
/// pair reads its own pose and arena bases, in every row and at the rows' edges. Each pair has a
/// pose of its own (two meshes, touching and apart by turns), so a pair reading its neighbour's
/// texels, or the first row's, would give another answer than the oracle's.
#[test]
fn batches_spanning_several_pose_rows_equal_the_oracle() {
    let Some(ctx) = shared() else { return };
    let bodies = [
        body(ctx, shapes::icosphere(1.0, 1)),
        body(ctx, shapes::cuboid(DVec3::new(0.9, 0.4, 0.2))),
    ];
    let mut rng = StdRng::seed_from_u64(1300);
    let n = 1300;
    let poses: Vec<(Pose, Pose)> = (0..n)
        .map(|k| {
            let axis = random_axis(&mut rng);
            // Centres 1.4-2.6 apart: some pairs touch, some do not.
            let d = 1.4 + 1.2 * ((k * 37) % 100) as f64 / 100.0;
            (
                Pose::new(DVec3::new(k as f64, 0.0, 0.0), DQuat::IDENTITY),
                Pose::new(
                    DVec3::new(k as f64 + d * axis.x, d * axis.y, d * axis.z),
                    DQuat::from_axis_angle(axis, rng.random_range(0.0..6.0)),
                ),
            )
        })
        .collect();
    let batch: Vec<_> = poses
        .iter()
        .enumerate()
        .map(|(k, (pa, pb))| (&bodies[k % 2].gpu, pa, &bodies[(k / 2) % 2].gpu, pb))
        .collect();
    let got = ctx
        .collide_batch(&batch, &mut QueryScratch::default())
        .unwrap();
    let mut touching = [0usize; 3];
    for (k, (pa, pb)) in poses.iter().enumerate() {
        let want = oracle::pairs(&bodies[k % 2].mesh, pa, &bodies[(k / 2) % 2].mesh, pb);
        assert_eq!(got.results[k].pairs, want, "body pair {k}");
        touching[k / 512] += usize::from(!want.is_empty());
    }
    // Each of the three rows has touching pairs and pairs apart.
    for (row, &t) in touching.iter().enumerate() {
        let size = (n - 512 * row).min(512);
        assert!(t > 0 && t < size, "row {row}: {t} of {size} touching");
    }
}

/// `Recheck::Uncertain`: the GPU's touching pairs are taken without the exact test, so the
/// answers must still equal the oracle's (the bounds hold on this adapter), the counts of
/// GPU-decided and uncertain pairs are the same as with `Recheck::All`, and nothing is refuted.
#[test]
fn rechecking_only_uncertain_pairs_gives_the_oracles_pairs() {
    let Some(mut ctx) = new_context() else { return };
    assert_eq!(ctx.recheck(), frcd_gpgpu::Recheck::All);
    let a = body(&ctx, shapes::icosphere(1.0, 4));
    let b = body(&ctx, shapes::torus(0.8, 0.25, 64, 24).expect("torus"));
    let poses: Vec<Pose> = (0..12)
        .map(|k| {
            let s = k as f64 / 12.0;
            Pose::new(
                DVec3::new(0.5 + 0.6 * s, 0.2 - 0.3 * s, 0.1),
                DQuat::from_rotation_y(3.0 * s),
            )
        })
        .collect();
    let batch: Vec<_> = poses
        .iter()
        .map(|p| (&a.gpu, &Pose::IDENTITY, &b.gpu, p))
        .collect();
    let mut scratch = QueryScratch::default();
    let all = ctx.collide_batch(&batch, &mut scratch).unwrap();
    ctx.set_recheck(frcd_gpgpu::Recheck::Uncertain);
    let trusted = ctx.collide_batch(&batch, &mut scratch).unwrap();
    let (mut decided, mut uncertain) = (0, 0);
    for (k, p) in poses.iter().enumerate() {
        let want = oracle::pairs(&a.mesh, &Pose::IDENTITY, &b.mesh, p);
        assert_eq!(all.results[k].pairs, want, "pose {k}, Recheck::All");
        assert_eq!(
            trusted.results[k].pairs, want,
            "pose {k}, Recheck::Uncertain"
        );
        let (x, y) = (&all.results[k], &trusted.results[k]);
        assert_eq!(
            (x.gpu_decided, x.gpu_refuted, x.uncertain),
            (y.gpu_decided, 0, y.uncertain)
        );
        decided += y.gpu_decided;
        uncertain += y.uncertain;
    }
    // Both kinds occur, so both paths of the re-decision ran.
    assert!(decided > 0 && uncertain > 0, "{decided} {uncertain}");
}

/// The triangle pass's exact reference-point path (the default: `W = R c_B + t - c_A` in integer
/// arithmetic, only small offsets rotated in f32) leaves far fewer pairs uncertain than the
/// rotated path on a scene with many touching pairs (icospheres through each other, at the
/// origin and far from it), and both give the oracle's pairs.
#[test]
fn the_exact_path_leaves_far_fewer_uncertain_pairs() {
    let Some(mut ctx) = new_context() else { return };
    assert!(ctx.exact_offsets());
    let a = body(&ctx, shapes::icosphere(1.0, 4));
    let b = body(&ctx, shapes::icosphere(0.9, 4));
    let far = DVec3::new(3.0e3, -1.0e3, 500.0);
    let poses: Vec<(Pose, Pose)> = (0..6)
        .map(|k| {
            let s = k as f64 / 6.0;
            let base = if k % 2 == 0 { DVec3::ZERO } else { far };
            (
                Pose::new(base, DQuat::from_rotation_y(0.3 * s)),
                Pose::new(
                    base + DVec3::new(0.4 + 1.2 * s, 0.11, -0.05),
                    DQuat::from_rotation_z(0.9 * s) * DQuat::from_rotation_x(0.4),
                ),
            )
        })
        .collect();
    let batch: Vec<_> = poses
        .iter()
        .map(|(pa, pb)| (&a.gpu, pa, &b.gpu, pb))
        .collect();
    let mut scratch = QueryScratch::default();
    let exact = ctx.collide_batch(&batch, &mut scratch).unwrap();
    ctx.set_exact_offsets(false);
    let rotated = ctx.collide_batch(&batch, &mut scratch).unwrap();
    let (mut touching, mut unc_exact, mut unc_rotated) = (0, 0, 0);
    for (k, (pa, pb)) in poses.iter().enumerate() {
        let want = oracle::pairs(&a.mesh, pa, &b.mesh, pb);
        let (x, y) = (&exact.results[k], &rotated.results[k]);
        assert_eq!(x.pairs, want, "pose {k}, exact path");
        assert_eq!(y.pairs, want, "pose {k}, rotated path");
        assert!(x.exact_offsets && !y.exact_offsets, "pose {k}");
        assert_eq!((x.gpu_refuted, y.gpu_refuted), (0, 0));
        touching += want.len();
        unc_exact += x.uncertain;
        unc_rotated += y.uncertain;
    }
    println!("{touching} touching pairs: uncertain {unc_rotated} rotated, {unc_exact} exact");
    assert!(touching > 1000, "{touching}");
    assert!(unc_rotated > 100, "{unc_rotated}");
    assert!(
        unc_exact * 10 <= unc_rotated,
        "exact path: {unc_exact} uncertain, rotated: {unc_rotated}"
    );
}

/// Pairs whose integer ranges cannot hold take the rotated path and still equal the oracle: A
/// below the grid's range (1e-12 across: no grid, offsets are the vertices), and A 2^50 times
/// smaller than B (A's grid more than 2^46 below B's). A large A with a small B takes the exact
/// path's mode 2 (B rebuilt in f32, only `t - c_A` exact), also equal to the oracle.
#[test]
fn pairs_outside_the_exact_paths_ranges_take_the_rotated_path() {
    let Some(ctx) = shared() else { return };
    let tiny = body(ctx, shapes::icosphere(1.0e-12, 2));
    let big = body(ctx, shapes::icosphere(1.0e4, 3));
    let small = body(ctx, shapes::icosphere(1.0e-2, 2));
    let huge = body(ctx, shapes::icosphere(1.0e6, 2));
    let speck = body(ctx, shapes::icosphere(1.0e-9, 1));
    let rot = DQuat::from_rotation_z(0.3) * DQuat::from_rotation_x(0.2);
    // The speck at a vertex of the huge sphere.
    let corner = huge.mesh.vertices()[0];
    let cases: [(&Body, Pose, &Body, Pose, bool); 4] = [
        (
            &tiny,
            Pose::IDENTITY,
            &tiny,
            Pose::new(DVec3::new(1.2e-12, 3e-13, 0.0), rot),
            false,
        ),
        (&speck, Pose::new(corner, rot), &huge, Pose::IDENTITY, false),
        (
            &big,
            Pose::IDENTITY,
            &small,
            Pose::new(DVec3::new(1.0e4, 2e-3, 0.0), rot),
            true,
        ),
        (
            &small,
            Pose::new(DVec3::new(1.0e4, 2e-3, 0.0), rot),
            &big,
            Pose::IDENTITY,
            true,
        ),
    ];
    let mut scratch = QueryScratch::default();
    for (k, (a, pa, b, pb, exact)) in cases.iter().enumerate() {
        let got = ctx.collide(&a.gpu, pa, &b.gpu, pb, &mut scratch).unwrap();
        let want = oracle::pairs(&a.mesh, pa, &b.mesh, pb);
        assert!(!want.is_empty(), "case {k}");
        assert_eq!(got.pairs, want, "case {k}");
        assert_eq!(got.exact_offsets, *exact, "case {k}");
    }
}

/// The exact path's default: on for hardware adapters, off for software ones (where its integer
/// work costs more than it saves), unless `FRCD_GPGPU_EXACT_OFFSETS` says; the rotated path (the
/// other pipeline) gives the oracle's pairs on the same scene as the exact one.
#[test]
fn the_exact_paths_default_follows_the_adapter() {
    let ctx = match GpuContext::headless() {
        Ok(c) => c,
        Err(e) => {
            assert!(!require_gpu(), "{e}");
            return;
        }
    };
    let want = match std::env::var(frcd_gpgpu::EXACT_OFFSETS_ENV).as_deref() {
        Ok("1") => true,
        Ok("0") => false,
        _ => !ctx.is_software(),
    };
    assert_eq!(ctx.exact_offsets(), want);
    let a = body(&ctx, shapes::icosphere(1.0, 3));
    let b = body(&ctx, shapes::torus(0.8, 0.25, 48, 16).expect("torus"));
    let pose_b = Pose::new(DVec3::new(0.7, 0.1, 0.0), DQuat::from_rotation_x(0.7));
    let got = ctx
        .collide(
            &a.gpu,
            &Pose::IDENTITY,
            &b.gpu,
            &pose_b,
            &mut QueryScratch::default(),
        )
        .unwrap();
    assert_eq!(
        got.pairs,
        oracle::pairs(&a.mesh, &Pose::IDENTITY, &b.mesh, &pose_b)
    );
    assert_eq!(got.exact_offsets, want);
}

/// Pass timers: with them, a batch reports one GPU time per traversal level, the triangle pass
/// and the whole chain (consistent with each other), and the same pairs as without them
/// (also after an overflow re-run, whose timestamps come from the last run). Without them the
/// GPU fields stay empty; the host's wait and re-decision times are always filled.
#[test]
fn pass_timers_time_every_level_and_leave_the_answer_alone() {
    let Some(mut plain) = new_context() else {
        return;
    };
    let mut timed = match GpuContext::headless_with(&HeadlessOptions {
        pass_timers: true,
        ..Default::default()
    }) {
        Ok(c) => c,
        Err(e) => panic!("a context that could be made without timers fails with them: {e}"),
    };
    // Every level of the trees on the GPU (no CPU front) in the level chain (one dispatch per
    // level), so there is one time per level.
    plain.set_host_front(0);
    timed.set_host_front(0);
    plain.set_one_pass(0);
    timed.set_one_pass(0);
    let a = shapes::icosphere(1.0, 3);
    let b = shapes::torus(0.8, 0.25, 48, 16).expect("torus");
    let pose_b = Pose::new(DVec3::new(0.7, 0.1, 0.0), DQuat::from_rotation_x(0.7));
    let want = oracle::pairs(&a, &Pose::IDENTITY, &b, &pose_b);
    assert!(!want.is_empty());
    let run = |ctx: &GpuContext, scratch: &mut QueryScratch| {
        let (ga, gb) = (body(ctx, a.clone()), body(ctx, b.clone()));
        let batch = [(&ga.gpu, &Pose::IDENTITY, &gb.gpu, &pose_b)];
        let depth = ga.gpu.depth().max(gb.gpu.depth());
        (ctx.collide_batch(&batch, scratch).expect("batch"), depth)
    };
    let (untimed, _) = run(&plain, &mut QueryScratch::default());
    // Equal batches compare equal whatever their timings.
    let mut other = untimed.clone();
    other.timings.wait += std::time::Duration::from_millis(1);
    assert_eq!(other, untimed);
    other.reruns += 1;
    assert_ne!(other, untimed);
    assert_eq!(untimed.results[0].pairs, want);
    assert!(untimed.timings.gpu_levels.is_empty());
    assert_eq!(
        (untimed.timings.gpu_triangles, untimed.timings.gpu_total),
        (None, None)
    );
    assert!(untimed.timings.wait > std::time::Duration::ZERO);
    assert!(untimed.timings.decide > std::time::Duration::ZERO);
    // Tiny buffers: the first batch overflows and re-runs.
    for mut scratch in [QueryScratch::with_capacity(2, 2), QueryScratch::default()] {
        let (got, depth) = run(&timed, &mut scratch);
        assert_eq!(got.results[0].pairs, want);
        let t = &got.timings;
        if !timed.has_pass_timers() {
            println!("SKIP pass timers: the adapter has no timestamps inside passes");
            assert!(t.gpu_levels.is_empty() && t.gpu_total.is_none());
            return;
        }
        assert_eq!(t.gpu_levels.len(), depth as usize, "{t:?}");
        println!("{t:?}");
        let (tris, total) = (t.gpu_triangles.unwrap(), t.gpu_total.unwrap());
        let parts: std::time::Duration = t.gpu_levels.iter().sum::<std::time::Duration>() + tris;
        assert!(parts <= total, "{t:?}");
        // Not `total <= wait`: a driver may run the work inside `submit` (lavapipe once did).
        assert!(total > std::time::Duration::ZERO, "{t:?}");
    }
    // The one-pass traversal: one dispatch, timed as a whole.
    timed.set_one_pass(2);
    let (got, _) = run(&timed, &mut QueryScratch::default());
    assert_eq!(got.results[0].pairs, want);
    let t = &got.timings;
    assert!(
        t.gpu_levels.is_empty() && t.gpu_triangles.is_none(),
        "{t:?}"
    );
    assert!(
        t.gpu_total.is_some_and(|d| d > std::time::Duration::ZERO),
        "{t:?}"
    );
}

/// llvmpipe silently ends an invocation's loops after 65,535 iterations in all, so a one-pass
/// workgroup whose share needs more than its loop budget stops and the batch re-runs as the
/// level chain: with a budget too small for the batch, the answers are still the oracle's,
/// one re-run more, and the node pairs tested are the level chain's; with the default budget
/// the same batch needs no re-run.
#[test]
fn a_one_pass_run_past_its_loop_budget_reruns_as_the_level_chain() {
    let Some(mut ctx) = new_context() else { return };
    let a = body(&ctx, shapes::icosphere(1.0, 3));
    let b = body(&ctx, shapes::torus(0.8, 0.25, 48, 16).expect("torus"));
    let poses: Vec<(Pose, Pose)> = (0..4)
        .map(|k| {
            let at = DVec3::new(5.0 * k as f64, 0.0, 0.0);
            (
                Pose::from_translation(at),
                Pose::new(
                    at + DVec3::new(0.6, 0.1, 0.05 * k as f64),
                    DQuat::from_rotation_x(0.4 * k as f64),
                ),
            )
        })
        .collect();
    let want: Vec<_> = poses
        .iter()
        .map(|(pa, pb)| oracle::pairs(&a.mesh, pa, &b.mesh, pb))
        .collect();
    assert!(want.iter().all(|w| !w.is_empty()));
    let batch: Vec<_> = poses
        .iter()
        .map(|(pa, pb)| (&a.gpu, pa, &b.gpu, pb))
        .collect();
    ctx.set_one_pass(0);
    let chain = ctx
        .collide_batch(&batch, &mut QueryScratch::default())
        .expect("level chain");
    ctx.set_one_pass(2);
    let mut scratch = QueryScratch::default();
    let fits = ctx.collide_batch(&batch, &mut scratch).expect("one pass");
    assert_eq!(fits.reruns, 0);
    for budget in [0, 1, 40] {
        ctx.set_one_pass_loop_budget(budget);
        let got = ctx
            .collide_batch(&batch, &mut scratch)
            .expect("over budget");
        for (k, (r, w)) in got.results.iter().zip(&want).enumerate() {
            assert_eq!(&r.pairs, w, "budget {budget}, pair {k}");
        }
        assert_eq!(got.reruns, 1, "budget {budget}");
        assert_eq!(got.submissions, 2, "budget {budget}");
        assert_eq!(
            (got.node_pairs_tested, got.levels),
            (chain.node_pairs_tested, chain.levels),
            "budget {budget}"
        );
    }
    ctx.set_one_pass_loop_budget(frcd_gpgpu::ONE_PASS_LOOP_BUDGET);
    let again = ctx.collide_batch(&batch, &mut scratch).expect("one pass");
    assert_eq!(
        (again.reruns, again.node_pairs_tested),
        (0, fits.node_pairs_tested)
    );
}

/// A batch whose share for one workgroup needs more loop iterations than llvmpipe runs (65,535
/// in all per invocation): with the default budget the workgroup stops short of it and the
/// batch re-runs as the level chain, with the oracle's answers; with no budget, llvmpipe's
/// cut ends the loops early (printed, not asserted: it depends on the driver).
#[test]
fn a_one_pass_batch_past_the_drivers_loop_limit_keeps_its_pairs() {
    let Some(mut ctx) = new_context() else { return };
    let a = body(&ctx, shapes::icosphere(1.0, 3));
    let b = body(&ctx, shapes::torus(0.8, 0.25, 48, 16).expect("torus"));
    let (pa, pb) = (
        Pose::IDENTITY,
        Pose::new(DVec3::new(0.6, 0.1, 0.0), DQuat::from_rotation_x(0.4)),
    );
    let want = oracle::pairs(&a.mesh, &pa, &b.mesh, &pb);
    assert!(!want.is_empty());
    ctx.set_one_pass(1);
    ctx.set_host_front(0);
    let one = ctx
        .collide_batch(&[(&a.gpu, &pa, &b.gpu, &pb)], &mut QueryScratch::default())
        .expect("one pair");
    // Enough copies of the pair that one workgroup's entries alone take > 65,535 rounds of 64.
    let copies = (65_536 * 64 * 4 / one.node_pairs_tested.max(1) + 1) as usize;
    let batch = vec![(&a.gpu, &pa, &b.gpu, &pb); copies];
    let mut scratch = QueryScratch::default();
    let got = ctx.collide_batch(&batch, &mut scratch).expect("batch");
    assert!(got.reruns >= 1, "{copies} copies fit the loop budget");
    for (k, r) in got.results.iter().enumerate() {
        assert_eq!(r.pairs, want, "copy {k}");
    }
    // Without the budget: on llvmpipe (Mesa 22.3.6, 2026-12-02) the driver's cut ended the
    // level loop early and the batch was refused ("174762 node pairs left after 13 levels").
    ctx.set_one_pass_loop_budget(u32::MAX);
    let outcome = match ctx.collide_batch(&batch, &mut scratch) {
        Ok(r) => {
            let lost = r.results.iter().filter(|r| r.pairs != want).count();
            format!("{lost} copies lost pairs")
        }
        Err(e) => format!("refused: {e}"),
    };
    println!(
        "{copies} copies, {} node pairs tested; without the budget on {}: {outcome}",
        got.node_pairs_tested,
        ctx.adapter_info().name
    );
}

/// The one-pass traversal (`GpuContext::set_one_pass`): for any number of workgroups, with and
/// without the CPU's front, and through overflow re-runs of its per-workgroup regions, a frame of
/// many body pairs equals the oracle pair for pair, and it tests exactly the node pairs and
/// runs exactly the levels the level chain does (the same traversal, only dispatched
/// differently: a workgroup that skipped or repeated an entry would show here).
#[test]
fn the_one_pass_traversal_equals_the_oracle_and_the_level_chain() {
    let Some(mut ctx) = new_context() else { return };
    let meshes = [
        shapes::icosphere(1.0, 3),
        shapes::torus(0.8, 0.25, 48, 16).expect("torus"),
        shapes::cuboid(DVec3::new(0.9, 0.4, 0.2)),
    ];
    let bodies: Vec<Body> = meshes.iter().map(|m| body(&ctx, m.clone())).collect();
    let poses = scattered_poses(1234, 30, 1.2, 0.4);
    let items: Vec<(usize, usize, usize, usize)> = (0..45)
        .map(|k| (k % 3, (k * 7) % 30, (k / 3) % 3, (k * 11 + 5) % 30))
        .collect();
    let want: Vec<_> = items
        .iter()
        .map(|&(a, pa, b, pb)| {
            oracle::pairs(&bodies[a].mesh, &poses[pa], &bodies[b].mesh, &poses[pb])
        })
        .collect();
    let touching = want.iter().filter(|w| !w.is_empty()).count();
    assert!(touching > 5 && touching < items.len(), "{touching}");
    let batch: Vec<_> = items
        .iter()
        .map(|&(a, pa, b, pb)| (&bodies[a].gpu, &poses[pa], &bodies[b].gpu, &poses[pb]))
        .collect();
    for front in [0, 256, frcd_gpgpu::HOST_FRONT_SOFTWARE] {
        ctx.set_host_front(front);
        ctx.set_one_pass(0);
        let chain = ctx
            .collide_batch(&batch, &mut QueryScratch::default())
            .expect("level chain");
        for (k, (r, w)) in chain.results.iter().zip(&want).enumerate() {
            assert_eq!(&r.pairs, w, "level chain, front {front}, pair {k}");
        }
        for groups in [1, 2, 3, 7, 64] {
            ctx.set_one_pass(groups);
            // Default buffers, then buffers far too small for any workgroup's region.
            for (name, mut scratch) in [
                ("default", QueryScratch::default()),
                ("tiny", QueryScratch::with_capacity(3, 2)),
            ] {
                let got = ctx
                    .collide_batch(&batch, &mut scratch)
                    .unwrap_or_else(|e| panic!("{groups} workgroups, front {front}: {e}"));
                let at = format!("{groups} workgroups, front {front}, {name} scratch");
                for (k, (r, w)) in got.results.iter().zip(&want).enumerate() {
                    assert_eq!(&r.pairs, w, "{at}, pair {k}");
                }
                assert_eq!(
                    (got.node_pairs_tested, got.levels, got.host_levels),
                    (chain.node_pairs_tested, chain.levels, chain.host_levels),
                    "{at}"
                );
                if name == "tiny" {
                    assert!(got.reruns > 0, "{at}: no overflow");
                }
                assert_eq!(got.submissions, 1 + got.reruns, "{at}");
            }
        }
    }
}

/// The one-pass traversal lists one entry per pair of overlapping leaves and tests their
/// triangles in two loops (`test_leaf_pair` in traverse.wgsl), where the level chain lists every
/// triangle pair: with trees of leaves of 1, 2, 3 and 4 triangles mixed in one batch, the one
/// pass (run as such: no fall-back to the chain) equals the oracle pair for pair and tests the
/// chain's node pairs; leaves at `MAX_LEAF_TRIANGLES`, whose tests may take more than a
/// workgroup's loop budget and then re-run as the chain, equal it too. A leaf's count decoded
/// wrongly, or a loop bound off by one, loses or invents pairs here.
#[test]
fn the_one_pass_traversal_tests_leaves_of_every_size() {
    let Some(mut ctx) = new_context() else { return };
    let meshes = [
        shapes::icosphere(1.0, 3),
        shapes::torus(0.8, 0.25, 40, 14).expect("torus"),
    ];
    let poses = scattered_poses(77, 12, 0.9, 0.5);
    for leaves in [&[1, 2, 3, 4][..], &[frcd_gpgpu::MAX_LEAF_TRIANGLES]] {
        // Bodies (mesh, its tree on the GPU): every mesh at every leaf size.
        let bodies: Vec<(usize, GpuMesh)> = leaves
            .iter()
            .flat_map(|&l| (0..meshes.len()).map(move |m| (m, l)))
            .map(|(m, l)| {
                let build = BuildOptions {
                    max_leaf_triangles: l,
                    ..BuildOptions::default()
                };
                let tree = ObbTree::build(&meshes[m], &build);
                (m, ctx.upload(&tree).expect("upload"))
            })
            .collect();
        let n = bodies.len();
        let items: Vec<(usize, usize, usize, usize)> = (0..36)
            .map(|k| (k % n, k % 12, (k * 7 + 3) % n, (k * 5 + 1) % 12))
            .collect();
        let want: Vec<_> = items
            .iter()
            .map(|&(a, pa, b, pb)| {
                let (ma, mb) = (&meshes[bodies[a].0], &meshes[bodies[b].0]);
                oracle::pairs(ma, &poses[pa], mb, &poses[pb])
            })
            .collect();
        let touching = want.iter().filter(|w| !w.is_empty()).count();
        assert!(touching > 5 && touching < items.len(), "{touching}");
        let batch: Vec<_> = items
            .iter()
            .map(|&(a, pa, b, pb)| (&bodies[a].1, &poses[pa], &bodies[b].1, &poses[pb]))
            .collect();
        let mut tested = Vec::new();
        for groups in [0, 1, 2, 5] {
            ctx.set_one_pass(groups);
            // Buffers that hold the batch: a re-run here is a fall-back to the chain.
            let mut scratch = QueryScratch::with_capacity(1 << 18, 1 << 16);
            let got = ctx
                .collide_batch(&batch, &mut scratch)
                .unwrap_or_else(|e| panic!("{groups} workgroups: {e}"));
            let at = format!("leaves {leaves:?}, {groups} workgroups");
            for (k, (r, w)) in got.results.iter().zip(&want).enumerate() {
                assert_eq!(&r.pairs, w, "{at}, pair {k} {:?}", items[k]);
            }
            if leaves.len() > 1 {
                assert_eq!(got.reruns, 0, "{at}: re-run");
            }
            tested.push(got.node_pairs_tested);
        }
        assert!(tested.iter().all(|&t| t == tested[0]), "{tested:?}");
    }
}

/// Issue 10 item 3: recorded into the caller's encoder, submitted by the caller, resolved by
/// waiting on that submission only.
#[test]
fn a_batch_recorded_into_the_callers_encoder() {
    let Some(ctx) = new_context() else { return };
    let a = body(&ctx, shapes::icosphere(1.0, 3));
    let poses: Vec<Pose> = (0..6)
        .map(|k| Pose::from_translation(DVec3::new(0.35 * k as f64, 0.1, 0.0)))
        .collect();
    let batch: Vec<_> = (0..5)
        .map(|k| (&a.gpu, &poses[0], &a.gpu, &poses[k + 1]))
        .collect();
    for caps in [(1 << 14, 1 << 12), (2, 2)] {
        let mut scratch = QueryScratch::with_capacity(caps.0, caps.1);
        let mut enc = ctx
            .device()
            .create_command_encoder(&frcd_gpgpu::wgpu::CommandEncoderDescriptor::default());
        let s0 = ctx.submissions();
        let pending = ctx.encode_batch(&mut enc, &batch, &mut scratch).unwrap();
        // The engine's own frame work would be recorded here too.
        let index = ctx.queue().submit([enc.finish()]);
        let got = pending.resolve(index).unwrap();
        assert_eq!(ctx.submissions() - s0, got.reruns as u64);
        assert_eq!(got.submissions, got.reruns);
        for (k, r) in got.results.iter().enumerate() {
            let want = oracle::pairs(&a.mesh, &poses[0], &a.mesh, &poses[k + 1]);
            assert_eq!(r.pairs, want, "caps {caps:?} pair {k}");
        }
    }
}

/// Issue 10 item 2: two batches in flight (frame k+1 submitted before frame k is read), each
/// equal to the oracle; overflow re-runs happen at resolve time.
#[test]
fn submitted_batches_overlap_and_resolve_in_order() {
    let Some(ctx) = new_context() else { return };
    let a = body(&ctx, shapes::icosphere(1.0, 3));
    let frames: Vec<Vec<Pose>> = (0..4)
        .map(|f| {
            (0..5)
                .map(|k| {
                    Pose::from_translation(DVec3::new(0.3 * k as f64 + 0.05 * f as f64, 0.1, 0.0))
                })
                .collect()
        })
        .collect();
    let batch = |f: usize| -> Vec<_> {
        (0..4)
            .map(|k| (&a.gpu, &frames[f][0], &a.gpu, &frames[f][k + 1]))
            .collect()
    };
    let check = |f: usize, got: &frcd_gpgpu::GpuBatch| {
        assert_eq!(got.results.len(), 4);
        for (k, r) in got.results.iter().enumerate() {
            let want = oracle::pairs(&a.mesh, &frames[f][0], &a.mesh, &frames[f][k + 1]);
            assert_eq!(r.pairs, want, "frame {f} pair {k}");
        }
    };
    // Tiny buffers: the first resolve re-runs after an overflow.
    let mut spare = Some(QueryScratch::with_capacity(2, 2));
    let mut in_flight = Some(
        ctx.submit_batch(&batch(0), QueryScratch::default())
            .unwrap(),
    );
    for f in 1..frames.len() {
        let s0 = ctx.submissions();
        let next = ctx.submit_batch(&batch(f), spare.take().unwrap()).unwrap();
        assert_eq!(ctx.submissions() - s0, 1);
        assert_eq!(next.len(), 4);
        let (got, scratch) = ctx.resolve_batch(in_flight.take().unwrap()).unwrap();
        check(f - 1, &got);
        assert_eq!(got.submissions, 1 + got.reruns);
        spare = Some(scratch);
        in_flight = Some(next);
    }
    let (got, _) = ctx.resolve_batch(in_flight.take().unwrap()).unwrap();
    check(frames.len() - 1, &got);
    let empty = ctx.submit_batch(&[], QueryScratch::default()).unwrap();
    assert!(empty.is_empty());
    assert!(ctx.resolve_batch(empty).unwrap().0.results.is_empty());
    if let Some(other) = new_context() {
        let theirs = other.submit_batch(&[], QueryScratch::default()).unwrap();
        assert!(matches!(
            ctx.resolve_batch(theirs),
            Err(GpuError::ForeignObject("SubmittedBatch"))
        ));
    }
}

#[test]
fn objects_of_another_context_are_refused() {
    let Some(ctx) = shared() else { return };
    let Some(other) = new_context() else { return };
    let t = tree(&shapes::icosphere(1.0, 1));
    let mine = ctx.upload(&t).unwrap();
    let theirs = other.upload(&t).unwrap();
    let err = ctx
        .collide(
            &mine,
            &Pose::IDENTITY,
            &theirs,
            &Pose::IDENTITY,
            &mut QueryScratch::default(),
        )
        .unwrap_err();
    assert!(matches!(err, GpuError::ForeignObject("GpuMesh")), "{err}");
    let mut scratch = QueryScratch::default();
    ctx.collide(&mine, &Pose::IDENTITY, &mine, &Pose::IDENTITY, &mut scratch)
        .unwrap();
    let theirs2 = other.upload(&t).unwrap();
    let err = other
        .collide(
            &theirs,
            &Pose::IDENTITY,
            &theirs2,
            &Pose::IDENTITY,
            &mut scratch,
        )
        .unwrap_err();
    assert!(
        matches!(err, GpuError::ForeignObject("QueryScratch")),
        "{err}"
    );
    let bad = Pose {
        translation: DVec3::new(f64::NAN, 0.0, 0.0),
        rotation: DQuat::IDENTITY,
    };
    let err = ctx
        .collide(
            &mine,
            &Pose::IDENTITY,
            &mine,
            &bad,
            &mut QueryScratch::default(),
        )
        .unwrap_err();
    assert!(matches!(err, GpuError::InvalidInput(_)), "{err}");
}

fn cpu_box_pairs(boxes: &[Aabb]) -> Vec<(u32, u32)> {
    let mut out = Vec::new();
    for i in 0..boxes.len() {
        for j in i + 1..boxes.len() {
            if boxes[i].intersects(&boxes[j]) {
                out.push((i as u32, j as u32));
            }
        }
    }
    out
}

#[test]
fn many_bodies_box_pass_equals_the_cpu() {
    let Some(ctx) = new_context() else { return };
    let mut rng = StdRng::seed_from_u64(3);
    let mut boxes: Vec<Aabb> = (0..700)
        .map(|_| {
            let c = DVec3::new(
                rng.random_range(0.0..30.0),
                rng.random_range(0.0..30.0),
                rng.random_range(0.0..30.0),
            ) + DVec3::splat(1e6);
            let h = DVec3::new(
                rng.random_range(0.0..1.5),
                rng.random_range(0.0..1.5),
                rng.random_range(0.0..1.5),
            );
            Aabb::new(c - h, c + h)
        })
        .collect();
    // Exactly touching faces and a one-ulp gap far from the origin, where f32 cannot tell.
    let base = Aabb::new(DVec3::splat(1e6 + 0.1), DVec3::splat(1e6 + 0.3));
    let touch = Aabb::new(
        DVec3::new(base.max.x, base.min.y, base.min.z),
        base.max + DVec3::X,
    );
    let gap = Aabb::new(
        DVec3::new(base.max.x.next_up(), base.min.y, base.min.z),
        base.max + DVec3::X,
    );
    boxes.extend([base, touch, gap, Aabb::EMPTY]);
    let want = cpu_box_pairs(&boxes);
    let mut scratch = BoxScratch::with_capacity(1);
    let s0 = ctx.submissions();
    let got = ctx.overlapping_bodies(&boxes, &mut scratch).unwrap();
    assert_eq!(got.pairs, want);
    assert!(got.submissions >= 2, "the tiny output buffer must overflow");
    assert_eq!(ctx.submissions() - s0, got.submissions as u64);
    assert!(got.uncertain > 0, "the one-ulp cases need the f64 check");
    let n = boxes.len() as u32;
    assert!(want.contains(&(n - 4, n - 3)) && !want.contains(&(n - 4, n - 2)));
    let again = ctx.overlapping_bodies(&boxes, &mut scratch).unwrap();
    assert_eq!((again.submissions, again.readbacks), (1, 1));
    assert_eq!(again.pairs, want);
    let nan = [Aabb::new(DVec3::splat(f64::NAN), DVec3::ONE), base];
    assert!(matches!(
        ctx.overlapping_bodies(&nan, &mut scratch),
        Err(GpuError::InvalidInput(_))
    ));
}

/// The box pass submitted and read later (`submit_broad_phase` / `resolve_broad_phase`) gives
/// `broad_phase`'s answer on both paths (all pairs up to 256 bodies, the sort-and-sweep above),
/// with a pair batch queued in between, through an output overflow, for 0 and 1 boxes; a pass
/// read on another context is refused.
#[test]
fn a_box_pass_read_later_equals_the_one_waited_for() {
    let Some(ctx) = new_context() else { return };
    let mut rng = StdRng::seed_from_u64(17);
    let scatter = |n: usize, rng: &mut StdRng| -> Vec<Aabb> {
        let side = (n as f64 / 4.0).cbrt() * 2.0;
        (0..n)
            .map(|_| {
                let c = DVec3::new(
                    rng.random_range(0.0..side),
                    rng.random_range(0.0..side),
                    rng.random_range(0.0..side),
                );
                Aabb::new(c - DVec3::splat(0.5), c + DVec3::splat(0.5))
            })
            .collect()
    };
    let a = body(&ctx, shapes::icosphere(1.0, 2));
    for n in [0usize, 1, 2, 64, 256, 300] {
        let boxes = scatter(n, &mut rng);
        let want = cpu_box_pairs(&boxes);
        let waited = ctx.broad_phase(&boxes, &mut BoxScratch::default()).unwrap();
        assert_eq!(waited.pairs, want, "{n} bodies, waited for");
        // Tiny output: the read overflows and re-runs (where there are pairs).
        let pending = ctx
            .submit_broad_phase(&boxes, BoxScratch::with_capacity(1))
            .unwrap();
        // Other GPU work queued after the pass (a pair batch) does not change its answer.
        let other = ctx
            .submit_batch(
                &[(
                    &a.gpu,
                    &Pose::IDENTITY,
                    &a.gpu,
                    &Pose::from_translation(DVec3::X),
                )],
                QueryScratch::default(),
            )
            .unwrap();
        let (got, scratch) = ctx.resolve_broad_phase(pending).unwrap();
        assert_eq!(got.pairs, want, "{n} bodies, read later");
        if want.len() > 1 && n <= 256 {
            assert!(got.submissions >= 2 && got.readbacks >= 2, "{n}: {got:?}");
            assert!(scratch.capacity() >= want.len() as u32);
        }
        let (batch, _) = ctx.resolve_batch(other).unwrap();
        assert_eq!(
            batch.results[0].pairs,
            oracle::pairs(
                &a.mesh,
                &Pose::IDENTITY,
                &a.mesh,
                &Pose::from_translation(DVec3::X)
            )
        );
        // The grown scratch again: one submission, one readback.
        let (again, _) = ctx
            .resolve_broad_phase(ctx.submit_broad_phase(&boxes, scratch).unwrap())
            .unwrap();
        assert_eq!(again.pairs, want);
        if (2..=256).contains(&n) {
            assert_eq!((again.submissions, again.readbacks), (1, 1), "{n}");
        }
    }
    let boxes = scatter(64, &mut rng);
    let pending = ctx
        .submit_broad_phase(&boxes, BoxScratch::default())
        .unwrap();
    if let Some(other) = new_context() {
        assert!(matches!(
            other.resolve_broad_phase(pending),
            Err(GpuError::ForeignObject(_))
        ));
    }
    let nan = [Aabb::new(DVec3::splat(f64::NAN), DVec3::ONE), boxes[0]];
    assert!(matches!(
        ctx.submit_broad_phase(&nan, BoxScratch::default()),
        Err(GpuError::InvalidInput(_))
    ));
}

fn adapter_and_device(
    limits: frcd_gpgpu::wgpu::Limits,
) -> Option<(
    frcd_gpgpu::wgpu::Adapter,
    frcd_gpgpu::wgpu::Device,
    frcd_gpgpu::wgpu::Queue,
)> {
    adapter_and_device_on(
        frcd_gpgpu::wgpu::InstanceDescriptor::new_without_display_handle_from_env(),
        |_| limits,
    )
}

/// [`adapter_and_device`] on an instance the test describes, with limits chosen from the
/// adapter's.
fn adapter_and_device_on(
    desc: frcd_gpgpu::wgpu::InstanceDescriptor,
    limits: impl FnOnce(frcd_gpgpu::wgpu::Limits) -> frcd_gpgpu::wgpu::Limits,
) -> Option<(
    frcd_gpgpu::wgpu::Adapter,
    frcd_gpgpu::wgpu::Device,
    frcd_gpgpu::wgpu::Queue,
)> {
    use frcd_gpgpu::wgpu;
    let instance = wgpu::Instance::new(desc);
    let adapter = match pollster::block_on(wgpu::util::initialize_adapter_from_env_or_default(
        &instance, None,
    )) {
        Ok(a) => a,
        Err(e) => {
            assert!(!require_gpu(), "FRCD_REQUIRE_GPU=1 but no adapter: {e}");
            println!("SKIP: no adapter: {e}");
            return None;
        }
    };
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        required_limits: limits(adapter.limits()),
        ..Default::default()
    }))
    .expect("device");
    Some((adapter, device, queue))
}

#[test]
fn two_dimensional_grids_without_indirect_validation() {
    use frcd_gpgpu::wgpu;
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    desc.flags
        .remove(wgpu::InstanceFlags::VALIDATION_INDIRECT_CALL);
    let Some((adapter, device, queue)) = adapter_and_device_on(desc, |l| wgpu::Limits {
        max_compute_workgroups_per_dimension: 8,
        ..l
    }) else {
        return;
    };
    let mut ctx = GpuContext::from_adapter(&adapter, device, queue).expect("limits suffice");
    // Levels of more than one row need the GPU to start at the roots (no CPU front), one
    // dispatch per level (the one-pass traversal has no grid to lay out).
    ctx.set_host_front(0);
    ctx.set_one_pass(0);
    let a = body(&ctx, shapes::icosphere(1.0, 3));
    let poses: Vec<(Pose, Pose)> = (0..6)
        .map(|k| {
            let s = k as f64 / 6.0;
            let dir = DVec3::new((6.0 * s).cos(), (6.0 * s).sin(), 0.3 - s).normalize();
            let at = DVec3::new(4.0 * k as f64, 0.0, 0.0);
            (
                Pose::from_translation(at),
                Pose::new(at + 0.9 * dir, DQuat::from_rotation_z(s)),
            )
        })
        .collect();
    let batch: Vec<_> = poses
        .iter()
        .map(|(pa, pb)| (&a.gpu, pa, &a.gpu, pb))
        .collect();
    let got = ctx
        .collide_batch(&batch, &mut QueryScratch::default())
        .expect("every level fits 8 × 8 × 64 entries (one invocation each)");
    let mut reported = 0;
    for (k, (pa, pb)) in poses.iter().enumerate() {
        let want = oracle::pairs(&a.mesh, pa, &a.mesh, pb);
        assert_eq!(got.results[k].pairs, want, "pair {k}");
        let r = &got.results[k];
        reported += r.gpu_decided + r.gpu_refuted + r.uncertain;
    }
    // More than one row of 8 workgroups of 64 in the triangle pass at least.
    assert!(reported > 8 * 64, "{reported} reported pairs");
    // Levels of more than one row too (their arguments raised on both dimensions), and
    // counts that add up there.
    assert!(
        got.node_pairs_tested > 2 * 8 * 64 * got.levels as u64,
        "{} node pairs in {} levels",
        got.node_pairs_tested,
        got.levels
    );
    level_counts_add_up(&ctx, &a, &poses);
    // A batch whose levels need more than one dispatch can cover: a typed error, not a
    // dispatch beyond the device's limits (nothing validates the arguments on this instance).
    let big = body(&ctx, shapes::icosphere(1.0, 5));
    let batch: Vec<_> = poses
        .iter()
        .cycle()
        .take(4 * poses.len())
        .map(|(pa, pb)| (&big.gpu, pa, &big.gpu, pb))
        .collect();
    match ctx.collide_batch(&batch, &mut QueryScratch::default()) {
        Err(GpuError::CapacityExceeded {
            what,
            needed,
            limit,
        }) => {
            // A level runs one invocation per frontier entry.
            assert_eq!(limit, 8 * 8 * 64, "{what}");
            assert!(what.starts_with("node pairs one level lists"), "{what}");
            assert!(needed > limit, "{needed}");
        }
        other => panic!("expected CapacityExceeded, got {other:?}"),
    }
    // The one-pass traversal's workgroups are one dispatch along x: more than the device's 8
    // per dimension are held at 8 (not a validation error at the dispatch), with the oracle's
    // answers.
    ctx.set_one_pass(u32::MAX);
    assert_eq!(ctx.one_pass(), 8);
    let small: Vec<_> = poses
        .iter()
        .map(|(pa, pb)| (&a.gpu, pa, &a.gpu, pb))
        .collect();
    let got = ctx
        .collide_batch(&small, &mut QueryScratch::default())
        .expect("8 workgroups");
    for (k, (pa, pb)) in poses.iter().enumerate() {
        assert_eq!(
            got.results[k].pairs,
            oracle::pairs(&a.mesh, pa, &a.mesh, pb),
            "pair {k}, one pass"
        );
    }
}

#[test]
fn callers_device_is_used_and_its_limits_checked() {
    use frcd_gpgpu::wgpu;
    // An engine's own device with default limits: accepted, and queries work on it.
    let Some((adapter, device, queue)) = adapter_and_device(wgpu::Limits::default()) else {
        return;
    };
    let ctx = GpuContext::from_adapter(&adapter, device, queue).expect("default limits suffice");
    let a = body(&ctx, shapes::icosphere(1.0, 2));
    let pb = Pose::from_translation(DVec3::new(1.1, 0.0, 0.2));
    let got = ctx
        .collide(
            &a.gpu,
            &Pose::IDENTITY,
            &a.gpu,
            &pb,
            &mut QueryScratch::default(),
        )
        .unwrap();
    assert_eq!(
        got.pairs,
        oracle::pairs(&a.mesh, &Pose::IDENTITY, &a.mesh, &pb)
    );
    // A device created with WebGL2-level limits (no storage buffers in compute): refused with
    // the limit named, read from the device rather than assumed.
    let Some((_, device, queue)) = adapter_and_device(wgpu::Limits::downlevel_webgl2_defaults())
    else {
        return;
    };
    match GpuContext::from_device(device, queue) {
        Err(GpuError::Unsupported {
            what,
            needed,
            available,
            ..
        }) => {
            assert!(needed > available, "{what}: {needed} vs {available}");
        }
        other => panic!("expected Unsupported, got {other:?}"),
    }
}

#[test]
fn meshes_that_do_not_fit_are_a_typed_error() {
    // One item per row and per layer: a 5,120-triangle mesh needs more layers than a device
    // offers (2,048 on lavapipe, 256 in WebGPU): a typed error, not a panic.
    let opts = HeadlessOptions {
        arena: ArenaOptions {
            items_per_row: Some(1),
            rows_per_layer: Some(1),
        },
        ..Default::default()
    };
    let Ok(ctx) = GpuContext::headless_with(&opts) else {
        assert!(!require_gpu());
        return;
    };
    let big = 1 + ctx.limits().max_texture_array_layers as usize;
    let mut sub = 0;
    while 20 * 4usize.pow(sub) < big {
        sub += 1;
    }
    let t = tree(&shapes::icosphere(1.0, sub));
    assert!(matches!(ctx.upload(&t), Err(GpuError::MeshTooLarge { .. })));
    // The context still works for meshes that fit.
    ctx.upload(&tree(&shapes::icosphere(1.0, 0))).unwrap();
}

#[test]
fn trees_with_huge_leaves_are_a_typed_error() {
    // An entry lists the triangle pairs of its leaf pairs in loops, which a software driver
    // ends after 65,535 iterations: leaves above the limit are refused at upload (leaves of 160
    // triangles lost pairs on llvmpipe when the limit was 256).
    let Some(ctx) = shared() else { return };
    let mesh = shapes::icosphere(1.0, 4);
    let limit = frcd_gpgpu::MAX_LEAF_TRIANGLES;
    assert!(mesh.triangle_count() > limit as usize);
    let leaves = |max_leaf_triangles| BuildOptions {
        max_leaf_triangles,
        ..BuildOptions::default()
    };
    let t = ObbTree::build(&mesh, &leaves(u32::MAX));
    assert!(matches!(
        ctx.upload(&t),
        Err(GpuError::MeshTooLarge { needed, .. }) if needed == mesh.triangle_count() as u64
    ));
    // Leaves at the limit still upload and answer.
    let t = ObbTree::build(&mesh, &leaves(limit));
    let g = ctx.upload(&t).unwrap();
    let pb = Pose::from_translation(DVec3::new(0.5, 0.1, 0.0));
    let got = ctx
        .collide(&g, &Pose::IDENTITY, &g, &pb, &mut QueryScratch::default())
        .unwrap();
    let want = oracle::pairs(&mesh, &Pose::IDENTITY, &mesh, &pb);
    assert!(!want.is_empty());
    assert_eq!(got.pairs, want);
}

#[test]
fn public_types_are_send_and_sync() {
    fn check<T: Send + Sync>() {}
    check::<GpuContext>();
    check::<GpuMesh>();
    check::<QueryScratch>();
    check::<BoxScratch>();
    check::<GpuError>();
}

#[test]
fn meshes_far_from_their_local_origin() {
    // f32 keeps ~7 digits: 1e3..3e4 away from the local origin the rounding is a sizeable
    // fraction of a triangle, so the box and triangle error bounds carry the answer.
    let Some(ctx) = shared() else { return };
    for offset in [
        DVec3::new(1.0e3, -700.0, 250.0),
        DVec3::new(3.0e4, -1.0e4, 5.0e3),
    ] {
        let at = Pose::from_translation(offset);
        let mesh = shapes::icosphere(1.0, 3).transformed(&at);
        let a = body(ctx, mesh.clone());
        let b = body(ctx, mesh);
        // B turned about the sphere's centre and shifted: the spheres cross.
        let poses: Vec<(Pose, Pose)> = [0.3, 1.2, 1.9]
            .iter()
            .map(|&d| {
                let turn = Pose::new(DVec3::new(d, 0.2, 0.0), DQuat::from_rotation_y(0.4 * d));
                (Pose::IDENTITY, at.compose(&turn).compose(&at.inverse()))
            })
            .collect();
        let (pairs, _) = agree(ctx, &a, &b, &poses, &mut QueryScratch::default(), false);
        assert!(pairs > 50, "{pairs}");
    }
}

/// Issue 11: on every wgpu backend present (Vulkan and GL here, whichever the machine has),
/// the context is either refused with a typed error at creation or answers exactly like the
/// oracle: never a wrong answer. GL's one-layer textures once read back as zeros (0 pairs).
#[test]
fn every_backend_is_correct_or_refused_at_creation() {
    let mut ran = Vec::new();
    for (name, backends) in [
        ("vulkan", frcd_gpgpu::wgpu::Backends::VULKAN),
        ("gl", frcd_gpgpu::wgpu::Backends::GL),
    ] {
        let opts = frcd_gpgpu::HeadlessOptions {
            backends: Some(backends),
            ..Default::default()
        };
        let ctx = match GpuContext::headless_with(&opts) {
            Ok(c) => c,
            Err(e @ GpuError::NoAdapter(_)) => {
                println!("SKIP backend {name}: {e}");
                continue;
            }
            // RequestDevice: an adapter whose driver cannot make a device (NVIDIA's GL through
            // EGL in a headless VM: "Parent device is lost", seen on an H200).
            Err(
                e @ (GpuError::Unsupported { .. }
                | GpuError::Pipeline { .. }
                | GpuError::RequestDevice { .. }),
            ) => {
                println!("backend {name} refused at creation (typed): {e}");
                continue;
            }
            Err(e) => panic!("backend {name}: unexpected error at creation: {e}"),
        };
        println!("backend {name}: {:?}", ctx.adapter_info());
        let a = body(&ctx, shapes::icosphere(1.0, 3));
        let b = body(&ctx, shapes::torus(0.8, 0.25, 32, 12).expect("torus"));
        let poses: Vec<(Pose, Pose)> = (0..5)
            .map(|k| {
                (
                    Pose::from_translation(DVec3::new(3e3, -1e3, 7.0)),
                    Pose::new(
                        DVec3::new(3e3 + 0.35 * k as f64 - 0.7, -1e3 + 0.1, 7.0),
                        DQuat::from_rotation_x(0.4 * k as f64),
                    ),
                )
            })
            .collect();
        // Tiny buffers: the overflow re-run path runs on this backend too.
        let mut scratch = QueryScratch::with_capacity(4, 4);
        let (pairs, _) = agree(&ctx, &a, &b, &poses, &mut scratch, false);
        assert!(pairs > 0, "backend {name}: the sweep must touch");
        let boxes: Vec<Aabb> = (0..150)
            .map(|i| {
                let c = DVec3::new((i % 10) as f64, ((i / 10) % 5) as f64, (i / 50) as f64);
                Aabb::new(c, c + DVec3::splat(0.6 + 0.5 * ((i % 3) as f64)))
            })
            .collect();
        let got = ctx
            .overlapping_bodies(&boxes, &mut BoxScratch::default())
            .unwrap();
        assert_eq!(got.pairs, cpu_box_pairs(&boxes), "backend {name}: box pass");
        ran.push(name);
    }
    if require_gpu() {
        assert!(!ran.is_empty(), "FRCD_REQUIRE_GPU=1 but no backend ran");
    }
}

/// Contexts created, used and dropped on several threads at once (what hung NVIDIA's driver on
/// an H200 before creation and drops were serialised by `frcd_gpu::creation_lock`): every
/// thread finishes with the oracle's answer. On lavapipe this checks that the lock never
/// deadlocks (nested drops, creation inside a held lock); the hang itself needs NVIDIA.
#[test]
fn contexts_created_and_dropped_on_many_threads() {
    if new_context().is_none() {
        return;
    }
    let mesh = shapes::icosphere(1.0, 2);
    let (pa, pb) = (
        Pose::IDENTITY,
        Pose::from_translation(DVec3::new(1.2, 0.3, 0.1)),
    );
    let want = oracle::pairs(&mesh, &pa, &mesh, &pb);
    assert!(!want.is_empty());
    std::thread::scope(|scope| {
        for _ in 0..4 {
            scope.spawn(|| {
                for _ in 0..3 {
                    let ctx = new_context().expect("an adapter was found above");
                    let a = body(&ctx, mesh.clone());
                    let got = ctx
                        .collide(&a.gpu, &pa, &a.gpu, &pb, &mut QueryScratch::default())
                        .expect("query");
                    assert_eq!(got.pairs, want);
                    // Meshes and scratch first, the context last: its drop releases the device.
                    drop(a);
                    drop(ctx);
                }
            });
        }
    });
}

/// More body pairs than the device's pose texture holds (256 pairs a row, as many rows as its
/// 2D textures allow): a typed error before any GPU work, naming the limit.
#[test]
fn batches_beyond_the_pose_texture_are_a_typed_error() {
    use frcd_gpgpu::wgpu;
    let Some((adapter, device, queue)) = adapter_and_device_on(
        wgpu::InstanceDescriptor::new_without_display_handle_from_env(),
        |l| wgpu::Limits {
            max_texture_dimension_2d: 2048,
            ..l
        },
    ) else {
        return;
    };
    let ctx = GpuContext::from_adapter(&adapter, device, queue).expect("limits suffice");
    let a = body(&ctx, shapes::icosphere(1.0, 1));
    let (pa, pb) = (Pose::IDENTITY, Pose::from_translation(DVec3::X));
    let most = 256 * 2048;
    let batch = vec![(&a.gpu, &pa, &a.gpu, &pb); most];
    let before = ctx.submissions();
    match ctx.collide_batch(&batch, &mut QueryScratch::default()) {
        Err(GpuError::CapacityExceeded {
            what,
            needed,
            limit,
        }) => {
            assert_eq!(what, "body pairs in one batch");
            assert_eq!((needed, limit), (most as u64, most as u64 - 1));
        }
        other => panic!("expected CapacityExceeded, got {other:?}"),
    }
    assert_eq!(ctx.submissions(), before, "nothing submitted");
    // The context is unharmed: a small batch still answers.
    let small = ctx
        .collide_batch(&batch[..3], &mut QueryScratch::default())
        .unwrap();
    let want = oracle::pairs(&a.mesh, &pa, &a.mesh, &pb);
    assert!(small.results.iter().all(|r| r.pairs == want));
}

/// The CPU's front (`GpuContext::set_host_front`): whatever its budget, every batch equals the
/// oracle pair for pair, the GPU runs no more levels than from the roots, and a budget large
/// enough to reach the leaves leaves the GPU one level (the leaf pairs' boxes, then their
/// triangles); the CPU's box tests are counted and timed.
#[test]
fn the_cpu_front_changes_no_answer_and_takes_levels_off_the_gpu() {
    let Some(mut ctx) = new_context() else { return };
    let a = body(&ctx, shapes::icosphere(1.0, 3));
    let b = body(&ctx, shapes::torus(0.8, 0.25, 48, 16).expect("torus"));
    // Touching, deep, grazing and apart pairs in one batch.
    let poses: Vec<(Pose, Pose)> = [
        DVec3::new(0.7, 0.1, 0.0),
        DVec3::new(0.1, 0.0, 0.05),
        DVec3::new(1.9, 0.3, 0.2),
        DVec3::new(6.0, 0.0, 0.0),
        DVec3::new(0.0, 1.0, 0.3),
    ]
    .iter()
    .enumerate()
    .map(|(k, &t)| {
        (
            Pose::from_translation(DVec3::X * 10.0 * k as f64),
            Pose::new(
                DVec3::X * 10.0 * k as f64 + t,
                DQuat::from_rotation_x(0.3 * k as f64),
            ),
        )
    })
    .collect();
    let want: Vec<_> = poses
        .iter()
        .map(|(pa, pb)| oracle::pairs(&a.mesh, pa, &b.mesh, pb))
        .collect();
    assert!(want.iter().filter(|w| !w.is_empty()).count() >= 3);
    assert!(want.iter().any(|w| w.is_empty()));
    let batch: Vec<_> = poses
        .iter()
        .map(|(pa, pb)| (&a.gpu, pa, &b.gpu, pb))
        .collect();
    let mut run = |budget: u32| {
        ctx.set_host_front(budget);
        let got = ctx
            .collide_batch(&batch, &mut QueryScratch::default())
            .expect("batch");
        for (k, (r, w)) in got.results.iter().zip(&want).enumerate() {
            assert_eq!(&r.pairs, w, "budget {budget}, pair {k}");
        }
        got
    };
    let roots = run(0);
    assert_eq!(roots.timings.host_front, std::time::Duration::ZERO);
    let depth = a.gpu.depth().max(b.gpu.depth());
    assert_eq!((roots.levels, roots.host_levels), (depth, 0));
    let mut last = roots.levels;
    for budget in [4, 64, 1024, 16384] {
        let got = run(budget);
        assert!(got.levels <= last, "budget {budget}: {} levels", got.levels);
        assert!(got.timings.host_front > std::time::Duration::ZERO);
        // (Four box tests cannot take the first step of five pairs.)
        assert!(budget < 64 || got.host_levels > 0, "budget {budget}");
        last = got.levels;
    }
    assert!(last < roots.levels);
    // Down to the leaves on the CPU: the GPU tests the leaf pairs only.
    let leaves = run(u32::MAX);
    assert_eq!(leaves.levels, 1);
    assert!(leaves.host_levels + 1 >= last);
    assert!(leaves.node_pairs_tested > 0);
    // A mesh uploaded with the front off keeps no CPU copy of its tree: its pairs start at
    // the roots, with the same answers, even with the front on.
    ctx.set_host_front(0);
    let bare = body(&ctx, shapes::torus(0.8, 0.25, 48, 16).expect("torus"));
    ctx.set_host_front(u32::MAX);
    let mixed: Vec<_> = poses
        .iter()
        .map(|(pa, pb)| (&a.gpu, pa, &bare.gpu, pb))
        .collect();
    let got = ctx
        .collide_batch(&mixed, &mut QueryScratch::default())
        .expect("batch");
    for (k, (r, w)) in got.results.iter().zip(&want).enumerate() {
        assert_eq!(&r.pairs, w, "pair {k} with a bare mesh");
    }
    assert_eq!((got.levels, got.host_levels), (depth, 0));
}
