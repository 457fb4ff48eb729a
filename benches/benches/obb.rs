//! frcd-obb against parry3d (f32) and parry3d-f64 on the same meshes and poses, in one run.
//!
//! ```text
//! cargo bench -p frcd-benches --bench obb -- --warm-up-time 1 --measurement-time 3
//! ```
//!
//! Before timing, every scene is answered once by frcd, by both parrys and by the exact oracle
//! ([`frcd_obb::oracle`]); the agreement is printed (frcd must equal the oracle; parry's
//! differences are reported, not asserted). One criterion iteration = the whole step sequence.
//!
//! - `build/*`: tree construction (frcd OBB tree vs parry's AABB BVH inside `TriMesh::new`);
//! - `spheres_l5`, `spheres_l6` (scene a): two icospheres, 20,480 / 81,920 triangles each, B
//!   sliding through A in 200 steps; FirstContact and AllPairs;
//! - `knots` (scene b): two 49,920-triangle torus knots in near contact, small rotations, 500
//!   steps; FirstContact and AllPairs, with and without the coherence cache;
//! - `sparse_1000` (scene c): every body pair of 1,000 sparse bodies (no broad phase), hybrid
//!   top volume vs root OBB only; `world_10000`: a `World` step loop over 10,000 bodies;
//! - `fit/*`: query time of trees built with each fit rule (the default is the fastest).

use criterion::{Criterion, criterion_group, criterion_main};
use frcd_benches::scenes::{self, Scene};
use frcd_obb::{
    BuildOptions, FitMethod, Mode, ObbTree, PairCache, Request, TopVolume, World, WorldOptions,
    collide, collide_cached, oracle,
};
use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;

macro_rules! parry_backend {
    ($m:ident, $krate:ident, $real:ty) => {
        mod $m {
            use $krate::bounding_volume::BoundingVolume;
            use $krate::math::{Pose, Rotation, Vector};
            use $krate::query::details::intersection_test_support_map_support_map;
            use $krate::shape::TriMesh;

            pub fn mesh(m: &frcd_geom::TriMesh) -> TriMesh {
                let v = m
                    .vertices()
                    .iter()
                    .map(|p| Vector::new(p.x as $real, p.y as $real, p.z as $real))
                    .collect();
                TriMesh::new(v, m.indices().to_vec()).expect("parry accepts the mesh")
            }

            pub fn pose(p: &frcd_geom::Pose) -> Pose {
                let (t, q) = (p.translation, p.rotation);
                Pose::from_parts(
                    Vector::new(t.x as $real, t.y as $real, t.z as $real),
                    Rotation::from_xyzw(q.x as $real, q.y as $real, q.z as $real, q.w as $real)
                        .normalize(),
                )
            }

            /// parry's boolean composite-composite test.
            pub fn first_contact(m1: &TriMesh, p1: &Pose, m2: &TriMesh, p2: &Pose) -> bool {
                $krate::query::intersection_test(p1, m1, p2, m2)
                    .expect("trimesh pairs are supported")
                    .intersecting
            }

            /// Every intersecting triangle pair: parry's simultaneous BVH traversal
            /// (`Bvh::leaf_pairs`, B's boxes mapped into A's frame) and its triangle test (GJK on
            /// support maps), sorted.
            pub fn all_pairs(m1: &TriMesh, p1: &Pose, m2: &TriMesh, p2: &Pose) -> Vec<(u32, u32)> {
                let pos12 = p1.inv_mul(p2);
                let mut out: Vec<(u32, u32)> = m1
                    .bvh()
                    .leaf_pairs(m2.bvh(), |n1, n2| {
                        n1.aabb().intersects(&n2.aabb().transform_by(&pos12))
                    })
                    .filter(|&(i, j)| {
                        intersection_test_support_map_support_map(
                            &pos12,
                            &m1.triangle(i),
                            &m2.triangle(j),
                        )
                    })
                    .collect();
                out.sort_unstable();
                out
            }
        }
    };
}

parry_backend!(p32, parry3d, f32);
parry_backend!(p64, parry3d_f64, f64);

/// Two-body scene prepared for every backend.
struct Pair {
    scene: Scene,
    frcd: [Arc<ObbTree>; 2],
    m32: [parry3d::shape::TriMesh; 2],
    m64: [parry3d_f64::shape::TriMesh; 2],
    poses32: Vec<[parry3d::math::Pose; 2]>,
    poses64: Vec<[parry3d_f64::math::Pose; 2]>,
}

