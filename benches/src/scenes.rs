//! Generated scenes shared by `cargo xtask verify`, the criterion benches and other backends'
//! tests: bodies (meshes, static or moving) and their poses at every step.
//!
//! Every generator is deterministic (its own SplitMix64 stream, no global RNG), so a scene is
//! the same on every machine and in every run.
//!
//! ```
//! use frcd_benches::scenes;
//! let s = scenes::icospheres_sweep(2, 10);
//! assert_eq!(s.bodies.len(), 2);
//! assert_eq!(s.frames.len(), 10);
//! assert_eq!(s.frames[3].len(), 2);
//! ```

use frcd_geom::shapes::{
    RailParams, RailPath, SpurGearParams, TorusKnotParams, WheelsetParams, rail, spur_gear,
    torus_knot, wheelset,
};
use frcd_geom::{DQuat, DVec3, Pose, TriMesh, shapes};
use std::sync::Arc;

/// A body of a scene.
#[derive(Clone, Debug)]
pub struct Body {
    /// A short name (`"sphere_a"`, `"gear_1"`, ...).
    pub name: String,
    /// The mesh, in the body's local frame (bodies may share one).
    pub mesh: Arc<TriMesh>,
    /// A static body never moves; static-static pairs are not tested.
    pub is_static: bool,
}

/// Bodies and their poses per step: `frames[step][body]`.
#[derive(Clone, Debug)]
pub struct Scene {
    /// A short name, used as a row label.
    pub name: String,
    /// The bodies.
    pub bodies: Vec<Body>,
    /// Poses per step, one per body.
    pub frames: Vec<Vec<Pose>>,
}

impl Scene {
    /// Number of steps.
    pub fn steps(&self) -> usize {
        self.frames.len()
    }

    /// Total triangle count over the bodies.
    pub fn triangle_count(&self) -> usize {
        self.bodies.iter().map(|b| b.mesh.triangle_count()).sum()
    }

    /// True when every mesh is closed (solid-mode comparisons are meaningful).
    pub fn all_closed(&self) -> bool {
        self.bodies.iter().all(|b| b.mesh.topology().is_closed())
    }

    /// Body pairs `(i, j)`, `i < j`, that are not both static, in ascending order.
    pub fn body_pairs(&self) -> Vec<(usize, usize)> {
        let n = self.bodies.len();
        let mut out = Vec::new();
        for i in 0..n {
            for j in i + 1..n {
                if !(self.bodies[i].is_static && self.bodies[j].is_static) {
                    out.push((i, j));
                }
            }
        }
        out
    }

    /// The same scene with only the first `steps` frames.
    pub fn truncated(mut self, steps: usize) -> Self {
        self.frames.truncate(steps);
        self
    }
}

/// A deterministic SplitMix64 stream.
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    /// A stream from a seed.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * ((self.next_u64() >> 11) as f64 / (1u64 << 53) as f64)
    }
    /// A uniformly distributed unit vector.
    pub fn unit(&mut self) -> DVec3 {
        loop {
            let v = DVec3::new(
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
            );
            let l = v.length_squared();
            if l > 1e-6 && l <= 1.0 {
                return v / l.sqrt();
            }
        }
    }
    /// A random rotation.
    pub fn rotation(&mut self) -> DQuat {
        DQuat::from_axis_angle(self.unit(), self.range(0.0, std::f64::consts::TAU))
    }
}

fn body(name: &str, mesh: &Arc<TriMesh>, is_static: bool) -> Body {
    Body {
        name: name.to_string(),
        mesh: mesh.clone(),
        is_static,
    }
}

/// Two unit icospheres of `20·4^level` triangles each (level 5: 20,480; level 6: 81,920): A
/// static at the origin, B sliding through it along x from -2.5 to 2.5 (apart, touching,
/// overlapping, through, apart again), slightly off-axis and turning slowly.
pub fn icospheres_sweep(level: u32, steps: usize) -> Scene {
    let mesh = Arc::new(shapes::icosphere(1.0, level));
    let frames = (0..steps)
        .map(|k| {
            let s = k as f64 / (steps.max(2) - 1) as f64;
            vec![
                Pose::IDENTITY,
                Pose::new(
                    DVec3::new(-2.5 + 5.0 * s, 0.15, -0.1),
                    DQuat::from_rotation_z(0.6 * s) * DQuat::from_rotation_x(0.3 * s),
                ),
            ]
        })
        .collect();
    Scene {
        name: format!("icospheres_l{level}"),
        bodies: vec![
            body("sphere_a", &mesh, true),
            body("sphere_b", &mesh, false),
        ],
        frames,
    }
}

