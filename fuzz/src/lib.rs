//! The bodies of the fuzz targets, as plain functions: each takes the fuzzer's bytes, returns
//! normally on any input the library must accept or refuse with a typed error, and panics
//! (assertion) only when a library invariant is broken.
//!
//! The cargo-fuzz targets in `fuzz_targets/` are one line each (`fuzz_target!` calling the
//! function of the same name). The stable smoke test `xtask/tests/fuzz_smoke.rs` includes this
//! file with `#[path]` (the fuzz crate is not a workspace member: it needs nightly) and replays
//! every committed seed and regression input plus deterministic mutations of them through the
//! same functions. This file must therefore build on stable and depend only on crates both
//! places have: frcd-geom (feature `shapes`), frcd-obb, frcd-io, serde_json.

use frcd_geom::{DQuat, DVec3, Pose, TriMesh, shapes};
use frcd_obb::{
    BodyId, BuildOptions, FitMethod, Mode, ObbTree, PairCache, Request, SplitMethod, World,
    WorldOptions, collide, collide_cached, oracle, overlapping_boxes,
};
use std::path::Path;
use std::sync::Arc;

/// A target's body: the fuzzer's bytes in, a panic only on a broken invariant.
pub type Body = fn(&[u8]);

/// The targets, by name, with their bodies (in the order `cargo xtask fuzz` runs them: cheap
/// parsers first).
pub const TARGETS: [(&str, Body); 7] = [
    ("stl", stl),
    ("obj", obj),
    ("scene", scene),
    ("trajectory", trajectory),
    ("mesh_tree", mesh_tree),
    ("collide_oracle", collide_oracle),
    ("world_broad", world_broad),
];

/// STL reader (ASCII and binary): any bytes give a mesh or a typed error, never a panic.
pub fn stl(data: &[u8]) {
    if let Ok(mesh) = frcd_io::parse_stl(data, Path::new("fuzz.stl")) {
        // A loaded mesh is valid: every index in range, every coordinate finite.
        assert!(mesh.triangle_count() > 0);
        assert!(mesh.vertices().iter().all(|v| v.is_finite()));
        let n = mesh.vertex_count() as u32;
        assert!(mesh.indices().iter().flatten().all(|&i| i < n));
    }
}

/// OBJ reader (one mesh and per-object): any bytes give meshes or a typed error.
pub fn obj(data: &[u8]) {
    let path = Path::new("fuzz.obj");
    let one = frcd_io::parse_obj(data, path);
    let per_object = frcd_io::parse_obj_objects(data, path);
    if let Ok(mesh) = &one {
        assert!(mesh.vertices().iter().all(|v| v.is_finite()));
        let n = mesh.vertex_count() as u32;
        assert!(mesh.indices().iter().flatten().all(|&i| i < n));
    }
    // Both readers see the same faces: when the per-object reader succeeds, so does the
    // merged one, with as many triangles in total.
    if let Ok(objects) = &per_object {
        let total: usize = objects.iter().map(|o| o.mesh.triangle_count()).sum();
        let merged = one
            .as_ref()
            .expect("per-object read succeeded, merged read failed");
        assert_eq!(merged.triangle_count(), total);
    }
}

/// Scene file parser: any text gives a SceneFile or a typed error naming a line; a parsed scene
/// writes back to JSON that parses to the same value.
pub fn scene(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let path = Path::new("fuzz.json");
    if let Ok(spec) = frcd_io::SceneFile::parse(text, path) {
        let again = serde_json::to_string(&spec).expect("a parsed scene serialises");
        let back = frcd_io::SceneFile::parse(&again, path).expect("written scene parses");
        assert_eq!(
            serde_json::to_value(&back).unwrap(),
            serde_json::to_value(&spec).unwrap()
        );
    }
}

/// Trajectory CSV parser: any bytes give rows or a typed error naming a line; every row's pose
/// is valid and its line lies in the file.
pub fn trajectory(data: &[u8]) {
    let path = Path::new("fuzz.csv");
    if let Ok(t) = frcd_io::Trajectory::parse(data, path) {
        let lines = 1 + data.iter().filter(|&&b| b == b'\n').count();
        for r in &t.rows {
            assert!(
                r.pose.is_valid(),
                "row at line {} has an invalid pose",
                r.line
            );
            assert!(r.line >= 1 && r.line <= lines, "line {} of {lines}", r.line);
            assert!(!r.body.is_empty());
        }
    }
}

