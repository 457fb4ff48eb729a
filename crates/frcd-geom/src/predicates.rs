//! Orientation predicates on f64 input points.
//!
//! PLACEHOLDER: plain floating point. Being replaced by the exact, underflow-safe implementation
//! (filter + exact expansion fallback); the signatures stay.
use glam::{DVec2, DVec3};

/// Sign of the determinant `[b-a, c-a, d-a]` = `(b-a)·((c-a)×(d-a))`... as `-1`, `0` or `1`.
/// Positive when `d` lies on the side of the plane `(a, b, c)` that `(b-a)×(c-a)` points to.
pub fn orient3d(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> i8 {
    let v = (b - a).cross(c - a).dot(d - a);
    if v > 0.0 {
        1
    } else if v < 0.0 {
        -1
    } else {
        0
    }
}

/// Sign of `(b-a)×(c-a)` in 2D as `-1`, `0` or `1` (positive: counter-clockwise).
pub fn orient2d(a: DVec2, b: DVec2, c: DVec2) -> i8 {
    let v = (b - a).perp_dot(c - a);
    if v > 0.0 {
        1
    } else if v < 0.0 {
        -1
    } else {
        0
    }
}

/// True when the three points are collinear (the triangle they span has zero area).
pub fn collinear3(a: DVec3, b: DVec3, c: DVec3) -> bool {
    let xy = |p: DVec3| DVec2::new(p.x, p.y);
    let yz = |p: DVec3| DVec2::new(p.y, p.z);
    let zx = |p: DVec3| DVec2::new(p.z, p.x);
    orient2d(xy(a), xy(b), xy(c)) == 0
        && orient2d(yz(a), yz(b), yz(c)) == 0
        && orient2d(zx(a), zx(b), zx(c)) == 0
}
