//! `cargo xtask gen-bogie [--out DIR]`: generates the bogie demo scene (testdata/bogie/).
//!
//! A full-scale (metres) two-axle bolster bogie on standard gauge running from a straight
//! through a clothoid into a left-hand circular curve: two wheelsets with flanged wheels,
//! four axle boxes, two side frames, two coil-spring nests, the bolster with two side bearers,
//! four brake blocks a few millimetres from the treads, the rails, and the car body's
//! underframe over this bogie. One mesh file per part (shared by the bodies that use it), a
//! `scene.json`, a 1 kHz `trajectory.csv` (wheelset hunting by Klingel's kinematics, car-body
//! roll in the curve), and a README with the parts and the interference schedule, which this
//! task computes on the written files with frcd-obb (exact triangle tests) and cross-checks
//! with the brute-force oracle on sampled frames.
//!
//! Axes: x along the track, y to the left, z up; top of rail at z = 0.

use anyhow::{Context, Result, ensure};
use frcd_geom::shapes::{self, CoilSpringParams, SweepFrame, WheelsetParams};
use frcd_geom::{DQuat, DVec2, DVec3, Pose, TriMesh};
use frcd_io::{
    FrameReport, Interference, PoseSpec, Report, Scene, SceneBody, SceneFile, Trajectory,
    TrajectoryRow, write_obj, write_stl_binary,
};
use frcd_obb::{BuildOptions, Mode, ObbTree, Request};
use std::f64::consts::{FRAC_PI_2, PI, TAU};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

// ---------------------------------------------------------------------------------------------
// Parameters (SI units)

/// Forward speed, m/s (90 km/h).
const SPEED: f64 = 25.0;
/// Trajectory rate, Hz, and duration, s.
const RATE: f64 = 1000.0;
const DURATION: f64 = 2.0;
/// Bogie centre's arc length at t = 0.
const S_START: f64 = 2.0;
/// Track: straight to S1, clothoid of length LC, then a circular curve of radius R (left).
const S1: f64 = 12.0;
const LC: f64 = 15.0;
const RADIUS: f64 = 600.0;
/// Track extent (arc length).
const TRACK_FROM: f64 = -3.0;
const TRACK_TO: f64 = 58.0;
/// Lateral position of each rail's centreline (gauge 1.435 m between the head inner faces).
const RAIL_OFFSET: f64 = 0.7175 + 0.036;
/// Semi-wheelbase, m.
const A: f64 = 1.2;
/// Wheel rolling radius (tape circle) and tread conicity of `shapes::wheelset`'s default.
const R0: f64 = 0.46;
const CONICITY: f64 = 0.025;
/// Half the lateral distance between the wheel-rail contact points (Klingel's b).
const B_CONTACT: f64 = 0.75;
/// Hunting amplitude (lateral, relative to the bogie frame), m.
const HUNT_AMPLITUDE: f64 = 0.008;
/// Steady outward shift of the wheelsets in the full curve, m.
const CURVE_SHIFT: f64 = 0.002;
/// Car-body roll in the full curve, rad, and a small sway on top.
const ROLL_MAX: f64 = 0.011;
const SWAY: (f64, f64) = (0.0008, 0.9);
/// Distance between the car's two bogie centres, m.
const BOGIE_PITCH: f64 = 18.0;
/// Brake block: radial gap to the tread, lateral gap from its inboard edge to the flange root.
const BLOCK_GAP: f64 = 0.004;
const BLOCK_INNER_S: f64 = 0.0451;
/// Parts assembled in contact overlap by this much (m), so that they touch whatever the
/// rounding of the files' coordinates (1 µm).
const SINK: f64 = 2e-6;
/// Side bearer vertical clearance (car-body pad to bolster side bearer), m.
const BEARER_GAP: f64 = 0.005;
const BEARER_Y: f64 = 0.76;

/// Lateral clearance from the brake block's inboard edge to the wheel's flange fillet, at the
/// block face's radius (the fillet runs straight from the tread to the flange front, as in
/// `shapes::wheel`).
fn block_flange_clearance(w: &frcd_geom::shapes::WheelParams) -> f64 {
    let r_t = |s: f64| w.tread_radius + (w.tape_offset - s) * w.conicity;
    let r_face = r_t(BLOCK_INNER_S) + BLOCK_GAP;
    let s_a = 1.3 * w.flange_thickness;
    let r_a = r_t(s_a);
    let (s_b, r_b) = (w.flange_thickness, w.tread_radius + 0.4 * w.flange_height);
    let s_at = s_a + (s_b - s_a) * (r_face - r_a) / (r_b - r_a);
    BLOCK_INNER_S - s_at
}

/// Klingel's wavelength of a free wheelset, m.
fn klingel_wavelength() -> f64 {
    TAU * (R0 * B_CONTACT / CONICITY).sqrt()
}

// ---------------------------------------------------------------------------------------------
// Track geometry

fn kappa_c() -> f64 {
    1.0 / RADIUS
}

/// Curvature at arc length s.
fn curvature(s: f64) -> f64 {
    if s <= S1 {
        0.0
    } else if s <= S1 + LC {
        kappa_c() * (s - S1) / LC
    } else {
        kappa_c()
    }
}

