//! `frcd_obb::distance` against parry3d-f64's `query::distance` (trimesh against trimesh), one
//! thread, one run.
//!
//! ```text
//! cargo bench -p frcd-benches --bench distance -- --warm-up-time 1 --measurement-time 3
//! ```
//!
//! Pairs: real CAD parts from `../shared/meshes` (SKIP when absent), each scaled to unit size
//! (bounding-box diagonal 1, centred) as in the issue's PQP measurement, plus a generated pair
//! (icosphere against torus knot) that needs no files. For every pair, 16 random setups (B
//! turned at random, approaching A along a random direction) in three kinds:
//!
//! - `contact`: B moved to first contact along its direction (bisection on `within(0)` to 1e-9),
//!   then 1e-7 back in: the surfaces just cross or sit within 1e-7;
//! - `gap`: first contact plus a gap drawn log-uniformly in `[1e-4, 1e-1]`;
//! - `far`: first contact plus 1 to 2 units.
//!
//! Criterion times one query cycling through the 16 setups (`frcd/<pair>/<kind>`); before that
//! the medians per query of frcd and parry3d-f64 are printed side by side (parry on the first 3
//! setups only: it is two to three orders of magnitude slower), with their agreement and
//! frcd's median work (volume pairs, triangle pairs). frcd's time per setup is the fastest of
//! 7 windows of 1 ms (the machine is shared; preempted windows are dropped), the median over
//! setups is printed. `FRCD_DISTANCE_NO_PARRY=1` times parry on one setup only (`=0`: not at
//! all), `FRCD_DISTANCE_ONLY=SUBSTRING` times only the rows whose `pair/kind` contains it,
//! `FRCD_DISTANCE_SPIN=SECONDS` keeps querying each timed row that long (for a profiler),
//! `FRCD_DISTANCE_DETAIL=1` prints every setup's time and work. When
//! `FRCD_DISTANCE_EXPORT=DIR` is set, every pair's meshes and poses are written there as plain
//! text, so a peer library run outside this repository can time the same queries.

use criterion::{Criterion, criterion_group, criterion_main};
use frcd_geom::{DQuat, DVec3, Pose, TriMesh};
use frcd_obb::distance::{DistanceRequest, distance, within};
use frcd_obb::{BuildOptions, ObbTree};
use std::hint::black_box;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

mod p64 {
    use parry3d_f64::math::{Pose, Rotation, Vector};
    use parry3d_f64::shape::TriMesh;

    pub fn mesh(m: &frcd_geom::TriMesh) -> TriMesh {
        let v = m
            .vertices()
            .iter()
            .map(|p| Vector::new(p.x, p.y, p.z))
            .collect();
        TriMesh::new(v, m.indices().to_vec()).expect("parry accepts the mesh")
    }

    pub fn pose(p: &frcd_geom::Pose) -> Pose {
        let (t, q) = (p.translation, p.rotation);
        Pose::from_parts(
            Vector::new(t.x, t.y, t.z),
            Rotation::from_xyzw(q.x, q.y, q.z, q.w).normalize(),
        )
    }

    /// `None` when parry does not answer this shape pair.
    pub fn distance(m1: &TriMesh, p1: &Pose, m2: &TriMesh, p2: &Pose) -> Option<f64> {
        parry3d_f64::query::distance(p1, m1, p2, m2)
            .ok()
            .map(|d| d.distance)
    }
}

const SETUPS: usize = 16;
const PARRY_SETUPS: usize = 3;
const KINDS: [&str; 3] = ["contact", "gap", "far"];

struct Pair {
    name: String,
    meshes: [TriMesh; 2],
    trees: [ObbTree; 2],
    parry: [parry3d_f64::shape::TriMesh; 2],
    /// Per kind, the setups (pose of A, pose of B).
    poses: [Vec<(Pose, Pose)>; 3],
}

fn shared_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/meshes")
}

