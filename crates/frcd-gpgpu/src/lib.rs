//! frcd-gpgpu (work in progress).