fn prepare(scene: Scene, fit: FitMethod) -> Pair {
    let opts = BuildOptions {
        fit,
        ..BuildOptions::default()
    };
    let tree = |i: usize| Arc::new(ObbTree::build(&scene.bodies[i].mesh, &opts));
    let frcd = [tree(0), tree(1)];
    let m32 = [
        p32::mesh(&scene.bodies[0].mesh),
        p32::mesh(&scene.bodies[1].mesh),
    ];
    let m64 = [
        p64::mesh(&scene.bodies[0].mesh),
        p64::mesh(&scene.bodies[1].mesh),
    ];
    let poses32 = scene
        .frames
        .iter()
        .map(|f| [p32::pose(&f[0]), p32::pose(&f[1])])
        .collect();
    let poses64 = scene
        .frames
        .iter()
        .map(|f| [p64::pose(&f[0]), p64::pose(&f[1])])
        .collect();
    Pair {
        scene,
        frcd,
        m32,
        m64,
        poses32,
        poses64,
    }
}

fn req(mode: Mode) -> Request {
    Request {
        mode,
        ..Request::default()
    }
}

fn frcd_run(p: &Pair, mode: Mode) -> Vec<Vec<(u32, u32)>> {
    let r = req(mode);
    p.scene
        .frames
        .iter()
        .map(|f| {
            let c = collide(&p.frcd[0], &f[0], &p.frcd[1], &f[1], &r);
            match mode {
                Mode::AllPairs => c.pairs,
                Mode::FirstContact => c.witness.into_iter().collect(),
            }
        })
        .collect()
}

/// Agreement of everyone with the oracle, printed once per scene.
fn agreement(p: &Pair) {
    let (ma, mb) = (&p.scene.bodies[0].mesh, &p.scene.bodies[1].mesh);
    let truth: Vec<Vec<(u32, u32)>> = p
        .scene
        .frames
        .iter()
        .map(|f| oracle::pairs(ma, &f[0], mb, &f[1]))
        .collect();
    let all = frcd_run(p, Mode::AllPairs);
    let first = frcd_run(p, Mode::FirstContact);
    let frcd_ok = all == truth
        && first.iter().zip(&truth).all(|(w, t)| {
            w.is_empty() == t.is_empty() && w.iter().all(|x| t.binary_search(x).is_ok())
        });
    assert!(frcd_ok, "{}: frcd differs from the oracle", p.scene.name);
    let touching = truth.iter().filter(|t| !t.is_empty()).count();
    let total: usize = truth.iter().map(|t| t.len()).sum();
    eprintln!(
        "[agreement] {}: {} steps, {} touching, {} pairs in all; frcd == oracle (both modes)",
        p.scene.name,
        truth.len(),
        touching,
        total
    );
    let report = |name: &str, bools: Vec<bool>, pairs: Vec<Vec<(u32, u32)>>| {
        let bool_diff = bools
            .iter()
            .zip(&truth)
            .filter(|(b, t)| **b == t.is_empty())
            .count();
        let (mut missing, mut extra, mut steps) = (0, 0, 0);
        for (g, t) in pairs.iter().zip(&truth) {
            let m = t.iter().filter(|x| g.binary_search(x).is_err()).count();
            let e = g.iter().filter(|x| t.binary_search(x).is_err()).count();
            missing += m;
            extra += e;
            steps += (m + e > 0) as usize;
        }
        eprintln!(
            "[agreement] {}: {name}: first-contact wrong in {bool_diff} steps; all-pairs differs in {steps} steps ({missing} pairs missing, {extra} extra)",
            p.scene.name
        );
    };
    report(
        "parry3d f32",
        p.poses32
            .iter()
            .map(|q| p32::first_contact(&p.m32[0], &q[0], &p.m32[1], &q[1]))
            .collect(),
        p.poses32
            .iter()
            .map(|q| p32::all_pairs(&p.m32[0], &q[0], &p.m32[1], &q[1]))
            .collect(),
    );
    report(
        "parry3d-f64",
        p.poses64
            .iter()
            .map(|q| p64::first_contact(&p.m64[0], &q[0], &p.m64[1], &q[1]))
            .collect(),
        p.poses64
            .iter()
            .map(|q| p64::all_pairs(&p.m64[0], &q[0], &p.m64[1], &q[1]))
            .collect(),
    );
}

