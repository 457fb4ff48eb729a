//! The built `frcd` binary: reports, and clear errors (never a panic) on bad input.

mod common;
use common::*;
use frcd_geom::{DVec3, shapes};
use std::path::{Path, PathBuf};

/// Two cubes; `b` moves through `a` along x: frames 0 and 4 apart, 1..=3 interfering
/// (frame 2 deep), plus a small ball that sits inside `a` in frame 2 only.
fn cube_scene(dir: &Path) -> PathBuf {
    frcd_io::write_obj(
        dir.join("cube.obj"),
        &shapes::cuboid(DVec3::splat(0.5)),
        "cube",
    )
    .unwrap();
    frcd_io::write_stl_binary(dir.join("ball.stl"), &shapes::icosphere(0.1, 1)).unwrap();
    let xs = [-2.0, -0.9, 0.2, 0.95, 2.0];
    let frames: Vec<String> = xs
        .iter()
        .enumerate()
        .map(|(i, x)| {
            let ball = if i == 2 { 0.0 } else { 5.0 };
            format!(
                r#"{{"b": {{"t": [{x}, 0.1, 0.05], "q": [0, 0, 0, 1]}}, "ball": {{"t": [0, {ball}, 0], "q": [0, 0, 0, 1]}}}}"#
            )
        })
        .collect();
    let scene = format!(
        r#"{{"bodies": [
  {{"name": "a", "mesh": "cube.obj", "static": true, "pose": {{"t": [0, 0, 0], "q": [0, 0, 0, 1]}}}},
  {{"name": "b", "mesh": "cube.obj", "static": false, "pose": {{"t": [-2, 0, 0], "q": [0, 0, 0, 1]}}}},
  {{"name": "ball", "mesh": "ball.stl", "static": false, "pose": {{"t": [0, 5, 0], "q": [0, 0, 0, 1]}}}}
 ],
 "exclude": [["b", "ball"]],
 "frames": [{}]}}"#,
        frames.join(",\n  ")
    );
    let p = dir.join("scene.json");
    std::fs::write(&p, scene).unwrap();
    p
}

#[test]
fn check_writes_json_and_csv_reports() {
    let dir = tempdir("check");
    cube_scene(&dir);
    for backend in ["cpu", "hybrid"] {
        let o = frcd(
            &[
                "check",
                "scene.json",
                "--backend",
                backend,
                "--json",
                "r.json",
                "--csv",
                "r.csv",
                "--segments",
            ],
            &dir,
        );
        assert!(o.status.success(), "{}", text(&o));
        let stdout = String::from_utf8_lossy(&o.stdout);
        assert!(stdout.contains("a / b: frames 1..=3"), "{stdout}");
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("r.json")).unwrap()).unwrap();
        assert_eq!(v["backend"], backend);
        assert_eq!(v["mode"], "exact");
        let frames = v["frames"].as_array().unwrap();
        assert_eq!(frames.len(), 5);
        for (i, f) in frames.iter().enumerate() {
            assert_eq!(f["index"], i);
            assert!(f["time_us"].as_f64().unwrap() > 0.0);
            let hits = f["interferences"].as_array().unwrap();
            let ab = hits.iter().find(|h| h["a"] == "a" && h["b"] == "b");
            assert_eq!(ab.is_some(), (1..=3).contains(&i), "frame {i}: {hits:?}");
            if let Some(h) = ab {
                assert!(h["triangle_pairs"].as_u64().unwrap() > 0);
                assert_eq!(h["contained"], false);
                assert!(!h["segments"].as_array().unwrap().is_empty());
            }
            let ball = hits.iter().find(|h| h["b"] == "ball");
            assert_eq!(ball.is_some(), i == 2, "frame {i}: {hits:?}");
            if let Some(h) = ball {
                assert_eq!(h["a"], "a");
                assert_eq!(h["triangle_pairs"], 0);
                assert_eq!(h["contained"], true);
            }
        }
        let csv = std::fs::read_to_string(dir.join("r.csv")).unwrap();
        assert!(csv.lines().count() >= 6, "{csv}");
    }
}

