//! Hostile and huge inputs (issue 11): every one gives a typed error or a correct answer, in
//! bounded time and memory.

use frcd_geom::{DVec3, shapes};
use frcd_io::{Error, Limits, Scene, SceneOptions, Trajectory, write_stl_binary};
use std::path::{Path, PathBuf};

mod common;
use common::TempDir;

fn temp_dir(name: &str) -> TempDir {
    let dir = TempDir::new("hostile", name);
    write_stl_binary(dir.join("box.stl"), &shapes::cuboid(DVec3::splat(0.5))).unwrap();
    dir
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn scene_with(dir: &Path, mesh: &str, trajectory: Option<&str>) -> PathBuf {
    let t = trajectory.map_or(String::new(), |t| format!(", \"trajectory\": \"{t}\""));
    write(
        dir,
        "scene.json",
        &format!(
            r#"{{"bodies": [{{"name": "a", "mesh": "{mesh}"}}, {{"name": "b", "mesh": "box.stl"}}]{t}}}"#
        ),
    )
}

const HEADER: &str = "frame,body,x,y,z,qx,qy,qz,qw\n";

#[test]
fn a_far_frame_is_stored_sparsely() {
    let dir = temp_dir("sparse");
    write(
        &dir,
        "t.csv",
        &format!("{HEADER}1000000,a,0,0,5,0,0,0,1\n3,b,1,0,0,0,0,0,1\n"),
    );
    let s = Scene::load(scene_with(&dir, "box.stl", Some("t.csv"))).unwrap();
    assert_eq!(s.frame_count(), 1_000_001);
    // Two poses stored, not a million frames of two.
    assert_eq!(s.pose_count(), 2);
    // Held between keyframes.
    assert_eq!(s.frame(2).poses[1].translation, DVec3::ZERO);
    assert_eq!(s.frame(3).poses[1].translation.x, 1.0);
    assert_eq!(s.frame(3).moved, vec![1]);
    assert_eq!(s.frame(999_999).poses[1].translation.x, 1.0);
    assert!(s.frame(999_999).moved.is_empty());
    assert_eq!(s.frame(999_999).poses[0].translation, DVec3::ZERO);
    let last = s.frame(1_000_000);
    assert_eq!(last.poses[0].translation.z, 5.0);
    assert_eq!(last.moved, vec![0]);
    // The iterator agrees with random access, starting anywhere.
    let it: Vec<_> = s.frames().range(999_998..1_000_001).collect();
    assert_eq!(it.len(), 3);
    for (k, f) in (999_998..).zip(&it) {
        assert_eq!(*f, s.frame(k), "frame {k}");
    }
    let head: Vec<_> = s.frames().iter().take(5).collect();
    for (k, f) in head.iter().enumerate() {
        assert_eq!(*f, s.frame(k), "frame {k}");
    }
}

#[test]
fn frame_indices_past_the_limit_are_errors_not_panics_or_huge_allocations() {
    let dir = temp_dir("limit");
    for frame in ["18446744073709551615", "1000000000000", "1000000000"] {
        write(&dir, "t.csv", &format!("{HEADER}{frame},a,0,0,5,0,0,0,1\n"));
        let e = Scene::load(scene_with(&dir, "box.stl", Some("t.csv"))).unwrap_err();
        assert!(
            matches!(&e, Error::Limit { place, .. } if place == "line 2"),
            "{frame}: {e}"
        );
        assert!(Trajectory::load(dir.join("t.csv")).is_err());
    }
    // A lower limit set by the caller.
    write(&dir, "t.csv", &format!("{HEADER}10,a,0,0,5,0,0,0,1\n"));
    let options = SceneOptions {
        limits: Limits {
            frames: 10,
            ..Limits::default()
        },
        ..SceneOptions::default()
    };
    let e = Scene::load_with(scene_with(&dir, "box.stl", Some("t.csv")), &options).unwrap_err();
    assert!(matches!(e, Error::Limit { .. }), "{e}");
}

#[test]
fn paths_outside_the_scene_folder_are_refused_unless_allowed() {
    let dir = temp_dir("outside");
    let sub = dir.join("scene");
    std::fs::create_dir_all(&sub).unwrap();
    std::fs::copy(dir.join("box.stl"), sub.join("box.stl")).unwrap();
    let abs = dir.join("box.stl").display().to_string();
    for (mesh, traj) in [
        ("../box.stl", None),
        (abs.as_str(), None),
        ("box.stl", Some("../../../../etc/passwd")),
        ("box.stl", Some("/etc/passwd")),
    ] {
        let p = scene_with(&sub, mesh, traj);
        let e = Scene::load(&p).unwrap_err();
        assert!(
            matches!(e, Error::OutsideSceneFolder { .. }),
            "{mesh} {traj:?}: {e}"
        );
        // The message never shows the outside file's content.
        assert!(!e.to_string().contains("root:"), "{e}");
    }
    // A symbolic link inside the folder that leads out is refused too.
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(dir.join("box.stl"), sub.join("link.stl")).unwrap();
        let e = Scene::load(scene_with(&sub, "link.stl", None)).unwrap_err();
        assert!(matches!(e, Error::OutsideSceneFolder { .. }), "{e}");
    }
    // Allowed on request.
    let allow = SceneOptions {
        allow_outside: true,
        ..SceneOptions::default()
    };
    let s = Scene::load_with(scene_with(&sub, "../box.stl", None), &allow).unwrap();
    assert_eq!(s.meshes().len(), 2);
    // Subfolders are inside.
    std::fs::create_dir_all(sub.join("m")).unwrap();
    std::fs::copy(dir.join("box.stl"), sub.join("m/b.stl")).unwrap();
    assert!(Scene::load(scene_with(&sub, "./m/../m/b.stl", None)).is_ok());
}

