//! Differential: `collide` (all pairs, solid or surface mode) against `frcd_obb::oracle` on
//! small meshes and poses. Coordinates are small integers scaled by a power of two (so touching,
//! coplanar and degenerate configurations are common), sometimes closed boxes (containment).
//! The two answers must be equal.
#![no_main]
use frcd_geom::{DQuat, DVec3, Pose, TriMesh, shapes};
use frcd_obb::{BuildOptions, Mode, ObbTree, Request, collide, oracle};
use libfuzzer_sys::fuzz_target;

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

fn mesh(b: &mut Bytes, scale: f64) -> Option<TriMesh> {
    let kind = b.byte();
    if kind % 4 == 0 {
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

fn pose(b: &mut Bytes, scale: f64) -> Pose {
    let t = DVec3::new(b.small(), b.small(), b.small()) * scale / 4.0;
    let q = DQuat::from_xyzw(b.small(), b.small(), b.small(), b.small());
    if b.byte() % 2 == 0 || q.length_squared() == 0.0 {
        Pose::from_translation(t)
    } else {
        Pose::new(t, q)
    }
}

fuzz_target!(|data: &[u8]| {
    let mut b = Bytes(data);
    let flags = b.byte();
    // 2^-8 .. 2^+990: small, ordinary and huge magnitudes.
    let exp = [-8, 0, 0, 0, 20, 500, 990][(b.byte() % 7) as usize];
    let scale = 2f64.powi(exp) / 4.0;
    let (Some(ma), Some(mb)) = (mesh(&mut b, scale), mesh(&mut b, scale)) else {
        return;
    };
    let (pa, pb) = (pose(&mut b, scale), pose(&mut b, scale));
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
});
