//! Triangle-triangle tests: time per test for every method at intersection ratios 0-100 %.
//!
//! Workload: vertices uniform in the unit cube, pairs kept by exact label until each class's
//! quota is met (both classes from one distribution), shuffled. One criterion group per ratio,
//! every method on the same pair set; throughput is reported per triangle pair.
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use frcd_benches::tritri_pairs::{RATIOS, pairs_at_ratio};
use frcd_tritri::{Method, intersects};
use std::hint::black_box;

const PAIRS: usize = 5000;

fn bench(c: &mut Criterion) {
    for ratio in RATIOS {
        let pairs = pairs_at_ratio(PAIRS, ratio, 42);
        let mut g = c.benchmark_group(format!("tritri/ratio{ratio:03}"));
        g.throughput(Throughput::Elements(pairs.len() as u64));
        for m in Method::ALL {
            g.bench_function(m.name(), |b| {
                b.iter(|| {
                    let mut n = 0usize;
                    for (x, y) in &pairs {
                        n += intersects(black_box(m), black_box(x), black_box(y)) as usize;
                    }
                    n
                })
            });
        }
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
