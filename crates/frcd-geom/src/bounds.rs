use crate::Pose;
use glam::{DMat3, DVec3};

/// Absolute floor added to every rounding slack of the bounding volumes: 2^-1000, far above
/// the absolute error of subnormal arithmetic (a few 2^-1074) and negligible at any normal scale.
pub const ABSOLUTE_SLACK: f64 = 9.332636185032189e-302;

/// An axis-aligned box `[min, max]` (closed). An empty box has `min > max`.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Aabb {
    /// Lower corner.
    pub min: DVec3,
    /// Upper corner.
    pub max: DVec3,
}

/// The variance of the boxes' centres along x, y and z (about the first centre, so that boxes
/// far from the origin do not cancel), skipping boxes with a non-finite centre or `min > max`:
/// the axis of the largest is the one to sort a sweep-and-prune broad phase on. Zeros for
/// fewer than two such boxes.
///
/// ```
/// use frcd_geom::{Aabb, DVec3, centre_variance};
/// let row: Vec<Aabb> = (0..4)
///     .map(|i| Aabb::new(DVec3::new(0.0, i as f64, 0.0), DVec3::new(1.0, i as f64 + 1.0, 1.0)))
///     .collect();
/// let v = centre_variance(&row);
/// assert!(v[1] > 0.0 && v[0] == 0.0 && v[2] == 0.0);
/// ```
pub fn centre_variance<'a>(boxes: impl IntoIterator<Item = &'a Aabb>) -> [f64; 3] {
    let mut n = 0.0f64;
    let mut sum = [0.0f64; 3];
    let mut sq = [0.0f64; 3];
    let mut origin = None;
    for b in boxes {
        let c = (b.min + b.max) * 0.5;
        if !c.is_finite() || b.min.cmpgt(b.max).any() {
            continue;
        }
        let d = c - *origin.get_or_insert(c);
        n += 1.0;
        for (a, v) in d.to_array().into_iter().enumerate() {
            sum[a] += v;
            sq[a] += v * v;
        }
    }
    if n < 2.0 {
        return [0.0; 3];
    }
    std::array::from_fn(|a| (sq[a] / n - (sum[a] / n).powi(2)).max(0.0))
}

impl Aabb {
    /// The empty box (identity for [`Aabb::union`]).
    pub const EMPTY: Aabb = Aabb {
        min: DVec3::splat(f64::INFINITY),
        max: DVec3::splat(f64::NEG_INFINITY),
    };

    /// A box from two corners.
    #[inline]
    pub fn new(min: DVec3, max: DVec3) -> Self {
        Self { min, max }
    }

