//! Exact orientation predicates on f64 input points.
//!
//! Every predicate returns the sign of the exact determinant of its (finite) f64 inputs, as if the
//! arithmetic were done with real numbers. Three stages:
//!
//! 1. **Filter**: the determinant in plain f64 plus Shewchuk's stage-A error bound computed from
//!    the permanent (`(7+56ε)ε·perm` for 3D, `(3+16ε)ε·perm` for 2D, ε = 2⁻⁵³), widened by an
//!    absolute term that covers underflow (`(M+1)·2⁻¹⁰⁷⁰`, `M` = the largest difference), and only
//!    trusted when no difference exceeds 2³⁰⁰ (no overflow). Almost every call ends here.
//! 2. **Exact expansions**: in 3D the 3×3 determinant of the differences to the first point,
//!    each difference an exact two-term expansion (`two_sum`; the tail is zero for nearby
//!    points), expanded into at most 48 triple products; in 2D the homogeneous `[x y 1]`
//!    determinant (6 products of raw coordinates). Each product is split exactly into four (two)
//!    doubles with Dekker's `two_product`; the sign of the exact sum comes from repeated error-free `two_sum`
//!    sweeps until the leading term dominates, or, when that does not settle (exact zeros), from
//!    an exact fixed-point accumulator of the terms. Before that every
//!    coordinate axis is scaled by its own exact power of two (the determinant is linear in each
//!    column, so the sign is unchanged) so that all non-zero coordinates lie in `[2⁻³⁰⁰, 2³⁰⁰]`:
//!    then no product underflows or overflows and every step is exact. Tiny and subnormal
//!    coordinates take this path.
//! 3. **Big integers**: when one axis spans more than 600 binades (say `1e-300` and `1e8` in the
//!    same coordinate), no single scale works; every coordinate is then converted to an exact
//!    integer multiple of `2⁻¹⁰⁷⁴` and the same sum is evaluated with `num-bigint`.
//!
//! [`orient3d_filter`] exposes the stage-1 value and bound for callers (such as the tri-tri tests)
//! that want to reason about the float value.
use glam::{DVec2, DVec3};
use num_bigint::BigInt;

/// Machine epsilon in Shewchuk's sense: half an ulp of 1, 2⁻⁵³.
pub const EPS: f64 = 1.110_223_024_625_156_5e-16;
/// Stage-A error bound factor for [`orient3d`], `(7 + 56ε)ε`.
pub const O3D_ERRBOUND_A: f64 = (7.0 + 56.0 * EPS) * EPS;
/// Stage-A error bound factor for [`orient2d`], `(3 + 16ε)ε`.
pub const O2D_ERRBOUND_A: f64 = (3.0 + 16.0 * EPS) * EPS;
/// Absolute slack that covers the underflow of a handful of products.
///
/// The underflow error of the filter's products is at most `(m + 1) · 2⁻¹⁰⁷⁰` for the largest
/// difference `m`; the filter only trusts `m ≤ 2³⁰⁰`, so `2⁻⁷⁰⁰` covers it with room to spare. It is
/// a *normal* constant on purpose: computing `(m + 1) · 2⁻¹⁰⁷⁰` per call is a subnormal multiply,
/// which measured about 20x slower than the whole rest of the filter on x86. Values with
/// `|det| ≤ 2⁻⁷⁰⁰` simply go to the exact stage.
const UNDERFLOW_SLACK: f64 = f64::from_bits((1023 - 700) << 52);
/// Differences above this magnitude are not trusted to the filter (overflow).
const FILTER_MAX: f64 = f64::from_bits((1023 + 300) << 52);

#[inline]
fn sign(v: f64) -> i8 {
    if v > 0.0 {
        1
    } else if v < 0.0 {
        -1
    } else {
        0
    }
}

