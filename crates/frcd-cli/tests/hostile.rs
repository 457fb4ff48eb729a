//! Issue 11 regressions, running the built binary: outputs never overwrite inputs or each
//! other and are checked before the run, hostile files are refused in bounded time, counts do
//! not wrap, names are escaped, `-q` is quiet, progress stays off redirected output, and the
//! report says what it measured.

mod common;
use common::*;
use frcd_geom::{DVec3, shapes};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

/// Cube `a` (static) and cube `b` moving along x through it, frames from a trajectory CSV
/// (`frames` frames); ball `c` inside `a` in frame 2 only.
fn scene(dir: &Path, frames: usize, name_b: &str) -> PathBuf {
    frcd_io::write_obj(
        dir.join("cube.obj"),
        &shapes::cuboid(DVec3::splat(0.5)),
        "cube",
    )
    .unwrap();
    frcd_io::write_stl_binary(dir.join("ball.stl"), &shapes::icosphere(0.1, 1)).unwrap();
    let mut csv = String::from("frame,body,x,y,z,qx,qy,qz,qw\n");
    let name_csv = name_b.replace('"', "\"\"");
    for k in 0..frames {
        let x = -2.0 + 4.0 * k as f64 / (frames.max(2) - 1) as f64;
        csv += &format!("{k},\"{name_csv}\",{x},0.1,0.05,0,0,0,1\n");
    }
    csv += "2,c,0,0,0,0,0,0,1\n3,c,0,5,0,0,0,0,1\n";
    std::fs::write(dir.join("traj.csv"), csv).unwrap();
    let name_json = serde_json::to_string(name_b).unwrap();
    let text = format!(
        r#"{{"bodies": [
  {{"name": "a", "mesh": "cube.obj", "static": true}},
  {{"name": {name_json}, "mesh": "cube.obj", "pose": {{"t": [-2, 0, 0], "q": [0, 0, 0, 1]}}}},
  {{"name": "c", "mesh": "ball.stl", "pose": {{"t": [0, 5, 0], "q": [0, 0, 0, 1]}}}}
 ],
 "exclude": [[{name_json}, "c"]],
 "trajectory": "traj.csv"}}"#
    );
    let p = dir.join("scene.json");
    std::fs::write(&p, text).unwrap();
    p
}

fn snapshot(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .map(|p| {
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                std::fs::read(&p).unwrap(),
            )
        })
        .collect();
    v.sort();
    v
}

#[test]
fn outputs_never_overwrite_inputs_or_each_other() {
    let dir = tempdir("outputs");
    scene(&dir, 5, "b");
    let before = snapshot(&dir);
    for (args, needle) in [
        (
            vec!["check", "scene.json", "--json", "scene.json"],
            "inputs",
        ),
        (vec!["check", "scene.json", "--csv", "traj.csv"], "inputs"),
        (vec!["check", "scene.json", "--json", "cube.obj"], "inputs"),
        (
            vec!["check", "scene.json", "--json", "./ball.stl"],
            "inputs",
        ),
        (
            vec!["check", "scene.json", "--json", "r.out", "--csv", "./r.out"],
            "also given to --json",
        ),
        (vec!["render", "scene.json", "-o", "scene.json"], "inputs"),
        (vec!["bench", "scene.json", "--json", "traj.csv"], "inputs"),
    ] {
        assert_clean_failure(&frcd(&args, &dir), needle);
    }
    // A hard link to an input is the input.
    std::fs::hard_link(dir.join("scene.json"), dir.join("link.json")).unwrap();
    assert_clean_failure(
        &frcd(&["check", "scene.json", "--json", "link.json"], &dir),
        "inputs",
    );
    std::fs::remove_file(dir.join("link.json")).unwrap();
    assert_eq!(snapshot(&dir), before, "an input changed");
}

#[test]
fn output_paths_are_checked_before_the_run() {
    let dir = tempdir("early");
    scene(&dir, 5, "b");
    std::fs::create_dir_all(dir.join("adir")).unwrap();
    for (out, needle) in [
        ("no/such/folder/r.json", "no/such/folder"),
        ("adir", "directory"),
        ("/dev/null", "not a regular file"),
    ] {
        let o = frcd(&["check", "scene.json", "--json", out], &dir);
        assert_clean_failure(&o, needle);
        // Nothing was checked: the summary line of a run never appeared.
        assert!(
            !String::from_utf8_lossy(&o.stdout).contains("time per frame"),
            "{}",
            text(&o)
        );
    }
    // A previous report is replaced whole, and no temporary file is left behind.
    std::fs::write(dir.join("r.json"), "old").unwrap();
    let o = frcd(&["check", "scene.json", "--json", "r.json", "-q"], &dir);
    assert!(o.status.success(), "{}", text(&o));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("r.json")).unwrap()).unwrap();
    assert_eq!(v["frames"].as_array().unwrap().len(), 5);
    let temps: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".tmp"))
        .collect();
    assert!(temps.is_empty(), "{temps:?}");
}

