//! The `World`'s broad phase (sweep and grid) against all pairs of boxes, through edits, on
//! scenes of a few to 1,355 bodies that the input lays out.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| frcd_fuzz::world_broad(data));
