//! An engine with its own bounding-volume hierarchy takes only the narrow phase: its leaves
//! hand frcd-tritri pairs of triangles, and the exact test decides them correctly even when
//! they only touch, where a float test with a tolerance answers by luck.
//!
//! `cargo run -p frcd-example-engine-tritri`

use frcd_geom::DVec3;
use frcd_tritri::{Contact, Method, Triangle, exact, intersection_segment, intersects};

fn main() {
    let floor = Triangle::new(
        DVec3::new(-1.0, -1.0, 0.0),
        DVec3::new(3.0, -1.0, 0.0),
        DVec3::new(-1.0, 3.0, 0.0),
    );
    // A triangle standing on the floor: its lowest edge lies in the floor's plane.
    let standing = Triangle::new(
        DVec3::new(0.0, 0.0, 0.0),
        DVec3::new(1.0, 0.0, 0.0),
        DVec3::new(0.5, 0.0, 1.0),
    );
    // The same triangle lifted by 1e-12: disjoint, closer than any float tolerance.
    let lift = DVec3::new(0.0, 0.0, 1e-12);
    let hovering = Triangle::new(
        standing.v[0] + lift,
        standing.v[1] + lift,
        standing.v[2] + lift,
    );

    for (label, t) in [("standing", &standing), ("hovering", &hovering)] {
        let contact = intersection_segment(&floor, t);
        println!(
            "{label}: exact = {}, contact = {contact:?}",
            exact(&floor, t)
        );
        for m in [Method::Moller, Method::Shen, Method::Tropp] {
            println!("    {:>16}: {}", m.name(), intersects(m, &floor, t));
        }
    }
    assert!(exact(&floor, &standing));
    assert!(matches!(
        intersection_segment(&floor, &standing),
        Some(Contact::Segment(..))
    ));
    assert!(!exact(&floor, &hovering));
    assert!(intersection_segment(&floor, &hovering).is_none());
}
