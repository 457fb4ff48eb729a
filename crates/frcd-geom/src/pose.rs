use glam::{DMat3, DQuat, DVec3};

/// Why a pose was refused by [`Pose::try_new`] or [`Pose::validate`].
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum PoseError {
    /// A translation component is NaN or infinite.
    #[error("translation {0:?} is not finite")]
    NonFiniteTranslation([f64; 3]),
    /// A quaternion component is NaN or infinite.
    #[error("rotation quaternion {0:?} (x, y, z, w) is not finite")]
    NonFiniteRotation([f64; 4]),
    /// The quaternion has zero length (or so small a length that it cannot be normalised):
    /// it names no rotation.
    #[error("rotation quaternion {0:?} (x, y, z, w) has zero length: it names no rotation")]
    ZeroRotation([f64; 4]),
    /// The quaternion of a constructed pose is not of unit length (see [`Pose::validate`]).
    #[error("rotation quaternion {quaternion:?} (x, y, z, w) has length {length}, not 1")]
    NotUnitRotation {
        /// The quaternion.
        quaternion: [f64; 4],
        /// Its length.
        length: f64,
    },
}

/// A rigid transform: rotate by `rotation` (a unit quaternion), then translate by `translation`.
///
/// `p_world = rotation * p_local + translation`.
///
/// ```
/// use frcd_geom::{Pose, DVec3, DQuat};
/// let a = Pose::new(DVec3::new(1.0, 2.0, 3.0), DQuat::from_rotation_z(0.5));
/// let b = Pose::new(DVec3::new(-4.0, 0.0, 1.0), DQuat::from_rotation_x(1.0));
/// // The pose of b seen from a's frame maps b-local points to a-local points.
/// let rel = b.relative_to(&a);
/// let p = DVec3::new(0.3, -0.2, 0.7);
/// let direct = a.inverse().transform_point(b.transform_point(p));
/// assert!((rel.transform_point(p) - direct).length() < 1e-12);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Pose {
    /// Translation applied after the rotation.
    pub translation: DVec3,
    /// Unit quaternion.
    pub rotation: DQuat,
}

impl Default for Pose {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Pose {
    /// The identity pose.
    pub const IDENTITY: Pose = Pose {
        translation: DVec3::ZERO,
        rotation: DQuat::IDENTITY,
    };

    /// A pose from a translation and a rotation; the quaternion is normalised.
    ///
    /// Takes the inputs on trust: a NaN or infinite component, or a zero quaternion, gives a
    /// pose whose rotation is NaN, and queries with it answer nothing meaningful. Use
    /// [`Pose::try_new`] for input you did not compute yourself, or check a pose with
    /// [`Pose::validate`]; `frcd_obb::try_collide` does that for every query.
    #[inline]
    pub fn new(translation: DVec3, rotation: DQuat) -> Self {
        Self {
            translation,
            rotation: rotation.normalize(),
        }
    }

    /// A pose from a translation and a rotation, checked: every component finite and the
    /// quaternion of non-zero length (it is normalised, so any non-zero length is accepted).
    ///
    /// ```
    /// use frcd_geom::{Pose, PoseError, DVec3, DQuat};
    /// assert!(Pose::try_new(DVec3::X, DQuat::from_xyzw(0.0, 0.0, 0.0, 2.0)).is_ok());
    /// assert!(matches!(
    ///     Pose::try_new(DVec3::new(f64::NAN, 0.0, 0.0), DQuat::IDENTITY),
    ///     Err(PoseError::NonFiniteTranslation(_))
    /// ));
    /// assert!(matches!(
    ///     Pose::try_new(DVec3::ZERO, DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0)),
    ///     Err(PoseError::ZeroRotation(_))
    /// ));
    /// ```
    pub fn try_new(translation: DVec3, rotation: DQuat) -> Result<Self, PoseError> {
        if !translation.is_finite() {
            return Err(PoseError::NonFiniteTranslation(translation.to_array()));
        }
        let q = rotation.to_array();
        if !rotation.is_finite() {
            return Err(PoseError::NonFiniteRotation(q));
        }
        // Scale by the largest component first, so tiny and huge (finite) quaternions
        // normalise without underflow or overflow.
        let m = q.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        if m == 0.0 {
            return Err(PoseError::ZeroRotation(q));
        }
        let scaled = DQuat::from_array(q.map(|x| x / m));
        if !scaled.is_finite() || scaled.length_squared() == 0.0 {
            return Err(PoseError::ZeroRotation(q));
        }
        Ok(Self {
            translation,
            rotation: scaled.normalize(),
        })
    }

