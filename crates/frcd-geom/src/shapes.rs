//! Procedural closed meshes with outward normals, for tests, benches and demos.
//!
//! Every shape here is a closed, consistently oriented 2-manifold with positive signed volume, no
//! degenerate or duplicate triangles (tested over coarse and fine tessellations). Sizes are in
//! metres where a default is given (railway scale for wheels, rails, springs and gears); shapes
//! are centred on the origin unless stated.
//!
//! Two generic builders keep the shapes short: [`revolve`] (a profile turned about the z axis)
//! and [`sweep`] (a cross-section carried along a path of frames). [`subdivide`] refines any
//! mesh 1 → 4 for stress sizes and [`merge`] concatenates meshes (several components).
//!
//! | shape | builder | components | genus |
//! |---|---|---|---|
//! | [`cuboid`], [`icosphere`], [`uv_sphere`], [`cylinder`] | direct / revolve | 1 | 0 |
//! | [`torus`] | revolve (closed profile) | 1 | 1 |
//! | [`torus_knot`] | sweep (closed path) | 1 | 1 |
//! | [`spur_gear`] | extrusion | 1 | 0, or 1 with a bore |
//! | [`coil_spring`] | sweep (open path, capped) | 1 | 0 |
//! | [`wheel`] | revolve (closed profile, bore) | 1 | 1 |
//! | [`wheelset`] | revolve (pole to pole) | 1 | 0 |
//! | [`rail`] | sweep (open path, capped) | 1 | 0 |

use crate::{MeshError, Pose, TriMesh};
use glam::{DQuat, DVec2, DVec3};
use std::collections::HashMap;
use std::f64::consts::{PI, TAU};

/// Why a shape could not be built.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ShapeError {
    /// A parameter is out of its valid range.
    #[error("{shape}: invalid parameter `{param}`: {reason}")]
    InvalidParameter {
        /// The shape or builder.
        shape: &'static str,
        /// The parameter's name.
        param: &'static str,
        /// What is wrong.
        reason: &'static str,
    },
    /// The generated mesh was refused (e.g. coordinates overflowed to infinity).
    #[error("{shape}: {source}")]
    Mesh {
        /// The shape or builder.
        shape: &'static str,
        /// The validation error.
        source: MeshError,
    },
}

fn check(
    ok: bool,
    shape: &'static str,
    param: &'static str,
    reason: &'static str,
) -> Result<(), ShapeError> {
    if ok {
        Ok(())
    } else {
        Err(ShapeError::InvalidParameter {
            shape,
            param,
            reason,
        })
    }
}

fn positive(x: f64, shape: &'static str, param: &'static str) -> Result<(), ShapeError> {
    check(
        x.is_finite() && x > 0.0,
        shape,
        param,
        "must be finite and > 0",
    )
}

/// Validates and orients a generated mesh: if the signed volume is negative every triangle is
/// flipped (the builders produce a consistent orientation; this fixes its global sign).
fn finish(
    shape: &'static str,
    vertices: Vec<DVec3>,
    mut indices: Vec<[u32; 3]>,
) -> Result<TriMesh, ShapeError> {
    let mesh = TriMesh::new(vertices, indices.clone())
        .map_err(|source| ShapeError::Mesh { shape, source })?;
    if mesh.signed_volume() >= 0.0 {
        return Ok(mesh);
    }
    for t in &mut indices {
        t.swap(1, 2);
    }
    TriMesh::new(mesh.vertices().to_vec(), indices)
        .map_err(|source| ShapeError::Mesh { shape, source })
}

fn build(vertices: Vec<DVec3>, indices: Vec<[u32; 3]>) -> TriMesh {
    TriMesh::new(vertices, indices).expect("procedural shapes are valid by construction")
}

/// An axis-aligned box centred on the origin with the given half extents (12 triangles).
///
/// ```
/// let b = frcd_geom::shapes::cuboid(frcd_geom::DVec3::new(1.0, 2.0, 3.0));
/// assert_eq!(b.triangle_count(), 12);
/// assert!((b.signed_volume() - 48.0).abs() < 1e-12);
/// ```
pub fn cuboid(half: DVec3) -> TriMesh {
    let v: Vec<DVec3> = (0..8)
        .map(|i| {
            DVec3::new(
                if i & 1 == 0 { -half.x } else { half.x },
                if i & 2 == 0 { -half.y } else { half.y },
                if i & 4 == 0 { -half.z } else { half.z },
            )
        })
        .collect();
    let idx = vec![
        [0, 2, 1],
        [1, 2, 3], // -z
        [4, 5, 6],
        [5, 7, 6], // +z
        [0, 1, 4],
        [1, 5, 4], // -y
        [2, 6, 3],
        [3, 6, 7], // +y
        [0, 4, 2],
        [2, 4, 6], // -x
        [1, 3, 5],
        [3, 7, 5], // +x
    ];
    build(v, idx)
}

/// A geodesic sphere: an icosahedron subdivided `level` times (each level splits every triangle
/// into four), vertices projected on the sphere. `20 · 4^level` triangles.
///
/// ```
/// let s = frcd_geom::shapes::icosphere(2.0, 3);
/// assert_eq!(s.triangle_count(), 20 * 64);
/// ```
pub fn icosphere(radius: f64, level: u32) -> TriMesh {
    let phi = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<DVec3> = [
        (-1.0, phi, 0.0),
        (1.0, phi, 0.0),
        (-1.0, -phi, 0.0),
        (1.0, -phi, 0.0),
        (0.0, -1.0, phi),
        (0.0, 1.0, phi),
        (0.0, -1.0, -phi),
        (0.0, 1.0, -phi),
        (phi, 0.0, -1.0),
        (phi, 0.0, 1.0),
        (-phi, 0.0, -1.0),
        (-phi, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| DVec3::new(x, y, z).normalize())
    .collect();
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..level {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
        let mut next = Vec::with_capacity(f.len() * 4);
        let mut midpoint = |a: u32, b: u32, v: &mut Vec<DVec3>| -> u32 {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                v.push((v[a as usize] + v[b as usize]).normalize());
                (v.len() - 1) as u32
            })
        };
        for [a, b, c] in f {
            let ab = midpoint(a, b, &mut v);
            let bc = midpoint(b, c, &mut v);
            let ca = midpoint(c, a, &mut v);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        f = next;
    }
    for p in &mut v {
        *p *= radius;
    }
    build(v, f)
}

// ---------------------------------------------------------------------------------------------
// Generic builders
// ---------------------------------------------------------------------------------------------

fn finite_profile(profile: &[DVec2], shape: &'static str) -> Result<(), ShapeError> {
    check(
        profile.iter().all(|p| p.is_finite()),
        shape,
        "profile",
        "coordinates must be finite",
    )
}

