//! The exact decision "are two triangles within `t` of each other?" for f64 inputs.
//!
//! For closed triangles that do not intersect, the distance is the smallest of
//! - 18 vertex-edge distances (each vertex of one triangle against each edge of the other),
//! - 9 edge-edge distances between interior points (the lines' common perpendicular, when its
//!   feet fall strictly inside both edges and the edges are not parallel),
//! - 6 vertex-face distances (when the vertex projects into the closed face).
//!
//! Each of these is the length of a segment between the two triangles, and the true closest pair
//! is one of them, so `dist <= t` iff one of them is `<= t`. Every test is the sign of a
//! polynomial in the input coordinates that is homogeneous in lengths (both sides of each
//! comparison have the same degree, up to 6), written once generically ([`Arith`]) and run:
//!
//! 1. on [`Bounded`] floats, which carry a certified running error bound (every operation adds
//!    its rounding, `ε|result|`, plus a normal absolute term that covers underflow); a sign is
//!    trusted only when `|value| > bound`;
//! 2. when some sign is not certain, on exact integers ([`num_bigint::BigInt`]: every finite f64
//!    is an integer multiple of `2⁻¹⁰⁷⁴`; homogeneity lets the common scale cancel).
//!
//! Intersection itself is decided by [`frcd_tritri::exact`] (exact for every finite input).

use frcd_geom::DVec3;
use num_bigint::BigInt;
use std::ops::{Add, Mul, Sub};

/// Unit roundoff, 2⁻⁵³.
const EPS: f64 = f64::EPSILON * 0.5;
/// Absolute error added by each operation: covers the underflow of one product or sum (at most
/// 2⁻¹⁰⁷⁵) with huge room. A normal constant on purpose (subnormal arithmetic is slow); values
/// below it are simply left to the exact stage.
const ETA: f64 = f64::from_bits((1023 - 1000) << 52);
/// Every propagated bound is inflated by this factor, which dominates the rounding of the bound
/// computation itself (a few `ε` relative per operation).
const GROW: f64 = 1.0 + 1e-12;

/// A value that either is exact or carries a certified error bound.
pub(crate) trait Arith:
    Clone + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Sized
{
    /// Sign, or `None` when the value's sign is not certain.
    fn sign(&self) -> Option<i8>;
}

/// A float with a certified bound on its distance to the exact value of the same expression.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Bounded {
    v: f64,
    e: f64,
}

impl Bounded {
    #[inline(always)]
    pub(crate) fn exact(v: f64) -> Self {
        Bounded { v, e: 0.0 }
    }
}

impl Add for Bounded {
    type Output = Bounded;
    #[inline(always)]
    fn add(self, o: Bounded) -> Bounded {
        let v = self.v + o.v;
        Bounded {
            v,
            e: (self.e + o.e + v.abs() * EPS) * GROW + ETA,
        }
    }
}

impl Sub for Bounded {
    type Output = Bounded;
    #[inline(always)]
    fn sub(self, o: Bounded) -> Bounded {
        let v = self.v - o.v;
        Bounded {
            v,
            e: (self.e + o.e + v.abs() * EPS) * GROW + ETA,
        }
    }
}

impl Mul for Bounded {
    type Output = Bounded;
    #[inline(always)]
    fn mul(self, o: Bounded) -> Bounded {
        let v = self.v * o.v;
        // |ab - ãb̃| <= |ã| e_b + |b̃| e_a + e_a e_b, plus the rounding of ãb̃.
        let e = self.v.abs() * o.e + o.v.abs() * self.e + self.e * o.e + v.abs() * EPS;
        Bounded {
            v,
            e: e * GROW + ETA,
        }
    }
}

impl Arith for Bounded {
    #[inline(always)]
    fn sign(&self) -> Option<i8> {
        // NaN or infinite values (overflow) compare false everywhere: not certain.
        if self.v > self.e {
            Some(1)
        } else if -self.v > self.e {
            Some(-1)
        } else if self.v == 0.0 && self.e == 0.0 {
            Some(0)
        } else {
            None
        }
    }
}

/// An exact integer (a coordinate times `2¹⁰⁷⁴`).
#[derive(Clone, Debug)]
pub(crate) struct Exact(BigInt);

