//! frcd-hybrid (work in progress).
