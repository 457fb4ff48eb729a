//! The scheduler against the brute-force exact oracle on generated many-body scenes.

use frcd_geom::{DQuat, DVec3, Pose, TriMesh, shapes};
use frcd_hybrid::{
    Accuracy, Backend, BodySpec, Checker, CostModel, FrameState, GpuPolicy, HybridError, Options,
    Stage, StageBackend, Via,
};
use frcd_obb::oracle;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::sync::Arc;

/// A cuboid with one triangle removed: an open mesh (no solid, no image space).
fn open_box() -> TriMesh {
    let c = shapes::cuboid(DVec3::new(0.6, 0.4, 0.3));
    let idx: Vec<[u32; 3]> = c.indices()[1..].to_vec();
    TriMesh::new(c.vertices().to_vec(), idx).expect("valid open mesh")
}

struct GenScene {
    bodies: Vec<BodySpec>,
    exclude: Vec<(usize, usize)>,
    frames: Vec<Vec<Pose>>,
}

/// `n` bodies of four kinds in a box sized so that a fair share of pairs overlap, moving
/// coherently for `frames` frames; body 0 is a static big sphere that holds a small sphere
/// (body 1, static too but excluded from nothing) in frame 0; one pair is excluded.
fn scene(seed: u64, n: usize, frames: usize, with_open: bool) -> GenScene {
    let mut rng = StdRng::seed_from_u64(seed);
    let sphere = Arc::new(shapes::icosphere(1.0, 2));
    let small = Arc::new(shapes::icosphere(0.2, 1));
    let cube = Arc::new(shapes::cuboid(DVec3::new(0.7, 0.5, 0.4)));
    let torus = Arc::new(shapes::torus(0.8, 0.25, 16, 8).expect("torus"));
    let open = Arc::new(open_box());
    let mut bodies = vec![
        BodySpec {
            name: "big".into(),
            mesh: sphere.clone(),
            is_static: true,
        },
        BodySpec {
            name: "inner".into(),
            mesh: small,
            is_static: false,
        },
    ];
    for i in 2..n {
        let mesh = match i % 4 {
            0 => sphere.clone(),
            1 => cube.clone(),
            2 => torus.clone(),
            _ if with_open => open.clone(),
            _ => cube.clone(),
        };
        bodies.push(BodySpec {
            name: format!("body{i}"),
            mesh,
            is_static: i % 7 == 0,
        });
    }
    let side = (n as f64).cbrt() * 1.6;
    let mut pos: Vec<DVec3> = (0..n)
        .map(|_| DVec3::new(rng.random(), rng.random(), rng.random()) * side)
        .collect();
    pos[0] = DVec3::splat(side / 2.0);
    pos[1] = pos[0] + DVec3::new(0.1, 0.0, 0.0);
    let axes: Vec<DVec3> = (0..n)
        .map(|_| {
            DVec3::new(
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() + 0.1,
            )
            .normalize()
        })
        .collect();
    let vel: Vec<DVec3> = (0..n)
        .map(|_| {
            DVec3::new(
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() - 0.5,
            ) * 0.15
        })
        .collect();
    let mut out = Vec::new();
    for f in 0..frames {
        let poses = (0..n)
            .map(|i| {
                if bodies[i].is_static {
                    Pose::from_translation(pos[i])
                } else {
                    let t = pos[i] + vel[i] * f as f64 * if i == 1 { 8.0 } else { 1.0 };
                    Pose::new(
                        t,
                        DQuat::from_axis_angle(axes[i], 0.3 * f as f64 + i as f64),
                    )
                }
            })
            .collect();
        out.push(poses);
    }
    pos.clear();
    GenScene {
        bodies,
        exclude: vec![(2, 3)],
        frames: out,
    }
}

/// The oracle's interfering pairs `(a, b, pairs, contained)` of one frame.
type Truth = Vec<(usize, usize, Vec<(u32, u32)>, bool)>;

/// A frame's answer in the oracle's form.
fn answer_of(r: &frcd_hybrid::FrameResult) -> Truth {
    r.contacts
        .iter()
        .map(|c| (c.a, c.b, c.pairs.clone(), c.contained.is_some()))
        .collect()
}

