//! STL and OBJ mesh loading.

use crate::{Error, Location, Result};
use frcd_geom::{DVec3, TriMesh};
use std::collections::HashMap;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

/// How meshes are loaded.
#[derive(Clone, Debug, PartialEq)]
pub struct LoadOptions {
    /// After welding bit-identical positions, also merge vertices closer than this distance
    /// (in the file's units; see [`TriMesh::welded`]). `0.0` (the default) welds exact
    /// duplicates only, which is what a correct STL export needs.
    pub weld_tolerance: f64,
    /// Largest file read, in bytes ([`crate::MAX_MESH_BYTES`] by default); a larger file is an
    /// [`Error::TooLarge`].
    pub max_bytes: u64,
}

impl Default for LoadOptions {
    fn default() -> Self {
        Self {
            weld_tolerance: 0.0,
            max_bytes: crate::MAX_MESH_BYTES,
        }
    }
}

/// The mesh formats frcd reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshFormat {
    /// STL, ASCII or binary (told apart by content).
    Stl,
    /// Wavefront OBJ.
    Obj,
}

impl MeshFormat {
    /// The format named by a path's extension (case-insensitive), if any.
    pub fn from_path(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "stl" => Some(MeshFormat::Stl),
            "obj" => Some(MeshFormat::Obj),
            _ => None,
        }
    }
}

/// One named object (`o` / `g` statement) of an OBJ file.
#[derive(Clone, Debug)]
pub struct ObjObject {
    /// The object's name as the file gives it.
    pub name: String,
    /// Its triangles, welded by position.
    pub mesh: TriMesh,
}

/// Loads a mesh from an `.stl` or `.obj` file with default options: vertices welded by
/// bit-identical position, all OBJ objects merged into one mesh.
///
/// ```no_run
/// let mesh = frcd_io::load_mesh("part.stl")?;
/// println!("{} triangles, closed: {}", mesh.triangle_count(), mesh.topology().is_closed());
/// # Ok::<(), frcd_io::Error>(())
/// ```
pub fn load_mesh(path: impl AsRef<Path>) -> Result<TriMesh> {
    load_mesh_with(path, &LoadOptions::default())
}

/// Loads a mesh from an `.stl` or `.obj` file (see [`load_mesh`]).
pub fn load_mesh_with(path: impl AsRef<Path>, options: &LoadOptions) -> Result<TriMesh> {
    let path = path.as_ref();
    let format = MeshFormat::from_path(path)
        .ok_or_else(|| Error::UnsupportedFormat { path: path.into() })?;
    let bytes = crate::read_limited(path, options.max_bytes)?;
    let mesh = match format {
        MeshFormat::Stl => parse_stl(&bytes, path)?,
        MeshFormat::Obj => parse_obj(&bytes, path)?,
    };
    Ok(weld(mesh, options))
}

/// Loads each object of an OBJ file as its own mesh (objects of the same name, e.g. split by
/// material, are merged). Faces before the first `o`/`g` statement form an object named
/// `"unnamed_object"`.
pub fn load_obj_objects(path: impl AsRef<Path>, options: &LoadOptions) -> Result<Vec<ObjObject>> {
    let path = path.as_ref();
    let bytes = crate::read_limited(path, options.max_bytes)?;
    let mut objects = parse_obj_objects(&bytes, path)?;
    for o in &mut objects {
        if options.weld_tolerance > 0.0 {
            o.mesh = o.mesh.welded(options.weld_tolerance);
        }
    }
    Ok(objects)
}

fn weld(mesh: TriMesh, options: &LoadOptions) -> TriMesh {
    if options.weld_tolerance > 0.0 {
        mesh.welded(options.weld_tolerance)
    } else {
        mesh
    }
}

fn mesh_error(path: &Path, object: Option<&str>, source: frcd_geom::MeshError) -> Error {
    Error::Mesh {
        path: path.into(),
        object: object.map(str::to_owned),
        source,
    }
}

// ---------------------------------------------------------------------------------------------
// STL

