//! Trajectories from dynamics simulations as CSV: `frame,body,x,y,z,qx,qy,qz,qw`.

use crate::scene::pose_from_parts;
use crate::{Error, Location, Result};
use frcd_geom::Pose;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The CSV header a trajectory file starts with.
pub const TRAJECTORY_HEADER: [&str; 9] = ["frame", "body", "x", "y", "z", "qx", "qy", "qz", "qw"];

/// One row of a trajectory: the world pose of `body` at `frame`.
#[derive(Clone, Debug, PartialEq)]
pub struct TrajectoryRow {
    /// 0-based frame index (the scene's frame list).
    pub frame: usize,
    /// Body name.
    pub body: String,
    /// World pose (quaternion normalised when read).
    pub pose: Pose,
    /// 1-based line in the file (0 for rows made in code).
    pub line: usize,
}

/// A trajectory CSV file with header `frame,body,x,y,z,qx,qy,qz,qw` (the output format of
/// most multibody dynamics tools after a little scripting). Fields may be padded with spaces,
/// lines starting with `#` are comments, rows may come in any order; a frame lists only the
/// bodies that move. Merged into a scene by [`crate::Scene`]; a body given twice in one frame
/// is an error naming both places. Between the rows given for a body its pose is **held** (no
/// interpolation): frame `k` uses the body's row with the largest frame `<= k`.
///
/// ```
/// let csv = "frame,body,x,y,z,qx,qy,qz,qw\n0,a,0,0,1,0,0,0,1\n1,a,0,0,2,0,0,0,1\n";
/// let t = frcd_io::Trajectory::parse(csv.as_bytes(), "t.csv".as_ref()).unwrap();
/// assert_eq!(t.rows.len(), 2);
/// assert_eq!(t.rows[1].pose.translation.z, 2.0);
/// ```
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trajectory {
    /// The file (used in errors).
    pub path: PathBuf,
    /// The rows, in file order.
    pub rows: Vec<TrajectoryRow>,
}

/// One parsed row, borrowed from the reader (no allocation per row).
pub(crate) struct RowRef<'a> {
    pub frame: u32,
    pub body: &'a str,
    pub pose: Pose,
    pub line: usize,
}

/// Shows at most 80 characters of file text in an error, control characters escaped.
pub(crate) fn shown(text: &str) -> String {
    let mut out: String = text.chars().take(80).flat_map(char::escape_debug).collect();
    if text.chars().count() > 80 {
        out.push_str("...");
    }
    out
}

/// Parses trajectory CSV bytes row by row, calling `row` for each; every error names the line.
/// Frame indices must be below `max_frames` (at most `u32::MAX`).
pub(crate) fn parse_rows(
    bytes: &[u8],
    path: &Path,
    max_frames: u64,
    mut row: impl FnMut(RowRef<'_>) -> Result<()>,
) -> Result<()> {
    let max_frames = max_frames.min(u32::MAX as u64);
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_reader(bytes);
    let header = reader
        .headers()
        .map_err(|e| csv_error(&e, path, bytes))?
        .iter()
        .map(|h| h.to_ascii_lowercase())
        .collect::<Vec<_>>();
    if header != TRAJECTORY_HEADER {
        return Err(Error::parse(
            path,
            Location::Line(1),
            format!(
                "expected header '{}', got '{}'",
                TRAJECTORY_HEADER.join(","),
                shown(&header.join(","))
            ),
        ));
    }
    let mut lines = LineCounter::new(bytes);
    let mut record = csv::StringRecord::new();
    loop {
        match reader.read_record(&mut record) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => return Err(csv_error(&e, path, bytes)),
        }
        let line = record.position().map_or(0, |p| lines.line_of(p.byte()));
        let at = Location::Line(line);
        let field = |k: usize| -> Result<f64> {
            let s = &record[k];
            s.parse::<f64>().map_err(|_| {
                Error::parse(
                    path,
                    at,
                    format!(
                        "column '{}': '{}' is not a number",
                        TRAJECTORY_HEADER[k],
                        shown(s)
                    ),
                )
            })
        };
        let frame = record[0].parse::<u64>().map_err(|_| {
            Error::parse(
                path,
                at,
                format!(
                    "column 'frame': '{}' is not a frame index (0, 1, 2, ...)",
                    shown(&record[0])
                ),
            )
        })?;
        if frame >= max_frames {
            return Err(Error::Limit {
                path: path.into(),
                place: format!("line {line}"),
                msg: format!(
                    "frame {frame} is past the limit of {max_frames} frames (frcd_io::Limits::frames)"
                ),
            });
        }
        let body = &record[1];
        if body.is_empty() {
            return Err(Error::parse(path, at, "column 'body' is empty"));
        }
        let t = [field(2)?, field(3)?, field(4)?];
        let q = [field(5)?, field(6)?, field(7)?, field(8)?];
        let pose = pose_from_parts(t, q).map_err(|msg| Error::BadPose {
            path: path.into(),
            place: format!("line {line}"),
            msg,
        })?;
        row(RowRef {
            frame: frame as u32,
            body,
            pose,
            line,
        })?;
    }
    Ok(())
}

