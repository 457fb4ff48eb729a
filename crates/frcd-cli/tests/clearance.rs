//! `frcd check --clearance`: per-frame clearances in the JSON and CSV reports, the text
//! summary, the SVG plot, and typed errors for bad thresholds (the built binary).

mod common;
use common::*;
use frcd_geom::{DVec3, shapes};
use std::path::{Path, PathBuf};

/// Gaps between cube `a` (static, at the origin) and cube `b` per frame: 4 mm, touching,
/// interfering, 3 mm, 1 m. A small ball sits inside `a` in frame 4 only (contained).
const XS: [f64; 5] = [-1.004, -1.0, -0.9, -1.003, 2.0];

fn scene(dir: &Path, extra: &str) -> PathBuf {
    frcd_io::write_obj(
        dir.join("cube.obj"),
        &shapes::cuboid(DVec3::splat(0.5)),
        "cube",
    )
    .unwrap();
    frcd_io::write_stl_binary(dir.join("ball.stl"), &shapes::icosphere(0.1, 1)).unwrap();
    let frames: Vec<String> = XS
        .iter()
        .enumerate()
        .map(|(i, x)| {
            let ball = if i == 4 { 0.0 } else { 5.0 };
            format!(
                r#"{{"b": {{"t": [{x}, 0.1, 0.05], "q": [0, 0, 0, 1]}}, "ball": {{"t": [0, {ball}, 0], "q": [0, 0, 0, 1]}}}}"#
            )
        })
        .collect();
    let text = format!(
        r#"{{"bodies": [
  {{"name": "a", "mesh": "cube.obj", "static": true}},
  {{"name": "b", "mesh": "cube.obj"}},
  {{"name": "ball", "mesh": "ball.stl", "pose": {{"t": [0, 5, 0], "q": [0, 0, 0, 1]}}}}
 ],
 "exclude": [["b", "ball"]]{extra},
 "frames": [{}]}}"#,
        frames.join(",\n  ")
    );
    let p = dir.join("scene.json");
    std::fs::write(&p, text).unwrap();
    p
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The `a`/`b` clearance of every frame of a JSON report (`None`: not reported).
fn ab_distances(v: &serde_json::Value) -> Vec<Option<f64>> {
    v["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            f["clearances"]
                .as_array()
                .unwrap()
                .iter()
                .find(|c| c["a"] == "a" && c["b"] == "b")
                .map(|c| c["distance"].as_f64().unwrap())
        })
        .collect()
}