    /// The smallest box holding all points (empty for no points).
    pub fn from_points<'a>(points: impl IntoIterator<Item = &'a DVec3>) -> Self {
        points.into_iter().fold(Self::EMPTY, |b, p| b.grown(*p))
    }

    /// True when the box holds no point.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x || self.min.y > self.max.y || self.min.z > self.max.z
    }

    /// This box grown to hold `p`.
    #[inline]
    pub fn grown(&self, p: DVec3) -> Self {
        Self {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    /// The smallest box holding both.
    #[inline]
    pub fn union(&self, other: &Aabb) -> Self {
        Self {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    /// The intersection (possibly empty).
    #[inline]
    pub fn intersection(&self, other: &Aabb) -> Self {
        Self {
            min: self.min.max(other.min),
            max: self.max.min(other.max),
        }
    }

    /// True when the closed boxes share a point.
    #[inline]
    pub fn intersects(&self, other: &Aabb) -> bool {
        self.min.x <= other.max.x
            && other.min.x <= self.max.x
            && self.min.y <= other.max.y
            && other.min.y <= self.max.y
            && self.min.z <= other.max.z
            && other.min.z <= self.max.z
    }

    /// True when `p` lies in the closed box.
    #[inline]
    pub fn contains_point(&self, p: DVec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    /// The centre.
    #[inline]
    pub fn center(&self) -> DVec3 {
        0.5 * (self.min + self.max)
    }

    /// Half the side lengths.
    #[inline]
    pub fn half_extents(&self) -> DVec3 {
        0.5 * (self.max - self.min)
    }

    /// The box grown by `margin` on every side.
    #[inline]
    pub fn inflated(&self, margin: f64) -> Self {
        Self {
            min: self.min - DVec3::splat(margin),
            max: self.max + DVec3::splat(margin),
        }
    }

    /// A box holding this box after the pose is applied (the box of the rotated box), grown so
    /// that rounding cannot make it smaller than the exact one: the slack is a few ulp of every
    /// magnitude that was rounded on the way, including the local centre and the translation,
    /// which may be large even when they cancel (a body far from its frame's origin posed back
    /// near the world origin). The pose is taken as a rigid motion ([`Pose::rigid`]), as
    /// [`Pose::relative_to`] takes it.
    // Inlined across crates: returned through memory, the box's 24-byte corners were read
    // back as 16-byte pieces, which waited for the writes to reach the cache (perf: a
    // quarter of `World::set_poses`). `inline(always)`: with the hint alone it stayed out of
    // line in the World.
    #[inline(always)]
    pub fn transformed(&self, pose: &Pose) -> Self {
        if self.is_empty() {
            return *self;
        }
        // Made rigid once; the matrix below is then used as it is (the value
        // `rotation_matrix` gives for this rigid pose). The centre goes through the matrix
        // too, not the quaternion: another rounding of the same rotation, which the slack
        // covers (about 12 ulp of the local 1-norms against the 16 allowed).
        let pose = pose.rigid();
        let m = DMat3::from_quat(pose.rotation);
        let local_c = self.center();
        let c = m * local_c + pose.translation;
        let h = self.half_extents();
        let abs = DMat3::from_cols(m.x_axis.abs(), m.y_axis.abs(), m.z_axis.abs());
        let e = abs * h;
        // 1-norms: at least the Euclidean lengths, without two square roots on the World's
        // per-body path.
        let local = local_c.abs().element_sum() + h.element_sum();
        let slack =
            (c.abs() + e + pose.translation.abs() + DVec3::splat(local)) * (16.0 * f64::EPSILON);
        Self {
            min: c - e - slack,
            max: c + e + slack,
        }
    }

    /// Volume (0 for an empty box).
    #[inline]
    pub fn volume(&self) -> f64 {
        if self.is_empty() {
            0.0
        } else {
            (self.max - self.min).element_product()
        }
    }
}

/// A sphere (closed ball).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Sphere {
    /// Centre.
    pub center: DVec3,
    /// Radius (≥ 0).
    pub radius: f64,
}

impl Sphere {
    /// A sphere from centre and radius.
    #[inline]
    pub fn new(center: DVec3, radius: f64) -> Self {
        Self { center, radius }
    }

    /// A sphere holding all points: Ritter's bounding sphere, then grown by a relative 1e-12 so
    /// rounding never leaves a point outside. Returns a zero sphere at the origin for no points.
    pub fn from_points(points: &[DVec3]) -> Self {
        let Some(&p0) = points.first() else {
            return Self::new(DVec3::ZERO, 0.0);
        };
        let far = |from: DVec3| {
            let (mut best, mut best_d2) = (from, 0.0);
            for &p in points {
                let d2 = p.distance_squared(from);
                if d2 > best_d2 {
                    (best, best_d2) = (p, d2);
                }
            }
            best
        };
        let a = far(p0);
        let b = far(a);
        let mut center = 0.5 * (a + b);
        let mut radius = 0.5 * a.distance(b);
        for &p in points {
            // The square root only for the few points that grow the sphere (a point the
            // squared test rounds inside lies within an ulp of it: the final slack holds it).
            if p.distance_squared(center) <= radius * radius {
                continue;
            }
            let d = p.distance(center);
            if d > radius {
                let new_r = 0.5 * (radius + d);
                center += (p - center) * ((new_r - radius) / d);
                radius = new_r;
            }
        }
        let scale = center.abs().max_element().max(radius);
        Self::new(center, radius + scale * 1e-12)
    }

    /// True when the closed balls share a point.
    #[inline]
    pub fn intersects(&self, other: &Sphere) -> bool {
        let r = self.radius + other.radius;
        self.center.distance_squared(other.center) <= r * r
    }

    /// The sphere mapped by a rigid pose.
    #[inline]
    pub fn transformed(&self, pose: &Pose) -> Self {
        Self::new(pose.transform_point(self.center), self.radius)
    }
}

/// An oriented box: centre, orthonormal axes (the columns of `axes`) and half extents along them.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Obb {
    /// Centre.
    pub center: DVec3,
    /// Orthonormal axes as columns, right-handed.
    pub axes: DMat3,
    /// Half extents along `axes.x_axis`, `axes.y_axis`, `axes.z_axis` (≥ 0).
    pub half_extents: DVec3,
}

impl Obb {
    /// The tightest box with the given orthonormal axes that holds all points, grown by a relative
    /// few ulp so that rounding in the projections cannot leave a point outside.
    ///
    /// ```
    /// use frcd_geom::{Obb, DMat3, DVec3};
    /// let pts = [DVec3::ZERO, DVec3::new(2.0, 1.0, 0.5)];
    /// let obb = Obb::from_points_with_axes(&pts, DMat3::IDENTITY);
    /// assert!((obb.center - DVec3::new(1.0, 0.5, 0.25)).length() < 1e-12);
    /// assert!(obb.contains_point(pts[1]));
    /// ```
    pub fn from_points_with_axes(points: &[DVec3], axes: DMat3) -> Self {
        Self::from_point_iter_with_axes(points.iter().copied(), axes)
    }

    /// [`Obb::from_points_with_axes`] over any sequence of points, in one pass.
    pub fn from_point_iter_with_axes(points: impl Iterator<Item = DVec3>, axes: DMat3) -> Self {
        let t = axes.transpose();
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        let mut point_mag = 0.0f64;
        let mut any = false;
        for p in points {
            let q = t * p;
            lo = lo.min(q);
            hi = hi.max(q);
            point_mag = point_mag.max(p.abs().element_sum());
            any = true;
        }
        if !any {
            return Self {
                center: DVec3::ZERO,
                axes,
                half_extents: DVec3::ZERO,
            };
        }
        Self::from_projection_bounds(axes, lo, hi, point_mag)
    }

    /// The box [`Obb::from_points_with_axes`] gives, from a pass the caller made itself (a tree
    /// build fuses it with other work): `lo` and `hi` the componentwise min and max of
    /// `axes.transpose() * p` over the points `p` (at least one), `point_mag` the max of
    /// `p.abs().element_sum()`. The rounding slack is added here.
    ///
    /// ```
    /// use frcd_geom::{Obb, DMat3, DVec3};
    /// let pts = [DVec3::ZERO, DVec3::new(2.0, 1.0, 0.5)];
    /// let t = DMat3::IDENTITY.transpose();
    /// let (lo, hi) = (t * pts[0], t * pts[1]);
    /// let mag = pts.iter().map(|p| p.abs().element_sum()).fold(0.0, f64::max);
    /// let obb = Obb::from_projection_bounds(DMat3::IDENTITY, lo, hi, mag);
    /// assert_eq!(obb, Obb::from_points_with_axes(&pts, DMat3::IDENTITY));
    /// ```
    pub fn from_projection_bounds(axes: DMat3, lo: DVec3, hi: DVec3, point_mag: f64) -> Self {
        let mid = 0.5 * (lo + hi);
        let half = 0.5 * (hi - lo);
        // Rounding of the projections (each ≤ 3 ulp of |p|₁ for unit axes), of the centre
        // reconstruction and of the containment test's own projection: a few ulp of the largest
        // point magnitude, generously.
        let mag = point_mag.max(lo.abs().max(hi.abs()).max_element());
        // Relative rounding does not cover subnormal arithmetic, whose error is absolute
        // (2^-1074 per operation): the floor covers it with room to spare and is invisible at
        // any normal magnitude.
        let slack = mag * (32.0 * f64::EPSILON) + ABSOLUTE_SLACK;
        Self {
            center: axes * mid,
            axes,
            half_extents: half + DVec3::splat(slack),
        }
    }

    /// The axis-aligned box of this OBB, grown by a few ulp so rounding cannot make it smaller
    /// than the exact one.
    pub fn aabb(&self) -> Aabb {
        let abs = DMat3::from_cols(
            self.axes.x_axis.abs(),
            self.axes.y_axis.abs(),
            self.axes.z_axis.abs(),
        );
        let e = abs * self.half_extents;
        let slack = (self.center.abs() + e) * (8.0 * f64::EPSILON) + DVec3::splat(ABSOLUTE_SLACK);
        Aabb::new(self.center - e - slack, self.center + e + slack)
    }

    /// True when `p` lies in the closed box (rounded arithmetic).
    pub fn contains_point(&self, p: DVec3) -> bool {
        let d = self.axes.transpose() * (p - self.center);
        d.abs().cmple(self.half_extents).all()
    }

    /// The eight corners.
    pub fn corners(&self) -> [DVec3; 8] {
        let mut out = [DVec3::ZERO; 8];
        for (i, c) in out.iter_mut().enumerate() {
            let s = DVec3::new(
                if i & 1 == 0 { -1.0 } else { 1.0 },
                if i & 2 == 0 { -1.0 } else { 1.0 },
                if i & 4 == 0 { -1.0 } else { 1.0 },
            );
            *c = self.center + self.axes * (s * self.half_extents);
        }
        out
    }

    /// Volume.
    #[inline]
    pub fn volume(&self) -> f64 {
        8.0 * self.half_extents.element_product()
    }

    /// The OBB mapped by a rigid pose.
    pub fn transformed(&self, pose: &Pose) -> Self {
        Self {
            center: pose.transform_point(self.center),
            axes: pose.rotation_matrix() * self.axes,
            half_extents: self.half_extents,
        }
    }
}
