//! Scene files, trajectories and reports.

use frcd_geom::{DQuat, DVec3, Pose, shapes};
use frcd_io::{
    Error, FrameReport, Interference, Location, Report, Scene, SceneFile, Trajectory,
    write_stl_binary,
};
use std::path::{Path, PathBuf};
use std::sync::Arc;

mod common;
use common::TempDir;

fn temp_dir(name: &str) -> TempDir {
    let dir = TempDir::new("scene", name);
    std::fs::create_dir_all(dir.join("meshes")).unwrap();
    write_stl_binary(
        dir.join("meshes/box.stl"),
        &shapes::cuboid(DVec3::splat(0.5)),
    )
    .unwrap();
    write_stl_binary(dir.join("meshes/ball.stl"), &shapes::icosphere(0.5, 1)).unwrap();
    dir
}

const SCENE: &str = r#"{
  "bodies": [
    {"name": "floor", "mesh": "meshes/box.stl", "static": true, "pose": {"t": [0, 0, -1], "q": [0, 0, 0, 1]}},
    {"name": "a", "mesh": "meshes/box.stl"},
    {"name": "b", "mesh": "./meshes/ball.stl", "pose": {"t": [2, 0, 0], "q": [0, 0, 0.7071068, 0.7071068]}}
  ],
  "exclude": [["b", "floor"]],
  "frames": [
    {"a": {"t": [0, 0, 0.5], "q": [0, 0, 0, 1]}},
    {},
    {"b": {"t": [1, 0, 0], "q": [0, 0, 0, 1]}, "a": {"t": [0, 0, 0.5], "q": [0, 0, 0, 1]}}
  ]
}"#;

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn scene_loads_shares_meshes_and_carries_poses_forward() {
    let dir = temp_dir("ok");
    let path = write(&dir, "scene.json", SCENE);
    let s = Scene::load(&path).unwrap();
    assert_eq!(s.bodies().len(), 3);
    assert_eq!(s.meshes().len(), 2);
    assert!(Arc::ptr_eq(&s.bodies()[0].mesh, &s.bodies()[1].mesh));
    assert!(s.bodies()[0].is_static && !s.bodies()[1].is_static);
    assert!(s.is_excluded(0, 2) && s.is_excluded(2, 0) && !s.is_excluded(0, 1));
    assert_eq!(s.frame_count(), 3);
    let f: Vec<_> = s.frames().iter().collect();
    assert_eq!(f[0].poses[1].translation, DVec3::new(0.0, 0.0, 0.5));
    assert_eq!(f[0].moved, vec![1]);
    // Frame 1 lists nothing: everything carried forward.
    assert_eq!(f[1].poses, f[0].poses);
    assert!(f[1].moved.is_empty());
    // Frame 2 re-lists `a` unchanged: only `b` moved.
    assert_eq!(f[2].moved, vec![2]);
    assert_eq!(f[2].poses[2].translation.x, 1.0);
    // The initial quaternion was normalised.
    assert!((s.bodies()[2].initial_pose.rotation.length() - 1.0).abs() < 1e-15);
    assert_eq!(s.frame(0).poses[2], s.bodies()[2].initial_pose);
}

#[test]
fn trajectory_csv_merges_into_frames() {
    let dir = temp_dir("csv");
    let scene = SCENE.replace(
        "\"exclude\"",
        "\"trajectory\": \"traj.csv\",\n  \"exclude\"",
    );
    let path = write(&dir, "scene.json", &scene);
    write(
        &dir,
        "traj.csv",
        "frame,body,x,y,z,qx,qy,qz,qw\n# comment\n4, b, 3,0,0, 0,0,0,1\n3,a,0,1,0,0,0,0,1\n",
    );
    let s = Scene::load(&path).unwrap();
    assert_eq!(s.frame_count(), 5);
    assert_eq!(s.frame(3).moved, vec![1]);
    assert_eq!(s.frame(3).poses[2].translation.x, 1.0);
    assert_eq!(s.frame(4).poses[2].translation.x, 3.0);
    assert_eq!(s.frame(4).poses[1].translation.y, 1.0);
    // An extra CSV that repeats a body in a frame the scene already sets is refused, naming both.
    let extra = write(
        &dir,
        "extra.csv",
        "frame,body,x,y,z,qx,qy,qz,qw\n2,b,0,0,0,0,0,0,1\n",
    );
    let e = Scene::load_with_trajectory(&path, &extra).unwrap_err();
    assert!(matches!(e, Error::Invalid { .. }), "{e}");
    let text = e.to_string();
    assert!(
        text.contains("extra.csv") && text.contains("line 2") && text.contains("frame 2"),
        "{text}"
    );
}

