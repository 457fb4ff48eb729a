//! The image-space backend (frcd-image) in `cargo xtask verify`, in solid mode.
//!
//! The image detector is exact only up to its stated bounds, so its row passes when every
//! disagreement with the exact oracle is explained by them. For every body pair whose boxes
//! overlap, the same view's pixel-centre rays are also cast on the CPU in f64
//! ([`frcd_image::reference`]); then
//!
//! - a pair the oracle finds interfering and the image misses is explained when the reference sees
//!   no interference at any pixel centre beyond the bounds (the penetration is thinner than a pixel
//!   across, or within depth precision);
//! - a pair the image reports and the oracle does not is explained when every interfering pixel is
//!   one the bounds make ambiguous (the solids are closer than `separation`);
//! - where both agree, every pixel where the GPU and the reference differ must be explained.
//!
//! Anything else is a failure. Unexplained pixels and a reference that contradicts the oracle
//! (a bug in one of them) fail too.

use crate::verify::{Answers, Backend, PairAnswer};
use anyhow::Result;
use frcd_benches::scenes::Scene;
use frcd_geom::{Pose, Sphere, TriMesh};
use frcd_image::reference::{agreement, reference_image};
use frcd_image::{ImageDetector, ImageError, ImageMesh, ImageOptions, ImageScratch};
use std::collections::HashMap;
use std::sync::Arc;

/// What the image backend learned about one queried pair.
#[derive(Clone, Debug, Default)]
struct PairNote {
    /// GPU pixels that interfere.
    gpu_pixels: u64,
    /// Reference pixels that interfere and are not ambiguous (certain interference).
    certain_pixels: usize,
    /// GPU interfering pixels the reference calls ambiguous.
    gpu_pixels_ambiguous: usize,
    /// Pixels where GPU and reference differ without explanation.
    unexplained: usize,
    /// Pixel size and separation bound of the view.
    pixel_size: f64,
    separation: f64,
}

/// The image detector as a verify backend.
pub struct ImageBackend {
    det: Arc<ImageDetector>,
    resolution: u32,
    notes: HashMap<(usize, usize, usize), PairNote>,
    refused: Option<String>,
}

/// The image backends of the table (none, with a SKIP line, when no GPU adapter exists and
/// `FRCD_REQUIRE_GPU` is not 1).
pub fn backends() -> Vec<Box<dyn Backend>> {
    match ImageDetector::headless() {
        Ok(det) => {
            println!("image backend on {}", det.context().adapter_name());
            let det = Arc::new(det);
            vec![Box::new(ImageBackend {
                det,
                resolution: 128,
                notes: HashMap::new(),
                refused: None,
            })]
        }
        Err(e) => {
            if std::env::var("FRCD_REQUIRE_GPU").as_deref() == Ok("1") {
                panic!("FRCD_REQUIRE_GPU=1 but the image backend has no device: {e}");
            }
            println!("SKIP image backend: {e}");
            Vec::new()
        }
    }
}

fn world_sphere(mesh: &TriMesh, pose: &Pose) -> Sphere {
    let s = Sphere::from_points(mesh.vertices());
    let c = pose.transform_point(s.center);
    Sphere::new(
        c,
        s.radius * (1.0 + 1e-9) + 1e-9 * c.abs().max_element() + 1e-300,
    )
}

impl Backend for ImageBackend {
    fn name(&self) -> String {
        format!("image solid r{}", self.resolution)
    }

    fn solid(&self) -> bool {
        true
    }