/// Parses STL bytes (ASCII or binary), welding vertices with bit-identical positions. `path` is
/// used in errors only.
///
/// Binary is recognised by its size (`84 + 50 n` bytes for the `n` in its header) or a NUL
/// byte among its first 512 bytes, so binary files whose header starts with `solid` load
/// correctly (and, truncated, get a binary error naming the record). ASCII files may hold several solids;
/// all are read.
pub fn parse_stl(bytes: &[u8], path: &Path) -> Result<TriMesh> {
    // ASCII STL never holds a NUL byte; a binary header's triangle count nearly always does,
    // so a damaged binary file whose header starts with "solid" is still read as binary.
    let has_nul = bytes[..bytes.len().min(512)].contains(&0);
    let soup = if is_binary_stl(bytes) || has_nul || !starts_with_solid(bytes) {
        read_binary_stl(bytes, path)?
    } else {
        read_ascii_stl(bytes, path)?
    };
    TriMesh::from_triangle_soup(&soup).map_err(|e| mesh_error(path, None, e))
}

fn is_binary_stl(bytes: &[u8]) -> bool {
    if bytes.len() < 84 {
        return false;
    }
    let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as u64;
    84 + 50 * n == bytes.len() as u64
}

fn starts_with_solid(bytes: &[u8]) -> bool {
    let start = bytes
        .iter()
        .position(|b| !b.is_ascii_whitespace())
        .unwrap_or(bytes.len());
    let rest = &bytes[start..];
    rest.starts_with(b"solid") && rest.get(5).is_none_or(|b| b.is_ascii_whitespace())
}

fn to_dvec(v: stl_io::Vertex) -> DVec3 {
    DVec3::new(v.0[0] as f64, v.0[1] as f64, v.0[2] as f64)
}

fn read_binary_stl(bytes: &[u8], path: &Path) -> Result<Vec<[DVec3; 3]>> {
    if bytes.len() < 84 {
        return Err(Error::parse(
            path,
            Location::File,
            format!(
                "not an ASCII STL (no 'solid' line) and too short for a binary STL header: {} bytes < 84",
                bytes.len()
            ),
        ));
    }
    let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
    let expected = 84 + 50 * n as u64;
    let len = bytes.len() as u64;
    if len < expected {
        let complete = (bytes.len() - 84) / 50;
        return Err(Error::parse(
            path,
            Location::Record(complete),
            format!(
                "binary STL truncated: header announces {n} triangles ({expected} bytes) but the file has {len} bytes; record {complete} is incomplete"
            ),
        ));
    }
    if len > expected {
        return Err(Error::parse(
            path,
            Location::Record(n),
            format!(
                "binary STL has {} bytes after the {n} triangles its header announces",
                len - expected
            ),
        ));
    }
    // stl_io probes for ASCII by a leading "solid ": hide the (ignored) header from it.
    let mut reader = Prefixed {
        prefix: &[0u8; 80],
        rest: &bytes[80..],
        pos: 0,
    };
    let iter = stl_io::create_stl_reader(&mut reader)
        .map_err(|e| Error::parse(path, Location::File, e.to_string()))?;
    let mut soup = Vec::with_capacity(n);
    for (record, t) in iter.enumerate() {
        let t = t.map_err(|e| Error::parse(path, Location::Record(record), e.to_string()))?;
        let tri = t.vertices.map(to_dvec);
        if let Some((corner, p)) = tri.iter().enumerate().find(|(_, p)| !p.is_finite()) {
            return Err(Error::parse(
                path,
                Location::Record(record),
                format!(
                    "vertex {corner} has a non-finite coordinate {:?}",
                    p.to_array()
                ),
            ));
        }
        soup.push(tri);
    }
    Ok(soup)
}

/// A `Read + Seek` view of `prefix` followed by `rest`, without copying either.
struct Prefixed<'a> {
    prefix: &'a [u8],
    rest: &'a [u8],
    pos: u64,
}

impl Prefixed<'_> {
    fn len(&self) -> u64 {
        (self.prefix.len() + self.rest.len()) as u64
    }
}

impl Read for Prefixed<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let p = self.pos as usize;
        let (src, off) = if p < self.prefix.len() {
            (self.prefix, p)
        } else if p - self.prefix.len() < self.rest.len() {
            (self.rest, p - self.prefix.len())
        } else {
            return Ok(0);
        };
        let n = buf.len().min(src.len() - off);
        buf[..n].copy_from_slice(&src[off..off + n]);
        self.pos += n as u64;
        Ok(n)
    }
}

