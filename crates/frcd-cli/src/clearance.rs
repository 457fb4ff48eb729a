//! Clearance per frame: every checked body pair closer than its threshold, with its distance,
//! closest points and triangle pair (issue 12, item 3).
//!
//! [`frame_clearances`] is the one place that computes it. It runs a broad phase on world boxes
//! grown by the threshold, so pairs whose boxes stay farther apart than their threshold cost no
//! distance query, decides "closer than the threshold" exactly with
//! [`frcd_obb::distance::within`], and only then asks [`frcd_obb::distance::distance`] for the
//! value and the closest points. (When the checker computes clearance itself, this function's
//! body becomes a call to it.)

use frcd_geom::{Aabb, DVec3, Pose};
use frcd_io::Clearances;
use frcd_obb::ObbTree;
use frcd_obb::distance::{DistanceRequest, distance_below, error_bound, within};
use std::collections::HashSet;

/// Which body pairs have a clearance threshold, and what it is.
#[derive(Clone, Debug, Default)]
pub struct Thresholds {
    /// Scene-wide and per-pair thresholds (by body index).
    pub clearances: Clearances,
    /// Pairs never checked (`a < b`).
    pub excluded: HashSet<(usize, usize)>,
    /// Static bodies (a pair of two is never checked).
    pub is_static: Vec<bool>,
}

impl Thresholds {
    /// The threshold of the pair `a < b`, `None` when the pair is not checked or has none.
    pub fn of(&self, a: usize, b: usize) -> Option<f64> {
        let static_pair = self.is_static.get(a).copied().unwrap_or(false)
            && self.is_static.get(b).copied().unwrap_or(false);
        if static_pair || self.excluded.contains(&(a.min(b), a.max(b))) {
            return None;
        }
        self.clearances.threshold(a, b)
    }
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
    /// One body lies inside the other (from the checker's solid-mode answer).
    pub contained: bool,
}

/// Work done by one call, for the tests and the timing notes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Work {
    /// Pairs whose grown boxes come within the threshold.
    pub candidates: usize,
    /// Distance queries run (candidates the checker did not find touching).
    pub distance_queries: usize,
    /// Exact `within` decisions (distance within its error band of the threshold).
    pub exact_decisions: usize,
}

/// A conservative world box of a posed tree: the local box mapped by the pose, grown by a
/// relative margin that covers the rounding of the mapping (as the checker's broad phase).
fn world_box(tree: &ObbTree, pose: &Pose) -> Aabb {
    let b = tree.aabb().transformed(pose);
    let mag = b.min.abs().max(b.max.abs()).max_element();
    b.inflated(mag * 1e-12 + f64::MIN_POSITIVE)
}

/// Euclidean distance between two boxes (0 when they overlap).
fn box_gap(x: &Aabb, y: &Aabb) -> f64 {
    let d = (y.min - x.max).max(x.min - y.max).max(DVec3::ZERO);
    d.length()
}