    /// Checks a pose as queries need it: finite translation, finite unit quaternion (length
    /// within 1e-6 of 1, looser than [`Pose::is_valid`] so poses composed in f64 pass).
    ///
    /// ```
    /// use frcd_geom::{Pose, DVec3, DQuat};
    /// assert!(Pose::new(DVec3::X, DQuat::from_rotation_z(1.0)).validate().is_ok());
    /// // A zero quaternion normalises to NaN: the pose is refused, not silently used.
    /// assert!(Pose::new(DVec3::X, DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0)).validate().is_err());
    /// ```
    pub fn validate(&self) -> Result<(), PoseError> {
        if !self.translation.is_finite() {
            return Err(PoseError::NonFiniteTranslation(self.translation.to_array()));
        }
        let q = self.rotation.to_array();
        if !self.rotation.is_finite() {
            return Err(PoseError::NonFiniteRotation(q));
        }
        let length = self.rotation.length();
        if length == 0.0 {
            return Err(PoseError::ZeroRotation(q));
        }
        if (length - 1.0).abs() > 1e-6 {
            return Err(PoseError::NotUnitRotation {
                quaternion: q,
                length,
            });
        }
        Ok(())
    }

    /// A pure translation.
    #[inline]
    pub fn from_translation(translation: DVec3) -> Self {
        Self {
            translation,
            rotation: DQuat::IDENTITY,
        }
    }

    /// Maps a point from the local frame to the parent frame (as a rigid motion,
    /// [`Pose::rigid`]).
    #[inline]
    pub fn transform_point(&self, p: DVec3) -> DVec3 {
        let r = self.rigid();
        r.rotation * p + r.translation
    }

    /// Rotates a direction (no translation; as a rigid motion, [`Pose::rigid`]).
    #[inline]
    pub fn transform_vector(&self, v: DVec3) -> DVec3 {
        self.rigid().rotation * v
    }

    /// The inverse transform (of the rigid motion, [`Pose::rigid`]).
    #[inline]
    pub fn inverse(&self) -> Self {
        let r = self.rigid().rotation.conjugate();
        Self {
            translation: -(r * self.translation),
            rotation: r,
        }
    }

    /// `self ∘ other`: apply `other` first, then `self` (both as rigid motions,
    /// [`Pose::rigid`]).
    #[inline]
    pub fn compose(&self, other: &Pose) -> Self {
        let (a, b) = (self.rigid(), other.rigid());
        Self {
            translation: a.rotation * b.translation + a.translation,
            rotation: (a.rotation * b.rotation).normalize(),
        }
    }

    /// This pose as a rigid motion: the same pose, bit for bit, when its quaternion has unit
    /// length to rounding (`|q|²` within 8 ε of 1, as [`Pose::new`] leaves it), else with the
    /// quaternion normalised.
    ///
    /// A quaternion a little off unit length (what [`Pose::is_valid`] and [`Pose::validate`]
    /// accept) does not turn points rigidly: `q * v` scales them by `|q|²`, and the matrix of
    /// `q` distorts them another way. Every map of a pose ([`Pose::transform_point`],
    /// [`Pose::transform_vector`], [`Pose::rotation_matrix`], [`Pose::inverse`],
    /// [`Pose::compose`], [`Pose::relative_to`], [`crate::Aabb::transformed`]) takes it
    /// through this first, so such a pose means the same rigid motion to the narrow phase
    /// (which tests B in A's frame), to the world boxes of a broad phase and to the points
    /// reported in world coordinates.
    ///
    /// ```
    /// use frcd_geom::{Pose, DVec3, DQuat};
    /// let off = Pose {
    ///     translation: DVec3::X,
    ///     rotation: DQuat::from_xyzw(0.0, 0.0, 0.0, 1.0 + 4e-10),
    /// };
    /// assert!(off.is_valid());
    /// assert_eq!(off.rigid().rotation, DQuat::IDENTITY);
    /// let unit = Pose::new(DVec3::X, DQuat::from_rotation_z(0.3));
    /// assert_eq!(unit.rigid(), unit);
    /// ```
    #[inline]
    pub fn rigid(&self) -> Self {
        let n = self.rotation.length_squared();
        if (n - 1.0).abs() <= 8.0 * f64::EPSILON {
            *self
        } else {
            // What glam's `normalize` computes, without its optional finiteness assertion (an
            // engine that turns on glam's `glam-assert` would otherwise see a zero or NaN
            // quaternion panic here instead of giving the NaN pose `Pose::new` documents).
            Self {
                translation: self.translation,
                rotation: self.rotation * (1.0 / n.sqrt()),
            }
        }
    }

    /// The pose of `self` expressed in the frame of `frame`: `frame⁻¹ ∘ self`, both taken as
    /// rigid motions ([`Pose::rigid`]).
    ///
    /// Narrow-phase queries test body B in the frame of body A with
    /// `pose_b.relative_to(&pose_a)`, so world offsets of 1e6 cost no precision beyond this one
    /// subtraction.
    #[inline]
    pub fn relative_to(&self, frame: &Pose) -> Self {
        let (this, frame) = (self.rigid(), frame.rigid());
        let inv = frame.rotation.conjugate();
        Self {
            translation: inv * (this.translation - frame.translation),
            rotation: (inv * this.rotation).normalize(),
        }
    }

