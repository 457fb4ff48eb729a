//! The world boxes of four bodies at once, for [`World::set_poses`](crate::World::set_poses):
//! each lane runs exactly the operations of `world_box` (the pose made rigid,
//! [`Aabb::transformed`], the relative margin) in the same order, so each box is the same bit
//! for bit, while the four lanes share each instruction.
//!
//! One body at a time, the transform is a chain of dependent 3-vector operations that glam
//! writes as a 128-bit half and a scalar each. The lanes are written once, over [`Lanes`]:
//! plain `[f64; 4]` for the baseline build (which the compiler leaves mostly scalar) and one
//! AVX2 register in the World's AVX2 build ([`avx::F64x4`]; the compiler did not vectorise the
//! plain lanes across 256 bits). No fused multiply-add in either, so both give the same bits.

use frcd_geom::{Aabb, DVec3, Pose};

/// Four f64 lanes and the operations the world box needs, each one IEEE operation per lane.
pub(super) trait Lanes: Copy {
    fn load(a: [f64; 4]) -> Self;
    fn store(self) -> [f64; 4];
    fn splat(x: f64) -> Self;
    fn add(self, o: Self) -> Self;
    fn sub(self, o: Self) -> Self;
    fn mul(self, o: Self) -> Self;
    fn abs(self) -> Self;
    /// glam's `max` (component-wise and `max_element`): `self` where `self > o`, else `o`.
    fn max(self, o: Self) -> Self;
}

impl Lanes for [f64; 4] {
    #[inline(always)]
    fn load(a: [f64; 4]) -> Self {
        a
    }
    #[inline(always)]
    fn store(self) -> [f64; 4] {
        self
    }
    #[inline(always)]
    fn splat(x: f64) -> Self {
        [x; 4]
    }
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        [
            self[0] + o[0],
            self[1] + o[1],
            self[2] + o[2],
            self[3] + o[3],
        ]
    }
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        [
            self[0] - o[0],
            self[1] - o[1],
            self[2] - o[2],
            self[3] - o[3],
        ]
    }
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        [
            self[0] * o[0],
            self[1] * o[1],
            self[2] * o[2],
            self[3] * o[3],
        ]
    }
    #[inline(always)]
    fn abs(self) -> Self {
        [self[0].abs(), self[1].abs(), self[2].abs(), self[3].abs()]
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        let m = |a: f64, b: f64| if a > b { a } else { b };
        [
            m(self[0], o[0]),
            m(self[1], o[1]),
            m(self[2], o[2]),
            m(self[3], o[3]),
        ]
    }
}

/// `[e(0), e(1), e(2)]` written out (`array::map` stays out of line here, a call per use).
macro_rules! arr3 {
    ($i:ident => $e:expr) => {
        [
            {
                let $i = 0usize;
                $e
            },
            {
                let $i = 1usize;
                $e
            },
            {
                let $i = 2usize;
                $e
            },
        ]
    };
}

