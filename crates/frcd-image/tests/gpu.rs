//! GPU tests of the image-space detector, with analytic answers. They run on whatever adapter
//! wgpu finds (Mesa's lavapipe on a machine without a GPU); with no adapter they print SKIP and
//! pass, unless FRCD_REQUIRE_GPU=1, when they fail.

use frcd_geom::{DQuat, DVec2, DVec3, Pose, TriMesh, shapes};
use frcd_image::reference::{agreement, reference_image};
use frcd_image::{ImageDetector, ImageError, ImageMesh, ImageOptions, ImageResult, ImageScratch};
use std::f64::consts::PI;
use std::sync::{Mutex, OnceLock};

fn detector() -> Option<&'static ImageDetector> {
    static DET: OnceLock<Option<ImageDetector>> = OnceLock::new();
    DET.get_or_init(|| {
        let required = std::env::var("FRCD_REQUIRE_GPU").as_deref() == Ok("1");
        match ImageDetector::headless() {
            Ok(d) => {
                eprintln!("frcd-image tests on {}", d.context().adapter_name());
                Some(d)
            }
            // A backend the detector cannot use (GL) is refused at creation, by design: the
            // refusal itself is what `gl_is_refused_at_context_creation` checks.
            Err(e @ ImageError::UnsupportedBackend { .. }) => {
                eprintln!("SKIP frcd-image GPU tests (refused, typed): {e}");
                None
            }
            Err(e) if !required => {
                eprintln!("SKIP frcd-image GPU tests: {e}");
                None
            }
            Err(e) => panic!("FRCD_REQUIRE_GPU=1 but no usable adapter: {e}"),
        }
    })
    .as_ref()
}

/// Runs `f` with the detector and a scratch, or prints SKIP. One GPU test at a time: lavapipe
/// already uses every core.
fn with_gpu(name: &str, f: impl FnOnce(&ImageDetector, &mut ImageScratch)) {
    static LOCK: Mutex<()> = Mutex::new(());
    let Some(det) = detector() else {
        println!("SKIP {name}: no GPU adapter");
        return;
    };
    let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    f(det, &mut ImageScratch::default());
}

fn opts(resolution: u32) -> ImageOptions {
    ImageOptions {
        resolution,
        ..Default::default()
    }
}

/// Volume of the intersection of balls of radii r1, r2 with centres `d` apart.
fn lens(r1: f64, r2: f64, d: f64) -> f64 {
    if d >= r1 + r2 {
        return 0.0;
    }
    if d + r1.min(r2) <= r1.max(r2) {
        return 4.0 / 3.0 * PI * r1.min(r2).powi(3);
    }
    PI * (r1 + r2 - d).powi(2)
        * (d * d + 2.0 * d * r2 - 3.0 * r2 * r2 + 2.0 * d * r1 + 6.0 * r1 * r2 - 3.0 * r1 * r1)
        / (12.0 * d)
}

/// Distance from the origin to the nearest face plane (the inscribed ball's radius).
fn inradius(m: &TriMesh) -> f64 {
    m.triangles()
        .map(|t| t.normal().normalize().dot(t.v[0]).abs())
        .fold(f64::INFINITY, f64::min)
}

/// Every pixel where the GPU differs from the f64 reference must be explained by the bounds, and
/// lengths must agree to a few depth bounds elsewhere.
fn check_reference(r: &ImageResult, a: &ImageMesh, b: &ImageMesh, rel: &Pose) {
    let view = r.view.as_ref().expect("boxes overlap");
    let reference = reference_image(view, &r.bounds, a.mesh(), &Pose::IDENTITY, b.mesh(), rel);
    let ag = agreement(r, &reference);
    println!("    reference: {ag:?}");
    assert_eq!(
        ag.unexplained, 0,
        "pixels where the GPU differs from the f64 reference without explanation: {ag:?}"
    );
    assert_eq!(
        ag.length_violations, 0,
        "pixel lengths differ from the reference beyond their tolerance: {ag:?}"
    );
    // The volume is Σ length × pixel area, so it may differ from the reference's by the sum of
    // the per-pixel tolerances checked above. A real GPU uses that room: on an H200 every length
    // was within its tolerance (largest error 5.6e-5) but the errors leaned one way, 7.4e-4 of
    // the volume, past the 1e-4 that lavapipe had always met.
    let slack = 4.0 * r.bounds.depth;
    let length_room: f64 = (0..reference.mask.len())
        .filter(|&i| reference.mask[i] && r.image.mask[i] && !reference.ambiguous[i])
        .map(|i| reference.tolerance[i] + slack)
        .sum();
    let rv = reference.volume(view);
    let room = 1e-4 * rv.max(1e-30) + (length_room + ag.explained as f64 * 4.0) * view.pixel_area();
    assert!(
        (rv - r.volume).abs() <= room,
        "volume {} vs reference {rv}, room {room:e} ({ag:?})",
        r.volume
    );
}