/// `TriMesh::new` on raw vertices and indices (NaN, infinities, huge and subnormal coordinates,
/// out-of-range indices), then `ObbTree::build` on every mesh it accepts; the tree's
/// self-collision must equal the exact oracle's pairs.
pub fn mesh_tree(data: &[u8]) {
    if data.len() < 2 {
        return;
    }
    let (head, rest) = data.split_at(2);
    let nv = (head[0] % 12) as usize;
    let leaf = 1 + (head[1] % 4) as u32;
    let fit = [
        FitMethod::VertexCovariance,
        FitMethod::AreaWeighted,
        FitMethod::HullSurface,
    ][(head[1] / 4 % 3) as usize];
    let split = [SplitMethod::SurfaceCost, SplitMethod::MajorAxisMean][(head[1] / 12 % 2) as usize];
    let mut words = rest
        .chunks_exact(8)
        .map(|c| u64::from_le_bytes(c.try_into().unwrap()));
    let mut vertices = Vec::with_capacity(nv);
    for _ in 0..nv {
        let mut c = [0.0; 3];
        for x in &mut c {
            *x = f64::from_bits(words.next().unwrap_or(0));
        }
        vertices.push(DVec3::from_array(c));
    }
    let mut indices = Vec::new();
    for w in words {
        // Mostly in range, sometimes not.
        let m = nv as u32 + 1;
        let idx = |s: u32| ((w >> s) as u32 & 0xFF) % m.max(1);
        indices.push([idx(0), idx(8), idx(16)]);
        if indices.len() >= 24 {
            break;
        }
    }
    let Ok(mesh) = TriMesh::new(vertices, indices) else {
        return;
    };
    let _ = mesh.topology();
    let options = BuildOptions {
        fit,
        max_leaf_triangles: leaf,
        split,
    };
    let tree = ObbTree::build(&mesh, &options);
    let request = Request {
        mode: Mode::AllPairs,
        ..Request::default()
    };
    let got = collide(&tree, &Pose::IDENTITY, &tree, &Pose::IDENTITY, &request);
    let want = oracle::pairs(&mesh, &Pose::IDENTITY, &mesh, &Pose::IDENTITY);
    assert_eq!(got.pairs, want, "self-collision differs from the oracle");
}

/// Reads the differential target's input: bytes in order, zeros after the end.
struct Bytes<'a>(&'a [u8]);

impl Bytes<'_> {
    fn byte(&mut self) -> u8 {
        match self.0.split_first() {
            Some((b, rest)) => {
                self.0 = rest;
                *b
            }
            None => 0,
        }
    }
    fn small(&mut self) -> f64 {
        (self.byte() as i8) as f64
    }
}

fn small_mesh(b: &mut Bytes, scale: f64) -> Option<TriMesh> {
    let kind = b.byte();
    if kind.is_multiple_of(4) {
        // A closed box, so containment is exercised.
        let h = DVec3::new(
            1.0 + (b.byte() % 16) as f64,
            1.0 + (b.byte() % 16) as f64,
            1.0 + (b.byte() % 16) as f64,
        ) * scale;
        return Some(shapes::cuboid(h));
    }
    let nv = 3 + (b.byte() % 6) as usize;
    let v: Vec<DVec3> = (0..nv)
        .map(|_| DVec3::new(b.small(), b.small(), b.small()) * scale)
        .collect();
    let nt = 1 + (b.byte() % 8) as usize;
    let t: Vec<[u32; 3]> = (0..nt)
        .map(|_| {
            let mut i = || (b.byte() as usize % nv) as u32;
            [i(), i(), i()]
        })
        .collect();
    TriMesh::new(v, t).ok()
}

fn small_pose(b: &mut Bytes, scale: f64) -> Pose {
    let t = DVec3::new(b.small(), b.small(), b.small()) * scale / 4.0;
    let q = DQuat::from_xyzw(b.small(), b.small(), b.small(), b.small());
    if b.byte().is_multiple_of(2) || q.length_squared() == 0.0 {
        Pose::from_translation(t)
    } else {
        Pose::new(t, q)
    }
}

