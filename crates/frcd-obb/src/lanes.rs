//! Four f32 lanes as a plain array the compiler vectorises (SSE on the x86-64 baseline, NEON on
//! aarch64; no unsafe code, no runtime detection). Only what the box test needs; every operation
//! is the IEEE one (no fused multiply-add: the error bounds of `sat.rs` count one rounding per
//! operation).

mod imp {
    /// Four f32 lanes.
    #[derive(Clone, Copy, Debug)]
    #[repr(C, align(16))]
    pub(crate) struct F4([f32; 4]);

    impl F4 {
        #[inline(always)]
        fn map2(self, o: F4, f: impl Fn(f32, f32) -> f32) -> F4 {
            F4([
                f(self.0[0], o.0[0]),
                f(self.0[1], o.0[1]),
                f(self.0[2], o.0[2]),
                f(self.0[3], o.0[3]),
            ])
        }
        #[inline(always)]
        pub fn load(a: &[f32; 4]) -> F4 {
            F4(*a)
        }
        #[inline(always)]
        pub fn lane(self, k: u32) -> f32 {
            self.0[k as usize & 3]
        }
        #[cfg(test)]
        pub fn to_array(self) -> [f32; 4] {
            self.0
        }
        #[inline(always)]
        pub fn new(a: f32, b: f32, c: f32, d: f32) -> F4 {
            F4([a, b, c, d])
        }
        #[inline(always)]
        pub fn splat(x: f32) -> F4 {
            F4([x; 4])
        }
        #[inline(always)]
        pub fn add(self, o: F4) -> F4 {
            self.map2(o, |a, b| a + b)
        }
        #[inline(always)]
        pub fn sub(self, o: F4) -> F4 {
            self.map2(o, |a, b| a - b)
        }
        #[inline(always)]
        pub fn mul(self, o: F4) -> F4 {
            self.map2(o, |a, b| a * b)
        }
        #[inline(always)]
        pub fn abs(self) -> F4 {
            F4(self.0.map(f32::abs))
        }
        #[inline(always)]
        pub fn zero3(self) -> F4 {
            F4([self.0[0], self.0[1], self.0[2], 0.0])
        }
        #[inline(always)]
        pub fn shuf<const IMM: i32>(self) -> F4 {
            let i = |k: i32| self.0[((IMM >> (2 * k)) & 3) as usize];
            F4([i(0), i(1), i(2), i(3)])
        }
        #[inline(always)]
        pub fn positive(self) -> u32 {
            (0..4).fold(0, |m, k| m | ((self.0[k] > 0.0) as u32) << k)
        }
    }

    /// Lanes 0..3 of three vectors transposed: `out[k][i] = v[i][k]`, lane 3 of the results
    /// zero.
    #[inline(always)]
    pub(crate) fn transpose3(v: [F4; 3]) -> [F4; 3] {
        let r = |k: usize| F4([v[0].0[k], v[1].0[k], v[2].0[k], 0.0]);
        [r(0), r(1), r(2)]
    }
}

pub(crate) use imp::{F4, transpose3};

/// The shuffle immediate of `(v[a], v[b], v[c], v[d])`.
pub(crate) const fn sel(a: i32, b: i32, c: i32, d: i32) -> i32 {
    a | b << 2 | c << 4 | d << 6
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lanes_do_what_they_say() {
        let a = F4::new(1.0, -2.0, 3.0, -4.0);
        let b = F4::splat(0.5);
        assert_eq!(a.add(b).to_array(), [1.5, -1.5, 3.5, -3.5]);
        assert_eq!(a.sub(b).to_array(), [0.5, -2.5, 2.5, -4.5]);
        assert_eq!(a.mul(b).to_array(), [0.5, -1.0, 1.5, -2.0]);
        assert_eq!(a.abs().to_array(), [1.0, 2.0, 3.0, 4.0]);
        assert_eq!(a.zero3().to_array(), [1.0, -2.0, 3.0, 0.0]);
        assert_eq!(
            a.shuf::<{ sel(3, 0, 2, 1) }>().to_array(),
            [-4.0, 1.0, 3.0, -2.0]
        );
        assert_eq!(a.positive(), 0b0101);
        assert_eq!(F4::new(f32::NAN, 0.0, -0.0, 1e-45).positive(), 0b1000);
        assert_eq!(F4::load(&[1.0, 2.0, 3.0, 4.0]).to_array(), [1.0, 2.0, 3.0, 4.0]);
        let t = transpose3([
            F4::new(1.0, 2.0, 3.0, 9.0),
            F4::new(4.0, 5.0, 6.0, 9.0),
            F4::new(7.0, 8.0, -0.5, 9.0),
        ]);
        assert_eq!(t[0].to_array(), [1.0, 4.0, 7.0, 0.0]);
        assert_eq!(t[1].to_array(), [2.0, 5.0, 8.0, 0.0]);
        assert_eq!(t[2].to_array(), [3.0, 6.0, -0.5, 0.0]);
    }
}