    /// The rotation as a 3×3 matrix (columns are the local axes in the parent frame).
    #[inline]
    pub fn rotation_matrix(&self) -> DMat3 {
        DMat3::from_quat(self.rigid().rotation)
    }

    /// True when translation and rotation are finite and the rotation is a unit quaternion
    /// (within 1e-9).
    pub fn is_valid(&self) -> bool {
        self.translation.is_finite()
            && self.rotation.is_finite()
            && (self.rotation.length_squared() - 1.0).abs() < 1e-9
    }
}

impl core::ops::Mul for Pose {
    type Output = Pose;
    /// Same as [`Pose::compose`].
    fn mul(self, rhs: Pose) -> Pose {
        self.compose(&rhs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pose whose quaternion is off unit length within what `is_valid` accepts maps points
    /// rigidly through every helper, the same as its normalised pose; a unit pose is untouched.
    #[test]
    fn nearly_unit_quaternions_map_rigidly_everywhere() {
        let unit = DQuat::from_axis_angle(DVec3::new(0.3, -0.5, 0.8).normalize(), 1.1);
        let off = Pose {
            translation: DVec3::new(1e3, -2e3, 5e2),
            rotation: unit * (1.0 + 4e-10),
        };
        assert!(off.is_valid() && off.rigid() != off);
        let rigid = Pose {
            translation: off.translation,
            rotation: off.rotation.normalize(),
        };
        assert_eq!(off.rigid(), rigid);
        let v = DVec3::new(1e3, 2.5e2, -7e2);
        // `q * v` of the raw quaternion would be longer by about 4e-10 * |v| = 5e-7.
        let moved = off.transform_point(v) - off.translation;
        assert!(
            (moved.length() - v.length()).abs() < 1e-12,
            "{}",
            moved.length() - v.length()
        );
        assert_eq!(off.transform_point(v), rigid.transform_point(v));
        assert_eq!(off.transform_vector(v), rigid.transform_vector(v));
        assert_eq!(off.rotation_matrix(), rigid.rotation_matrix());
        assert_eq!(off.inverse(), rigid.inverse());
        assert_eq!(off.compose(&off), rigid.compose(&rigid));
        assert_eq!(off.relative_to(&off), rigid.relative_to(&rigid));
        // The round trip through the inverse comes back to the point.
        let back = off.inverse().transform_point(off.transform_point(v));
        assert!((back - v).length() < 1e-9, "{}", (back - v).length());
        // Unit quaternions are left bit for bit as they are.
        let p = Pose::new(DVec3::X, unit);
        assert_eq!(p.rigid(), p);
    }

    #[test]
    fn try_new_refuses_non_finite_and_zero_input() {
        let nan = f64::NAN;
        let inf = f64::INFINITY;
        for t in [
            DVec3::new(nan, 0.0, 0.0),
            DVec3::new(0.0, inf, 0.0),
            DVec3::new(0.0, 0.0, -inf),
        ] {
            assert!(matches!(
                Pose::try_new(t, DQuat::IDENTITY),
                Err(PoseError::NonFiniteTranslation(_))
            ));
            assert!(Pose::new(t, DQuat::IDENTITY).validate().is_err());
        }
        for q in [
            DQuat::from_xyzw(nan, 0.0, 0.0, 1.0),
            DQuat::from_xyzw(0.0, 0.0, inf, 1.0),
        ] {
            assert!(matches!(
                Pose::try_new(DVec3::ZERO, q),
                Err(PoseError::NonFiniteRotation(_))
            ));
        }
        let zero = DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0);
        assert!(matches!(
            Pose::try_new(DVec3::ZERO, zero),
            Err(PoseError::ZeroRotation(_))
        ));
        assert!(Pose::new(DVec3::ZERO, zero).validate().is_err());
        // Not unit, but normalisable at any finite scale.
        for s in [1e-300, 5e-324, 1e300, f64::MAX] {
            let p = Pose::try_new(DVec3::ZERO, DQuat::from_xyzw(0.0, 0.0, s, s)).unwrap();
            assert!(p.validate().is_ok(), "scale {s:e}");
            assert!((p.rotation.z - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-15);
        }
        let raw = Pose {
            translation: DVec3::ZERO,
            rotation: DQuat::from_xyzw(0.0, 0.0, 0.0, 2.0),
        };
        assert!(matches!(
            raw.validate(),
            Err(PoseError::NotUnitRotation { length, .. }) if length == 2.0
        ));
    }
}