/// A sparse scene: `n` small bodies (icospheres, boxes, tori-like rings where available) in a
/// cube sized so that each body has about 125 of its own volumes of room, drifting with small
/// random velocities and spins; every fifth body is static. A few bodies touch at any step.
pub fn sparse(n: usize, steps: usize, seed: u64) -> Scene {
    let templates: Vec<Arc<TriMesh>> = vec![
        Arc::new(shapes::icosphere(0.5, 2)),
        Arc::new(shapes::cuboid(DVec3::new(0.6, 0.25, 0.35))),
        Arc::new(shapes::icosphere(0.35, 1)),
    ];
    let mut rng = Rng::new(seed);
    let side = 5.0 * (n as f64).cbrt();
    let mut bodies = Vec::with_capacity(n);
    let mut pos = Vec::with_capacity(n);
    let mut rot = Vec::with_capacity(n);
    let mut vel = Vec::with_capacity(n);
    let mut spin = Vec::with_capacity(n);
    for i in 0..n {
        let is_static = i % 5 == 0;
        bodies.push(body(
            &format!("body_{i}"),
            &templates[i % templates.len()],
            is_static,
        ));
        pos.push(DVec3::new(
            rng.range(0.0, side),
            rng.range(0.0, side),
            rng.range(0.0, side),
        ));
        rot.push(rng.rotation());
        let v = if is_static { 0.0 } else { 0.08 };
        vel.push(rng.unit() * v);
        spin.push(DQuat::from_axis_angle(
            rng.unit(),
            if is_static { 0.0 } else { 0.03 },
        ));
    }
    let mut frames = Vec::with_capacity(steps);
    for _ in 0..steps {
        frames.push(
            pos.iter()
                .zip(&rot)
                .map(|(p, r)| Pose::new(*p, *r))
                .collect(),
        );
        for i in 0..n {
            pos[i] += vel[i];
            // Bounce off the walls.
            for k in 0..3 {
                if pos[i][k] < 0.0 || pos[i][k] > side {
                    vel[i][k] = -vel[i][k];
                }
            }
            rot[i] = (spin[i] * rot[i]).normalize();
        }
    }
    Scene {
        name: format!("sparse_{n}"),
        bodies,
        frames,
    }
}

/// A mesh against a copy of itself: A static, B starting one box diagonal away along a skew
/// direction and sliding to A's centre while turning (apart, grazing, deep overlap).
pub fn self_sweep(name: &str, mesh: Arc<TriMesh>, steps: usize) -> Scene {
    let b = mesh.aabb();
    let diag = (b.max - b.min).length();
    let dir = DVec3::new(1.0, 0.7, 0.4).normalize();
    let frames = (0..steps)
        .map(|k| {
            let s = k as f64 / (steps.max(2) - 1) as f64;
            // Rotate B about A's box centre so the two stay comparable in position.
            let c = b.center();
            let q = DQuat::from_rotation_z(0.4 * s) * DQuat::from_rotation_x(0.2 * s);
            let t = c - q * c + dir * (diag * (1.05 - s));
            vec![Pose::IDENTITY, Pose::new(t, q)]
        })
        .collect();
    Scene {
        name: name.to_string(),
        bodies: vec![body("a", &mesh, true), body("b", &mesh, false)],
        frames,
    }
}

/// The generated scenes of `cargo xtask verify` (sizes chosen so the brute-force oracle stays
/// quick).
pub fn verify_set() -> Vec<Scene> {
    vec![
        icospheres_sweep(4, 40),
        torus_knots(256, 10, 40),
        meshing_gears(40),
        wheelset_on_rails(40),
        sparse(1000, 12, 1),
    ]
}

