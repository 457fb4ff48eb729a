//! Checked pair queries: [`try_collide`] and [`try_collide_cached`] refuse poses that would make
//! the answer meaningless (NaN or infinite components, a zero quaternion, B mapped into A's frame
//! beyond the finite range) with a typed [`QueryError`], instead of answering "no collision".

use crate::query::{Collision, PairCache, RelativeFrame, Request, collide, collide_cached};
use crate::tree::ObbTree;
use frcd_geom::{Pose, PoseError};

/// Which body of a pair query.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PairSide {
    /// The first tree (`a`, `pose_a`).
    A,
    /// The second tree (`b`, `pose_b`).
    B,
}

impl std::fmt::Display for PairSide {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            PairSide::A => "A",
            PairSide::B => "B",
        })
    }
}

/// Why a checked query refused to answer.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum QueryError {
    /// A pose is not finite, or its rotation is not a unit quaternion.
    #[error("invalid pose of body {body}")]
    InvalidPose {
        /// Whose pose.
        body: PairSide,
        /// What is wrong with it.
        #[source]
        source: PoseError,
    },
    /// B's geometry, mapped into A's frame, would leave the finite f64 range (poses or meshes
    /// near ±1.8e308), where no exact answer can be computed.
    #[error(
        "body B mapped into A's frame reaches {reach:e}, beyond the finite f64 range (relative translation {translation:?})"
    )]
    OutOfRange {
        /// Bound on B's mapped coordinates (may be infinite).
        reach: f64,
        /// B's origin in A's frame.
        translation: [f64; 3],
    },
}

/// Checks both poses and the range of B mapped into A's frame.
fn check(a_pose: &Pose, b: &ObbTree, b_pose: &Pose, a: &ObbTree) -> Result<(), QueryError> {
    a_pose
        .validate()
        .map_err(|source| QueryError::InvalidPose {
            body: PairSide::A,
            source,
        })?;
    b_pose
        .validate()
        .map_err(|source| QueryError::InvalidPose {
            body: PairSide::B,
            source,
        })?;
    let frame = RelativeFrame::new(a_pose, b_pose);
    // Every mapped coordinate is at most |t|max + |p| (a rotation keeps lengths), plus rounding.
    let reach = frame.t.abs().max_element() + b.radius_from_origin * (1.0 + 1e-12);
    let a_reach = a.radius_from_origin;
    if !frame.t.is_finite()
        || !frame.m.is_finite()
        || !reach.is_finite()
        || reach >= f64::MAX
        || !a_reach.is_finite()
    {
        return Err(QueryError::OutOfRange {
            reach,
            translation: frame.t.to_array(),
        });
    }
    Ok(())
}

/// [`collide`] after checking the poses: a typed error for a NaN or infinite translation or
/// rotation, a zero or non-unit quaternion (see [`Pose::validate`]), or B mapped beyond the
/// finite range; otherwise exactly [`collide`]'s answer.
///
/// ```
/// use frcd_geom::{shapes, DQuat, DVec3, Pose};
/// use frcd_obb::{BuildOptions, ObbTree, QueryError, Request, try_collide};
/// let t = ObbTree::build(&shapes::icosphere(1.0, 1), &BuildOptions::default());
/// let ok = try_collide(&t, &Pose::IDENTITY, &t, &Pose::from_translation(DVec3::X), &Request::default());
/// assert!(ok.unwrap().collide);
/// let nan = Pose::from_translation(DVec3::new(f64::NAN, 0.0, 0.0));
/// assert!(matches!(
///     try_collide(&t, &Pose::IDENTITY, &t, &nan, &Request::default()),
///     Err(QueryError::InvalidPose { .. })
/// ));
/// // A pose built from a zero quaternion is refused too.
/// let zero = Pose::new(DVec3::ZERO, DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0));
/// assert!(try_collide(&t, &zero, &t, &Pose::IDENTITY, &Request::default()).is_err());
/// ```
pub fn try_collide(
    a: &ObbTree,
    pose_a: &Pose,
    b: &ObbTree,
    pose_b: &Pose,
    request: &Request,
) -> Result<Collision, QueryError> {
    check(pose_a, b, pose_b, a)?;
    Ok(collide(a, pose_a, b, pose_b, request))
}

