//! OBB tree construction: frcd's whole `ObbTree::build` against parry3d-f64's `TriMesh::new`
//! (which builds its BVH), on the same meshes, in one run (issue 9: build ≤ 2× parry3d-f64's,
//! one thread), plus the tree-quality counters the build must not make worse.
//!
//! ```text
//! cargo bench -p frcd-benches --bench build -- --warm-up-time 1 --measurement-time 2
//! FRCD_BUILD_QUALITY=0 cargo bench -p frcd-benches --bench build   # ratio lines only
//! FRCD_BUILD_ONLY=fandisk,knot cargo bench -p frcd-benches --bench build   # these meshes only
//! FRCD_BUILD_SPLIT=mean cargo bench -p frcd-benches --bench build   # ratios of SplitMethod::MajorAxisMean
//! ```
//!
//! - `build/ratio` lines: per mesh, the two builds interleaved build by build for about three
//!   seconds (the machine's load moves both alike), medians and their ratio, with the load
//!   average. The allocator couples the two builders: what one frees moves glibc's mmap
//!   threshold, and so the other's page faults (parry3d-f64's icosphere build took 6.2-8.8 ms
//!   depending on the frcd build beside it). Run one mesh per process (`FRCD_BUILD_ONLY`) as
//!   well, and compare frcd's own times between binaries. Meshes: an icosphere of 20,480 triangles, a torus knot of 49,920, and the CAD
//!   meshes of `../shared/meshes` (the intermodal wagon underframe, 18,824 triangles; the bogie
//!   frame, 5,268; the fandisk, 5,750; SKIP when the folder is absent).
//! - `build/quality` lines (unless `FRCD_BUILD_QUALITY=0`): box and triangle tests per query of
//!   the trees on the `dense` (two icospheres sliding through each other, 200 steps),
//!   `knots_near` (two torus knots in near contact, 500 steps) and CAD (the three pairs of
//!   `../shared/meshes` at random poses near first contact, 100 steps each; SKIP when absent)
//!   classes of the `obb` bench, in both modes, and the trees' total box surface: time-free
//!   numbers, identical run to run, so a build change that loosens the trees shows up here
//!   exactly.
//! - criterion rows `build/frcd_*` and `build/parry3d_f64_*`: each build alone.

#[path = "common/cad.rs"]
mod cad;

use criterion::{Criterion, criterion_group, criterion_main};
use frcd_benches::scenes::{self, Scene};
use frcd_benches::thread_cpu;
use frcd_geom::TriMesh;
use frcd_obb::{BuildOptions, Mode, ObbTree, Request, SplitMethod, collide};
use std::hint::black_box;
use std::sync::Arc;
use std::time::{Duration, Instant};

fn parry_mesh(m: &TriMesh) -> parry3d_f64::shape::TriMesh {
    let v = m
        .vertices()
        .iter()
        .map(|p| parry3d_f64::math::Vector::new(p.x, p.y, p.z))
        .collect();
    parry3d_f64::shape::TriMesh::new(v, m.indices().to_vec()).expect("parry accepts the mesh")
}

fn meshes() -> Vec<(String, TriMesh)> {
    let mut out = vec![
        (
            "icosphere_20k".to_string(),
            frcd_geom::shapes::icosphere(1.0, 5),
        ),
        (
            "knot_50k".to_string(),
            scenes::torus_knots(1040, 24, 1).bodies[0]
                .mesh
                .as_ref()
                .clone(),
        ),
    ];
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/meshes");
    for (name, file) in [
        (
            "cad_wagon",
            "railway_3dprintedtrains/intermodal_wagon_no_visible_container_holes_binary.stl",
        ),
        ("cad_bogie", "railway_3dprintedtrains/bogie.stl"),
        ("cad_fandisk", "mechanical_trimesh/fandisk.obj"),
    ] {
        match frcd_io::load_mesh(dir.join(file)) {
            Ok(m) => out.push((format!("{name}_{}", m.triangle_count()), m)),
            Err(e) => eprintln!("SKIP {name}: {file}: {e}"),
        }
    }
    let only = std::env::var("FRCD_BUILD_ONLY").unwrap_or_default();
    out.retain(|(n, _)| only.is_empty() || only.split(',').any(|o| n.contains(o)));
    for (_, m) in &out {
        // Topology is cached in the mesh after its first use (the mesh's, not the tree's).
        let _ = m.topology();
    }
    out
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn load() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "?".into())
}

/// Wall and thread-CPU time of one call.
fn timed<T>(f: impl FnOnce() -> T) -> (f64, Option<f64>) {
    let (c, t) = (thread_cpu(), Instant::now());
    black_box(f());
    let wall = t.elapsed().as_secs_f64();
    (wall, thread_cpu().zip(c).map(|(b, a)| b - a))
}