#[cfg(unix)]
#[test]
fn fifos_and_devices_are_refused_without_hanging() {
    let dir = tempdir("fifo");
    scene(&dir, 5, "b");
    let made = Command::new("mkfifo")
        .arg(dir.join("pipe.json"))
        .status()
        .is_ok_and(|s| s.success());
    let limit = Duration::from_secs(60);
    if made {
        let o = run_with_timeout(&["check", "pipe.json"], &dir, limit);
        assert_clean_failure(&o, "FIFO");
    }
    for args in [
        vec!["check", "/dev/zero"],
        vec!["check", "scene.json", "--trajectory", "/dev/zero"],
        vec!["check", "scene.json", "--cost", "/dev/zero"],
        vec!["check", "scene.json", "--trajectory", "/dev/urandom"],
    ] {
        let o = run_with_timeout(&args, &dir, limit);
        assert_clean_failure(&o, "not a regular file");
    }
    // A mesh that is a symbolic link to /dev/zero (inside the folder, so only the file type
    // stops it once outside paths are allowed).
    std::os::unix::fs::symlink("/dev/zero", dir.join("zero.stl")).unwrap();
    let zero = std::fs::read_to_string(dir.join("scene.json"))
        .unwrap()
        .replace("ball.stl", "zero.stl");
    std::fs::write(dir.join("zero.json"), zero).unwrap();
    let o = run_with_timeout(&["check", "zero.json", "--allow-outside"], &dir, limit);
    assert_clean_failure(&o, "not a regular file");
}

#[test]
fn counts_do_not_wrap_and_zero_is_refused() {
    let dir = tempdir("counts");
    scene(&dir, 8, "b");
    let o = frcd(
        &[
            "check",
            "scene.json",
            "--first",
            "5",
            "--count",
            "18446744073709551614",
            "--json",
            "r.json",
        ],
        &dir,
    );
    assert!(o.status.success(), "{}", text(&o));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("r.json")).unwrap()).unwrap();
    assert_eq!(v["frames"].as_array().unwrap().len(), 3, "frames 5, 6, 7");
    assert_eq!(v["frame_range"], serde_json::json!([5, 7]));
    assert!(String::from_utf8_lossy(&o.stdout).contains("frames 5..=7 (3 checked)"));
    assert_clean_failure(
        &frcd(&["check", "scene.json", "--count", "0"], &dir),
        "--count 0",
    );
    assert_clean_failure(
        &frcd(&["bench", "scene.json", "--frames", "0"], &dir),
        "--frames 0",
    );
}

#[test]
fn huge_frame_indices_are_clean_errors_and_far_frames_cost_no_memory() {
    let dir = tempdir("frames");
    scene(&dir, 3, "b");
    let mut csv = std::fs::read_to_string(dir.join("traj.csv")).unwrap();
    csv += "18446744073709551615,b,0,0,0,0,0,0,1\n";
    std::fs::write(dir.join("bad.csv"), &csv).unwrap();
    for args in [
        vec!["check", "scene.json", "--trajectory", "bad.csv"],
        vec![
            "render",
            "scene.json",
            "--trajectory",
            "bad.csv",
            "-o",
            "x.png",
        ],
    ] {
        assert_clean_failure(&frcd(&args, &dir), "past the limit");
    }
    // One row at frame 1,000,000: loads at once (sparse), and a window of it is checked.
    std::fs::write(
        dir.join("far.csv"),
        "frame,body,x,y,z,qx,qy,qz,qw\n1000000,b,0,0,0,0,0,0,1\n",
    )
    .unwrap();
    let o = frcd(
        &[
            "check",
            "scene.json",
            "--trajectory",
            "far.csv",
            "--first",
            "999998",
            "--json",
            "r.json",
        ],
        &dir,
    );
    assert!(o.status.success(), "{}", text(&o));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("r.json")).unwrap()).unwrap();
    let frames = v["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 3);
    // Held at x = 2 (the last row of traj.csv) until frame 1,000,000 moves it into `a`.
    assert!(frames[1]["interferences"].as_array().unwrap().is_empty());
    assert_eq!(frames[2]["interferences"][0]["b"], "b");
}

#[test]
fn files_outside_the_scene_folder_need_allow_outside() {
    let dir = tempdir("outside");
    scene(&dir, 3, "b");
    let evil = std::fs::read_to_string(dir.join("scene.json"))
        .unwrap()
        .replace("traj.csv", "../../../../../../etc/passwd");
    std::fs::write(dir.join("evil.json"), evil).unwrap();
    let o = frcd(&["check", "evil.json"], &dir);
    assert_clean_failure(&o, "--allow-outside");
    assert!(!text(&o).contains("root:"), "{}", text(&o));
}