/// [`collide_cached`] after the checks of [`try_collide`]; the cache is untouched on error.
pub fn try_collide_cached(
    a: &ObbTree,
    pose_a: &Pose,
    b: &ObbTree,
    pose_b: &Pose,
    request: &Request,
    cache: &mut PairCache,
) -> Result<Collision, QueryError> {
    check(pose_a, b, pose_b, a)?;
    Ok(collide_cached(a, pose_a, b, pose_b, request, cache))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{BuildOptions, Mode, oracle};
    use frcd_geom::{DQuat, DVec3, shapes};

    fn tree(m: &frcd_geom::TriMesh) -> ObbTree {
        ObbTree::build(m, &BuildOptions::default())
    }

    /// Regression (issue 11): NaN/inf translations and zero quaternions answered "no collision".
    #[test]
    fn bad_poses_are_refused_with_the_body_named() {
        let m = shapes::icosphere(1.0, 1);
        let t = tree(&m);
        let r = Request::default();
        let nan = f64::NAN;
        let inf = f64::INFINITY;
        let bad = [
            Pose::from_translation(DVec3::new(nan, 0.0, 0.0)),
            Pose::from_translation(DVec3::new(0.0, inf, 0.0)),
            Pose::new(DVec3::ZERO, DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0)),
            Pose::new(DVec3::ZERO, DQuat::from_xyzw(nan, 0.0, 0.0, 1.0)),
            Pose {
                translation: DVec3::ZERO,
                rotation: DQuat::from_xyzw(0.0, 0.0, 0.0, 3.0),
            },
        ];
        let mut cache = PairCache::default();
        for p in bad {
            match try_collide(&t, &Pose::IDENTITY, &t, &p, &r) {
                Err(QueryError::InvalidPose {
                    body: PairSide::B, ..
                }) => {}
                other => panic!("{p:?}: {other:?}"),
            }
            match try_collide_cached(&t, &p, &t, &Pose::IDENTITY, &r, &mut cache) {
                Err(QueryError::InvalidPose {
                    body: PairSide::A, ..
                }) => {}
                other => panic!("{p:?}: {other:?}"),
            }
        }
    }

    #[test]
    fn poses_beyond_the_finite_range_are_refused() {
        let t = tree(&shapes::icosphere(1.0, 1));
        let r = Request::default();
        let a = Pose::from_translation(DVec3::new(-1.5e308, 0.0, 0.0));
        let b = Pose::from_translation(DVec3::new(1.5e308, 0.0, 0.0));
        assert!(matches!(
            try_collide(&t, &a, &t, &b, &r),
            Err(QueryError::OutOfRange { .. })
        ));
        // Large but representable offsets are answered (and equal the oracle).
        let a = Pose::from_translation(DVec3::new(1e300, 0.0, 0.0));
        let b = Pose::from_translation(DVec3::new(1e300, 0.0, 0.0));
        assert!(try_collide(&t, &a, &t, &b, &r).unwrap().collide);
    }

    #[test]
    fn valid_poses_give_collides_answer() {
        let m = shapes::icosphere(1.0, 2);
        let t = tree(&m);
        let r = Request {
            mode: Mode::AllPairs,
            ..Request::default()
        };
        for k in 0..20 {
            let pb = Pose::new(
                DVec3::new(0.1 * k as f64, 0.05 * k as f64, 0.0),
                DQuat::from_rotation_z(0.3 * k as f64),
            );
            let got = try_collide(&t, &Pose::IDENTITY, &t, &pb, &r).unwrap();
            assert_eq!(got, collide(&t, &Pose::IDENTITY, &t, &pb, &r));
            assert_eq!(got.pairs, oracle::pairs(&m, &Pose::IDENTITY, &m, &pb));
        }
    }
}