/// The clearance records of one frame, sorted by `(a, b)`.
///
/// - `trees[i]`, `poses[i]`: body `i`'s tree and world pose (same length);
/// - `thresholds`: which pairs are checked and their thresholds;
/// - `contained`: pairs `(a, b)`, `a < b`, the checker found one inside the other this frame
///   (they report distance 0 whatever their surfaces' distance);
/// - `touching`: `(a, b, tri_a, tri_b)`, `a < b`: one touching triangle pair of each pair the
///   checker found interfering (distance 0 on that pair, no distance query).
///
/// A pair is reported when its surfaces come within its threshold (decided exactly for the f64
/// inputs: by the distance and its error bound, by [`within`] when that is not enough), or it
/// touches or is `contained`. Pairs whose grown world boxes stay apart cost no query.
pub fn frame_clearances(
    trees: &[&ObbTree],
    poses: &[Pose],
    thresholds: &Thresholds,
    contained: &[(usize, usize)],
    touching: &[(usize, usize, u32, u32)],
) -> (Vec<Record>, Work) {
    let mut work = Work::default();
    let mut out = Vec::new();
    let Some(grow) = thresholds.clearances.max_threshold() else {
        return (out, work);
    };
    let n = trees.len().min(poses.len());
    let boxes: Vec<Aabb> = (0..n).map(|i| world_box(trees[i], &poses[i])).collect();
    // Sweep and prune on x with every box grown by the largest threshold.
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&i, &j| boxes[i].min.x.total_cmp(&boxes[j].min.x));
    for (k, &i) in order.iter().enumerate() {
        let reach = boxes[i].max.x + grow;
        for &j in &order[k + 1..] {
            if boxes[j].min.x > reach {
                break;
            }
            let (a, b) = (i.min(j), i.max(j));
            let Some(threshold) = thresholds.of(a, b) else {
                continue;
            };
            let is_contained = contained.contains(&(a, b));
            if !is_contained && box_gap(&boxes[a], &boxes[b]) > threshold {
                // Touching pairs' boxes overlap, so none is lost here.
                continue;
            }
            work.candidates += 1;
            let (ta, tb, pa, pb) = (trees[a], trees[b], &poses[a], &poses[b]);
            if let Some(&(_, _, x, y)) = touching.iter().find(|t| (t.0, t.1) == (a, b)) {
                // The checker found this triangle pair touching: distance 0, no query.
                if x as usize >= ta.triangle_count() || y as usize >= tb.triangle_count() {
                    continue;
                }
                let tri_a = ta.triangle(x);
                let tri_b = frcd_obb::RelativeFrame::new(pa, pb).triangle(&tb.triangle(y));
                let (_, p, q) = frcd_obb::oracle::closest_points_triangles(&tri_a, &tri_b);
                out.push(Record {
                    a,
                    b,
                    distance: 0.0,
                    points: [pa.transform_point(p), pa.transform_point(q)],
                    triangles: (x, y),
                    contained: false,
                });
                continue;
            }
            work.distance_queries += 1;
            // `d` is the length of a real point pair (up to the rounding in `error_bound`), so
            // `d + error_bound <= threshold` proves the pair within. It is also accurate to
            // `error_bound` for well-conditioned features and to ~sqrt(ε)·L in the worst case
            // (see `frcd_obb::distance`): `WORST` covers that with a wide margin. In the band
            // between, `within` decides exactly. The search is bounded by the top of that band:
            // a pair farther apart never opens the node pairs a full distance query would.
            const WORST: f64 = (1u64 << 28) as f64;
            let band = DistanceRequest::default();
            // A contained pair reports 0 with its closest surface points, however far apart
            // those are: no limit then.
            let limit = if is_contained {
                f64::INFINITY
            } else {
                threshold + WORST * error_bound(ta, pa, tb, pb)
            };
            let Some(d) = distance_below(ta, pa, tb, pb, &band, limit) else {
                continue;
            };
            if d.distance.is_nan() {
                continue; // non-finite poses: the scene loader refuses them
            }
            let inside = is_contained
                || d.distance + d.error_bound <= threshold
                || (d.distance - d.error_bound * WORST <= threshold && {
                    work.exact_decisions += 1;
                    within(ta, pa, tb, pb, threshold)
                });
            if !inside {
                continue;
            }
            out.push(Record {
                a,
                b,
                distance: if is_contained { 0.0 } else { d.distance },
                points: d.points,
                triangles: d.triangles,
                contained: is_contained,
            });
        }
    }
    out.sort_by_key(|r| (r.a, r.b));
    (out, work)
}

#[cfg(test)]
mod tests {
    use super::*;
    use frcd_geom::{DQuat, TriMesh, shapes};
    use frcd_obb::BuildOptions;

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