/// Heading (rad) at arc length s.
fn heading(s: f64) -> f64 {
    if s <= S1 {
        0.0
    } else if s <= S1 + LC {
        kappa_c() * (s - S1).powi(2) / (2.0 * LC)
    } else {
        kappa_c() * LC / 2.0 + (s - S1 - LC) / RADIUS
    }
}

/// Centreline point (x, y) at arc length s.
fn centreline(s: f64) -> DVec2 {
    if s <= S1 {
        return DVec2::new(s, 0.0);
    }
    let clothoid = |to: f64| {
        // Simpson over the clothoid from S1 to `to` (the heading is a quadratic: smooth).
        let n = 256;
        let h = (to - S1) / n as f64;
        let f = |u: f64| {
            let th = heading(u);
            DVec2::new(th.cos(), th.sin())
        };
        let mut sum = f(S1) + f(to);
        for i in 1..n {
            sum += f(S1 + h * i as f64) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        DVec2::new(S1, 0.0) + sum * h / 3.0
    };
    if s <= S1 + LC {
        return clothoid(s);
    }
    let p2 = clothoid(S1 + LC);
    let th2 = heading(S1 + LC);
    let centre = p2 + RADIUS * DVec2::new(-th2.sin(), th2.cos());
    let th = heading(s);
    centre + RADIUS * DVec2::new(th.sin(), -th.cos())
}

/// Left normal at arc length s.
fn normal(s: f64) -> DVec2 {
    let th = heading(s);
    DVec2::new(-th.sin(), th.cos())
}

// ---------------------------------------------------------------------------------------------
// Parts (local frames documented per part)

struct Part {
    file: &'static str,
    mesh: TriMesh,
    what: &'static str,
}

/// Rounds every coordinate to 1 µm so the files stay short and reproducible.
fn micro(mesh: TriMesh) -> Result<TriMesh> {
    let v = mesh
        .vertices()
        .iter()
        .map(|p| (*p * 1e6).round() / 1e6)
        .collect();
    let m = TriMesh::new(v, mesh.indices().to_vec())?;
    ensure!(
        m.report().degenerate.is_empty(),
        "rounding made triangles degenerate"
    );
    Ok(m)
}

/// A polygon in the (x, z) plane extruded along y over [-half, half].
fn extrude_y(poly_xz: &[DVec2], half: f64) -> Result<TriMesh> {
    let frames = [-half, half].map(|y| SweepFrame {
        origin: DVec3::new(0.0, y, 0.0),
        u: DVec3::X,
        v: DVec3::Z,
    });
    Ok(shapes::sweep(poly_xz, &frames, false)?)
}

/// A polygon in the (y, z) plane extruded along x over [-half, half].
fn extrude_x(poly_yz: &[DVec2], half: f64) -> Result<TriMesh> {
    let frames = [-half, half].map(|x| SweepFrame {
        origin: DVec3::new(x, 0.0, 0.0),
        u: DVec3::Y,
        v: DVec3::Z,
    });
    Ok(shapes::sweep(poly_yz, &frames, false)?)
}

fn translated(m: &TriMesh, t: DVec3) -> TriMesh {
    m.transformed(&Pose::from_translation(t))
}

fn boxed(min: DVec3, max: DVec3) -> TriMesh {
    translated(&shapes::cuboid((max - min) / 2.0), (min + max) / 2.0)
}

/// Vertical layout of the suspension, from the parts' real extents.
struct Layout {
    /// Height of the spring nests' origin (their bottom sinks `SINK` into the seat).
    nest_z: f64,
    /// Bolster bottom and top.
    bolster: (f64, f64),
}

/// Side frame: x along the track, centred on y = 0 (placed at y = ±1.0), z absolute. Its ends
/// rest on the axle boxes (z = 0.59); the middle dips to a spring seat at z = 0.45.
fn side_frame() -> Result<TriMesh> {
    let top = 0.46 + 0.13;
    let poly: Vec<DVec2> = [
        (-1.45, top),
        (-0.80, top),
        (-0.55, 0.30),
        (0.55, 0.30),
        (0.80, top),
        (1.45, top),
        (1.45, 0.77),
        (0.75, 0.77),
        (0.50, 0.45),
        (-0.50, 0.45),
        (-0.75, 0.77),
        (-1.45, 0.77),
    ]
    .iter()
    .map(|&(x, z)| DVec2::new(x, z))
    .collect();
    extrude_y(&poly, 0.12)
}

/// Spring nest: two outer and two inner coils side by side along x; bottom at z = 0.
fn spring_nest() -> Result<TriMesh> {
    let outer = CoilSpringParams {
        segments_per_turn: 16,
        radial_segments: 8,
        ..Default::default()
    };
    let inner = CoilSpringParams {
        coil_radius: 0.06,
        wire_radius: 0.011,
        ..outer
    };
    let mut coils = Vec::new();
    for p in [outer, inner] {
        let c = shapes::coil_spring(&p)?;
        let lift = -c.aabb().min.z;
        for x in [-0.125, 0.125] {
            coils.push(translated(&c, DVec3::new(x, 0.0, lift)));
        }
    }
    Ok(shapes::merge(&coils)?)
}

/// Brake block for the left wheel of a wheelset at the origin (axle along y, flange back face
/// at y = 0.68): a shoe following the conical tread at `BLOCK_GAP`, on the −x side at axle
/// height, spanning 36°, 50 mm thick, from `BLOCK_INNER_S` to 0.125 m from the flange back.
fn brake_block(w: &WheelsetParams) -> Result<TriMesh> {
    let wheel = &w.wheel;
    let r_t = |s: f64| wheel.tread_radius + (wheel.tape_offset - s) * wheel.conicity;
    let (s0, s1, thick) = (BLOCK_INNER_S, 0.125, 0.05);
    let y0 = w.back_to_back / 2.0;
    // Profile (radial, lateral y).
    let profile = [
        DVec2::new(r_t(s0) + BLOCK_GAP, y0 + s0),
        DVec2::new(r_t(s1) + BLOCK_GAP, y0 + s1),
        DVec2::new(r_t(s1) + BLOCK_GAP + thick, y0 + s1),
        DVec2::new(r_t(s0) + BLOCK_GAP + thick, y0 + s0),
    ];
    let span = 36f64.to_radians();
    let n = 12;
    let frames: Vec<SweepFrame> = (0..=n)
        .map(|k| {
            let phi = PI - span / 2.0 + span * k as f64 / n as f64;
            SweepFrame {
                origin: DVec3::ZERO,
                u: DVec3::new(phi.cos(), 0.0, phi.sin()),
                v: DVec3::Y,
            }
        })
        .collect();
    Ok(shapes::sweep(&profile, &frames, false)?)
}

/// The car body's underframe over this bogie, in a frame whose origin is the centre-plate
/// contact point: body bolster (with the centre plate boss and two 5 mm side-bearer pads),
/// centre sill, side sills and floor, 6 m long. Separate members are 1 mm apart (disjoint
/// closed components, so ray parity stays valid).
fn car_body() -> Result<TriMesh> {
    // Pad bottom above the centre-plate contact: the bolster side bearer is 60 mm tall.
    let pad = 0.06 + BEARER_GAP;
    let base = 0.07; // body bolster bottom
    let (y0, y1) = (BEARER_Y - 0.08, BEARER_Y + 0.08);
    let poly: Vec<DVec2> = [
        (-1.4, base),
        (-y1, base),
        (-y1, pad),
        (-y0, pad),
        (-y0, base),
        (-0.15, base),
        (-0.15, 0.0),
        (0.15, 0.0),
        (0.15, base),
        (y0, base),
        (y0, pad),
        (y1, pad),
        (y1, base),
        (1.4, base),
        (1.4, 0.35),
        (-1.4, 0.35),
    ]
    .iter()
    .map(|&(y, z)| DVec2::new(y, z))
    .collect();
    let bolster = extrude_x(&poly, 0.25)?;
    let sill = |y0: f64, y1: f64| boxed(DVec3::new(-3.0, y0, 0.351), DVec3::new(3.0, y1, 0.60));
    let floor = boxed(DVec3::new(-3.0, -1.45, 0.601), DVec3::new(3.0, 1.45, 0.63));
    Ok(shapes::merge(&[
        bolster,
        sill(-0.2, 0.2),
        sill(1.25, 1.45),
        sill(-1.45, -1.25),
        floor,
    ])?)
}

/// Bolster: a fish-belly beam across the bogie, 0.44 m wide, ends 0.20 m deep resting on the
/// spring nests, 0.32 m deep in the middle; centred on its end-section mid-height.
fn bolster() -> Result<TriMesh> {
    let poly: Vec<DVec2> = [
        (-1.15, -0.10),
        (-0.80, -0.10),
        (-0.50, -0.22),
        (0.50, -0.22),
        (0.80, -0.10),
        (1.15, -0.10),
        (1.15, 0.10),
        (-1.15, 0.10),
    ]
    .iter()
    .map(|&(y, z)| DVec2::new(y, z))
    .collect();
    extrude_x(&poly, 0.22)
}

/// Both rails along the track, foot at z = −0.172 so the top of rail is z = 0.
fn track() -> Result<TriMesh> {
    let mut stations = vec![TRACK_FROM];
    let mut s = S1;
    while s < TRACK_TO {
        stations.push(s);
        s += 1.0;
    }
    stations.push(TRACK_TO);
    let profile = shapes::rail_profile();
    let rail = |side: f64| -> Result<TriMesh> {
        let frames: Vec<SweepFrame> = stations
            .iter()
            .map(|&s| {
                let n = normal(s);
                let p = centreline(s) + side * RAIL_OFFSET * n;
                SweepFrame {
                    origin: DVec3::new(p.x, p.y, -0.172),
                    u: DVec3::new(n.x, n.y, 0.0),
                    v: DVec3::Z,
                }
            })
            .collect();
        Ok(shapes::sweep(&profile, &frames, false)?)
    };
    Ok(shapes::merge(&[rail(1.0)?, rail(-1.0)?])?)
}

// ---------------------------------------------------------------------------------------------
// Kinematics

fn yaw(a: f64) -> DQuat {
    DQuat::from_rotation_z(a)
}

fn at(p: DVec2, z: f64) -> DVec3 {
    DVec3::new(p.x, p.y, z)
}

/// The rigid bogie frame at time t: origin on the chord between the two wheelsets' track
/// points (top of rail), heading along that chord.
fn bogie_frame(s_b: f64) -> Pose {
    let (p1, p2) = (centreline(s_b + A), centreline(s_b - A));
    let d = p1 - p2;
    Pose::new(at((p1 + p2) / 2.0, 0.0), yaw(d.y.atan2(d.x)))
}

/// Lateral displacement (relative to the bogie frame, + left) and yaw (relative) of wheelset
/// `i` (0 leading, 1 trailing) at time t: Klingel hunting plus a steady outward shift in the
/// curve. The trailing wheelset passes the same track point 2a/v later (same wave, phase lag
/// 2π·2a/L). ψ = dy/dx.
fn hunting(i: usize, t: f64, s_i: f64) -> (f64, f64) {
    let l = klingel_wavelength();
    let k = TAU / l;
    let phase = k * (SPEED * t) - i as f64 * k * 2.0 * A + 0.4;
    let shift = -CURVE_SHIFT * curvature(s_i) / kappa_c();
    let dshift = if s_i > S1 && s_i < S1 + LC {
        -CURVE_SHIFT / LC
    } else {
        0.0
    };
    (
        HUNT_AMPLITUDE * phase.sin() + shift,
        HUNT_AMPLITUDE * k * phase.cos() + dshift,
    )
}

struct Bodies {
    /// (name, mesh file, static, exclude-with)
    list: Vec<(String, &'static str, bool)>,
    exclude: Vec<[String; 2]>,
}

fn bodies() -> Bodies {
    let mut list: Vec<(String, &'static str, bool)> = vec![("track".into(), "track.obj", true)];
    let mut exclude = Vec::new();
    let pair = |a: &str, b: &str| [a.to_owned(), b.to_owned()];
    for w in 1..=2 {
        let ws = format!("wheelset_{w}");
        list.push((ws.clone(), "wheelset.obj", false));
        exclude.push(pair(&ws, "track"));
        for side in ["L", "R"] {
            let ab = format!("axle_box_{w}{side}");
            list.push((ab.clone(), "axle_box.stl", false));
            exclude.push(pair(&ab, &ws));
            exclude.push(pair(&ab, &format!("side_frame_{side}")));
        }
    }
    for side in ["L", "R"] {
        list.push((format!("side_frame_{side}"), "side_frame.obj", false));
    }
    for side in ["L", "R"] {
        let sn = format!("spring_nest_{side}");
        list.push((sn.clone(), "spring_nest.obj", false));
        exclude.push(pair(&sn, &format!("side_frame_{side}")));
        exclude.push(pair(&sn, "bolster"));
    }
    list.push(("bolster".into(), "bolster.obj", false));
    for side in ["L", "R"] {
        let sb = format!("side_bearer_{side}");
        list.push((sb.clone(), "side_bearer.stl", false));
        exclude.push(pair(&sb, "bolster"));
    }
    for w in 1..=2 {
        for side in ["L", "R"] {
            list.push((format!("brake_block_{w}{side}"), "brake_block.stl", false));
        }
    }
    list.push(("car_body".into(), "car_body_underframe.obj", false));
    exclude.push(pair("car_body", "bolster"));
    Bodies { list, exclude }
}

/// Every body's world pose at time t (frame k = t·RATE).
fn poses(t: f64, layout: &Layout, names: &[String]) -> Vec<Pose> {
    let s_b = S_START + SPEED * t;
    let frame = bogie_frame(s_b);
    let local =
        |x: f64, y: f64, z: f64, q: DQuat| frame.compose(&Pose::new(DVec3::new(x, y, z), q));
    // Wheelsets: on the track at their own arc length, shifted and yawed by hunting, spinning.
    let mut ws = Vec::new();
    for (i, x) in [A, -A].into_iter().enumerate() {
        let s_i = s_b + x;
        let (y, psi) = hunting(i, t, s_i);
        // Relative to the frame: the track point seen from the frame (≈ (x, 0)) plus y, ψ.
        let track_pt = frame.inverse().transform_point(at(centreline(s_i), 0.0));
        let track_yaw = heading(s_i) - heading_of(&frame);
        let spin = DQuat::from_rotation_y(s_i / R0);
        let rot = yaw(track_yaw + psi);
        let centre = DVec3::new(track_pt.x, track_pt.y + y, 0.46029);
        ws.push((
            frame.compose(&Pose::new(centre, rot * spin)),
            frame.compose(&Pose::new(centre, rot)),
        ));
    }
    let bolster_mid = (layout.bolster.0 + layout.bolster.1) / 2.0;
    let body_pose = {
        let p_this = centreline(s_b);
        let p_other = centreline(s_b - BOGIE_PITCH);
        let d = p_this - p_other;
        let roll = ROLL_MAX * curvature(s_b) / kappa_c() + SWAY.0 * (TAU * SWAY.1 * t).sin();
        let pivot = frame.transform_point(DVec3::new(0.0, 0.0, layout.bolster.1 - SINK));
        Pose::new(pivot, yaw(d.y.atan2(d.x)) * DQuat::from_rotation_x(roll))
    };
    names
        .iter()
        .map(|name| {
            let n = name.as_str();
            let side = if n.ends_with('L') { 1.0 } else { -1.0 };
            let w = if n.contains("_1") { 0 } else { 1 };
            match n {
                "track" => Pose::IDENTITY,
                "wheelset_1" => ws[0].0,
                "wheelset_2" => ws[1].0,
                _ if n.starts_with("axle_box") => ws[w].1.compose(&Pose::new(
                    DVec3::new(0.0, side * 1.0, 0.0),
                    DQuat::IDENTITY,
                )),
                _ if n.starts_with("side_frame") => local(0.0, side * 1.0, 0.0, DQuat::IDENTITY),
                _ if n.starts_with("spring_nest") => {
                    local(0.0, side * 1.0, layout.nest_z, DQuat::IDENTITY)
                }
                "bolster" => local(0.0, 0.0, bolster_mid, DQuat::IDENTITY),
                _ if n.starts_with("side_bearer") => local(
                    0.0,
                    side * BEARER_Y,
                    layout.bolster.1 + 0.03 - SINK,
                    DQuat::IDENTITY,
                ),
                _ if n.starts_with("brake_block") => {
                    // The block mesh is for the left wheel of a wheelset at the origin, on its
                    // −x side; turn it to the right wheel (about x) and/or to the +x side
                    // (about z) so every block faces the bogie centre.
                    let x = if w == 0 { A } else { -A };
                    let mut q = DQuat::IDENTITY;
                    if w == 1 {
                        q = DQuat::from_rotation_z(PI) * q;
                    }
                    if (side < 0.0) != (w == 1) {
                        q = DQuat::from_rotation_x(PI) * q;
                    }
                    local(x, 0.0, 0.46029, q)
                }
                "car_body" => body_pose,
                other => unreachable!("no kinematics for {other}"),
            }
        })
        .collect()
}

fn heading_of(p: &Pose) -> f64 {
    let x = p.rotation * DVec3::X;
    x.y.atan2(x.x)
}

/// Rounds a pose for the CSV: translation to 1 µm, quaternion to 1e-7 (sign fixed w ≥ 0).
fn rounded(p: &Pose) -> Pose {
    let r = |x: f64, k: f64| (x * k).round() / k;
    let q = if p.rotation.w < 0.0 {
        -p.rotation
    } else {
        p.rotation
    };
    Pose {
        translation: DVec3::new(
            r(p.translation.x, 1e6),
            r(p.translation.y, 1e6),
            r(p.translation.z, 1e6),
        ),
        rotation: DQuat::from_xyzw(r(q.x, 1e7), r(q.y, 1e7), r(q.z, 1e7), r(q.w, 1e7)),
    }
}

// ---------------------------------------------------------------------------------------------
// Interference check of the written scene

struct Checked {
    report: Report,
    /// Excluded pairs that do not touch in frame 0 (the exclusion list should be only parts
    /// assembled in contact).
    excluded_apart: Vec<String>,
    oracle_frames: usize,
    oracle_pairs: usize,
    millis: f64,
}

fn world_aabb(mesh: &TriMesh, pose: &Pose) -> (DVec3, DVec3) {
    let b = mesh.aabb();
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for i in 0..8 {
        let c = DVec3::new(
            if i & 1 == 0 { b.min.x } else { b.max.x },
            if i & 2 == 0 { b.min.y } else { b.max.y },
            if i & 4 == 0 { b.min.z } else { b.max.z },
        );
        let p = pose.transform_point(c);
        lo = lo.min(p);
        hi = hi.max(p);
    }
    (lo, hi)
}

/// Every non-excluded pair in every frame: AABB cull, then frcd-obb (exact triangle tests,
/// solid mode). On every 50th frame and around every interval boundary, the brute-force
/// oracle must agree pair for pair.
fn check(scene: &Scene) -> Result<Checked> {
    let start = Instant::now();
    let trees: Vec<Arc<ObbTree>> = scene
        .meshes()
        .iter()
        .map(|m| Arc::new(ObbTree::build(m, &BuildOptions::default())))
        .collect();
    let bodies = scene.bodies();
    let request = Request {
        mode: Mode::AllPairs,
        solid: true,
        ..Request::default()
    };
    let mut report = Report::new("cpu-obb (gen-bogie)", "exact");
    let mut candidates: Vec<Vec<(usize, usize)>> = Vec::new();
    for (k, frame) in scene.frames().iter().enumerate() {
        let boxes: Vec<(DVec3, DVec3)> = bodies
            .iter()
            .zip(&frame.poses)
            .map(|(b, p)| world_aabb(&b.mesh, p))
            .collect();
        let mut inter = Vec::new();
        let mut cand = Vec::new();
        for i in 0..bodies.len() {
            for j in i + 1..bodies.len() {
                if scene.is_excluded(i, j) || (bodies[i].is_static && bodies[j].is_static) {
                    continue;
                }
                let ((alo, ahi), (blo, bhi)) = (boxes[i], boxes[j]);
                if alo.cmpgt(bhi).any() || blo.cmpgt(ahi).any() {
                    continue;
                }
                cand.push((i, j));
                let c = frcd_obb::collide(
                    &trees[bodies[i].mesh_index],
                    &frame.poses[i],
                    &trees[bodies[j].mesh_index],
                    &frame.poses[j],
                    &request,
                );
                if c.collide {
                    inter.push(Interference {
                        a: bodies[i].name.clone(),
                        b: bodies[j].name.clone(),
                        triangle_pairs: c.pairs.len() as u64,
                        contained: c.contained.is_some(),
                        ..Interference::default()
                    });
                }
            }
        }
        candidates.push(cand);
        report.frames.push(FrameReport {
            index: k,
            time_us: 0.0,
            interferences: inter,
        });
    }
    report.summarize();
    let millis = start.elapsed().as_secs_f64() * 1e3;
    let f0 = &scene.frame(0);
    let excluded_apart = scene
        .exclusions()
        .iter()
        .filter(|&&(i, j)| {
            !frcd_obb::collide(
                &trees[bodies[i].mesh_index],
                &f0.poses[i],
                &trees[bodies[j].mesh_index],
                &f0.poses[j],
                &Request {
                    solid: true,
                    ..Request::default()
                },
            )
            .collide
        })
        .map(|&(i, j)| format!("{}–{}", bodies[i].name, bodies[j].name))
        .collect();
    // Oracle cross-check.
    let mut sample: Vec<usize> = (0..scene.frame_count()).step_by(50).collect();
    for p in &report.pairs {
        for iv in &p.intervals {
            sample.extend([iv[0].saturating_sub(1), iv[0], iv[1], iv[1] + 1]);
        }
    }
    sample.retain(|&k| k < scene.frame_count());
    sample.sort_unstable();
    sample.dedup();
    let mut oracle_pairs = 0;
    for &k in &sample {
        let frame = &scene.frame(k);
        for &(i, j) in &candidates[k] {
            let o = frcd_obb::oracle::answer(
                &bodies[i].mesh,
                &frame.poses[i],
                &bodies[j].mesh,
                &frame.poses[j],
                true,
            );
            let got = report.frames[k]
                .interferences
                .iter()
                .find(|x| x.a == bodies[i].name && x.b == bodies[j].name);
            let ok = match got {
                Some(g) => {
                    o.collide()
                        && g.triangle_pairs == o.pairs.len() as u64
                        && g.contained == o.contained.is_some()
                }
                None => !o.collide(),
            };
            ensure!(
                ok,
                "frame {k}: OBB and oracle disagree on {} × {}",
                bodies[i].name,
                bodies[j].name
            );
            oracle_pairs += 1;
        }
    }
    Ok(Checked {
        report,
        excluded_apart,
        oracle_frames: sample.len(),
        oracle_pairs,
        millis,
    })
}

// ---------------------------------------------------------------------------------------------
// Driver

/// Options of `cargo xtask gen-bogie`.
#[derive(clap::Args, Debug)]
pub struct Opts {
    /// Folder the scene is written to.
    #[arg(long, value_name = "DIR", default_value_os_t = crate::workspace_path("testdata/bogie"))]
    pub out: PathBuf,
}

/// Entry point of `cargo xtask gen-bogie`.
pub fn run(o: Opts) -> Result<()> {
    let out = o.out;
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;

    // Parts.
    let ws_params = WheelsetParams::default();
    let nest = micro(spring_nest()?)?;
    let seat = 0.45;
    let nest_h = nest.aabb().max.z - nest.aabb().min.z;
    let b0 = ((seat + nest_h) * 1e6).round() / 1e6 - 2.0 * SINK;
    let layout = Layout {
        nest_z: seat - SINK - nest.aabb().min.z,
        bolster: (b0, b0 + 0.20),
    };
    let parts = vec![
        Part {
            file: "track.obj",
            mesh: track()?,
            what: "both rails (UIC 60-like profile), straight, clothoid, R 600 m left curve",
        },
        Part {
            file: "wheelset.obj",
            mesh: shapes::wheelset(&ws_params)?,
            what: "axle and two 920 mm flanged wheels, 1:40 tread (shapes::wheelset)",
        },
        Part {
            file: "axle_box.stl",
            mesh: shapes::cylinder(0.13, 0.09, 32, 1)?
                .transformed(&Pose::new(DVec3::ZERO, DQuat::from_rotation_x(-FRAC_PI_2))),
            what: "axle box housing around the journal",
        },
        Part {
            file: "side_frame.obj",
            mesh: side_frame()?,
            what: "side frame resting on the axle boxes, dropped spring seat",
        },
        Part {
            file: "spring_nest.obj",
            mesh: nest,
            what: "two outer and two inner coil springs (4 components)",
        },
        Part {
            file: "bolster.obj",
            mesh: bolster()?,
            what: "fish-belly bolster on the spring nests",
        },
        Part {
            file: "side_bearer.stl",
            mesh: shapes::cuboid(DVec3::new(0.08, 0.08, 0.03)),
            what: "side bearer on the bolster",
        },
        Part {
            file: "brake_block.stl",
            mesh: brake_block(&ws_params)?,
            what: "brake block (shoe) 4 mm off the tread",
        },
        Part {
            file: "car_body_underframe.obj",
            mesh: car_body()?,
            what: "car body underframe over the bogie: body bolster with centre plate and side-bearer pads, sills, floor",
        },
    ];
    let mut sizes = Vec::new();
    for p in &parts {
        let path = out.join(p.file);
        let mesh = micro(p.mesh.clone())?;
        ensure!(
            mesh.topology().is_closed_oriented_manifold() && mesh.signed_volume() > 0.0,
            "{}: not a closed outward solid: {:?}",
            p.file,
            mesh.topology()
        );
        if p.file.ends_with(".stl") {
            write_stl_binary(&path, &mesh)?;
        } else {
            write_obj(&path, &mesh, p.file.trim_end_matches(".obj"))?;
        }
        sizes.push(std::fs::metadata(&path)?.len());
    }

    // Scene and trajectory.
    let Bodies { list, exclude } = bodies();
    let names: Vec<String> = list.iter().map(|b| b.0.clone()).collect();
    let initial = poses(0.0, &layout, &names);
    let spec = SceneFile {
        bodies: list
            .iter()
            .zip(&initial)
            .map(|((name, file, st), p)| SceneBody {
                name: name.clone(),
                mesh: (*file).to_owned(),
                is_static: *st,
                pose: PoseSpec::from_pose(&rounded(p)),
            })
            .collect(),
        exclude,
        trajectory: Some("trajectory.csv".into()),
        frames: Vec::new(),
        ..SceneFile::default()
    };
    spec.write(out.join("scene.json"))?;
    let frames = (DURATION * RATE).round() as usize + 1;
    let mut rows = Vec::with_capacity(frames * names.len());
    for k in 0..frames {
        let t = k as f64 / RATE;
        for (b, p) in names.iter().zip(poses(t, &layout, &names)) {
            if b == "track" {
                continue;
            }
            rows.push(TrajectoryRow {
                frame: k,
                body: b.clone(),
                pose: rounded(&p),
                line: 0,
            });
        }
    }
    let traj = Trajectory {
        path: out.join("trajectory.csv"),
        rows,
    };
    traj.write(&traj.path)?;
    let csv_size = std::fs::metadata(&traj.path)?.len();

    // Load what was written, and check it.
    let scene = Scene::load(out.join("scene.json"))?;
    ensure!(scene.frame_count() == frames, "frame count");
    let checked = check(&scene)?;
    let mut schedule = String::new();
    for p in &checked.report.pairs {
        let iv: Vec<String> = p
            .intervals
            .iter()
            .map(|[a, b]| {
                format!(
                    "{a}–{b} ({:.3}–{:.3} s)",
                    *a as f64 / RATE,
                    *b as f64 / RATE
                )
            })
            .collect();
        let _ = writeln!(
            schedule,
            "| {} | {} | {} | {} | {} |",
            p.a,
            p.b,
            p.frames,
            p.max_triangle_pairs,
            iv.join(", ")
        );
    }
    let interfering: std::collections::BTreeSet<(&str, &str)> = checked
        .report
        .pairs
        .iter()
        .map(|p| (p.a.as_str(), p.b.as_str()))
        .collect();
    let bodies = scene.bodies();
    let mut never = 0usize;
    for i in 0..bodies.len() {
        for j in i + 1..bodies.len() {
            let skipped = scene.is_excluded(i, j) || (bodies[i].is_static && bodies[j].is_static);
            let pair = (bodies[i].name.as_str(), bodies[j].name.as_str());
            if !skipped && !interfering.contains(&pair) {
                never += 1;
            }
        }
    }
    println!("gen-bogie: wrote {}", out.display());
    println!(
        "  {} bodies, {} distinct meshes, {} frames at {} Hz, {} excluded pairs",
        bodies.len(),
        scene.meshes().len(),
        scene.frame_count(),
        RATE,
        scene.exclusions().len()
    );
    println!(
        "  interference (frcd-obb, exact, solid; oracle agreed on {} pair checks in {} frames; {:.0} ms):",
        checked.oracle_pairs, checked.oracle_frames, checked.millis
    );
    print!("{}", schedule.replace("| ", "  ").replace(" |", ""));
    println!("  {} other checked pairs never interfere", never);
    println!(
        "  excluded pairs not touching at frame 0: {}",
        if checked.excluded_apart.is_empty() {
            "none".to_owned()
        } else {
            checked.excluded_apart.join(", ")
        }
    );

    // README.
    let mut parts_table = String::new();
    for (p, size) in parts.iter().zip(&sizes) {
        let users: Vec<&str> = list
            .iter()
            .filter(|b| b.1 == p.file)
            .map(|b| b.0.as_str())
            .collect();
        let _ = writeln!(
            parts_table,
            "| `{}` | {} | {} | {} | {} |",
            p.file,
            p.mesh.triangle_count(),
            size,
            users.join(", "),
            p.what
        );
    }
    let summary = Report {
        frames: Vec::new(),
        ..checked.report.clone()
    };
    summary.write_json(out.join("expected_interference.json"))?;
    // The first frame with the most interfering pairs: the one to render.
    let busiest = checked
        .report
        .frames
        .iter()
        .rev()
        .max_by_key(|f| f.interferences.len())
        .map_or(0, |f| f.index);
    let busiest_pairs: Vec<String> = checked.report.frames[busiest]
        .interferences
        .iter()
        .map(|i| format!("{} × {}", i.a, i.b))
        .collect();
    println!("  busiest frame: {busiest} ({})", busiest_pairs.join(", "));
    let apart = if checked.excluded_apart.is_empty() {
        "every excluded pair touches or overlaps at frame 0".to_owned()
    } else {
        format!(
            "at frame 0 these excluded pairs do not touch: {}",
            checked.excluded_apart.join(", ")
        )
    };
    let busiest_text = busiest_pairs.join(", ");
    let readme = readme(
        &scene,
        &Facts {
            parts: &parts_table,
            schedule: &schedule,
            csv_size,
            frames,
            never,
            apart: &apart,
            busiest: (busiest, &busiest_text),
        },
    );
    std::fs::write(out.join("README.md"), readme)?;
    Ok(())
}

/// What the README reports besides the constants.
struct Facts<'a> {
    parts: &'a str,
    schedule: &'a str,
    csv_size: u64,
    frames: usize,
    never: usize,
    apart: &'a str,
    busiest: (usize, &'a str),
}

fn readme(scene: &Scene, facts: &Facts) -> String {
    let Facts {
        parts,
        schedule,
        csv_size,
        frames,
        never,
        apart,
        busiest,
    } = *facts;
    let l = klingel_wavelength();
    let excl: Vec<String> = scene
        .exclusions()
        .iter()
        .map(|&(a, b)| format!("{}–{}", scene.bodies()[a].name, scene.bodies()[b].name))
        .collect();
    format!(
        r#"# Bogie demo scene

Generated by `cargo xtask gen-bogie` (xtask/src/gen_bogie.rs); do not edit by hand. Full scale,
metres; x along the track, y to the left, z up, top of rail at z = 0.

A two-axle bolster bogie on standard gauge (1.435 m) runs at {speed} m/s from a straight through a
{lc} m clothoid into a left-hand curve of radius {radius} m, for {dur} s at {rate} Hz ({frames} frames).

- `scene.json`: {nb} bodies, meshes relative to this folder, {ne} excluded pairs (parts assembled
  in contact: {excl}; {apart}), and `"trajectory": "trajectory.csv"`.
- `trajectory.csv` ({csv} bytes): `frame,body,x,y,z,qx,qy,qz,qw`, every moving body in every frame,
  translations to 1 µm, quaternions to 1e-7.
- `expected_interference.json`: the schedule below as an frcd report (`pairs`, no frames).

## Parts

| file | triangles | bytes | bodies | what |
| --- | ---: | ---: | --- | --- |
{parts}
Every mesh is a closed, outward-oriented solid (checked on generation); coordinates are rounded to
1 µm.

## Kinematics

- **Track**: straight to s = {s1} m, clothoid (curvature linear in s) to s = {s2} m, then the
  circular curve. The bogie centre starts at s = {s0} m.
- **Bogie frame** (side frames, spring nests, bolster, side bearers, brake blocks): rigid, origin
  on the chord between the two wheelsets' track points, heading along that chord.
- **Wheelsets** (semi-wheelbase {a} m): on the track at their own arc length, spinning at v/r0,
  hunting relative to the frame with Klingel's kinematics: y = A sin(2π x / L + φ) with
  A = {amp} mm and L = 2π √(r0 b / λ) = {l:.2} m (r0 = {r0} m, b = {b} m half the contact-point
  distance, λ = {lam} the wheel's tread conicity; with b = half gauge 0.7175 m, L = {l2:.2} m); the
  trailing wheelset runs the same wave 2a/v later; yaw ψ = dy/dx. In the curve both shift
  {shift} mm outward. Axle boxes follow their wheelset (without the spin).
- **Car body**: pivots on the bolster's centre plate, heads along the chord to the car's other
  bogie {pitch} m behind, and rolls outward in proportion to the curvature, up to {roll} rad in
  the full curve, plus a {sway_a} rad, {sway_f} Hz sway.

Clearances by design: brake blocks {gap} mm radially off the treads and {lat:.1} mm laterally from
the flange fillet (at the block face's radius); side bearers {bgap} mm below the car body's pads at y = ±{by} m.

## Interference schedule

Computed on the written files by `gen-bogie` with frcd-obb (exact triangle tests, solid mode) over
every non-excluded pair in every frame, and cross-checked pair for pair against the brute-force
oracle on every 50th frame and around every interval boundary.

| a | b | frames | max triangle pairs | intervals (frames, time) |
| --- | --- | ---: | ---: | --- |
{schedule}
So: the brake blocks touch the wheel flanges at the hunting peaks (left blocks when the wheelset
swings left, right blocks when it swings right; in the curve the outward shift favours the right
side), and the right-hand (outer) side-bearer clearance closes once the car body's roll exceeds
{bgap} mm / {by} m in the curve. The other {never} checked pairs never interfere.

The first frame with the most interfering pairs is {busiest_frame} ({busiest_pairs}), the frame to
render: `frcd render testdata/bogie/scene.json --frame {busiest_frame} -o bogie.png`. The whole
run: `frcd check testdata/bogie/scene.json`.
"#,
        speed = SPEED,
        lc = LC,
        radius = RADIUS,
        dur = DURATION,
        rate = RATE,
        frames = frames,
        nb = scene.bodies().len(),
        ne = scene.exclusions().len(),
        excl = excl.join(", "),
        csv = csv_size,
        parts = parts,
        s1 = S1,
        s2 = S1 + LC,
        s0 = S_START,
        a = A,
        amp = HUNT_AMPLITUDE * 1e3,
        l = l,
        r0 = R0,
        b = B_CONTACT,
        lam = CONICITY,
        l2 = TAU * (R0 * 0.7175 / CONICITY).sqrt(),
        shift = CURVE_SHIFT * 1e3,
        pitch = BOGIE_PITCH,
        roll = ROLL_MAX,
        sway_a = SWAY.0,
        sway_f = SWAY.1,
        gap = BLOCK_GAP * 1e3,
        lat = block_flange_clearance(&WheelsetParams::default().wheel) * 1e3,
        bgap = BEARER_GAP * 1e3,
        by = BEARER_Y,
        schedule = schedule,
        never = never,
        apart = apart,
        busiest_frame = busiest.0,
        busiest_pairs = busiest.1,
    )
}
