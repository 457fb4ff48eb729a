/// Everything that can go wrong in frcd-gpgpu. Nothing here panics on bad input.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum GpuError {
    /// No adapter (GPU or software driver) could be found.
    #[error("no GPU adapter found: {0}")]
    NoAdapter(String),
    /// The adapter refused to create a device.
    #[error("could not create a device on adapter '{adapter}': {reason}")]
    RequestDevice {
        /// Adapter name.
        adapter: String,
        /// The driver's reason.
        reason: String,
    },
    /// The device lacks a limit or capability the pipeline needs.
    #[error("device '{adapter}' does not meet requirement {what}: needs {needed}, has {available}")]
    Unsupported {
        /// Adapter name.
        adapter: String,
        /// The limit or capability.
        what: &'static str,
        /// What frcd-gpgpu needs.
        needed: u64,
        /// What the device offers.
        available: u64,
    },
    /// The device rejected a shader or pipeline of the crate.
    #[error("device '{adapter}' rejected a frcd-gpgpu pipeline: {reason}")]
    Pipeline {
        /// Adapter name.
        adapter: String,
        /// The validation error.
        reason: String,
    },
    /// A mesh does not fit the device's textures, or indices would not be exact in f32.
    #[error("mesh too large for the GPU: {what}: {needed} > {limit}")]
    MeshTooLarge {
        /// What overflowed.
        what: &'static str,
        /// The amount needed.
        needed: u64,
        /// The limit.
        limit: u64,
    },
    /// An output or frontier buffer would exceed the device's buffer limits.
    #[error("GPU buffer '{what}' would need {needed} bytes, device allows {limit}")]
    CapacityExceeded {
        /// Which buffer.
        what: &'static str,
        /// Bytes needed.
        needed: u64,
        /// Bytes allowed.
        limit: u64,
    },
    /// A node of the tree has axes too far from orthonormal to bound its f32 rounding.
    #[error("OBB node {node}: axes are not orthonormal (deviation {deviation:e})")]
    BadNodeAxes {
        /// Node index.
        node: usize,
        /// max |AᵀA - I|.
        deviation: f64,
    },
    /// A coordinate, extent or translation too large for the f32 error bounds: above
    /// [`crate::MAX_MAGNITUDE`] the shaders' products could overflow, and WGSL allows an
    /// implementation to assume finite math. Re-centre the mesh (upload it relative to a
    /// local origin near its geometry).
    #[error("{what} has magnitude {value:e}, above the GPU limit {limit:e}")]
    MagnitudeOutOfRange {
        /// What (node, triangle or pose) was too large.
        what: String,
        /// Its magnitude.
        value: f64,
        /// [`crate::MAX_MAGNITUDE`].
        limit: f64,
    },
    /// A pose or box with NaN/inf, or a non-unit rotation.
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// A mesh or scratch object made with another context was passed in.
    #[error("{0} belongs to another GpuContext")]
    ForeignObject(&'static str),
    /// Reading results back failed (device lost, mapping error).
    #[error("GPU readback failed")]
    Readback(#[source] frcd_gpu::SetupError),
    /// The GPU reported a state that the traversal cannot produce (a bug, or a broken driver).
    #[error("GPU traversal inconsistency: {0}")]
    Internal(String),
}
