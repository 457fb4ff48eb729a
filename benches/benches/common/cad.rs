//! The CAD class of the OBB benches: real meshes from `../shared/meshes` at random poses near
//! first contact (incoherent), shared by the `obb` bench and the peers' export so both time the
//! very same steps. SKIP (on stderr) for a pair whose files are absent.

use frcd_benches::scenes::{self, Scene};
use frcd_obb::{BuildOptions, Mode, ObbTree, Request, collide};
use std::sync::Arc;

/// The three CAD pairs, 100 random poses each near first contact (seeded: identical run to run).
pub fn cad_scenes() -> Vec<Scene> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/meshes");
    let load = |f: &str| frcd_io::load_mesh(dir.join(f)).ok().map(Arc::new);
    let pairs = [
        (
            "cad_wagon_bogie",
            "railway_3dprintedtrains/intermodal_wagon_no_visible_container_holes_binary.stl",
            "railway_3dprintedtrains/bogie.stl",
        ),
        (
            "cad_bogie_pair",
            "railway_3dprintedtrains/bogie.stl",
            "railway_3dprintedtrains/bogie.stl",
        ),
        (
            "cad_fandisk_pair",
            "mechanical_trimesh/fandisk.obj",
            "mechanical_trimesh/fandisk.obj",
        ),
    ];
    let mut out = Vec::new();
    for (k, (name, fa, fb)) in pairs.into_iter().enumerate() {
        let (Some(a), Some(b)) = (load(fa), load(fb)) else {
            eprintln!(
                "SKIP {name}: {fa} or {fb} not found under {}",
                dir.display()
            );
            continue;
        };
        let (ta, tb) = (
            ObbTree::build(&a, &BuildOptions::default()),
            ObbTree::build(&b, &BuildOptions::default()),
        );
        let r = Request {
            mode: Mode::FirstContact,
            ..Request::default()
        };
        out.push(scenes::random_near_contact(
            name,
            a,
            b,
            100,
            0.01,
            0xCAD0 + k as u64,
            |pb| collide(&ta, &frcd_geom::Pose::IDENTITY, &tb, pb, &r).collide,
        ));
    }
    out
}