impl Seek for Prefixed<'_> {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        let target = match to {
            SeekFrom::Start(s) => s as i128,
            SeekFrom::Current(d) => self.pos as i128 + d as i128,
            SeekFrom::End(d) => self.len() as i128 + d as i128,
        };
        if target < 0 {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "seek before start",
            ));
        }
        self.pos = target as u64;
        Ok(self.pos)
    }
}

/// A non-blank line of a text file: its 1-based number and byte range.
struct TextLine {
    number: usize,
    start: usize,
    end: usize,
}

fn non_blank_lines(text: &str) -> Vec<TextLine> {
    let mut lines = Vec::new();
    let mut start = 0;
    for (i, line) in text.split('\n').enumerate() {
        let end = start + line.len();
        if !line.trim().is_empty() {
            lines.push(TextLine {
                number: i + 1,
                start,
                end,
            });
        }
        start = end + 1;
    }
    lines
}

fn utf8<'a>(bytes: &'a [u8], path: &Path) -> Result<&'a str> {
    std::str::from_utf8(bytes).map_err(|e| {
        let line = 1 + bytes[..e.valid_up_to()]
            .iter()
            .filter(|&&b| b == b'\n')
            .count();
        Error::parse(path, Location::Line(line), "text is not valid UTF-8")
    })
}

fn read_ascii_stl(bytes: &[u8], path: &Path) -> Result<Vec<[DVec3; 3]>> {
    let text = utf8(bytes, path)?;
    match read_ascii_stl_text(text, path) {
        // Some exporters write `facet normal nan nan nan` for zero-area facets; stl_io refuses
        // that, but frcd never reads normals: blank them (same line numbers) and read again.
        Err(e) if e.location().is_some_and(|l| is_bad_normal_line(text, l)) => {
            let fixed: String = text
                .split('\n')
                .map(|line| {
                    if is_bad_normal(line) {
                        "facet normal 0 0 0"
                    } else {
                        line
                    }
                })
                .collect::<Vec<_>>()
                .join("\n");
            read_ascii_stl_text(&fixed, path)
        }
        other => other,
    }
}

/// A `facet normal a b c` line whose normal is NaN or infinite (as C libraries print them).
fn is_bad_normal(line: &str) -> bool {
    let t: Vec<&str> = line.split_whitespace().collect();
    let odd = |x: &str| {
        let l = x.to_ascii_lowercase();
        x.parse::<f32>().is_ok_and(|v| !v.is_finite())
            || l.contains("nan")
            || l.contains("inf")
            || l.contains('#')
    };
    t.len() == 5 && t[0] == "facet" && t[1] == "normal" && t[2..].iter().any(|x| odd(x))
}

fn is_bad_normal_line(text: &str, location: Location) -> bool {
    location
        .line()
        .and_then(|l| text.split('\n').nth(l - 1))
        .is_some_and(is_bad_normal)
}

fn read_ascii_stl_text(text: &str, path: &Path) -> Result<Vec<[DVec3; 3]>> {
    let bytes = text.as_bytes();
    let lines = non_blank_lines(text);
    let mut soup = Vec::new();
    let mut cursor = 0; // index into `lines` of the next `solid` line
    while cursor < lines.len() {
        let first = &lines[cursor];
        let first_text = &text[first.start..first.end];
        if first_text.split_whitespace().next() != Some("solid") {
            return Err(Error::parse(
                path,
                Location::Line(first.number),
                format!("expected 'solid', got {:?}", first_text.trim()),
            ));
        }
        // stl_io wants "solid <name>" on the first line; give it one, then the solid's body.
        let body_start = lines.get(cursor + 1).map_or(bytes.len(), |l| l.start);
        let mut reader = Prefixed {
            prefix: b"solid frcd\n",
            rest: &bytes[body_start..],
            pos: 0,
        };
        let iter = stl_io::create_stl_reader(&mut reader)
            .map_err(|e| Error::parse(path, Location::Line(first.number), e.to_string()))?;
        let mut count = 0;
        for t in iter {
            match t {
                Ok(t) => {
                    soup.push(t.vertices.map(to_dvec));
                    count += 1;
                }
                Err(e) => {
                    let location = locate_ascii_stl_error(text, &lines, cursor + 1 + 7 * count);
                    return Err(Error::parse(path, location, with_line(text, location, e)));
                }
            }
        }
        // The facets, then the `endsolid` line stl_io stopped at.
        cursor += 1 + 7 * count + 1;
    }
    if lines.is_empty() {
        return Err(Error::parse(path, Location::EndOfFile, "empty file"));
    }
    Ok(soup)
}