fn truth(s: &GenScene, poses: &[Pose]) -> Truth {
    let mut out = Vec::new();
    for a in 0..s.bodies.len() {
        for b in a + 1..s.bodies.len() {
            if (s.bodies[a].is_static && s.bodies[b].is_static) || s.exclude.contains(&(a, b)) {
                continue;
            }
            let ans = oracle::answer(
                &s.bodies[a].mesh,
                &poses[a],
                &s.bodies[b].mesh,
                &poses[b],
                true,
            );
            if ans.collide() {
                out.push((a, b, ans.pairs, ans.contained.is_some()));
            }
        }
    }
    out
}

fn run(s: &GenScene, options: Options) -> Result<(Vec<Truth>, Vec<Truth>, Checker), HybridError> {
    let checker = Checker::new(s.bodies.clone(), &s.exclude, options)?;
    let mut state = FrameState::default();
    let mut got = Vec::new();
    let mut want = Vec::new();
    for poses in &s.frames {
        let r = checker.check(poses, &mut state)?;
        got.push(answer_of(&r));
        want.push(truth(s, poses));
    }
    Ok((want, got, checker))
}

fn gpu_required() -> bool {
    std::env::var("FRCD_REQUIRE_GPU").is_ok_and(|v| v == "1")
}

#[test]
fn exact_cpu_equals_oracle() {
    for (seed, with_open) in [(1, false), (2, true), (3, true)] {
        let s = scene(seed, 24, 6, with_open);
        let options = Options {
            backend: Backend::Cpu,
            ..Options::default()
        };
        let (want, got, _) = run(&s, options).expect("cpu never fails");
        let hits: usize = want.iter().map(Vec::len).sum();
        assert!(
            hits > 10,
            "scene {seed} has too few interferences ({hits}) to test much"
        );
        assert!(
            want[0].iter().any(|t| t.0 == 0 && t.1 == 1 && t.3),
            "containment case present"
        );
        assert_eq!(want, got, "seed {seed}");
    }
}

#[test]
fn exact_hybrid_default_equals_oracle_and_reuses_unchanged_pairs() {
    let s = scene(4, 30, 5, true);
    let (want, got, checker) = run(&s, Options::default()).unwrap();
    assert_eq!(want, got);
    // Same poses twice: every pair answered from last frame, same answer.
    let mut state = FrameState::default();
    let first = checker.check(&s.frames[0], &mut state).unwrap();
    let again = checker.check(&s.frames[0], &mut state).unwrap();
    assert_eq!(again.reused, again.rcs);
    assert!(again.contacts.iter().all(|c| c.via == Via::Reused));
    let strip = |r: &frcd_hybrid::FrameResult| {
        r.contacts
            .iter()
            .map(|c| (c.a, c.b, c.pairs.clone(), c.contained))
            .collect::<Vec<_>>()
    };
    assert_eq!(strip(&first), strip(&again));
}

#[test]
fn segments_match_pairs() {
    let s = scene(5, 12, 2, false);
    let checker = Checker::new(
        s.bodies.clone(),
        &s.exclude,
        Options {
            segments: true,
            ..Options::default()
        },
    )
    .unwrap();
    let r = checker
        .check(&s.frames[1], &mut FrameState::default())
        .unwrap();
    assert!(!r.contacts.is_empty());
    for c in &r.contacts {
        assert_eq!(c.segments.len(), c.pairs.len());
        assert!(c.segments.iter().all(Option::is_some));
    }
}

#[test]
fn nothing_runs_without_box_overlap() {
    let ball = Arc::new(shapes::icosphere(1.0, 1));
    let bodies: Vec<BodySpec> = (0..5)
        .map(|i| BodySpec {
            name: format!("b{i}"),
            mesh: ball.clone(),
            is_static: false,
        })
        .collect();
    let poses: Vec<Pose> = (0..5)
        .map(|i| Pose::from_translation(DVec3::new(3.0 * i as f64, 0.0, 0.0)))
        .collect();
    let checker = Checker::new(bodies, &[], Options::default()).unwrap();
    assert!(
        !checker.has_gpgpu() && !checker.has_image(),
        "a 5-body scene needs no GPU"
    );
    let r = checker.check(&poses, &mut FrameState::default()).unwrap();
    assert_eq!(r.rcs, 0);
    assert!(r.contacts.is_empty());
    assert_eq!(r.stages[0].backend, StageBackend::Cpu);
    assert_eq!(r.stages[1].stage, Stage::Image);
    assert_eq!(r.stages[1].backend, StageBackend::Skipped);
    assert_eq!(r.stages[2].backend, StageBackend::Skipped);
}

