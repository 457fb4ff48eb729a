//! frcd-io (work in progress).
