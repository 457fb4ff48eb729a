use crate::{Aabb, Pose};
use glam::DVec3;

/// A triangle as a closed point set in 3D (f64).
///
/// A zero-area triangle is still meaningful: it is the segment or point its vertices span, and the
/// exact tests in `frcd-tritri` treat it as such.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Triangle {
    /// The three vertices, in order (counter-clockwise seen from the outside for mesh faces).
    pub v: [DVec3; 3],
}

impl Triangle {
    /// A triangle from its three vertices.
    ///
    /// ```
    /// use frcd_geom::{Triangle, DVec3};
    /// let t = Triangle::new(DVec3::ZERO, DVec3::X, DVec3::Y);
    /// assert_eq!(t.area(), 0.5);
    /// ```
    #[inline]
    pub const fn new(a: DVec3, b: DVec3, c: DVec3) -> Self {
        Self { v: [a, b, c] }
    }

    /// The unnormalised normal `(b - a) × (c - a)`; its length is twice the area.
    #[inline]
    pub fn normal(&self) -> DVec3 {
        (self.v[1] - self.v[0]).cross(self.v[2] - self.v[0])
    }

    /// The area (rounded f64; use `frcd-tritri`'s exact predicates to decide degeneracy).
    #[inline]
    pub fn area(&self) -> f64 {
        0.5 * self.normal().length()
    }

    /// The centroid.
    #[inline]
    pub fn centroid(&self) -> DVec3 {
        (self.v[0] + self.v[1] + self.v[2]) / 3.0
    }

    /// The smallest axis-aligned box holding the triangle.
    #[inline]
    pub fn aabb(&self) -> Aabb {
        Aabb {
            min: self.v[0].min(self.v[1]).min(self.v[2]),
            max: self.v[0].max(self.v[1]).max(self.v[2]),
        }
    }

    /// The triangle mapped by a pose.
    #[inline]
    pub fn transformed(&self, pose: &Pose) -> Self {
        Self::new(
            pose.transform_point(self.v[0]),
            pose.transform_point(self.v[1]),
            pose.transform_point(self.v[2]),
        )
    }

    /// True when every coordinate is finite.
    #[inline]
    pub fn is_finite(&self) -> bool {
        self.v.iter().all(|p| p.is_finite())
    }
}
