//! `cargo run -p frcd-io --example meshinfo -- FILE...`: loads meshes (or a scene, for `.json`)
//! and prints what frcd sees, or the error.

fn main() {
    let mut failed = false;
    for arg in std::env::args().skip(1) {
        if arg.ends_with(".json") {
            match frcd_io::Scene::load(&arg) {
                Ok(s) => println!(
                    "{arg}: {} bodies, {} meshes, {} triangles, {} frames, {} exclusions",
                    s.bodies().len(),
                    s.meshes().len(),
                    s.triangle_count(),
                    s.frame_count(),
                    s.exclusions().len()
                ),
                Err(e) => {
                    failed = true;
                    eprintln!("error: {e}");
                }
            }
            continue;
        }
        match frcd_io::load_mesh(&arg) {
            Ok(m) => {
                let t = m.topology();
                println!(
                    "{arg}: {} triangles, {} vertices, closed {}, components {}, degenerate {}, volume {:.6e}",
                    m.triangle_count(),
                    m.vertex_count(),
                    t.is_closed_oriented_manifold(),
                    t.components,
                    m.report().degenerate.len(),
                    m.signed_volume()
                );
            }
            Err(e) => {
                failed = true;
                eprintln!("error: {e}");
            }
        }
    }
    if failed {
        std::process::exit(1);
    }
}