/// The message, followed by the offending line's text when the location is a line.
fn with_line(text: &str, location: Location, msg: impl std::fmt::Display) -> String {
    match location.line().and_then(|l| text.lines().nth(l - 1)) {
        Some(line) => {
            let line = line.trim();
            let shown: String = line.chars().take(80).collect();
            let more = if shown.len() < line.len() { "..." } else { "" };
            format!("{msg} (in '{shown}{more}')")
        }
        None => msg.to_string(),
    }
}

/// Finds the line of the facet starting at `lines[first]` that stl_io refused: the first line
/// that does not follow `facet normal f f f / outer loop / vertex f f f (x3) / endloop / endfacet`.
fn locate_ascii_stl_error(text: &str, lines: &[TextLine], first: usize) -> Location {
    let finite = |t: &str| t.parse::<f32>().is_ok_and(f32::is_finite);
    for k in 0..7 {
        let Some(line) = lines.get(first + k) else {
            return Location::EndOfFile;
        };
        let tokens: Vec<&str> = text[line.start..line.end].split_whitespace().collect();
        let ok = match k {
            0 => {
                tokens.first() == Some(&"endsolid")
                    || (tokens.len() == 5
                        && tokens[0] == "facet"
                        && tokens[1] == "normal"
                        && tokens[2..].iter().all(|t| finite(t)))
            }
            1 => tokens == ["outer", "loop"],
            2..=4 => {
                tokens.len() == 4 && tokens[0] == "vertex" && tokens[1..].iter().all(|t| finite(t))
            }
            5 => tokens == ["endloop"],
            _ => tokens == ["endfacet"],
        };
        if !ok {
            return Location::Line(line.number);
        }
    }
    lines
        .get(first)
        .map_or(Location::EndOfFile, |l| Location::Line(l.number))
}

// ---------------------------------------------------------------------------------------------
// OBJ

fn tobj_options() -> tobj::LoadOptions {
    tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        // Points and polylines are not surfaces: they carry no triangles.
        ignore_points: true,
        ignore_lines: true,
    }
}

fn tobj_models(bytes: &[u8], path: &Path) -> Result<Vec<tobj::Model>> {
    let text = utf8(bytes, path)?;
    let mut reader = std::io::Cursor::new(bytes);
    // Materials are irrelevant to collision: never open .mtl files.
    let (models, _materials) = tobj::load_obj_buf(&mut reader, &tobj_options(), |_| {
        Ok((Vec::new(), Default::default()))
    })
    .map_err(|e| {
        let location = locate_obj_error(text, &e);
        Error::parse(path, location, with_line(text, location, e))
    })?;
    for m in &models {
        if m.mesh.positions.iter().any(|x| !x.is_finite()) {
            let location = locate_obj_non_finite(text);
            let msg = with_line(text, location, "vertex has a non-finite coordinate");
            return Err(Error::parse(path, location, msg));
        }
    }
    Ok(models)
}

fn model_soup(m: &tobj::Model, soup: &mut Vec<[DVec3; 3]>) {
    let p = &m.mesh.positions;
    let at = |i: u32| {
        let i = i as usize * 3;
        DVec3::new(p[i], p[i + 1], p[i + 2])
    };
    for t in m.mesh.indices.chunks_exact(3) {
        soup.push([at(t[0]), at(t[1]), at(t[2])]);
    }
}

/// Parses OBJ bytes into one mesh: every object, polygons triangulated as fans, vertices welded
/// by bit-identical position (so vertices split at UV or normal seams are joined). `path` is
/// used in errors only.
pub fn parse_obj(bytes: &[u8], path: &Path) -> Result<TriMesh> {
    let models = tobj_models(bytes, path)?;
    let mut soup = Vec::new();
    for m in &models {
        model_soup(m, &mut soup);
    }
    TriMesh::from_triangle_soup(&soup).map_err(|e| mesh_error(path, None, e))
}