/// `world_box(local[k], poses[k])` for each lane `k`, for local boxes that are not empty
/// (an empty one is returned as it is by [`Aabb::transformed`]: the caller takes that lane
/// one body at a time).
#[inline(always)]
pub(super) fn world_boxes4<V: Lanes>(local: &[Aabb; 4], poses: &[Pose; 4]) -> [Aabb; 4] {
    let poses = [
        poses[0].rigid(),
        poses[1].rigid(),
        poses[2].rigid(),
        poses[3].rigid(),
    ];
    let q = |f: fn(&Pose) -> f64| V::load([f(&poses[0]), f(&poses[1]), f(&poses[2]), f(&poses[3])]);
    let (x, y, z, w) = (
        q(|p| p.rotation.x),
        q(|p| p.rotation.y),
        q(|p| p.rotation.z),
        q(|p| p.rotation.w),
    );
    let t = [
        q(|p| p.translation.x),
        q(|p| p.translation.y),
        q(|p| p.translation.z),
    ];
    // `DMat3::from_quat`, columns `m[col][row]`.
    let (x2, y2, z2) = (x.add(x), y.add(y), z.add(z));
    let (xx, xy, xz) = (x.mul(x2), x.mul(y2), x.mul(z2));
    let (yy, yz, zz) = (y.mul(y2), y.mul(z2), z.mul(z2));
    let (wx, wy, wz) = (w.mul(x2), w.mul(y2), w.mul(z2));
    let one = V::splat(1.0);
    let m = [
        [one.sub(yy.add(zz)), xy.add(wz), xz.sub(wy)],
        [xy.sub(wz), one.sub(xx.add(zz)), yz.add(wx)],
        [xz.add(wy), yz.sub(wx), one.sub(xx.add(yy))],
    ];
    // `Aabb::center` and `half_extents` of the local boxes.
    let corner = |f: fn(&Aabb) -> DVec3, a: usize| {
        V::load([
            f(&local[0])[a],
            f(&local[1])[a],
            f(&local[2])[a],
            f(&local[3])[a],
        ])
    };
    let half = V::splat(0.5);
    let lc = arr3!(a => half.mul(corner(|b| b.min, a).add(corner(|b| b.max, a))));
    let h = arr3!(a => half.mul(corner(|b| b.max, a).sub(corner(|b| b.min, a))));
    // `m * lc + t` and `|m| * h`, as glam's `mul_vec3` (x column, then y, then z).
    let c = arr3!(r => m[0][r]
        .mul(lc[0])
        .add(m[1][r].mul(lc[1]))
        .add(m[2][r].mul(lc[2]))
        .add(t[r]));
    let e = arr3!(r => m[0][r]
        .abs()
        .mul(h[0])
        .add(m[1][r].abs().mul(h[1]))
        .add(m[2][r].abs().mul(h[2])));
    // The local 1-norms, `local_c.abs().element_sum() + h.element_sum()`.
    let local_sum = lc[0]
        .abs()
        .add(lc[1].abs())
        .add(lc[2].abs())
        .add(h[0].add(h[1]).add(h[2]));
    let eps16 = V::splat(16.0 * f64::EPSILON);
    let slack = arr3!(r => c[r].abs().add(e[r]).add(t[r].abs()).add(local_sum).mul(eps16));
    let bmin = arr3!(r => c[r].sub(e[r]).sub(slack[r]));
    let bmax = arr3!(r => c[r].add(e[r]).add(slack[r]));
    // `world_box`'s relative margin: the largest coordinate magnitude, `max_element` (x
    // against the max of y and z) of the component-wise `max` of the two corners' magnitudes.
    let top = arr3!(r => bmin[r].abs().max(bmax[r].abs()));
    let mag = top[0].max(top[1].max(top[2]));
    let d = mag.mul(V::splat(1e-12)).add(V::splat(f64::MIN_POSITIVE));
    let lo = arr3!(r => bmin[r].sub(d).store());
    let hi = arr3!(r => bmax[r].add(d).store());
    let out = |k: usize| Aabb {
        min: DVec3::new(lo[0][k], lo[1][k], lo[2][k]),
        max: DVec3::new(hi[0][k], hi[1][k], hi[2][k]),
    };
    [out(0), out(1), out(2), out(3)]
}

/// The lanes in one AVX2 register (the World's AVX2 build).
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
pub(super) mod avx {
    use super::Lanes;
    use std::arch::x86_64::*;

    /// Four f64 in one 256-bit register. Only made inside the World's AVX2 build, where its
    /// intrinsics inline as single instructions.
    #[derive(Clone, Copy)]
    pub(in crate::world) struct F64x4(__m256d);