impl Exact {
    /// `x · 2¹⁰⁷⁴` exactly (finite `x`; non-finite input maps to 0, callers reject it first).
    pub(crate) fn from_f64(x: f64) -> Self {
        if x == 0.0 || !x.is_finite() {
            return Exact(BigInt::from(0));
        }
        let bits = x.to_bits();
        let biased = ((bits >> 52) & 0x7ff) as usize;
        let frac = bits & ((1u64 << 52) - 1);
        let (mant, shift) = if biased == 0 {
            (frac, 0)
        } else {
            (frac | (1u64 << 52), biased - 1)
        };
        let v = BigInt::from(mant) << shift;
        Exact(if x < 0.0 { -v } else { v })
    }
}

impl Add for Exact {
    type Output = Exact;
    fn add(self, o: Exact) -> Exact {
        Exact(self.0 + o.0)
    }
}
impl Sub for Exact {
    type Output = Exact;
    fn sub(self, o: Exact) -> Exact {
        Exact(self.0 - o.0)
    }
}
impl Mul for Exact {
    type Output = Exact;
    fn mul(self, o: Exact) -> Exact {
        Exact(self.0 * o.0)
    }
}
impl Arith for Exact {
    fn sign(&self) -> Option<i8> {
        Some(match self.0.sign() {
            num_bigint::Sign::Plus => 1,
            num_bigint::Sign::Minus => -1,
            num_bigint::Sign::NoSign => 0,
        })
    }
}

/// A 3-vector over an [`Arith`] type.
#[derive(Clone, Debug)]
pub(crate) struct V<N>([N; 3]);

impl<N: Arith> V<N> {
    fn sub(&self, o: &V<N>) -> V<N> {
        let [a, b, c] = &self.0;
        let [x, y, z] = &o.0;
        V([
            a.clone() - x.clone(),
            b.clone() - y.clone(),
            c.clone() - z.clone(),
        ])
    }
    fn dot(&self, o: &V<N>) -> N {
        let [a, b, c] = &self.0;
        let [x, y, z] = &o.0;
        a.clone() * x.clone() + b.clone() * y.clone() + c.clone() * z.clone()
    }
    fn cross(&self, o: &V<N>) -> V<N> {
        let [a, b, c] = &self.0;
        let [x, y, z] = &o.0;
        V([
            b.clone() * z.clone() - c.clone() * y.clone(),
            c.clone() * x.clone() - a.clone() * z.clone(),
            a.clone() * y.clone() - b.clone() * x.clone(),
        ])
    }
}

/// Three-valued "or": `Some(true)` wins over unknown, unknown wins over `Some(false)`.
#[derive(Clone, Copy)]
struct Or {
    found: bool,
    unknown: bool,
}

impl Or {
    fn add(&mut self, r: Option<bool>) {
        match r {
            Some(true) => self.found = true,
            Some(false) => {}
            None => self.unknown = true,
        }
    }
    fn result(self) -> Option<bool> {
        if self.found {
            Some(true)
        } else if self.unknown {
            None
        } else {
            Some(false)
        }
    }
}

/// `sign(x) <= 0`, or `None`.
#[inline]
fn nonpos<N: Arith>(x: &N) -> Option<bool> {
    x.sign().map(|s| s <= 0)
}

/// `dist(p, [a, b])² <= t2`.
fn point_segment<N: Arith>(p: &V<N>, a: &V<N>, b: &V<N>, t2: &N) -> Option<bool> {
    let d = b.sub(a);
    let w = p.sub(a);
    let s = w.dot(&d);
    match s.sign()? {
        ..=0 => nonpos(&(w.dot(&w) - t2.clone())),
        _ => {
            let dd = d.dot(&d);
            match (s.clone() - dd.clone()).sign()? {
                0.. => {
                    let wb = p.sub(b);
                    nonpos(&(wb.dot(&wb) - t2.clone()))
                }
                _ => {
                    // |w|²|d|² - s² = |w × d|² is the squared distance times |d|².
                    nonpos(&(w.dot(&w) * dd.clone() - s.clone() * s - t2.clone() * dd))
                }
            }
        }
    }
}

