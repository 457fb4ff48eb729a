//! The checker on frcd-obb's World: state ownership, clearance against the oracle, software
//! adapters costed as software, thread pools.

use frcd_geom::{DQuat, DVec3, Pose, TriMesh, shapes};
use frcd_hybrid::{BodySpec, Checker, FrameState, HybridError, Options};
use frcd_obb::oracle;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::sync::Arc;

fn bodies(meshes: &[Arc<TriMesh>], n: usize) -> Vec<BodySpec> {
    (0..n)
        .map(|i| BodySpec {
            name: format!("b{i}"),
            mesh: meshes[i % meshes.len()].clone(),
            is_static: i == 0,
        })
        .collect()
}

fn poses(rng: &mut StdRng, n: usize, spread: f64) -> Vec<Pose> {
    (0..n)
        .map(|_| {
            let axis = DVec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
            .normalize_or(DVec3::X);
            Pose::new(
                DVec3::new(
                    rng.random_range(-spread..spread),
                    rng.random_range(-spread..spread),
                    rng.random_range(-spread..spread),
                ),
                DQuat::from_axis_angle(axis, rng.random_range(0.0..6.3)),
            )
        })
        .collect()
}

#[test]
fn a_state_belongs_to_one_checker() {
    let m = vec![Arc::new(shapes::icosphere(1.0, 1))];
    let a = Checker::new(bodies(&m, 3), &[], Options::default()).unwrap();
    let b = Checker::new(bodies(&m, 3), &[], Options::default()).unwrap();
    let p = poses(&mut StdRng::seed_from_u64(1), 3, 2.0);
    let mut st = FrameState::default();
    a.check(&p, &mut st).unwrap();
    assert!(matches!(
        b.check(&p, &mut st),
        Err(HybridError::ForeignState)
    ));
    st.reset();
    b.check(&p, &mut st).unwrap();
}

#[test]
fn bad_clearance_is_refused() {
    let m = vec![Arc::new(shapes::icosphere(1.0, 1))];
    for (clearance, pairs) in [
        (Some(-1.0), vec![]),
        (Some(f64::NAN), vec![]),
        (None, vec![((0, 0), 1.0)]),
        (None, vec![((0, 5), 1.0)]),
        (None, vec![((0, 1), -0.5)]),
    ] {
        let o = Options {
            clearance,
            pair_clearances: pairs,
            ..Options::default()
        };
        assert!(matches!(
            Checker::new(bodies(&m, 3), &[], o),
            Err(HybridError::BadClearance { .. })
        ));
    }
}

/// Every pair within the threshold (and only those) with the oracle's distance; interfering
/// pairs at 0 and listed as contacts too; one thread and two give the same frames.
#[test]
fn clearance_matches_the_oracle() {
    let meshes = vec![
        Arc::new(shapes::icosphere(1.0, 1)),
        Arc::new(shapes::cuboid(DVec3::new(1.2, 0.3, 0.3))),
    ];
    let n = 12;
    let t = 0.35;
    let options = Options {
        clearance: Some(t),
        pair_clearances: vec![((1, 2), 2.5)],
        ..Options::default()
    };
    let mut one = Checker::new(bodies(&meshes, n), &[], options.clone()).unwrap();
    one.set_thread_pool(Some(Arc::new(
        rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap(),
    )));
    let mut two = Checker::new(bodies(&meshes, n), &[], options).unwrap();
    two.set_thread_pool(Some(Arc::new(
        rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap(),
    )));
    let mut rng = StdRng::seed_from_u64(9);
    let (mut s1, mut s2) = (FrameState::default(), FrameState::default());
    let (mut close, mut hits) = (0, 0);
    for frame in 0..4 {
        let p = poses(&mut rng, n, 3.0);
        let r = one.check(&p, &mut s1).unwrap();
        let r2 = two.check(&p, &mut s2).unwrap();
        assert_eq!(r.contacts, r2.contacts);
        assert_eq!(r.clearances, r2.clearances);
        let mut expected = Vec::new();
        for i in 0..n {
            for j in i + 1..n {
                let th = if (i, j) == (1, 2) { 2.5 } else { t };
                let (ma, mb) = (&meshes[i % 2], &meshes[j % 2]);
                let hit = oracle::answer(ma, &p[i], mb, &p[j], true).collide();
                let d = oracle::distance(ma, &p[i], mb, &p[j]).distance;
                let inside = if (d - th).abs() < 1e-9 {
                    oracle::within_exact(ma, &p[i], mb, &p[j], th)
                } else {
                    d <= th
                };
                if hit || inside {
                    expected.push((i, j, if hit { 0.0 } else { d }, hit));
                }
            }
        }
        assert_eq!(r.clearances.len(), expected.len(), "frame {frame}");
        for (g, e) in r.clearances.iter().zip(&expected) {
            assert_eq!((g.a, g.b, g.interfering), (e.0, e.1, e.3));
            assert!((g.distance - e.2).abs() < 1e-12, "{g:?} {e:?}");
            if !g.interfering {
                assert!(((g.points[0] - g.points[1]).length() - g.distance).abs() < 1e-9);
            }
            close += 1;
        }
        let contacts: Vec<_> = r.contacts.iter().map(|c| (c.a, c.b)).collect();
        let interfering: Vec<_> = expected
            .iter()
            .filter(|e| e.3)
            .map(|e| (e.0, e.1))
            .collect();
        assert_eq!(contacts, interfering);
        hits += contacts.len();
    }
    assert!(close > hits && hits > 0, "{close} {hits}");
}

/// With the gpgpu feature and a cost model that wants the GPU but was not calibrated on this
/// adapter, a software adapter (lavapipe) is not used by the hybrid backend.
#[cfg(feature = "gpgpu")]
#[test]
fn software_adapters_are_costed_as_software() {
    let Ok(ctx) = frcd_gpgpu::GpuContext::headless() else {
        println!("SKIP: no adapter");
        return;
    };
    if !ctx.is_software() {
        println!("SKIP: a hardware adapter");
        return;
    }
    drop(ctx);
    let m = vec![Arc::new(shapes::icosphere(1.0, 2))];
    let cheap_gpu = frcd_hybrid::CostModel {
        gpu_broad_us: Some(0.0),
        gpu_broad_ns_per_body: Some(0.0),
        gpu_narrow_us: Some(0.0),
        gpu_narrow_ns_per_triangle: Some(0.0),
        ..frcd_hybrid::CostModel::default()
    };
    let o = Options {
        cost: cheap_gpu.clone(),
        ..Options::default()
    };
    let c = Checker::new(bodies(&m, 4), &[], o).unwrap();
    assert!(!c.has_gpgpu(), "{:?}", c.notes());
    assert!(c.notes().iter().any(|n| n.contains("software")));
    // Calibrated on this adapter: used.
    let name = frcd_gpgpu::GpuContext::headless()
        .unwrap()
        .adapter_info()
        .name
        .clone();
    let o = Options {
        cost: frcd_hybrid::CostModel {
            adapter: name,
            ..cheap_gpu
        },
        ..Options::default()
    };
    let c = Checker::new(bodies(&m, 4), &[], o).unwrap();
    assert!(c.has_gpgpu(), "{:?}", c.notes());
}
