//! # frcd-obb
//!
//! FRCD: OBB trees on the CPU with exact triangle tests.
#![warn(missing_docs)]

mod tree;

pub use tree::{Node, ObbTree};
