//! `cargo xtask verify`: every backend against the exact oracle, on generated scenes and on the
//! stored meshes (`../shared/meshes`, skipped when absent).
//!
//! The check is a table: scenes × backends. For every step of a scene, the oracle lists the
//! interfering body pairs with all their touching triangle pairs (surface mode) and, when every
//! mesh is closed, containment too (solid mode). Each backend returns the same kind of answer
//! (see [`Backend`]) and the row reports whether every step agrees. Any difference fails the task
//! (non-zero exit).
//!
//! Adding a backend (GPU, image space, hybrid): implement [`Backend`] and push it in
//! [`backends`]. A backend whose accuracy is bounded rather than exact overrides
//! [`Backend::compare`].
//!
//! Options: `--scene SUBSTR` and `--backend SUBSTR` keep matching rows only; `--no-stored` skips
//! the stored meshes; `--quick` shortens every scene to a few steps.

use anyhow::{Result, bail};
use frcd_benches::scenes::{self, Scene};
use frcd_geom::{Pose, Sphere, TriMesh};
use frcd_obb::{
    BuildOptions, Mode, ObbTree, PairCache, Request, World, WorldOptions, collide, collide_cached,
    oracle,
};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

/// One interfering body pair at one step.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PairAnswer {
    /// Lower body index.
    pub a: usize,
    /// Higher body index.
    pub b: usize,
    /// Every touching triangle pair, sorted; `None` for a backend that answers a boolean only.
    pub pairs: Option<Vec<(u32, u32)>>,
    /// One touching triangle pair, when the backend names one (must be a true touching pair).
    pub witness: Option<(u32, u32)>,
    /// Solid mode: one body lies inside the other (and no surface pair touches).
    pub contained: bool,
}

/// Interfering body pairs per step, each step sorted by `(a, b)`.
pub type Answers = Vec<Vec<PairAnswer>>;

/// A backend under test: one row of the table per scene.
pub trait Backend {
    /// Row label.
    fn name(&self) -> String;
    /// True when the backend answers in solid mode (compared with the solid oracle, and only on
    /// scenes whose meshes are all closed).
    fn solid(&self) -> bool;
    /// The backend's answers for every step of the scene.
    fn answer(&mut self, scene: &Scene) -> Result<Answers>;
    /// Differences between the oracle's and the backend's answers, one line each (empty when
    /// they agree). The default is exact agreement.
    fn compare(&self, truth: &Answers, got: &Answers) -> Vec<String> {
        exact_compare(truth, got)
    }
}

/// Exact agreement: the same interfering body pairs at every step, the same triangle pairs
/// where the backend lists them, a witness that is a true touching pair, the same containment.
pub fn exact_compare(truth: &Answers, got: &Answers) -> Vec<String> {
    let mut out = Vec::new();
    if truth.len() != got.len() {
        out.push(format!(
            "{} steps answered, {} expected",
            got.len(),
            truth.len()
        ));
        return out;
    }
    for (step, (t, g)) in truth.iter().zip(got).enumerate() {
        let tk: Vec<(usize, usize)> = t.iter().map(|p| (p.a, p.b)).collect();
        let gk: Vec<(usize, usize)> = g.iter().map(|p| (p.a, p.b)).collect();
        if tk != gk {
            let missing: Vec<_> = tk.iter().filter(|k| !gk.contains(k)).collect();
            let extra: Vec<_> = gk.iter().filter(|k| !tk.contains(k)).collect();
            out.push(format!(
                "step {step}: body pairs differ: missing {missing:?}, extra {extra:?}"
            ));
            continue;
        }
        for (tp, gp) in t.iter().zip(g) {
            let truth_pairs = tp.pairs.as_ref().expect("the oracle lists pairs");
            if let Some(pairs) = gp.pairs.as_ref().filter(|p| *p != truth_pairs) {
                let missing = truth_pairs
                    .iter()
                    .filter(|p| pairs.binary_search(p).is_err())
                    .count();
                let extra = pairs
                    .iter()
                    .filter(|p| truth_pairs.binary_search(p).is_err())
                    .count();
                out.push(format!(
                    "step {step}, bodies ({}, {}): {} triangle pairs, oracle {} ({missing} missing, {extra} extra)",
                    tp.a,
                    tp.b,
                    pairs.len(),
                    truth_pairs.len()
                ));
            }
            if let Some(w) = gp.witness.filter(|w| truth_pairs.binary_search(w).is_err()) {
                out.push(format!(
                    "step {step}, bodies ({}, {}): witness {w:?} does not touch",
                    tp.a, tp.b
                ));
            }
            if tp.contained != gp.contained {
                out.push(format!(
                    "step {step}, bodies ({}, {}): contained {} vs oracle {}",
                    tp.a, tp.b, gp.contained, tp.contained
                ));
            }
        }
    }
    out
}

