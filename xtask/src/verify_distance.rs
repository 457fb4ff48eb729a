//! Distance rows of `cargo xtask verify`: `frcd_obb::distance::{distance, within}` against the
//! brute-force oracle (`frcd_obb::oracle::{distance, within_exact}`) on generated scenes and the
//! stored meshes (`../shared/meshes`, skipped when absent).
//!
//! For each scene, every body pair whose triangle-count product keeps the brute force quick
//! (at most 6e7 pairs; larger pairs are checked at fewer steps, larger stored meshes skipped, and the table says so),
//! at every checked step:
//! - `distance`: `|frcd - oracle| <= 2 · error_bound` (both are float evaluations of the same
//!   exact quantity, each within the bound); the row prints the largest difference;
//! - `within`: at tolerances `0`, the oracle distance and `±1e-9` relative around it, equal to
//!   the oracle's exact (rational) label.

use anyhow::Result;
use frcd_benches::scenes::{self, Scene};
use frcd_geom::TriMesh;
use frcd_obb::distance::{DistanceRequest, distance, within};
use frcd_obb::{BuildOptions, ObbTree, oracle};
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

const MAX_PAIRS: f64 = 6e7;

fn generated() -> Vec<Scene> {
    vec![
        scenes::icospheres_sweep(3, 12),
        scenes::meshing_gears(8),
        scenes::wheelset_on_rails(8),
        scenes::torus_knots(64, 8, 8),
    ]
}

fn stored(dir: &Path) -> Result<Vec<Scene>> {
    let mut out = Vec::new();
    for (name, mesh) in crate::verify::stored_meshes(dir)? {
        let n = mesh.triangle_count() as f64;
        if n * n > MAX_PAIRS {
            println!(
                "{:<34} {:<36} SKIP ({} triangles: brute force too slow)",
                format!("stored/{name}"),
                "distance",
                mesh.triangle_count()
            );
            continue;
        }
        out.push(scenes::self_sweep(
            &format!("stored/{name}"),
            Arc::new(mesh),
            6,
        ));
    }
    Ok(out)
}

/// Runs the distance rows; returns the number of failing rows.
pub fn run(
    stored_dir: &Path,
    use_stored: bool,
    quick: bool,
    filter: Option<&str>,
) -> Result<usize> {
    let mut all = generated();
    if use_stored {
        if stored_dir.is_dir() {
            all.extend(stored(stored_dir)?);
        } else {
            println!(
                "SKIP stored meshes for distance: {} not found",
                stored_dir.display()
            );
        }
    }
    if quick {
        all = all.into_iter().map(|s| s.truncated(3)).collect();
    }
    if let Some(f) = filter {
        all.retain(|s| s.name.contains(f));
    }
    let mut failures = 0;
    let opts = BuildOptions::default();
    for scene in &all {
        let trees: Vec<ObbTree> = scene
            .bodies
            .iter()
            .map(|b| ObbTree::build(&b.mesh, &opts))
            .collect();
        let meshes: Vec<&TriMesh> = scene.bodies.iter().map(|b| b.mesh.as_ref()).collect();
        let mut pairs: Vec<(usize, usize)> = scene
            .body_pairs()
            .into_iter()
            .filter(|&(i, j)| {
                (meshes[i].triangle_count() as f64) * (meshes[j].triangle_count() as f64)
                    <= MAX_PAIRS
            })
            .collect();
        pairs.truncate(3);
        if pairs.is_empty() {
            println!(
                "{:<34} {:<36} SKIP (every body pair too large for the brute force)",
                scene.name, "distance"
            );
            continue;
        }
        // Large pairs: fewer steps.
        let biggest = pairs
            .iter()
            .map(|&(i, j)| meshes[i].triangle_count() as f64 * meshes[j].triangle_count() as f64)
            .fold(0.0, f64::max);
        let stride = if biggest > 3e6 {
            (scene.steps() / 3).max(1)
        } else {
            1
        };
        let t0 = Instant::now();
        let (mut checked, mut worst, mut worst_ratio, mut decisions) = (0, 0.0f64, 0.0f64, 0);
        let mut diffs: Vec<String> = Vec::new();
        for (step, frame) in scene.frames.iter().enumerate().step_by(stride) {
            for &(i, j) in &pairs {
                let (pa, pb) = (&frame[i], &frame[j]);
                let d = distance(&trees[i], pa, &trees[j], pb, &DistanceRequest::default());
                let o = oracle::distance(meshes[i], pa, meshes[j], pb);
                let diff = (d.distance - o.distance).abs();
                worst = worst.max(diff);
                worst_ratio = worst_ratio.max(diff / d.error_bound);
                checked += 1;
                if diff > 2.0 * d.error_bound {
                    diffs.push(format!(
                        "step {step} bodies ({i},{j}): distance {} oracle {} (bound {})",
                        d.distance, o.distance, d.error_bound
                    ));
                }
                let od = o.distance;
                for tol in [0.0, od, od * (1.0 - 1e-9), od * (1.0 + 1e-9)] {
                    let got = within(&trees[i], pa, &trees[j], pb, tol);
                    let want = oracle::within_exact(meshes[i], pa, meshes[j], pb, tol);
                    decisions += 1;
                    if got != want {
                        diffs.push(format!(
                            "step {step} bodies ({i},{j}): within({tol:e}) = {got}, exact {want}"
                        ));
                    }
                }
            }
        }
        let status = if diffs.is_empty() {
            "ok".to_string()
        } else {
            failures += 1;
            format!("DIFFERS ({} differences)", diffs.len())
        };
        println!(
            "{:<34} {:<36} {:>7} {:>9.1}  {status}: {checked} distances (max |diff| {worst:.1e}, {worst_ratio:.2} bounds), {decisions} within",
            scene.name,
            "distance+within vs oracle",
            checked,
            t0.elapsed().as_secs_f64() * 1e3
        );
        for d in diffs.iter().take(5) {
            println!("    {d}");
        }
    }
    Ok(failures)
}
