//! Mesh loading: round trips, format quirks, and malformed files whose errors must name the
//! file and the line or record.

use frcd_geom::{DVec3, TriMesh, shapes};
use frcd_io::{
    Error, LoadOptions, Location, load_mesh, load_obj_objects, write_obj, write_stl_binary,
};
use std::path::Path;

mod common;
use common::TempDir;

fn temp_dir(name: &str) -> TempDir {
    TempDir::new("mesh", name)
}

#[test]
fn temp_dir_is_removed_with_its_contents_when_dropped() {
    let dir = temp_dir("guard");
    let path = dir.to_path_buf();
    std::fs::create_dir_all(path.join("sub")).unwrap();
    std::fs::write(path.join("sub/f.txt"), "x").unwrap();
    assert!(path.join("sub/f.txt").is_file());
    drop(dir);
    assert!(!path.exists(), "{} left behind", path.display());
    // The guard also runs when a test panics.
    let unwound = std::panic::catch_unwind(|| {
        let dir = temp_dir("guard-panic");
        std::fs::write(dir.join("f.txt"), "x").unwrap();
        panic!("{}", dir.display());
    });
    let message = unwound.unwrap_err();
    let path = message.downcast_ref::<String>().unwrap();
    assert!(path.ends_with("guard-panic"), "{path}");
    assert!(!Path::new(path).exists(), "{path} left behind");
}

fn cube() -> TriMesh {
    shapes::cuboid(DVec3::new(1.0, 2.0, 0.5))
}

/// Asserts a parse error naming `path` at `location`, and returns its message.
fn expect_parse(result: frcd_io::Result<TriMesh>, path: &Path, location: Location) -> String {
    match result {
        Err(e @ Error::Parse { .. }) => {
            assert_eq!(e.path(), path);
            assert_eq!(e.location(), Some(location), "{e}");
            let text = e.to_string();
            assert!(text.contains(&path.display().to_string()), "{text}");
            assert!(text.contains(&location.to_string()), "{text}");
            text
        }
        other => panic!("expected a parse error at {location}, got {other:?}"),
    }
}

fn ascii_stl(mesh: &TriMesh, name: &str) -> String {
    let mut s = format!("solid {name}\n");
    for t in mesh.triangles() {
        let n = t.normal().normalize();
        s += &format!("  facet normal {} {} {}\n    outer loop\n", n.x, n.y, n.z);
        for p in t.v {
            s += &format!("      vertex {} {} {}\n", p.x, p.y, p.z);
        }
        s += "    endloop\n  endfacet\n";
    }
    s += &format!("endsolid {name}\n");
    s
}

fn same_geometry(a: &TriMesh, b: &TriMesh) {
    assert_eq!(a.triangle_count(), b.triangle_count());
    assert_eq!(a.vertex_count(), b.vertex_count());
    for (ta, tb) in a.triangles().zip(b.triangles()) {
        assert_eq!(ta.v, tb.v);
    }
}

#[test]
fn binary_stl_round_trip_welds_and_closes() {
    let dir = temp_dir("bin");
    let path = dir.join("cube.stl");
    write_stl_binary(&path, &cube()).unwrap();
    assert_eq!(std::fs::metadata(&path).unwrap().len(), 84 + 50 * 12);
    let m = load_mesh(&path).unwrap();
    same_geometry(&m, &cube());
    assert!(m.topology().is_closed_oriented_manifold());
}

#[test]
fn binary_stl_with_solid_header_is_read_as_binary() {
    let dir = temp_dir("solidheader");
    let path = dir.join("cube.STL");
    write_stl_binary(&path, &cube()).unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[..19].copy_from_slice(b"solid exported part");
    std::fs::write(&path, &bytes).unwrap();
    let m = load_mesh(&path).unwrap();
    same_geometry(&m, &cube());
    // Truncated, it is still recognised as binary and the record is named.
    std::fs::write(&path, &bytes[..84 + 50 * 3 + 10]).unwrap();
    expect_parse(load_mesh(&path), &path, Location::Record(3));
}

#[test]
fn ascii_stl_with_several_solids_and_blank_lines() {
    let dir = temp_dir("ascii");
    let path = dir.join("two.stl");
    let other = cube().transformed(&frcd_geom::Pose::from_translation(DVec3::new(
        5.0, 0.0, 0.0,
    )));
    let text = format!("{}\n\n{}", ascii_stl(&cube(), "a"), ascii_stl(&other, "b"));
    std::fs::write(&path, text.replace("endsolid b", "endsolid")).unwrap();
    let m = load_mesh(&path).unwrap();
    assert_eq!(m.triangle_count(), 24);
    assert_eq!(m.topology().components, 2);
    assert!(m.topology().is_closed_oriented_manifold());
    // A bare "solid" line (no name) is accepted too.
    std::fs::write(
        &path,
        ascii_stl(&cube(), "x").replacen("solid x", "solid", 1),
    )
    .unwrap();
    assert_eq!(load_mesh(&path).unwrap().triangle_count(), 12);
}