    fn answer(&mut self, scene: &Scene) -> Result<Answers> {
        self.notes.clear();
        self.refused = None;
        let mut uploaded: HashMap<*const TriMesh, Arc<ImageMesh>> = HashMap::new();
        let mut meshes = Vec::with_capacity(scene.bodies.len());
        for b in &scene.bodies {
            let key = Arc::as_ptr(&b.mesh);
            if let Some(m) = uploaded.get(&key) {
                meshes.push(m.clone());
                continue;
            }
            match self.det.upload_shared(&b.name, b.mesh.clone()) {
                Ok(m) => {
                    let m = Arc::new(m);
                    uploaded.insert(key, m.clone());
                    meshes.push(m);
                }
                Err(e @ ImageError::NotSolid { .. }) => {
                    self.refused = Some(e.to_string());
                    return Ok(vec![Vec::new(); scene.steps()]);
                }
                Err(e) => return Err(e.into()),
            }
        }
        let options = ImageOptions {
            resolution: self.resolution,
            ..Default::default()
        };
        let mut scratch = ImageScratch::default();
        let pairs = scene.body_pairs();
        let mut out = Vec::with_capacity(scene.steps());
        for (step, poses) in scene.frames.iter().enumerate() {
            let mut answers = Vec::new();
            for &(i, j) in &pairs {
                let (bi, bj) = (&scene.bodies[i], &scene.bodies[j]);
                if !world_sphere(&bi.mesh, &poses[i]).intersects(&world_sphere(&bj.mesh, &poses[j]))
                {
                    continue;
                }
                let r = self.det.query(
                    &mut scratch,
                    &meshes[i],
                    &poses[i],
                    &meshes[j],
                    &poses[j],
                    &options,
                )?;
                let Some(view) = &r.view else { continue };
                let rel = poses[j].relative_to(&poses[i]);
                let reference =
                    reference_image(view, &r.bounds, &bi.mesh, &Pose::IDENTITY, &bj.mesh, &rel);
                let ag = agreement(&r, &reference);
                let certain_pixels = reference
                    .mask
                    .iter()
                    .zip(&reference.ambiguous)
                    .filter(|(m, a)| **m && !**a)
                    .count();
                let gpu_pixels_ambiguous = r
                    .image
                    .mask
                    .iter()
                    .zip(&reference.ambiguous)
                    .filter(|(m, a)| **m && **a)
                    .count();
                self.notes.insert(
                    (step, i, j),
                    PairNote {
                        gpu_pixels: r.interfering_pixels,
                        certain_pixels,
                        gpu_pixels_ambiguous,
                        unexplained: ag.unexplained + ag.length_violations,
                        pixel_size: r.bounds.pixel_size,
                        separation: r.bounds.separation,
                    },
                );
                if r.collide {
                    answers.push(PairAnswer {
                        a: i,
                        b: j,
                        pairs: None,
                        witness: None,
                        contained: false,
                    });
                }
            }
            out.push(answers);
        }
        Ok(out)
    }

    fn compare(&self, truth: &Answers, got: &Answers) -> Vec<String> {
        if let Some(why) = &self.refused {
            println!("    image: n/a, {why}");
            return Vec::new();
        }
        let mut out = Vec::new();
        let mut explained = 0usize;
        for (step, (t, g)) in truth.iter().zip(got).enumerate() {
            let note =
                |a: usize, b: usize| self.notes.get(&(step, a, b)).cloned().unwrap_or_default();
            for p in t {
                if !self.notes.contains_key(&(step, p.a, p.b)) {
                    out.push(format!(
                        "step {step}, bodies ({}, {}): interfering, but the detector found the boxes disjoint",
                        p.a, p.b
                    ));
                    continue;
                }
                let n = note(p.a, p.b);
                if !g.iter().any(|q| (q.a, q.b) == (p.a, p.b)) {
                    if n.certain_pixels == 0 {
                        explained += 1;
                    } else {
                        out.push(format!(
                            "step {step}, bodies ({}, {}): missed although {} pixel centres certainly interfere (pixel {:.2e})",
                            p.a, p.b, n.certain_pixels, n.pixel_size
                        ));
                    }
                }
            }
            for q in g {
                if t.iter().any(|p| (p.a, p.b) == (q.a, q.b)) {
                    continue;
                }
                let n = note(q.a, q.b);
                if n.gpu_pixels as usize == n.gpu_pixels_ambiguous && n.certain_pixels == 0 {
                    explained += 1;
                } else {
                    out.push(format!(
                        "step {step}, bodies ({}, {}): reported ({} pixels, {} certain in the reference) but the oracle finds no interference (separation bound {:.2e})",
                        q.a, q.b, n.gpu_pixels, n.certain_pixels, n.separation
                    ));
                }
            }
        }
        let mut bad: Vec<_> = self
            .notes
            .iter()
            .filter(|(_, n)| n.unexplained > 0)
            .collect();
        bad.sort_by_key(|(k, _)| **k);
        for ((step, a, b), n) in bad {
            out.push(format!(
                "step {step}, bodies ({a}, {b}): {} pixels differ from the f64 reference beyond the bounds",
                n.unexplained
            ));
        }
        if explained > 0 {
            println!(
                "    image: {explained} pair answers differ from the oracle, each explained by the resolution/depth bounds"
            );
        }
        out
    }
}
