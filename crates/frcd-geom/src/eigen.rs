//! Eigen-decomposition of symmetric 3×3 matrices (covariances), for fitting box axes.
//!
//! [`symmetric_eigen`] is closed form: the eigenvalues from the trigonometric solution of the
//! characteristic cubic, the eigenvector of the best separated eigenvalue from the largest cross
//! product of two rows of `A − λI` (D. Eberly, "A Robust Eigensolver for 3×3 Symmetric
//! Matrices", Geometric Tools, 2014), the other two from one Jacobi rotation of the 2×2 problem
//! in the plane orthogonal to it (accurate even where two eigenvalues nearly coincide, where the
//! cubic's roots are only good to √ε). About ten times faster than cyclic Jacobi sweeps, which
//! remain the fallback ([`symmetric_eigen_jacobi`]) whenever the closed form cannot give a finite
//! orthonormal basis.

use glam::{DMat3, DVec3};

/// Eigenvalues and eigenvectors of the symmetric matrix `m` (only its upper triangle is read):
/// `(values, vectors)` with `values` ascending and `vectors`' columns the matching unit
/// eigenvectors, forming a right-handed orthonormal basis. `None` when `m` has a non-finite
/// entry.
///
/// ```
/// use frcd_geom::{eigen::symmetric_eigen, DMat3, DVec3};
/// let m = DMat3::from_cols(
///     DVec3::new(2.0, 1.0, 0.0),
///     DVec3::new(1.0, 2.0, 0.0),
///     DVec3::new(0.0, 0.0, 5.0),
/// );
/// let (values, vectors) = symmetric_eigen(m).unwrap();
/// assert!((values - DVec3::new(1.0, 3.0, 5.0)).abs().max_element() < 1e-12);
/// for k in 0..3 {
///     let v = vectors.col(k);
///     assert!((m * v - values[k] * v).length() < 1e-12);
/// }
/// ```
pub fn symmetric_eigen(m: DMat3) -> Option<(DVec3, DMat3)> {
    let (a00, a01, a02) = (m.x_axis.x, m.y_axis.x, m.z_axis.x);
    let (a11, a12, a22) = (m.y_axis.y, m.z_axis.y, m.z_axis.z);
    let max_abs = [a00, a01, a02, a11, a12, a22]
        .iter()
        .fold(0.0f64, |s, x| s.max(x.abs()));
    if !max_abs.is_finite() || [a00, a01, a02, a11, a12, a22].iter().any(|x| x.is_nan()) {
        return None;
    }
    if max_abs == 0.0 {
        return Some((DVec3::ZERO, DMat3::IDENTITY));
    }
    closed_form(max_abs, [a00, a01, a02, a11, a12, a22]).or_else(|| {
        let upper = DMat3::from_cols(
            DVec3::new(a00, a01, a02),
            DVec3::new(a01, a11, a12),
            DVec3::new(a02, a12, a22),
        );
        Some(symmetric_eigen_jacobi(upper))
    })
}