#[test]
fn sphere_lens_volume_matches_analytic_over_resolutions() {
    with_gpu("sphere_lens", |det, scratch| {
        let mesh = shapes::icosphere(1.0, 4);
        let (r_out, r_in) = (1.0, inradius(&mesh));
        let a = det.upload("a", &mesh).unwrap();
        let b = det.upload("b", &mesh).unwrap();
        // Along an axis (view along the centre line) and along a diagonal (resolution matters).
        for dir in [DVec3::X, DVec3::new(1.0, 1.0, 1.0).normalize()] {
            for dist in [1.2, 1.7] {
                let pose_b = Pose::from_translation(dir * dist);
                for res in [64, 256] {
                    let r = det
                        .query(scratch, &a, &Pose::IDENTITY, &b, &pose_b, &opts(res))
                        .unwrap();
                    let (lo, hi) = (lens(r_in, r_in, dist), lens(r_out, r_out, dist));
                    println!(
                        "dir {dir:?} dist {dist} res {res}: volume {:.6} in [{lo:.6}, {hi:.6}] ± {:.2e}, {} px, layers {:?}",
                        r.volume, r.volume_error_estimate, r.interfering_pixels, r.layers
                    );
                    assert!(r.collide);
                    assert!(
                        r.volume >= lo - r.volume_error_estimate
                            && r.volume <= hi + r.volume_error_estimate,
                        "volume {} outside [{lo}, {hi}] ± {}",
                        r.volume,
                        r.volume_error_estimate
                    );
                    check_reference(&r, &a, &b, &pose_b);
                }
            }
        }
    });
}

#[test]
fn box_overlaps_match_analytic() {
    with_gpu("box_overlaps", |det, scratch| {
        let ha = DVec3::new(1.0, 2.0, 3.0);
        let hb = DVec3::new(1.5, 1.0, 0.5);
        let a = det.upload("a", &shapes::cuboid(ha)).unwrap();
        let b = det.upload("b", &shapes::cuboid(hb)).unwrap();
        for t in [
            DVec3::new(1.8, 0.5, -0.2),
            DVec3::new(-0.3, 2.7, 3.1),
            DVec3::new(2.4999, 0.0, 0.0), // 1e-4 deep: thin, seen along x, in depth
        ] {
            let overlap = |i: usize| {
                ((ha[i] + hb[i]) - t[i].abs())
                    .min(2.0 * ha[i])
                    .min(2.0 * hb[i])
                    .max(0.0)
            };
            let exact = overlap(0) * overlap(1) * overlap(2);
            for res in [64, 512] {
                let pose_b = Pose::from_translation(t);
                let r = det
                    .query(scratch, &a, &Pose::IDENTITY, &b, &pose_b, &opts(res))
                    .unwrap();
                println!(
                    "t {t:?} res {res}: volume {:.8} exact {exact:.8} ± {:.2e}",
                    r.volume, r.volume_error_estimate
                );
                assert!(r.collide);
                assert!(
                    (r.volume - exact).abs() <= r.volume_error_estimate + 1e-5 * exact,
                    "volume {} vs exact {exact} ± {}",
                    r.volume,
                    r.volume_error_estimate
                );
                check_reference(&r, &a, &b, &pose_b);
            }
        }
    });
}