/// World bounding sphere of a body, inflated far beyond any rounding (a cull for the oracle
/// that shares nothing with the backends' broad phases).
fn world_sphere(local: &Sphere, pose: &Pose) -> Sphere {
    let c = pose.transform_point(local.center);
    Sphere::new(
        c,
        local.radius * (1.0 + 1e-9) + 1e-9 * c.abs().max_element() + 1e-300,
    )
}

/// The oracle's answers for a scene: every body pair (not both static) whose inflated spheres
/// meet gets [`oracle::answer`].
pub fn oracle_answers(scene: &Scene, solid: bool) -> Answers {
    let spheres: Vec<Sphere> = scene
        .bodies
        .iter()
        .map(|b| Sphere::from_points(b.mesh.vertices()))
        .collect();
    let pairs = scene.body_pairs();
    scene
        .frames
        .iter()
        .map(|poses| {
            let ws: Vec<Sphere> = spheres
                .iter()
                .zip(poses)
                .map(|(s, p)| world_sphere(s, p))
                .collect();
            let mut out = Vec::new();
            for &(i, j) in &pairs {
                if !ws[i].intersects(&ws[j]) {
                    continue;
                }
                let (bi, bj) = (&scene.bodies[i], &scene.bodies[j]);
                let ans = oracle::answer(&bi.mesh, &poses[i], &bj.mesh, &poses[j], solid);
                if ans.collide() {
                    out.push(PairAnswer {
                        a: i,
                        b: j,
                        witness: None,
                        contained: ans.contained.is_some(),
                        pairs: Some(ans.pairs),
                    });
                }
            }
            out
        })
        .collect()
}

/// One tree per distinct mesh of the scene (bodies sharing an `Arc<TriMesh>` share a tree).
fn trees(scene: &Scene) -> Vec<Arc<ObbTree>> {
    let mut built: HashMap<*const TriMesh, Arc<ObbTree>> = HashMap::new();
    scene
        .bodies
        .iter()
        .map(|b| {
            built
                .entry(Arc::as_ptr(&b.mesh))
                .or_insert_with(|| Arc::new(ObbTree::build(&b.mesh, &BuildOptions::default())))
                .clone()
        })
        .collect()
}

/// The OBB pair query on every body pair, cached or not.
struct ObbPairs {
    mode: Mode,
    cached: bool,
    solid: bool,
}

impl Backend for ObbPairs {
    fn name(&self) -> String {
        format!(
            "obb {} {}{}",
            if self.mode == Mode::AllPairs {
                "all-pairs"
            } else {
                "first-contact"
            },
            if self.solid { "solid" } else { "surface" },
            if self.cached { " +cache" } else { "" }
        )
    }
    fn solid(&self) -> bool {
        self.solid
    }
    fn answer(&mut self, scene: &Scene) -> Result<Answers> {
        let trees = trees(scene);
        let request = Request {
            mode: self.mode,
            solid: self.solid,
            ..Request::default()
        };
        let pairs = scene.body_pairs();
        let mut caches: Vec<PairCache> =
            vec![PairCache::new(); if self.cached { pairs.len() } else { 0 }];
        Ok(scene
            .frames
            .iter()
            .map(|poses| {
                let mut out = Vec::new();
                for (k, &(i, j)) in pairs.iter().enumerate() {
                    let c = if self.cached {
                        collide_cached(
                            &trees[i],
                            &poses[i],
                            &trees[j],
                            &poses[j],
                            &request,
                            &mut caches[k],
                        )
                    } else {
                        collide(&trees[i], &poses[i], &trees[j], &poses[j], &request)
                    };
                    if c.collide {
                        out.push(PairAnswer {
                            a: i,
                            b: j,
                            pairs: (self.mode == Mode::AllPairs).then_some(c.pairs),
                            witness: c.witness,
                            contained: c.contained.is_some(),
                        });
                    }
                }
                out
            })
            .collect())
    }
}