    #[test]
    fn matches_brute_force_oracle_on_generated_frames() {
        let meshes = meshes();
        let trees: Vec<ObbTree> = meshes
            .iter()
            .map(|m| ObbTree::build(m, &BuildOptions::default()))
            .collect();
        let tree_refs: Vec<&ObbTree> = trees.iter().collect();
        let n = trees.len();
        let mut thresholds = Thresholds {
            clearances: Clearances {
                default: Some(0.05),
                pairs: vec![(0, 2, 0.2), (1, 3, 0.0)],
            },
            excluded: [(2, 3)].into_iter().collect(),
            is_static: vec![false; n],
        };
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let (mut reported, mut skipped, mut far) = (0, 0, 0);
        for frame in 0..60 {
            if frame == 30 {
                // Halfway: a scene-wide threshold that covers every pair near each other.
                thresholds.clearances.default = Some(0.3);
            }
            let poses: Vec<Pose> = (0..n)
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
            let (got, work) = frame_clearances(&tree_refs, &poses, &thresholds, &[], &[]);
            assert!(work.distance_queries <= work.candidates);
            for a in 0..n {
                for b in a + 1..n {
                    let r = got.iter().find(|r| (r.a, r.b) == (a, b));
                    let Some(t) = thresholds.of(a, b) else {
                        assert!(r.is_none(), "frame {frame}: pair {a}/{b} has no threshold");
                        continue;
                    };
                    let o =
                        frcd_obb::oracle::distance(&meshes[a], &poses[a], &meshes[b], &poses[b]);
                    let exact_within = frcd_obb::oracle::within_exact(
                        &meshes[a], &poses[a], &meshes[b], &poses[b], t,
                    );
                    assert_eq!(
                        r.is_some(),
                        exact_within,
                        "frame {frame}: pair {a}/{b} threshold {t}, oracle distance {}",
                        o.distance
                    );
                    match r {
                        Some(r) => {
                            reported += 1;
                            assert!(
                                (r.distance - o.distance).abs() <= 1e-12,
                                "frame {frame}: pair {a}/{b}: {} vs oracle {}",
                                r.distance,
                                o.distance
                            );
                            assert!(
                                ((r.points[0] - r.points[1]).length() - r.distance).abs() <= 1e-12
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
                            assert!(on(&meshes[a], &poses[a], r.triangles.0, r.points[0]));
                            assert!(on(&meshes[b], &poses[b], r.triangles.1, r.points[1]));
                        }
                        None => {
                            if o.distance > 0.0 {
                                far += 1;
                            }
                            let boxes_apart = box_gap(
                                &world_box(&trees[a], &poses[a]),
                                &world_box(&trees[b], &poses[b]),
                            ) > t;
                            skipped += boxes_apart as usize;
                        }
                    }
                }
            }
        }
        // The generated frames exercise every branch: reported, skipped by boxes, farther.
        assert!(reported > 20, "reported {reported}");
        assert!(skipped > 20, "skipped by the broad phase {skipped}");
        assert!(far > skipped, "far {far}");
    }

    #[test]
    fn far_pairs_cost_no_query_and_touching_pairs_report_zero() {
        let m = shapes::cuboid(DVec3::splat(0.5));
        let t = ObbTree::build(&m, &BuildOptions::default());
        let trees = [&t, &t, &t];
        // 0 and 1 touch face to face; 2 is 4 mm from 1 (within 5 mm), 1.504 from 0.
        let poses = [
            Pose::IDENTITY,
            Pose::from_translation(DVec3::new(1.0, 0.0, 0.0)),
            Pose::from_translation(DVec3::new(2.004, 0.0, 0.0)),
        ];
        let th = Thresholds {
            clearances: Clearances {
                default: Some(0.005),
                pairs: vec![],
            },
            excluded: HashSet::new(),
            is_static: vec![false; 3],
        };
        let (r, work) = frame_clearances(&trees, &poses, &th, &[], &[]);
        assert_eq!(r.len(), 2, "{r:?}");
        assert_eq!((r[0].a, r[0].b, r[0].distance), (0, 1, 0.0));
        assert_eq!((r[1].a, r[1].b), (1, 2));
        assert!((r[1].distance - 0.004).abs() < 1e-12);
        // Pair 0/2 is far: no query at all.
        assert_eq!(work.candidates, 2);
        // Told that 0/1 touch on triangles (0, 0): distance 0 there, one query fewer.
        let (r2, work2) = frame_clearances(&trees, &poses, &th, &[], &[(0, 1, 0, 0)]);
        assert_eq!((r2[0].distance, r2[0].triangles), (0.0, (0, 0)));
        assert_eq!(work2.distance_queries, work.distance_queries - 1);
        // Contained pairs report 0, whatever their surfaces' distance; no threshold: nothing.
        let inner = Pose::IDENTITY;
        let small = shapes::cuboid(DVec3::splat(0.1));
        let ts = ObbTree::build(&small, &BuildOptions::default());
        let (r, _) = frame_clearances(&[&t, &ts], &[Pose::IDENTITY, inner], &th, &[(0, 1)], &[]);
        assert_eq!(r.len(), 1);
        assert!(r[0].contained && r[0].distance == 0.0);
        let none = Thresholds {
            is_static: vec![false; 3],
            ..Default::default()
        };
        assert!(
            frame_clearances(&trees, &poses, &none, &[], &[])
                .0
                .is_empty()
        );
        // Both static, or excluded: never reported.
        let mut st = th.clone();
        st.is_static = vec![true, true, false];
        st.excluded.insert((1, 2));
        assert!(frame_clearances(&trees, &poses, &st, &[], &[]).0.is_empty());
    }
}