#[test]
fn bad_input_is_a_typed_error() {
    let s = scene(6, 6, 1, false);
    assert!(matches!(
        Checker::new(s.bodies.clone(), &[(0, 9)], Options::default()),
        Err(HybridError::BadExclusion { b: 9, .. })
    ));
    let fast_image_exact = Options {
        backend: Backend::Image,
        mode: Accuracy::Exact,
        ..Options::default()
    };
    let e = Checker::new(s.bodies.clone(), &[], fast_image_exact).unwrap_err();
    assert!(
        matches!(
            e,
            HybridError::ImageNeedsFast | HybridError::FeatureDisabled { .. }
        ),
        "{e}"
    );
    let checker = Checker::new(s.bodies.clone(), &[], Options::default()).unwrap();
    let mut st = FrameState::default();
    assert!(matches!(
        checker.check(&s.frames[0][..3], &mut st),
        Err(HybridError::PoseCount {
            expected: 6,
            got: 3
        })
    ));
    let mut poses = s.frames[0].clone();
    poses[4].translation.y = f64::NAN;
    let e = checker.check(&poses, &mut st).unwrap_err();
    assert!(e.to_string().contains("body4"), "{e}");
}

/// GPU backends on the software adapter; SKIP without an adapter unless FRCD_REQUIRE_GPU=1.
#[test]
fn exact_gpgpu_and_gpu_heavy_hybrid_equal_oracle() {
    let s = scene(7, 20, 3, true);
    let forced = Options {
        backend: Backend::Gpgpu,
        gpu: GpuPolicy::Require,
        ..Options::default()
    };
    if !cfg!(feature = "gpgpu") {
        let e = Checker::new(s.bodies.clone(), &s.exclude, forced).unwrap_err();
        assert!(
            matches!(
                e,
                HybridError::FeatureDisabled {
                    feature: "gpgpu",
                    ..
                }
            ),
            "{e}"
        );
        println!("SKIP exact_gpgpu: built without the 'gpgpu' feature");
        return;
    }
    let (want, got, checker) = match run(&s, forced.clone()) {
        Err(HybridError::Gpu {
            source: message, ..
        }) if !gpu_required() => {
            println!("SKIP exact_gpgpu: no GPU adapter ({message})");
            return;
        }
        other => other.expect("gpgpu backend"),
    };
    assert!(checker.has_gpgpu());
    assert_eq!(want, got);
    // The box pass on the CPU below `gpgpu_box_pass_min_bodies` (by default for this scene's
    // bodies) and on the GPU from it: the answers of the oracle, and each frame reports where
    // its box pass ran.
    let n = s.bodies.len();
    for (min, backend) in [
        (forced.gpgpu_box_pass_min_bodies, StageBackend::Cpu),
        (n, StageBackend::Gpu),
        (n + 1, StageBackend::Cpu),
        (0, StageBackend::Gpu),
    ] {
        let options = Options {
            gpgpu_box_pass_min_bodies: min,
            ..forced.clone()
        };
        let checker = Checker::new(s.bodies.clone(), &s.exclude, options).unwrap();
        let mut st = FrameState::default();
        for poses in &s.frames {
            let r = checker.check(poses, &mut st).unwrap();
            assert_eq!(
                r.stages[0].backend, backend,
                "box pass from {min} of {n} bodies"
            );
            assert_eq!(
                answer_of(&r),
                truth(&s, poses),
                "box pass from {min} bodies"
            );
        }
    }
    // The GPU's own trees (leaves of 2 by default) or the collision trees (leaves of 4): the
    // same answers.
    let (want, got, _) = run(
        &s,
        Options {
            gpu_build: None,
            ..forced.clone()
        },
    )
    .expect("gpgpu backend on the collision trees");
    assert_eq!(want, got);
    // The GPU from the roots (no CPU front) and the CPU down to the leaves: the same answers.
    for front in [0, u32::MAX] {
        let (want, got, _) = run(
            &s,
            Options {
                gpu_host_front: Some(front),
                ..forced.clone()
            },
        )
        .expect("gpgpu backend");
        assert_eq!(want, got, "CPU front of {front} box tests per level");
    }
    // The level chain (one dispatch per level, the default on hardware) and the one-pass
    // traversal in several workgroups (the default on software adapters): the same answers.
    for workgroups in [0, 1, 3] {
        let (want, got, _) = run(
            &s,
            Options {
                gpu_one_pass: Some(workgroups),
                ..forced.clone()
            },
        )
        .expect("gpgpu backend");
        assert_eq!(want, got, "one pass of {workgroups} workgroups");
    }
    // Only the pairs the GPU left uncertain re-decided on the CPU: the same answers.
    let (want, got, _) = run(
        &s,
        Options {
            gpu_recheck_certified: false,
            ..forced.clone()
        },
    )
    .expect("gpgpu backend");
    assert_eq!(want, got, "touching verdicts taken from the GPU");
    // A cost model in which the GPU is free: hybrid puts broad and narrow phase on it.
    let cheap_gpu = CostModel {
        gpu_broad_us: Some(0.0),
        gpu_broad_ns_per_body: Some(0.0),
        gpu_narrow_us: Some(0.0),
        gpu_narrow_ns_per_triangle: Some(0.0),
        ..CostModel::default()
    };
    let options = Options {
        cost: cheap_gpu,
        gpu: GpuPolicy::Require,
        ..Options::default()
    };
    let checker = Checker::new(s.bodies.clone(), &s.exclude, options).unwrap();
    let mut st = FrameState::default();
    for poses in &s.frames {
        let r = checker.check(poses, &mut st).unwrap();
        assert_eq!(r.stages[0].backend, StageBackend::Gpu);
        assert!(r.contacts.iter().all(|c| c.via == Via::Gpu));
        assert_eq!(answer_of(&r), truth(&s, poses));
    }
}

