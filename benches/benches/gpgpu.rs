//! GPGPU pipeline against the CPU OBB traversal, by mesh size: one pair query (all touching
//! pairs) of two crossing icospheres, transfers included on the GPU side (pose upload, one
//! submission, one readback, CPU re-decision of uncertain pairs); and the many-body box pass
//! against the CPU's all-pairs box test. Without a GPU adapter the GPU rows print SKIP.
//!
//! `cargo bench -p frcd-benches --bench gpgpu`; the table with the crossover comes from
//! `cargo xtask bench gpgpu`.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use frcd_geom::{Aabb, DQuat, DVec3, Pose, shapes};
use frcd_gpgpu::{BoxScratch, GpuContext, QueryScratch};
use frcd_obb::{BuildOptions, Mode, ObbTree, Request, collide};
use std::hint::black_box;

fn pair_queries(c: &mut Criterion) {
    let ctx = match GpuContext::headless() {
        Ok(ctx) => Some(ctx),
        Err(e) => {
            println!("SKIP gpgpu rows: {e}");
            None
        }
    };
    let mut group = c.benchmark_group("gpgpu/pair_query");
    group.sample_size(10);
    let request = Request {
        mode: Mode::AllPairs,
        ..Request::default()
    };
    let pa = Pose::IDENTITY;
    let pb = Pose::new(DVec3::new(0.95, 0.2, -0.1), DQuat::from_rotation_x(1.0));
    for level in [2u32, 3, 4, 5] {
        let mesh = shapes::icosphere(1.0, level);
        let tree = ObbTree::build(&mesh, &BuildOptions::default());
        let n = mesh.triangle_count();
        group.bench_with_input(BenchmarkId::new("cpu_obb", n), &tree, |b, t| {
            b.iter(|| black_box(collide(t, &pa, t, &pb, &request)))
        });
        if let Some(ctx) = &ctx {
            let gpu = ctx.upload(&tree).expect("upload");
            let mut scratch = QueryScratch::default();
            let want = collide(&tree, &pa, &tree, &pb, &request).pairs;
            let got = ctx
                .collide(&gpu, &pa, &gpu, &pb, &mut scratch)
                .expect("query");
            assert_eq!(got.pairs, want, "GPU and CPU disagree at level {level}");
            group.bench_with_input(BenchmarkId::new("gpu", n), &gpu, |b, g| {
                b.iter(|| black_box(ctx.collide(g, &pa, g, &pb, &mut scratch).expect("query")))
            });
        }
    }
    group.finish();

    let mut group = c.benchmark_group("gpgpu/body_boxes");
    group.sample_size(10);
    for n in [100usize, 1000, 4000] {
        let side = (n as f64 / 4.0).cbrt() * 2.0;
        let boxes: Vec<Aabb> = (0..n)
            .map(|i| {
                let f = |k: u64| ((i as u64 * 2654435761 + k * 40503) % 10007) as f64 / 10007.0;
                let c = DVec3::new(f(1), f(2), f(3)) * side;
                let h = DVec3::splat(0.3 + 0.4 * f(4));
                Aabb::new(c - h, c + h)
            })
            .collect();
        group.bench_with_input(BenchmarkId::new("cpu_all_pairs", n), &boxes, |b, boxes| {
            b.iter(|| {
                let mut count = 0usize;
                for i in 0..boxes.len() {
                    for j in i + 1..boxes.len() {
                        count += boxes[i].intersects(&boxes[j]) as usize;
                    }
                }
                black_box(count)
            })
        });
        if let Some(ctx) = &ctx {
            let mut scratch = BoxScratch::default();
            group.bench_with_input(BenchmarkId::new("gpu", n), &boxes, |b, boxes| {
                b.iter(|| black_box(ctx.overlapping_bodies(boxes, &mut scratch).expect("boxes")))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, pair_queries);
criterion_main!(benches);