/// Two (2,3) torus knots of `2 · tubular · radial` triangles (1040 × 24: 49,920) in near
/// contact: B is A lifted by about one tube diameter, so the tubes graze where the knot climbs,
/// and turned by small rotations (±2 mrad about changing axes through the centre) every step.
pub fn torus_knots(tubular: u32, radial: u32, steps: usize) -> Scene {
    torus_knots_lifted(tubular, radial, steps, 1.36)
}

/// [`torus_knots`] with B lifted by `lift` tube diameters.
pub fn torus_knots_lifted(tubular: u32, radial: u32, steps: usize, lift: f64) -> Scene {
    let params = TorusKnotParams {
        tubular_segments: tubular,
        radial_segments: radial,
        ..TorusKnotParams::default()
    };
    let mesh = Arc::new(torus_knot(&params).expect("valid torus knot parameters"));
    let lift = 2.0 * params.tube_radius * lift;
    let mut rng = Rng::new(0x7075);
    let frames = (0..steps)
        .map(|k| {
            let s = k as f64;
            let wobble = DQuat::from_axis_angle(rng.unit(), 0.008 * (0.3 * s).sin())
                * DQuat::from_rotation_z(0.01 * (0.05 * s).sin());
            vec![
                Pose::IDENTITY,
                Pose::new(DVec3::new(0.0, 0.0, lift), wobble),
            ]
        })
        .collect();
    Scene {
        name: format!("torus_knots_{}", mesh.triangle_count()),
        bodies: vec![body("knot_a", &mesh, true), body("knot_b", &mesh, false)],
        frames,
    }
}

/// Near contact, non-convex: [`torus_knots`] lifted to 1.42 tube diameters, so that about half
/// the steps (292 of 500) are disjoint and the rest graze: the class where proving
/// disjointness takes a deep traversal.
pub fn knots_near_contact(steps: usize) -> Scene {
    let mut s = torus_knots_lifted(1040, 24, steps, 1.42);
    s.name = format!("knots_near_{}", s.bodies[0].mesh.triangle_count());
    s
}

/// Slow coherent motion: the two knots of [`torus_knots`] (lift 1.40, grazing in places)
/// with B turning steadily about z by 0.1 mrad and drifting 10 µm per step: the motion a
/// coherence cache is for.
pub fn knots_slow_rotation(steps: usize) -> Scene {
    let params = TorusKnotParams {
        tubular_segments: 1040,
        radial_segments: 24,
        ..TorusKnotParams::default()
    };
    let mesh = Arc::new(torus_knot(&params).expect("valid torus knot parameters"));
    let lift = 2.0 * params.tube_radius * 1.40;
    let frames = (0..steps)
        .map(|k| {
            let s = k as f64;
            vec![
                Pose::IDENTITY,
                Pose::new(
                    DVec3::new(1e-5 * s, 0.0, lift),
                    DQuat::from_rotation_z(1e-4 * s),
                ),
            ]
        })
        .collect();
    Scene {
        name: format!("knots_slow_{}", mesh.triangle_count()),
        bodies: vec![body("knot_a", &mesh, true), body("knot_b", &mesh, false)],
        frames,
    }
}

/// Two meshes at random relative rotations, B placed along a random direction from A at
/// `contact · (1 + u)`, `u` uniform in `±spread`, where `contact` is the offset of first
/// contact along that direction (found by the caller's `touches` bisection): incoherent poses
/// near first contact, about half of them touching.
pub fn random_near_contact(
    name: &str,
    a: Arc<TriMesh>,
    b: Arc<TriMesh>,
    steps: usize,
    spread: f64,
    seed: u64,
    mut touches: impl FnMut(&Pose) -> bool,
) -> Scene {
    let ca = a.aabb().center();
    let cb = b.aabb().center();
    let reach = (a.aabb().max - a.aabb().min).length() + (b.aabb().max - b.aabb().min).length();
    let mut rng = Rng::new(seed);
    let mut frames = Vec::with_capacity(steps);
    while frames.len() < steps {
        let q = rng.rotation();
        let d = rng.unit();
        let pose = |s: f64| Pose::new(ca + d * s - q * cb, q);
        // Bisection on the offset between touching (lo) and apart (hi).
        let (mut lo, mut hi) = (0.0, reach);
        if !touches(&pose(lo)) || touches(&pose(hi)) {
            continue;
        }
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            if touches(&pose(mid)) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let u = rng.range(-spread, spread);
        frames.push(vec![Pose::IDENTITY, pose(hi * (1.0 + u))]);
    }
    Scene {
        name: name.to_string(),
        bodies: vec![body("a", &a, false), body("b", &b, false)],
        frames,
    }
}