/// The closed form on the matrix scaled by `1 / max_abs` (so no intermediate overflows or
/// underflows); `None` when rounding leaves it without a finite orthonormal basis.
fn closed_form(max_abs: f64, a: [f64; 6]) -> Option<(DVec3, DMat3)> {
    let inv = 1.0 / max_abs;
    let [a00, a01, a02, a11, a12, a22] = a.map(|x| x * inv);
    // An exactly diagonal matrix has the world axes; also keeps the cubic's `p > 0` below.
    let norm = a01 * a01 + a02 * a02 + a12 * a12;
    if norm == 0.0 {
        return Some(sorted_diagonal([a00, a11, a22], max_abs));
    }
    // Few divisions and square roots: they are most of this function's latency.
    let q = (a00 + a11 + a22) * (1.0 / 3.0);
    let (b00, b11, b22) = (a00 - q, a11 - q, a22 - q);
    let p = ((b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * norm) * (1.0 / 6.0)).sqrt();
    let inv_p = 1.0 / p;
    let c00 = b11 * b22 - a12 * a12;
    let c01 = a01 * b22 - a12 * a02;
    let c02 = a01 * a12 - b11 * a02;
    let det = (b00 * c00 - a01 * c01 + a02 * c02) * (inv_p * inv_p * inv_p);
    let half_det = (0.5 * det).clamp(-1.0, 1.0);
    let rows = [
        DVec3::new(a00, a01, a02),
        DVec3::new(a01, a11, a12),
        DVec3::new(a02, a12, a22),
    ];
    // The eigenvalue farther from the middle one is the better separated (and accurate to a few
    // ulp; the other two are only accurate to √ε when they nearly coincide): its vector from
    // the cubic's root, the other two from the 2×2 problem in the plane orthogonal to it.
    // The roots are q + 2p·c with c the roots of 4c³ − 3c = half_det (c = cos(θ/3 + 2πk/3),
    // cos θ = half_det): the largest for half_det ≥ 0, else the smallest, minus the largest
    // root for −half_det (the cubic is odd).
    let c = largest_chebyshev_root(half_det.abs());
    let lone = q + 2.0 * p * if half_det >= 0.0 { c } else { -c };
    let w = eigenvector_of_simple(rows, lone)?;
    let ([l0, l1], [v0, v1]) = pair_in_complement(rows, w);
    // Three compare-exchanges sort the pairs ascending.
    let mut e = [(lone, w), (l0, v0), (l1, v1)];
    for (i, j) in [(0, 1), (1, 2), (0, 1)] {
        if e[j].0 < e[i].0 {
            e.swap(i, j);
        }
    }
    let vectors = DMat3::from_cols(e[0].1, e[1].1, e[0].1.cross(e[1].1));
    if !(vectors.is_finite() && e[0].0 <= e[1].0 && e[1].0 <= e[2].0) {
        return None;
    }
    let values = DVec3::new(e[0].0, e[1].0, e[2].0);
    Some((values * max_abs, vectors))
}

/// `cos(acos(y) / 3)` for `y` in `[0, 1]`, the largest root of `4c³ − 3c = y` (in
/// `[√3/2, 1]`, where the derivative `12c² − 3` is at least 6), without trigonometry: a cubic
/// interpolant (within 5·10⁻⁵) and two Newton steps (quadratic convergence: within an ulp or so).
#[inline]
fn largest_chebyshev_root(y: f64) -> f64 {
    let mut c = 0.866_066_329_533_191_7
        + y * (0.165_330_350_220_845_4
            + y * (-0.040_691_197_422_887_7 + y * 0.009_319_683_897_481_92));
    for _ in 0..2 {
        c -= (4.0 * c * c * c - 3.0 * c - y) / (12.0 * c * c - 3.0);
    }
    c
}

fn sorted_diagonal(d: [f64; 3], scale: f64) -> (DVec3, DMat3) {
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| d[i].total_cmp(&d[j]));
    let e = [DVec3::X, DVec3::Y, DVec3::Z];
    let (x, y) = (e[order[0]], e[order[1]]);
    (
        DVec3::new(d[order[0]], d[order[1]], d[order[2]]) * scale,
        DMat3::from_cols(x, y, x.cross(y)),
    )
}

/// Unit eigenvector of a simple eigenvalue: `A − λI` has rank 2, and the largest cross product
/// of two of its rows spans its kernel.
fn eigenvector_of_simple(rows: [DVec3; 3], value: f64) -> Option<DVec3> {
    let r0 = rows[0] - DVec3::X * value;
    let r1 = rows[1] - DVec3::Y * value;
    let r2 = rows[2] - DVec3::Z * value;
    let c = [r0.cross(r1), r0.cross(r2), r1.cross(r2)];
    let d = c.map(|v| v.length_squared());
    let k = if d[0] >= d[1] && d[0] >= d[2] {
        0
    } else if d[1] >= d[2] {
        1
    } else {
        2
    };
    let len = d[k].sqrt();
    (len > 0.0 && len.is_finite()).then(|| c[k] * (1.0 / len))
}

