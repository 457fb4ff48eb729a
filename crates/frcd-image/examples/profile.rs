//! Times a few queries at a given resolution on the headless adapter:
//! `cargo run --release -p frcd-image --example profile -- 2048`.

use frcd_geom::{DQuat, DVec3, Pose, shapes};
use frcd_image::{ImageDetector, ImageOptions, ImageScratch};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let res: u32 = std::env::args().nth(1).map_or(Ok(1024), |s| s.parse())?;
    let det = ImageDetector::headless()?;
    println!("{}", det.context().adapter_name());
    let cube = det.upload("cube", &shapes::cuboid(DVec3::ONE))?;
    let ball = det.upload("ball", &shapes::icosphere(1.0, 5))?;
    let o = ImageOptions {
        resolution: res,
        ..Default::default()
    };
    let mut scratch = ImageScratch::default();
    for (name, m, pose) in [
        (
            "boxes",
            &cube,
            Pose::new(DVec3::new(1.2, 0.3, 0.4), DQuat::from_rotation_z(0.5)),
        ),
        (
            "lens",
            &ball,
            Pose::from_translation(DVec3::ONE.normalize() * 1.5),
        ),
    ] {
        for _ in 0..3 {
            let t0 = Instant::now();
            let r = det.query(&mut scratch, m, &Pose::IDENTITY, m, &pose, &o)?;
            println!(
                "{name} {res}: {:.1} ms, {} px, layers {:?}",
                t0.elapsed().as_secs_f64() * 1e3,
                r.interfering_pixels,
                r.layers
            );
        }
    }
    Ok(())
}