#[test]
fn names_are_escaped_on_the_terminal() {
    let dir = tempdir("names");
    scene(&dir, 5, "b\u{1b}[31mRED\rX\nfake line");
    let o = frcd(&["check", "scene.json"], &dir);
    assert!(o.status.success(), "{}", text(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(!out.contains('\u{1b}') && !out.contains('\r'), "{out:?}");
    assert!(out.contains("b\\u{1b}[31mRED\\rX\\nfake line"), "{out}");
    assert!(!out.lines().any(|l| l.starts_with("fake line")), "{out}");
}

#[test]
fn quiet_prints_nothing_and_progress_never_reaches_a_log() {
    let dir = tempdir("quiet");
    scene(&dir, 400, "b");
    let o = frcd(&["check", "scene.json", "-q", "--json", "r.json"], &dir);
    assert!(o.status.success(), "{}", text(&o));
    assert!(o.stdout.is_empty() && o.stderr.is_empty(), "{}", text(&o));
    assert!(dir.join("r.json").exists());
    // Not quiet, output redirected: the summary, but no progress line.
    let o = frcd(&["check", "scene.json"], &dir);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        !o.stderr.contains(&b'\r') && !o.stdout.contains(&b'\r'),
        "{}",
        text(&o)
    );
    assert!(
        !String::from_utf8_lossy(&o.stderr).contains("frame 1"),
        "{}",
        text(&o)
    );
}

#[test]
fn the_report_says_what_it_measured() {
    let dir = tempdir("report");
    scene(&dir, 5, "b");
    let o = frcd(
        &[
            "check",
            "scene.json",
            "--json",
            "r.json",
            "--pairs",
            "--backend",
            "cpu",
        ],
        &dir,
    );
    assert!(o.status.success(), "{}", text(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    // The ball sits inside `a` in frame 2: said in words, not as "0 triangle pairs".
    assert!(
        stdout.contains("a / c: frames 2..=2 (1 frames, contained)"),
        "{stdout}"
    );
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("r.json")).unwrap()).unwrap();
    assert_eq!(v["frcd_version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(v["frame_range"], serde_json::json!([0, 4]));
    assert!(v["units"]["length"].is_string() && v["units"]["time"].is_string());
    let mut any_pairs = false;
    for f in v["frames"].as_array().unwrap() {
        let t = f["time_us"].as_f64().unwrap();
        assert_eq!((t * 10.0).round() / 10.0, t, "time rounded to 0.1 µs: {t}");
        for i in f["interferences"].as_array().unwrap() {
            let n = i["triangle_pairs"].as_u64().unwrap() as usize;
            let listed = i
                .get("triangles")
                .map_or(0, |t| t.as_array().unwrap().len());
            assert_eq!(listed, n, "{i}");
            any_pairs |= n > 0;
        }
    }
    assert!(any_pairs);
    assert!(
        v["pairs"]
            .as_array()
            .unwrap()
            .iter()
            .any(|p| p["contained"] == true)
    );
}

#[test]
fn loaded_mesh_problems_are_reported() {
    let dir = tempdir("meshes");
    scene(&dir, 5, "b");
    // An open box (one face missing) with a duplicated and a degenerate triangle.
    let cube = shapes::cuboid(DVec3::splat(0.5));
    let mut idx: Vec<[u32; 3]> = cube.indices()[2..].to_vec();
    idx.push(idx[0]);
    idx.push([idx[0][0], idx[0][0], idx[0][1]]);
    let open = frcd_geom::TriMesh::new(cube.vertices().to_vec(), idx).unwrap();
    frcd_io::write_obj(dir.join("open.obj"), &open, "open").unwrap();
    let open_scene = std::fs::read_to_string(dir.join("scene.json"))
        .unwrap()
        .replace(
            "\"mesh\": \"cube.obj\", \"static\": true",
            "\"mesh\": \"open.obj\", \"static\": true",
        );
    std::fs::write(dir.join("open.json"), open_scene).unwrap();
    let o = frcd(&["check", "open.json", "--mode", "exact"], &dir);
    assert!(o.status.success(), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("open.obj"), "{err}");
    assert!(err.contains("duplicate"), "{err}");
    assert!(err.contains("degenerate"), "{err}");
    assert!(err.contains("open ("), "{err}");
    assert!(err.contains("containment in it cannot be decided"), "{err}");
}

#[test]
fn no_xdg_runtime_dir_noise() {
    let dir = tempdir("xdg");
    scene(&dir, 3, "b");
    let o = Command::new(env!("CARGO_BIN_EXE_frcd"))
        .args(["check", "scene.json", "--backend", "hybrid"])
        .current_dir(&dir)
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("FRCD_COST_MODEL")
        // frcd makes its private runtime folder in the temp folder: this test's own, so that
        // the folder goes with it.
        .env("TMPDIR", dir.as_os_str())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    assert!(!text(&o).contains("XDG_RUNTIME_DIR"), "{}", text(&o));
}
