//! Pipelined checking (`Checker::check_pipelined`) against `Checker::check`, frame for frame, on
//! a multi-frame many-body scene: identical answers, one GPU submission per frame, frame k+1
//! submitted before frame k is read. GPU runs SKIP without an adapter unless FRCD_REQUIRE_GPU=1.

use frcd_geom::{DQuat, DVec3, Pose, shapes};
use frcd_hybrid::{
    Backend, BodySpec, Checker, FrameResult, FrameState, GpuPolicy, HybridError, Options, Pipeline,
};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::sync::Arc;

fn gpu_required() -> bool {
    std::env::var("FRCD_REQUIRE_GPU").is_ok_and(|v| v == "1")
}

/// 24 bodies of three kinds moving through each other for 10 frames; frames 4 and 5 repeat
/// frame 3's poses (answers reused), body 0 is static, one pair is excluded.
/// Bodies, excluded pairs, poses per frame.
type Scene = (Vec<BodySpec>, Vec<(usize, usize)>, Vec<Vec<Pose>>);

fn scene() -> Scene {
    let mut rng = StdRng::seed_from_u64(42);
    let meshes = [
        Arc::new(shapes::icosphere(1.0, 2)),
        Arc::new(shapes::cuboid(DVec3::new(0.7, 0.5, 0.4))),
        Arc::new(shapes::torus(0.8, 0.25, 16, 8).expect("torus")),
    ];
    let n = 24;
    let bodies: Vec<BodySpec> = (0..n)
        .map(|i| BodySpec {
            name: format!("body{i}"),
            mesh: meshes[i % 3].clone(),
            is_static: i == 0,
        })
        .collect();
    let side = 4.5;
    let start: Vec<DVec3> = (0..n)
        .map(|_| DVec3::new(rng.random(), rng.random(), rng.random()) * side)
        .collect();
    let vel: Vec<DVec3> = (0..n)
        .map(|i| {
            if i == 0 {
                DVec3::ZERO
            } else {
                DVec3::new(
                    rng.random::<f64>() - 0.5,
                    rng.random::<f64>() - 0.5,
                    rng.random::<f64>() - 0.5,
                ) * 0.6
            }
        })
        .collect();
    let frames = (0..10)
        .map(|f| {
            let t = match f {
                4 | 5 => 3.0,
                _ => f as f64,
            };
            (0..n)
                .map(|i| {
                    Pose::new(
                        start[i] + vel[i] * t,
                        DQuat::from_rotation_z(0.2 * t * (i % 5) as f64),
                    )
                })
                .collect()
        })
        .collect();
    (bodies, vec![(1, 2)], frames)
}

/// Everything of a frame's answer but timings.
fn answer(r: &FrameResult) -> impl PartialEq + std::fmt::Debug {
    (
        r.contacts.clone(),
        r.clearances.clone(),
        r.rcs,
        r.reused,
        r.stages.map(|s| (s.stage, s.backend, s.items)),
        r.notes.clone(),
    )
}

/// Runs the scene with `check` and with `check_pipelined` on two checkers of `options`;
/// returns the two checkers (for their counters) and the number of frames with contacts.
fn compare(options: Options) -> Result<(Checker, Checker, usize), HybridError> {
    compare_in(options, false)
}

/// [`compare`] with the pipeline's order of work ([`Pipeline::set_decide_first`]).
fn compare_in(
    options: Options,
    decide_first: bool,
) -> Result<(Checker, Checker, usize), HybridError> {
    let (bodies, exclude, frames) = scene();
    let plain = Checker::new(bodies.clone(), &exclude, options.clone())?;
    let piped = Checker::new(bodies, &exclude, options)?;
    let mut state = FrameState::default();
    let want: Vec<FrameResult> = frames
        .iter()
        .map(|p| plain.check(p, &mut state))
        .collect::<Result<_, _>>()?;
    let mut pipe = Pipeline::new();
    pipe.set_decide_first(decide_first);
    let mut got = Vec::new();
    for (k, poses) in frames.iter().enumerate() {
        let out = piped.check_pipelined(poses, &mut pipe)?;
        assert_eq!(out.is_none(), k == 0, "one frame of latency");
        assert!(pipe.is_holding());
        got.extend(out);
    }
    got.extend(piped.flush_pipelined(&mut pipe)?);
    assert!(!pipe.is_holding());
    assert!(piped.flush_pipelined(&mut pipe)?.is_none());
    assert_eq!(got.len(), want.len());
    for (k, (w, g)) in want.iter().zip(&got).enumerate() {
        assert_eq!(answer(w), answer(g), "frame {k}");
    }
    let touching = want.iter().filter(|r| !r.contacts.is_empty()).count();
    assert!(
        want.iter().any(|r| r.reused > 0),
        "the repeated frames reuse"
    );
    Ok((plain, piped, touching))
}

