//! Clearance per frame: every checked body pair closer than its threshold, with its distance,
//! closest points and triangle pair (issue 12, item 3).
//!
//! The checker computes it ([`frcd_hybrid::Options::clearance`] and `pair_clearances`, on
//! frcd-obb's `pair_clearance_cached`): a broad phase on world boxes grown by the threshold, so
//! pairs whose boxes stay farther apart cost no distance query; per-pair state between frames,
//! so a pair proved farther than its threshold by its last distance less the bodies' motion
//! since costs none either; a search bounded by the decision band, and an exact `within` in
//! the band. This module maps the scene's thresholds onto the checker's options and the
//! checker's answers onto report records.

use frcd_geom::DVec3;
use frcd_hybrid::{FrameResult, Options};
use frcd_io::Clearances;

/// Puts the run's thresholds (scene-wide and per pair, by body index) into the checker's
/// options. Static pairs and excluded pairs are never checked (the checker's rule).
pub fn apply(clearances: &Clearances, options: &mut Options) {
    options.clearance = clearances.default;
    options.pair_clearances = clearances
        .pairs
        .iter()
        .map(|&(a, b, t)| ((a, b), t))
        .collect();
}

/// One body pair closer than its threshold in one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Record {
    /// Body indices, `a < b`.
    pub a: usize,
    /// Second body.
    pub b: usize,
    /// Distance between the surfaces (0 when they touch or cross, or when `contained`).
    pub distance: f64,
    /// Closest points in world coordinates (on `a`, on `b`).
    pub points: [DVec3; 2],
    /// The triangle pair the points lie on.
    pub triangles: (u32, u32),
    /// One body lies inside the other (solid mode: no surface pair touches).
    pub contained: bool,
}