/// The many-body [`World`] (sweep-and-prune, coherence, parallel narrow phase).
struct ObbWorld {
    solid: bool,
}

impl Backend for ObbWorld {
    fn name(&self) -> String {
        format!(
            "obb world all-pairs {}",
            if self.solid { "solid" } else { "surface" }
        )
    }
    fn solid(&self) -> bool {
        self.solid
    }
    fn answer(&mut self, scene: &Scene) -> Result<Answers> {
        let trees = trees(scene);
        let mut options = WorldOptions::default();
        options.request.solid = self.solid;
        let mut world = World::new(options);
        let Some(first) = scene.frames.first() else {
            return Ok(Vec::new());
        };
        let ids: Vec<_> = trees
            .iter()
            .zip(&scene.bodies)
            .zip(first)
            .map(|((t, b), p)| world.add_body(t.clone(), *p, b.is_static))
            .collect::<Result<_, _>>()?;
        let mut out = Vec::new();
        for poses in &scene.frames {
            for (id, p) in ids.iter().zip(poses) {
                world.set_pose(*id, *p)?;
            }
            let report = world.step();
            out.push(
                report
                    .contacts
                    .into_iter()
                    .map(|c| PairAnswer {
                        a: c.a.index() as usize,
                        b: c.b.index() as usize,
                        pairs: Some(c.pairs.to_vec()),
                        witness: c.witness,
                        contained: c.contained.is_some(),
                    })
                    .collect(),
            );
        }
        Ok(out)
    }
}

/// Every backend in the table. Other backends add their rows here.
pub fn backends() -> Vec<Box<dyn Backend>> {
    let mut out: Vec<Box<dyn Backend>> = Vec::new();
    for solid in [false, true] {
        for mode in [Mode::FirstContact, Mode::AllPairs] {
            for cached in [false, true] {
                out.push(Box::new(ObbPairs {
                    mode,
                    cached,
                    solid,
                }));
            }
        }
        out.push(Box::new(ObbWorld { solid }));
    }
    out.extend(crate::verify_image::backends());
    out.extend(crate::verify_gpgpu::backends());
    out.extend(crate::verify_hybrid::backends());
    out
}

/// `../shared/meshes` from the workspace root.
fn stored_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/meshes")
}

/// Every STL and OBJ mesh one folder below `dir` (the layout of `../shared/meshes`), sorted by
/// path, with its file stem as name.
pub(crate) fn stored_meshes(dir: &Path) -> Result<Vec<(String, TriMesh)>> {
    let mut files = Vec::new();
    for sub in std::fs::read_dir(dir)? {
        let sub = sub?.path();
        if sub.is_dir() {
            for f in std::fs::read_dir(&sub)? {
                let f = f?.path();
                let ext = f
                    .extension()
                    .and_then(|e| e.to_str())
                    .unwrap_or("")
                    .to_ascii_lowercase();
                if ext == "stl" || ext == "obj" {
                    files.push(f);
                }
            }
        }
    }
    files.sort();
    files
        .into_iter()
        .map(|f| {
            let name = f
                .file_stem()
                .and_then(|s| s.to_str())
                .unwrap_or("mesh")
                .to_string();
            Ok((name, frcd_io::load_mesh(&f)?))
        })
        .collect()
}

/// The stored-mesh scenes: each mesh against a copy of itself sliding diagonally through it,
/// turning. `None` when the folder is absent.
fn stored_scenes(steps: usize) -> Result<Option<Vec<Scene>>> {
    let dir = stored_dir();
    if !dir.is_dir() {
        return Ok(None);
    }
    let mut out = Vec::new();
    for (name, mesh) in stored_meshes(&dir)? {
        out.push(scenes::self_sweep(
            &format!("stored/{name}"),
            Arc::new(mesh),
            steps,
        ));
    }
    Ok(Some(out))
}