/// A solid of revolution: `profile` points `(r, z)` turned about the z axis in `segments` steps
/// (a point `(r, z)` at angle θ becomes `(r cos θ, r sin θ, z)`).
///
/// Two kinds of profile:
/// - *pole to pole*: the first and last points lie on the axis (`r == 0`) and every other point
///   has `r > 0`: a sphere-like solid, closed by triangle fans at the poles;
/// - *closed loop*: every point has `r > 0`; the last point connects back to the first: a
///   torus-like solid (a ring with a hole).
///
/// The profile must be a simple polyline (it is not checked for self-intersection);
/// consecutive points must differ. The result is oriented outward whichever way the profile
/// runs. `2 · segments · (edges of the profile)` triangles.
///
/// ```
/// use frcd_geom::{shapes::revolve, DVec2};
/// // A cone.
/// let m = revolve(&[DVec2::new(0.0, 0.0), DVec2::new(1.0, 0.0), DVec2::new(0.0, 2.0)], 16).unwrap();
/// assert!(m.topology().is_closed_oriented_manifold());
/// assert_eq!(m.triangle_count(), 32);
/// ```
pub fn revolve(profile: &[DVec2], segments: u32) -> Result<TriMesh, ShapeError> {
    const S: &str = "revolve";
    check(segments >= 3, S, "segments", "must be >= 3")?;
    check(profile.len() >= 3, S, "profile", "needs at least 3 points")?;
    finite_profile(profile, S)?;
    let poles = profile[0].x == 0.0;
    check(
        poles == (profile[profile.len() - 1].x == 0.0),
        S,
        "profile",
        "must start and end on the axis, or not touch it at all",
    )?;
    let inner = if poles {
        &profile[1..profile.len() - 1]
    } else {
        profile
    };
    check(
        inner.iter().all(|p| p.x > 0.0),
        S,
        "profile",
        "points other than the poles need r > 0",
    )?;
    let closing = if poles { 0 } else { 1 };
    check(
        (0..profile.len() - 1 + closing).all(|i| profile[i] != profile[(i + 1) % profile.len()]),
        S,
        "profile",
        "consecutive points must differ",
    )?;
    let n = segments as usize;
    let sin_cos: Vec<(f64, f64)> = (0..n)
        .map(|j| (TAU * j as f64 / n as f64).sin_cos())
        .collect();
    let mut v = Vec::with_capacity(inner.len() * n + 2);
    if poles {
        v.push(DVec3::new(0.0, 0.0, profile[0].y));
    }
    let base = v.len();
    for p in inner {
        for &(s, c) in &sin_cos {
            v.push(DVec3::new(p.x * c, p.x * s, p.y));
        }
    }
    let ring = |i: usize, j: usize| (base + (i % inner.len()) * n + j % n) as u32;
    let mut f = Vec::with_capacity(2 * n * profile.len());
    let rings = inner.len();
    for i in 0..rings - 1 + closing {
        for j in 0..n {
            let (a, b, c, d) = (
                ring(i, j),
                ring(i, j + 1),
                ring(i + 1, j + 1),
                ring(i + 1, j),
            );
            f.push([a, b, c]);
            f.push([a, c, d]);
        }
    }
    if poles {
        let top = v.len() as u32;
        v.push(DVec3::new(0.0, 0.0, profile[profile.len() - 1].y));
        for j in 0..n {
            f.push([0, ring(0, j + 1), ring(0, j)]);
            f.push([ring(rings - 1, j), ring(rings - 1, j + 1), top]);
        }
    }
    finish(S, v, f)
}

/// A cross-section frame for [`sweep`]: the profile point `(x, y)` maps to
/// `origin + x·u + y·v`.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct SweepFrame {
    /// Where the profile's origin goes.
    pub origin: DVec3,
    /// Image of the profile's x axis.
    pub u: DVec3,
    /// Image of the profile's y axis.
    pub v: DVec3,
}

/// Twice the signed area of a polygon (positive: counter-clockwise).
fn signed_area2(poly: &[DVec2]) -> f64 {
    (0..poly.len())
        .map(|i| poly[i].perp_dot(poly[(i + 1) % poly.len()]))
        .sum()
}

/// Ear-clipping triangulation of a simple counter-clockwise polygon (indices into `poly`).
/// `None` when no ear is found (the polygon is not simple, or has collinear runs that leave no
/// strictly convex ear).
fn triangulate_polygon(poly: &[DVec2]) -> Option<Vec<[u32; 3]>> {
    let cross = |a: DVec2, b: DVec2, c: DVec2| (b - a).perp_dot(c - a);
    let mut idx: Vec<usize> = (0..poly.len()).collect();
    let mut out = Vec::with_capacity(poly.len().saturating_sub(2));
    while idx.len() > 3 {
        let m = idx.len();
        let ear = (0..m).find(|&i| {
            let (a, b, c) = (idx[(i + m - 1) % m], idx[i], idx[(i + 1) % m]);
            let (pa, pb, pc) = (poly[a], poly[b], poly[c]);
            cross(pa, pb, pc) > 0.0
                && idx.iter().all(|&k| {
                    k == a
                        || k == b
                        || k == c
                        || !(cross(pa, pb, poly[k]) >= 0.0
                            && cross(pb, pc, poly[k]) >= 0.0
                            && cross(pc, pa, poly[k]) >= 0.0)
                })
        })?;
        let (a, b, c) = (idx[(ear + m - 1) % m], idx[ear], idx[(ear + 1) % m]);
        out.push([a as u32, b as u32, c as u32]);
        idx.remove(ear);
    }
    (cross(poly[idx[0]], poly[idx[1]], poly[idx[2]]) > 0.0)
        .then(|| out.push([idx[0] as u32, idx[1] as u32, idx[2] as u32]))?;
    Some(out)
}

/// A swept solid: the closed polygon `profile` (a simple polygon in the frame's `(x, y)`
/// plane, either orientation) placed at each frame and connected ring to ring.
///
/// - `closed == false`: the ends are capped with an ear-clipping triangulation of the
///   profile (a tube with flat ends, a rail);
/// - `closed == true`: the last ring connects back to the first (the frames must be periodic,
///   e.g. a torus knot); no caps.
///
/// The frames should be right-handed along the path (`u × v` pointing forward) for the
/// orientation to come out outward directly; otherwise the whole mesh is flipped, which is also
/// correct. The swept tube must not self-intersect (not checked).
/// `2 · |profile| · (rings − 1 or rings)` side triangles, plus `2 (|profile| − 2)` in caps.
pub fn sweep(
    profile: &[DVec2],
    frames: &[SweepFrame],
    closed: bool,
) -> Result<TriMesh, ShapeError> {
    const S: &str = "sweep";
    check(profile.len() >= 3, S, "profile", "needs at least 3 points")?;
    finite_profile(profile, S)?;
    check(
        frames.len() >= if closed { 3 } else { 2 },
        S,
        "frames",
        "needs at least 2 frames (3 for a closed path)",
    )?;
    check(
        frames
            .iter()
            .all(|f| f.origin.is_finite() && f.u.is_finite() && f.v.is_finite()),
        S,
        "frames",
        "must be finite",
    )?;
    let area = signed_area2(profile);
    check(area != 0.0, S, "profile", "has zero area")?;
    let mut prof = profile.to_vec();
    if area < 0.0 {
        prof.reverse();
    }
    let caps = if closed {
        Vec::new()
    } else {
        triangulate_polygon(&prof).ok_or(ShapeError::InvalidParameter {
            shape: S,
            param: "profile",
            reason: "is not a simple polygon",
        })?
    };
    let m = prof.len();
    let mut v = Vec::with_capacity(m * frames.len());
    for fr in frames {
        for p in &prof {
            v.push(fr.origin + fr.u * p.x + fr.v * p.y);
        }
    }
    let k_rings = frames.len();
    let at = |k: usize, i: usize| ((k % k_rings) * m + i % m) as u32;
    let mut f = Vec::with_capacity(2 * m * k_rings + 2 * caps.len());
    let spans = if closed { k_rings } else { k_rings - 1 };
    for k in 0..spans {
        for i in 0..m {
            let (a, b, c, d) = (at(k, i), at(k, i + 1), at(k + 1, i + 1), at(k + 1, i));
            f.push([a, b, c]);
            f.push([a, c, d]);
        }
    }
    let last = (k_rings - 1) * m;
    for t in &caps {
        f.push([t[0], t[2], t[1]]);
        f.push([last as u32 + t[0], last as u32 + t[1], last as u32 + t[2]]);
    }
    finish(S, v, f)
}

/// Splits every triangle into four at its edge midpoints (flat: the new vertices are not
/// projected). Shared edges get one midpoint, so a closed manifold stays one; the triangle count
/// is multiplied by 4. For stress sizes.
///
/// ```
/// use frcd_geom::{shapes, DVec3};
/// let m = shapes::subdivide(&shapes::cuboid(DVec3::ONE));
/// assert_eq!(m.triangle_count(), 48);
/// assert!(m.topology().is_closed_oriented_manifold());
/// ```
pub fn subdivide(mesh: &TriMesh) -> TriMesh {
    let mut v = mesh.vertices().to_vec();
    let mut mid: HashMap<(u32, u32), u32> = HashMap::with_capacity(mesh.triangle_count() * 3 / 2);
    let mut f = Vec::with_capacity(mesh.triangle_count() * 4);
    let mut midpoint = |a: u32, b: u32, v: &mut Vec<DVec3>| -> u32 {
        *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
            // 0.5a + 0.5b cannot overflow, unlike (a + b) / 2.
            v.push(0.5 * v[a as usize] + 0.5 * v[b as usize]);
            (v.len() - 1) as u32
        })
    };
    for &[a, b, c] in mesh.indices() {
        let ab = midpoint(a, b, &mut v);
        let bc = midpoint(b, c, &mut v);
        let ca = midpoint(c, a, &mut v);
        f.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
    }
    TriMesh::new(v, f).expect("midpoints of finite vertices are finite and indices are in range")
}

