use frcd_geom::Topology;

/// Which of the two meshes of a query an error is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Which {
    /// The first mesh (`a`), whose frame the query works in.
    A,
    /// The second mesh (`b`).
    B,
}

/// Everything the image-space detector can refuse or fail at. Each variant names what and where.
#[derive(Clone, Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ImageError {
    /// No GPU adapter (not even a software one such as Mesa's lavapipe) could be found.
    #[error("no GPU adapter available: {0}")]
    NoAdapter(String),
    /// The adapter was found but refused to create a device.
    #[error("GPU device request failed on adapter '{adapter}': {reason}")]
    DeviceRequest {
        /// Adapter name.
        adapter: String,
        /// The driver's reason.
        reason: String,
    },
    /// The device lacks a feature the detector needs.
    #[error("GPU device lacks required features {missing:?}")]
    MissingFeatures {
        /// The missing features.
        missing: wgpu::Features,
    },
    /// A device limit is below what the detector needs.
    #[error("GPU limit {name} is {have}, the detector needs at least {need}")]
    LimitTooLow {
        /// Name of the limit (as in `wgpu::Limits`).
        name: &'static str,
        /// The device's value.
        have: u64,
        /// The needed value.
        need: u64,
    },
    /// The device runs on a wgpu backend the detector cannot run on correctly. wgpu's GL
    /// backend translates WGSL to GLSL, which cannot `textureLoad` a depth texture or read the
    /// stencil aspect as an integer texture (the depth peeling and the parity resolve need
    /// both): refused here, at context creation, rather than failing or answering wrongly later.
    #[error(
        "adapter '{adapter}' uses the {backend:?} backend, which the image detector cannot use: {reason}"
    )]
    UnsupportedBackend {
        /// Adapter name.
        adapter: String,
        /// The backend.
        backend: wgpu::Backend,
        /// Why.
        reason: &'static str,
    },
    /// A mesh is not a closed, consistently oriented 2-manifold; ray parity needs one.
    #[error(
        "mesh '{name}' is not a closed oriented manifold (ray parity needs a solid): {topology:?}"
    )]
    NotSolid {
        /// Caller's label of the mesh (see [`crate::ImageDetector::upload`]).
        name: String,
        /// The topology report of the mesh.
        topology: Box<Topology>,
    },
    /// A mesh has more vertices or indices than one GPU buffer may hold on this device.
    #[error("mesh '{name}' needs a {bytes}-byte buffer, the device allows {max}")]
    MeshTooLarge {
        /// Caller's label of the mesh.
        name: String,
        /// Bytes needed.
        bytes: u64,
        /// `max_buffer_size` of the device.
        max: u64,
    },
    /// A mesh handle was created by another detector (another device).
    #[error("mesh {which:?} was uploaded by a different ImageDetector (device)")]
    ForeignMesh {
        /// Which argument.
        which: Which,
    },
    /// A pose has a non-finite translation or a non-unit rotation.
    #[error("pose of mesh {which:?} is invalid (non-finite or non-unit rotation)")]
    InvalidPose {
        /// Which argument.
        which: Which,
    },
    /// The requested resolution is zero or exceeds what the device can render or store.
    #[error("resolution {requested} px is invalid here: {reason}")]
    Resolution {
        /// The requested resolution (pixels across the overlap).
        requested: u32,
        /// Why it cannot be used.
        reason: String,
    },
    /// More surface layers than `ImageOptions::max_layers` lie in the overlap region.
    #[error("more than {max_layers} depth layers of mesh {which:?} in the overlap region")]
    TooManyLayers {
        /// Mesh whose layers were being peeled.
        which: Which,
        /// The limit that was hit.
        max_layers: u32,
    },
    /// The GPU reported an error (validation, out of memory, lost device, failed readback).
    #[error("GPU error during {stage}: {message}")]
    Gpu {
        /// What was being done.
        stage: &'static str,
        /// The driver's message.
        message: String,
    },
}
