use glam::{DMat3, DQuat, DVec3};

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
    #[inline]
    pub fn new(translation: DVec3, rotation: DQuat) -> Self {
        Self {
            translation,
            rotation: rotation.normalize(),
        }
    }

    /// A pure translation.
    #[inline]
    pub fn from_translation(translation: DVec3) -> Self {
        Self {
            translation,
            rotation: DQuat::IDENTITY,
        }
    }

    /// Maps a point from the local frame to the parent frame.
    #[inline]
    pub fn transform_point(&self, p: DVec3) -> DVec3 {
        self.rotation * p + self.translation
    }

    /// Rotates a direction (no translation).
    #[inline]
    pub fn transform_vector(&self, v: DVec3) -> DVec3 {
        self.rotation * v
    }

    /// The inverse transform.
    #[inline]
    pub fn inverse(&self) -> Self {
        let r = self.rotation.conjugate();
        Self {
            translation: -(r * self.translation),
            rotation: r,
        }
    }

    /// `self ∘ other`: apply `other` first, then `self`.
    #[inline]
    pub fn compose(&self, other: &Pose) -> Self {
        Self {
            translation: self.rotation * other.translation + self.translation,
            rotation: (self.rotation * other.rotation).normalize(),
        }
    }

    /// The pose of `self` expressed in the frame of `frame`: `frame⁻¹ ∘ self`.
    ///
    /// Narrow-phase queries test body B in the frame of body A with
    /// `pose_b.relative_to(&pose_a)`, so world offsets of 1e6 cost no precision beyond this one
    /// subtraction.
    #[inline]
    pub fn relative_to(&self, frame: &Pose) -> Self {
        let inv = frame.rotation.conjugate();
        Self {
            translation: inv * (self.translation - frame.translation),
            rotation: (inv * self.rotation).normalize(),
        }
    }

    /// The rotation as a 3×3 matrix (columns are the local axes in the parent frame).
    #[inline]
    pub fn rotation_matrix(&self) -> DMat3 {
        DMat3::from_quat(self.rotation)
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