#[test]
fn pipelined_equals_plain_on_the_cpu() {
    let options = Options {
        gpu: GpuPolicy::Off,
        clearance: Some(0.2),
        ..Options::default()
    };
    let (_, piped, touching) = compare(options).unwrap();
    assert!(touching >= 5, "{touching}");
    assert_eq!(piped.gpu_submissions(), 0);
}

#[test]
fn pipelined_equals_plain_on_the_gpu() {
    // The box pass on the CPU (the default below 1,024 bodies) and on the GPU.
    let mut submissions = Vec::new();
    for box_pass_min in [1024, 0] {
        let options = Options {
            backend: Backend::Gpgpu,
            gpu: GpuPolicy::Require,
            clearance: Some(0.2),
            gpgpu_box_pass_min_bodies: box_pass_min,
            ..Options::default()
        };
        let (plain, piped, touching) = match compare(options.clone()) {
            Err(HybridError::FeatureDisabled { .. }) => {
                println!("SKIP pipelined GPU: built without the 'gpgpu' feature");
                return;
            }
            Err(HybridError::Gpu { source, .. }) if !gpu_required() => {
                println!("SKIP pipelined GPU: no GPU adapter ({source})");
                return;
            }
            other => other.expect("gpgpu backend"),
        };
        assert!(plain.has_gpgpu() && piped.has_gpgpu());
        assert!(touching >= 5, "{touching}");
        // The same submissions in both modes: per frame one pair batch (and the box pass when
        // it runs on the GPU), submitted ahead of their frame in the pipelined mode (its broad
        // phase runs once per frame, in the look-ahead) and none re-submitted.
        assert!(plain.gpu_submissions() > 0);
        assert_eq!(piped.gpu_submissions(), plain.gpu_submissions());
        submissions.push(plain.gpu_submissions());
        // The other order of a call's work (frame k re-decided before frame k+1's batch is
        // submitted): the same answers and submissions.
        let (plain, piped, _) = compare_in(options, true).expect("gpgpu backend");
        assert_eq!(piped.gpu_submissions(), plain.gpu_submissions());
    }
    // The same pair batches either way; the GPU box pass adds one submission per frame.
    let frames = scene().2.len() as u64;
    assert_eq!(submissions[1], submissions[0] + frames, "{submissions:?}");
}

#[test]
fn a_pipeline_of_another_checker_and_bad_poses_are_refused() {
    let (bodies, exclude, frames) = scene();
    let a = Checker::new(bodies.clone(), &exclude, Options::default()).unwrap();
    let b = Checker::new(bodies, &exclude, Options::default()).unwrap();
    let mut pipe = Pipeline::new();
    assert!(a.check_pipelined(&frames[0], &mut pipe).unwrap().is_none());
    assert!(matches!(
        b.check_pipelined(&frames[1], &mut pipe),
        Err(HybridError::ForeignState)
    ));
    assert!(matches!(
        a.check_pipelined(&frames[1][1..], &mut pipe),
        Err(HybridError::PoseCount { .. })
    ));
    let mut bad = frames[1].clone();
    bad[3].translation.x = f64::NAN;
    assert!(matches!(
        a.check_pipelined(&bad, &mut pipe),
        Err(HybridError::InvalidPose { .. })
    ));
    // The held frame survived the refusals.
    let r = a.flush_pipelined(&mut pipe).unwrap().expect("frame 0 held");
    let want = a.check(&frames[0], &mut FrameState::default()).unwrap();
    assert_eq!(r.contacts, want.contacts);
    pipe.reset();
    assert!(b.check_pipelined(&frames[0], &mut pipe).unwrap().is_none());
}

