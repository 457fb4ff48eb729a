//! The generated bogie demo (testdata/bogie, `cargo xtask gen-bogie`) loads with this crate, and
//! its documented interference schedule holds under the brute-force exact oracle.

use frcd_io::{Report, Scene};
use std::path::PathBuf;
use std::sync::Arc;

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../testdata/bogie")
}

fn load() -> Option<Scene> {
    let path = dir().join("scene.json");
    if !path.exists() {
        eprintln!(
            "SKIP: {} absent (run `cargo xtask gen-bogie`)",
            path.display()
        );
        return None;
    }
    Some(Scene::load(&path).unwrap_or_else(|e| panic!("{e}")))
}

#[test]
fn bogie_scene_loads() {
    let Some(s) = load() else { return };
    assert_eq!(s.frame_count(), 2001);
    assert_eq!(s.bodies().len(), 19);
    let track = s.body_index("track").unwrap();
    assert!(s.bodies()[track].is_static);
    let (w1, w2) = (
        s.body_index("wheelset_1").unwrap(),
        s.body_index("wheelset_2").unwrap(),
    );
    assert!(Arc::ptr_eq(&s.bodies()[w1].mesh, &s.bodies()[w2].mesh));
    assert!(s.is_excluded(w1, track));
    for m in s.meshes() {
        assert!(m.topology().is_closed_oriented_manifold());
        assert!(m.report().degenerate.is_empty());
    }
    // Frame 0 repeats the initial poses; every later frame moves every body but the track.
    assert!(s.frame(0).moved.is_empty());
    for f in s.frames().iter().skip(1) {
        assert_eq!(f.moved.len(), 18);
        assert!(!f.moved.contains(&track));
    }
    // 1 kHz at 25 m/s: 25 mm per frame along the track.
    let d = s.frame(1).poses[w1].translation - s.frame(0).poses[w1].translation;
    assert!((d.length() - 0.025).abs() < 1e-4, "{d}");
}

/// Frames inside and just outside every documented interval, checked with the oracle.
#[test]
fn bogie_schedule_matches_the_oracle() {
    let Some(s) = load() else { return };
    let expected = Report::read_json(dir().join("expected_interference.json")).unwrap();
    assert!(expected.pairs.len() >= 3, "the demo must really interfere");
    let oracle = |frame: usize, a: &str, b: &str| {
        let (i, j) = (s.body_index(a).unwrap(), s.body_index(b).unwrap());
        let f = &s.frame(frame);
        let (bi, bj) = (&s.bodies()[i], &s.bodies()[j]);
        frcd_obb::oracle::answer(&bi.mesh, &f.poses[i], &bj.mesh, &f.poses[j], true)
    };
    for p in &expected.pairs {
        for iv in &p.intervals {
            let mid = (iv[0] + iv[1]) / 2;
            let o = oracle(mid, &p.a, &p.b);
            assert!(o.collide(), "{} × {} at frame {mid}", p.a, p.b);
            if iv[0] > 0 {
                assert!(
                    !oracle(iv[0] - 1, &p.a, &p.b).collide(),
                    "{} × {} before {}",
                    p.a,
                    p.b,
                    iv[0]
                );
            }
            assert!(oracle(iv[0], &p.a, &p.b).collide());
        }
    }
    // The inner side bearer never closes; the outer one does in the full curve.
    assert!(!oracle(2000, "side_bearer_L", "car_body").collide());
    assert!(oracle(2000, "side_bearer_R", "car_body").collide());
}