/// Angle of a tooth centre of a spur gear mesh about z (mod one pitch), from its tip vertices.
fn tooth_phase(mesh: &TriMesh, teeth: u32) -> f64 {
    let rmax = mesh
        .vertices()
        .iter()
        .map(|p| p.truncate().length())
        .fold(0.0, f64::max);
    let (mut c, mut s) = (0.0, 0.0);
    for p in mesh.vertices() {
        if p.truncate().length() > rmax * (1.0 - 1e-9) {
            let a = teeth as f64 * p.y.atan2(p.x);
            c += a.cos();
            s += a.sin();
        }
    }
    s.atan2(c) / teeth as f64
}

/// Two spur gears (20 and 30 teeth, module 10 mm) turning in mesh at a centre distance
/// 0.2 mm short of nominal, so flanks touch and slightly interfere at the pitch point.
pub fn meshing_gears(steps: usize) -> Scene {
    let (za, zb) = (20u32, 30u32);
    let params = |teeth| SpurGearParams {
        teeth,
        ..SpurGearParams::default()
    };
    let pa = params(za);
    let a = Arc::new(spur_gear(&pa).expect("valid gear"));
    let b = Arc::new(spur_gear(&params(zb)).expect("valid gear"));
    let centre = pa.module * (za + zb) as f64 / 2.0 - 0.0002;
    // A: a tooth on +x; B: a gap facing -x.
    let phase_a = -tooth_phase(&a, za);
    let pitch_b = std::f64::consts::TAU / zb as f64;
    let phase_b = std::f64::consts::PI - (tooth_phase(&b, zb) + 0.5 * pitch_b);
    let frames = (0..steps)
        .map(|k| {
            let theta = 0.01 * k as f64;
            vec![
                Pose::new(DVec3::ZERO, DQuat::from_rotation_z(phase_a + theta)),
                Pose::new(
                    DVec3::new(centre, 0.0, 0.0),
                    DQuat::from_rotation_z(phase_b - theta * za as f64 / zb as f64),
                ),
            ]
        })
        .collect();
    Scene {
        name: "meshing_gears".to_string(),
        bodies: vec![body("gear_20", &a, false), body("gear_30", &b, false)],
        frames,
    }
}

/// A wheelset rolling along two straight 4 m rails (static), hunting laterally by ±4 mm and
/// bouncing vertically by ±0.3 mm about the nominal tape-circle-on-rail-crown position: contact
/// on the treads, sometimes the flanges, sometimes lifted clear.
pub fn wheelset_on_rails(steps: usize) -> Scene {
    let wp = WheelsetParams::default();
    let ws = Arc::new(wheelset(&wp).expect("valid wheelset"));
    let r = Arc::new(
        rail(&RailParams {
            path: RailPath::Straight { length: 4.0 },
            segments: 8,
        })
        .expect("valid rail"),
    );
    let tape_y = wp.back_to_back / 2.0 + wp.wheel.tape_offset;
    let crown = 0.172;
    let rail_z = -wp.wheel.tread_radius - crown;
    let frames = (0..steps)
        .map(|k| {
            let s = k as f64;
            let x = -1.0 + 2.0 * s / steps.max(1) as f64;
            let roll = DQuat::from_rotation_y(x / wp.wheel.tread_radius);
            let yaw = DQuat::from_rotation_z(0.002 * (0.4 * s).cos());
            vec![
                Pose::new(
                    DVec3::new(x, 0.004 * (0.4 * s).sin(), 0.0003 * (1.3 * s).sin()),
                    yaw * roll,
                ),
                Pose::from_translation(DVec3::new(-2.0, -tape_y, rail_z)),
                Pose::from_translation(DVec3::new(-2.0, tape_y, rail_z)),
            ]
        })
        .collect();
    Scene {
        name: "wheelset_on_rails".to_string(),
        bodies: vec![
            body("wheelset", &ws, false),
            body("rail_right", &r, true),
            body("rail_left", &r, true),
        ],
        frames,
    }
}
