//! Triangle-pair workloads for the tri-tri benchmarks (`benches/tritri.rs`, `cargo xtask bench
//! tritri`): the Shen et al. harness setting, vertices uniform in the unit cube, pairs mixed at a
//! chosen intersection ratio.
use frcd_geom::{DVec3, Triangle};
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};

/// The intersection ratios the benchmarks sweep, in percent.
pub const RATIOS: [u32; 5] = [0, 25, 50, 75, 100];

/// A triangle with vertices uniform in the unit cube, rejecting (near-)collinear ones as the
/// Shen et al. generator does.
pub fn unit_cube_triangle(rng: &mut impl Rng) -> Triangle {
    loop {
        let mut p = || DVec3::new(rng.random(), rng.random(), rng.random());
        let t = Triangle::new(p(), p(), p());
        if t.area() > 1e-6 {
            return t;
        }
    }
}

/// `n` random pairs of which `round(n·percent/100)` intersect, labelled by
/// [`frcd_tritri::exact`]: pairs are drawn from one distribution and kept until each class's
/// quota is met, so both classes follow the same distribution; the result is shuffled.
/// Deterministic for a given `seed`.
pub fn pairs_at_ratio(n: usize, percent: u32, seed: u64) -> Vec<(Triangle, Triangle)> {
    let mut rng =
        StdRng::seed_from_u64(seed ^ (percent as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15));
    let want_hit = (n * percent as usize + 50) / 100;
    let want_miss = n - want_hit;
    let (mut hit, mut miss) = (Vec::with_capacity(want_hit), Vec::with_capacity(want_miss));
    while hit.len() < want_hit || miss.len() < want_miss {
        let a = unit_cube_triangle(&mut rng);
        let b = unit_cube_triangle(&mut rng);
        if frcd_tritri::exact(&a, &b) {
            if hit.len() < want_hit {
                hit.push((a, b));
            }
        } else if miss.len() < want_miss {
            miss.push((a, b));
        }
    }
    hit.append(&mut miss);
    hit.shuffle(&mut rng);
    hit
}