/// Interior edge-edge part: the common perpendicular of non-parallel lines with both feet
/// strictly inside the edges, no longer than `t`.
fn segment_interiors<N: Arith>(p1: &V<N>, q1: &V<N>, p2: &V<N>, q2: &V<N>, t2: &N) -> Option<bool> {
    let d1 = q1.sub(p1);
    let d2 = q2.sub(p2);
    let r = p1.sub(p2);
    let n = d1.cross(&d2);
    let den = n.dot(&n);
    if den.sign()? == 0 {
        return Some(false); // parallel: the minimum is at an endpoint
    }
    let a = d1.dot(&d1);
    let b = d1.dot(&d2);
    let c = d2.dot(&d2);
    let d = d1.dot(&r);
    let e = d2.dot(&r);
    // s = (b e - c d) / den, t = (a e - b d) / den, den > 0.
    let sn = b.clone() * e.clone() - c * d.clone();
    let tn = a * e - b * d;
    if sn.sign()? <= 0 || tn.sign()? <= 0 {
        return Some(false);
    }
    if (sn - den.clone()).sign()? >= 0 || (tn - den.clone()).sign()? >= 0 {
        return Some(false);
    }
    let h = r.dot(&n);
    nonpos(&(h.clone() * h - t2.clone() * den))
}

/// Vertex-face part: `p` projects into the closed non-degenerate triangle and its distance to
/// the plane is at most `t`.
fn point_face<N: Arith>(p: &V<N>, t: &[V<N>; 3], n: &V<N>, nn: &N, t2: &N) -> Option<bool> {
    if nn.sign()? == 0 {
        return Some(false); // degenerate: its edges cover it
    }
    for i in 0..3 {
        let (a, b) = (&t[i], &t[(i + 1) % 3]);
        if b.sub(a).cross(&p.sub(a)).dot(n).sign()? < 0 {
            return Some(false);
        }
    }
    let h = p.sub(&t[0]).dot(n);
    nonpos(&(h.clone() * h - t2.clone() * nn.clone()))
}

/// Are two non-intersecting triangles within `t` (`t2 = t·t` as an [`Arith`])? `None` when a sign
/// was not certain.
fn features_within<N: Arith>(a: &[V<N>; 3], b: &[V<N>; 3], t2: &N) -> Option<bool> {
    let mut or = Or {
        found: false,
        unknown: false,
    };
    for (x, y) in [(a, b), (b, a)] {
        let n = y[1].sub(&y[0]).cross(&y[2].sub(&y[0]));
        let nn = n.dot(&n);
        for p in x.iter() {
            or.add(point_face(p, y, &n, &nn, t2));
            if or.found {
                return Some(true);
            }
            for j in 0..3 {
                or.add(point_segment(p, &y[j], &y[(j + 1) % 3], t2));
                if or.found {
                    return Some(true);
                }
            }
        }
    }
    for i in 0..3 {
        for j in 0..3 {
            or.add(segment_interiors(
                &a[i],
                &a[(i + 1) % 3],
                &b[j],
                &b[(j + 1) % 3],
                t2,
            ));
            if or.found {
                return Some(true);
            }
        }
    }
    or.result()
}

fn lift<N: Arith>(t: &[DVec3; 3], f: impl Fn(f64) -> N) -> [V<N>; 3] {
    t.map(|p| V([f(p.x), f(p.y), f(p.z)]))
}

/// Which stage decided a [`triangles_within`] call.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Stage {
    /// The exact intersection test (the triangles touch or cross).
    Intersect,
    /// The float filter.
    Filter,
    /// Exact integer arithmetic.
    Exact,
}

/// Exactly: is the distance between the closed triangles `a` and `b` (f64 coordinates in one
/// frame) at most `t` (finite, `>= 0`)? Also says which stage decided it.
pub(crate) fn triangles_within(a: &[DVec3; 3], b: &[DVec3; 3], t: f64) -> (bool, Stage) {
    if frcd_tritri::exact(
        &frcd_geom::Triangle { v: *a },
        &frcd_geom::Triangle { v: *b },
    ) {
        return (true, Stage::Intersect);
    }
    let tb = Bounded::exact(t);
    if let Some(r) = features_within(
        &lift(a, Bounded::exact),
        &lift(b, Bounded::exact),
        &(tb * tb),
    ) {
        return (r, Stage::Filter);
    }
    let te = Exact::from_f64(t);
    let r = features_within(
        &lift(a, Exact::from_f64),
        &lift(b, Exact::from_f64),
        &(te.clone() * te),
    )
    .expect("exact arithmetic decides every sign");
    (r, Stage::Exact)
}

