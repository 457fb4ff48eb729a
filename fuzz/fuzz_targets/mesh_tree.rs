//! `TriMesh::new` on raw vertices and indices (NaN, infinities, huge and subnormal coordinates,
//! out-of-range indices), then `ObbTree::build` on every mesh it accepts; the tree's
//! self-collision must equal the exact oracle's pairs.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| frcd_fuzz::mesh_tree(data));