/// Parses OBJ bytes into one mesh per object name (see [`load_obj_objects`]).
pub fn parse_obj_objects(bytes: &[u8], path: &Path) -> Result<Vec<ObjObject>> {
    let models = tobj_models(bytes, path)?;
    let mut order: Vec<String> = Vec::new();
    let mut soups: HashMap<String, Vec<[DVec3; 3]>> = HashMap::new();
    for m in &models {
        let soup = soups.entry(m.name.clone()).or_insert_with(|| {
            order.push(m.name.clone());
            Vec::new()
        });
        model_soup(m, soup);
    }
    if order.is_empty() {
        return Err(mesh_error(
            path,
            None,
            frcd_geom::MeshError::Empty {
                vertices: 0,
                triangles: 0,
            },
        ));
    }
    order
        .into_iter()
        .map(|name| {
            let mesh = TriMesh::from_triangle_soup(&soups[&name])
                .map_err(|e| mesh_error(path, Some(&name), e))?;
            Ok(ObjObject { name, mesh })
        })
        .collect()
}

/// The first `v` line with a non-finite coordinate.
fn locate_obj_non_finite(text: &str) -> Location {
    for (i, line) in text.lines().enumerate() {
        let mut w = line.split_whitespace();
        if w.next() == Some("v")
            && w.take(3)
                .any(|t| t.parse::<f64>().is_ok_and(|x| !x.is_finite()))
        {
            return Location::Line(i + 1);
        }
    }
    Location::File
}

/// Finds the line that makes tobj fail with `err`, by walking the file with tobj's rules:
/// the first line that fails with the same kind of error, else the first line that fails at
/// all. Index bounds are checked against the elements defined before the face (OBJ's rule;
/// tobj checks at the end of each object).
fn locate_obj_error(text: &str, err: &tobj::LoadError) -> Location {
    use tobj::LoadError as E;
    let (mut npos, mut ntex, mut nnorm) = (0usize, 0usize, 0usize);
    let mut first_any = None;
    let floats = |w: &mut std::str::SplitWhitespace, n: usize| {
        w.by_ref()
            .take(n)
            .filter(|t| t.parse::<f64>().is_ok())
            .count()
            == n
    };
    for (i, line) in text.lines().enumerate() {
        let mut w = line.split_whitespace();
        let found: Option<E> = match w.next() {
            Some("v") => {
                if !floats(&mut w, 3) {
                    Some(E::PositionParseError)
                } else {
                    let rest: Vec<&str> = w.collect();
                    npos += 1;
                    match rest.len() {
                        0 | 3 => None,
                        1 => match rest[0].parse::<f64>() {
                            Err(_) => Some(E::PositionParseError),
                            Ok(0.0) => Some(E::ScalingByZeroError),
                            Ok(_) => None,
                        },
                        _ => Some(E::ColorParseError),
                    }
                }
            }
            Some("vt") => {
                ntex += 1;
                (!floats(&mut w, 2)).then_some(E::TexcoordParseError)
            }
            Some("vn") => {
                nnorm += 1;
                (!floats(&mut w, 3)).then_some(E::NormalParseError)
            }
            Some("f") | Some("l") => {
                let mut problem = None;
                let mut count = 0;
                for token in w {
                    count += 1;
                    let parts: Vec<&str> = token.split('/').collect();
                    if parts.len() > 3 {
                        problem = Some(E::FaceParseError);
                        break;
                    }
                    for (k, part) in parts.iter().enumerate() {
                        if part.is_empty() {
                            continue;
                        }
                        let Ok(x) = part.parse::<isize>() else {
                            problem = Some(E::FaceParseError);
                            break;
                        };
                        let size = [npos, ntex, nnorm][k] as isize;
                        let index = if x < 0 { size + x } else { x - 1 };
                        if index < 0 || index >= size {
                            problem = Some(
                                [
                                    E::FaceVertexOutOfBounds,
                                    E::FaceTexCoordOutOfBounds,
                                    E::FaceNormalOutOfBounds,
                                ][k],
                            );
                            break;
                        }
                    }
                    if problem.is_some() {
                        break;
                    }
                }
                if problem.is_none() && count == 0 {
                    problem = Some(E::InvalidPolygon);
                }
                problem
            }
            Some("usemtl") => line
                .split_once(' ')
                .is_none_or(|(_, n)| n.trim().is_empty())
                .then_some(E::MaterialParseError),
            _ => None,
        };
        if let Some(kind) = found {
            if &kind == err {
                return Location::Line(i + 1);
            }
            first_any.get_or_insert(Location::Line(i + 1));
        }
    }
    first_any.unwrap_or(Location::File)
}