#[test]
fn bad_input_fails_cleanly() {
    let dir = tempdir("bad");
    cube_scene(&dir);
    assert_clean_failure(&frcd(&["check", "missing.json"], &dir), "missing.json");
    std::fs::write(dir.join("broken.json"), "{\"bodies\": [").unwrap();
    assert_clean_failure(&frcd(&["check", "broken.json"], &dir), "broken.json");
    std::fs::write(
        dir.join("nomesh.json"),
        r#"{"bodies": [{"name": "a", "mesh": "nope.stl", "static": true, "pose": {"t": [0,0,0], "q": [0,0,0,1]}}], "frames": []}"#,
    )
    .unwrap();
    assert_clean_failure(&frcd(&["check", "nomesh.json"], &dir), "nope.stl");
    assert_clean_failure(
        &frcd(&["check", "scene.json", "--first", "99"], &dir),
        "--first 99",
    );
    assert_clean_failure(
        &frcd(
            &[
                "check",
                "scene.json",
                "--backend",
                "image",
                "--mode",
                "exact",
            ],
            &dir,
        ),
        "fast",
    );
    std::fs::write(dir.join("cost.json"), "{\"threads\": \"two\"}").unwrap();
    assert_clean_failure(
        &frcd(&["check", "scene.json", "--cost", "cost.json"], &dir),
        "cost.json",
    );
    assert_clean_failure(
        &frcd(&["check", "scene.json", "--backend", "nope"], &dir),
        "nope",
    );
    assert_clean_failure(
        &frcd(
            &["render", "scene.json", "--frame", "7", "-o", "x.png"],
            &dir,
        ),
        "--frame 7",
    );
}

#[test]
fn calibrate_writes_a_loadable_model() {
    let dir = tempdir("calibrate");
    cube_scene(&dir);
    let o = frcd(
        &[
            "calibrate",
            "--cpu-only",
            "--repetitions",
            "1",
            "-o",
            "frcd-cost.json",
        ],
        &dir,
    );
    assert!(o.status.success(), "{}", text(&o));
    let m = frcd_hybrid::CostModel::load(dir.join("frcd-cost.json")).unwrap();
    assert!(m.cpu_narrow_ns_per_triangle > 0.0 && m.gpu_narrow_us.is_none());
    // A model file in the working directory is never picked up by itself (issue 11): a note
    // says it is there, and naming it uses it.
    let o = frcd(&["check", "scene.json"], &dir);
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&o);
    assert!(t.contains("cost model built-in"), "{t}");
    assert!(t.contains("frcd-cost.json is not used unless named"), "{t}");
    let o = frcd(&["check", "scene.json", "--cost", "frcd-cost.json"], &dir);
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("cost model frcd-cost.json"),
        "{}",
        text(&o)
    );
}

#[test]
fn bench_prints_a_row_per_backend() {
    let dir = tempdir("bench");
    cube_scene(&dir);
    let o = frcd(
        &["bench", "scene.json", "--frames", "5", "--json", "b.json"],
        &dir,
    );
    assert!(o.status.success(), "{}", text(&o));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("b.json")).unwrap()).unwrap();
    let rows = v.as_array().unwrap();
    let cpu = &rows[0];
    assert_eq!(cpu["backend"], "cpu");
    assert_eq!(cpu["interferences"], 4);
    // Every exact row agrees with cpu exact.
    for r in rows.iter().filter(|r| r["mode"] == "exact") {
        assert_eq!(r["differences_from_cpu_exact"], 0, "{r}");
    }
}

#[cfg(feature = "gpu")]
#[test]
fn render_writes_a_png() {
    let dir = tempdir("render");
    cube_scene(&dir);
    let o = frcd(
        &[
            "render",
            "scene.json",
            "--frame",
            "2",
            "-o",
            "f.png",
            "--width",
            "320",
            "--height",
            "200",
        ],
        &dir,
    );
    let t = text(&o);
    if !o.status.success()
        && t.contains("no GPU adapter")
        && std::env::var("FRCD_REQUIRE_GPU").as_deref() != Ok("1")
    {
        println!("SKIP render_writes_a_png: no GPU adapter");
        return;
    }
    assert!(o.status.success(), "{t}");
    let bytes = std::fs::read(dir.join("f.png")).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (320, 200));
    // Some highlighted (red) pixels: the interfering triangles are visible.
    let red = buf[..info.buffer_size()]
        .chunks(4)
        .filter(|p| p[0] > 150 && p[1] < 60 && p[2] < 60)
        .count();
    assert!(red > 0, "no highlighted pixel");
}

/// The demo: `frcd check testdata/bogie/scene.json` reports exactly the schedule the generator
/// computed with the exact oracle (`expected_interference.json`).
#[test]
fn bogie_demo_matches_the_expected_schedule() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let scene = root.join("testdata/bogie/scene.json");
    let expected = root.join("testdata/bogie/expected_interference.json");
    if !scene.exists() || !expected.exists() {
        println!(
            "SKIP bogie demo: {} not found (cargo xtask gen-bogie)",
            scene.display()
        );
        return;
    }
    let dir = tempdir("bogie");
    let out = dir.join("bogie.json");
    let o = frcd(
        &[
            "check",
            scene.to_str().unwrap(),
            "--backend",
            "cpu",
            "--quiet",
            "--json",
            out.to_str().unwrap(),
        ],
        &dir,
    );
    assert!(o.status.success(), "{}", text(&o));
    let got = frcd_io::Report::read_json(&out).unwrap();
    let want = frcd_io::Report::read_json(&expected).unwrap();
    assert!(!want.pairs.is_empty());
    assert_eq!(got.pairs, want.pairs);
}
