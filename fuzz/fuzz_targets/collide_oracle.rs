//! Differential: `collide` (all pairs, solid or surface mode) against `frcd_obb::oracle` on
//! small meshes and poses. Coordinates are small integers scaled by a power of two (so touching,
//! coplanar and degenerate configurations are common), sometimes closed boxes (containment).
//! The two answers must be equal.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| frcd_fuzz::collide_oracle(data));
