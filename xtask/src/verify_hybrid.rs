//! The hybrid scheduler (frcd-hybrid) in `cargo xtask verify`, solid mode.
//!
//! Rows:
//! - `hybrid cpu exact (cached)`: CPU only, sweep and prune + OBB queries with the per-pair
//!   coherence cache; must equal the oracle.
//! - `hybrid exact`: the scheduler with the built-in cost model; must equal the oracle.
//! - `hybrid gpgpu exact`, `hybrid exact gpu-heavy` (with an adapter): every pair on the GPU,
//!   and a cost model in which the GPU is free (GPU box pass and GPU pair queries); must equal
//!   the oracle.
//! - `hybrid fast r128` (with an adapter): the thesis's pipeline. It passes when every
//!   disagreement is explained by the stated bound: no reported body pair or triangle pair may be
//!   false; a body pair the oracle finds and fast mode misses must have no interfering,
//!   unambiguous pixel-centre ray in the same view cast on the CPU in f64
//!   ([`frcd_image::reference`]); a triangle pair missed in a reported body pair must lie outside
//!   the image stage's colliding set (the ACS bound: triangles crossing the dilated interfering
//!   pixels), which the row re-queries to check.

use crate::verify::{Answers, Backend, PairAnswer, exact_compare};
use anyhow::Result;
use frcd_benches::scenes::Scene;
use frcd_geom::{Pose, TriMesh};
use frcd_hybrid::{
    Accuracy, Backend as HBackend, BodySpec, Checker, CostModel, FrameState, GpuPolicy, Options,
};
use frcd_image::reference::reference_image;
use frcd_image::{ImageDetector, ImageOptions, ImageScratch};
use std::sync::Arc;

const FAST_RESOLUTION: u32 = 128;

struct HybridRow {
    label: &'static str,
    options: Options,
    /// Fast mode: what the compare step needs to explain differences.
    fast: Option<FastCheck>,
}

struct FastCheck {
    det: ImageDetector,
    meshes: Vec<Arc<TriMesh>>,
    frames: Vec<Vec<Pose>>,
}

fn checker_for(scene: &Scene, options: &Options) -> Result<Checker> {
    let bodies = scene
        .bodies
        .iter()
        .map(|b| BodySpec {
            name: b.name.clone(),
            mesh: b.mesh.clone(),
            is_static: b.is_static,
        })
        .collect();
    Ok(Checker::new(bodies, &[], options.clone())?)
}

impl Backend for HybridRow {
    fn name(&self) -> String {
        self.label.to_string()
    }
    fn solid(&self) -> bool {
        true
    }
    fn answer(&mut self, scene: &Scene) -> Result<Answers> {
        let checker = checker_for(scene, &self.options)?;
        let mut state = FrameState::default();
        let mut out = Vec::with_capacity(scene.steps());
        for poses in &scene.frames {
            let r = checker.check(poses, &mut state)?;
            out.push(
                r.contacts
                    .into_iter()
                    .map(|c| PairAnswer {
                        a: c.a,
                        b: c.b,
                        pairs: Some(c.pairs),
                        witness: None,
                        contained: c.contained.is_some(),
                    })
                    .collect(),
            );
        }
        if let Some(f) = &mut self.fast {
            f.meshes = scene.bodies.iter().map(|b| b.mesh.clone()).collect();
            f.frames = scene.frames.clone();
        }
        Ok(out)
    }
    fn compare(&self, truth: &Answers, got: &Answers) -> Vec<String> {
        match &self.fast {
            None => exact_compare(truth, got),
            Some(f) => fast_compare(f, truth, got),
        }
    }
}

