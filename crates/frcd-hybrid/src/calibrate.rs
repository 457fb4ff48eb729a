//! Measuring the [`CostModel`] on the present machine (what `frcd calibrate` runs).
//!
//! Each figure is the median of a few timed repetitions of the real stage code on generated
//! scenes: the CPU broad phase over random boxes, OBB-tree pair queries between overlapping
//! icospheres, and (with the features and an adapter) the GPU box pass, the GPU pair query and
//! the image-space pass. A missing adapter leaves the GPU figures `None`.

use crate::CostModel;
use frcd_geom::{Aabb, DQuat, DVec3, Pose, TriMesh, shapes};
use frcd_obb::{BuildOptions, Mode, ObbTree, Request, collide};
use std::time::Instant;

/// Options of [`measure`].
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrateOptions {
    /// Timed repetitions per figure (the median is kept). Default 5.
    pub repetitions: usize,
    /// Measure GPU figures when the features are compiled in. Default true.
    pub gpu: bool,
}

impl Default for CalibrateOptions {
    fn default() -> Self {
        Self {
            repetitions: 5,
            gpu: true,
        }
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Deterministic pseudo-random numbers in [0, 1) (xorshift), so runs are comparable.
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn random_boxes(n: usize, rng: &mut Lcg) -> Vec<Aabb> {
    // Density chosen so each box overlaps a few others.
    let side = (n as f64).cbrt() * 2.0;
    (0..n)
        .map(|_| {
            let c = DVec3::new(rng.next(), rng.next(), rng.next()) * side;
            Aabb::new(c - DVec3::splat(0.5), c + DVec3::splat(0.5))
        })
        .collect()
}

/// Overlapping pose pairs for two unit icospheres (centre distance 1.0..1.8).
fn overlapping_poses(count: usize, rng: &mut Lcg) -> Vec<Pose> {
    (0..count)
        .map(|_| {
            let d = 1.0 + 0.8 * rng.next();
            let dir = DVec3::new(rng.next() - 0.5, rng.next() - 0.5, rng.next() - 0.5)
                .normalize_or(DVec3::X);
            let q = DQuat::from_axis_angle(
                DVec3::new(rng.next(), rng.next(), rng.next() + 0.1).normalize(),
                6.0 * rng.next(),
            );
            Pose::new(dir * d, q)
        })
        .collect()
}

/// Boxes of the broad-phase figures: enough that the GPU pass's per-body cost shows past its
/// fixed cost (on an H200 the GPU sort-and-sweep took 0.8 ms at 4,096 bodies and 2.8 ms at
/// 16,384, 2026-11-28).
const BROAD_BODIES: usize = 16_384;

/// Measures the cost model (see the module docs). Takes a few seconds.
pub fn measure(options: &CalibrateOptions) -> CostModel {
    let reps = options.repetitions.max(1);
    let mut rng = Lcg(0x9E37_79B9_7F4A_7C15);
    let mut model = CostModel {
        adapter: String::new(),
        threads: rayon::current_num_threads(),
        ..CostModel::default()
    }
    .cpu_only();

    // The CPU broad phase per body: the World's box-pair search on a fresh frame (an upper
    // bound of its cost under coherence, where it keeps its candidates). As many boxes as the
    // GPU figure below, so both per-body figures come from one size.
    let boxes = random_boxes(BROAD_BODIES, &mut rng);
    let times: Vec<f64> = (0..reps)
        .map(|_| {
            let t = Instant::now();
            std::hint::black_box(frcd_obb::overlapping_boxes(&boxes, 0.0));
            t.elapsed().as_secs_f64() * 1e9 / BROAD_BODIES as f64
        })
        .collect();
    model.cpu_broad_ns_per_body = median(times);

    // CPU exact pair query per triangle (one thread).
    let mesh: TriMesh = shapes::icosphere(1.0, 3);
    let tree = ObbTree::build(&mesh, &BuildOptions::default());
    let poses = overlapping_poses(8, &mut rng);
    let request = Request {
        mode: Mode::AllPairs,
        solid: true,
        ..Request::default()
    };
    let tris = 2 * mesh.triangle_count();
    let times: Vec<f64> = (0..reps)
        .map(|_| {
            let t = Instant::now();
            for p in &poses {
                std::hint::black_box(collide(&tree, &Pose::IDENTITY, &tree, p, &request));
            }
            t.elapsed().as_secs_f64() * 1e9 / (poses.len() * tris) as f64
        })
        .collect();
    model.cpu_narrow_ns_per_triangle = median(times);

    if options.gpu {
        #[cfg(feature = "gpgpu")]
        gpgpu_figures(&mut model, reps, &boxes, &tree, &poses);
        #[cfg(feature = "image")]
        image_figures(&mut model, reps, &mesh, &poses);
    }
    model
}

#[cfg(feature = "gpgpu")]
fn gpgpu_figures(
    model: &mut CostModel,
    reps: usize,
    boxes: &[Aabb],
    tree: &ObbTree,
    poses: &[Pose],
) {
    use frcd_gpgpu::{BoxScratch, GpuContext, QueryScratch};
    let Ok(ctx) = GpuContext::headless() else {
        return;
    };
    let time = |f: &mut dyn FnMut() -> bool| -> Option<f64> {
        let mut v = Vec::with_capacity(reps);
        f(); // warm-up: pipelines and buffers
        for _ in 0..reps {
            let t = Instant::now();
            if !f() {
                return None;
            }
            v.push(t.elapsed().as_secs_f64() * 1e6);
        }
        Some(median(v))
    };
    let mut scratch = BoxScratch::default();
    let small = &boxes[..2];
    let Some(fixed) = time(&mut || ctx.overlapping_bodies(small, &mut scratch).is_ok()) else {
        return;
    };
    let Some(big) = time(&mut || ctx.overlapping_bodies(boxes, &mut scratch).is_ok()) else {
        return;
    };
    let n = boxes.len() as f64;
    model.gpu_broad_us = Some(fixed);
    model.gpu_broad_ns_per_body = Some(((big - fixed).max(0.0) * 1e3) / n);
    let cube = ObbTree::build(&shapes::cuboid(DVec3::splat(0.5)), &BuildOptions::default());
    let (Ok(gc), Ok(gt)) = (ctx.upload(&cube), ctx.upload(tree)) else {
        return;
    };
    let mut qs = QueryScratch::default();
    let near = Pose::from_translation(DVec3::new(0.5, 0.2, 0.1));
    let Some(fixed) = time(&mut || {
        ctx.collide(&gc, &Pose::IDENTITY, &gc, &near, &mut qs)
            .is_ok()
    }) else {
        return;
    };
    let Some(heavy) = time(&mut || {
        poses
            .iter()
            .all(|p| ctx.collide(&gt, &Pose::IDENTITY, &gt, p, &mut qs).is_ok())
    }) else {
        return;
    };
    let per_query = heavy / poses.len() as f64;
    let tris = 2.0 * tree.triangles().len() as f64;
    model.gpu_narrow_us = Some(fixed);
    model.gpu_narrow_ns_per_triangle = Some(((per_query - fixed).max(0.0) * 1e3) / tris);
    model.adapter = ctx.adapter_info().name.clone();
}

#[cfg(feature = "image")]
fn image_figures(model: &mut CostModel, reps: usize, mesh: &TriMesh, poses: &[Pose]) {
    use frcd_image::{ImageDetector, ImageOptions, ImageScratch};
    let Ok(det) = ImageDetector::headless() else {
        return;
    };
    let Ok(g) = det.upload("calibration sphere", mesh) else {
        return;
    };
    let opts = ImageOptions {
        colliding_set: true,
        ..ImageOptions::default()
    };
    let mut scratch = ImageScratch::default();
    let _ = det.query(&mut scratch, &g, &Pose::IDENTITY, &g, &poses[0], &opts);
    let mut v = Vec::new();
    for _ in 0..reps {
        let t = Instant::now();
        for p in poses {
            if det
                .query(&mut scratch, &g, &Pose::IDENTITY, &g, p, &opts)
                .is_err()
            {
                return;
            }
        }
        v.push(t.elapsed().as_secs_f64() * 1e6 / poses.len() as f64);
    }
    model.image_us = Some(median(v));
    if model.adapter.is_empty() {
        model.adapter = det.context().adapter_name();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_figures_are_positive() {
        let m = measure(&CalibrateOptions {
            repetitions: 1,
            gpu: false,
        });
        assert!(m.cpu_broad_ns_per_body > 0.0 && m.cpu_narrow_ns_per_triangle > 0.0);
        assert!(m.gpu_narrow_us.is_none() && m.image_us.is_none());
        assert!(m.threads >= 1);
    }
}
