//! Trajectory CSV parser: any bytes give rows or a typed error naming a line; every row's pose
//! is valid and its line lies in the file.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| frcd_fuzz::trajectory(data));