/// The stage-1 filter of [`orient3d`]: the f64 value of `det[b-a, c-a, d-a]` and a bound on its
/// error. When `|value| > bound` the sign of `value` is the exact sign. The bound is `+∞` when the
/// inputs are outside the range where the bound is proven (huge differences, NaN).
#[inline]
pub fn orient3d_filter(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> (f64, f64) {
    let u = b - a;
    let v = c - a;
    let w = d - a;
    let vywz = v.y * w.z;
    let vzwy = v.z * w.y;
    let vzwx = v.z * w.x;
    let vxwz = v.x * w.z;
    let vxwy = v.x * w.y;
    let vywx = v.y * w.x;
    let det = u.x * (vywz - vzwy) + u.y * (vzwx - vxwz) + u.z * (vxwy - vywx);
    let perm = u.x.abs() * (vywz.abs() + vzwy.abs())
        + u.y.abs() * (vzwx.abs() + vxwz.abs())
        + u.z.abs() * (vxwy.abs() + vywx.abs());
    let m = u.abs().max(v.abs()).max(w.abs()).max_element();
    // NaN differences (non-finite input) are never trusted.
    if m.is_nan() || m > FILTER_MAX {
        return (det, f64::INFINITY);
    }
    (det, O3D_ERRBOUND_A * perm + UNDERFLOW_SLACK)
}

/// Sign of the determinant `[b-a, c-a, d-a]` = `(d-a)·((b-a)×(c-a))`, exactly, as `-1`, `0` or `1`.
///
/// Positive when `d` lies on the side of the plane `(a, b, c)` that `(b-a)×(c-a)` points to.
/// Exact for every finite input (see the module docs); non-finite input gives an unspecified sign.
///
/// ```
/// use frcd_geom::{DVec3, predicates::orient3d};
/// let (a, b, c) = (DVec3::ZERO, DVec3::X, DVec3::Y);
/// assert_eq!(orient3d(a, b, c, DVec3::Z), 1);
/// assert_eq!(orient3d(a, b, c, DVec3::new(0.3, 0.3, 0.0)), 0);
/// // 0.1 + 0.2 != 0.3 in f64: the point (0.1, 0.2, ·) vs the plane x + y = 0.3 is decided exactly.
/// let p = DVec3::new(0.3, 0.0, 0.0);
/// let q = DVec3::new(0.0, 0.3, 0.0);
/// assert_ne!(orient3d(p, q, p + DVec3::Z, DVec3::new(0.1, 0.2, 0.0)), 0);
/// ```
#[inline]
pub fn orient3d(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> i8 {
    let (det, bound) = orient3d_filter(a, b, c, d);
    if det > bound {
        1
    } else if -det > bound {
        -1
    } else {
        orient3d_exact(a, b, c, d)
    }
}

/// The stage-1 filter of [`orient2d`]: the f64 value of `(b-a)×(c-a)` and a bound on its error
/// (`+∞` when not proven, see [`orient3d_filter`]).
#[inline]
pub fn orient2d_filter(a: DVec2, b: DVec2, c: DVec2) -> (f64, f64) {
    let u = b - a;
    let v = c - a;
    let l = u.x * v.y;
    let r = u.y * v.x;
    let det = l - r;
    let m = u.abs().max(v.abs()).max_element();
    if m.is_nan() || m > FILTER_MAX {
        return (det, f64::INFINITY);
    }
    (det, O2D_ERRBOUND_A * (l.abs() + r.abs()) + UNDERFLOW_SLACK)
}

/// Sign of `(b-a)×(c-a)` in 2D, exactly, as `-1`, `0` or `1` (positive: counter-clockwise).
///
/// ```
/// use frcd_geom::{DVec2, predicates::orient2d};
/// assert_eq!(orient2d(DVec2::ZERO, DVec2::X, DVec2::Y), 1);
/// assert_eq!(orient2d(DVec2::ZERO, DVec2::ONE, DVec2::splat(1e-310)), 0);
/// ```
#[inline]
pub fn orient2d(a: DVec2, b: DVec2, c: DVec2) -> i8 {
    let (det, bound) = orient2d_filter(a, b, c);
    if det > bound {
        1
    } else if -det > bound {
        -1
    } else {
        orient2d_exact(a, b, c)
    }
}

/// True when the three points are collinear (the triangle they span has zero area), exactly.
pub fn collinear3(a: DVec3, b: DVec3, c: DVec3) -> bool {
    let xy = |p: DVec3| DVec2::new(p.x, p.y);
    let yz = |p: DVec3| DVec2::new(p.y, p.z);
    let zx = |p: DVec3| DVec2::new(p.z, p.x);
    orient2d(xy(a), xy(b), xy(c)) == 0
        && orient2d(yz(a), yz(b), yz(c)) == 0
        && orient2d(zx(a), zx(b), zx(c)) == 0
}

// ---------------------------------------------------------------------------------------------
// Exact stages.

/// Terms of `det[b-a, c-a, d-a]` as a polynomial in raw coordinates: the 4×4 determinant
/// `|p x y z 1|` over the rows (a, b, c, d) expands into 24 signed triple products
/// `±x_i·y_j·z_k` (i, j, k distinct rows). `det[b-a,c-a,d-a]` equals that determinant with the
/// sign below; the tests pin it against rational arithmetic.
const O3D_TERMS: [(usize, usize, usize, i8); 24] = {
    // All permutations (i, j, k) of 3 distinct rows out of 4; the sign is that of the permutation
    // (i, j, k, l) of (0, 1, 2, 3) with l the remaining row, times -1 (orientation convention).
    let mut out = [(0usize, 0usize, 0usize, 0i8); 24];
    let mut n = 0;
    let mut i = 0;
    while i < 4 {
        let mut j = 0;
        while j < 4 {
            let mut k = 0;
            while k < 4 {
                if i != j && j != k && i != k {
                    let l = 6 - i - j - k;
                    let p = [i, j, k, l];
                    let mut inv = 0;
                    let mut s = 0;
                    while s < 4 {
                        let mut t = s + 1;
                        while t < 4 {
                            if p[s] > p[t] {
                                inv += 1;
                            }
                            t += 1;
                        }
                        s += 1;
                    }
                    // |rows x y z 1|: column 3 is all ones, so the term is x_i y_j z_k * 1_l.
                    let sg = if inv % 2 == 0 { 1 } else { -1 };
                    out[n] = (i, j, k, -sg);
                    n += 1;
                }
                k += 1;
            }
            j += 1;
        }
        i += 1;
    }
    out
};

/// Terms of `(b-a)×(c-a)` as `±x_i·y_j` (i ≠ j) over the rows (a, b, c): the 3×3 determinant
/// `|x y 1|`.
const O2D_TERMS: [(usize, usize, i8); 6] = [
    (0, 1, 1),
    (1, 2, 1),
    (2, 0, 1),
    (1, 0, -1),
    (2, 1, -1),
    (0, 2, -1),
];

const SPLITTER: f64 = 134_217_729.0; // 2^27 + 1

#[inline]
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let x = a + b;
    let bv = x - a;
    let av = x - bv;
    (x, (a - av) + (b - bv))
}

#[inline]
fn split(a: f64) -> (f64, f64) {
    let c = SPLITTER * a;
    let big = c - a;
    let hi = c - big;
    (hi, a - hi)
}

/// `a·b = x + y` exactly (Dekker), provided nothing underflows or overflows.
#[inline]
fn two_product(a: f64, b: f64) -> (f64, f64) {
    let x = a * b;
    let (ah, al) = split(a);
    let (bh, bl) = split(b);
    let err1 = x - ah * bh;
    let err2 = err1 - al * bh;
    let err3 = err2 - ah * bl;
    (x, al * bl - err3)
}

/// Exact fixed-point accumulator for doubles: 32-bit digits (in `i64`, so carries can wait)
/// covering every bit position from `2^-1074` to `2^1216`.
struct SuperAcc {
    d: [i64; 72],
}

impl SuperAcc {
    fn new() -> Self {
        Self { d: [0; 72] }
    }

    fn add(&mut self, v: f64) {
        if v == 0.0 {
            return;
        }
        let bits = v.to_bits();
        let biased = ((bits >> 52) & 0x7ff) as usize;
        let frac = bits & ((1u64 << 52) - 1);
        // v = ±m · 2^(pos - 1074)
        let (m, pos) = if biased == 0 {
            (frac, 0)
        } else {
            (frac | (1u64 << 52), biased - 1)
        };
        let (q, r) = (pos / 32, pos % 32);
        let wide = (m as u128) << r; // < 2^85: three digits
        let parts = [
            (wide & 0xffff_ffff) as i64,
            ((wide >> 32) & 0xffff_ffff) as i64,
            (wide >> 64) as i64,
        ];
        for (k, p) in parts.into_iter().enumerate() {
            if bits >> 63 == 1 {
                self.d[q + k] -= p;
            } else {
                self.d[q + k] += p;
            }
        }
    }

    fn sign(&self) -> i8 {
        // Carry-propagate to digits in [0, 2^32); the final carry holds the sign.
        let mut carry = 0i64;
        let mut any = false;
        for &x in &self.d {
            let v = x + carry;
            carry = v >> 32;
            any |= (v & 0xffff_ffff) != 0;
        }
        if carry < 0 {
            -1
        } else if carry > 0 || any {
            1
        } else {
            0
        }
    }
}

/// Exact sign of the sum of `t` (any finite doubles; `t` is scrambled).
///
/// Repeated error-free `two_sum` sweeps (Ogita-Rump-Oishi `VecSum`: the exact sum is invariant,
/// the last slot holds the float sum, the others the errors) until the last slot dominates the
/// others (then its sign is the sign) or everything is zero. Falls back to an exact fixed-point
/// accumulator when two sweeps do not settle it (typically an exactly zero sum).
fn sum_sign(t: &mut [f64]) -> i8 {
    let mut n = 0;
    for i in 0..t.len() {
        if t[i] != 0.0 {
            t[n] = t[i];
            n += 1;
        }
    }
    for _ in 0..2 {
        if n == 0 {
            return 0;
        }
        for i in 1..n {
            let (s, e) = two_sum(t[i], t[i - 1]);
            t[i] = s;
            t[i - 1] = e;
        }
        let last = t[n - 1];
        let mut rest = 0.0;
        let mut m = 0;
        for i in 0..n - 1 {
            if t[i] != 0.0 {
                rest += t[i].abs();
                t[m] = t[i];
                m += 1;
            }
        }
        t[m] = last;
        n = m + 1;
        if last == 0.0 && m == 0 {
            return 0;
        }
        // Upper bound on the exact sum of |rest| (float summation of m non-negative values).
        let rest_up = rest * (1.0 + 4.0 * (m as f64 + 1.0) * EPS);
        if last.abs() > rest_up {
            return sign(last);
        }
    }
    let mut acc = SuperAcc::new();
    for &v in &t[..n] {
        acc.add(v);
    }
    acc.sign()
}

/// Binary exponent `e` with `2^e <= |x| < 2^(e+1)` for finite non-zero `x` (subnormals included).
fn exponent(x: f64) -> i32 {
    let bits = x.to_bits();
    let biased = ((bits >> 52) & 0x7ff) as i32;
    if biased == 0 {
        let mant = bits & ((1u64 << 52) - 1);
        -1074 + (63 - mant.leading_zeros() as i32)
    } else {
        biased - 1023
    }
}

/// `x · 2^k`, exact when the result is a normal number (or the scaling is upwards).
fn ldexp(mut x: f64, mut k: i32) -> f64 {
    let up = f64::from_bits(((1023 + 600) as u64) << 52); // 2^600
    let down = f64::from_bits(((1023 - 600) as u64) << 52); // 2^-600
    while k > 600 {
        x *= up;
        k -= 600;
    }
    while k < -600 {
        x *= down;
        k += 600;
    }
    x * f64::from_bits(((1023 + k) as u64) << 52)
}

/// Per-column power-of-two exponents that bring every non-zero value of each column into
/// `[2^-300, 2^300]`; `None` when a column spans too many binades.
fn column_scales<const R: usize, const C: usize>(rows: &[[f64; C]; R]) -> Option<[i32; C]> {
    let mut k = [0i32; C];
    for (col, kc) in k.iter_mut().enumerate() {
        let mut lo = i32::MAX;
        let mut hi = i32::MIN;
        for row in rows {
            let v = row[col];
            if v != 0.0 {
                let e = exponent(v);
                lo = lo.min(e);
                hi = hi.max(e);
            }
        }
        if lo == i32::MAX {
            continue; // all zero
        }
        if hi - lo > 598 {
            return None;
        }
        *kc = -((hi + lo).div_euclid(2));
    }
    Some(k)
}

/// Exact integer `x · 2^1074` (every finite f64 is an integer multiple of `2^-1074`).
fn to_bigint(x: f64) -> BigInt {
    if x == 0.0 {
        return BigInt::from(0);
    }
    let bits = x.to_bits();
    let biased = ((bits >> 52) & 0x7ff) as i64;
    let frac = bits & ((1u64 << 52) - 1);
    let (mant, shift) = if biased == 0 {
        (frac, 0)
    } else {
        (frac | (1u64 << 52), biased - 1)
    };
    let v = BigInt::from(mant) << (shift as usize);
    if x < 0.0 { -v } else { v }
}

/// Exact sign of `det[b-a, c-a, d-a]` without the filter (expansions, or big integers when a
/// coordinate axis spans more than ~600 binades). Slow; use [`orient3d`].
pub fn orient3d_exact(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> i8 {
    let rows = [a.to_array(), b.to_array(), c.to_array(), d.to_array()];
    match column_scales(&rows) {
        Some(k) => {
            let mut s = rows;
            for row in &mut s {
                for (v, &kc) in row.iter_mut().zip(&k) {
                    *v = ldexp(*v, kc);
                }
            }
            // det[b-a, c-a, d-a] over the differences, each an exact two-term expansion
            // `hi + lo` (two_sum); nearby points have `lo = 0`, and an exactly repeated point gives
            // a zero row: both cases drop most of the up to 6·8 triple products.
            let mut hi = [[0.0f64; 3]; 3];
            let mut lo = [[0.0f64; 3]; 3];
            for r in 0..3 {
                for c in 0..3 {
                    let (x, e) = two_sum(s[r + 1][c], -s[0][c]);
                    hi[r][c] = x;
                    lo[r][c] = e;
                }
            }
            let mut t = [0.0f64; 192];
            let mut n = 0;
            for (i, j, l, f) in [
                (0, 1, 2, 1.0),
                (0, 2, 1, -1.0),
                (1, 0, 2, -1.0),
                (1, 2, 0, 1.0),
                (2, 0, 1, 1.0),
                (2, 1, 0, -1.0),
            ] {
                for x in [hi[0][i], lo[0][i]] {
                    if x == 0.0 {
                        continue;
                    }
                    for y in [hi[1][j], lo[1][j]] {
                        if y == 0.0 {
                            continue;
                        }
                        let (p, q) = two_product(x, y);
                        for z in [hi[2][l], lo[2][l]] {
                            if z == 0.0 {
                                continue;
                            }
                            let (p1, p0) = two_product(p, z);
                            let (q1, q0) = two_product(q, z);
                            for v in [p1, p0, q1, q0] {
                                t[n] = f * v;
                                n += 1;
                            }
                        }
                    }
                }
            }
            sum_sign(&mut t[..n])
        }
        None => {
            let mut sum = BigInt::from(0);
            for &(i, j, l, sg) in &O3D_TERMS {
                let t = to_bigint(rows[i][0]) * to_bigint(rows[j][1]) * to_bigint(rows[l][2]);
                if sg > 0 {
                    sum += t;
                } else {
                    sum -= t;
                }
            }
            match sum.sign() {
                num_bigint::Sign::Plus => 1,
                num_bigint::Sign::Minus => -1,
                num_bigint::Sign::NoSign => 0,
            }
        }
    }
}

/// Exact sign of `(b-a)×(c-a)` without the filter. Slow; use [`orient2d`].
pub fn orient2d_exact(a: DVec2, b: DVec2, c: DVec2) -> i8 {
    let rows = [a.to_array(), b.to_array(), c.to_array()];
    match column_scales(&rows) {
        Some(k) => {
            let mut s = rows;
            for row in &mut s {
                for (v, &kc) in row.iter_mut().zip(&k) {
                    *v = ldexp(*v, kc);
                }
            }
            let mut t = [0.0f64; 12];
            let mut n = 0;
            for &(i, j, sg) in &O2D_TERMS {
                let f = sg as f64;
                let (p, q) = two_product(s[i][0], s[j][1]);
                t[n] = f * p;
                t[n + 1] = f * q;
                n += 2;
            }
            sum_sign(&mut t[..n])
        }
        None => {
            let mut sum = BigInt::from(0);
            for &(i, j, sg) in &O2D_TERMS {
                let t = to_bigint(rows[i][0]) * to_bigint(rows[j][1]);
                if sg > 0 {
                    sum += t;
                } else {
                    sum -= t;
                }
            }
            match sum.sign() {
                num_bigint::Sign::Plus => 1,
                num_bigint::Sign::Minus => -1,
                num_bigint::Sign::NoSign => 0,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_rational::BigRational;
    use num_traits::{Signed, Zero};
    use rand::{Rng, SeedableRng, rngs::StdRng};

    fn q(x: f64) -> BigRational {
        BigRational::from_float(x).expect("finite")
    }

    fn rsign(v: &BigRational) -> i8 {
        if v.is_zero() {
            0
        } else if v.is_positive() {
            1
        } else {
            -1
        }
    }

    /// Independent reference: det[b-a, c-a, d-a] in rationals.
    fn o3_ref(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> i8 {
        let sub = |p: DVec3, r: DVec3| [q(p.x) - q(r.x), q(p.y) - q(r.y), q(p.z) - q(r.z)];
        let u = sub(b, a);
        let v = sub(c, a);
        let w = sub(d, a);
        let det = &u[0] * (&v[1] * &w[2] - &v[2] * &w[1])
            + &u[1] * (&v[2] * &w[0] - &v[0] * &w[2])
            + &u[2] * (&v[0] * &w[1] - &v[1] * &w[0]);
        rsign(&det)
    }

    fn o2_ref(a: DVec2, b: DVec2, c: DVec2) -> i8 {
        let det = (q(b.x) - q(a.x)) * (q(c.y) - q(a.y)) - (q(b.y) - q(a.y)) * (q(c.x) - q(a.x));
        rsign(&det)
    }

    fn check3(a: DVec3, b: DVec3, c: DVec3, d: DVec3) {
        let r = o3_ref(a, b, c, d);
        assert_eq!(orient3d(a, b, c, d), r, "orient3d {a:?} {b:?} {c:?} {d:?}");
        assert_eq!(
            orient3d_exact(a, b, c, d),
            r,
            "orient3d_exact {a:?} {b:?} {c:?} {d:?}"
        );
    }

    fn check2(a: DVec2, b: DVec2, c: DVec2) {
        let r = o2_ref(a, b, c);
        assert_eq!(orient2d(a, b, c), r, "orient2d {a:?} {b:?} {c:?}");
        assert_eq!(
            orient2d_exact(a, b, c),
            r,
            "orient2d_exact {a:?} {b:?} {c:?}"
        );
    }

    fn rv(rng: &mut StdRng, s: f64) -> DVec3 {
        DVec3::new(
            rng.random_range(-s..s),
            rng.random_range(-s..s),
            rng.random_range(-s..s),
        )
    }

    /// Nudges a coordinate by a few ulps.
    fn nudge(rng: &mut StdRng, x: f64) -> f64 {
        let k: i64 = rng.random_range(-3..=3);
        if x == 0.0 {
            return x;
        }
        f64::from_bits((x.to_bits() as i64 + k) as u64)
    }

    #[test]
    fn basic_signs() {
        assert_eq!(orient3d(DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z), 1);
        assert_eq!(orient3d(DVec3::ZERO, DVec3::Y, DVec3::X, DVec3::Z), -1);
        assert_eq!(orient2d(DVec2::ZERO, DVec2::X, DVec2::Y), 1);
        check3(DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z);
        check3(DVec3::ZERO, DVec3::Y, DVec3::X, DVec3::Z);
        check2(DVec2::ZERO, DVec2::Y, DVec2::X);
    }

    #[test]
    fn random_near_degenerate_3d() {
        let mut rng = StdRng::seed_from_u64(7);
        for it in 0..4000 {
            let scale = [1.0, 1e-3, 1e3][it % 3];
            let offset = [0.0, 1.0, 1e4, 1e8][(it / 3) % 4];
            let o = DVec3::splat(offset);
            let a = o + rv(&mut rng, scale);
            let b = o + rv(&mut rng, scale);
            let c = o + rv(&mut rng, scale);
            // d on the plane (rounded), then nudged by a few ulps.
            let (s, t) = (rng.random_range(-1.0..2.0), rng.random_range(-1.0..2.0));
            let d0 = a + (b - a) * s + (c - a) * t;
            let d = DVec3::new(
                nudge(&mut rng, d0.x),
                nudge(&mut rng, d0.y),
                nudge(&mut rng, d0.z),
            );
            check3(a, b, c, d);
            // Collinear-ish and repeated points.
            check3(a, b, a + (b - a) * s, d);
            check3(a, a, c, d);
        }
    }

    #[test]
    fn random_near_degenerate_2d() {
        let mut rng = StdRng::seed_from_u64(8);
        for it in 0..4000 {
            let offset = [0.0, 1.0, 1e8][it % 3];
            let o = DVec2::splat(offset);
            let a = o + DVec2::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            let b = o + DVec2::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            let s = rng.random_range(-1.0..2.0);
            let c0 = a + (b - a) * s;
            let c = DVec2::new(nudge(&mut rng, c0.x), nudge(&mut rng, c0.y));
            check2(a, b, c);
        }
    }

    #[test]
    fn tiny_subnormal_and_huge() {
        let mut rng = StdRng::seed_from_u64(9);
        let scales = [1e-300, 1e-310, 5e-324 * 1e6, 1e-200, 1e150, 1e300];
        for it in 0..3000 {
            let s = scales[it % scales.len()];
            let a = rv(&mut rng, 1.0) * s;
            let b = rv(&mut rng, 1.0) * s;
            let c = rv(&mut rng, 1.0) * s;
            let t = rng.random_range(-1.0..2.0);
            let d0 = a + (b - a) * t + (c - a) * (1.0 - t);
            let d = DVec3::new(
                nudge(&mut rng, d0.x),
                nudge(&mut rng, d0.y),
                nudge(&mut rng, d0.z),
            );
            check3(a, b, c, d);
            check3(a, b, c, rv(&mut rng, s));
            let p = |v: DVec3| DVec2::new(v.x, v.y);
            check2(p(a), p(b), p(d));
        }
        // Hand-made subnormal cases: products underflow in plain f64.
        let m = 5e-324;
        check3(
            DVec3::ZERO,
            DVec3::new(m, 0.0, 0.0),
            DVec3::new(0.0, m, 0.0),
            DVec3::new(0.0, 0.0, m),
        );
        check3(
            DVec3::ZERO,
            DVec3::new(3.0 * m, m, 0.0),
            DVec3::new(m, 2.0 * m, 0.0),
            DVec3::new(m, m, m),
        );
        check2(DVec2::ZERO, DVec2::new(m, 0.0), DVec2::new(0.0, m));
        check2(
            DVec2::ZERO,
            DVec2::new(3.0 * m, m),
            DVec2::new(6.0 * m, 2.0 * m),
        );
        check2(
            DVec2::ZERO,
            DVec2::new(3.0 * m, m),
            DVec2::new(6.0 * m, 3.0 * m),
        );
        // Near the top of the range: differences overflow in f64.
        let h = f64::MAX;
        check3(
            DVec3::new(-h, -h, 0.0),
            DVec3::new(h, -h, 0.0),
            DVec3::new(-h, h, 0.0),
            DVec3::new(h, h, 1.0),
        );
        check2(DVec2::new(-h, -h), DVec2::new(h, h), DVec2::new(0.0, 0.0));
        check2(DVec2::new(-h, -h), DVec2::new(h, h), DVec2::new(0.0, m));
    }

    #[test]
    fn mixed_dynamic_range_uses_big_integers() {
        // One axis holds both 1e8 and a subnormal: no common scale exists.
        let m = 5e-324;
        let a = DVec3::new(1e8, 0.0, 0.0);
        let b = DVec3::new(m, 1.0, 0.0);
        let c = DVec3::new(0.0, 0.0, 1.0);
        check3(a, b, c, DVec3::ZERO);
        check3(a, b, c, DVec3::new(1e-320, 1e-300, 1e8));
        check3(
            DVec3::new(m, m, m),
            DVec3::new(1e300, 0.0, 0.0),
            DVec3::new(0.0, 1e300, 0.0),
            DVec3::new(2.0 * m, 0.0, m),
        );
        check2(
            DVec2::new(m, 1e300),
            DVec2::new(1e300, m),
            DVec2::new(2.0 * m, 1e300),
        );
        let mut rng = StdRng::seed_from_u64(10);
        for _ in 0..500 {
            let pick = |rng: &mut StdRng| -> f64 {
                let e: i32 = rng.random_range(-1074..1000);
                let s = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                s * ldexp(rng.random_range(1.0..2.0), e).max(5e-324)
            };
            let mut v = [DVec3::ZERO; 4];
            for p in &mut v {
                *p = DVec3::new(pick(&mut rng), pick(&mut rng), pick(&mut rng));
            }
            check3(v[0], v[1], v[2], v[3]);
            check2(v[0].truncate(), v[1].truncate(), v[2].truncate());
        }
    }

    #[test]
    fn filter_bound_is_sound() {
        let mut rng = StdRng::seed_from_u64(11);
        for _ in 0..2000 {
            let a = rv(&mut rng, 1.0) + DVec3::splat(1e6);
            let b = rv(&mut rng, 1.0) + DVec3::splat(1e6);
            let c = rv(&mut rng, 1.0) + DVec3::splat(1e6);
            let d = a + (b - a) * 0.5 + (c - a) * 0.25;
            let (v, bound) = orient3d_filter(a, b, c, d);
            if v.abs() > bound {
                assert_eq!(sign(v), o3_ref(a, b, c, d));
            }
        }
    }

    #[test]
    fn exact_sum_sign_matches_rationals() {
        let mut rng = StdRng::seed_from_u64(12);
        for it in 0..3000 {
            let n = rng.random_range(1..40);
            let mut t: Vec<f64> = (0..n)
                .map(|_| {
                    let e: i32 = rng.random_range(-1074..900);
                    let v = ldexp(rng.random_range(1.0..2.0), e);
                    if rng.random_bool(0.5) { v } else { -v }
                })
                .collect();
            // Force exact cancellation in a third of the cases.
            if it % 3 == 0 {
                let neg: Vec<f64> = t.iter().map(|v| -v).collect();
                t.extend(neg);
                t.reverse();
            }
            let r: BigRational = t.iter().map(|&v| q(v)).sum();
            let want = rsign(&r);
            let mut u = t.clone();
            assert_eq!(sum_sign(&mut u), want, "{t:?}");
            let mut acc = SuperAcc::new();
            t.iter().for_each(|&v| acc.add(v));
            assert_eq!(acc.sign(), want, "{t:?}");
        }
    }

    #[test]
    fn collinear3_exact() {
        let a = DVec3::new(0.1, 0.2, 0.3);
        let b = DVec3::new(0.4, 0.5, 0.6);
        assert!(collinear3(a, b, a));
        assert!(collinear3(a, a, a));
        assert!(collinear3(DVec3::ZERO, DVec3::ONE, DVec3::splat(3.0)));
        // (0.1+0.3)/2 rounds: not collinear in exact arithmetic.
        assert!(!collinear3(
            DVec3::ZERO,
            DVec3::new(0.1, 0.3, 0.7),
            DVec3::new(0.2, 0.6, 1.4000000000000001)
        ));
    }
}
