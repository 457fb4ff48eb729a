//! OBJ reader (one mesh and per-object): any bytes give meshes or a typed error.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| frcd_fuzz::obj(data));