#[test]
fn scene_validation_errors() {
    let dir = temp_dir("bad");
    type Case = (String, fn(&Error) -> bool, &'static str);
    let cases: Vec<Case> = vec![
        (
            SCENE.replace(r#"{"b": {"t": [1, 0, 0]"#, r#"{"c": {"t": [1, 0, 0]"#),
            |e| matches!(e, Error::UnknownBody { name, place, .. } if name == "c" && place == "frame 2"),
            "frame 2",
        ),
        (
            SCENE.replace(r#"[["b", "floor"]]"#, r#"[["b", "floor"], ["a", "wall"]]"#),
            |e| matches!(e, Error::UnknownBody { place, .. } if place == "exclude pair 1"),
            "exclude pair 1",
        ),
        (
            SCENE.replace(r#"{"name": "a""#, r#"{"name": "b""#),
            |e| matches!(e, Error::DuplicateBody { name, .. } if name == "b"),
            "'b'",
        ),
        (
            SCENE.replace("[0, 0, 0.7071068, 0.7071068]", "[0, 0, 0.5, 0.5]"),
            |e| matches!(e, Error::BadPose { place, .. } if place == "body 'b'"),
            "length",
        ),
        (
            SCENE.replace(r#"{"b": {"t": [1, 0, 0], "q": [0, 0, 0, 1]}"#, r#"{"b": {"t": [1, 0, 0], "q": [0, 0, 0, 2]}"#),
            |e| matches!(e, Error::BadPose { place, .. } if place == "frame 2, body 'b'"),
            "frame 2",
        ),
        (
            SCENE.replace("meshes/ball.stl", "meshes/missing.stl"),
            |e| matches!(e, Error::Io { path, .. } if path.ends_with("missing.stl")),
            "missing.stl",
        ),
        (
            SCENE.replace(r#"{},"#, r#"{"floor": {"t": [0, 0, 0], "q": [0, 0, 0, 1]}},"#),
            |e| matches!(e, Error::StaticBodyMoves { name, place, .. } if name == "floor" && place == "frame 1"),
            "static",
        ),
        (
            SCENE.replace(r#"{},"#, r#"{"a": {"t": [0, 0, 0], "q": [0, 0, 0, 1]}, "a": {"t": [0, 0, 1], "q": [0, 0, 0, 1]}},"#),
            |e| matches!(e, Error::Parse { location: Location::LineColumn(10, _), .. }),
            "twice",
        ),
        (
            SCENE.replace(r#""static": true"#, r#""statc": true"#),
            |e| matches!(e, Error::Parse { location: Location::LineColumn(3, _), .. }),
            "statc",
        ),
        (
            SCENE.replace("\"exclude\"", "\"exclude\" ,,"),
            |e| matches!(e, Error::Parse { location: Location::LineColumn(7, _), .. }),
            "line 7",
        ),
        (
            SCENE.replace(r#"[1, 0, 0]"#, r#"[1e999, 0, 0]"#),
            |e| matches!(e, Error::Parse { location: Location::LineColumn(11, _), .. }),
            "line 11",
        ),
    ];
    for (k, (text, check, needle)) in cases.into_iter().enumerate() {
        let path = write(&dir, &format!("bad{k}.json"), &text);
        let e = Scene::load(&path).expect_err(&format!("case {k} should fail"));
        assert!(check(&e), "case {k}: {e:?}");
        let msg = e.to_string();
        assert!(msg.contains(needle), "case {k}: {msg}");
        if !matches!(e, Error::Io { .. }) {
            assert!(msg.contains(&format!("bad{k}.json")), "case {k}: {msg}");
        }
    }
}

#[test]
fn trajectory_errors_name_the_line() {
    let dir = temp_dir("badcsv");
    let scene = write(&dir, "scene.json", SCENE);
    let h = "frame,body,x,y,z,qx,qy,qz,qw\n";
    let cases: Vec<(String, usize, &str)> = vec![
        (
            format!("{h}5,a,0,0,0,0,0,0,1\n1,a,0,zero,0,0,0,0,1\n"),
            3,
            "column 'y'",
        ),
        (
            format!("{h}5,a,0,0,0,0,0,0,1\n-1,a,0,0,0,0,0,0,1\n"),
            3,
            "frame",
        ),
        (format!("{h}5,a,0,0,0,0,0,0,1\n\n1,a,0,0,0\n"), 4, "fields"),
        (
            format!("{h}5,a,0,0,0,0,0,0,1\n2,zz,0,0,0,0,0,0,1\n"),
            3,
            "unknown body 'zz'",
        ),
        (
            format!("{h}5,a,0,0,0,0,0,0,1\n2,a,0,NaN,0,0,0,0,1\n"),
            3,
            "not finite",
        ),
        (
            format!("{h}5,a,0,0,0,0,0,0,1\n2,a,0,0,0,0,0,0,0.9\n"),
            3,
            "length",
        ),
        (
            format!("{h}5,a,0,0,0,0,0,0,1\n5,a,0,0,0,0,0,0,1\n"),
            3,
            "already given",
        ),
        (format!("{h}0,floor,0,0,0,0,0,0,1\n"), 2, "static"),
        ("frame,body,x,y,z\n0,a,0,0,0\n".to_owned(), 1, "header"),
    ];
    for (k, (text, line, needle)) in cases.into_iter().enumerate() {
        let csv = write(&dir, &format!("t{k}.csv"), &text);
        let e = Scene::load_with_trajectory(&scene, &csv).expect_err(&format!("case {k}"));
        let msg = e.to_string();
        assert!(msg.contains(&format!("t{k}.csv")), "case {k}: {msg}");
        assert!(msg.contains(&format!("line {line}")), "case {k}: {msg}");
        assert!(msg.contains(needle), "case {k}: {msg}");
    }
}

#[test]
fn scene_file_and_trajectory_round_trip() {
    let dir = temp_dir("roundtrip");
    let spec: SceneFile = serde_json::from_str(SCENE).unwrap();
    let path = dir.join("again.json");
    spec.write(&path).unwrap();
    assert_eq!(SceneFile::read(&path).unwrap(), spec);
    let pose = Pose {
        translation: DVec3::new(12.345678, -0.001, 0.46),
        rotation: DQuat::from_rotation_z(0.003),
    };
    let t = Trajectory {
        path: dir.join("t.csv"),
        rows: vec![frcd_io::TrajectoryRow {
            frame: 7,
            body: "a".into(),
            pose,
            line: 0,
        }],
    };
    t.write(&t.path).unwrap();
    let back = Trajectory::load(&t.path).unwrap();
    assert_eq!(back.rows[0].frame, 7);
    assert_eq!(back.rows[0].line, 2);
    assert_eq!(back.rows[0].pose.translation, pose.translation);
    assert!(back.rows[0].pose.rotation.abs_diff_eq(pose.rotation, 1e-16));
}

#[test]
fn report_json_csv_and_summary() {
    let mut r = Report::new("cpu", "exact");
    r.scene = Some("scene.json".into());
    for index in 0..6 {
        let mut interferences = Vec::new();
        if (1..=2).contains(&index) || index == 4 {
            interferences.push(Interference {
                a: "brake, left".into(),
                b: "wheel".into(),
                triangle_pairs: index as u64,
                contained: false,
                segments: vec![],
                triangles: vec![[0, 1]],
            });
        }
        if index == 5 {
            interferences.push(Interference {
                a: "x".into(),
                b: "y".into(),
                triangle_pairs: 0,
                contained: true,
                segments: vec![[[0.0; 3], [1.0, 0.0, 0.0]]],
                triangles: vec![],
            });
        }
        r.frames.push(FrameReport {
            index,
            time_us: 100.0 + index as f64,
            interferences,
        });
    }
    r.summarize();
    assert_eq!(r.pairs.len(), 2);
    assert_eq!(
        (
            r.pairs[0].first_frame,
            r.pairs[0].last_frame,
            r.pairs[0].frames
        ),
        (1, 4, 3)
    );
    assert_eq!(r.pairs[0].intervals, vec![[1, 2], [4, 4]]);
    assert_eq!(r.pairs[0].max_triangle_pairs, 4);
    assert_eq!(r.median_time_us(), Some(103.0));
    let json: serde_json::Value = serde_json::from_str(&r.to_json_string()).unwrap();
    for key in ["backend", "mode", "frames"] {
        assert!(json.get(key).is_some());
    }
    let f1 = &json["frames"][1];
    assert_eq!(f1["index"], 1);
    assert_eq!(f1["interferences"][0]["triangle_pairs"], 1);
    assert_eq!(f1["interferences"][0]["contained"], false);
    assert!(f1["interferences"][0].get("segments").is_none());
    let dir = temp_dir("report");
    r.write_json(dir.join("r.json")).unwrap();
    assert_eq!(Report::read_json(dir.join("r.json")).unwrap(), r);
    let csv = r.to_csv_string();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines[0], "frame,time_us,a,b,triangle_pairs,contained");
    assert_eq!(lines[1], "0,100,,,0,false");
    assert_eq!(lines[2], "1,101,\"brake, left\",wheel,1,false");
    assert_eq!(lines.last(), Some(&"5,105,x,y,0,true"));
}

#[test]
fn loaded_types_are_send_and_sync() {
    fn check<T: Send + Sync>() {}
    check::<Scene>();
    check::<Report>();
    check::<Trajectory>();
    check::<Error>();
}