#[test]
fn ascii_stl_nan_normals_are_ignored_but_nan_vertices_are_not() {
    let dir = temp_dir("nannormal");
    let path = dir.join("cube.stl");
    let good = ascii_stl(&cube(), "c");
    let mut lines: Vec<String> = good.lines().map(str::to_owned).collect();
    lines[1 + 7 * 2] = "  facet normal nan -nan NaN".into();
    lines[1 + 7 * 5] = "  facet normal -1.#IND 0 0".into();
    std::fs::write(&path, lines.join("\n")).unwrap();
    let m = load_mesh(&path).unwrap();
    same_geometry(&m, &cube());
    lines[1 + 7 * 7 + 2] = "      vertex nan 0 0".into();
    std::fs::write(&path, lines.join("\n")).unwrap();
    expect_parse(load_mesh(&path), &path, Location::Line(2 + 7 * 7 + 2));
}

#[test]
fn truncated_binary_stl_names_the_record() {
    let dir = temp_dir("trunc");
    let path = dir.join("cube.stl");
    write_stl_binary(&path, &cube()).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..84 + 50 * 5 + 20]).unwrap();
    let msg = expect_parse(load_mesh(&path), &path, Location::Record(5));
    assert!(msg.contains("truncated"), "{msg}");
    // Extra bytes after the announced triangles are refused too (they may be lost triangles).
    let mut longer = bytes.clone();
    longer.extend_from_slice(&[0u8; 50]);
    std::fs::write(&path, &longer).unwrap();
    expect_parse(load_mesh(&path), &path, Location::Record(12));
    // Too short even for a header.
    std::fs::write(&path, &bytes[..40]).unwrap();
    expect_parse(load_mesh(&path), &path, Location::File);
}

#[test]
fn binary_stl_nan_vertex_names_the_record() {
    let dir = temp_dir("binnan");
    let path = dir.join("cube.stl");
    write_stl_binary(&path, &cube()).unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    let at = 84 + 50 * 7 + 12 + 4; // record 7, vertex 0, y
    bytes[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    std::fs::write(&path, &bytes).unwrap();
    let msg = expect_parse(load_mesh(&path), &path, Location::Record(7));
    assert!(msg.contains("non-finite"), "{msg}");
}

#[test]
fn ascii_stl_bad_token_names_the_line() {
    let dir = temp_dir("asciibad");
    let path = dir.join("cube.stl");
    let good = ascii_stl(&cube(), "c");
    let mut lines: Vec<String> = good.lines().map(str::to_owned).collect();
    // Line 1 is "solid", facets take 7 lines: line 2 + 7*3 + 3 is facet 3's second vertex.
    let n = 2 + 7 * 3 + 3;
    assert!(lines[n - 1].trim_start().starts_with("vertex"));
    lines[n - 1] = "      vertex 1.0 2.0x 3.0".into();
    std::fs::write(&path, lines.join("\n")).unwrap();
    expect_parse(load_mesh(&path), &path, Location::Line(n));
    // A NaN coordinate is refused at its line.
    lines[n - 1] = "      vertex 1.0 nan 3.0".into();
    std::fs::write(&path, lines.join("\n")).unwrap();
    expect_parse(load_mesh(&path), &path, Location::Line(n));
    // A wrong keyword.
    let mut lines: Vec<String> = good.lines().map(str::to_owned).collect();
    lines[1 + 7 * 2 + 5] = "    endlop".into();
    std::fs::write(&path, lines.join("\n")).unwrap();
    expect_parse(load_mesh(&path), &path, Location::Line(2 + 7 * 2 + 5));
    // Missing endsolid.
    let cut: Vec<&str> = good.lines().take(1 + 7 * 4).collect();
    std::fs::write(&path, cut.join("\n")).unwrap();
    expect_parse(load_mesh(&path), &path, Location::EndOfFile);
    // Garbage after endsolid.
    std::fs::write(&path, format!("{good}garbage here\n")).unwrap();
    expect_parse(
        load_mesh(&path),
        &path,
        Location::Line(good.lines().count() + 1),
    );
}

const CUBE_OBJ_SEAMS: &str = "\
# a unit cube with every face's corners repeated (as UV seams do)
o cube
v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n
v 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n
v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\n
vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1
f 1/1 4/4 3/3 2/2
f 5/1 6/2 7/3 8/4
f 9/1 10/2 11/3 12/4
f 2 3 7 6
f 3 4 8 7
f 4 1 5 8
";

#[test]
fn obj_quads_are_triangulated_and_seams_welded() {
    let dir = temp_dir("objseam");
    let path = dir.join("cube.obj");
    std::fs::write(&path, CUBE_OBJ_SEAMS).unwrap();
    let m = load_mesh(&path).unwrap();
    assert_eq!(m.triangle_count(), 12);
    assert_eq!(m.vertex_count(), 8);
    assert!(
        m.topology().is_closed_oriented_manifold(),
        "{:?}",
        m.topology()
    );
    assert!((m.signed_volume() - 1.0).abs() < 1e-15);
}

#[test]
fn obj_objects_merged_or_separate() {
    let dir = temp_dir("objobjects");
    let path = dir.join("two.obj");
    let shifted = CUBE_OBJ_SEAMS
        .replace("o cube", "o second")
        .replace("# a unit", "# another")
        .lines()
        .map(|l| match l.strip_prefix("v ") {
            Some(rest) => {
                let x: Vec<f64> = rest
                    .split_whitespace()
                    .map(|t| t.parse().unwrap())
                    .collect();
                format!("v {} {} {}", x[0] + 3.0, x[1], x[2])
            }
            None => match l.strip_prefix("f ") {
                Some(rest) => {
                    let f: Vec<String> = rest
                        .split_whitespace()
                        .map(|t| {
                            let mut parts: Vec<String> = t.split('/').map(str::to_owned).collect();
                            parts[0] = (parts[0].parse::<i64>().unwrap() + 12).to_string();
                            if parts.len() > 1 {
                                parts[1] = (parts[1].parse::<i64>().unwrap() + 4).to_string();
                            }
                            parts.join("/")
                        })
                        .collect();
                    format!("f {}", f.join(" "))
                }
                None => l.to_owned(),
            },
        })
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(&path, format!("{CUBE_OBJ_SEAMS}{shifted}\n")).unwrap();
    let merged = load_mesh(&path).unwrap();
    assert_eq!(merged.triangle_count(), 24);
    assert_eq!(merged.topology().components, 2);
    let objects = load_obj_objects(&path, &LoadOptions::default()).unwrap();
    let names: Vec<&str> = objects.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, ["cube", "second"]);
    for o in &objects {
        assert_eq!(o.mesh.triangle_count(), 12);
        assert!(o.mesh.topology().is_closed_oriented_manifold());
    }
    assert_eq!(objects[1].mesh.aabb().min.x, 3.0);
}