/// Centred and scaled to a bounding-box diagonal of 1.
fn unit_size(m: &TriMesh) -> TriMesh {
    let b = m.aabb();
    let c = b.center();
    let s = 1.0 / (b.max - b.min).length();
    let v: Vec<DVec3> = m.vertices().iter().map(|p| (*p - c) * s).collect();
    TriMesh::new(v, m.indices().to_vec()).expect("scaling keeps the mesh valid")
}

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn unit(&mut self) -> DVec3 {
        loop {
            let v = DVec3::new(self.next(), self.next(), self.next()) * 2.0 - DVec3::ONE;
            let l = v.length();
            if l > 0.1 && l <= 1.0 {
                return v / l;
            }
        }
    }
    fn rotation(&mut self) -> DQuat {
        DQuat::from_axis_angle(self.unit(), self.next() * std::f64::consts::TAU)
    }
}

/// B at offset `s` along `dir`.
fn at(rot: DQuat, dir: DVec3, s: f64) -> Pose {
    Pose::new(dir * s, rot)
}

/// The smallest offset along `dir` (to 1e-9) at which the surfaces no longer touch, starting
/// from far enough away; `None` when they do not touch at offset 0 (one inside the other's hull
/// without contact is fine too: the search then starts from 0).
fn first_contact(a: &ObbTree, b: &ObbTree, rot: DQuat, dir: DVec3) -> f64 {
    let (mut lo, mut hi) = (0.0f64, 2.0f64);
    while within(a, &Pose::IDENTITY, b, &at(rot, dir, hi), 0.0) {
        hi *= 2.0;
    }
    while hi - lo > 1e-9 {
        let mid = 0.5 * (lo + hi);
        if within(a, &Pose::IDENTITY, b, &at(rot, dir, mid), 0.0) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

fn make_pair(name: &str, ma: TriMesh, mb: TriMesh, seed: u64) -> Pair {
    let opts = BuildOptions::default();
    let ta = ObbTree::build(&ma, &opts);
    let tb = ObbTree::build(&mb, &opts);
    let mut rng = Rng(seed | 1);
    let mut poses: [Vec<(Pose, Pose)>; 3] = Default::default();
    for _ in 0..SETUPS {
        let rot = rng.rotation();
        let dir = rng.unit();
        let s0 = first_contact(&ta, &tb, rot, dir);
        let gap = 10f64.powf(-4.0 + 3.0 * rng.next());
        let far = 1.0 + rng.next();
        poses[0].push((Pose::IDENTITY, at(rot, dir, s0 - 1e-7)));
        poses[1].push((Pose::IDENTITY, at(rot, dir, s0 + gap)));
        poses[2].push((Pose::IDENTITY, at(rot, dir, s0 + far)));
    }
    Pair {
        name: name.to_string(),
        parry: [p64::mesh(&ma), p64::mesh(&mb)],
        trees: [ta, tb],
        meshes: [ma, mb],
        poses,
    }
}

fn pairs() -> Vec<Pair> {
    let mut out = Vec::new();
    let dir = shared_dir();
    let cad = [
        (
            "wagon_vs_intermodal_bogie",
            "railway_3dprintedtrains/intermodal_wagon_no_visible_container_holes_binary.stl",
            "railway_3dprintedtrains/intermodal_bogie_binary.stl",
        ),
        (
            "adis_vs_wagon",
            "mechanical_trimesh/ADIS16480.STL",
            "railway_3dprintedtrains/intermodal_wagon_no_visible_container_holes_binary.stl",
        ),
    ];
    if dir.is_dir() {
        for (k, (name, fa, fb)) in cad.iter().enumerate() {
            match (
                frcd_io::load_mesh(dir.join(fa)),
                frcd_io::load_mesh(dir.join(fb)),
            ) {
                (Ok(a), Ok(b)) => {
                    out.push(make_pair(name, unit_size(&a), unit_size(&b), 11 + k as u64))
                }
                (a, b) => println!("SKIP {name}: {:?} {:?}", a.err(), b.err()),
            }
        }
    } else {
        println!("SKIP CAD pairs: {} not found", dir.display());
    }
    let sphere = frcd_geom::shapes::icosphere(0.5, 5);
    let knot = frcd_geom::shapes::torus_knot(&frcd_geom::shapes::TorusKnotParams::default())
        .expect("default knot");
    out.push(make_pair(
        "icosphere_vs_knot",
        unit_size(&sphere),
        unit_size(&knot),
        5,
    ));
    out
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// Median over the setups of the seconds per call of `f`: each setup is timed in 7 windows of
/// at least 1 ms and keeps its fastest window (the machine is shared: the minimum drops the
/// windows in which the thread was preempted).
fn time_each(n: usize, mut f: impl FnMut(usize)) -> f64 {
    let cpu = std::env::var_os("FRCD_DISTANCE_CPU").is_some();
    let mut per = Vec::new();
    for i in 0..n {
        f(i); // warm
        let mut fastest = f64::INFINITY;
        for _ in 0..7 {
            let t = Instant::now();
            let c0 = thread_cpu();
            let mut reps = 0u32;
            while t.elapsed() < Duration::from_millis(1) || reps == 0 {
                f(i);
                reps += 1;
            }
            let spent = if cpu {
                thread_cpu() - c0
            } else {
                t.elapsed().as_secs_f64()
            };
            fastest = fastest.min(spent / reps as f64);
        }
        per.push(fastest);
    }
    median(per)
}

/// This thread's CPU time in seconds, NaN where it cannot be read (`FRCD_DISTANCE_CPU=1` times
/// with it instead of the wall clock: on a loaded machine it leaves out the time the thread
/// waits for a core; for comparing two builds of frcd, not for the peer ratios, which use the
/// wall clock).
fn thread_cpu() -> f64 {
    frcd_benches::thread_cpu().unwrap_or(f64::NAN)
}

fn export(p: &Pair, dir: &Path) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    let mut f =
        std::io::BufWriter::new(std::fs::File::create(dir.join(format!("{}.txt", p.name)))?);
    for m in &p.meshes {
        writeln!(f, "{}", m.triangle_count())?;
        for t in m.triangles() {
            for v in t.v {
                write!(f, "{:e} {:e} {:e} ", v.x, v.y, v.z)?;
            }
            writeln!(f)?;
        }
    }
    for (k, kind) in KINDS.iter().enumerate() {
        writeln!(f, "{kind} {}", p.poses[k].len())?;
        for (pa, pb) in &p.poses[k] {
            for pose in [pa, pb] {
                let r = pose.rotation_matrix();
                let t = pose.translation;
                // Row-major rotation, then translation.
                for row in 0..3 {
                    let c = r.row(row);
                    write!(f, "{:e} {:e} {:e} ", c.x, c.y, c.z)?;
                }
                writeln!(f, "{:e} {:e} {:e}", t.x, t.y, t.z)?;
            }
        }
    }
    Ok(())
}

fn bench(c: &mut Criterion) {
    let all = pairs();
    let export_dir = std::env::var_os("FRCD_DISTANCE_EXPORT").map(PathBuf::from);
    println!(
        "{:<28} {:>8} {:>8} {:>12} {:>12} {:>10} {:>10}",
        "pair/kind", "tris A", "tris B", "frcd med", "parry med", "parry/frcd", "max |diff|"
    );
    let req = DistanceRequest::default();
    // `FRCD_DISTANCE_ONLY=SUBSTRING`: time only the rows whose label contains it (profiling).
    let only = std::env::var("FRCD_DISTANCE_ONLY").ok();
    for p in &all {
        if let Some(Err(e)) = export_dir.as_ref().map(|dir| export(p, dir)) {
            println!("export {}: {e}", p.name);
        }
        for (k, kind) in KINDS.iter().enumerate() {
            if only
                .as_ref()
                .is_some_and(|o| !format!("{}/{kind}", p.name).contains(o.as_str()))
            {
                continue;
            }
            let poses = &p.poses[k];
            let [ta, tb] = &p.trees;
            let frcd_t = time_each(poses.len(), |i| {
                black_box(distance(ta, &poses[i].0, tb, &poses[i].1, &req));
            });
            if let Some(secs) = std::env::var("FRCD_DISTANCE_SPIN")
                .ok()
                .and_then(|v| v.parse::<f64>().ok())
            {
                // Profiling: keep querying this row's setups for `secs` seconds.
                let t = Instant::now();
                while t.elapsed().as_secs_f64() < secs {
                    for (pa, pb) in poses {
                        black_box(distance(ta, pa, tb, pb, &req));
                    }
                }
            }
            let work = |f: fn(&frcd_obb::distance::DistanceCounters) -> u64| {
                median(
                    poses
                        .iter()
                        .map(|(pa, pb)| f(&distance(ta, pa, tb, pb, &req).counters) as f64)
                        .collect(),
                )
            };
            let (boxes, tris) = (work(|c| c.box_tests), work(|c| c.tri_tests));
            if std::env::var_os("FRCD_DISTANCE_DETAIL").is_some() {
                for (i, (pa, pb)) in poses.iter().enumerate() {
                    let t = time_each(1, |_| {
                        black_box(distance(ta, pa, tb, pb, &req));
                    });
                    let c = distance(ta, pa, tb, pb, &req).counters;
                    println!(
                        "  {kind} setup {i}: {:.3} ms, {} volume pairs, {} triangle pairs",
                        t * 1e3,
                        c.box_tests,
                        c.tri_tests
                    );
                }
            }
            let [ma, mb] = &p.parry;
            let mut diff = 0.0f64;
            let mut supported = true;
            let mut parry_times = Vec::new();
            let parry_setups = if let Some(v) = std::env::var_os("FRCD_DISTANCE_NO_PARRY") {
                // `=0`: no parry call at all (profiling).
                if v == "0" { 0 } else { 1 }
            } else {
                PARRY_SETUPS
            };
            for (pa, pb) in poses.iter().take(parry_setups) {
                let (qa, qb) = (p64::pose(pa), p64::pose(pb));
                let t = Instant::now();
                let d = p64::distance(ma, &qa, mb, &qb);
                parry_times.push(t.elapsed().as_secs_f64());
                match d {
                    Some(d) => {
                        let ours = distance(ta, pa, tb, pb, &req).distance;
                        diff = diff.max((d - ours).abs());
                    }
                    None => supported = false,
                }
            }
            let parry_t = median(parry_times);
            let label = format!("{}/{kind}", p.name);
            if supported {
                println!(
                    "{label:<28} {:>8} {:>8} {:>9.3} ms {:>9.3} ms {:>10.0} {:>10.1e}   (frcd median work: {boxes} volume pairs, {tris} triangle pairs)",
                    p.meshes[0].triangle_count(),
                    p.meshes[1].triangle_count(),
                    frcd_t * 1e3,
                    parry_t * 1e3,
                    parry_t / frcd_t,
                    diff
                );
            } else {
                println!(
                    "{label:<28} {:>8} {:>8} {:>9.3} ms   parry3d-f64 does not answer trimesh-trimesh distance",
                    p.meshes[0].triangle_count(),
                    p.meshes[1].triangle_count(),
                    frcd_t * 1e3
                );
            }
            let mut i = 0;
            c.bench_function(&format!("frcd/{label}"), |bch| {
                bch.iter(|| {
                    i = (i + 1) % poses.len();
                    black_box(distance(ta, &poses[i].0, tb, &poses[i].1, &req))
                })
            });
        }
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench
}
criterion_main!(benches);