impl Trajectory {
    /// Reads a trajectory CSV file (at most [`crate::MAX_TRAJECTORY_BYTES`]; a FIFO, device or
    /// directory is refused).
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let bytes = crate::read_limited(path, crate::MAX_TRAJECTORY_BYTES)?;
        Self::parse(&bytes, path)
    }

    /// Parses trajectory CSV bytes; `path` is used in errors only. Every error names the line
    /// (and the column for a bad field). Frame indices must be below [`crate::MAX_FRAMES`].
    pub fn parse(bytes: &[u8], path: &Path) -> Result<Self> {
        let mut rows = Vec::new();
        parse_rows(bytes, path, crate::MAX_FRAMES, |r| {
            rows.push(TrajectoryRow {
                frame: r.frame as usize,
                body: r.body.to_owned(),
                pose: r.pose,
                line: r.line,
            });
            Ok(())
        })?;
        Ok(Self {
            path: path.into(),
            rows,
        })
    }

    /// The CSV text: the header, then one row per entry; numbers in Rust's shortest form that
    /// reads back to the same f64 (round them first for a compact file).
    pub fn to_csv_string(&self) -> String {
        let mut s = String::with_capacity(64 * (self.rows.len() + 1));
        s.push_str(&TRAJECTORY_HEADER.join(","));
        s.push('\n');
        for r in &self.rows {
            let (t, q) = (r.pose.translation, r.pose.rotation);
            let _ = writeln!(
                s,
                "{},{},{},{},{},{},{},{},{}",
                r.frame, r.body, t.x, t.y, t.z, q.x, q.y, q.z, q.w
            );
        }
        s
    }

    /// Writes the CSV file (see [`Trajectory::to_csv_string`]).
    pub fn write(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        if let Some(r) = self.rows.iter().find(|r| r.body.contains([',', '"', '\n'])) {
            return Err(Error::Invalid {
                path: path.into(),
                msg: format!("body name {:?} contains a CSV delimiter", r.body),
            });
        }
        crate::write_atomic(path, self.to_csv_string().as_bytes())
    }
}

/// Byte offset of a record to its 1-based line, counted incrementally (records come in order),
/// so no per-line table is kept. The csv crate's own line count skips blank lines, and a
/// record's offset may point at blank lines before it: skip those.
struct LineCounter<'a> {
    bytes: &'a [u8],
    /// Bytes before `pos` hold `newlines` newlines.
    pos: usize,
    newlines: usize,
}

impl<'a> LineCounter<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        Self {
            bytes,
            pos: 0,
            newlines: 0,
        }
    }

    fn line_of(&mut self, byte: u64) -> usize {
        let mut b = (byte as usize).min(self.bytes.len());
        while b < self.bytes.len() && matches!(self.bytes[b], b'\n' | b'\r') {
            b += 1;
        }
        if b < self.pos {
            // Out of order (not expected): count from the start.
            self.pos = 0;
            self.newlines = 0;
        }
        self.newlines += self.bytes[self.pos..b]
            .iter()
            .filter(|&&c| c == b'\n')
            .count();
        self.pos = b;
        1 + self.newlines
    }
}

fn csv_error(e: &csv::Error, path: &Path, bytes: &[u8]) -> Error {
    let location = e.position().map_or(Location::File, |p| {
        Location::Line(LineCounter::new(bytes).line_of(p.byte()))
    });
    let msg = match e.kind() {
        csv::ErrorKind::UnequalLengths {
            expected_len, len, ..
        } => {
            format!("expected {expected_len} fields, got {len}")
        }
        csv::ErrorKind::Utf8 { .. } => "text is not valid UTF-8".to_owned(),
        _ => e.to_string(),
    };
    Error::parse(path, location, msg)
}