/// Concatenates meshes into one (one component or more each); vertices are not welded.
/// Fails with [`MeshError::Empty`] for no meshes and [`MeshError::TooLarge`] past `u32` indices.
pub fn merge(meshes: &[TriMesh]) -> Result<TriMesh, MeshError> {
    let mut v = Vec::with_capacity(meshes.iter().map(|m| m.vertex_count()).sum());
    let mut f = Vec::with_capacity(meshes.iter().map(|m| m.triangle_count()).sum());
    for m in meshes {
        let base = v.len();
        if base + m.vertex_count() > u32::MAX as usize {
            return Err(MeshError::TooLarge {
                what: "vertices",
                count: base + m.vertex_count(),
            });
        }
        v.extend_from_slice(m.vertices());
        f.extend(m.indices().iter().map(|t| t.map(|i| i + base as u32)));
    }
    TriMesh::new(v, f)
}

// ---------------------------------------------------------------------------------------------
// Simple solids
// ---------------------------------------------------------------------------------------------

/// A UV sphere of the given radius centred on the origin, poles on the z axis: `slices`
/// meridians (≥ 3) and `stacks` bands (≥ 2). `2 · slices · (stacks − 1)` triangles.
///
/// ```
/// let s = frcd_geom::shapes::uv_sphere(1.0, 16, 8).unwrap();
/// assert_eq!(s.triangle_count(), 2 * 16 * 7);
/// ```
pub fn uv_sphere(radius: f64, slices: u32, stacks: u32) -> Result<TriMesh, ShapeError> {
    const S: &str = "uv_sphere";
    positive(radius, S, "radius")?;
    check(stacks >= 2, S, "stacks", "must be >= 2")?;
    let profile: Vec<DVec2> = (0..=stacks)
        .map(|i| {
            let phi = -PI / 2.0 + PI * i as f64 / stacks as f64;
            if i == 0 || i == stacks {
                DVec2::new(0.0, radius * phi.signum())
            } else {
                DVec2::new(radius * phi.cos(), radius * phi.sin())
            }
        })
        .collect();
    revolve(&profile, slices).map_err(|e| rename(e, S))
}

/// A closed cylinder of radius `radius` from `z = -half_height` to `z = half_height`, `segments`
/// around (≥ 3), the side split into `stacks` bands (≥ 1). `2 · segments · (stacks + 1)`
/// triangles.
pub fn cylinder(
    radius: f64,
    half_height: f64,
    segments: u32,
    stacks: u32,
) -> Result<TriMesh, ShapeError> {
    const S: &str = "cylinder";
    positive(radius, S, "radius")?;
    positive(half_height, S, "half_height")?;
    check(stacks >= 1, S, "stacks", "must be >= 1")?;
    let mut profile = vec![DVec2::new(0.0, -half_height)];
    for i in 0..=stacks {
        profile.push(DVec2::new(
            radius,
            -half_height + 2.0 * half_height * i as f64 / stacks as f64,
        ));
    }
    profile.push(DVec2::new(0.0, half_height));
    revolve(&profile, segments).map_err(|e| rename(e, S))
}

/// A torus about the z axis: tube centre circle of radius `major`, tube radius `minor`
/// (`0 < minor < major`). `2 · major_segments · minor_segments` triangles.
pub fn torus(
    major: f64,
    minor: f64,
    major_segments: u32,
    minor_segments: u32,
) -> Result<TriMesh, ShapeError> {
    const S: &str = "torus";
    positive(major, S, "major")?;
    positive(minor, S, "minor")?;
    check(minor < major, S, "minor", "must be < major")?;
    check(minor_segments >= 3, S, "minor_segments", "must be >= 3")?;
    let profile: Vec<DVec2> = (0..minor_segments)
        .map(|i| {
            let (s, c) = (TAU * i as f64 / minor_segments as f64).sin_cos();
            DVec2::new(major + minor * c, minor * s)
        })
        .collect();
    revolve(&profile, major_segments).map_err(|e| rename(e, S))
}

/// Re-labels a builder's error with the calling shape's name.
fn rename(e: ShapeError, shape: &'static str) -> ShapeError {
    match e {
        ShapeError::InvalidParameter { param, reason, .. } => ShapeError::InvalidParameter {
            shape,
            param,
            reason,
        },
        ShapeError::Mesh { source, .. } => ShapeError::Mesh { shape, source },
    }
}