/// Differential: `collide` (all pairs, solid or surface mode) against `frcd_obb::oracle` on
/// small meshes and poses. Coordinates are small integers scaled by a power of two (so touching,
/// coplanar and degenerate configurations are common), sometimes closed boxes (containment).
/// The two answers must be equal, and `collide_cached` over a short sequence of poses must
/// answer as `collide` does.
pub fn collide_oracle(data: &[u8]) {
    let mut b = Bytes(data);
    let flags = b.byte();
    // 2^-8 .. 2^+990: small, ordinary and huge magnitudes.
    let exp = [-8, 0, 0, 0, 20, 500, 990][(b.byte() % 7) as usize];
    let scale = 2f64.powi(exp) / 4.0;
    let (Some(ma), Some(mb)) = (small_mesh(&mut b, scale), small_mesh(&mut b, scale)) else {
        return;
    };
    let (pa, pb) = (small_pose(&mut b, scale), small_pose(&mut b, scale));
    let solid = flags & 1 == 1;
    let options = BuildOptions {
        max_leaf_triangles: 1 + (flags >> 1) as u32 % 3,
        ..BuildOptions::default()
    };
    let (ta, tb) = (ObbTree::build(&ma, &options), ObbTree::build(&mb, &options));
    let request = Request {
        mode: Mode::AllPairs,
        solid,
        ..Request::default()
    };
    let got = collide(&ta, &pa, &tb, &pb, &request);
    let want = oracle::answer(&ma, &pa, &mb, &pb, solid);
    assert_eq!(got.pairs, want.pairs, "pairs differ");
    assert_eq!(got.contained, want.contained, "containment differs");
    assert_eq!(got.collide, want.collide());
    // First contact agrees on the boolean.
    let first = collide(
        &ta,
        &pa,
        &tb,
        &pb,
        &Request {
            mode: Mode::FirstContact,
            ..request
        },
    );
    assert_eq!(first.collide, want.collide());
    // The coherence cache over a short sequence (B turning by a milliradian a step, then a jump
    // to a second pose and back): every answer equals the uncached query's.
    let jump = small_pose(&mut b, scale);
    let mut caches = [PairCache::new(), PairCache::new()];
    for step in 0..7u32 {
        let pose = if step == 4 {
            jump
        } else {
            Pose::new(
                pb.translation,
                DQuat::from_rotation_z(1e-3 * step as f64) * pb.rotation,
            )
        };
        for (cache, mode) in caches.iter_mut().zip([Mode::AllPairs, Mode::FirstContact]) {
            let r = Request { mode, ..request };
            let plain = collide(&ta, &pa, &tb, &pose, &r);
            let cached = collide_cached(&ta, &pa, &tb, &pose, &r, cache);
            assert_eq!(
                cached.collide, plain.collide,
                "cached answer differs, step {step}"
            );
            if mode == Mode::AllPairs {
                assert_eq!(
                    cached.pairs, plain.pairs,
                    "cached pairs differ, step {step}"
                );
            }
        }
    }
}