fn pair_group(c: &mut Criterion, group: &str, p: &Pair, coherence: bool) {
    let mut g = c.benchmark_group(format!("obb/{group}"));
    g.sample_size(10);
    for (mode, label) in [(Mode::FirstContact, "first"), (Mode::AllPairs, "all")] {
        let r = req(mode);
        g.bench_function(format!("frcd_{label}"), |b| {
            b.iter(|| {
                let mut n = 0usize;
                for f in &p.scene.frames {
                    let c = collide(&p.frcd[0], &f[0], &p.frcd[1], &f[1], &r);
                    n += c.pairs.len() + c.collide as usize;
                }
                black_box(n)
            })
        });
        if coherence {
            g.bench_function(format!("frcd_{label}_cached"), |b| {
                b.iter(|| {
                    let mut cache = PairCache::new();
                    let mut n = 0usize;
                    for f in &p.scene.frames {
                        let c =
                            collide_cached(&p.frcd[0], &f[0], &p.frcd[1], &f[1], &r, &mut cache);
                        n += c.pairs.len() + c.collide as usize;
                    }
                    black_box(n)
                })
            });
        }
        g.bench_function(format!("parry3d_{label}"), |b| {
            b.iter(|| {
                let mut n = 0usize;
                for q in &p.poses32 {
                    n += match mode {
                        Mode::FirstContact => {
                            p32::first_contact(&p.m32[0], &q[0], &p.m32[1], &q[1]) as usize
                        }
                        Mode::AllPairs => p32::all_pairs(&p.m32[0], &q[0], &p.m32[1], &q[1]).len(),
                    };
                }
                black_box(n)
            })
        });
        g.bench_function(format!("parry3d_f64_{label}"), |b| {
            b.iter(|| {
                let mut n = 0usize;
                for q in &p.poses64 {
                    n += match mode {
                        Mode::FirstContact => {
                            p64::first_contact(&p.m64[0], &q[0], &p.m64[1], &q[1]) as usize
                        }
                        Mode::AllPairs => p64::all_pairs(&p.m64[0], &q[0], &p.m64[1], &q[1]).len(),
                    };
                }
                black_box(n)
            })
        });
    }
    g.finish();
}

fn bench_build(c: &mut Criterion) {
    let mut g = c.benchmark_group("obb/build");
    g.sample_size(10);
    let meshes = [
        ("icosphere_20k", frcd_geom::shapes::icosphere(1.0, 5)),
        ("icosphere_80k", frcd_geom::shapes::icosphere(1.0, 6)),
        (
            "knot_50k",
            scenes::torus_knots(1040, 24, 1).bodies[0]
                .mesh
                .as_ref()
                .clone(),
        ),
    ];
    for (name, mesh) in &meshes {
        // Topology is cached in the mesh after its first use (it is the mesh's, not the tree's).
        let _ = mesh.topology();
        g.bench_function(format!("frcd_{name}"), |b| {
            b.iter(|| black_box(ObbTree::build(mesh, &BuildOptions::default())))
        });
        for fit in [FitMethod::AreaWeighted, FitMethod::HullSurface] {
            g.bench_function(format!("frcd_{fit:?}_{name}"), |b| {
                b.iter(|| {
                    black_box(ObbTree::build(
                        mesh,
                        &BuildOptions {
                            fit,
                            ..BuildOptions::default()
                        },
                    ))
                })
            });
        }
        g.bench_function(format!("parry3d_{name}"), |b| {
            b.iter(|| black_box(p32::mesh(mesh)))
        });
        g.bench_function(format!("parry3d_f64_{name}"), |b| {
            b.iter(|| black_box(p64::mesh(mesh)))
        });
    }
    g.finish();
}

fn bench_pairs(c: &mut Criterion) {
    let only = std::env::var("FRCD_BENCH_ONLY").unwrap_or_default();
    let want = |n: &str| only.is_empty() || only.split(',').any(|o| n.contains(o));
    if want("spheres_l5") {
        let p = prepare(scenes::icospheres_sweep(5, 200), FitMethod::default());
        agreement(&p);
        pair_group(c, "spheres_l5", &p, false);
    }
    if want("spheres_l6") {
        let p = prepare(scenes::icospheres_sweep(6, 200), FitMethod::default());
        agreement(&p);
        pair_group(c, "spheres_l6", &p, false);
    }
    if want("knots") {
        let p = prepare(scenes::torus_knots(1040, 24, 500), FitMethod::default());
        agreement(&p);
        pair_group(c, "knots", &p, true);
    }
}

