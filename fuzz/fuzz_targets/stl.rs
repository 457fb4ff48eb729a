//! STL reader (ASCII and binary): any bytes give a mesh or a typed error, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| frcd_fuzz::stl(data));