    // SAFETY (every method): values of this type exist only in code that runs after the CPU
    // was found to have AVX2 (`World::set_poses`, `isa::has_avx2`).
    impl Lanes for F64x4 {
        #[inline(always)]
        fn load(a: [f64; 4]) -> Self {
            unsafe { F64x4(_mm256_loadu_pd(a.as_ptr())) }
        }
        #[inline(always)]
        fn store(self) -> [f64; 4] {
            let mut a = [0.0; 4];
            unsafe { _mm256_storeu_pd(a.as_mut_ptr(), self.0) };
            a
        }
        #[inline(always)]
        fn splat(x: f64) -> Self {
            unsafe { F64x4(_mm256_set1_pd(x)) }
        }
        #[inline(always)]
        fn add(self, o: Self) -> Self {
            unsafe { F64x4(_mm256_add_pd(self.0, o.0)) }
        }
        #[inline(always)]
        fn sub(self, o: Self) -> Self {
            unsafe { F64x4(_mm256_sub_pd(self.0, o.0)) }
        }
        #[inline(always)]
        fn mul(self, o: Self) -> Self {
            unsafe { F64x4(_mm256_mul_pd(self.0, o.0)) }
        }
        #[inline(always)]
        fn abs(self) -> Self {
            unsafe { F64x4(_mm256_andnot_pd(_mm256_set1_pd(-0.0), self.0)) }
        }
        #[inline(always)]
        fn max(self, o: Self) -> Self {
            // `vmaxpd a, b` is `a > b ? a : b` lane by lane (NaN in either gives `b`), as
            // glam's `max`.
            unsafe { F64x4(_mm256_max_pd(self.0, o.0)) }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use frcd_geom::DQuat;

    /// The same bits as one body at a time (NaN as NaN), in both builds, over random boxes
    /// and poses, far offsets, huge and tiny sizes, quaternions a little off unit length, and
    /// overflow to infinity and NaN.
    #[test]
    fn four_lanes_equal_one_body_at_a_time() {
        let mut bits = crate::test_rng::xorshift(0x9E37_79B9_7F4A_7C15);
        let mut rnd = move || (bits() >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0;
        let same = |a: f64, b: f64| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
        let (mut checked, mut nan, mut inf) = (0, 0, 0);
        for round in 0..4000 {
            let scale = [1.0, 1e-9, 1e6, 1e300, 1e-300, 1e308][round % 6];
            let offset = [0.0, 1e3, 1e8, 1e307, f64::MAX][(round / 6) % 5];
            let mut local = [Aabb::EMPTY; 4];
            let mut poses = [Pose::IDENTITY; 4];
            for k in 0..4 {
                let h = DVec3::new(rnd().abs(), rnd().abs(), rnd().abs()) * scale;
                // Every seventh round: unrotated boxes moved so that a corner lands on the
                // origin, where the world box's corner is the slack alone (so every bit of
                // the slack shows).
                let edge = round % 7 == 0;
                let shift = DVec3::new(rnd(), rnd(), rnd()) * scale;
                let c = if edge {
                    h + shift
                } else {
                    DVec3::new(rnd(), rnd(), rnd()) * scale
                };
                local[k] = Aabb::new(c - h, c + h);
                let q = if edge {
                    DQuat::IDENTITY
                } else {
                    DQuat::from_xyzw(rnd(), rnd(), rnd(), rnd()).normalize()
                };
                // Some quaternions off unit length by up to the World's 1e-9 tolerance.
                let q = if round % 3 == 0 {
                    q * (1.0 + 4e-10 * rnd())
                } else {
                    q
                };
                let t = if edge {
                    -shift
                } else {
                    DVec3::new(rnd(), rnd(), rnd()) * offset
                };
                poses[k] = Pose {
                    translation: t,
                    rotation: q,
                };
            }
            let mut builds = vec![world_boxes4::<[f64; 4]>(&local, &poses)];
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2.
                #[allow(unsafe_code)]
                builds.push(unsafe { avx2_boxes(&local, &poses) });
            }
            for four in builds {
                for k in 0..4 {
                    let one = super::super::world_box(&local[k], &poses[k]);
                    for a in 0..3 {
                        assert!(
                            same(four[k].min[a], one.min[a]) && same(four[k].max[a], one.max[a]),
                            "round {round} lane {k}: {:?} against {:?}",
                            four[k],
                            one
                        );
                    }
                    nan += one.min.is_nan() as usize;
                    inf += (one.max.is_finite() || one.min.is_nan()) as usize ^ 1;
                    checked += 1;
                }
            }
        }
        assert!(checked >= 16_000);
        assert!(
            nan > 100 && inf > 100,
            "overflow is covered: {nan} NaN, {inf} infinite"
        );
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[allow(unsafe_code)]
    unsafe fn avx2_boxes(local: &[Aabb; 4], poses: &[Pose; 4]) -> [Aabb; 4] {
        world_boxes4::<avx::F64x4>(local, poses)
    }
}
