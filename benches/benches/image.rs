//! Criterion benches of the image-space detector (frcd-image): one query (peeling, parity,
//! resolve, readback) against resolution, on two icospheres and two boxes. Runs on whatever
//! adapter wgpu finds (lavapipe without a GPU); prints SKIP and measures nothing without one.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use frcd_geom::{DQuat, DVec3, Pose, shapes};
use frcd_image::{ImageDetector, ImageOptions, ImageScratch};
use std::hint::black_box;

fn image(c: &mut Criterion) {
    let det = match ImageDetector::headless() {
        Ok(d) => d,
        Err(e) => {
            println!("SKIP image benches: {e}");
            return;
        }
    };
    let ball = det.upload("ball", &shapes::icosphere(1.0, 4)).unwrap();
    let cube = det.upload("cube", &shapes::cuboid(DVec3::ONE)).unwrap();
    let lens_pose = Pose::from_translation(DVec3::ONE.normalize() * 1.5);
    let box_pose = Pose::new(DVec3::new(1.2, 0.3, 0.4), DQuat::from_rotation_z(0.5));
    let mut group = c.benchmark_group(format!("image/{}", det.context().adapter_name()));
    group.sample_size(10);
    let mut scratch = ImageScratch::default();
    for res in [64u32, 256, 1024] {
        let o = ImageOptions {
            resolution: res,
            ..Default::default()
        };
        group.bench_with_input(BenchmarkId::new("lens_5120tri", res), &o, |bench, o| {
            bench.iter(|| {
                black_box(
                    det.query(&mut scratch, &ball, &Pose::IDENTITY, &ball, &lens_pose, o)
                        .unwrap()
                        .volume,
                )
            })
        });
        group.bench_with_input(BenchmarkId::new("boxes", res), &o, |bench, o| {
            bench.iter(|| {
                black_box(
                    det.query(&mut scratch, &cube, &Pose::IDENTITY, &cube, &box_pose, o)
                        .unwrap()
                        .volume,
                )
            })
        });
    }
    group.finish();
}

criterion_group!(benches, image);
criterion_main!(benches);
