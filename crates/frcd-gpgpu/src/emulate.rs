//! CPU emulation of `shaders/traverse.wgsl`'s arithmetic under WGSL's float rules (issue 10):
//! every f32 operation rounded to nearest, up, down, toward zero, away from zero, or to a random
//! neighbour; with and without multiply-adds fused; with and without flush-to-zero of subnormal
//! inputs and results. The functions below mirror the shader's `obb_overlap` and `tri_tri` line
//! by line (same operation order); the tests check that no pair the exact f64 test finds
//! touching is ever declared separated or disjoint, and that the tests could fail (with the
//! error bounds removed, some rounding mode loses a pair).
//!
//! The triangle pass has two paths (issue 10): the exact one (`tri_tri_exact`: the offsets of
//! each triangle from its grid reference point, and `W = R c_B + t - c_A` computed in the
//! shader's integer limbs, mirrored here with checked i32 arithmetic and compared with an i128
//! computation) and the rotated one (`tri_tri_rotated`: vertices rebuilt from the offsets, B
//! rotated in f32). `tri_tri_absolute` is main's arithmetic before the offsets (absolute f32
//! vertices), kept as the baseline the uncertain counts are compared with.

use std::cell::Cell;

/// How each f32 operation rounds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Rounding {
    Nearest,
    Up,
    Down,
    TowardZero,
    AwayFromZero,
    /// Either neighbour, chosen by a xorshift generator.
    Random,
}

#[derive(Clone, Copy, Debug)]
pub(crate) struct Env {
    pub rounding: Rounding,
    /// Flush subnormal inputs and results to (signed) zero.
    pub ftz: bool,
    /// Contract `a * b + c` into one rounding (dot products, cross products, rot() + t).
    pub fma: bool,
    /// Multiplier of the shaders' error bounds (1: as in the shader; 0: no bounds).
    pub bound_scale: f32,
}

thread_local! {
    static ENV: Cell<Env> = const { Cell::new(Env {
        rounding: Rounding::Nearest,
        ftz: false,
        fma: false,
        bound_scale: 1.0,
    }) };
    static RNG: Cell<u64> = const { Cell::new(0x9E37_79B9_7F4A_7C15) };
}

pub(crate) fn set_env(e: Env) {
    ENV.with(|c| c.set(e));
}

fn env() -> Env {
    ENV.with(|c| c.get())
}

fn coin() -> bool {
    RNG.with(|r| {
        let mut x = r.get();
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        r.set(x);
        x & 1 == 1
    })
}

fn flush_in(x: f32) -> f64 {
    if env().ftz && x.is_subnormal() {
        0.0
    } else {
        x as f64
    }
}

/// `a + b` exactly as `s + e` (Knuth's two-sum).
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    let e = (a - (s - bb)) + (b - bb);
    (s, e)
}

/// Rounds the exact value `hi + lo` to f32 under the environment.
fn round(hi: f64, lo: f64) -> f32 {
    let c = hi as f32;
    if !c.is_finite() {
        return c;
    }
    // Sign of (exact - c); `hi - c` is exact (c is the f32 nearest to hi).
    let r = (hi - c as f64) + lo;
    let down = if r < 0.0 { c.next_down() } else { c };
    let up = if r > 0.0 { c.next_up() } else { c };
    let exact_positive = hi + lo > 0.0 || (hi + lo == 0.0 && c >= 0.0);
    let out = match env().rounding {
        Rounding::Nearest => c,
        Rounding::Up => up,
        Rounding::Down => down,
        Rounding::TowardZero => {
            if exact_positive {
                down
            } else {
                up
            }
        }
        Rounding::AwayFromZero => {
            if exact_positive {
                up
            } else {
                down
            }
        }
        Rounding::Random => {
            if coin() {
                up
            } else {
                down
            }
        }
    };
    if env().ftz && out.is_subnormal() {
        0.0f32.copysign(out)
    } else {
        out
    }
}

fn add(a: f32, b: f32) -> f32 {
    let (s, e) = two_sum(flush_in(a), flush_in(b));
    round(s, e)
}

fn sub(a: f32, b: f32) -> f32 {
    add(a, -b)
}

/// f32 × f32 is exact in f64 (48 significant bits).
fn mul(a: f32, b: f32) -> f32 {
    round(flush_in(a) * flush_in(b), 0.0)
}