/// A pair batch the GPU refuses at run time (two bodies whose boxes overlap near the world's
/// origin while their poses are 1.2e11 apart, beyond what frcd-gpgpu accepts in f32: its typed
/// `MagnitudeOutOfRange`): under `GpuPolicy::Auto` both `check` and `check_pipelined` answer
/// every frame on the CPU, equal to the CPU backend's answers, and say so in the frame's notes;
/// under `GpuPolicy::Require` both fail with `HybridError::Gpu` for the pair query, and a
/// pipeline that failed holds no frame.
#[test]
fn a_pair_batch_the_gpu_refuses_falls_back_or_fails_in_both_modes() {
    let far = 6.0e10;
    let cube = shapes::cuboid(DVec3::splat(0.5));
    let at = |x: f64| Pose::from_translation(DVec3::new(x, 0.0, 0.0));
    let bodies = vec![
        BodySpec {
            name: "east".into(),
            mesh: Arc::new(cube.transformed(&at(far))),
            is_static: false,
        },
        BodySpec {
            name: "west".into(),
            mesh: Arc::new(cube.transformed(&at(-far))),
            is_static: false,
        },
    ];
    // East's cube slides past west's at the origin: touching, then apart.
    let frames: Vec<Vec<Pose>> = (0..6)
        .map(|f| vec![at(-far + 0.3 * f as f64), at(far)])
        .collect();
    let cpu = Checker::new(
        bodies.clone(),
        &[],
        Options {
            gpu: GpuPolicy::Off,
            ..Options::default()
        },
    )
    .unwrap();
    let mut state = FrameState::default();
    let want: Vec<_> = frames
        .iter()
        .map(|p| cpu.check(p, &mut state).unwrap().contacts)
        .collect();
    assert!(want.iter().filter(|c| !c.is_empty()).count() >= 3);
    assert!(want.last().unwrap().is_empty());
    let options = |gpu| Options {
        backend: Backend::Gpgpu,
        gpu,
        ..Options::default()
    };
    let auto = match Checker::new(bodies.clone(), &[], options(GpuPolicy::Auto)) {
        Err(HybridError::FeatureDisabled { .. }) => {
            println!("SKIP refused batch: built without the 'gpgpu' feature");
            return;
        }
        other => other.unwrap(),
    };
    if !auto.has_gpgpu() {
        assert!(!gpu_required(), "FRCD_REQUIRE_GPU=1 but no GPGPU device");
        println!("SKIP refused batch: no GPU adapter");
        return;
    }
    let fell_back = |r: &FrameResult| r.notes.iter().any(|n| n.contains("pair query failed"));
    let mut state = FrameState::default();
    for (k, p) in frames.iter().enumerate() {
        let r = auto.check(p, &mut state).unwrap();
        assert_eq!(r.contacts, want[k], "check, frame {k}");
        assert!(!want[k].is_empty() || r.contacts.is_empty());
        if !want[k].is_empty() {
            assert!(fell_back(&r), "check, frame {k}: {:?}", r.notes);
        }
    }
    let mut pipe = Pipeline::new();
    let mut got = Vec::new();
    for p in &frames {
        got.extend(auto.check_pipelined(p, &mut pipe).unwrap());
    }
    got.extend(auto.flush_pipelined(&mut pipe).unwrap());
    assert_eq!(got.len(), frames.len());
    for (k, r) in got.iter().enumerate() {
        assert_eq!(r.contacts, want[k], "check_pipelined, frame {k}");
        if !want[k].is_empty() {
            assert!(fell_back(r), "check_pipelined, frame {k}: {:?}", r.notes);
        }
    }
    let required = Checker::new(bodies, &[], options(GpuPolicy::Require)).unwrap();
    let is_pair_query = |e: &HybridError| {
        matches!(
            e,
            HybridError::Gpu {
                stage: "pair query",
                ..
            }
        )
    };
    let e = required
        .check(&frames[0], &mut FrameState::default())
        .unwrap_err();
    assert!(is_pair_query(&e), "{e}");
    let mut pipe = Pipeline::new();
    let e = required.check_pipelined(&frames[0], &mut pipe).unwrap_err();
    assert!(is_pair_query(&e), "{e}");
    assert!(!pipe.is_holding());
    assert!(required.flush_pipelined(&mut pipe).unwrap().is_none());
}