#[cfg(unix)]
#[test]
fn fifos_devices_and_directories_are_refused_without_blocking() {
    let dir = temp_dir("devices");
    let fifo = dir.join("pipe.stl");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .is_ok_and(|s| s.success());
    let allow = SceneOptions {
        allow_outside: true,
        ..SceneOptions::default()
    };
    if made {
        let e = Scene::load(scene_with(&dir, "pipe.stl", None)).unwrap_err();
        assert!(matches!(e, Error::NotAFile { .. }), "{e}");
        let e = frcd_io::load_mesh(&fifo).unwrap_err();
        assert!(matches!(e, Error::NotAFile { .. }), "{e}");
        let e = Scene::load(&fifo).unwrap_err();
        assert!(matches!(e, Error::NotAFile { .. }), "{e}");
    }
    std::os::unix::fs::symlink("/dev/zero", dir.join("zero.stl")).unwrap();
    let e = Scene::load_with(scene_with(&dir, "zero.stl", None), &allow).unwrap_err();
    assert!(matches!(e, Error::NotAFile { .. }), "{e}");
    for dev in ["/dev/zero", "/dev/urandom"] {
        assert!(matches!(Scene::load(dev), Err(Error::NotAFile { .. })));
        assert!(matches!(Trajectory::load(dev), Err(Error::NotAFile { .. })));
        let e = Scene::load_with_trajectory(scene_with(&dir, "box.stl", None), dev).unwrap_err();
        assert!(matches!(e, Error::NotAFile { .. }), "{e}");
    }
    std::fs::create_dir_all(dir.join("d.stl")).unwrap();
    let e = Scene::load(scene_with(&dir, "d.stl", None)).unwrap_err();
    assert!(matches!(e, Error::NotAFile { .. }), "{e}");
}

#[test]
fn files_over_the_limits_are_refused() {
    let dir = temp_dir("toolarge");
    write(&dir, "t.csv", &format!("{HEADER}1,a,0,0,5,0,0,0,1\n"));
    let scene = scene_with(&dir, "box.stl", Some("t.csv"));
    for limits in [
        Limits {
            mesh_bytes: 100,
            ..Limits::default()
        },
        Limits {
            scene_bytes: 10,
            ..Limits::default()
        },
        Limits {
            trajectory_bytes: 20,
            ..Limits::default()
        },
    ] {
        let options = SceneOptions {
            limits,
            ..SceneOptions::default()
        };
        let e = Scene::load_with(&scene, &options).unwrap_err();
        assert!(matches!(e, Error::TooLarge { .. }), "{limits:?}: {e}");
    }
}

#[test]
fn a_body_twice_in_one_frame_names_both_places_across_files() {
    let dir = temp_dir("twice");
    write(&dir, "t.csv", &format!("{HEADER}1,a,0,0,5,0,0,0,1\n"));
    write(
        &dir,
        "u.csv",
        &format!("{HEADER}0,b,0,0,5,0,0,0,1\n\n1,a,0,0,6,0,0,0,1\n"),
    );
    let e = Scene::load_with_trajectory(
        scene_with(&dir, "box.stl", Some("t.csv")),
        dir.join("u.csv"),
    )
    .unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("u.csv: line 4") && msg.contains("t.csv: line 2"),
        "{msg}"
    );
}

#[test]
fn header_errors_show_little_and_escape_it() {
    let dir = temp_dir("header");
    let long = format!("frame,body\u{1b}[31m,{}\n", "x".repeat(500));
    let p = write(&dir, "t.csv", &long);
    let msg = Trajectory::load(&p).unwrap_err().to_string();
    assert!(!msg.contains('\u{1b}'), "{msg}");
    assert!(msg.len() < 300, "{}", msg.len());
}

/// Found by the scene fuzz target: serde_json's default float parser was off by an ulp on some
/// 17-digit numbers, so a pose read from a scene was not the pose written in it.
#[test]
fn scene_numbers_are_read_exactly() {
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let mut texts = vec![
        "1.0000000000080002e+44".to_string(),
        "2.2250738585072011e-308".into(),
    ];
    for _ in 0..2000 {
        let mantissa = next() % 100_000_000_000_000_000;
        let exp = (next() % 540) as i64 - 290;
        texts.push(format!("{mantissa}e{exp}"));
    }
    for t in texts {
        let want: f64 = t.parse().unwrap();
        let json = format!(
            r#"{{"bodies": [{{"name": "a", "mesh": "a.stl", "pose": {{"t": [{t}, 0, 0], "q": [0, 0, 0, 1]}}}}]}}"#
        );
        let spec = frcd_io::SceneFile::parse(&json, Path::new("s.json")).unwrap();
        assert_eq!(spec.bodies[0].pose.t[0].to_bits(), want.to_bits(), "{t}");
    }
}