/// Same as [`triangles_within`] but always in exact arithmetic (tests compare the stages).
#[cfg(test)]
pub(crate) fn triangles_within_exact(a: &[DVec3; 3], b: &[DVec3; 3], t: f64) -> bool {
    if frcd_tritri::exact(
        &frcd_geom::Triangle { v: *a },
        &frcd_geom::Triangle { v: *b },
    ) {
        return true;
    }
    let te = Exact::from_f64(t);
    features_within(
        &lift(a, Exact::from_f64),
        &lift(b, Exact::from_f64),
        &(te.clone() * te),
    )
    .expect("exact")
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    fn tri(rng: &mut StdRng, s: f64) -> [DVec3; 3] {
        [(); 3].map(|_| {
            DVec3::new(
                rng.random_range(-s..s),
                rng.random_range(-s..s),
                rng.random_range(-s..s),
            )
        })
    }

    #[test]
    fn filter_and_exact_stage_agree_and_the_filter_usually_decides() {
        let mut rng = StdRng::seed_from_u64(3);
        let mut filtered = 0;
        for k in 0..3000 {
            let a = tri(&mut rng, 1.0);
            let mut b = tri(&mut rng, 1.0);
            let shift = DVec3::new(rng.random_range(0.0..2.0), 0.0, 0.0);
            for p in &mut b {
                *p += shift;
            }
            let (_, pa, pb) = super::super::tri::triangle_features(&a, &b);
            let d = pa.distance(pb);
            // Tolerances at, just below and just above the float distance.
            for (i, t) in [d, d.next_down(), d.next_up(), d * 0.5, d * 2.0, 0.0]
                .into_iter()
                .enumerate()
            {
                let (got, stage) = triangles_within(&a, &b, t);
                assert_eq!(got, triangles_within_exact(&a, &b, t), "case {k} t {t}");
                // Away from the boundary the filter (or the intersection test) decides.
                if i >= 3 && stage != Stage::Exact {
                    filtered += 1;
                }
            }
        }
        assert!(filtered >= 8950, "filter decided {filtered} of 9000");
    }

    #[test]
    fn degenerate_contacts_are_decided_exactly() {
        // Vertex over a face at 1e-12, parallel edges, a point triangle, subnormal gaps.
        let a = [DVec3::ZERO, DVec3::X, DVec3::Y];
        let h = 1e-12;
        let b = [
            DVec3::new(0.25, 0.25, h),
            DVec3::new(0.25, 0.25, 1.0),
            DVec3::new(1.0, 1.0, 1.0),
        ];
        assert!(triangles_within(&a, &b, h).0);
        assert!(!triangles_within(&a, &b, h.next_down()).0);
        // Parallel edges 1e-300 apart (sub-filter scale: the exact stage decides).
        let g = 1e-300;
        let b = [
            DVec3::new(0.0, -g, 0.0),
            DVec3::new(1.0, -g, 0.0),
            DVec3::new(0.5, -1.0, 0.0),
        ];
        let (r, stage) = triangles_within(&a, &b, g);
        assert!(r);
        assert_eq!(stage, Stage::Exact);
        assert!(!triangles_within(&a, &b, g.next_down()).0);
        // Subnormal gap.
        let g = f64::from_bits(5);
        let b = [
            DVec3::new(0.0, 0.0, g),
            DVec3::new(1.0, 0.0, g),
            DVec3::new(0.0, 1.0, 1.0),
        ];
        assert!(triangles_within(&a, &b, g).0);
        assert!(!triangles_within(&a, &b, f64::from_bits(4)).0);
        // A point triangle.
        let p = DVec3::new(0.3, 0.3, 0.5);
        assert!(triangles_within(&a, &[p, p, p], 0.5).0);
        assert!(!triangles_within(&a, &[p, p, p], 0.5f64.next_down()).0);
    }
}
