//! Clearance: the distance of every body pair closer than a threshold.

use super::BodyId;
use crate::distance::{DistanceRequest, distance, within};
use crate::query::RelativeFrame;
use crate::tree::ObbTree;
use frcd_geom::{DVec3, Pose};
use frcd_tritri::Contact;

/// A body pair closer than its clearance threshold (or interfering), with where it is closest.
///
/// `Id` names the bodies: [`BodyId`] in a [`super::World`], the body index in `frcd-hybrid`,
/// `()` from [`pair_clearance`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clearance<Id = BodyId> {
    /// The body with the lower slot index.
    pub a: Id,
    /// The other body.
    pub b: Id,
    /// Smallest distance between the two surfaces; 0 when the bodies interfere (touching
    /// surfaces, or in solid mode one inside the other).
    pub distance: f64,
    /// Closest points in world coordinates (on A, on B). Interfering pairs: a point of the
    /// contact of `triangles` (twice); contained pairs: the closest surface points.
    pub points: [DVec3; 2],
    /// The triangle pair `(tri of a, tri of b)` the points lie on.
    pub triangles: (u32, u32),
    /// The bodies interfere (the `distance` is 0 by definition).
    pub interfering: bool,
}

impl<Id> Clearance<Id> {
    /// The same answer naming the bodies with other ids.
    pub fn with_ids<J>(self, a: J, b: J) -> Clearance<J> {
        Clearance {
            a,
            b,
            distance: self.distance,
            points: self.points,
            triangles: self.triangles,
            interfering: self.interfering,
        }
    }
}

/// The clearance of one body pair for a `threshold`, given what the collision query found:
/// `None` when the pair does not interfere and its surfaces are farther apart than the threshold
/// (decided exactly by [`within`], so no distance query is run for such a pair); otherwise the
/// distance (0 when `interfering`), closest points and triangle pair. `witness` is a touching
/// triangle pair of an interfering pair, when there is one (its contact point is reported
/// without a distance query).
pub fn pair_clearance(
    a: &ObbTree,
    pose_a: &Pose,
    b: &ObbTree,
    pose_b: &Pose,
    threshold: f64,
    witness: Option<(u32, u32)>,
    interfering: bool,
) -> Option<Clearance<()>> {
    if interfering {
        if let Some((x, y)) = witness {
            let frame = RelativeFrame::new(pose_a, pose_b);
            let ta = a.triangle(x);
            let tb = frame.triangle(&b.triangle(y));
            let p = match frcd_tritri::intersection_segment(&ta, &tb) {
                Some(Contact::Point(p)) => p,
                Some(Contact::Segment(p, q)) => 0.5 * (p + q),
                Some(Contact::Polygon(v)) if !v.is_empty() => v[0],
                // A non-exact method's witness: the closest points of the pair instead.
                _ => crate::oracle::closest_points_triangles(&ta, &tb).1,
            };
            let w = pose_a.transform_point(p);
            return Some(Clearance {
                a: (),
                b: (),
                distance: 0.0,
                points: [w, w],
                triangles: (x, y),
                interfering: true,
            });
        }
    } else if !within(a, pose_a, b, pose_b, threshold) {
        return None;
    }
    let d = distance(a, pose_a, b, pose_b, &DistanceRequest::default());
    Some(Clearance {
        a: (),
        b: (),
        distance: if interfering { 0.0 } else { d.distance },
        points: d.points,
        triangles: d.triangles,
        interfering,
    })
}