#[test]
fn clearance_in_json_csv_summary_and_plot() {
    let dir = tempdir("run");
    scene(&dir, "");
    let o = frcd(
        &[
            "check",
            "scene.json",
            "--backend",
            "cpu",
            "--clearance",
            "0.005",
            "--json",
            "r.json",
            "--csv",
            "r.csv",
            "--plot-clearance",
            "c.svg",
        ],
        &dir,
    );
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    let v = json(&dir.join("r.json"));
    let d = ab_distances(&v);
    let want = [Some(0.004), Some(0.0), Some(0.0), Some(0.003), None];
    for (k, (g, w)) in d.iter().zip(want).enumerate() {
        match (g, w) {
            (Some(g), Some(w)) => assert!((g - w).abs() < 1e-12, "frame {k}: {g} vs {w}\n{t}"),
            (None, None) => {}
            _ => panic!("frame {k}: {g:?} vs {w:?}\n{t}"),
        }
    }
    // Frame 0: points 4 mm apart along x, on the facing faces; triangles named.
    let c0 = &v["frames"][0]["clearances"][0];
    let (pa, pb) = (&c0["points"][0], &c0["points"][1]);
    assert!((pa[0].as_f64().unwrap() + 0.5).abs() < 1e-12, "{c0}");
    assert!((pb[0].as_f64().unwrap() + 0.504).abs() < 1e-12, "{c0}");
    assert_eq!(c0["triangles"].as_array().unwrap().len(), 2);
    // Frame 4: the ball inside `a` reports 0, contained.
    let c4 = v["frames"][4]["clearances"].as_array().unwrap();
    let ball = c4
        .iter()
        .find(|c| c["b"] == "ball")
        .expect("contained ball");
    assert_eq!(ball["distance"].as_f64(), Some(0.0));
    assert_eq!(ball["contained"], true);
    // The excluded pair b / ball never appears.
    assert!(
        v["frames"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|f| f["clearances"].as_array().unwrap())
            .all(|c| !(c["a"] == "b" && c["b"] == "ball"))
    );
    // Summary: minimum per pair and its frame (first occurrence).
    let s = v["clearance_pairs"].as_array().unwrap();
    let ab = s.iter().find(|p| p["a"] == "a" && p["b"] == "b").unwrap();
    assert_eq!(ab["min_distance"].as_f64(), Some(0.0));
    assert_eq!(ab["min_frame"].as_u64(), Some(1));
    assert_eq!(ab["zero_intervals"], serde_json::json!([[1, 2]]));
    assert_eq!(v["clearance"]["default"].as_f64(), Some(0.005));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("a / b: min 0.000000 at frame 1"), "{t}");
    assert!(out.contains("interferes (0) in frames 1-2"), "{t}");
    assert!(out.contains("a / ball: min 0.000000 at frame 4"), "{t}");
    // CSV: a row per pair and frame, with the clearance columns.
    let csv = std::fs::read_to_string(dir.join("r.csv")).unwrap();
    let mut lines = csv.lines();
    let header = lines.next().unwrap();
    assert!(header.starts_with("frame,time_us,a,b,triangle_pairs,contained,distance,"));
    let cols = header.split(',').count();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert!(rows.iter().all(|r| r.len() == cols), "{csv}");
    let row = |f: &str, a: &str, b: &str| {
        rows.iter()
            .find(|r| r[0] == f && r[2] == a && r[3] == b)
            .unwrap_or_else(|| panic!("no row {f} {a} {b}:\n{csv}"))
    };
    assert_eq!(row("0", "a", "b")[4], "0");
    assert!((row("0", "a", "b")[6].parse::<f64>().unwrap() - 0.004).abs() < 1e-12);
    assert_ne!(row("2", "a", "b")[4], "0"); // interfering: triangle pairs and distance 0
    assert_eq!(row("2", "a", "b")[6].parse::<f64>().unwrap(), 0.0);
    assert_eq!(row("4", "a", "ball")[5], "true");
    // Frame 4: a / b is beyond its threshold, so its only row is a / ball.
    assert_eq!(rows.iter().filter(|r| r[0] == "4").count(), 1, "{csv}");
    let svg = std::fs::read_to_string(dir.join("c.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("a / b"), "{svg}");
}

#[test]
fn scene_thresholds_and_overrides() {
    let dir = tempdir("scene");
    // Scene-wide 5 mm and a pair threshold of 3.5 mm for a / b: the 4 mm frame is not reported.
    scene(
        &dir,
        r#", "clearance": 0.005, "clearances": [{"a": "b", "b": "a", "threshold": 0.0035}]"#,
    );
    let o = frcd(&["check", "scene.json", "--json", "r.json", "-q"], &dir);
    assert!(o.status.success(), "{}", text(&o));
    let d = ab_distances(&json(&dir.join("r.json")));
    assert_eq!(d[0], None);
    assert!((d[3].unwrap() - 0.003).abs() < 1e-12);
    // --clearance replaces the scene-wide value, not the pair's own.
    let o = frcd(
        &[
            "check",
            "scene.json",
            "--json",
            "r2.json",
            "-q",
            "--clearance",
            "0.5",
        ],
        &dir,
    );
    assert!(o.status.success(), "{}", text(&o));
    let v = json(&dir.join("r2.json"));
    assert_eq!(ab_distances(&v)[0], None);
    assert_eq!(v["clearance"]["default"].as_f64(), Some(0.5));
    // Without any threshold: no clearance in the report, the old CSV header.
    let dir2 = tempdir("none");
    scene(&dir2, "");
    let o = frcd(
        &["check", "scene.json", "--json", "r.json", "--csv", "r.csv"],
        &dir2,
    );
    assert!(o.status.success(), "{}", text(&o));
    let v = json(&dir2.join("r.json"));
    assert!(v["frames"][0].get("clearances").is_none());
    let csv = std::fs::read_to_string(dir2.join("r.csv")).unwrap();
    assert!(csv.starts_with("frame,time_us,a,b,triangle_pairs,contained\n"));
}

#[test]
fn bad_thresholds_fail_cleanly_before_the_run() {
    let dir = tempdir("bad");
    scene(&dir, "");
    for (arg, needle) in [
        ("-0.001", "negative"),
        ("NaN", "not finite"),
        ("inf", "not finite"),
    ] {
        let o = frcd(&["check", "scene.json", "--clearance", arg], &dir);
        assert_clean_failure(&o, needle);
    }
    for (extra, needle) in [
        (r#", "clearance": -0.1"#, "clearance: bad clearance"),
        (r#", "clearance": 1e999"#, "scene.json"),
        (
            r#", "clearances": [{"a": "a", "b": "nope", "threshold": 0.1}]"#,
            "clearances entry 0: unknown body 'nope'",
        ),
        (
            r#", "clearances": [{"a": "a", "b": "b", "threshold": -1}]"#,
            "clearances entry 0: bad clearance",
        ),
        (
            r#", "clearances": [{"a": "ball", "b": "b", "threshold": 0.1}]"#,
            "excluded",
        ),
        (
            r#", "clearances": [{"a": "a", "b": "a", "threshold": 0.1}]"#,
            "twice",
        ),
        (
            r#", "clearances": [{"a": "a", "b": "b", "threshold": 0.1}, {"a": "b", "b": "a", "threshold": 0.2}]"#,
            "already has a threshold (clearances entry 0)",
        ),
        (
            r#", "clearances": [{"a": "a", "b": "b", "threshhold": 0.1}]"#,
            "threshhold",
        ),
    ] {
        scene(&dir, extra);
        let o = frcd(&["check", "scene.json"], &dir);
        assert_clean_failure(&o, needle);
    }
    scene(&dir, "");
    // A plot needs a threshold; its path is checked like every output, before the run.
    let o = frcd(&["check", "scene.json", "--plot-clearance", "c.svg"], &dir);
    assert_clean_failure(&o, "needs a clearance threshold");
    let o = frcd(
        &[
            "check",
            "scene.json",
            "--clearance",
            "0.01",
            "--plot-clearance",
            "scene.json",
        ],
        &dir,
    );
    assert_clean_failure(&o, "one of the run's inputs");
    let o = frcd(
        &[
            "check",
            "scene.json",
            "--clearance",
            "0.01",
            "--plot-clearance",
            "x.out",
            "--json",
            "x.out",
        ],
        &dir,
    );
    assert_clean_failure(&o, "each output needs its own file");
    assert!(!dir.join("x.out").exists());
}

/// Every frame of the bogie demo with 5 mm: the checker's clearances through the run's state
/// (motion-bound skips, warm starts) and the wheelsets' meridian bound equal those of a fresh
/// state each frame of a checker without the meridian bound (no temporal state, a distance
/// search for every pair in range): the same pairs, the same distances, and the frames at 0
/// are the interfering ones.
#[test]
fn bogie_cached_clearance_equals_fresh_on_every_frame() {
    use frcd_hybrid::{Backend, BodySpec, Checker, FrameState, Options};
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let path = root.join("testdata/bogie/scene.json");
    if !path.exists() {
        println!("SKIP bogie: {} not found", path.display());
        return;
    }
    let scene = frcd_io::Scene::load(&path).unwrap();
    let bodies = || {
        scene
            .bodies()
            .iter()
            .map(|b| BodySpec {
                name: b.name.clone(),
                mesh: b.mesh.clone(),
                is_static: b.is_static,
            })
            .collect()
    };
    let options = Options {
        backend: Backend::Cpu,
        clearance: Some(0.005),
        ..Options::default()
    };
    assert!(options.clearance_spin);
    let checker = Checker::new(bodies(), scene.exclusions(), options.clone()).unwrap();
    let plain = Checker::new(
        bodies(),
        scene.exclusions(),
        Options {
            clearance_spin: false,
            ..options
        },
    )
    .unwrap();
    let mut state = FrameState::default();
    let (mut work, mut reported) = (frcd_obb::ClearanceWork::default(), 0);
    for (k, frame) in scene.frames().iter().enumerate() {
        let cached = checker.check(&frame.poses, &mut state).unwrap();
        let fresh = plain
            .check(&frame.poses, &mut FrameState::default())
            .unwrap();
        assert_eq!(cached.contacts, fresh.contacts, "frame {k}");
        let key = |c: &frcd_hybrid::PairClearance| (c.a, c.b, c.interfering);
        let (g, w): (Vec<_>, Vec<_>) = (
            cached.clearances.iter().map(key).collect(),
            fresh.clearances.iter().map(key).collect(),
        );
        assert_eq!(g, w, "frame {k}: cached vs fresh pairs");
        for (g, w) in cached.clearances.iter().zip(&fresh.clearances) {
            // The same smallest computed distance (another triangle pair only on exact ties).
            assert_eq!(g.distance, w.distance, "frame {k}: {g:?} vs {w:?}");
            assert_eq!(g.distance == 0.0, g.interfering, "frame {k}: {g:?}");
        }
        let contacts: Vec<_> = cached.contacts.iter().map(|c| (c.a, c.b)).collect();
        let zero: Vec<_> = cached
            .clearances
            .iter()
            .filter(|c| c.interfering)
            .map(|c| (c.a, c.b))
            .collect();
        assert_eq!(contacts, zero, "frame {k}");
        work += cached.clearance_work;
        reported += cached.clearances.len();
    }
    // The temporal state did skip queries, and the run reported pairs every frame.
    assert!(work.skipped > 1000, "{work:?}");
    // The wheelsets' pairs with the side frames and the car body: proved far at every spin.
    assert!(work.spin_skipped > 10_000, "{work:?}");
    assert!(reported > scene.frame_count(), "{reported}");
    println!("bogie clearance work with temporal state: {work:?}");
}

/// `frcd plot-clearance`: the same plot as `check --plot-clearance` (one code path), the
/// per-pair minima printed, nothing else; a threshold is required.
#[test]
fn plot_clearance_subcommand_writes_the_same_svg() {
    let dir = tempdir("plotcmd");
    scene(&dir, "");
    let o = frcd(
        &[
            "check",
            "scene.json",
            "--backend",
            "cpu",
            "--clearance",
            "0.005",
            "--plot-clearance",
            "check.svg",
        ],
        &dir,
    );
    assert!(o.status.success(), "{}", text(&o));
    let o = frcd(
        &[
            "plot-clearance",
            "scene.json",
            "--backend",
            "cpu",
            "--clearance",
            "0.005",
            "-o",
            "plot.svg",
        ],
        &dir,
    );
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("a / b: min 0.000000 at frame 1"), "{t}");
    assert!(out.contains("clearance of 2 pairs plotted"), "{t}");
    assert!(!out.contains("time per frame"), "{t}");
    let a = std::fs::read_to_string(dir.join("check.svg")).unwrap();
    let b = std::fs::read_to_string(dir.join("plot.svg")).unwrap();
    assert!(b.starts_with("<svg") && b.contains("a / b"), "{b}");
    assert_eq!(a, b);
    let o = frcd(&["plot-clearance", "scene.json", "-o", "x.svg"], &dir);
    assert_clean_failure(&o, "needs a clearance threshold");
    assert!(!dir.join("x.svg").exists());
}

/// `frcd plot-clearance -o` never overwrites one of the run's inputs (the scene file here):
/// refused before any work, the input left as it was.
#[test]
fn plot_clearance_refuses_to_overwrite_its_scene() {
    let dir = tempdir("plotinput");
    scene(&dir, "");
    let before = std::fs::read(dir.join("scene.json")).unwrap();
    let o = frcd(
        &[
            "plot-clearance",
            "scene.json",
            "--clearance",
            "0.005",
            "-o",
            "scene.json",
        ],
        &dir,
    );
    assert_clean_failure(&o, "one of the run's inputs");
    assert_eq!(std::fs::read(dir.join("scene.json")).unwrap(), before);
}