/// Area of the intersection of two convex polygons (counter-clockwise), Sutherland–Hodgman.
fn clip_area(subject: &[DVec2], clip: &[DVec2]) -> f64 {
    let mut poly = subject.to_vec();
    for k in 0..clip.len() {
        let (p, q) = (clip[k], clip[(k + 1) % clip.len()]);
        let side = |x: DVec2| (q - p).perp_dot(x - p);
        let input = std::mem::take(&mut poly);
        for i in 0..input.len() {
            let (c, n) = (input[i], input[(i + 1) % input.len()]);
            let (sc, sn) = (side(c), side(n));
            if sc >= 0.0 {
                poly.push(c);
            }
            if (sc >= 0.0) != (sn >= 0.0) {
                poly.push(c + (n - c) * (sc / (sc - sn)));
            }
        }
    }
    0.5 * (0..poly.len())
        .map(|i| poly[i].perp_dot(poly[(i + 1) % poly.len()]))
        .sum::<f64>()
}

#[test]
fn rotated_box_overlap_matches_analytic() {
    with_gpu("rotated_box", |det, scratch| {
        let a = det.upload("a", &shapes::cuboid(DVec3::ONE)).unwrap();
        let b = det
            .upload("b", &shapes::cuboid(DVec3::new(1.0, 1.0, 0.5)))
            .unwrap();
        let angle = 0.5;
        let t = DVec3::new(1.2, 0.3, 0.4);
        let pose_b = Pose::new(t, DQuat::from_rotation_z(angle));
        let square = |c: DVec2, rot: f64| -> Vec<DVec2> {
            [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
                .iter()
                .map(|&(x, y)| c + DVec2::from_angle(rot).rotate(DVec2::new(x, y)))
                .collect()
        };
        let area = clip_area(&square(DVec2::ZERO, 0.0), &square(t.truncate(), angle));
        let exact = area * (1.0f64.min(t.z + 0.5) - (-1.0f64).max(t.z - 0.5));
        let mut last_err = f64::INFINITY;
        for res in [64, 256, 1024] {
            let r = det
                .query(scratch, &a, &Pose::IDENTITY, &b, &pose_b, &opts(res))
                .unwrap();
            let err = (r.volume - exact).abs();
            println!(
                "res {res}: volume {:.6} exact {exact:.6} error {err:.2e} estimate {:.2e}",
                r.volume, r.volume_error_estimate
            );
            assert!(
                err <= r.volume_error_estimate,
                "{err} > {}",
                r.volume_error_estimate
            );
            assert!(
                err <= last_err * 1.5 + 1e-9,
                "error does not shrink with resolution"
            );
            last_err = err;
            check_reference(&r, &a, &b, &pose_b);
        }
    });
}

#[test]
fn containment_is_detected_with_the_inner_volume() {
    with_gpu("containment", |det, scratch| {
        let outer = det.upload("outer", &shapes::icosphere(1.0, 3)).unwrap();
        let small = shapes::icosphere(0.3, 3);
        let exact = small.signed_volume();
        let inner = det.upload("inner", &small).unwrap();
        let pose = Pose::new(DVec3::new(0.2, -0.1, 0.15), DQuat::from_rotation_y(0.3));
        for (a, b) in [(&outer, &inner), (&inner, &outer)] {
            let (pa, pb) = if a.name() == "outer" {
                (Pose::IDENTITY, pose)
            } else {
                (pose, Pose::IDENTITY)
            };
            let r = det.query(scratch, a, &pa, b, &pb, &opts(256)).unwrap();
            println!(
                "{} first: volume {:.6} exact {exact:.6} ± {:.2e}",
                a.name(),
                r.volume,
                r.volume_error_estimate
            );
            assert!(r.collide, "containment not detected");
            assert!((r.volume - exact).abs() <= r.volume_error_estimate);
            check_reference(&r, a, b, &pb.relative_to(&pa));
        }
    });
}

#[test]
fn no_false_positive_beyond_the_separation_bound() {
    with_gpu("separation", |det, scratch| {
        // Spheres on a diagonal (their boxes overlap) separated by a gap just above the bound.
        let mesh = shapes::icosphere(1.0, 4);
        let a = det.upload("a", &mesh).unwrap();
        let b = det.upload("b", &mesh).unwrap();
        let dir = DVec3::new(1.0, 1.0, 1.0).normalize();
        for res in [64, 512, 2048] {
            // Circumradius 1: centres 2 + gap apart are at least `gap` apart.
            let probe = det
                .query(
                    scratch,
                    &a,
                    &Pose::IDENTITY,
                    &b,
                    &Pose::from_translation(dir * 2.0),
                    &opts(res),
                )
                .unwrap();
            let gap = 1.01 * probe.bounds.separation;
            let r = det
                .query(
                    scratch,
                    &a,
                    &Pose::IDENTITY,
                    &b,
                    &Pose::from_translation(dir * (2.0 + gap)),
                    &opts(res),
                )
                .unwrap();
            println!("res {res}: gap {gap:.3e} → collide {}", r.collide);
            assert!(
                r.view.is_some(),
                "boxes must overlap for this test to mean anything"
            );
            assert!(!r.collide, "false positive at gap {gap} > bound");
        }
        // A cube turned 45° about z beside A's vertical edge x = y = 1, a gap away on the
        // diagonal: the boxes overlap, the solids do not.
        let cube = det.upload("cube", &shapes::cuboid(DVec3::ONE)).unwrap();
        let rot = DQuat::from_rotation_z(PI / 4.0);
        let at = |g: f64| {
            let c = 1.0 + std::f64::consts::FRAC_1_SQRT_2 * (1.0 + g);
            Pose::new(DVec3::new(c, c, 0.3), rot)
        };
        for res in [64, 1024] {
            let probe = det
                .query(scratch, &cube, &Pose::IDENTITY, &cube, &at(0.0), &opts(res))
                .unwrap();
            assert!(probe.view.is_some());
            let gap = 1.01 * probe.bounds.separation;
            let r = det
                .query(scratch, &cube, &Pose::IDENTITY, &cube, &at(gap), &opts(res))
                .unwrap();
            assert!(r.view.is_some(), "boxes must overlap");
            assert!(!r.collide, "false positive: edge {gap} from the face");
            check_reference(&r, &cube, &cube, &at(gap));
            // Pressed in by far more than a pixel: found, and in agreement with the reference.
            let deep = 4.0 * r.bounds.pixel_size;
            let r = det
                .query(
                    scratch,
                    &cube,
                    &Pose::IDENTITY,
                    &cube,
                    &at(-deep),
                    &opts(res),
                )
                .unwrap();
            println!(
                "edge res {res}: gap {gap:.2e} clear; pressed {deep:.2e}: {} px",
                r.interfering_pixels
            );
            assert!(r.collide);
            check_reference(&r, &cube, &cube, &at(-deep));
        }
    });
}

#[test]
fn penetration_holding_the_detection_ball_is_always_found() {
    with_gpu("detection_radius", |det, scratch| {
        // Icospheres contain their inscribed balls, so centres 2·r_in − d apart give a lens that
        // holds a ball of radius d/2. Diagonal approach: the overlap box is far larger than the
        // lens, so this is the resolution-limited case.
        let mesh = shapes::icosphere(1.0, 4);
        let r_in = inradius(&mesh);
        let a = det.upload("a", &mesh).unwrap();
        let dir = DVec3::new(1.0, 1.0, 1.0).normalize();
        for res in [64, 512] {
            let mut d = 0.1;
            // The bounds depend on the view, which depends on d: iterate to a fixed point.
            for _ in 0..4 {
                let probe = det
                    .query(
                        scratch,
                        &a,
                        &Pose::IDENTITY,
                        &a,
                        &Pose::from_translation(dir * (2.0 * r_in - d)),
                        &opts(res),
                    )
                    .unwrap();
                d = 2.0 * probe.bounds.detection_radius * 1.01;
            }
            let pose_b = Pose::from_translation(dir * (2.0 * r_in - d));
            let r = det
                .query(scratch, &a, &Pose::IDENTITY, &a, &pose_b, &opts(res))
                .unwrap();
            println!(
                "res {res}: penetration {d:.3e} (pixel {:.2e}) → {} px",
                r.bounds.pixel_size, r.interfering_pixels
            );
            assert!(d / 2.0 >= r.bounds.detection_radius);
            assert!(
                r.collide,
                "a ball of radius {} inside A ∩ B was missed",
                d / 2.0
            );
            check_reference(&r, &a, &a, &pose_b);
        }
    });
}

#[test]
fn shallow_flat_penetration_is_measured_in_depth() {
    with_gpu("shallow", |det, scratch| {
        let a = det.upload("a", &shapes::cuboid(DVec3::ONE)).unwrap();
        for d in [1e-3, 1e-5] {
            let pose_b = Pose::from_translation(DVec3::new(0.3, 0.2, 2.0 - d));
            let r = det
                .query(scratch, &a, &Pose::IDENTITY, &a, &pose_b, &opts(64))
                .unwrap();
            let exact = 1.7 * 1.8 * d;
            println!("d {d:e}: volume {:.4e} exact {exact:.4e}", r.volume);
            assert_eq!(r.view.as_ref().unwrap().axis, 2, "view along the thin axis");
            assert!(r.collide);
            assert!((r.volume - exact).abs() <= r.volume_error_estimate);
        }
    });
}

#[test]
fn world_offset_and_frame_do_not_change_the_answer() {
    with_gpu("offset", |det, scratch| {
        let mesh = shapes::icosphere(1.0, 3);
        let a = det.upload("a", &mesh).unwrap();
        let b = det.upload("b", &mesh).unwrap();
        let rel = Pose::new(DVec3::new(1.1, 0.4, -0.3), DQuat::from_rotation_x(0.7));
        let base = det
            .query(scratch, &a, &Pose::IDENTITY, &b, &rel, &opts(128))
            .unwrap();
        let far = Pose::new(DVec3::new(1e6, -2e6, 3e5), DQuat::from_rotation_z(1.1));
        let moved = det
            .query(scratch, &a, &far, &b, &far.compose(&rel), &opts(128))
            .unwrap();
        assert!(base.collide && moved.collide);
        assert_eq!(base.image.width, moved.image.width);
        assert!(
            (base.volume - moved.volume).abs() <= 1e-6 * base.volume + 16.0 * base.bounds.depth,
            "{} vs {}",
            base.volume,
            moved.volume
        );
    });
}

#[test]
fn colliding_set_covers_the_interference() {
    with_gpu("acs", |det, scratch| {
        let mesh = shapes::icosphere(1.0, 3);
        let a = det.upload("a", &mesh).unwrap();
        let b = det.upload("b", &mesh).unwrap();
        for (c, res) in [
            (DVec3::new(1.3, 0.2, 0.1), 128),
            (DVec3::new(1.0, 1.0, 1.0).normalize() * 1.9, 64),
            (DVec3::new(0.3, -1.7, 0.5), 256),
        ] {
            let pose_b = Pose::from_translation(c);
            let o = ImageOptions {
                resolution: res,
                colliding_set: true,
                ..Default::default()
            };
            let r = det
                .query(scratch, &a, &Pose::IDENTITY, &b, &pose_b, &o)
                .unwrap();
            let acs = r.colliding_set.as_ref().unwrap();
            let view = r.view.as_ref().unwrap();
            println!(
                "ACS: {} of {} A triangles, {} B triangles",
                acs.tris_a.len(),
                mesh.triangle_count(),
                acs.tris_b.len()
            );
            assert!(!acs.tris_a.is_empty() && !acs.tris_b.is_empty());
            assert!(acs.tris_a.len() < mesh.triangle_count() / 2);
            for ids in [&acs.tris_a, &acs.tris_b] {
                assert!(ids.windows(2).all(|w| w[0] < w[1]), "ascending, unique");
            }
            // Every A triangle whose centroid is inside B's inscribed ball by a few pixels crosses an
            // interfering pixel: it must be in the set (and the same for B inside A).
            let r_in = inradius(&mesh);
            let margin = 3.0 * view.pixel_size;
            for (t, tri) in mesh.triangles().enumerate() {
                if (tri.centroid() - c).length() < r_in - margin {
                    assert!(
                        acs.tris_a.binary_search(&(t as u32)).is_ok(),
                        "A triangle {t} missing"
                    );
                }
                if (tri.centroid() + c).length() < r_in - margin {
                    assert!(
                        acs.tris_b.binary_search(&(t as u32)).is_ok(),
                        "B triangle {t} missing"
                    );
                }
            }
            // Against the exact oracle: every pair of triangles that touch (exact predicates,
            // brute force) has both triangles in the set.
            let tb: Vec<_> = mesh.triangles().map(|t| t.transformed(&pose_b)).collect();
            let mut touching = 0;
            for (i, ta) in mesh.triangles().enumerate() {
                for (j, tb) in tb.iter().enumerate() {
                    if frcd_tritri::exact(&ta, tb) {
                        touching += 1;
                        assert!(
                            acs.tris_a.binary_search(&(i as u32)).is_ok(),
                            "A {i} (touches B {j}) missing"
                        );
                        assert!(
                            acs.tris_b.binary_search(&(j as u32)).is_ok(),
                            "B {j} (touches A {i}) missing"
                        );
                    }
                }
            }
            println!("{touching} touching triangle pairs, all covered");
            assert!(touching > 0);
            // And nothing outside the region.
            for &t in &acs.tris_a {
                let bb = mesh.triangle(t as usize).aabb();
                assert!(
                    bb.intersects(&view.region.inflated(r.bounds.separation + view.pixel_size))
                );
            }
        }
    });
}

#[test]
fn disjoint_boxes_answer_without_gpu_work_and_errors_are_typed() {
    with_gpu("errors", |det, scratch| {
        let a = det.upload("a", &shapes::cuboid(DVec3::ONE)).unwrap();
        let r = det
            .query(
                scratch,
                &a,
                &Pose::IDENTITY,
                &a,
                &Pose::from_translation(DVec3::new(2.001, 0.0, 0.0)),
                &opts(64),
            )
            .unwrap();
        assert!(!r.collide && r.view.is_none());
        let bad = Pose {
            translation: DVec3::new(f64::NAN, 0.0, 0.0),
            rotation: DQuat::IDENTITY,
        };
        assert!(matches!(
            det.query(scratch, &a, &Pose::IDENTITY, &a, &bad, &opts(64)),
            Err(ImageError::InvalidPose {
                which: frcd_image::Which::B
            })
        ));
        assert!(matches!(
            det.query(scratch, &a, &Pose::IDENTITY, &a, &Pose::IDENTITY, &opts(0)),
            Err(ImageError::Resolution { .. })
        ));
        let huge = ImageOptions {
            resolution: 1 << 20,
            ..Default::default()
        };
        assert!(matches!(
            det.query(scratch, &a, &Pose::IDENTITY, &a, &Pose::IDENTITY, &huge),
            Err(ImageError::Resolution { .. })
        ));
        let few = ImageOptions {
            max_layers: 1,
            ..opts(64)
        };
        assert!(matches!(
            det.query(
                scratch,
                &a,
                &Pose::IDENTITY,
                &a,
                &Pose::from_translation(DVec3::X),
                &few
            ),
            Err(ImageError::TooManyLayers { max_layers: 1, .. })
        ));
        let other = ImageDetector::new(det.context().clone()).unwrap();
        let foreign = other.upload("f", &shapes::cuboid(DVec3::ONE)).unwrap();
        assert!(matches!(
            det.query(
                scratch,
                &a,
                &Pose::IDENTITY,
                &foreign,
                &Pose::IDENTITY,
                &opts(64)
            ),
            Err(ImageError::ForeignMesh {
                which: frcd_image::Which::B
            })
        ));
        let open = TriMesh::new(
            shapes::cuboid(DVec3::ONE).vertices().to_vec(),
            shapes::cuboid(DVec3::ONE).indices()[1..].to_vec(),
        )
        .unwrap();
        assert!(matches!(
            det.upload("open", &open),
            Err(ImageError::NotSolid { .. })
        ));
    });
}

/// Issue 11: wgpu's GL backend cannot run the detector (GLSL has no depth `textureLoad`); it is
/// refused with a typed error when the context is made, never later and never with an answer.
/// Vulkan (lavapipe here) is accepted. Runs on whichever of the two the machine has.
#[test]
fn gl_is_refused_at_context_creation() {
    for backends in [wgpu::Backends::GL, wgpu::Backends::VULKAN] {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = backends;
        match frcd_image::ImageContext::headless_with(desc) {
            Err(ImageError::NoAdapter(e)) => println!("SKIP {backends:?}: {e}"),
            Err(ImageError::UnsupportedBackend { backend, .. }) => {
                assert_eq!(backend, wgpu::Backend::Gl);
                assert_eq!(backends, wgpu::Backends::GL);
            }
            Err(e) => panic!("{backends:?}: unexpected error {e}"),
            Ok(ctx) => {
                assert_ne!(backends, wgpu::Backends::GL, "GL must be refused");
                // And it works: a real query on the accepted backend.
                let det = ImageDetector::new(ctx).expect("pipelines");
                let a = det.upload("a", &shapes::cuboid(DVec3::splat(0.5))).unwrap();
                let r = det
                    .query(
                        &mut ImageScratch::default(),
                        &a,
                        &Pose::IDENTITY,
                        &a,
                        &Pose::from_translation(DVec3::new(0.5, 0.1, 0.0)),
                        &opts(64),
                    )
                    .unwrap();
                assert!(
                    r.collide && r.volume > 0.3 && r.volume < 0.7,
                    "{}",
                    r.volume
                );
            }
        }
    }
}

/// Issue 10 item 3: targets allocated once per resolution, whatever the overlap's aspect ratio
/// (it changes with every pose), and the answers stay right in the reused targets.
#[test]
fn targets_are_allocated_once_per_resolution() {
    with_gpu(
        "targets_are_allocated_once_per_resolution",
        |det, scratch| {
            let a = det
                .upload("a", &shapes::cuboid(DVec3::new(1.0, 0.5, 0.25)))
                .unwrap();
            let b = det.upload("b", &shapes::cuboid(DVec3::splat(0.5))).unwrap();
            let mut volumes = Vec::new();
            for (k, dx) in [0.2, 0.9, 1.3, 0.5, 1.1].into_iter().enumerate() {
                let pb = Pose::new(DVec3::new(dx, 0.3 * k as f64 / 4.0, 0.1), DQuat::IDENTITY);
                let r = det
                    .query(scratch, &a, &Pose::IDENTITY, &b, &pb, &opts(128))
                    .unwrap();
                let view = r.view.expect("boxes overlap");
                assert!(view.width <= 128 && view.height <= 128);
                // Exact overlap volume of two axis-aligned boxes.
                let ov =
                    |lo1: f64, hi1: f64, lo2: f64, hi2: f64| (hi1.min(hi2) - lo1.max(lo2)).max(0.0);
                let want = ov(-1.0, 1.0, dx - 0.5, dx + 0.5)
                    * ov(-0.5, 0.5, pb.translation.y - 0.5, pb.translation.y + 0.5)
                    * ov(-0.25, 0.25, -0.4, 0.6);
                assert!(
                    (r.volume - want).abs() <= 0.03 * want + 1e-3,
                    "{k}: {} vs {want}",
                    r.volume
                );
                volumes.push((view.width, view.height));
            }
            assert!(
                volumes.windows(2).any(|w| w[0] != w[1]),
                "aspect ratios must vary: {volumes:?}"
            );
            assert_eq!(scratch.allocations(), 1);
            assert_eq!(scratch.capacity(), Some((128, 128)));
        },
    );
}

/// Detectors created, used and dropped on several threads at once (creation and drops are
/// serialised by `frcd_gpu::creation_lock`; NVIDIA's driver hung without it): each thread gets
/// the same answer as the shared detector, and nothing deadlocks.
#[test]
fn detectors_created_and_dropped_on_many_threads() {
    let Some(shared) = detector() else {
        println!("SKIP detectors_created_and_dropped_on_many_threads: no GPU adapter");
        return;
    };
    let mesh = shapes::icosphere(1.0, 2);
    let pose_b = Pose::from_translation(DVec3::new(1.3, 0.2, 0.1));
    // Interfering pixels and volume of the mesh against itself at `pose_b`, on `det`.
    let answer = |det: &ImageDetector| {
        let a = det.upload("a", &mesh).unwrap();
        let r = det
            .query(
                &mut ImageScratch::default(),
                &a,
                &Pose::IDENTITY,
                &a,
                &pose_b,
                &opts(64),
            )
            .unwrap();
        (r.interfering_pixels, r.volume)
    };
    let want = answer(shared);
    assert!(want.0 > 0);
    std::thread::scope(|scope| {
        for _ in 0..3 {
            scope.spawn(|| {
                for _ in 0..2 {
                    let det = ImageDetector::headless().expect("an adapter was found above");
                    assert_eq!(answer(&det), want);
                    drop(det);
                }
            });
        }
    });
}
