//! Scene file parser: any text gives a SceneFile or a typed error naming a line; a parsed scene
//! writes back to JSON that parses to the same value.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| frcd_fuzz::scene(data));
