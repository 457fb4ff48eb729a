//! `set_wide_traversal_isa`: the build it reports is the one queries then run, never one the
//! CPU lacks, and answers stay the oracle's under each (its own process: the override is
//! process-wide).

use frcd_geom::{DQuat, DVec3, Pose, shapes};
use frcd_obb::{BuildOptions, Mode, ObbTree, Request, collide, oracle, set_wide_traversal_isa};

#[test]
fn every_build_that_is_set_runs_and_answers_as_the_oracle() {
    let ma = shapes::torus(1.0, 0.35, 32, 12).expect("valid torus");
    let mb = shapes::icosphere(0.5, 2);
    let opts = BuildOptions::default();
    let (ta, tb) = (ObbTree::build(&ma, &opts), ObbTree::build(&mb, &opts));
    let default = frcd_obb::wide_traversal_isa();
    let mut reference = None;
    for name in ["baseline", "avx2", "avx512", "no such build"] {
        let now = set_wide_traversal_isa(name);
        assert_eq!(now, frcd_obb::wide_traversal_isa());
        match name {
            "baseline" => assert_eq!(now, "baseline"),
            // Taken only where the CPU has it; else the CPU's default build.
            "avx2" | "avx512" => assert!(now == name || now == default, "{name} -> {now}"),
            _ => assert_eq!(now, default, "an unknown name keeps the default"),
        }
        let mut answers = Vec::new();
        for k in 0..24 {
            let s = 0.13 * k as f64;
            let pb = Pose::new(
                DVec3::new(1.0 - 0.9 * s.sin(), 0.1 * s.cos(), 0.05 * k as f64 - 0.6),
                DQuat::from_axis_angle(DVec3::new(0.3, 1.0, 0.2).normalize(), s),
            );
            let req = Request {
                mode: Mode::AllPairs,
                ..Request::default()
            };
            let got = collide(&ta, &Pose::IDENTITY, &tb, &pb, &req);
            assert_eq!(
                got.pairs,
                oracle::pairs(&ma, &Pose::IDENTITY, &mb, &pb),
                "{now} step {k}"
            );
            answers.push((got.pairs, got.counters));
        }
        // Work counters too are the same bits under every build.
        match &reference {
            None => reference = Some(answers),
            Some(r) => assert_eq!(r, &answers, "{now}"),
        }
    }
}