fn circle(radius: f64, n: u32) -> Vec<DVec2> {
    (0..n)
        .map(|i| {
            let (s, c) = (TAU * i as f64 / n as f64).sin_cos();
            DVec2::new(radius * c, radius * s)
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Torus knot
// ---------------------------------------------------------------------------------------------

/// Parameters of [`torus_knot`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct TorusKnotParams {
    /// Windings about the z axis (≥ 1).
    pub p: u32,
    /// Windings through the hole (≥ 1; `gcd(p, q) == 1` for a knot rather than a link).
    pub q: u32,
    /// Radius of the torus the knot lies on (centre circle).
    pub radius: f64,
    /// Radius of the tube of that torus (the knot's distance from the centre circle).
    pub offset: f64,
    /// Radius of the swept tube.
    pub tube_radius: f64,
    /// Rings along the knot (≥ 3).
    pub tubular_segments: u32,
    /// Vertices around the tube (≥ 3).
    pub radial_segments: u32,
}

impl Default for TorusKnotParams {
    /// The (2, 3) trefoil: radius 1, offset 0.4, tube 0.1, 128 × 12.
    fn default() -> Self {
        Self {
            p: 2,
            q: 3,
            radius: 1.0,
            offset: 0.4,
            tube_radius: 0.1,
            tubular_segments: 128,
            radial_segments: 12,
        }
    }
}

impl TorusKnotParams {
    /// The knot's centreline at parameter `t ∈ [0, 2π)`, with its unit tangent and the unit
    /// normal of the underlying torus there (perpendicular to the tangent).
    pub fn centreline(&self, t: f64) -> (DVec3, DVec3, DVec3) {
        let (p, q) = (self.p as f64, self.q as f64);
        let (sp, cp) = (p * t).sin_cos();
        let (sq, cq) = (q * t).sin_cos();
        let rr = self.radius + self.offset * cq;
        let pos = DVec3::new(rr * cp, rr * sp, self.offset * sq);
        let d = DVec3::new(
            -self.offset * q * sq * cp - rr * p * sp,
            -self.offset * q * sq * sp + rr * p * cp,
            self.offset * q * cq,
        );
        let normal = DVec3::new(cq * cp, cq * sp, sq);
        (pos, d.normalize(), normal)
    }
}

fn gcd(a: u32, b: u32) -> u32 {
    if b == 0 { a } else { gcd(b, a % b) }
}

/// A `(p, q)` torus knot swept with a circular tube. The frame is the underlying torus's
/// surface normal (exactly perpendicular to the knot) and its cross product with the tangent:
/// periodic, so the tube closes without a twist seam. `2 · tubular · radial` triangles.
/// Non-self-intersecting when the tube is thin against the strand spacing (the defaults are;
/// tests check the centreline clearance).
pub fn torus_knot(params: &TorusKnotParams) -> Result<TriMesh, ShapeError> {
    const S: &str = "torus_knot";
    let k = params;
    check(k.p >= 1 && k.q >= 1, S, "p, q", "must be >= 1")?;
    check(
        gcd(k.p, k.q) == 1,
        S,
        "p, q",
        "must be coprime (otherwise the curve is a link)",
    )?;
    positive(k.radius, S, "radius")?;
    positive(k.offset, S, "offset")?;
    positive(k.tube_radius, S, "tube_radius")?;
    check(k.offset < k.radius, S, "offset", "must be < radius")?;
    check(k.radial_segments >= 3, S, "radial_segments", "must be >= 3")?;
    check(
        k.tubular_segments >= 3,
        S,
        "tubular_segments",
        "must be >= 3",
    )?;
    let frames: Vec<SweepFrame> = (0..k.tubular_segments)
        .map(|i| {
            let t = TAU * i as f64 / k.tubular_segments as f64;
            let (origin, tangent, normal) = k.centreline(t);
            SweepFrame {
                origin,
                u: normal,
                v: tangent.cross(normal),
            }
        })
        .collect();
    sweep(&circle(k.tube_radius, k.radial_segments), &frames, true).map_err(|e| rename(e, S))
}

// ---------------------------------------------------------------------------------------------
// Coil spring
// ---------------------------------------------------------------------------------------------

/// Parameters of [`coil_spring`] (defaults: a bogie primary suspension coil).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct CoilSpringParams {
    /// Mean coil radius (axis to wire centre), m.
    pub coil_radius: f64,
    /// Wire radius, m.
    pub wire_radius: f64,
    /// Rise per turn, m (must leave a gap between neighbouring turns).
    pub pitch: f64,
    /// Number of turns (may be fractional).
    pub turns: f64,
    /// Rings per turn (≥ 3).
    pub segments_per_turn: u32,
    /// Vertices around the wire (≥ 3).
    pub radial_segments: u32,
}

impl Default for CoilSpringParams {
    /// Mean radius 0.1 m, wire radius 0.016 m, pitch 0.055 m, 5.5 turns, 32 × 10.
    fn default() -> Self {
        Self {
            coil_radius: 0.1,
            wire_radius: 0.016,
            pitch: 0.055,
            turns: 5.5,
            segments_per_turn: 32,
            radial_segments: 10,
        }
    }
}

/// A helical coil spring about the z axis (bottom wire centre at `z = 0`), a tube of the wire
/// radius swept along the helix, with flat end caps. The frame is the helix's radial direction
/// (exactly perpendicular to its tangent) and its cross product with the tangent.
pub fn coil_spring(params: &CoilSpringParams) -> Result<TriMesh, ShapeError> {
    const S: &str = "coil_spring";
    let c = params;
    positive(c.coil_radius, S, "coil_radius")?;
    positive(c.wire_radius, S, "wire_radius")?;
    positive(c.pitch, S, "pitch")?;
    positive(c.turns, S, "turns")?;
    check(
        c.wire_radius < c.coil_radius,
        S,
        "wire_radius",
        "must be < coil_radius",
    )?;
    check(
        c.segments_per_turn >= 3,
        S,
        "segments_per_turn",
        "must be >= 3",
    )?;
    check(c.radial_segments >= 3, S, "radial_segments", "must be >= 3")?;
    // Neighbouring turns are `pitch` apart along z; the wire's cross-section, tilted by the
    // helix angle α, spans 2 w / cos α along z.
    let rise = c.pitch / TAU;
    let cos_alpha = c.coil_radius / c.coil_radius.hypot(rise);
    check(
        c.pitch * cos_alpha > 2.0 * c.wire_radius,
        S,
        "pitch",
        "neighbouring turns would touch (need pitch·cos(helix angle) > 2·wire_radius)",
    )?;
    let steps = (c.turns * c.segments_per_turn as f64).ceil().max(1.0) as usize;
    check(steps < 1 << 24, S, "turns", "too many rings")?;
    let t_end = TAU * c.turns;
    let frames: Vec<SweepFrame> = (0..=steps)
        .map(|i| {
            let t = t_end * i as f64 / steps as f64;
            let (s, co) = t.sin_cos();
            let radial = DVec3::new(co, s, 0.0);
            let tangent = DVec3::new(-c.coil_radius * s, c.coil_radius * co, rise).normalize();
            SweepFrame {
                origin: DVec3::new(c.coil_radius * co, c.coil_radius * s, rise * t),
                u: radial,
                v: tangent.cross(radial),
            }
        })
        .collect();
    sweep(&circle(c.wire_radius, c.radial_segments), &frames, false).map_err(|e| rename(e, S))
}

// ---------------------------------------------------------------------------------------------
// Spur gear
// ---------------------------------------------------------------------------------------------

/// Parameters of [`spur_gear`] (defaults: a traction gear pinion, module 10 mm).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct SpurGearParams {
    /// Module (pitch diameter / teeth), m.
    pub module: f64,
    /// Number of teeth (≥ 6).
    pub teeth: u32,
    /// Pressure angle, radians.
    pub pressure_angle: f64,
    /// Face width (thickness along z), m.
    pub face_width: f64,
    /// Bore radius, m (`None`: solid).
    pub bore_radius: Option<f64>,
    /// Points on each involute flank (≥ 2).
    pub flank_samples: u32,
    /// Extra points on each tip and root arc (≥ 0).
    pub arc_samples: u32,
}

impl Default for SpurGearParams {
    /// Module 0.01 m, 20 teeth, 20°, face width 0.08 m, bore radius 0.04 m, 5 flank points,
    /// 2 arc points.
    fn default() -> Self {
        Self {
            module: 0.01,
            teeth: 20,
            pressure_angle: 20f64.to_radians(),
            face_width: 0.08,
            bore_radius: Some(0.04),
            flank_samples: 5,
            arc_samples: 2,
        }
    }
}

fn involute(phi: f64) -> f64 {
    phi.tan() - phi
}

/// The gear's outline as points of strictly increasing polar angle (so the outline is
/// star-shaped about the axis: caps can be fans or strips to a bore).
fn gear_outline(g: &SpurGearParams) -> Result<Vec<DVec2>, ShapeError> {
    const S: &str = "spur_gear";
    positive(g.module, S, "module")?;
    positive(g.face_width, S, "face_width")?;
    check(
        g.teeth >= 6 && g.teeth <= 10_000,
        S,
        "teeth",
        "must be in 6..=10000",
    )?;
    check(
        g.pressure_angle.is_finite() && g.pressure_angle > 0.0 && g.pressure_angle < 0.6,
        S,
        "pressure_angle",
        "must be in (0, 0.6) rad",
    )?;
    check(g.flank_samples >= 2, S, "flank_samples", "must be >= 2")?;
    let z = g.teeth as f64;
    let pitch_r = g.module * z / 2.0;
    let tip_r = pitch_r + g.module;
    let root_r = pitch_r - 1.25 * g.module;
    let base_r = pitch_r * g.pressure_angle.cos();
    let inv_a = involute(g.pressure_angle);
    // Half the tooth's angular thickness at radius ρ ≥ base radius.
    let psi = |rho: f64| PI / (2.0 * z) + inv_a - involute((base_r / rho).min(1.0).acos());
    check(
        psi(tip_r) > 0.0,
        S,
        "teeth",
        "teeth would be pointed (too few teeth)",
    )?;
    let half_pitch = PI / z;
    let start_r = root_r.max(base_r);
    // Below the base circle the flank continues as a slightly tapering line (a radial line would
    // repeat a polar angle).
    let delta = 0.25 * (half_pitch - psi(start_r));
    check(delta > 0.0, S, "teeth", "teeth too thick at the root")?;
    let mut flank: Vec<(f64, f64)> = Vec::new(); // (radius, half angle), root to tip
    if root_r < base_r {
        flank.push((root_r, psi(base_r) + delta));
    }
    let ns = g.flank_samples as usize;
    for i in 0..ns {
        let rho = start_r + (tip_r - start_r) * i as f64 / (ns - 1) as f64;
        flank.push((rho, psi(rho)));
    }
    let mut out = Vec::new();
    let polar = |r: f64, a: f64| DVec2::new(r * a.cos(), r * a.sin());
    let arc = g.arc_samples as usize;
    for j in 0..g.teeth {
        let c = TAU * j as f64 / z;
        for &(r, a) in &flank {
            out.push(polar(r, c - a));
        }
        let tip_half = psi(tip_r);
        for i in 1..=arc {
            out.push(polar(
                tip_r,
                c - tip_half + 2.0 * tip_half * i as f64 / (arc + 1) as f64,
            ));
        }
        for &(r, a) in flank.iter().rev() {
            out.push(polar(r, c + a));
        }
        let (r0, a0) = flank[0];
        let (from, to) = (c + a0, c + 2.0 * half_pitch - a0);
        for i in 1..=arc {
            out.push(polar(r0, from + (to - from) * i as f64 / (arc + 1) as f64));
        }
    }
    Ok(out)
}

