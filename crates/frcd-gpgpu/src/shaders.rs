//! The WGSL sources (from the crate's `shaders/`), compiled into the crate.

/// One level of the pair-tree traversal: OBB separating-axis test and triangle test.
pub const TRAVERSE: &str = include_str!("../shaders/traverse.wgsl");
/// All-pairs box overlap of many bodies.
pub const BOXES: &str = include_str!("../shaders/boxes.wgsl");

/// Sort-based sweep and prune over many bodies' boxes (bitonic sort, gather, sweep).
pub const SWEEP: &str = include_str!("../shaders/sweep.wgsl");

/// Every shader of the crate as `(file name, source)`.
pub const ALL: [(&str, &str); 3] = [
    ("traverse.wgsl", TRAVERSE),
    ("boxes.wgsl", BOXES),
    ("sweep.wgsl", SWEEP),
];