/// `a * b + c`: fused (one rounding) when the environment contracts, else two roundings.
fn mad(a: f32, b: f32, c: f32) -> f32 {
    if env().fma {
        let (s, e) = two_sum(flush_in(a) * flush_in(b), flush_in(c));
        round(s, e)
    } else {
        add(mul(a, b), c)
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct V3 {
    pub x: f32,
    pub y: f32,
    pub z: f32,
}

pub(crate) fn v3(x: f32, y: f32, z: f32) -> V3 {
    V3 { x, y, z }
}

impl V3 {
    fn sub(self, o: V3) -> V3 {
        v3(sub(self.x, o.x), sub(self.y, o.y), sub(self.z, o.z))
    }
    fn add(self, o: V3) -> V3 {
        v3(add(self.x, o.x), add(self.y, o.y), add(self.z, o.z))
    }
    fn min(self, o: V3) -> V3 {
        v3(self.x.min(o.x), self.y.min(o.y), self.z.min(o.z))
    }
    fn max(self, o: V3) -> V3 {
        v3(self.x.max(o.x), self.y.max(o.y), self.z.max(o.z))
    }
}

fn dot(a: V3, b: V3) -> f32 {
    mad(a.z, b.z, mad(a.y, b.y, mul(a.x, b.x)))
}

fn cross(a: V3, b: V3) -> V3 {
    v3(
        mad(a.y, b.z, -mul(a.z, b.y)),
        mad(a.z, b.x, -mul(a.x, b.z)),
        mad(a.x, b.y, -mul(a.y, b.x)),
    )
}

fn l1(v: V3) -> f32 {
    add(add(v.x.abs(), v.y.abs()), v.z.abs())
}

fn maxabs(v: V3) -> f32 {
    v.x.abs().max(v.y.abs().max(v.z.abs()))
}

const U: f32 = 1.192_092_9e-7;
const TAU: f32 = 1.175_494_4e-38;

/// The relative pose as the shader sees it: rows of R and t, f32.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PoseF {
    pub r: [V3; 3],
    pub t: V3,
}

fn rot(p: &PoseF, v: V3) -> V3 {
    v3(dot(p.r[0], v), dot(p.r[1], v), dot(p.r[2], v))
}

/// A node as loaded from the texture.
#[derive(Clone, Copy, Debug)]
pub(crate) struct NodeF {
    pub c: V3,
    /// The axes' distance bound to an orthonormal frame that the shader uses for this node: its
    /// mesh's (the largest of the mesh's nodes', `pack::PackedTree::eps`).
    pub eps: f32,
    pub a: [V3; 3],
    pub h: V3,
}

/// Mirror of the shader's `obb_overlap` (Gottschalk's form, same operation order).
pub(crate) fn obb_overlap(p: &PoseF, na: &NodeF, nb: &NodeF) -> bool {
    let b = [rot(p, nb.a[0]), rot(p, nb.a[1]), rot(p, nb.a[2])];
    let tt = rot(p, nb.c).add(p.t).sub(na.c);
    // c[i].{x,y,z} = a_i . b_{0,1,2}
    let c: [V3; 3] =
        std::array::from_fn(|i| v3(dot(na.a[i], b[0]), dot(na.a[i], b[1]), dot(na.a[i], b[2])));
    let t = v3(dot(na.a[0], tt), dot(na.a[1], tt), dot(na.a[2], tt));
    let (ha, hb) = (na.h, nb.h);
    let sha = add(add(ha.x, ha.y), ha.z);
    let shb = add(add(hb.x, hb.y), hb.z);
    let ltt = l1(tt);
    // The pose texture's eps_A + eps_B, summed and rounded up on the CPU (`query::prepare`).
    let eps_ab = crate::pack::round_up(na.eps as f64 + nb.eps as f64);
    let eps = add(eps_ab, U);
    let err = mul(
        add(
            add(
                mad(
                    add(mul(48.0, U), mul(5.0, eps)),
                    ltt,
                    mul(mul(20.0, U), add(l1(nb.c), l1(p.t))),
                ),
                mul(add(mul(20.0, U), mul(4.0, eps)), add(sha, shb)),
            ),
            mul(mul(128.0, TAU), add(add(add(1.0, sha), shb), ltt)),
        ),
        1.01,
    );
    let err = err * env().bound_scale;
    let abs3 = |v: V3| v3(v.x.abs(), v.y.abs(), v.z.abs());
    let a = [abs3(c[0]), abs3(c[1]), abs3(c[2])];
    let g = |v: V3, k: usize| [v.x, v.y, v.z][k];
    let hav = [ha.x, ha.y, ha.z];
    let hbv = [hb.x, hb.y, hb.z];
    let tv = [t.x, t.y, t.z];
    // A's face axes.
    for i in 0..3 {
        if tv[i].abs() > add(add(hav[i], dot(hb, a[i])), err) {
            return false;
        }
    }
    // B's face axes.
    for j in 0..3 {
        let col = v3(g(a[0], j), g(a[1], j), g(a[2], j));
        if dot(tt, b[j]).abs() > add(add(dot(ha, col), hbv[j]), err) {
            return false;
        }
    }
    // Edge axes a_i x b_j, (i, k, m) and (j, p, q) cyclic.
    for i in 0..3 {
        let (k, m) = ((i + 1) % 3, (i + 2) % 3);
        for j in 0..3 {
            let (pp, q) = ((j + 1) % 3, (j + 2) % 3);
            let d = mad(tv[m], g(c[k], j), -mul(tv[k], g(c[m], j))).abs();
            // The shader lists the terms as (h of the lower index first).
            let (k1, m1) = if k < m { (k, m) } else { (m, k) };
            let (p1, q1) = if pp < q { (pp, q) } else { (q, pp) };
            let r = mad(
                hbv[q1],
                g(a[i], p1),
                mad(
                    hbv[p1],
                    g(a[i], q1),
                    mad(hav[m1], g(a[k1], j), mul(hav[k1], g(a[m1], j))),
                ),
            );
            if d > add(r, err) {
                return false;
            }
        }
    }
    true
}

pub(crate) const TRI_DISJOINT: u32 = 0;
pub(crate) const TRI_TOUCH: u32 = 1;
pub(crate) const TRI_UNCERTAIN: u32 = 2;

fn sgn(v: f32, e: f32) -> i32 {
    if v > e {
        1
    } else if v < -e {
        -1
    } else {
        0
    }
}

fn orient(x: V3, y: V3, z: V3, w: V3) -> f32 {
    dot(w.sub(z), cross(x.sub(z), y.sub(z)))
}

#[allow(clippy::too_many_arguments)]
fn check_min_max(p1: V3, q1: V3, r1: V3, p2: V3, q2: V3, r2: V3, e: f32) -> u32 {
    let v1 = sgn(dot(q2.sub(q1), cross(p2.sub(q1), p1.sub(q1))), e);
    let v2 = sgn(dot(r2.sub(p1), cross(p2.sub(p1), r1.sub(p1))), e);
    if v1 > 0 || v2 > 0 {
        return TRI_DISJOINT;
    }
    if v1 < 0 && v2 < 0 {
        return TRI_TOUCH;
    }
    TRI_UNCERTAIN
}

/// Mirror of the shader's `lone_first`: the triangle rotated so that its lone vertex (the one
/// whose sign differs from the other two) comes first, and whether that vertex is on the
/// negative side. Meaningful only for nonzero signs that are not all equal.
fn lone_first(t: [V3; 3], s: [i32; 3]) -> ([V3; 3], bool) {
    let [p, q, r] = t;
    let [sp, sq, sr] = s;
    if sq == sp {
        ([r, p, q], sr < 0)
    } else if sr == sp {
        ([q, r, p], sq < 0)
    } else {
        ([p, q, r], sp < 0)
    }
}

/// The six points, in order, that the generic case of `tri_tri_core` passes to
/// `check_min_max` (the shader's selects): triangle 1 rotated to its lone vertex, plane 2
/// flipped when that vertex is negative, then the same for triangle 2 and plane 1.
fn canonical_points(a: [V3; 3], sa: [i32; 3], b: [V3; 3], sb: [i32; 3]) -> [V3; 6] {
    let ([p1, q1, r1], neg1) = lone_first(a, sa);
    let (b, sb) = if neg1 {
        ([b[0], b[2], b[1]], [sb[0], sb[2], sb[1]])
    } else {
        (b, sb)
    };
    let ([p2, q2, r2], neg2) = lone_first(b, sb);
    let (q1, r1) = if neg2 { (r1, q1) } else { (q1, r1) };
    [p1, q1, r1, p2, q2, r2]
}

/// Main's `tri_tri` before issue 10's offsets (absolute f32 vertices, B rotated in f32): the
/// baseline of the uncertain counts. Triangle `a` in A's frame, `b` in B's frame.
pub(crate) fn tri_tri_absolute(p: &PoseF, a: [V3; 3], b: [V3; 3]) -> u32 {
    let [p1, q1, r1] = a;
    let [pb, qb, rb] = b;
    let p2 = rot(p, pb).add(p.t);
    let q2 = rot(p, qb).add(p.t);
    let r2 = rot(p, rb).add(p.t);
    let pa_mag = maxabs(p1).max(maxabs(q1).max(maxabs(r1)));
    let pb_mag = maxabs(pb).max(maxabs(qb).max(maxabs(rb)));
    let delta = mul(
        add(
            mul(mul(0.5, U), pa_mag).max(mul(U, add(mul(16.0, pb_mag), mul(5.0, maxabs(p.t))))),
            mul(8.0, TAU),
        ),
        1.01,
    );
    tri_tri_core([p1, q1, r1], [p2, q2, r2], delta)
}

/// Mirror of the shader's `tri_tri_core`: both triangles in A's frame (shifted alike), `delta`
/// bounding every coordinate's distance from the exact test's points.
pub(crate) fn tri_tri_core(a: [V3; 3], b: [V3; 3], delta: f32) -> u32 {
    let [p1, q1, r1] = a;
    let [p2, q2, r2] = b;
    let lo = p1.min(q1).min(r1.min(p2)).min(q2.min(r2));
    let hi = p1.max(q1).max(r1.max(p2)).max(q2.max(r2));
    let ext = hi.sub(lo);
    let d = mul(
        add(ext.x.max(ext.y.max(ext.z)), mul(2.0, delta)),
        add(1.0, mul(4.0, U)),
    );
    let dd = add(1.0, d);
    let e = mul(
        add(
            add(
                add(
                    add(
                        mul(mul(mul(mul(50.0, U), d), d), d),
                        mul(mul(mul(32.0, delta), d), d),
                    ),
                    mul(mul(mul(64.0, delta), delta), d),
                ),
                mul(mul(mul(42.0, delta), delta), delta),
            ),
            mul(mul(mul(64.0, TAU), dd), dd),
        ),
        1.01,
    );
    let e = e * env().bound_scale;
    let sp1 = sgn(orient(p2, q2, r2, p1), e);
    let sq1 = sgn(orient(p2, q2, r2, q1), e);
    let sr1 = sgn(orient(p2, q2, r2, r1), e);
    if sp1 != 0 && sp1 == sq1 && sp1 == sr1 {
        return TRI_DISJOINT;
    }
    let sp2 = sgn(orient(p1, q1, r1, p2), e);
    let sq2 = sgn(orient(p1, q1, r1, q2), e);
    let sr2 = sgn(orient(p1, q1, r1, r2), e);
    if sp2 != 0 && sp2 == sq2 && sp2 == sr2 {
        return TRI_DISJOINT;
    }
    if sp1 == 0 || sq1 == 0 || sr1 == 0 || sp2 == 0 || sq2 == 0 || sr2 == 0 {
        return TRI_UNCERTAIN;
    }
    let [p1, q1, r1, p2, q2, r2] =
        canonical_points([p1, q1, r1], [sp1, sq1, sr1], [p2, q2, r2], [sp2, sq2, sr2]);
    check_min_max(p1, q1, r1, p2, q2, r2, e)
}

/// `x 2^e` for an f32 `x` whose result is 0 or normal (the shader's `ldexp` where exact).
fn ldexp(x: f32, e: i32) -> f32 {
    let r = (x as f64 * 2f64.powi(e)) as f32;
    assert!(
        r == 0.0 || r.is_normal(),
        "ldexp({x}, {e}) = {r} is not exact"
    );
    r
}

/// The shader's one delta of `tri_pair`: `max(U (c_a |p_A| + 0.5 |o_A|), U (cp |pb| + co |o_B| +
/// cw |W or t|) + far) + 16 TAU`, times 1.01; `a = [c_a, |p_A|, |o_A|]`, `b = [cp, |pb|, co,
/// |o_B|, cw, |W or t|]`.
fn pair_delta(a: [f32; 3], b: [f32; 6], far: f32) -> f32 {
    let da = mul(U, mad(0.5, a[2], mul(a[0], a[1])));
    let db = mad(U, mad(b[4], b[5], mad(b[2], b[3], mul(b[0], b[1]))), far);
    mul(add(da.max(db), mul(16.0, TAU)), 1.01)
}

/// A triangle as the triangle pass loads it: offsets from its reference point and the point's
/// grid coordinates.
#[derive(Clone, Copy, Debug)]
pub(crate) struct TriOff {
    pub o: [V3; 3],
    pub k: [i64; 3],
}

/// Mirror of the shader's `exact_w` (limb by limb, every i32 operation checked for overflow),
/// asserted equal to [`crate::pack::ExactPose::w_units`]'s i128 value. `None`: `|W / f| >= 2^79`
/// (ruled out by the CPU's ranges; the shader then reports the pair uncertain).
pub(crate) fn exact_w(ep: &crate::pack::ExactPose, ka: [i64; 3], kb: [i64; 3]) -> Option<V3> {
    let w = ep.words();
    let direct = ep.w_units(ka, kb);
    let mode2 = w.fix[0] == 2;
    let sa = if mode2 { 46 } else { w.fix[1] - w.fix[2] + 46 };
    let ef = if mode2 { w.fix[1] - 46 } else { w.fix[2] - 46 };
    let kb = if mode2 { [0; 3] } else { kb };
    let ck = |x: Option<i32>| x.expect("i32 overflow in exact_w");
    let carry = |l: &mut [i32; 5]| {
        for i in 0..4 {
            let c = l[i] >> 16;
            l[i] &= 0xffff;
            l[i + 1] = ck(l[i + 1].checked_add(c));
        }
    };
    let mut out = [0f32; 3];
    for i in 0..3 {
        let mut l = [
            (w.t01[i] & 0xffff) as i32,
            (w.t01[i] >> 16) as i32,
            (w.t23[i] & 0xffff) as i32,
            (w.t23[i] >> 16) as i32,
            w.t4[i],
        ];
        // M k_B per limb of M, summed onto T's limbs unsplit (as the shader).
        let k = kb.map(|x| i32::try_from(x).unwrap());
        assert!(k.iter().all(|x| x.abs() <= 1 << crate::pack::GRID_BITS));
        let limb = |l: usize, j: usize| -> i32 {
            let lo = w.m_lo[j][i];
            match l {
                0 => (lo & 0xffff) as i32,
                1 => (lo >> 16) as i32,
                _ => w.m_hi[j][i],
            }
        };
        for (l, x) in l.iter_mut().enumerate().take(3) {
            for (j, &kj) in k.iter().enumerate() {
                *x = ck(x.checked_add(ck(limb(l, j).checked_mul(kj))));
            }
        }
        let q = (sa >> 4) as usize;
        let ks = ck(i32::try_from(ka[i]).unwrap().checked_mul(1 << (sa & 15)));
        l[q] = ck(l[q].checked_sub(ks & 0xffff));
        l[q + 1] = ck(l[q + 1].checked_sub(ks >> 16));
        carry(&mut l);
        let neg = l[4] < 0;
        if neg {
            for x in &mut l {
                *x = -*x;
            }
            carry(&mut l);
        }
        let v: i128 = (0..5).map(|m| (l[m] as i128) << (16 * m)).sum();
        assert_eq!(
            if neg { -v } else { v },
            direct[i],
            "exact_w: limbs disagree"
        );
        if l[4] >= 32768 {
            return None;
        }
        let big = l[4] != 0 || l[3] >= 32768;
        let (hi, lo, e0) = if big {
            (
                (l[4] << 16 | l[3]) as u32,
                (l[2] << 16 | l[1]) as u32,
                ef + 16,
            )
        } else {
            ((l[3] << 16 | l[2]) as u32, (l[1] << 16 | l[0]) as u32, ef)
        };
        let n1 = if hi == 0 { 0 } else { 32 - hi.leading_zeros() };
        let top = (hi << ((32 - n1) & 31)) | (lo >> n1);
        // u32 -> f32: one rounding, either direction (the environment's).
        let m = ldexp(round(top as f64, 0.0), n1 as i32 + e0);
        out[i] = if neg { -m } else { m };
    }
    Some(v3(out[0], out[1], out[2]))
}

/// Mirror of the shader's exact path: `exact_w`, then `tri_tri_exact` (`TRI_UNCERTAIN` when W
/// does not fit); mode 2 rebuilds B's vertices as `o_B + k_B 2^(e_B)` first.
pub(crate) fn tri_tri_exact(p: &PoseF, ep: &crate::pack::ExactPose, a: &TriOff, b: &TriOff) -> u32 {
    let Some(w) = exact_w(ep, a.k, b.k) else {
        return TRI_UNCERTAIN;
    };
    let mode2 = ep.words().fix[0] == 2;
    let ef = ep.fine_exponent();
    let kbx = if mode2 { [0; 3] } else { b.k };
    let cb = if mode2 {
        v3(
            ldexp(b.k[0] as f32, ep.eb),
            ldexp(b.k[1] as f32, ep.eb),
            ldexp(b.k[2] as f32, ep.eb),
        )
    } else {
        V3::default()
    };
    let [p1, q1, r1] = a.o;
    let ob_mag = maxabs(b.o[0]).max(maxabs(b.o[1]).max(maxabs(b.o[2])));
    let [pb, qb, rb] = b.o.map(|o| if mode2 { o.add(cb) } else { o });
    let p2 = rot(p, pb).add(w);
    let q2 = rot(p, qb).add(w);
    let r2 = rot(p, rb).add(w);
    let oa_mag = maxabs(p1).max(maxabs(q1).max(maxabs(r1)));
    let pb_mag = maxabs(pb).max(maxabs(qb).max(maxabs(rb)));
    let (cp, co) = if mode2 { (17.0, 2.0) } else { (16.0, 0.0) };
    let kb = v3(kbx[0] as f32, kbx[1] as f32, kbx[2] as f32);
    let far = mad(2f32.powi(-46), maxabs(p.t), ldexp(add(l1(kb), 0.5), ef));
    let delta = pair_delta(
        [0.0, oa_mag, oa_mag],
        [cp, pb_mag, co, ob_mag, 3.0, maxabs(w)],
        far,
    );
    tri_tri_core([p1, q1, r1], [p2, q2, r2], delta)
}

/// Mirror of the shader's rotated path: vertices rebuilt as `o + k 2^e` in f32 (grid exponents
/// `ea`, `eb`; 0 for a mesh without a grid, whose `k` are 0), then `tri_tri_rotated`.
pub(crate) fn tri_tri_rotated(p: &PoseF, ea: i32, eb: i32, a: &TriOff, b: &TriOff) -> u32 {
    let c = |k: [i64; 3], e: i32| {
        v3(
            ldexp(k[0] as f32, e),
            ldexp(k[1] as f32, e),
            ldexp(k[2] as f32, e),
        )
    };
    let (ca, cb) = (c(a.k, ea), c(b.k, eb));
    let mag = |o: [V3; 3]| maxabs(o[0]).max(maxabs(o[1]).max(maxabs(o[2])));
    let (oa_mag, ob_mag) = (mag(a.o), mag(b.o));
    let [p1, q1, r1] = a.o.map(|o| o.add(ca));
    let [pb, qb, rb] = b.o.map(|o| o.add(cb));
    let p2 = rot(p, pb).add(p.t);
    let q2 = rot(p, qb).add(p.t);
    let r2 = rot(p, rb).add(p.t);
    let pa_mag = maxabs(p1).max(maxabs(q1).max(maxabs(r1)));
    let pb_mag = maxabs(pb).max(maxabs(qb).max(maxabs(rb)));
    let delta = pair_delta(
        [1.0, pa_mag, oa_mag],
        [17.0, pb_mag, 2.0, ob_mag, 5.0, maxabs(p.t)],
        0.0,
    );
    tri_tri_core([p1, q1, r1], [p2, q2, r2], delta)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A xorshift stream of uniform values in [-1, 1), the same sequence for the same seed.
    fn signed_uniform(seed: u64) -> impl Fn() -> f64 {
        let state = Cell::new(seed);
        move || {
            let mut x = state.get();
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            state.set(x);
            (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        }
    }
    use crate::pack::{
        ExactPose, GRID_BITS, grid_coords, grid_exponent_for, grid_point, obb_to_f32,
        pack_tree_rows, unpack_k,
    };
    use frcd_geom::{DQuat, DVec3, Pose, Triangle, shapes};
    use frcd_obb::{BuildOptions, ObbTree, RelativeFrame, oracle};
    use frcd_tritri::Method;

    /// Guigue-Devillers' two permutation steps as the shader wrote them before they became
    /// selects (six rotations of triangle 1, each with six of triangle 2): the points each
    /// branch passed to CHECK_MIN_MAX.
    fn branching_points(a: [V3; 3], sa: [i32; 3], b: [V3; 3], sb: [i32; 3]) -> [V3; 6] {
        let [p1, q1, r1] = a;
        let [p2, q2, r2] = b;
        let [sp1, sq1, sr1] = sa;
        let [sp2, sq2, sr2] = sb;
        let step2 = |[p1, q1, r1]: [V3; 3], [p2, q2, r2]: [V3; 3], [sp2, sq2, sr2]: [i32; 3]| {
            if sp2 > 0 {
                if sq2 > 0 {
                    return [p1, r1, q1, r2, p2, q2];
                }
                if sr2 > 0 {
                    return [p1, r1, q1, q2, r2, p2];
                }
                return [p1, q1, r1, p2, q2, r2];
            }
            if sq2 < 0 {
                return [p1, q1, r1, r2, p2, q2];
            }
            if sr2 < 0 {
                return [p1, q1, r1, q2, r2, p2];
            }
            [p1, r1, q1, p2, q2, r2]
        };
        if sp1 > 0 {
            if sq1 > 0 {
                return step2([r1, p1, q1], [p2, r2, q2], [sp2, sr2, sq2]);
            }
            if sr1 > 0 {
                return step2([q1, r1, p1], [p2, r2, q2], [sp2, sr2, sq2]);
            }
            return step2([p1, q1, r1], [p2, q2, r2], [sp2, sq2, sr2]);
        }
        if sq1 < 0 {
            return step2([r1, p1, q1], [p2, q2, r2], [sp2, sq2, sr2]);
        }
        if sr1 < 0 {
            return step2([q1, r1, p1], [p2, q2, r2], [sp2, sq2, sr2]);
        }
        step2([p1, q1, r1], [p2, r2, q2], [sp2, sr2, sq2])
    }

    /// The selects of `canonical_points` (the shader's `lone_first` and swaps) pass the same
    /// points as the branching form for every generic sign pattern (36 of them: each
    /// triangle's signs nonzero and not all equal).
    #[test]
    fn select_permutation_equals_the_branching_form() {
        let point = |i: u8| V3 {
            x: i as f32,
            y: 0.0,
            z: 0.0,
        };
        let (a, b) = (
            [point(1), point(2), point(3)],
            [point(4), point(5), point(6)],
        );
        let generic: Vec<[i32; 3]> = (0..8)
            .map(|m| [0, 1, 2].map(|k| if m >> k & 1 == 1 { 1 } else { -1 }))
            .filter(|s| !(s[0] == s[1] && s[1] == s[2]))
            .collect();
        assert_eq!(generic.len(), 6);
        let mut checked = 0;
        for &sa in &generic {
            for &sb in &generic {
                let got = canonical_points(a, sa, b, sb).map(|v| v.x as u8);
                let want = branching_points(a, sa, b, sb).map(|v| v.x as u8);
                assert_eq!(got, want, "signs {sa:?} {sb:?}");
                // Each is a permutation within each triangle.
                let mut first = got[..3].to_vec();
                first.sort();
                assert_eq!(first, [1, 2, 3]);
                checked += 1;
            }
        }
        assert_eq!(checked, 36);
    }

    const MODES: [Rounding; 6] = [
        Rounding::Nearest,
        Rounding::Up,
        Rounding::Down,
        Rounding::TowardZero,
        Rounding::AwayFromZero,
        Rounding::Random,
    ];

    fn envs(bound_scale: f32) -> Vec<Env> {
        let mut out = Vec::new();
        for rounding in MODES {
            for ftz in [false, true] {
                for fma in [false, true] {
                    out.push(Env {
                        rounding,
                        ftz,
                        fma,
                        bound_scale,
                    });
                }
            }
        }
        out
    }

    fn f(v: DVec3) -> V3 {
        v3(v.x as f32, v.y as f32, v.z as f32)
    }

    /// As `query::pose_words`: R's rows and t rounded to nearest.
    fn pose_f(frame: &RelativeFrame) -> PoseF {
        let m = frame.m;
        let row = |k: usize| v3(m.x_axis[k] as f32, m.y_axis[k] as f32, m.z_axis[k] as f32);
        PoseF {
            r: [row(0), row(1), row(2)],
            t: f(frame.t),
        }
    }

    fn tri_f(t: &Triangle) -> [V3; 3] {
        [f(t.v[0]), f(t.v[1]), f(t.v[2])]
    }

    /// Pairs `(a, b_local, frame)` that touch for the exact f64 test, many of them only just:
    /// B is built through a point of A (vertex, edge point or interior point), sometimes
    /// coplanar, at scales from 1e-30 (products underflow f32: flush-to-zero territory) to
    /// 1e4 and offsets up to 1e7.
    fn touching_cases() -> Vec<(Triangle, Triangle, RelativeFrame)> {
        let rnd = signed_uniform(12345u64);
        let mut out = Vec::new();
        let scales = [1e-30, 1e-12, 1e-3, 1.0, 1e4];
        let offsets = [0.0, 1.0, 1e3, 1e7];
        let mut k = 0;
        while out.len() < 3000 && k < 200_000 {
            k += 1;
            let s = scales[k % scales.len()];
            let off = offsets[(k / 5) % offsets.len()];
            let o = DVec3::new(off, -0.5 * off, 0.25 * off);
            let rv = || DVec3::new(rnd(), rnd(), rnd());
            let a = Triangle::new(o + s * rv(), o + s * rv(), o + s * rv());
            // A point of A: a vertex, an edge point or an interior point.
            let (u, v) = match k % 3 {
                0 => (0.0, 0.0),
                1 => (0.5 * (rnd() + 1.0), 0.0),
                _ => (0.25 * (rnd() + 1.0), 0.25 * (rnd() + 1.0)),
            };
            let p = a.v[0] + u * (a.v[1] - a.v[0]) + v * (a.v[2] - a.v[0]);
            // B through p: p as a vertex, or B coplanar with A.
            let nrm = (a.v[1] - a.v[0]).cross(a.v[2] - a.v[0]);
            let b_world = if k % 4 == 0 {
                let t1 = (a.v[1] - a.v[0]).normalize_or_zero();
                let t2 = nrm.cross(t1).normalize_or_zero();
                Triangle::new(
                    p,
                    p + s * (rnd() * t1 + rnd() * t2),
                    p + s * (rnd() * t1 + rnd() * t2),
                )
            } else {
                Triangle::new(p, p + s * rv(), p + s * rv())
            };
            let q = DQuat::from_axis_angle(rv().normalize_or(DVec3::Z), 3.0 * rnd());
            let pose_b = Pose::new(o + s * rv(), q);
            let frame = RelativeFrame::new(&Pose::IDENTITY, &pose_b);
            // B's local coordinates, mapped back through the frame in f64 by the exact test.
            let inv = |x: DVec3| frame.m.transpose() * (x - frame.t);
            let b_local = Triangle::new(inv(b_world.v[0]), inv(b_world.v[1]), inv(b_world.v[2]));
            if frcd_tritri::intersects(Method::Exact, &a, &frame.triangle(&b_local)) {
                out.push((a, b_local, frame));
            }
        }
        out
    }

    /// Pairs `(a, b_local, frame)` that are disjoint for the exact f64 test, many of them only
    /// just: B starts a gap (1e-10 to 0.2 of the scale) off a point of A (vertex, edge point or
    /// interior point) and lies wholly on the far side of A's plane, or (coplanar) of one of
    /// A's edge lines, at the scales and offsets of `touching_cases`.
    fn disjoint_cases() -> Vec<(Triangle, Triangle, RelativeFrame)> {
        let rnd = signed_uniform(67890u64);
        let mut out = Vec::new();
        let scales = [1e-30, 1e-12, 1e-3, 1.0, 1e4];
        let offsets = [0.0, 1.0, 1e3, 1e7];
        let gaps = [1e-10, 1e-8, 1e-6, 1e-4, 1e-2, 0.2];
        let mut k = 0;
        while out.len() < 3000 && k < 200_000 {
            k += 1;
            let s = scales[k % scales.len()];
            let off = offsets[(k / 5) % offsets.len()];
            let gap = s * gaps[(k / 20) % gaps.len()];
            let o = DVec3::new(off, -0.5 * off, 0.25 * off);
            let rv = || DVec3::new(rnd(), rnd(), rnd());
            let a = Triangle::new(o + s * rv(), o + s * rv(), o + s * rv());
            let nrm = (a.v[1] - a.v[0]).cross(a.v[2] - a.v[0]).normalize_or_zero();
            let b_world = if k % 4 == 0 {
                // Coplanar, beyond the edge v0 v1: from a point of the edge, outward in A's
                // plane, every vertex of B at least `gap` past the edge's line.
                let e = (a.v[1] - a.v[0]).normalize_or_zero();
                let out_dir = nrm.cross(e);
                let out_dir = if out_dir.dot(a.v[2] - a.v[0]) > 0.0 {
                    -out_dir
                } else {
                    out_dir
                };
                let p = a.v[0] + 0.5 * (rnd() + 1.0) * (a.v[1] - a.v[0]) + gap * out_dir;
                let far = |x: f64| p + s * (rnd() * e + (x * 0.5 * (rnd() + 1.0)) * out_dir);
                Triangle::new(p, far(1.0), far(1.0))
            } else {
                let (u, v) = match k % 3 {
                    0 => (0.0, 0.0),
                    1 => (0.5 * (rnd() + 1.0), 0.0),
                    _ => (0.25 * (rnd() + 1.0), 0.25 * (rnd() + 1.0)),
                };
                let p = a.v[0] + u * (a.v[1] - a.v[0]) + v * (a.v[2] - a.v[0]) + gap * nrm;
                // The other vertices above A's plane too (a tangent part and a normal part).
                let up = |x: DVec3| p + s * (x - x.dot(nrm) * nrm + 0.5 * (rnd() + 1.0) * nrm);
                Triangle::new(p, up(rv()), up(rv()))
            };
            let q = DQuat::from_axis_angle(rv().normalize_or(DVec3::Z), 3.0 * rnd());
            let pose_b = Pose::new(o + s * rv(), q);
            let frame = RelativeFrame::new(&Pose::IDENTITY, &pose_b);
            let inv = |x: DVec3| frame.m.transpose() * (x - frame.t);
            let b_local = Triangle::new(inv(b_world.v[0]), inv(b_world.v[1]), inv(b_world.v[2]));
            if !frcd_tritri::intersects(Method::Exact, &a, &frame.triangle(&b_local)) {
                out.push((a, b_local, frame));
            }
        }
        out
    }

    /// A triangle of a one-triangle "mesh" as the packing stores it (grid from its own vertices).
    fn tri_off(t: &Triangle) -> (TriOff, Option<i32>) {
        let mag =
            t.v.iter()
                .map(|p| p.abs().max_element())
                .fold(0.0, f64::max);
        let e = grid_exponent_for(mag);
        let k = e.map_or([0; 3], |e| grid_point(&t.v, e));
        let c = grid_coords(k, e.unwrap_or(0));
        (
            TriOff {
                o: t.v.map(|v| f(v - c)),
                k,
            },
            e,
        )
    }

    /// The triangle pass as the shader runs it: the exact path where the pair's ranges hold
    /// (`Some` exact pose), else the rotated path.
    fn pass(
        pose: &PoseF,
        ep: Option<&ExactPose>,
        grids: (Option<i32>, Option<i32>),
        a: &TriOff,
        b: &TriOff,
    ) -> u32 {
        match ep {
            Some(ep) => tri_tri_exact(pose, ep, a, b),
            None => tri_tri_rotated(pose, grids.0.unwrap_or(0), grids.1.unwrap_or(0), a, b),
        }
    }

    /// `touching_cases` as the triangle pass sees them: (absolute f32 triangles for main's
    /// arithmetic, packed triangles, grids, exact pose if the ranges hold, f32 pose).
    fn packed_cases() -> Vec<PackedCase> {
        pack_cases(&touching_cases())
    }

    /// A case as the triangle pass sees it (see `packed_cases`).
    type PackedCase = (
        [V3; 3],
        [V3; 3],
        TriOff,
        TriOff,
        (Option<i32>, Option<i32>),
        Option<ExactPose>,
        PoseF,
    );

    fn pack_cases(cases: &[(Triangle, Triangle, RelativeFrame)]) -> Vec<PackedCase> {
        cases
            .iter()
            .map(|(a, b, frame)| {
                let (ta, ea) = tri_off(a);
                let (tb, eb) = tri_off(b);
                let ep = ExactPose::new(&frame.m, frame.t, ea, eb);
                (tri_f(a), tri_f(b), ta, tb, (ea, eb), ep, pose_f(frame))
            })
            .collect()
    }

    #[test]
    fn no_touching_triangle_pair_is_declared_disjoint_under_any_rounding() {
        let cases = packed_cases();
        assert!(cases.len() >= 1000, "{}", cases.len());
        // Most cases take the exact path; the tiny ones (1e-30) have no grid.
        let exact = cases.iter().filter(|c| c.5.is_some()).count();
        assert!(exact * 5 >= cases.len() * 3, "{exact} of {}", cases.len());
        for env in envs(1.0) {
            set_env(env);
            for (i, (a, b, ta, tb, grids, ep, pose)) in cases.iter().enumerate() {
                let r = tri_tri_absolute(pose, *a, *b);
                assert_ne!(r, TRI_DISJOINT, "{env:?}: case {i} lost (absolute)");
                let r = pass(pose, ep.as_ref(), *grids, ta, tb);
                assert_ne!(r, TRI_DISJOINT, "{env:?}: case {i} lost ({ep:?})");
                // The rotated path on every case, also where the exact one applies.
                let r = tri_tri_rotated(pose, grids.0.unwrap_or(0), grids.1.unwrap_or(0), ta, tb);
                assert_ne!(r, TRI_DISJOINT, "{env:?}: case {i} lost (rotated)");
            }
        }
        set_env(envs(1.0)[0]);
    }

    /// The other direction, which `Recheck::Uncertain` relies on: a pair the GPU reports as
    /// touching (not uncertain) touches, under every rounding mode, with and without FMA and
    /// flush-to-zero, on every path.
    #[test]
    fn no_disjoint_triangle_pair_is_declared_touching_under_any_rounding() {
        let cases = pack_cases(&disjoint_cases());
        assert!(cases.len() >= 1000, "{}", cases.len());
        let exact = cases.iter().filter(|c| c.5.is_some()).count();
        assert!(exact * 5 >= cases.len() * 3, "{exact} of {}", cases.len());
        // Under every environment, how many cases each path decided disjoint (the others
        // are uncertain): the gaps span both outcomes.
        let mut decided = [usize::MAX; 3];
        for env in envs(1.0) {
            set_env(env);
            let mut d = [0; 3];
            for (i, (a, b, ta, tb, grids, ep, pose)) in cases.iter().enumerate() {
                let r = tri_tri_absolute(pose, *a, *b);
                assert_ne!(r, TRI_TOUCH, "{env:?}: case {i} added (absolute)");
                d[0] += (r == TRI_DISJOINT) as usize;
                let r = pass(pose, ep.as_ref(), *grids, ta, tb);
                assert_ne!(r, TRI_TOUCH, "{env:?}: case {i} added ({ep:?})");
                d[1] += (r == TRI_DISJOINT) as usize;
                let r = tri_tri_rotated(pose, grids.0.unwrap_or(0), grids.1.unwrap_or(0), ta, tb);
                assert_ne!(r, TRI_TOUCH, "{env:?}: case {i} added (rotated)");
                d[2] += (r == TRI_DISJOINT) as usize;
            }
            decided = std::array::from_fn(|k| decided[k].min(d[k]));
        }
        set_env(envs(1.0)[0]);
        assert!(
            decided.iter().all(|&n| n > 100 && n < cases.len() - 100),
            "{decided:?} of {}",
            cases.len()
        );
    }

    #[test]
    fn without_the_bounds_some_rounding_declares_a_disjoint_pair_touching() {
        // The test above can fail: with the error bounds zeroed, some rounding declares some
        // disjoint pair touching, on each path.
        let cases = pack_cases(&disjoint_cases());
        let mut added = [0; 3];
        for env in envs(0.0) {
            set_env(env);
            for (a, b, ta, tb, grids, ep, pose) in &cases {
                let (ga, gb) = (grids.0.unwrap_or(0), grids.1.unwrap_or(0));
                added[0] += (tri_tri_absolute(pose, *a, *b) == TRI_TOUCH) as usize;
                added[1] += (tri_tri_rotated(pose, ga, gb, ta, tb) == TRI_TOUCH) as usize;
                if let Some(ep) = ep {
                    added[2] += (tri_tri_exact(pose, ep, ta, tb) == TRI_TOUCH) as usize;
                }
            }
        }
        set_env(envs(1.0)[0]);
        assert!(added.iter().all(|&n| n > 0), "{added:?}");
    }

    #[test]
    fn without_the_bounds_some_rounding_loses_a_pair() {
        // The test above can fail: with the error bounds zeroed, directed rounding declares
        // some touching pair disjoint, on each path.
        let cases = packed_cases();
        let mut lost = [0; 3];
        for env in envs(0.0) {
            set_env(env);
            for (a, b, ta, tb, grids, ep, pose) in &cases {
                let (ga, gb) = (grids.0.unwrap_or(0), grids.1.unwrap_or(0));
                lost[0] += (tri_tri_absolute(pose, *a, *b) == TRI_DISJOINT) as usize;
                lost[1] += (tri_tri_rotated(pose, ga, gb, ta, tb) == TRI_DISJOINT) as usize;
                if let Some(ep) = ep {
                    lost[2] += (tri_tri_exact(pose, ep, ta, tb) == TRI_DISJOINT) as usize;
                }
            }
        }
        set_env(envs(1.0)[0]);
        assert!(lost.iter().all(|&n| n > 0), "{lost:?}");
    }

    #[test]
    fn exact_w_matches_the_integer_value_within_its_bound() {
        // Random grid coordinates, rotations, translations and grid exponents across both
        // modes and the whole range (|W / f| up to 2^79, both windows of the conversion):
        // the limbs equal the i128 value (asserted inside `exact_w`) and the f32 W is within
        // 1.02 U |W| of it under every rounding mode.
        let rnd = signed_uniform(424242u64);
        let lim = (1i64 << GRID_BITS) as f64;
        let mut windows = [0usize; 2];
        let mut cases = Vec::new();
        for n in 0..4000 {
            let ea = -50 + (n % 73) as i32;
            let eb = ea - [0, 5, -16, 16, 30, -46, 3][n % 7];
            let q = DQuat::from_axis_angle(
                DVec3::new(rnd(), rnd(), rnd()).normalize_or(DVec3::Z),
                3.0 * rnd(),
            );
            let m = frcd_geom::DMat3::from_quat(q);
            // t of the meshes' size (A's grid times up to 2^16).
            let t = DVec3::new(rnd(), rnd(), rnd()) * 2f64.powi(ea + 16) * rnd().abs();
            let Some(ep) = ExactPose::new(&m, t, Some(ea), Some(eb).filter(|_| n % 11 != 0)) else {
                continue;
            };
            let k = || [rnd(), rnd(), rnd()].map(|x| (x * lim).round() as i64);
            cases.push((ep, k(), k()));
        }
        assert!(cases.len() > 3000, "{}", cases.len());
        for env in envs(1.0) {
            set_env(env);
            for (ep, ka, kb) in &cases {
                let exact = ep.w_units(*ka, *kb);
                let w = exact_w(ep, *ka, *kb).expect("in range");
                let f = 2f64.powi(ep.fine_exponent());
                for (i, got) in [w.x, w.y, w.z].into_iter().enumerate() {
                    let want = exact[i] as f64 * f;
                    windows[(exact[i].unsigned_abs() >> 64 != 0) as usize] += 1;
                    let err = (got as f64 - want).abs();
                    assert!(
                        err <= 1.02 * U as f64 * (got as f64).abs(),
                        "{env:?}: {ep:?} {ka:?} {kb:?}: {got} against {want}"
                    );
                }
            }
        }
        set_env(envs(1.0)[0]);
        assert!(windows.iter().all(|&n| n > 0), "{windows:?}");
    }

    #[test]
    fn exact_w_limbs_stay_in_i32_at_the_extremes() {
        // The largest words the CPU can give (|M| <= 2^46 with full low limbs, |T| < 2^78, A's
        // shift 62, |k| = 2^13) in every sign combination: `exact_w`'s checked i32 operations
        // must not overflow and must equal the i128 value.
        let big_t = (1i128 << 78) - 1;
        let kk = 1i64 << GRID_BITS;
        let mut n = 0;
        for m in [
            (1i64 << 46) - 1,
            -(1i64 << 46),
            (1i64 << 46) - 0x8001,
            0xffff_ffff,
        ] {
            for sm in [1, -1] {
                for st in [1, -1, 0] {
                    for sk in [1, -1] {
                        for (ea, eb) in [(16, 0), (-46, 0), (0, 0)] {
                            let ep = ExactPose {
                                mode: 1,
                                m: [[sm * m, -sm * m, sm * m]; 3],
                                t: [st * big_t, -st * big_t, st * (big_t >> 20)],
                                ea,
                                eb,
                            };
                            let k = [sk * kk, -sk * kk, sk * kk];
                            let w = exact_w(&ep, k, [-k[0], k[1], k[2]]);
                            assert!(w.is_some(), "{ep:?}");
                            n += 1;
                        }
                    }
                }
            }
        }
        assert_eq!(n, 144);
    }

    /// Box pairs that share a point for certain, most of them only just: a corner of A (the
    /// f32 parallelepiped) pushed a hair (1e-9 of its extents) through a face of B, which is
    /// placed by an f64 pose so that the face's outward normal looks at A (so the overlap is
    /// that hair, not a deep one). Scales 1e-3 to 1e4, A's centre up to 1e4 extents from the origin.
    fn touching_boxes() -> Vec<(NodeF, NodeF, PoseF)> {
        use crate::pack::ObbF32;
        use frcd_geom::DMat3;
        let rnd = signed_uniform(987654321u64);
        let rv = || DVec3::new(rnd(), rnd(), rnd());
        let rot = || {
            DMat3::from_quat(DQuat::from_axis_angle(
                rv().normalize_or(DVec3::Z),
                3.0 * rnd(),
            ))
        };
        let back = |v: [f32; 3]| DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64);
        let node = |c: DVec3, m: DMat3, h: DVec3| {
            let o = ObbF32 {
                center: [c.x as f32, c.y as f32, c.z as f32],
                axes: [m.x_axis, m.y_axis, m.z_axis].map(|a| [a.x as f32, a.y as f32, a.z as f32]),
                half_extents: [h.x as f32, h.y as f32, h.z as f32],
            };
            let w = |x: [f32; 3]| v3(x[0], x[1], x[2]);
            let n = NodeF {
                c: w(o.center),
                eps: o.axes_deviation(),
                a: o.axes.map(w),
                h: w(o.half_extents),
            };
            (o, n)
        };
        let mut out = Vec::new();
        let scales = [1e-3, 1.0, 1e4];
        // Offsets relative to the scale keep the f64 construction's rounding (<= 1e-12 of the
        // extents) far inside the 1e-9 hair, and f32's (~1e-3 of them) far outside it.
        let offsets = [0.0, 1e2, 1e4];
        for k in 0..3000 {
            let s = scales[k % 3];
            let off = s * offsets[(k / 3) % 3];
            let ext =
                |_: ()| DVec3::new(rnd().abs() + 0.1, rnd().abs() + 0.1, rnd().abs() + 0.1) * s;
            let (oa, na) = node(
                DVec3::new(off, -0.5 * off, 0.3 * off) + s * rv(),
                rot(),
                ext(()),
            );
            let (ob, nb) = node(s * rv(), rot(), ext(()));
            let r = rot();
            // Face j of B (sign sj), at a random point of it (1e-9 inside).
            let j = k % 3;
            let sj = if rnd() > 0.0 { 1.0 } else { -1.0 };
            let inner = 1.0 - 1e-9;
            let mut u = [0.9 * rnd(), 0.9 * rnd(), 0.9 * rnd()];
            u[j] = sj * inner;
            let bq = back(ob.center)
                + (0..3)
                    .map(|i| u[i] * ob.half_extents[i] as f64 * back(ob.axes[i]))
                    .fold(DVec3::ZERO, |x, y| x + y);
            let n = r * (sj * back(ob.axes[j]));
            // A's corner deepest towards -n, 1e-9 inside A.
            let p = back(oa.center)
                + (0..3)
                    .map(|i| {
                        let a = back(oa.axes[i]);
                        -a.dot(n).signum() * inner * oa.half_extents[i] as f64 * a
                    })
                    .fold(DVec3::ZERO, |x, y| x + y);
            // t such that R bq + t = p.
            let t = p - r * bq;
            let frame = RelativeFrame { m: r, t };
            out.push((na, nb, pose_f(&frame)));
        }
        out
    }

    #[test]
    fn no_touching_box_pair_is_separated_under_any_rounding() {
        let cases = touching_boxes();
        for env in envs(1.0) {
            set_env(env);
            for (i, (na, nb, pose)) in cases.iter().enumerate() {
                assert!(obb_overlap(pose, na, nb), "{env:?}: box case {i} lost");
            }
        }
        set_env(envs(1.0)[0]);
    }

    #[test]
    fn without_the_bound_some_rounding_separates_a_touching_box_pair() {
        let cases = touching_boxes();
        let mut lost = 0;
        for env in envs(0.0) {
            set_env(env);
            lost += cases
                .iter()
                .filter(|(na, nb, pose)| !obb_overlap(pose, na, nb))
                .count();
        }
        set_env(envs(1.0)[0]);
        assert!(lost > 0);
    }

    /// Ancestors of every triangle slot (root first).
    fn ancestors(tree: &ObbTree) -> Vec<Vec<usize>> {
        let mut out = vec![Vec::new(); tree.triangles().len()];
        let mut stack = vec![(0usize, vec![0usize])];
        while let Some((i, path)) = stack.pop() {
            let n = &tree.node(i as u32);
            if n.is_leaf() {
                for &t in &tree.leaf_triangles()[n.first as usize..(n.first + n.count) as usize] {
                    out[t as usize] = path.clone();
                }
            } else {
                for c in [i + 1, n.right as usize] {
                    let mut p = path.clone();
                    p.push(c);
                    stack.push((c, p));
                }
            }
        }
        out
    }

    /// The mesh's axes' bound, as `pack::PackedTree::eps` (the largest of its nodes').
    fn mesh_eps(tree: &ObbTree) -> f32 {
        (0..tree.node_count())
            .map(|k| {
                obb_to_f32(&tree.node(k as u32).obb, k)
                    .unwrap()
                    .axes_deviation()
            })
            .fold(0f32, f32::max)
    }

    /// Node `i` as the shader sees it, with its mesh's axes' bound `eps` ([`mesh_eps`]).
    fn node_f(tree: &ObbTree, i: usize, eps: f32) -> NodeF {
        let b = obb_to_f32(&tree.node(i as u32).obb, i).unwrap();
        let c = |x: [f32; 3]| v3(x[0], x[1], x[2]);
        NodeF {
            c: c(b.center),
            eps,
            a: [c(b.axes[0]), c(b.axes[1]), c(b.axes[2])],
            h: v3(b.half_extents[0], b.half_extents[1], b.half_extents[2]),
        }
    }

    #[test]
    fn no_node_pair_above_a_touching_pair_is_separated_under_any_rounding() {
        // Grazing contact (two cubes face to face, shifted and rotated a hair), far from the
        // origin, plus spheres through each other: every pair of ancestors of a touching
        // triangle pair must overlap in the emulated f32 test.
        let far = DVec3::new(1.0e5, -2.0e4, 3.0e3);
        let cube = shapes::cuboid(DVec3::splat(0.5));
        let sphere = shapes::icosphere(0.7, 2);
        let cases = [
            (
                cube.clone(),
                Pose::from_translation(far),
                cube.clone(),
                Pose::new(
                    far + DVec3::new(1.0, 0.3, 0.1),
                    DQuat::from_rotation_x(1e-7),
                ),
            ),
            (
                cube.clone(),
                Pose::new(far, DQuat::from_rotation_z(0.3)),
                cube,
                Pose::new(far, DQuat::from_rotation_z(0.3))
                    .compose(&Pose::from_translation(DVec3::new(0.2, 1.0 - 1e-9, 0.0))),
            ),
            (
                sphere.clone(),
                Pose::IDENTITY,
                sphere,
                Pose::new(DVec3::new(1.1, 0.2, -0.1), DQuat::from_rotation_y(0.8)),
            ),
        ];
        for (case, (ma, pa, mb, pb)) in cases.into_iter().enumerate() {
            let ta = ObbTree::build(&ma, &BuildOptions::default());
            let tb = ObbTree::build(&mb, &BuildOptions::default());
            let (anc_a, anc_b) = (ancestors(&ta), ancestors(&tb));
            let pairs = oracle::pairs(&ma, &pa, &mb, &pb);
            assert!(!pairs.is_empty(), "case {case}");
            let frame = RelativeFrame::new(&pa, &pb);
            let pose = pose_f(&frame);
            let ((pa_tris, ga), (pb_tris, gb)) = (packed(&ta), packed(&tb));
            let grids = (ga, gb);
            let ep = ExactPose::new(&frame.m, frame.t, ga, gb);
            assert!(ep.is_some(), "case {case}");
            let mut node_pairs = std::collections::BTreeSet::new();
            for &(i, j) in &pairs {
                for &x in &anc_a[i as usize] {
                    for &y in &anc_b[j as usize] {
                        node_pairs.insert((x, y));
                    }
                }
            }
            let (ea, eb) = (mesh_eps(&ta), mesh_eps(&tb));
            for env in envs(1.0) {
                set_env(env);
                for &(x, y) in &node_pairs {
                    assert!(
                        obb_overlap(&pose, &node_f(&ta, x, ea), &node_f(&tb, y, eb)),
                        "{env:?}: nodes ({x}, {y}) separated above a touching pair"
                    );
                }
                for &(i, j) in &pairs {
                    let (x, y) = (&pa_tris[i as usize], &pb_tris[j as usize]);
                    let r = pass(&pose, ep.as_ref(), grids, x, y);
                    assert_ne!(r, TRI_DISJOINT, "{env:?}: pair ({i}, {j}) lost");
                }
            }
        }
        set_env(envs(1.0)[0]);
    }

    /// Every triangle of a tree as `pack_tree_rows` stores it (decoded from the texels), by
    /// input index, and the mesh's grid exponent.
    fn packed(tree: &ObbTree) -> (Vec<TriOff>, Option<i32>) {
        let p = pack_tree_rows(tree, 64, 64).unwrap();
        let mut out = vec![
            TriOff {
                o: [V3::default(); 3],
                k: [0; 3]
            };
            tree.triangle_count()
        ];
        for slot in 0..tree.triangle_count() as u32 {
            let t: [[f32; 4]; 3] =
                std::array::from_fn(|j| p.tris[p.tri_layout.linear(slot, j as u32)]);
            out[t[0][3] as usize] = TriOff {
                o: t.map(|x| v3(x[0], x[1], x[2])),
                k: unpack_k(t[1][3], t[2][3]),
            };
        }
        (out, p.grid)
    }

    #[test]
    fn on_icospheres_through_each_other_the_exact_path_is_never_wrong_and_rarely_uncertain() {
        // Two icospheres (5,120 triangles each) through each other, at the origin and 3e3 away
        // (the GPU test `the_exact_path_leaves_far_fewer_uncertain_pairs`'s scene): every triangle pair whose f64 boxes (B mapped into A's frame) meet, decided by
        // the triangle pass as it runs now under every rounding mode, never wrong (disjoint
        // when touching, touching when disjoint); and far fewer uncertain than main's
        // arithmetic (round to nearest; counted over all candidates, as the GPU reports them).
        let ma = shapes::icosphere(1.0, 4);
        let mb = shapes::icosphere(0.9, 4);
        let (ta, tb) = (
            ObbTree::build(&ma, &BuildOptions::default()),
            ObbTree::build(&mb, &BuildOptions::default()),
        );
        let ((pa_tris, ga), (pb_tris, gb)) = (packed(&ta), packed(&tb));
        let far = DVec3::new(3.0e3, -1.0e3, 500.0);
        let (mut old, mut new, mut touching, mut candidates) = (0, 0, 0, 0);
        for k in 0..6 {
            let s = k as f64 / 6.0;
            let base = if k % 2 == 0 { DVec3::ZERO } else { far };
            let pose_a = Pose::new(base, DQuat::from_rotation_y(0.3 * s));
            let pose_b = Pose::new(
                base + DVec3::new(0.4 + 1.2 * s, 0.11, -0.05),
                DQuat::from_rotation_z(0.9 * s) * DQuat::from_rotation_x(0.4),
            );
            let frame = RelativeFrame::new(&pose_a, &pose_b);
            let pose = pose_f(&frame);
            let ep = ExactPose::new(&frame.m, frame.t, ga, gb);
            assert!(ep.is_some());
            let b_mapped: Vec<Triangle> = mb.triangles().map(|t| frame.triangle(&t)).collect();
            let bounds = |t: &Triangle| {
                let lo = t.v[0].min(t.v[1]).min(t.v[2]) - DVec3::splat(1e-6);
                let hi = t.v[0].max(t.v[1]).max(t.v[2]) + DVec3::splat(1e-6);
                (lo, hi)
            };
            let bb: Vec<_> = b_mapped.iter().map(bounds).collect();
            let mut cand = Vec::new();
            for (i, t) in ma.triangles().enumerate() {
                let (lo, hi) = bounds(&t);
                for (j, (l2, h2)) in bb.iter().enumerate() {
                    if lo.cmple(*h2).all() && l2.cmple(hi).all() {
                        let exact = frcd_tritri::intersects(Method::Exact, &t, &b_mapped[j]);
                        cand.push((i, j, exact));
                    }
                }
            }
            candidates += cand.len();
            touching += cand.iter().filter(|c| c.2).count();
            for env in envs(1.0) {
                set_env(env);
                for &(i, j, exact) in &cand {
                    let r = pass(&pose, ep.as_ref(), (ga, gb), &pa_tris[i], &pb_tris[j]);
                    let wrong = (exact && r == TRI_DISJOINT) || (!exact && r == TRI_TOUCH);
                    assert!(
                        !wrong,
                        "{env:?}: pose {k}, pair ({i}, {j}): {r}, exact {exact}"
                    );
                }
            }
            set_env(envs(1.0)[0]);
            for &(i, j, _) in &cand {
                let (x, y) = (ma.triangle(i), mb.triangle(j));
                old += (tri_tri_absolute(&pose, tri_f(&x), tri_f(&y)) == TRI_UNCERTAIN) as usize;
                new += (pass(&pose, ep.as_ref(), (ga, gb), &pa_tris[i], &pb_tris[j])
                    == TRI_UNCERTAIN) as usize;
            }
        }
        println!(
            "icospheres: {candidates} candidates, {touching} touching: {old} uncertain before, {new} now"
        );
        assert!(touching > 500, "{touching}");
        assert!(old > 100, "{old}");
        assert!(new * 10 <= old, "{new} against {old}");
    }
}