/// The other two eigenpairs, orthogonal to the unit eigenvector `w`: the 2×2 restriction of `A`
/// to the plane orthogonal to `w`, diagonalised by one Jacobi rotation (accurate however close
/// the two eigenvalues are).
fn pair_in_complement(rows: [DVec3; 3], w: DVec3) -> ([f64; 2], [DVec3; 2]) {
    let u = if w.x.abs() > w.y.abs() {
        DVec3::new(-w.z, 0.0, w.x) * (1.0 / (w.x * w.x + w.z * w.z).sqrt())
    } else {
        DVec3::new(0.0, w.z, -w.y) * (1.0 / (w.y * w.y + w.z * w.z).sqrt())
    };
    let v = w.cross(u);
    let mul = |x: DVec3| DVec3::new(rows[0].dot(x), rows[1].dot(x), rows[2].dot(x));
    let (au, av) = (mul(u), mul(v));
    let (a, b, c) = (u.dot(au), 0.5 * (u.dot(av) + v.dot(au)), v.dot(av));
    if b == 0.0 {
        return ([a, c], [u, v]);
    }
    let tau = (c - a) / (2.0 * b);
    // tan of the rotation angle, the smaller root of t² + 2τt − 1 = 0.
    let t = if tau.abs() > 1e150 {
        0.5 / tau
    } else {
        tau.signum() / (tau.abs() + (tau * tau + 1.0).sqrt())
    };
    let cs = 1.0 / (t * t + 1.0).sqrt();
    let sn = t * cs;
    ([a - t * b, c + t * b], [u * cs - v * sn, u * sn + v * cs])
}

