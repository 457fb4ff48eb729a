//! The shader-variant measurement hook (`SHADER_VARIANT_ENV`): a context built while it names
//! a variant compiles its pipelines with that `VARIANT` and, since no shipped code reads it,
//! answers as the oracle does, on both traversals; a value that is not a u32 is variant 0 (a
//! warning), not a failed context. Its own test binary: it sets the process's environment,
//! which no other test of this binary reads meanwhile.

use frcd_geom::shapes;
use frcd_geom::{DQuat, DVec3, Pose};
use frcd_gpgpu::{GpuContext, QueryScratch, SHADER_VARIANT_ENV};
use frcd_obb::{BuildOptions, ObbTree, oracle};

#[test]
fn a_named_variant_builds_and_answers_as_the_oracle() {
    let mesh = shapes::icosphere(1.0, 3);
    let tree = ObbTree::build(&mesh, &BuildOptions::default());
    let pa = Pose::IDENTITY;
    let pb = Pose::new(
        DVec3::new(1.2, 0.3, -0.1),
        DQuat::from_axis_angle(DVec3::new(1.0, 2.0, 3.0).normalize(), 0.7),
    );
    let want = oracle::pairs(&mesh, &pa, &mesh, &pb);
    assert!(!want.is_empty());
    for value in ["7", "not a number"] {
        // SAFETY: this binary's only test; no other thread reads the environment meanwhile.
        unsafe { std::env::set_var(SHADER_VARIANT_ENV, value) };
        let mut ctx = match GpuContext::headless() {
            Ok(c) => c,
            Err(e) => {
                assert!(
                    std::env::var("FRCD_REQUIRE_GPU").map_or(true, |v| v != "1"),
                    "FRCD_REQUIRE_GPU=1 but no usable adapter: {e}"
                );
                println!("SKIP frcd-gpgpu variant test: {e}");
                return;
            }
        };
        let gpu = ctx.upload(&tree).expect("upload");
        for one_pass in [0, 2] {
            ctx.set_one_pass(one_pass);
            let got = ctx
                .collide(&gpu, &pa, &gpu, &pb, &mut QueryScratch::default())
                .expect("query");
            assert_eq!(got.pairs, want, "variant {value:?}, one pass {one_pass}");
        }
    }
    unsafe { std::env::remove_var(SHADER_VARIANT_ENV) };
}