/// The split rule the ratio lines build with: `FRCD_BUILD_SPLIT=mean` for
/// `SplitMethod::MajorAxisMean`, else the default.
fn split_rule() -> (SplitMethod, &'static str) {
    match std::env::var("FRCD_BUILD_SPLIT").as_deref() {
        Ok("mean") => (SplitMethod::MajorAxisMean, "mean"),
        _ => (SplitMethod::SurfaceCost, "surface"),
    }
}

/// Interleaved medians of the two builds, in wall and in thread-CPU time.
fn ratio(name: &str, mesh: &TriMesh) {
    let (split, rule) = split_rule();
    let opts = BuildOptions {
        split,
        ..BuildOptions::default()
    };
    let (mut f, mut p, mut fc, mut pc) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let end = Instant::now() + Duration::from_secs(3);
    while Instant::now() < end || f.len() < 15 {
        let (w, c) = timed(|| ObbTree::build(mesh, &opts));
        f.push(w);
        fc.extend(c);
        let (w, c) = timed(|| parry_mesh(mesh));
        p.push(w);
        pc.extend(c);
    }
    let n = f.len();
    let (mf, mp) = (median(f), median(p));
    let cpu = if fc.len() == n && pc.len() == n {
        let (cf, cp) = (median(fc), median(pc));
        format!(
            "; thread CPU time: frcd {:.2} ms, parry3d-f64 {:.2} ms: {:.2}x",
            cf * 1e3,
            cp * 1e3,
            cf / cp
        )
    } else {
        String::new()
    };
    println!(
        "build/ratio {name} (split {rule}): wall: frcd {:.2} ms, parry3d-f64 {:.2} ms: {:.2}x{cpu} (medians of {n} interleaved builds, load average {})",
        mf * 1e3,
        mp * 1e3,
        mf / mp,
        load()
    );
}

fn surface(tree: &ObbTree) -> f64 {
    tree.nodes()
        .iter()
        .map(|n| {
            let e = n.obb.half_extents;
            8.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
        })
        .sum()
}

/// Box and triangle tests per query over a two-body scene, both modes.
fn quality(scene: &Scene) {
    let opts = BuildOptions::default();
    let ta = ObbTree::build_shared(scene.bodies[0].mesh.clone(), &opts);
    let tb = ObbTree::build_shared(scene.bodies[1].mesh.clone(), &opts);
    for (mode, label) in [(Mode::FirstContact, "first"), (Mode::AllPairs, "all")] {
        let r = Request {
            mode,
            ..Request::default()
        };
        let (mut boxes, mut tris, mut touching) = (0u64, 0u64, 0usize);
        for f in &scene.frames {
            let c = collide(&ta, &f[0], &tb, &f[1], &r);
            boxes += c.counters.box_tests;
            tris += c.counters.tri_tests;
            touching += c.collide as usize;
        }
        let q = scene.frames.len() as f64;
        println!(
            "build/quality {} {label}: {:.1} box tests, {:.1} triangle tests per query ({} of {} steps touching)",
            scene.name,
            boxes as f64 / q,
            tris as f64 / q,
            touching,
            scene.frames.len()
        );
    }
    println!(
        "build/quality {}: total box surface {:.6} (A), {} nodes, depth {}",
        scene.name,
        surface(&ta),
        ta.node_count(),
        ta.depth()
    );
}

fn bench_build(c: &mut Criterion) {
    let meshes = meshes();
    for (name, mesh) in &meshes {
        ratio(name, mesh);
    }
    if std::env::var("FRCD_BUILD_QUALITY").as_deref() != Ok("0") {
        let mut dense = scenes::icospheres_sweep(5, 200);
        dense.name = format!("dense_{}", dense.name);
        quality(&dense);
        quality(&scenes::knots_near_contact(500));
        // The railway CAD pairs react most to a build change (a sampled binning cost them
        // 20-35 % more box tests where the knots lost 5 %).
        for scene in cad::cad_scenes() {
            quality(&scene);
        }
        for (name, mesh) in &meshes {
            let t = ObbTree::build_shared(Arc::new(mesh.clone()), &BuildOptions::default());
            println!(
                "build/quality {name}: total box surface {:.6}, {} nodes, depth {}",
                surface(&t),
                t.node_count(),
                t.depth()
            );
        }
    }
    let mut g = c.benchmark_group("build");
    g.sample_size(10);
    for (name, mesh) in &meshes {
        g.bench_function(format!("frcd_{name}"), |b| {
            b.iter(|| black_box(ObbTree::build(mesh, &BuildOptions::default())))
        });
        g.bench_function(format!("parry3d_f64_{name}"), |b| {
            b.iter(|| black_box(parry_mesh(mesh)))
        });
    }
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(2));
    targets = bench_build
}
criterion_main!(benches);