/// Eigenvalues (ascending) and unit eigenvectors (columns, right-handed) of the symmetric
/// matrix `m` by cyclic Jacobi rotations: slower than [`symmetric_eigen`], kept as its fallback
/// and as a reference in tests. The identity basis for a zero or non-finite matrix.
pub fn symmetric_eigen_jacobi(m: DMat3) -> (DVec3, DMat3) {
    let mut a = m.to_cols_array_2d();
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let scale = a.iter().flatten().fold(0.0f64, |s, x| s.max(x.abs()));
    if scale == 0.0 || !scale.is_finite() {
        return (DVec3::ZERO, DMat3::IDENTITY);
    }
    for _sweep in 0..32 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        if off <= scale * 1e-15 {
            break;
        }
        for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
            if a[p][q].abs() <= scale * 1e-18 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let cs = 1.0 / (t * t + 1.0).sqrt();
            let sn = t * cs;
            // A ← Jᵀ A J: columns p, q, then rows p, q.
            for row in a.iter_mut() {
                let (akp, akq) = (row[p], row[q]);
                row[p] = cs * akp - sn * akq;
                row[q] = sn * akp + cs * akq;
            }
            let (rp, rq) = (a[p], a[q]);
            for k in 0..3 {
                a[p][k] = cs * rp[k] - sn * rq[k];
                a[q][k] = sn * rp[k] + cs * rq[k];
            }
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = cs * vp - sn * vq;
                row[q] = sn * vp + cs * vq;
            }
        }
    }
    // Columns of v (v[row][col]) are eigenvectors; sort by eigenvalue, ascending.
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| a[i][i].total_cmp(&a[j][j]));
    let col = |k: usize| DVec3::new(v[0][k], v[1][k], v[2][k]).normalize();
    let x = col(order[0]);
    let y0 = col(order[1]);
    let y = (y0 - x * x.dot(y0)).normalize();
    let z = x.cross(y);
    if !(x.is_finite() && y.is_finite() && z.is_finite()) {
        return (DVec3::ZERO, DMat3::IDENTITY);
    }
    (
        DVec3::new(
            a[order[0]][order[0]],
            a[order[1]][order[1]],
            a[order[2]][order[2]],
        ),
        DMat3::from_cols(x, y, z),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DQuat;

    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// `Q diag(d) Qᵀ` for a random rotation `Q`.
    fn with_spectrum(rng: &mut Rng, d: DVec3) -> (DMat3, DMat3) {
        let q = DQuat::from_euler(
            glam::EulerRot::XYZ,
            rng.next() * 7.0,
            rng.next() * 7.0,
            rng.next() * 7.0,
        );
        let r = DMat3::from_quat(q);
        (r * DMat3::from_diagonal(d) * r.transpose(), r)
    }

    /// Residual, orthonormality, handedness and order of a decomposition of `m`.
    fn check(m: DMat3, values: DVec3, vectors: DMat3) {
        let scale = m.to_cols_array().iter().fold(0.0f64, |s, x| s.max(x.abs()));
        assert!(values.x <= values.y && values.y <= values.z, "{values}");
        for k in 0..3 {
            let v = vectors.col(k);
            assert!((v.length() - 1.0).abs() < 1e-12);
            let r = (m * v - values[k] * v).length();
            assert!(r <= 1e-12 * scale.max(f64::MIN_POSITIVE), "{m} {k} {r}");
        }
        let o = vectors.transpose() * vectors - DMat3::IDENTITY;
        assert!(o.to_cols_array().iter().all(|x| x.abs() < 1e-12), "{o}");
        assert!((vectors.determinant() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn chebyshev_root_matches_the_trigonometric_form() {
        for i in 0..=100_000 {
            let y = i as f64 / 100_000.0;
            let c = largest_chebyshev_root(y);
            let want = (y.acos() / 3.0).cos();
            assert!(
                (c - want).abs() <= 4.0 * f64::EPSILON,
                "{y}: {c} against {want}"
            );
        }
    }

    #[test]
    fn random_spectra_match_jacobi() {
        let mut rng = Rng(1);
        for i in 0..2000 {
            let d = match i % 5 {
                // Distinct, repeated (two kinds), rank one, with a zero.
                0 => DVec3::new(rng.next(), rng.next(), rng.next()),
                1 => DVec3::new(0.3, 0.3, rng.next()),
                2 => DVec3::new(rng.next(), 0.7, 0.7),
                3 => DVec3::new(0.0, 0.0, 1.0 + rng.next()),
                _ => DVec3::new(0.0, rng.next(), rng.next()),
            };
            let (m, _) = with_spectrum(&mut rng, d);
            let (values, vectors) = symmetric_eigen(m).unwrap();
            check(m, values, vectors);
            let (jv, _) = symmetric_eigen_jacobi(m);
            assert!((values - jv).abs().max_element() < 1e-12, "{values} {jv}");
        }
    }

    #[test]
    fn well_separated_vectors_are_recovered() {
        let mut rng = Rng(2);
        for _ in 0..500 {
            let (m, r) = with_spectrum(&mut rng, DVec3::new(1.0, 2.0, 4.0));
            let (_, vectors) = symmetric_eigen(m).unwrap();
            for k in 0..3 {
                assert!(vectors.col(k).dot(r.col(k)).abs() > 1.0 - 1e-12);
            }
        }
    }

    #[test]
    fn extreme_scales_and_special_matrices() {
        let mut rng = Rng(3);
        for scale in [1e-300, 1e-310, 4.9e-324, 1e-150, 1e150, 1e300] {
            for _ in 0..50 {
                let d = DVec3::new(rng.next(), rng.next(), rng.next());
                let (m, _) = with_spectrum(&mut rng, d);
                let m = m * scale;
                let (values, vectors) = symmetric_eigen(m).unwrap();
                // Subnormal matrices lose relative precision: check the basis only.
                let o = vectors.transpose() * vectors - DMat3::IDENTITY;
                assert!(o.to_cols_array().iter().all(|x| x.abs() < 1e-12));
                assert!(values.is_finite());
                if (1e-150..=1e150).contains(&scale) {
                    check(m, values, vectors);
                }
            }
        }
        assert_eq!(
            symmetric_eigen(DMat3::ZERO),
            Some((DVec3::ZERO, DMat3::IDENTITY))
        );
        let (v, b) = symmetric_eigen(DMat3::from_diagonal(DVec3::new(3.0, 1.0, 2.0))).unwrap();
        assert_eq!(v, DVec3::new(1.0, 2.0, 3.0));
        check(DMat3::from_diagonal(DVec3::new(3.0, 1.0, 2.0)), v, b);
        let i7 = DMat3::IDENTITY * 7.0;
        let (v, b) = symmetric_eigen(i7).unwrap();
        check(i7, v, b);
        let mut bad = DMat3::IDENTITY;
        bad.y_axis.x = f64::NAN;
        assert!(symmetric_eigen(bad).is_none());
        bad.y_axis.x = f64::INFINITY;
        assert!(symmetric_eigen(bad).is_none());
        // Entries near the overflow threshold: scaled before any product.
        let big = DMat3::from_cols(
            DVec3::new(f64::MAX / 4.0, f64::MAX / 8.0, 0.0),
            DVec3::new(f64::MAX / 8.0, f64::MAX / 4.0, 0.0),
            DVec3::new(0.0, 0.0, 1.0),
        );
        let (v, b) = symmetric_eigen(big).unwrap();
        assert!(v.is_finite() && b.is_finite());
        assert!(b.col(2).dot(DVec3::new(1.0, 1.0, 0.0).normalize()).abs() > 1.0 - 1e-12);
    }
}
