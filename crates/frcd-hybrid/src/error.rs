//! Errors.

use frcd_geom::Pose;

/// The typed cause of a GPU failure.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum GpuFailure {
    /// The GPGPU backend (box pass, pair traversal) failed.
    #[cfg(feature = "gpgpu")]
    #[error(transparent)]
    Gpgpu(#[from] frcd_gpgpu::GpuError),
    /// The image-space backend failed.
    #[cfg(feature = "image")]
    #[error(transparent)]
    Image(#[from] frcd_image::ImageError),
    /// GPU use is off ([`crate::GpuPolicy::Off`]) or the GPU feature is not compiled in.
    #[error("{0}")]
    Unavailable(String),
}

/// Why a [`crate::Checker`] was refused or a frame failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum HybridError {
    /// An exclusion names a body index out of range.
    #[error("excluded pair ({a}, {b}) names a body out of range (the scene has {count})")]
    BadExclusion {
        /// First index.
        a: usize,
        /// Second index.
        b: usize,
        /// Body count.
        count: usize,
    },
    /// A clearance threshold is negative or NaN, or a per-pair threshold names a body out of
    /// range or a body with itself.
    #[error(
        "clearance threshold {value} for pair ({a}, {b}) is invalid (the scene has {count} bodies; thresholds are numbers >= 0)"
    )]
    BadClearance {
        /// First index (`usize::MAX` for the scene's threshold).
        a: usize,
        /// Second index (`usize::MAX` for the scene's threshold).
        b: usize,
        /// The threshold.
        value: f64,
        /// Body count.
        count: usize,
    },
    /// `check` got a pose slice of the wrong length.
    #[error("{got} poses given for {expected} bodies")]
    PoseCount {
        /// Bodies.
        expected: usize,
        /// Poses given.
        got: usize,
    },
    /// A pose is not finite or its rotation is not a unit quaternion.
    #[error("pose of body '{body}' is not finite or not a unit rotation: {pose:?}")]
    InvalidPose {
        /// The body.
        body: String,
        /// The pose.
        pose: Pose,
    },
    /// A [`crate::FrameState`] used with another checker was passed to this one.
    #[error("this FrameState belongs to another Checker: use one state per checker (or reset it)")]
    ForeignState,
    /// The broad phase refused an update (a bug: the checker validates first).
    #[error("broad phase: {0}")]
    World(#[from] frcd_obb::WorldError),
    /// The requested backend needs a cargo feature this build lacks.
    #[error("backend '{backend}' needs frcd-hybrid's cargo feature '{feature}'")]
    FeatureDisabled {
        /// The backend.
        backend: &'static str,
        /// The missing feature.
        feature: &'static str,
    },
    /// The image backend answers within a resolution bound only.
    #[error("the image backend is resolution-bounded: use mode 'fast' (exact mode never runs it)")]
    ImageNeedsFast,
    /// A GPU was required (by [`crate::GpuPolicy::Require`]) and failed; with
    /// [`crate::GpuPolicy::Auto`] a GPU failure falls back to the CPU instead.
    #[error("GPU ({stage}): {source}")]
    Gpu {
        /// Which GPU backend or stage.
        stage: &'static str,
        /// The typed cause.
        #[source]
        source: GpuFailure,
    },
}