/// Differential: the `World`'s broad phase against all pairs of boxes. The input picks a few
/// hundred bodies, or a crowd of 1,100-1,355 where the grid runs, laid out in a cube or strung
/// along one axis, near the origin or 10^6 or 10^9 away. The boxes have input-chosen sizes,
/// some long. The positions come from a generator the input seeds, so a short input makes a
/// large scene. Then byte-driven edits (moves, teleports, every body placed anew, removals,
/// additions, static bodies, excluded pairs) and queries with a margin. `World::overlapping_pairs` must equal the tested
/// pairs of bodies whose boxes are within the margin, and `overlapping_boxes` the same pairs
/// on the plain boxes, and all pairs by the formula with a fifth of them turned inside out.
pub fn world_broad(data: &[u8]) {
    let mut b = Bytes(data);
    let flags = b.byte();
    let crowd = flags & 1 == 1;
    let n = if crowd {
        1100 + b.byte() as usize
    } else {
        1 + b.byte() as usize
    };
    let offset = [0.0, 1e6, -1e9][(flags >> 1) as usize % 3];
    let layout = (flags >> 3) % 4;
    let trees: Vec<Arc<ObbTree>> = (0..3)
        .map(|k| {
            let s = |x: u8| 0.25 + (x % 16) as f64 * 0.25;
            let mut h = DVec3::new(s(b.byte()), s(b.byte()), s(b.byte()));
            if k == 2 {
                h.x *= 8.0;
            }
            Arc::new(ObbTree::build(&shapes::cuboid(h), &BuildOptions::default()))
        })
        .collect();
    let mut seed = u64::from_le_bytes(std::array::from_fn(|_| b.byte())) | 1;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    // About 4 neighbours per body at the boxes' typical size.
    let side = (n as f64 * 12.0).cbrt() * 2.0;
    let extent = match layout {
        0 => DVec3::splat(side),
        1 => DVec3::new(side * 8.0, side / 3.0, side / 3.0),
        2 => DVec3::new(side / 3.0, side * 8.0, side / 3.0),
        _ => DVec3::new(side / 3.0, side / 3.0, side * 8.0),
    };
    let place = |next: &mut dyn FnMut() -> u64| {
        let mut u = || (next() >> 11) as f64 / (1u64 << 53) as f64;
        let c = DVec3::new(u() * extent.x, u() * extent.y, u() * extent.z) + DVec3::splat(offset);
        let q = DQuat::from_xyzw(u() - 0.5, u() - 0.5, u() - 0.5, u() - 0.5);
        if q.length_squared() > 1e-6 {
            Pose::new(c, q)
        } else {
            Pose::from_translation(c)
        }
    };
    // The broad phase's grown boxes: the default, tight, and as large as the boxes.
    let mut w = World::new(WorldOptions {
        box_slack_percent: [10, 0, 100][(flags >> 5) as usize % 3],
        ..WorldOptions::default()
    });
    let mut ids: Vec<BodyId> = Vec::new();
    for k in 0..n {
        let pose = place(&mut next);
        let tree = trees[(next() % 3) as usize].clone();
        let id = w.add_body(tree, pose, k % 37 == 5).expect("finite pose");
        ids.push(id);
    }
    let ops = if crowd { 2 } else { 8 };
    for _ in 0..ops {
        let op = b.byte();
        if !ids.is_empty() {
            let k = (next() % ids.len() as u64) as usize;
            let id = ids[k];
            match op % 7 {
                // Every body anew (incoherent motion: twice in a row, the broad phase finds
                // that step's pairs with the bodies' own boxes).
                // All in one `set_poses` (four world boxes at a time), each box checked
                // against the World's formula for one body.
                6 => {
                    let batch: Vec<(BodyId, Pose)> =
                        ids.iter().map(|&id| (id, place(&mut next))).collect();
                    w.set_poses(&batch).expect("finite poses");
                    for &(id, pose) in &batch {
                        let local = w.tree(id).expect("live").aabb();
                        let b = local.transformed(&pose);
                        let mag = b.min.abs().max(b.max.abs()).max_element();
                        let want = b.inflated(mag * 1e-12 + f64::MIN_POSITIVE);
                        assert_eq!(w.body_aabb(id), Some(want), "set_poses's box");
                    }
                }
                0 | 1 => {
                    let p = w.pose(id).expect("live");
                    let d = DVec3::new(b.small(), b.small(), b.small()) * 0.05;
                    w.set_pose(id, Pose::new(p.translation + d, p.rotation))
                        .expect("finite pose");
                }
                2 => w.teleport(id, place(&mut next)).expect("finite pose"),
                3 => {
                    w.remove_body(ids.swap_remove(k)).expect("live");
                }
                4 => {
                    let other = ids[(next() % ids.len() as u64) as usize];
                    if other != id {
                        w.exclude_pair(id, other).expect("live pair");
                    }
                }
                _ => {
                    let tree = trees[(op as usize / 6) % 3].clone();
                    ids.push(w.add_body(tree, place(&mut next), false).expect("finite"));
                }
            }
        }
        let margin = [0.0, 0.1, 1.0, 5.0][(op >> 4) as usize % 4];
        let got = w.overlapping_pairs(margin);
        let live: Vec<BodyId> = w.bodies().collect();
        let boxes: Vec<_> = live
            .iter()
            .map(|&id| w.body_aabb(id).expect("live"))
            .collect();
        let within = |i: usize, j: usize| {
            let (p, q) = (&boxes[i], &boxes[j]);
            !(0..3).any(|k| p.min[k] - q.max[k] > margin || q.min[k] - p.max[k] > margin)
        };
        let mut want = Vec::new();
        let mut plain = Vec::new();
        for i in 0..live.len() {
            for j in i + 1..live.len() {
                if within(i, j) {
                    plain.push((i as u32, j as u32));
                    if w.is_pair_tested(live[i], live[j]) {
                        let (a, c) = (live[i], live[j]);
                        want.push(if a.index() < c.index() {
                            (a, c)
                        } else {
                            (c, a)
                        });
                    }
                }
            }
        }
        want.sort_unstable_by_key(|&(a, c)| (a.index(), c.index()));
        assert_eq!(got, want, "World::overlapping_pairs differs from all pairs");
        assert_eq!(
            overlapping_boxes(&boxes, margin),
            plain,
            "overlapping_boxes differs from all pairs"
        );
        // The same boxes with some turned inside out (min > max along an axis the input
        // picks): `overlapping_boxes` still pairs exactly by the formula.
        let axis = (op as usize >> 2) % 3;
        let inverted: Vec<_> = boxes
            .iter()
            .enumerate()
            .map(|(k, b)| {
                let mut b = *b;
                if k % 5 == 2 {
                    std::mem::swap(&mut b.min[axis], &mut b.max[axis]);
                }
                b
            })
            .collect();
        let mut plain_inverted = Vec::new();
        for i in 0..inverted.len() {
            for j in i + 1..inverted.len() {
                let (p, q) = (&inverted[i], &inverted[j]);
                if !(0..3).any(|k| p.min[k] - q.max[k] > margin || q.min[k] - p.max[k] > margin) {
                    plain_inverted.push((i as u32, j as u32));
                }
            }
        }
        assert_eq!(
            overlapping_boxes(&inverted, margin),
            plain_inverted,
            "overlapping_boxes differs from all pairs on inverted boxes"
        );
    }
}
