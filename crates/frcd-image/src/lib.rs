//! frcd-image (work in progress).
