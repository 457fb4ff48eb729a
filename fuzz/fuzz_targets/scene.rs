//! Scene file parser: any text gives a SceneFile or a typed error naming a line; a parsed scene
//! writes back to JSON that parses to the same value.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let path = std::path::Path::new("fuzz.json");
    if let Ok(spec) = frcd_io::SceneFile::parse(text, path) {
        let again = serde_json::to_string(&spec).expect("a parsed scene serialises");
        let back = frcd_io::SceneFile::parse(&again, path).expect("written scene parses");
        assert_eq!(
            serde_json::to_value(&back).unwrap(),
            serde_json::to_value(&spec).unwrap()
        );
    }
});
