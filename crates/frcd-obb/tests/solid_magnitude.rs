//! Solid mode at extreme magnitudes (issue 11): a closed box containing another must be reported
//! as containment by the tree query and by the oracle, whatever the (finite) scale.

use frcd_geom::{DQuat, DVec3, Pose, shapes};
use frcd_obb::{BuildOptions, Containment, Mode, ObbTree, Request, collide, oracle};

#[test]
fn containment_is_found_from_1e0_to_1e300() {
    let request = Request {
        mode: Mode::AllPairs,
        solid: true,
        ..Request::default()
    };
    for s in [1.0, 1e100, 1e154, 1e155, 1e200, 1e250, 1e300] {
        let outer = shapes::cuboid(DVec3::splat(s));
        let inner = shapes::icosphere(0.3 * s, 1);
        let (to, ti) = (
            ObbTree::build(&outer, &BuildOptions::default()),
            ObbTree::build(&inner, &BuildOptions::default()),
        );
        let pose_i = Pose::new(
            DVec3::new(0.2 * s, -0.1 * s, 0.05 * s),
            DQuat::from_rotation_y(0.3),
        );
        let want = oracle::answer(&outer, &Pose::IDENTITY, &inner, &pose_i, true);
        assert!(want.pairs.is_empty(), "extent {s:e}: surfaces touch");
        assert_eq!(
            want.contained,
            Some(Containment::BInsideA),
            "oracle at extent {s:e}"
        );
        let got = collide(&to, &Pose::IDENTITY, &ti, &pose_i, &request);
        assert!(got.collide, "tree query at extent {s:e}");
        assert_eq!(got.contained, Some(Containment::BInsideA), "extent {s:e}");
        // And the other way round.
        let got = collide(&ti, &pose_i, &to, &Pose::IDENTITY, &request);
        assert_eq!(got.contained, Some(Containment::AInsideB), "extent {s:e}");
        // Moved out: no interference.
        let away = Pose::from_translation(DVec3::new(3.0 * s, 0.0, 0.0));
        assert!(!collide(&to, &Pose::IDENTITY, &ti, &away, &request).collide);
        assert!(!oracle::answer(&outer, &Pose::IDENTITY, &inner, &away, true).collide());
    }
}