/// A checker on the caller's device (an engine's own, `Checker::with_device`): its GPU stages
/// run there, on the GPGPU backend (exact) and the image backend (fast), with the answers of
/// the oracle; a device too small for the GPGPU stage is refused where a headless checker of
/// the same options runs, so the stage really is on the device given.
#[cfg(feature = "gpgpu")]
#[test]
fn a_checker_on_the_callers_device_runs_there() {
    use frcd_hybrid::GpuDevice;
    let s = scene(11, 12, 3, true);
    // An engine on Vulkan, Metal or D3D12 (image space refuses GL).
    let adapter = match frcd_gpu::request_adapter(&frcd_gpu::AdapterOptions {
        backends: Some(wgpu::Backends::PRIMARY),
        ..Default::default()
    }) {
        Ok(a) => a,
        Err(e) if !gpu_required() => {
            println!("SKIP a_checker_on_the_callers_device_runs_there: no GPU adapter ({e})");
            return;
        }
        Err(e) => panic!("{e}"),
    };
    // The engine asks for every limit the adapter has and the features the image stage needs.
    let features = adapter.features() & wgpu::Features::DEPTH32FLOAT_STENCIL8;
    let (device, queue) =
        frcd_gpu::request_device(&adapter, "engine", features, adapter.limits()).expect("device");
    let engine = GpuDevice { device, queue };
    let exact = Options {
        backend: Backend::Gpgpu,
        gpu: GpuPolicy::Require,
        ..Options::default()
    };
    let checker = Checker::with_device(s.bodies.clone(), &s.exclude, exact.clone(), engine.clone())
        .expect("the GPGPU backend on the engine's device");
    assert!(checker.has_gpgpu());
    let mut state = FrameState::default();
    for poses in &s.frames {
        let r = checker.check(poses, &mut state).expect("frame");
        assert_eq!(answer_of(&r), truth(&s, poses));
    }
    assert!(checker.gpu_submissions() >= s.frames.len() as u64);
    // Image space (fast mode) on the same device: only true interference reported.
    #[cfg(feature = "image")]
    if features.contains(wgpu::Features::DEPTH32FLOAT_STENCIL8) {
        let fast = Options {
            mode: Accuracy::Fast,
            backend: Backend::Image,
            gpu: GpuPolicy::Require,
            ..Options::default()
        };
        let checker = Checker::with_device(s.bodies.clone(), &s.exclude, fast, engine.clone())
            .expect("the image backend on the engine's device");
        assert!(checker.has_image());
        let mut state = FrameState::default();
        for poses in &s.frames {
            let want = truth(&s, poses);
            let r = checker.check(poses, &mut state).expect("frame");
            for c in &r.contacts {
                assert!(
                    want.iter().any(|w| (w.0, w.1) == (c.a, c.b)),
                    "fast mode reported {}-{}, which do not interfere",
                    c.a,
                    c.b
                );
            }
        }
    }
    // The hybrid backend (GPU not required) costs the caller's device as the adapter it is: a
    // software one is not used for image space unless the cost model was calibrated on it,
    // a hardware one is.
    #[cfg(feature = "image")]
    if features.contains(wgpu::Features::DEPTH32FLOAT_STENCIL8) {
        let software = adapter.get_info().device_type == wgpu::DeviceType::Cpu;
        let fast = Options {
            mode: Accuracy::Fast,
            cost: CostModel {
                image_us: Some(0.0),
                ..CostModel::default()
            },
            ..Options::default()
        };
        let checker = Checker::with_device(s.bodies.clone(), &s.exclude, fast, engine.clone())
            .expect("hybrid backend on the engine's device");
        assert_eq!(checker.has_image(), !software, "{:?}", checker.notes());
        if software {
            assert!(
                checker
                    .notes()
                    .iter()
                    .any(|n| n.contains("software adapter")),
                "{:?}",
                checker.notes()
            );
        }
    }
    // A device with WebGL2's limits (no storage buffers in compute) cannot run the GPGPU stage:
    // refused, though a headless checker of the same options runs.
    let (small, small_queue) = frcd_gpu::request_device(
        &adapter,
        "small engine",
        wgpu::Features::empty(),
        wgpu::Limits::downlevel_webgl2_defaults(),
    )
    .expect("small device");
    let refused = Checker::with_device(
        s.bodies.clone(),
        &s.exclude,
        exact.clone(),
        GpuDevice {
            device: small,
            queue: small_queue,
        },
    )
    .unwrap_err();
    assert!(
        matches!(refused, HybridError::Gpu { stage: "gpgpu", .. }),
        "{refused}"
    );
    assert!(Checker::new(s.bodies.clone(), &s.exclude, exact).is_ok());
}

