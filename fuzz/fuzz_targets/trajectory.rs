//! Trajectory CSV parser: any bytes give rows or a typed error naming a line; every row's pose
//! is valid and its line lies in the file.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = std::path::Path::new("fuzz.csv");
    if let Ok(t) = frcd_io::Trajectory::parse(data, path) {
        let lines = 1 + data.iter().filter(|&&b| b == b'\n').count();
        for r in &t.rows {
            assert!(
                r.pose.is_valid(),
                "row at line {} has an invalid pose",
                r.line
            );
            assert!(r.line >= 1 && r.line <= lines, "line {} of {lines}", r.line);
            assert!(!r.body.is_empty());
        }
    }
});