/// A spur gear about the z axis, extruded from `z = -face_width/2` to `+face_width/2`: standard
/// proportions (addendum 1 module, dedendum 1.25 modules), involute flanks above the base
/// circle, an optional bore. One component; genus 1 with a bore.
pub fn spur_gear(params: &SpurGearParams) -> Result<TriMesh, ShapeError> {
    const S: &str = "spur_gear";
    let outline = gear_outline(params)?;
    let root_r = params.module * params.teeth as f64 / 2.0 - 1.25 * params.module;
    if let Some(b) = params.bore_radius {
        positive(b, S, "bore_radius")?;
        check(
            b < 0.95 * root_r,
            S,
            "bore_radius",
            "must be < 0.95 · root radius",
        )?;
    }
    let n = outline.len();
    let h = params.face_width / 2.0;
    let mut v: Vec<DVec3> = Vec::with_capacity(4 * n);
    v.extend(outline.iter().map(|p| p.extend(-h)));
    v.extend(outline.iter().map(|p| p.extend(h)));
    let (ob, ot) = (0u32, n as u32);
    let i = |k: usize| (k % n) as u32;
    let mut f = Vec::new();
    for k in 0..n {
        f.push([ob + i(k), ob + i(k + 1), ot + i(k + 1)]);
        f.push([ob + i(k), ot + i(k + 1), ot + i(k)]);
    }
    match params.bore_radius {
        Some(b) => {
            let (bb, bt) = (2 * n as u32, 3 * n as u32);
            v.extend(outline.iter().map(|p| (p.normalize() * b).extend(-h)));
            v.extend(outline.iter().map(|p| (p.normalize() * b).extend(h)));
            for k in 0..n {
                // Top ring (ccw from above), bottom ring reversed, bore wall facing the axis.
                f.push([bt + i(k), ot + i(k), ot + i(k + 1)]);
                f.push([bt + i(k), ot + i(k + 1), bt + i(k + 1)]);
                f.push([bb + i(k), ob + i(k + 1), ob + i(k)]);
                f.push([bb + i(k), bb + i(k + 1), ob + i(k + 1)]);
                f.push([bb + i(k + 1), bb + i(k), bt + i(k)]);
                f.push([bb + i(k + 1), bt + i(k), bt + i(k + 1)]);
            }
        }
        None => {
            let (cb, ct) = (2 * n as u32, 2 * n as u32 + 1);
            v.push(DVec3::new(0.0, 0.0, -h));
            v.push(DVec3::new(0.0, 0.0, h));
            for k in 0..n {
                f.push([ct, ot + i(k), ot + i(k + 1)]);
                f.push([cb, ob + i(k + 1), ob + i(k)]);
            }
        }
    }
    finish(S, v, f)
}

// ---------------------------------------------------------------------------------------------
// Railway: wheel, wheelset, rail
// ---------------------------------------------------------------------------------------------

/// Parameters of [`wheel`]: a railway wheel's cross-section (metres). Lateral positions `s` are
/// measured from the flange back face (inboard, `s = 0`) outward; radii from the axle axis.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct WheelParams {
    /// Rolling radius at the tape circle.
    pub tread_radius: f64,
    /// Rim width (flange back to outer face).
    pub rim_width: f64,
    /// Tape circle position from the flange back.
    pub tape_offset: f64,
    /// Tread conicity (radius change per lateral metre; 1:40 = 0.025), larger toward the flange.
    pub conicity: f64,
    /// Flange height above the tape circle radius.
    pub flange_height: f64,
    /// Flange thickness at its base.
    pub flange_thickness: f64,
    /// Radial depth of the rim below the tape circle radius.
    pub rim_depth: f64,
    /// Web (plate) thickness.
    pub web_thickness: f64,
    /// Web centre from the flange back.
    pub web_offset: f64,
    /// Hub outer radius.
    pub hub_radius: f64,
    /// Hub width.
    pub hub_width: f64,
    /// Hub centre from the flange back.
    pub hub_offset: f64,
    /// Bore radius (the axle's wheel seat).
    pub bore_radius: f64,
    /// Points on the flange arc (≥ 3).
    pub flange_samples: u32,
    /// Segments around the axle (≥ 3).
    pub segments: u32,
}

impl Default for WheelParams {
    /// A 920 mm wheel on standard gauge: 135 mm rim, tape circle 70 mm from the flange back,
    /// 1:40 tread, 28 mm flange, 190 mm bore; 64 segments.
    fn default() -> Self {
        Self {
            tread_radius: 0.46,
            rim_width: 0.135,
            tape_offset: 0.070,
            conicity: 0.025,
            flange_height: 0.028,
            flange_thickness: 0.0325,
            rim_depth: 0.06,
            web_thickness: 0.03,
            web_offset: 0.075,
            hub_radius: 0.125,
            hub_width: 0.175,
            hub_offset: 0.075,
            bore_radius: 0.095,
            flange_samples: 9,
            segments: 64,
        }
    }
}

/// The wheel's outline in `(s, r)`, from the outboard hub face at the bore, over the rim, to the
/// inboard hub face at the bore (the bore segment closes it).
fn wheel_outline(w: &WheelParams) -> Result<Vec<DVec2>, ShapeError> {
    const S: &str = "wheel";
    for (x, name) in [
        (w.tread_radius, "tread_radius"),
        (w.rim_width, "rim_width"),
        (w.flange_height, "flange_height"),
        (w.flange_thickness, "flange_thickness"),
        (w.rim_depth, "rim_depth"),
        (w.web_thickness, "web_thickness"),
        (w.hub_radius, "hub_radius"),
        (w.hub_width, "hub_width"),
        (w.bore_radius, "bore_radius"),
    ] {
        positive(x, S, name)?;
    }
    check(
        w.conicity.is_finite() && (0.0..0.5).contains(&w.conicity),
        S,
        "conicity",
        "must be in [0, 0.5)",
    )?;
    check(w.flange_samples >= 3, S, "flange_samples", "must be >= 3")?;
    let (rr, wd) = (w.tread_radius, w.rim_width);
    let chamfer = 0.04 * wd;
    let fillet = 0.3 * w.flange_thickness;
    let r_t = |s: f64| rr + (w.tape_offset - s) * w.conicity;
    let r_rim = rr - w.rim_depth;
    let (web0, web1) = (
        w.web_offset - w.web_thickness / 2.0,
        w.web_offset + w.web_thickness / 2.0,
    );
    let (hub0, hub1) = (
        w.hub_offset - w.hub_width / 2.0,
        w.hub_offset + w.hub_width / 2.0,
    );
    check(
        w.tape_offset.is_finite()
            && w.flange_thickness + fillet < w.tape_offset
            && w.tape_offset < wd - chamfer,
        S,
        "tape_offset",
        "must lie on the tread, between the flange root and the outer chamfer",
    )?;
    check(
        0.0 < web0 && web1 < wd,
        S,
        "web_offset",
        "the web must lie within the rim width",
    )?;
    check(
        hub0 < web0 && web1 < hub1,
        S,
        "hub_width",
        "the hub must be wider than the web",
    )?;
    check(
        w.bore_radius < w.hub_radius && w.hub_radius < r_rim && r_rim < r_t(wd) - chamfer,
        S,
        "radii",
        "need bore < hub < rim underside < tread",
    )?;
    // Flange: an elliptic arc from its front (toward the tread) over the tip to its back face.
    let fh = w.flange_height;
    let (cs, cr) = (w.flange_thickness / 2.0, rr + 0.4 * fh);
    let (ax, ay) = (w.flange_thickness / 2.0, 0.6 * fh);
    let mut out = vec![
        DVec2::new(hub1, w.bore_radius),
        DVec2::new(hub1, w.hub_radius),
        DVec2::new(web1, w.hub_radius),
        DVec2::new(web1, r_rim),
        DVec2::new(wd, r_rim),
        DVec2::new(wd, r_t(wd) - chamfer),
        DVec2::new(wd - chamfer, r_t(wd - chamfer)),
        DVec2::new(w.tape_offset, r_t(w.tape_offset)),
        DVec2::new(
            w.flange_thickness + fillet,
            r_t(w.flange_thickness + fillet),
        ),
    ];
    let k = w.flange_samples;
    for i in 0..k {
        let th = PI * i as f64 / (k - 1) as f64;
        out.push(DVec2::new(cs + ax * th.cos(), cr + ay * th.sin()));
    }
    out.extend([
        DVec2::new(0.0, r_rim),
        DVec2::new(web0, r_rim),
        DVec2::new(web0, w.hub_radius),
        DVec2::new(hub0, w.hub_radius),
        DVec2::new(hub0, w.bore_radius),
    ]);
    Ok(out)
}