/// Fast mode: everything reported is true; deep interference is found.
#[test]
fn fast_mode_reports_only_true_interference() {
    let s = scene(8, 16, 3, true);
    let options = Options {
        mode: Accuracy::Fast,
        backend: Backend::Image,
        gpu: GpuPolicy::Require,
        ..Options::default()
    };
    if !cfg!(feature = "image") {
        let e = Checker::new(s.bodies.clone(), &s.exclude, options).unwrap_err();
        assert!(
            matches!(
                e,
                HybridError::FeatureDisabled {
                    feature: "image",
                    ..
                }
            ),
            "{e}"
        );
        println!("SKIP fast_mode: built without the 'image' feature");
        return;
    }
    let (want, got, checker) = match run(&s, options) {
        Err(HybridError::Gpu {
            source: message, ..
        }) if !gpu_required() => {
            println!("SKIP fast_mode: no GPU adapter ({message})");
            return;
        }
        other => other.expect("image backend"),
    };
    assert!(checker.has_image());
    let r0 = checker
        .check(&s.frames[0], &mut FrameState::default())
        .unwrap();
    assert_eq!(
        r0.stages[1].backend,
        StageBackend::Gpu,
        "the image stage ran"
    );
    assert!(r0.acs_triangles > 0);
    let mut found = 0;
    for (w, g) in want.iter().zip(&got) {
        for (a, b, pairs, contained) in g {
            let t = w
                .iter()
                .find(|t| t.0 == *a && t.1 == *b)
                .unwrap_or_else(|| {
                    panic!("fast mode reported ({a}, {b}) which does not interfere")
                });
            assert!(pairs.iter().all(|p| t.2.binary_search(p).is_ok()));
            if *contained {
                assert!(t.3);
            }
            found += 1;
        }
    }
    let total: usize = want.iter().map(Vec::len).sum();
    assert!(
        found * 2 >= total,
        "fast mode found only {found} of {total}"
    );
    // The deep containment case (small sphere inside the big one) is found in frame 0.
    assert!(got[0].iter().any(|t| t.0 == 0 && t.1 == 1));
}
