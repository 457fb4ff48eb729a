//! The GPGPU backend (frcd-gpgpu) in `cargo xtask verify`, surface mode, held to exact agreement.
//!
//! Per step: the GPU box pass over all bodies' world boxes gives the rough colliding set (body
//! pairs); each of those pairs (not both static) runs the GPU pair traversal, whose uncertain
//! triangle pairs the CPU re-decides with the exact test. Every touching pair must equal the
//! oracle's.

use crate::verify::{Answers, Backend, PairAnswer};
use anyhow::{Result, bail};
use frcd_benches::scenes::Scene;
use frcd_geom::{Aabb, DVec3, TriMesh};
use frcd_gpgpu::{BoxScratch, GpuContext, GpuMesh, QueryScratch};
use frcd_obb::{BuildOptions, ObbTree};
use std::collections::HashMap;
use std::sync::Arc;

/// The GPU pipeline as a verify row.
pub struct GpgpuBackend {
    ctx: Option<Arc<GpuContext>>,
    /// Why there is no context (only with `FRCD_REQUIRE_GPU=1`: the row then fails).
    refused: Option<String>,
}

/// The gpgpu rows of the table: none, with a SKIP line, when no adapter exists (unless
/// `FRCD_REQUIRE_GPU=1`, where the row is kept and fails).
pub fn backends() -> Vec<Box<dyn Backend>> {
    match GpuContext::headless() {
        Ok(ctx) => {
            let info = ctx.adapter_info();
            println!(
                "gpgpu backend on {} ({:?}, {:?})",
                info.name, info.backend, info.device_type
            );
            vec![Box::new(GpgpuBackend {
                ctx: Some(Arc::new(ctx)),
                refused: None,
            })]
        }
        Err(e) if std::env::var("FRCD_REQUIRE_GPU").is_ok_and(|v| v == "1") => {
            vec![Box::new(GpgpuBackend {
                ctx: None,
                refused: Some(e.to_string()),
            })]
        }
        Err(e) => {
            println!("SKIP gpgpu backend: {e}");
            Vec::new()
        }
    }
}

/// A world box grown by a relative 1e-9 (far beyond the f64 rounding that separates world and
/// relative frames), so the broad phase never drops a pair the oracle finds.
fn world_box(local: &Aabb, pose: &frcd_geom::Pose) -> Aabb {
    let b = local.transformed(pose);
    let scale = b.min.abs().max(b.max.abs()).max_element() + (b.max - b.min).max_element();
    let m = 1e-9 * scale + 1e-300;
    Aabb::new(b.min - DVec3::splat(m), b.max + DVec3::splat(m))
}

impl Backend for GpgpuBackend {
    fn name(&self) -> String {
        "gpgpu all-pairs surface".to_string()
    }
    fn solid(&self) -> bool {
        false
    }
    fn answer(&mut self, scene: &Scene) -> Result<Answers> {
        let Some(ctx) = &self.ctx else {
            bail!(
                "FRCD_REQUIRE_GPU=1 but no adapter: {}",
                self.refused.as_deref().unwrap_or("?")
            );
        };
        // One tree and one upload per distinct mesh.
        let mut uploaded: HashMap<*const TriMesh, (Arc<ObbTree>, Arc<GpuMesh>)> = HashMap::new();
        let mut bodies = Vec::new();
        for b in &scene.bodies {
            let key = Arc::as_ptr(&b.mesh);
            if let std::collections::hash_map::Entry::Vacant(e) = uploaded.entry(key) {
                let tree = Arc::new(ObbTree::build(&b.mesh, &BuildOptions::default()));
                let gpu = Arc::new(ctx.upload(&tree)?);
                e.insert((tree, gpu));
            }
            bodies.push(uploaded[&key].clone());
        }
        let mut scratch = QueryScratch::default();
        let mut box_scratch = BoxScratch::default();
        let mut out = Vec::with_capacity(scene.frames.len());
        for poses in &scene.frames {
            let boxes: Vec<Aabb> = bodies
                .iter()
                .zip(poses)
                .map(|((t, _), p)| world_box(&t.aabb(), p))
                .collect();
            let rough = ctx.overlapping_bodies(&boxes, &mut box_scratch)?;
            let mut step = Vec::new();
            for &(i, j) in &rough.pairs {
                let (i, j) = (i as usize, j as usize);
                if scene.bodies[i].is_static && scene.bodies[j].is_static {
                    continue;
                }
                let hit = ctx.collide(
                    &bodies[i].1,
                    &poses[i],
                    &bodies[j].1,
                    &poses[j],
                    &mut scratch,
                )?;
                if hit.collide() {
                    step.push(PairAnswer {
                        a: i,
                        b: j,
                        witness: hit.pairs.first().copied(),
                        pairs: Some(hit.pairs),
                        contained: false,
                    });
                }
            }
            out.push(step);
        }
        Ok(out)
    }
}