/// The bogie demo (`testdata/bogie/scene.json`, written by `cargo xtask gen-bogie`) on a sample
/// of its 2,001 frames: every 100th, plus the first and last frame of each interference interval
/// and the frames around them, so every backend sees each interference start and end.
fn demo_scene() -> Result<Scene> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../testdata/bogie/scene.json");
    let loaded = frcd_io::Scene::load(&path)?;
    let n = loaded.frames().len();
    let mut picks: Vec<usize> = (0..n).step_by(100).collect();
    for edge in [
        69usize, 263, 521, 635, 761, 766, 1080, 1118, 1228, 1229, 1539, 1817,
    ] {
        picks.extend([edge.saturating_sub(1), edge, edge + 1]);
    }
    picks.retain(|&f| f < n);
    picks.sort_unstable();
    picks.dedup();
    Ok(Scene {
        name: "demo/bogie".into(),
        bodies: loaded
            .bodies()
            .iter()
            .map(|b| scenes::Body {
                name: b.name.clone(),
                mesh: b.mesh.clone(),
                is_static: b.is_static,
            })
            .collect(),
        frames: picks.iter().map(|&f| loaded.frame(f).poses).collect(),
    })
}

/// Options of `cargo xtask verify`.
#[derive(clap::Args, Debug)]
pub struct Opts {
    /// Keep only the scenes whose name contains this.
    #[arg(long, value_name = "SUBSTR")]
    pub scene: Option<String>,
    /// Keep only the backends whose name contains this.
    #[arg(long, value_name = "SUBSTR")]
    pub backend: Option<String>,
    /// Skip the stored meshes (../shared/meshes).
    #[arg(long)]
    pub no_stored: bool,
    /// Shorten every scene to a few steps.
    #[arg(long)]
    pub quick: bool,
}

/// Runs the task.
pub fn run(o: Opts) -> Result<()> {
    let Opts {
        scene: scene_filter,
        backend: backend_filter,
        no_stored,
        quick,
    } = o;
    let stored = !no_stored;
    let mut all = scenes::verify_set();
    all.push(demo_scene()?);
    if stored {
        match stored_scenes(12)? {
            Some(s) => all.extend(s),
            None => println!("SKIP stored meshes: {} not found", stored_dir().display()),
        }
    }
    if quick {
        all = all.into_iter().map(|s| s.truncated(4)).collect();
    }
    if let Some(f) = &scene_filter {
        all.retain(|s| s.name.contains(f.as_str()));
    }
    let mut backends = backends();
    if let Some(f) = &backend_filter {
        backends.retain(|b| b.name().contains(f.as_str()));
    }
    println!(
        "{:<34} {:<36} {:>7} {:>9}  result",
        "scene", "backend", "steps", "ms"
    );
    let mut failures = 0usize;
    for scene in &all {
        let t0 = Instant::now();
        let surface = oracle_answers(scene, false);
        let solid_truth = scene.all_closed().then(|| oracle_answers(scene, true));
        let touching = surface.iter().filter(|s| !s.is_empty()).count();
        println!(
            "{:<34} {:<36} {:>7} {:>9.1}  {} triangles, {} bodies, interference in {} steps",
            scene.name,
            "oracle",
            scene.steps(),
            t0.elapsed().as_secs_f64() * 1e3,
            scene.triangle_count(),
            scene.bodies.len(),
            touching
        );
        for backend in backends.iter_mut() {
            let truth = if backend.solid() {
                match &solid_truth {
                    Some(t) => t,
                    None => {
                        println!(
                            "{:<34} {:<36} {:>7} {:>9}  n/a (open mesh)",
                            scene.name,
                            backend.name(),
                            "",
                            ""
                        );
                        continue;
                    }
                }
            } else {
                &surface
            };
            let t0 = Instant::now();
            let got = backend.answer(scene)?;
            let ms = t0.elapsed().as_secs_f64() * 1e3;
            let diffs = backend.compare(truth, &got);
            let status = if diffs.is_empty() {
                "ok".to_string()
            } else {
                failures += 1;
                format!("DIFFERS ({} differences)", diffs.len())
            };
            println!(
                "{:<34} {:<36} {:>7} {:>9.1}  {status}",
                scene.name,
                backend.name(),
                scene.steps(),
                ms
            );
            for d in diffs.iter().take(5) {
                println!("    {d}");
            }
        }
    }
    if backend_filter
        .as_deref()
        .is_none_or(|f| "distance".contains(f))
    {
        failures +=
            crate::verify_distance::run(&stored_dir(), stored, quick, scene_filter.as_deref())?;
    }
    if failures > 0 {
        bail!("verify: {failures} rows differ from the oracle");
    }
    println!("verify: every row agrees with the oracle");
    Ok(())
}