/// The clearance records of one frame of the checker, sorted by `(a, b)`.
pub fn records(r: &FrameResult) -> Vec<Record> {
    let mut out: Vec<Record> = r
        .clearances
        .iter()
        .map(|c| {
            let contained = c.interfering
                && r.contacts.iter().any(|k| {
                    (k.a.min(k.b), k.a.max(k.b)) == (c.a.min(c.b), c.a.max(c.b))
                        && k.pairs.is_empty()
                        && k.contained.is_some()
                });
            Record {
                a: c.a,
                b: c.b,
                distance: c.distance,
                points: c.points,
                triangles: c.triangles,
                contained,
            }
        })
        .collect();
    out.sort_by_key(|r| (r.a, r.b));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use frcd_geom::{DQuat, Pose, TriMesh, shapes};
    use frcd_hybrid::{Backend, BodySpec, Checker, FrameState};
    use std::sync::Arc;

    /// A small scene: spheres and boxes placed along a line with gaps around the thresholds,
    /// under random rigid motions.
    fn meshes() -> Vec<TriMesh> {
        vec![
            shapes::icosphere(0.5, 2),
            shapes::cuboid(DVec3::new(0.3, 0.2, 0.4)),
            shapes::icosphere(0.35, 1),
            shapes::cuboid(DVec3::splat(0.25)),
        ]
    }

    /// A deterministic generator (xorshift), so failures reproduce.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
        fn range(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * self.next()
        }
    }

    /// A CPU checker over `meshes` with these thresholds, exclusions and static flags.
    fn checker(
        meshes: &[Arc<TriMesh>],
        clearances: &Clearances,
        exclude: &[(usize, usize)],
        is_static: &[bool],
    ) -> Checker {
        let bodies = meshes
            .iter()
            .enumerate()
            .map(|(i, m)| BodySpec {
                name: format!("b{i}"),
                mesh: m.clone(),
                is_static: is_static[i],
            })
            .collect();
        let mut options = Options {
            backend: Backend::Cpu,
            ..Options::default()
        };
        apply(clearances, &mut options);
        Checker::new(bodies, exclude, options).unwrap()
    }

    /// The checker's clearances, through the run's state (cached) and a fresh state every frame
    /// (uncached), against the brute-force oracle; under random motions and under slow ones
    /// (where the motion bound skips queries).
    #[test]
    fn matches_brute_force_oracle_on_generated_frames() {
        let meshes: Vec<Arc<TriMesh>> = meshes().into_iter().map(Arc::new).collect();
        let n = meshes.len();
        let mut clearances = Clearances {
            default: Some(0.05),
            pairs: vec![(0, 2, 0.2), (1, 3, 0.0)],
        };
        let exclude = [(2, 3)];
        let is_static = vec![false; n];
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let (mut reported, mut far, mut skipped) = (0, 0, 0);
        let mut ch = checker(&meshes, &clearances, &exclude, &is_static);
        let mut state = FrameState::default();
        // Random poses, then slow drifts from the last of them.
        let mut poses: Vec<Pose> = Vec::new();
        let mut drift: Vec<(DVec3, DQuat)> = Vec::new();
        for frame in 0..120 {
            if frame == 30 {
                // A scene-wide threshold that covers every pair near each other.
                clearances.default = Some(0.3);
                ch = checker(&meshes, &clearances, &exclude, &is_static);
                state = FrameState::default();
            }
            if frame < 60 || frame % 20 == 0 {
                poses = (0..n)
                    .map(|i| {
                        let axis = DVec3::new(
                            rng.range(-1.0, 1.0),
                            rng.range(-1.0, 1.0),
                            rng.range(-1.0, 1.0),
                        );
                        let axis = axis.try_normalize().unwrap_or(DVec3::Z);
                        let q = DQuat::from_axis_angle(axis, rng.range(-3.0, 3.0));
                        let t = DVec3::new(
                            i as f64 * 0.9 + rng.range(-0.3, 0.3),
                            rng.range(-0.3, 0.3),
                            rng.range(-0.3, 0.3),
                        );
                        Pose::new(t, q)
                    })
                    .collect();
                drift = (0..n)
                    .map(|_| {
                        let v = DVec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), 0.0);
                        (v * 2e-3, DQuat::from_rotation_z(rng.range(-2e-3, 2e-3)))
                    })
                    .collect();
            } else {
                for (p, (v, q)) in poses.iter_mut().zip(&drift) {
                    *p = Pose::new(p.translation + *v, (*q * p.rotation).normalize());
                }
            }
            let r = ch.check(&poses, &mut state).unwrap();
            let fresh = ch.check(&poses, &mut FrameState::default()).unwrap();
            let got = records(&r);
            let want = records(&fresh);
            assert_eq!(got.len(), want.len(), "frame {frame}: cached vs fresh");
            for (g, w) in got.iter().zip(&want) {
                assert_eq!((g.a, g.b, g.contained), (w.a, w.b, w.contained));
                assert!((g.distance - w.distance).abs() <= 1e-12, "{g:?} vs {w:?}");
            }
            let work = r.clearance_work;
            assert!(work.distance_queries + work.skipped <= work.pairs);
            skipped += work.skipped;
            for a in 0..n {
                for b in a + 1..n {
                    let rec = got.iter().find(|r| (r.a, r.b) == (a, b));
                    let t = if exclude.contains(&(a, b)) {
                        None
                    } else {
                        clearances.threshold(a, b)
                    };
                    let Some(t) = t else {
                        assert!(
                            rec.is_none(),
                            "frame {frame}: pair {a}/{b} has no threshold"
                        );
                        continue;
                    };
                    let (ma, mb) = (&*meshes[a], &*meshes[b]);
                    let (pa, pb) = (&poses[a], &poses[b]);
                    let o = frcd_obb::oracle::distance(ma, pa, mb, pb);
                    let hit = frcd_obb::oracle::answer(ma, pa, mb, pb, true).collide();
                    let exact_within = frcd_obb::oracle::within_exact(ma, pa, mb, pb, t);
                    assert_eq!(
                        rec.is_some(),
                        exact_within || hit,
                        "frame {frame}: pair {a}/{b} threshold {t}, oracle distance {}",
                        o.distance
                    );
                    let Some(rec) = rec else {
                        far += (o.distance > 0.0) as usize;
                        continue;
                    };
                    reported += 1;
                    let want = if hit { 0.0 } else { o.distance };
                    assert!(
                        (rec.distance - want).abs() <= 1e-12,
                        "frame {frame}: pair {a}/{b}: {} vs oracle {want}",
                        rec.distance
                    );
                    if hit {
                        continue;
                    }
                    assert!(
                        ((rec.points[0] - rec.points[1]).length() - rec.distance).abs() <= 1e-12
                    );
                    // The closest points lie on the reported triangles.
                    let on = |m: &TriMesh, pose: &Pose, t: u32, p: DVec3| {
                        let tri = m.triangle(t as usize);
                        let local = pose.inverse().transform_point(p);
                        let c = frcd_obb::oracle::closest_point_on_triangle(
                            local, tri.v[0], tri.v[1], tri.v[2],
                        );
                        (c - local).length() <= 1e-12
                    };
                    assert!(on(ma, pa, rec.triangles.0, rec.points[0]));
                    assert!(on(mb, pb, rec.triangles.1, rec.points[1]));
                }
            }
        }
        // The generated frames exercise every branch: reported, farther, skipped by motion.
        assert!(reported > 20, "reported {reported}");
        assert!(far > 20, "far {far}");
        assert!(skipped > 10, "skipped by the motion bound {skipped}");
    }

    #[test]
    fn far_pairs_cost_no_query_and_touching_pairs_report_zero() {
        let m = Arc::new(shapes::cuboid(DVec3::splat(0.5)));
        let meshes = [m.clone(), m.clone(), m];
        // 0 and 1 touch face to face; 2 is 4 mm from 1 (within 5 mm), 1.504 from 0.
        let poses = [
            Pose::IDENTITY,
            Pose::from_translation(DVec3::new(1.0, 0.0, 0.0)),
            Pose::from_translation(DVec3::new(2.004, 0.0, 0.0)),
        ];
        let th = Clearances {
            default: Some(0.005),
            pairs: vec![],
        };
        let ch = checker(&meshes, &th, &[], &[false; 3]);
        let r = ch.check(&poses, &mut FrameState::default()).unwrap();
        let recs = records(&r);
        assert_eq!(recs.len(), 2, "{recs:?}");
        assert_eq!((recs[0].a, recs[0].b, recs[0].distance), (0, 1, 0.0));
        assert_eq!((recs[1].a, recs[1].b), (1, 2));
        assert!((recs[1].distance - 0.004).abs() < 1e-12);
        // Pair 0/2 is far: no evaluation at all; the touching pair needs no query.
        assert_eq!(r.clearance_work.pairs, 2);
        assert_eq!(r.clearance_work.distance_queries, 1);
        // Contained pairs report 0, whatever their surfaces' distance.
        let small = Arc::new(shapes::cuboid(DVec3::splat(0.1)));
        let big = Arc::new(shapes::cuboid(DVec3::splat(0.5)));
        let ch = checker(&[big, small], &th, &[], &[false; 2]);
        let r = ch
            .check(
                &[Pose::IDENTITY, Pose::IDENTITY],
                &mut FrameState::default(),
            )
            .unwrap();
        let recs = records(&r);
        assert_eq!(recs.len(), 1);
        assert!(recs[0].contained && recs[0].distance == 0.0);
        // No threshold: nothing.
        let ch = checker(&meshes, &Clearances::default(), &[], &[false; 3]);
        let r = ch.check(&poses, &mut FrameState::default()).unwrap();
        assert!(records(&r).is_empty());
        // Both static, or excluded: never reported.
        let ch = checker(&meshes, &th, &[(1, 2)], &[true, true, false]);
        let r = ch.check(&poses, &mut FrameState::default()).unwrap();
        assert!(records(&r).is_empty(), "{:?}", records(&r));
    }
}