/// Rotation taking the revolve axis (z) to the axle axis (y): x stays, z → y, y → −z.
fn z_to_y() -> Pose {
    Pose::new(DVec3::ZERO, DQuat::from_rotation_x(-PI / 2.0))
}

/// A railway wheel as a solid of revolution about the **y** axis (railway axes: x along the
/// track, y lateral, z up): tread with conicity, flange, rim, web, hub and bore. The flange back
/// face lies in the plane `y = 0` and the wheel extends toward +y (the flange is at the
/// inboard, −y side). One component, genus 1.
///
/// ```
/// use frcd_geom::shapes::{wheel, WheelParams};
/// let w = wheel(&WheelParams::default()).unwrap();
/// assert!(w.topology().is_closed_oriented_manifold());
/// ```
pub fn wheel(params: &WheelParams) -> Result<TriMesh, ShapeError> {
    // (s, r) → revolve profile (r, z = s).
    let profile: Vec<DVec2> = wheel_outline(params)?
        .iter()
        .map(|p| DVec2::new(p.y, p.x))
        .collect();
    Ok(revolve(&profile, params.segments)
        .map_err(|e| rename(e, "wheel"))?
        .transformed(&z_to_y()))
}

/// Parameters of [`wheelset`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct WheelsetParams {
    /// Both wheels (the bore is filled by the axle's wheel seat).
    pub wheel: WheelParams,
    /// Distance between the two flange back faces (1.360 m on standard gauge).
    pub back_to_back: f64,
    /// Axle length, end to end.
    pub axle_length: f64,
    /// Axle body radius between the wheels.
    pub body_radius: f64,
    /// Radius of the collar between a wheel hub and its journal.
    pub collar_radius: f64,
    /// Journal (bearing seat) radius at the axle ends.
    pub journal_radius: f64,
    /// Distance from the axle centre where each journal begins.
    pub journal_start: f64,
}

impl Default for WheelsetParams {
    /// Standard gauge: back-to-back 1.360 m, axle 2.2 m, body radius 0.085 m, collar 0.08 m,
    /// journals of radius 0.065 m from 0.9 m out.
    fn default() -> Self {
        Self {
            wheel: WheelParams::default(),
            back_to_back: 1.360,
            axle_length: 2.2,
            body_radius: 0.085,
            collar_radius: 0.08,
            journal_radius: 0.065,
            journal_start: 0.9,
        }
    }
}

/// A wheelset: two [`wheel`]s pressed on an axle, as ONE solid of revolution about the y axis
/// (the axle fills the bores, so wheels and axle form a single closed 2-manifold with no
/// internal faces; one component, genus 0). Centred on the origin, flanges inboard at
/// `|y| = back_to_back / 2`, axle ends at `|y| = axle_length / 2`; resting on rails the tape
/// circles would be at `z = −tread_radius`.
pub fn wheelset(params: &WheelsetParams) -> Result<TriMesh, ShapeError> {
    let profile: Vec<DVec2> = wheelset_profile(params)?
        .iter()
        .map(|q| DVec2::new(q.y, q.x))
        .collect();
    Ok(revolve(&profile, params.wheel.segments)
        .map_err(|e| rename(e, "wheelset"))?
        .transformed(&z_to_y()))
}

/// The wheelset's profile in `(y, r)` from the left axle end (on the axis) to the right one.
fn wheelset_profile(params: &WheelsetParams) -> Result<Vec<DVec2>, ShapeError> {
    const S: &str = "wheelset";
    let p = params;
    let outline = wheel_outline(&p.wheel).map_err(|e| rename(e, S))?;
    for (x, name) in [
        (p.back_to_back, "back_to_back"),
        (p.axle_length, "axle_length"),
        (p.body_radius, "body_radius"),
        (p.collar_radius, "collar_radius"),
        (p.journal_radius, "journal_radius"),
        (p.journal_start, "journal_start"),
    ] {
        positive(x, S, name)?;
    }
    let half_b2b = p.back_to_back / 2.0;
    let w = &p.wheel;
    let hub0 = w.hub_offset - w.hub_width / 2.0;
    let hub1 = w.hub_offset + w.hub_width / 2.0;
    check(
        half_b2b + hub0 > 0.0,
        S,
        "back_to_back",
        "the wheel hubs would overlap",
    )?;
    check(
        p.journal_start > half_b2b + hub1 && p.journal_start < p.axle_length / 2.0,
        S,
        "journal_start",
        "must lie between the hub's outer face and the axle end",
    )?;
    check(
        p.body_radius < w.hub_radius && p.collar_radius < w.hub_radius,
        S,
        "body_radius",
        "axle radii must be < the hub radius",
    )?;
    check(
        p.journal_radius < p.collar_radius,
        S,
        "journal_radius",
        "must be < collar_radius",
    )?;
    let half_len = p.axle_length / 2.0;
    let last = outline.len() - 1;
    // Profile (y, r) from the left axle end to the right one.
    let mut prof: Vec<DVec2> = vec![
        DVec2::new(-half_len, 0.0),
        DVec2::new(-half_len, p.journal_radius),
        DVec2::new(-p.journal_start, p.journal_radius),
        DVec2::new(-p.journal_start, p.collar_radius),
    ];
    // Left wheel: y = -(b2b/2 + s), outline order (outboard face first).
    for (i, q) in outline.iter().enumerate() {
        let r = match i {
            0 => p.collar_radius,
            _ if i == last => p.body_radius,
            _ => q.y,
        };
        prof.push(DVec2::new(-(half_b2b + q.x), r));
    }
    // Right wheel: y = b2b/2 + s, outline reversed (inboard face first).
    for (i, q) in outline.iter().enumerate().rev() {
        let r = match i {
            0 => p.collar_radius,
            _ if i == last => p.body_radius,
            _ => q.y,
        };
        prof.push(DVec2::new(half_b2b + q.x, r));
    }
    prof.extend([
        DVec2::new(p.journal_start, p.collar_radius),
        DVec2::new(p.journal_start, p.journal_radius),
        DVec2::new(half_len, p.journal_radius),
        DVec2::new(half_len, 0.0),
    ]);
    Ok(prof)
}

/// The path of a [`rail`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum RailPath {
    /// Along +x from `x = 0` to `x = length`.
    Straight {
        /// Length, m.
        length: f64,
    },
    /// A circular arc starting at the origin heading +x and curving toward +y (centre at
    /// `(0, radius, 0)`).
    Curve {
        /// Radius of the rail's centreline, m (> 0.1).
        radius: f64,
        /// Swept angle, radians, in `(0, 2π)`.
        angle: f64,
    },
}

/// Parameters of [`rail`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct RailParams {
    /// The centreline.
    pub path: RailPath,
    /// Spans along the path (≥ 1).
    pub segments: u32,
}

impl Default for RailParams {
    /// A straight 2 m rail in 4 spans.
    fn default() -> Self {
        Self {
            path: RailPath::Straight { length: 2.0 },
            segments: 4,
        }
    }
}

/// The UIC 60-like flat-bottom rail profile (lateral, vertical), m: 150 mm foot, 16.5 mm web,
/// 72 mm head, 172 mm tall; foot bottom at 0. Counter-clockwise, no collinear neighbours.
pub fn rail_profile() -> Vec<DVec2> {
    let half = [
        (0.075, 0.0),
        (0.075, 0.0115),
        (0.0185, 0.030),
        (0.00825, 0.045),
        (0.00825, 0.122),
        (0.0165, 0.135),
        (0.036, 0.140),
        (0.036, 0.160),
        (0.034, 0.167),
        (0.027, 0.1705),
        (0.015, 0.172),
    ];
    let mut out: Vec<DVec2> = half.iter().map(|&(x, y)| DVec2::new(x, y)).collect();
    out.extend(half.iter().rev().map(|&(x, y)| DVec2::new(-x, y)));
    out
}

