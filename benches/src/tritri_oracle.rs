//! An independent exact oracle for triangle-triangle intersection: rational linear programming.
//!
//! Two closed triangles `A = conv(a0, a1, a2)` and `B = conv(b0, b1, b2)` meet iff there are
//! barycentric weights `λ, μ ≥ 0`, `Σλ = Σμ = 1`, with `Σ λ_i a_i = Σ μ_j b_j`. With
//! `λ0 = 1 − λ1 − λ2` and `μ0 = 1 − μ1 − μ2` that is a feasibility problem in four unknowns with
//! three equations and six inequalities. It is solved exactly over `BigRational`: Gaussian
//! elimination of the equations, then Fourier-Motzkin elimination of the remaining unknowns.
//!
//! It shares no code with `frcd_tritri::exact` (no orientation predicates, no case analysis),
//! works unchanged for coplanar and zero-area triangles, and is slow (tens of microseconds):
//! it labels test and stress data. This file is also compiled into frcd-tritri's tests.
use frcd_geom::DVec3;
use num_rational::BigRational;
use num_traits::{Signed, Zero};

fn q(x: f64) -> BigRational {
    BigRational::from_float(x).expect("finite coordinate")
}

/// `Σ row[v]·x_v ≤ row[4]` (or `= row[4]` for equations).
type Row = [BigRational; 5];

fn combine(p: &Row, cp: &BigRational, n: &Row, cn: &BigRational) -> Row {
    // cp·n − cn·p eliminates the variable whose coefficients are cp (in p) and cn (in n).
    std::array::from_fn(|i| cp * &n[i] - cn * &p[i])
}

/// True when the closed triangles `a` and `b` (finite coordinates) share a point, decided with
/// exact rational arithmetic.
pub fn lp_intersects(a: &[DVec3; 3], b: &[DVec3; 3]) -> bool {
    let z = BigRational::zero;
    let one = || BigRational::from_integer(1.into());
    let mut eqs: Vec<Row> = (0..3)
        .map(|c| {
            let a0 = q(a[0][c]);
            let b0 = q(b[0][c]);
            [
                q(a[1][c]) - &a0,
                q(a[2][c]) - &a0,
                -(q(b[1][c]) - &b0),
                -(q(b[2][c]) - &b0),
                b0 - a0,
            ]
        })
        .collect();
    let mut ineqs: Vec<Row> = Vec::with_capacity(8);
    for v in 0..4 {
        let mut r: Row = std::array::from_fn(|_| z());
        r[v] = -one();
        ineqs.push(r);
    }
    ineqs.push([one(), one(), z(), z(), one()]);
    ineqs.push([z(), z(), one(), one(), one()]);

    // Gaussian elimination: each equation with a non-zero coefficient removes one unknown.
    while let Some(e) = eqs.pop() {
        let Some(v) = (0..4).find(|&v| !e[v].is_zero()) else {
            if !e[4].is_zero() {
                return false; // 0 = non-zero
            }
            continue;
        };
        let cv = e[v].clone();
        let subst = |r: &mut Row| {
            if r[v].is_zero() {
                return;
            }
            let f = &r[v] / &cv;
            for i in 0..5 {
                let d = &f * &e[i];
                r[i] -= d;
            }
        };
        eqs.iter_mut().for_each(subst);
        ineqs.iter_mut().for_each(subst);
    }

    // Fourier-Motzkin on whatever unknowns remain.
    for v in 0..4 {
        let (mut pos, mut neg, mut rest) = (Vec::new(), Vec::new(), Vec::new());
        for r in ineqs {
            if r[v].is_positive() {
                pos.push(r);
            } else if r[v].is_negative() {
                neg.push(r);
            } else {
                rest.push(r);
            }
        }
        for p in &pos {
            for n in &neg {
                // p[v] > 0, n[v] < 0: p[v]·n − n[v]·p has a zero coefficient on v and is a
                // non-negative combination (p[v] > 0, −n[v] > 0).
                let mut r = combine(p, &p[v], n, &n[v]);
                normalize(&mut r);
                rest.push(r);
            }
        }
        rest.sort();
        rest.dedup();
        ineqs = rest;
    }
    ineqs.iter().all(|r| !r[4].is_negative())
}

/// Scales an inequality by a positive factor so that its largest coefficient has magnitude 1
/// (keeps the numbers small through Fourier-Motzkin).
fn normalize(r: &mut Row) {
    let m = r
        .iter()
        .map(|x| x.abs())
        .max()
        .unwrap_or_else(BigRational::zero);
    if !m.is_zero() {
        for x in r.iter_mut() {
            *x = &*x / &m;
        }
    }
}
