//! Writes the `obb` bench's pair classes (dense sweep, near-contact knots, slow coherent knots,
//! the CAD pairs) as plain text, so that a peer built outside this repository (PQP 1.3's
//! `PQP_Collide`) can time exactly the same steps and check its answers against frcd's. Nothing
//! is timed here.
//!
//! ```text
//! FRCD_COLLIDE_EXPORT=/tmp/export cargo bench -p frcd-benches --bench collide_export
//! ```
//!
//! One file per scene, `<name>.txt`: for each of the two meshes its triangle count, then one
//! line of nine coordinates per triangle (mesh-local, `%.17g`); then the step count, and per
//! step one line: A's rotation (row-major) and translation, B's rotation and translation
//! (twelve numbers each), frcd's first-contact answer (0/1) and its number of touching
//! triangle pairs (exact test).

#[path = "common/cad.rs"]
mod cad;

use frcd_benches::scenes::{self, Scene};
use frcd_geom::{Pose, TriMesh};
use frcd_obb::{BuildOptions, Mode, ObbTree, Request, collide};
use std::fmt::Write as _;

fn mesh_text(out: &mut String, m: &TriMesh) {
    let _ = writeln!(out, "{}", m.triangle_count());
    for t in m.triangles() {
        let v = t.v;
        let _ = writeln!(
            out,
            "{:e} {:e} {:e} {:e} {:e} {:e} {:e} {:e} {:e}",
            v[0].x, v[0].y, v[0].z, v[1].x, v[1].y, v[1].z, v[2].x, v[2].y, v[2].z
        );
    }
}

fn pose_text(out: &mut String, p: &Pose) {
    let r = p.rotation_matrix();
    for row in 0..3 {
        let v = r.row(row);
        let _ = write!(out, "{:e} {:e} {:e} ", v.x, v.y, v.z);
    }
    let t = p.translation;
    let _ = write!(out, "{:e} {:e} {:e} ", t.x, t.y, t.z);
}

fn export(dir: &std::path::Path, scene: &Scene) -> std::io::Result<()> {
    let (ma, mb) = (&scene.bodies[0].mesh, &scene.bodies[1].mesh);
    let opts = BuildOptions::default();
    let (ta, tb) = (ObbTree::build(ma, &opts), ObbTree::build(mb, &opts));
    let first = Request::default();
    let all = Request {
        mode: Mode::AllPairs,
        ..Request::default()
    };
    let mut out = String::new();
    mesh_text(&mut out, ma);
    mesh_text(&mut out, mb);
    let _ = writeln!(out, "{}", scene.steps());
    for f in &scene.frames {
        pose_text(&mut out, &f[0]);
        pose_text(&mut out, &f[1]);
        let touching = collide(&ta, &f[0], &tb, &f[1], &first).collide;
        let pairs = collide(&ta, &f[0], &tb, &f[1], &all).pairs.len();
        let _ = writeln!(out, "{} {}", touching as u8, pairs);
    }
    // Written whole to a temporary name, then renamed: never a half-written file.
    let path = dir.join(format!("{}.txt", scene.name));
    let tmp = dir.join(format!(".{}.txt.partial", scene.name));
    std::fs::write(&tmp, out)?;
    std::fs::rename(&tmp, &path)?;
    eprintln!("[export] {}", path.display());
    Ok(())
}

fn main() {
    let Some(dir) = std::env::var_os("FRCD_COLLIDE_EXPORT") else {
        eprintln!(
            "collide_export: set FRCD_COLLIDE_EXPORT=DIR to write the scenes (nothing to do)"
        );
        return;
    };
    let dir = std::path::PathBuf::from(dir);
    if let Err(e) = std::fs::create_dir_all(&dir) {
        eprintln!("collide_export: cannot create {}: {e}", dir.display());
        std::process::exit(1);
    }
    let mut dense = scenes::icospheres_sweep(5, 200);
    dense.name = format!("dense_{}", dense.name);
    let mut list = vec![
        dense,
        scenes::knots_near_contact(500),
        scenes::knots_slow_rotation(200),
    ];
    list.extend(cad::cad_scenes());
    for s in &list {
        if let Err(e) = export(&dir, s) {
            eprintln!("collide_export: {}: {e}", s.name);
            std::process::exit(1);
        }
    }
}