fn bench_fit(c: &mut Criterion) {
    let mut g = c.benchmark_group("obb/fit");
    g.sample_size(10);
    for (name, scene) in [
        ("spheres_l5", scenes::icospheres_sweep(5, 50)),
        ("knots", scenes::torus_knots(1040, 24, 50)),
    ] {
        for fit in [
            FitMethod::VertexCovariance,
            FitMethod::AreaWeighted,
            FitMethod::HullSurface,
        ] {
            let opts = BuildOptions {
                fit,
                ..BuildOptions::default()
            };
            let ta = ObbTree::build(&scene.bodies[0].mesh, &opts);
            let tb = ObbTree::build(&scene.bodies[1].mesh, &opts);
            for (mode, label) in [(Mode::FirstContact, "first"), (Mode::AllPairs, "all")] {
                let r = req(mode);
                g.bench_function(format!("{name}_{label}_{fit:?}"), |b| {
                    b.iter(|| {
                        let mut n = 0;
                        for f in &scene.frames {
                            n += collide(&ta, &f[0], &tb, &f[1], &r).pairs.len();
                        }
                        black_box(n)
                    })
                });
            }
        }
    }
    g.finish();
}

fn bench_sparse(c: &mut Criterion) {
    let mut g = c.benchmark_group("obb/sparse");
    g.sample_size(10);
    // All body pairs of 1,000 bodies, no broad phase: the top volume is the only cull.
    let scene = scenes::sparse(1000, 2, 7);
    let trees: Vec<Arc<ObbTree>> = {
        let mut cache: Vec<(*const frcd_geom::TriMesh, Arc<ObbTree>)> = Vec::new();
        scene
            .bodies
            .iter()
            .map(|b| {
                let key = Arc::as_ptr(&b.mesh);
                if let Some((_, t)) = cache.iter().find(|(k, _)| *k == key) {
                    return t.clone();
                }
                let t = Arc::new(ObbTree::build(&b.mesh, &BuildOptions::default()));
                cache.push((key, t.clone()));
                t
            })
            .collect()
    };
    let pairs = scene.body_pairs();
    for (top, label) in [
        (TopVolume::Hybrid, "hybrid"),
        (TopVolume::RootObb, "root_obb"),
    ] {
        let r = Request {
            top_volume: top,
            ..Request::default()
        };
        g.bench_function(format!("pairs_1000_{label}"), |b| {
            b.iter(|| {
                let f = &scene.frames[0];
                let mut n = 0;
                for &(i, j) in &pairs {
                    n += collide(&trees[i], &f[i], &trees[j], &f[j], &r).collide as usize;
                }
                black_box(n)
            })
        });
    }
    // A World over 10,000 bodies, 10 steps per iteration.
    let big = scenes::sparse(10_000, 10, 11);
    let big_trees: Vec<Arc<ObbTree>> = {
        let t: Vec<Arc<ObbTree>> = (0..3)
            .map(|k| {
                Arc::new(ObbTree::build(
                    &big.bodies[k].mesh,
                    &BuildOptions::default(),
                ))
            })
            .collect();
        (0..big.bodies.len()).map(|i| t[i % 3].clone()).collect()
    };
    for (top, label) in [
        (TopVolume::Hybrid, "hybrid"),
        (TopVolume::RootObb, "root_obb"),
    ] {
        g.bench_function(format!("world_10000_{label}"), |b| {
            b.iter(|| {
                let mut options = WorldOptions::default();
                options.request.top_volume = top;
                let mut w = World::new(options);
                let ids: Vec<_> = big
                    .bodies
                    .iter()
                    .enumerate()
                    .map(|(i, body)| {
                        w.add_body(big_trees[i].clone(), big.frames[0][i], body.is_static)
                            .expect("valid pose")
                    })
                    .collect();
                let mut n = 0;
                for f in &big.frames {
                    for (id, p) in ids.iter().zip(f) {
                        w.set_pose(*id, *p).expect("valid pose");
                    }
                    n += w.step().contacts.len();
                }
                black_box(n)
            })
        });
    }
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(3));
    targets = bench_build, bench_pairs, bench_sparse, bench_fit
}
criterion_main!(benches);