fn fast_compare(f: &FastCheck, truth: &Answers, got: &Answers) -> Vec<String> {
    let mut out = Vec::new();
    if truth.len() != got.len() {
        out.push(format!(
            "{} steps answered, {} expected",
            got.len(),
            truth.len()
        ));
        return out;
    }
    let mut scratch = ImageScratch::default();
    let (mut missed_bodies, mut missed_tris, mut found) = (0usize, 0usize, 0usize);
    for (step, (t, g)) in truth.iter().zip(got).enumerate() {
        let poses = &f.frames[step];
        for gp in g {
            let Some(tp) = t.iter().find(|p| p.a == gp.a && p.b == gp.b) else {
                out.push(format!(
                    "step {step}: reports ({}, {}) which does not interfere",
                    gp.a, gp.b
                ));
                continue;
            };
            found += 1;
            let (tpairs, gpairs) = (
                tp.pairs.as_deref().unwrap_or(&[]),
                gp.pairs.as_deref().unwrap_or(&[]),
            );
            if let Some(x) = gpairs.iter().find(|x| tpairs.binary_search(x).is_err()) {
                out.push(format!(
                    "step {step}, ({}, {}): false triangle pair {x:?}",
                    gp.a, gp.b
                ));
            }
            if gp.contained && !tp.contained {
                out.push(format!(
                    "step {step}, ({}, {}): false containment",
                    gp.a, gp.b
                ));
            }
            let missing: Vec<(u32, u32)> = tpairs
                .iter()
                .filter(|x| gpairs.binary_search(x).is_err())
                .copied()
                .collect();
            if !missing.is_empty() {
                missed_tris += missing.len();
                // Explained when the image stage's colliding set excludes the pair.
                let opts = ImageOptions {
                    resolution: FAST_RESOLUTION,
                    colliding_set: true,
                    ..ImageOptions::default()
                };
                match upload_query(f, &mut scratch, gp.a, gp.b, poses, &opts) {
                    Ok(r) => {
                        let cs = r.colliding_set.unwrap_or_default();
                        let inside = missing
                            .iter()
                            .filter(|(x, y)| {
                                cs.tris_a.binary_search(x).is_ok()
                                    && cs.tris_b.binary_search(y).is_ok()
                            })
                            .count();
                        if inside > 0 {
                            out.push(format!(
                                "step {step}, ({}, {}): {inside} triangle pairs inside the ACS missed",
                                gp.a, gp.b
                            ));
                        }
                    }
                    Err(e) => out.push(format!("step {step}: image re-query failed: {e}")),
                }
            }
        }
        for tp in t {
            if g.iter().any(|p| p.a == tp.a && p.b == tp.b) {
                continue;
            }
            missed_bodies += 1;
            let opts = ImageOptions {
                resolution: FAST_RESOLUTION,
                ..ImageOptions::default()
            };
            match upload_query(f, &mut scratch, tp.a, tp.b, poses, &opts) {
                Ok(r) => {
                    let Some(view) = &r.view else {
                        out.push(format!(
                            "step {step}, ({}, {}): missed, boxes disjoint",
                            tp.a, tp.b
                        ));
                        continue;
                    };
                    let rel = poses[tp.b].relative_to(&poses[tp.a]);
                    let reference = reference_image(
                        view,
                        &r.bounds,
                        &f.meshes[tp.a],
                        &Pose::IDENTITY,
                        &f.meshes[tp.b],
                        &rel,
                    );
                    let certain = reference
                        .mask
                        .iter()
                        .zip(&reference.ambiguous)
                        .filter(|(m, a)| **m && !**a)
                        .count();
                    if certain > 0 {
                        out.push(format!(
                            "step {step}, ({}, {}): missed, but {certain} pixel-centre rays meet A∩B (pixel {:.3e})",
                            tp.a, tp.b, r.bounds.pixel_size
                        ));
                    }
                }
                Err(e) => out.push(format!("step {step}: image re-query failed: {e}")),
            }
        }
    }
    println!(
        "    hybrid fast: {found} interfering pairs found, {missed_bodies} missed (sub-pixel), {missed_tris} triangle pairs outside the ACS"
    );
    out
}

fn upload_query(
    f: &FastCheck,
    scratch: &mut ImageScratch,
    a: usize,
    b: usize,
    poses: &[Pose],
    opts: &ImageOptions,
) -> Result<frcd_image::ImageResult> {
    let ga = f.det.upload_shared("a", f.meshes[a].clone())?;
    let gb = f.det.upload_shared("b", f.meshes[b].clone())?;
    Ok(f.det.query(scratch, &ga, &poses[a], &gb, &poses[b], opts)?)
}

/// The hybrid rows (GPU rows only with an adapter; without one a SKIP line, or a panic with
/// `FRCD_REQUIRE_GPU=1`).
pub fn backends() -> Vec<Box<dyn Backend>> {
    let cpu = Options {
        backend: HBackend::Cpu,
        gpu: GpuPolicy::Off,
        ..Options::default()
    };
    let mut out: Vec<Box<dyn Backend>> = vec![
        Box::new(HybridRow {
            label: "hybrid cpu exact (cached)",
            options: cpu,
            fast: None,
        }),
        Box::new(HybridRow {
            label: "hybrid exact",
            options: Options::default(),
            fast: None,
        }),
    ];
    let det = match (
        frcd_gpgpu::GpuContext::headless(),
        ImageDetector::headless(),
    ) {
        (Ok(_), Ok(det)) => det,
        (Err(e), _) => return skip(out, &e.to_string()),
        (_, Err(e)) => return skip(out, &e.to_string()),
    };
    let free_gpu = CostModel {
        gpu_broad_us: Some(0.0),
        gpu_broad_ns_per_body: Some(0.0),
        gpu_narrow_us: Some(0.0),
        gpu_narrow_ns_per_triangle: Some(0.0),
        ..CostModel::default()
    };
    out.push(Box::new(HybridRow {
        label: "hybrid gpgpu exact",
        options: Options {
            backend: HBackend::Gpgpu,
            gpu: GpuPolicy::Require,
            ..Options::default()
        },
        fast: None,
    }));
    out.push(Box::new(HybridRow {
        label: "hybrid exact gpu-heavy",
        options: Options {
            cost: free_gpu,
            gpu: GpuPolicy::Require,
            ..Options::default()
        },
        fast: None,
    }));
    out.push(Box::new(HybridRow {
        label: "hybrid fast r128",
        options: Options {
            mode: Accuracy::Fast,
            backend: HBackend::Image,
            gpu: GpuPolicy::Require,
            image_resolution: FAST_RESOLUTION,
            ..Options::default()
        },
        fast: Some(FastCheck {
            det,
            meshes: Vec::new(),
            frames: Vec::new(),
        }),
    }));
    out
}

fn skip(out: Vec<Box<dyn Backend>>, why: &str) -> Vec<Box<dyn Backend>> {
    if std::env::var("FRCD_REQUIRE_GPU").as_deref() == Ok("1") {
        panic!("FRCD_REQUIRE_GPU=1 but the hybrid GPU rows have no device: {why}");
    }
    println!("SKIP hybrid GPU rows: {why}");
    out
}