/// A rail: [`rail_profile`] extruded along a straight or circular [`RailPath`], capped at both
/// ends. The profile's lateral axis maps to the left of the direction of travel (+y on a
/// straight rail), its vertical axis to +z; the foot bottom lies in `z = 0`.
pub fn rail(params: &RailParams) -> Result<TriMesh, ShapeError> {
    const S: &str = "rail";
    check(
        params.segments >= 1 && params.segments < 1 << 24,
        S,
        "segments",
        "must be in 1..2^24",
    )?;
    let n = params.segments as usize;
    let frames: Vec<SweepFrame> = match params.path {
        RailPath::Straight { length } => {
            positive(length, S, "length")?;
            (0..=n)
                .map(|i| SweepFrame {
                    origin: DVec3::new(length * i as f64 / n as f64, 0.0, 0.0),
                    u: DVec3::Y,
                    v: DVec3::Z,
                })
                .collect()
        }
        RailPath::Curve { radius, angle } => {
            positive(radius, S, "radius")?;
            check(
                radius > 0.1,
                S,
                "radius",
                "must exceed 0.1 m (the foot's half width)",
            )?;
            check(
                angle.is_finite() && angle > 0.0 && angle < TAU,
                S,
                "angle",
                "must be in (0, 2π)",
            )?;
            (0..=n)
                .map(|i| {
                    let (s, c) = (angle * i as f64 / n as f64).sin_cos();
                    SweepFrame {
                        origin: DVec3::new(radius * s, radius * (1.0 - c), 0.0),
                        u: DVec3::new(-s, c, 0.0),
                        v: DVec3::Z,
                    }
                })
                .collect()
        }
    };
    sweep(&rail_profile(), &frames, false).map_err(|e| rename(e, S))
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn assert_solid(m: &TriMesh) {
        let t = m.topology();
        assert!(t.is_closed_oriented_manifold(), "{t:?}");
        assert!(
            m.report().degenerate.is_empty(),
            "degenerate: {:?}",
            m.report().degenerate
        );
        assert!(m.report().duplicates.is_empty());
        assert!(m.signed_volume() > 0.0, "normals point inward");
    }

    /// Solid, with the expected component count and total genus (Euler characteristic).
    fn assert_shape(m: &TriMesh, components: usize, genus: i64) {
        assert_solid(m);
        let t = m.topology();
        assert_eq!(t.components, components, "{t:?}");
        let chi = m.vertex_count() as i64 - t.edges as i64 + m.triangle_count() as i64;
        assert_eq!(
            chi,
            2 * components as i64 - 2 * genus,
            "Euler characteristic"
        );
    }

    /// True when the closed polygon's non-adjacent edges do not meet (O(n²), for tests).
    fn is_simple(poly: &[DVec2]) -> bool {
        let n = poly.len();
        let cross = |a: DVec2, b: DVec2, c: DVec2| (b - a).perp_dot(c - a);
        for i in 0..n {
            for j in i + 1..n {
                if j == i + 1 || (i == 0 && j == n - 1) {
                    continue;
                }
                let (a, b, c, d) = (poly[i], poly[(i + 1) % n], poly[j], poly[(j + 1) % n]);
                let (d1, d2) = (cross(a, b, c), cross(a, b, d));
                let (d3, d4) = (cross(c, d, a), cross(c, d, b));
                if d1 == 0.0 && d2 == 0.0 {
                    // Collinear: they meet iff their projections on the line overlap.
                    let dir = b - a;
                    let t = |p: DVec2| (p - a).dot(dir);
                    let (lo, hi) = (t(c).min(t(d)), t(c).max(t(d)));
                    if hi >= 0.0_f64.min(t(b)) && lo <= 0.0_f64.max(t(b)) {
                        return false;
                    }
                } else if d1 * d2 <= 0.0 && d3 * d4 <= 0.0 {
                    return false;
                }
            }
        }
        true
    }

    #[test]
    fn uv_sphere_and_cylinder() {
        for (sl, st) in [(3, 2), (8, 4), (64, 32)] {
            let s = uv_sphere(2.0, sl, st).unwrap();
            assert_shape(&s, 1, 0);
            assert_eq!(s.triangle_count(), (2 * sl * (st - 1)) as usize);
        }
        let v = uv_sphere(1.0, 128, 64).unwrap().signed_volume();
        assert!((v / (4.0 / 3.0 * PI) - 1.0).abs() < 2e-3, "{v}");
        for (seg, st) in [(3, 1), (16, 1), (64, 8)] {
            let c = cylinder(0.5, 2.0, seg, st).unwrap();
            assert_shape(&c, 1, 0);
            assert_eq!(c.triangle_count(), (2 * seg * (st + 1)) as usize);
            // A prism over a regular polygon: volume exactly n/2 r² sin(2π/n) · height.
            let n = seg as f64;
            let exact = n / 2.0 * 0.25 * (TAU / n).sin() * 4.0;
            assert!((c.signed_volume() - exact).abs() < 1e-12 * exact);
        }
        assert!(matches!(
            uv_sphere(-1.0, 8, 4),
            Err(ShapeError::InvalidParameter {
                shape: "uv_sphere",
                param: "radius",
                ..
            })
        ));
        assert!(cylinder(1.0, 1.0, 2, 1).is_err());
    }

    #[test]
    fn torus_has_genus_one() {
        for (a, b) in [(3, 3), (24, 12), (128, 64)] {
            let t = torus(1.0, 0.25, a, b).unwrap();
            assert_shape(&t, 1, 1);
            assert_eq!(t.triangle_count(), (2 * a * b) as usize);
        }
        let v = torus(1.0, 0.25, 256, 128).unwrap().signed_volume();
        let exact = 2.0 * PI * PI * 1.0 * 0.0625;
        assert!((v / exact - 1.0).abs() < 1e-3);
        assert!(torus(1.0, 1.0, 8, 8).is_err());
    }

    #[test]
    fn torus_knots() {
        let base = TorusKnotParams::default();
        for k in [
            base,
            TorusKnotParams {
                tubular_segments: 24,
                radial_segments: 3,
                ..base
            },
            TorusKnotParams {
                tubular_segments: 512,
                radial_segments: 24,
                ..base
            },
            TorusKnotParams {
                p: 3,
                q: 2,
                tube_radius: 0.06,
                ..base
            },
            TorusKnotParams {
                p: 3,
                q: 5,
                tube_radius: 0.06,
                tubular_segments: 300,
                ..base
            },
            TorusKnotParams { p: 1, q: 1, ..base },
        ] {
            let m = torus_knot(&k).unwrap();
            assert_shape(&m, 1, 1);
            assert_eq!(
                m.triangle_count(),
                (2 * k.tubular_segments * k.radial_segments) as usize
            );
            // Not self-intersecting: centreline points far apart along the curve keep more
            // than two tube radii (plus the chord sag of the tessellation) between them.
            let n = 720;
            let pts: Vec<DVec3> = (0..n)
                .map(|i| k.centreline(TAU * i as f64 / n as f64).0)
                .collect();
            // Cumulative polyline length, for the distance along the curve.
            let mut cum = vec![0.0];
            for i in 0..n {
                cum.push(cum[i] + pts[i].distance(pts[(i + 1) % n]));
            }
            let total = cum[n];
            let arc = |i: usize, j: usize| {
                let d = (cum[j] - cum[i]).abs();
                d.min(total - d)
            };
            for i in 0..n {
                for j in i + 1..n {
                    // Apart along the curve by more than ~4 tube radii.
                    if arc(i, j) > 4.0 * k.tube_radius {
                        assert!(
                            pts[i].distance(pts[j]) > 2.2 * k.tube_radius,
                            "{k:?}: strands {i} and {j} too close"
                        );
                    }
                }
            }
        }
        assert!(torus_knot(&TorusKnotParams { p: 2, q: 4, ..base }).is_err());
    }

    #[test]
    fn coil_springs() {
        let base = CoilSpringParams::default();
        for c in [
            base,
            CoilSpringParams {
                turns: 1.0,
                segments_per_turn: 3,
                radial_segments: 3,
                ..base
            },
            CoilSpringParams { turns: 0.3, ..base },
            CoilSpringParams {
                turns: 12.0,
                segments_per_turn: 96,
                radial_segments: 24,
                ..base
            },
        ] {
            let m = coil_spring(&c).unwrap();
            assert_shape(&m, 1, 0);
            // Volume of a tube ≈ wire cross-section × centreline length (Pappus).
            let len = c.turns * (TAU * c.coil_radius).hypot(c.pitch);
            let approx = PI * c.wire_radius * c.wire_radius * len;
            if c.radial_segments >= 10 {
                assert!((m.signed_volume() / approx - 1.0).abs() < 0.08, "{c:?}");
            }
        }
        assert!(
            coil_spring(&CoilSpringParams {
                pitch: 0.03,
                ..base
            })
            .is_err()
        );
    }

    #[test]
    fn spur_gears() {
        let base = SpurGearParams::default();
        for (g, genus) in [
            (base, 1),
            (
                SpurGearParams {
                    bore_radius: None,
                    ..base
                },
                0,
            ),
            (
                SpurGearParams {
                    teeth: 8,
                    flank_samples: 2,
                    arc_samples: 0,
                    bore_radius: Some(0.015),
                    ..base
                },
                1,
            ),
            (
                SpurGearParams {
                    teeth: 80,
                    bore_radius: None,
                    flank_samples: 10,
                    arc_samples: 5,
                    ..base
                },
                0,
            ),
        ] {
            let outline = gear_outline(&g).unwrap();
            assert!(is_simple(&outline));
            let angles: Vec<f64> = outline
                .iter()
                .map(|p| p.y.atan2(p.x).rem_euclid(TAU))
                .collect();
            // Strictly increasing polar angle (star-shaped), wrapping once.
            let wraps = (0..angles.len())
                .filter(|&i| angles[(i + 1) % angles.len()] <= angles[i])
                .count();
            assert_eq!(wraps, 1);
            let m = spur_gear(&g).unwrap();
            assert_shape(&m, 1, genus);
            let ap = m.aabb();
            let tip = g.module * (g.teeth as f64 / 2.0 + 1.0);
            assert!(ap.max.x <= tip * (1.0 + 1e-12) && ap.max.x > 0.99 * tip);
        }
        assert!(spur_gear(&SpurGearParams { teeth: 4, ..base }).is_err());
        assert!(
            spur_gear(&SpurGearParams {
                bore_radius: Some(1.0),
                ..base
            })
            .is_err()
        );
    }

    #[test]
    fn wheels_and_wheelsets() {
        let base = WheelParams::default();
        assert!(is_simple(&wheel_outline(&base).unwrap()));
        // Closed by the axis segment, the wheelset profile is a simple polygon too.
        assert!(is_simple(
            &wheelset_profile(&WheelsetParams::default()).unwrap()
        ));
        for seg in [3, 64, 256] {
            let w = wheel(&WheelParams {
                segments: seg,
                ..base
            })
            .unwrap();
            assert_shape(&w, 1, 1);
            // Axle along y: the flange tip radius in x-z, the width along y.
            let b = w.aabb();
            assert!(b.min.y < 0.0 && b.max.y > base.rim_width);
            assert!(b.max.z <= base.tread_radius + base.flange_height + 1e-12);
            let ws = wheelset(&WheelsetParams {
                wheel: WheelParams {
                    segments: seg,
                    ..base
                },
                ..Default::default()
            })
            .unwrap();
            assert_shape(&ws, 1, 0);
            let b = ws.aabb();
            assert!((b.max.y - 1.1).abs() < 1e-12 && (b.min.y + 1.1).abs() < 1e-12);
        }
        assert!(
            wheel(&WheelParams {
                bore_radius: 0.2,
                ..base
            })
            .is_err()
        );
        assert!(
            wheelset(&WheelsetParams {
                journal_start: 0.5,
                ..Default::default()
            })
            .is_err()
        );
    }

    #[test]
    fn rails() {
        assert!(is_simple(&rail_profile()));
        assert!(signed_area2(&rail_profile()) > 0.0);
        let area = signed_area2(&rail_profile()) / 2.0;
        for p in [
            RailParams::default(),
            RailParams {
                path: RailPath::Straight { length: 25.0 },
                segments: 1,
            },
            RailParams {
                path: RailPath::Curve {
                    radius: 300.0,
                    angle: 0.05,
                },
                segments: 20,
            },
            RailParams {
                path: RailPath::Curve {
                    radius: 0.5,
                    angle: 6.0,
                },
                segments: 200,
            },
        ] {
            let m = rail(&p).unwrap();
            assert_shape(&m, 1, 0);
            if let RailPath::Straight { length } = p.path {
                assert!((m.signed_volume() - area * length).abs() < 1e-12 * length);
            }
        }
        assert!(
            rail(&RailParams {
                path: RailPath::Curve {
                    radius: 0.05,
                    angle: 1.0
                },
                segments: 4
            })
            .is_err()
        );
    }

    #[test]
    fn subdivide_and_merge() {
        let t = torus(1.0, 0.3, 12, 6).unwrap();
        let s2 = subdivide(&subdivide(&t));
        assert_shape(&s2, 1, 1);
        assert_eq!(s2.triangle_count(), 16 * t.triangle_count());
        assert!((s2.signed_volume() - t.signed_volume()).abs() < 1e-12);
        let a = icosphere(1.0, 1);
        let b = a.transformed(&Pose::from_translation(DVec3::new(5.0, 0.0, 0.0)));
        let m = merge(&[a.clone(), b, t]).unwrap();
        assert_shape(&m, 3, 1);
        assert!(matches!(merge(&[]), Err(MeshError::Empty { .. })));
    }

    #[test]
    fn revolve_and_sweep_validate_input() {
        let p = |v: &[(f64, f64)]| v.iter().map(|&(x, y)| DVec2::new(x, y)).collect::<Vec<_>>();
        assert!(revolve(&p(&[(0.0, 0.0), (1.0, 0.0), (1.0, 1.0)]), 8).is_err()); // one pole
        assert!(revolve(&p(&[(1.0, 0.0), (-1.0, 0.0), (1.0, 1.0)]), 8).is_err()); // r < 0
        assert!(revolve(&p(&[(1.0, 0.0), (1.0, 0.0), (2.0, 1.0)]), 8).is_err()); // repeated
        assert!(revolve(&p(&[(1.0, 0.0), (2.0, f64::NAN), (2.0, 1.0)]), 8).is_err());
        let sq = p(&[(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]);
        let fr = |x: f64| SweepFrame {
            origin: DVec3::new(x, 0.0, 0.0),
            u: DVec3::Y,
            v: DVec3::Z,
        };
        // Either frame handedness gives an outward box.
        let m = sweep(&sq, &[fr(0.0), fr(2.0)], false).unwrap();
        assert_shape(&m, 1, 0);
        assert!((m.signed_volume() - 2.0).abs() < 1e-12);
        let flipped = [
            SweepFrame {
                u: DVec3::Z,
                v: DVec3::Y,
                ..fr(0.0)
            },
            SweepFrame {
                u: DVec3::Z,
                v: DVec3::Y,
                ..fr(2.0)
            },
        ];
        assert_shape(&sweep(&sq, &flipped, false).unwrap(), 1, 0);
        let bow = p(&[(0.0, 0.0), (1.0, 1.0), (1.0, 0.0), (0.0, 1.0)]);
        assert!(sweep(&bow, &[fr(0.0), fr(1.0)], false).is_err());
        assert!(sweep(&sq, &[fr(0.0)], false).is_err());
    }

    #[test]
    fn cuboid_is_solid() {
        let b = cuboid(DVec3::new(1.0, 2.0, 3.0));
        assert_solid(&b);
        assert_eq!(b.topology().components, 1);
    }

    #[test]
    fn icosphere_is_solid_and_round() {
        for level in 0..4 {
            let s = icosphere(3.0, level);
            assert_solid(&s);
            assert_eq!(s.triangle_count(), 20 * 4usize.pow(level));
            for p in s.vertices() {
                assert!((p.length() - 3.0).abs() < 1e-12);
            }
        }
        let v = icosphere(1.0, 5).signed_volume();
        let exact = 4.0 / 3.0 * std::f64::consts::PI;
        assert!(v < exact && v > 0.99 * exact, "{v}");
    }
}