#[test]
fn obj_index_out_of_range_names_the_line() {
    let dir = temp_dir("objoob");
    let path = dir.join("bad.obj");
    let text = CUBE_OBJ_SEAMS.replace("f 3 4 8 7", "f 3 4 80 7");
    let line = text.lines().position(|l| l == "f 3 4 80 7").unwrap() + 1;
    std::fs::write(&path, &text).unwrap();
    let msg = expect_parse(load_mesh(&path), &path, Location::Line(line));
    assert!(msg.contains("out of bounds"), "{msg}");
    // Negative (relative) indices past the start.
    let text = CUBE_OBJ_SEAMS.replace("f 3 4 8 7", "f -1 -2 -30");
    std::fs::write(&path, &text).unwrap();
    expect_parse(load_mesh(&path), &path, Location::Line(line));
}

#[test]
fn obj_nan_and_bad_numbers_name_the_line() {
    let dir = temp_dir("objnan");
    let path = dir.join("bad.obj");
    let lines: Vec<&str> = CUBE_OBJ_SEAMS.lines().collect();
    let target = lines.iter().position(|l| *l == "v 1 1 1").unwrap();
    for (bad, what) in [
        ("v 1 NaN 1", "non-finite"),
        ("v 1 inf 1", "non-finite"),
        ("v 1 1,5 1", "parse"),
    ] {
        let mut l = lines.clone();
        l[target] = bad;
        std::fs::write(&path, l.join("\n")).unwrap();
        let msg = expect_parse(load_mesh(&path), &path, Location::Line(target + 1));
        assert!(msg.contains(what), "{msg}");
    }
    // A broken face token.
    let mut l = lines.clone();
    let f = lines.iter().position(|l| *l == "f 2 3 7 6").unwrap();
    l[f] = "f 2 3 x 6";
    std::fs::write(&path, l.join("\n")).unwrap();
    expect_parse(load_mesh(&path), &path, Location::Line(f + 1));
}

#[test]
fn other_failures_are_typed() {
    let dir = temp_dir("other");
    let missing = dir.join("nope.stl");
    assert!(matches!(load_mesh(&missing), Err(Error::Io { path, .. }) if path == missing));
    let ply = dir.join("x.ply");
    std::fs::write(&ply, "ply").unwrap();
    assert!(matches!(
        load_mesh(&ply),
        Err(Error::UnsupportedFormat { .. })
    ));
    let empty = dir.join("empty.obj");
    std::fs::write(&empty, "# nothing\nv 0 0 0\n").unwrap();
    assert!(matches!(
        load_mesh(&empty),
        Err(Error::Mesh {
            source: frcd_geom::MeshError::Empty { .. },
            ..
        })
    ));
    let not_utf8 = dir.join("bin.obj");
    std::fs::write(&not_utf8, b"v 0 0 0\nv 1 0 0\n\xff\xfe\n").unwrap();
    expect_parse(load_mesh(&not_utf8), &not_utf8, Location::Line(3));
}

#[test]
fn obj_writer_round_trips_exactly() {
    let dir = temp_dir("objwrite");
    let path = dir.join("ball.obj");
    let ball = shapes::icosphere(0.123456789, 2).transformed(&frcd_geom::Pose::from_translation(
        DVec3::new(1e6, -3.3, 0.1),
    ));
    write_obj(&path, &ball, "ball").unwrap();
    let back = load_mesh(&path).unwrap();
    same_geometry(&back, &ball);
}
