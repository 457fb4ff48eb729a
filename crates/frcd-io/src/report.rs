//! Interference reports as JSON and CSV.

use crate::Result;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

/// One interfering pair of bodies in one frame.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Interference {
    /// First body's name.
    pub a: String,
    /// Second body's name.
    pub b: String,
    /// Number of touching triangle pairs (0 with `contained` when one solid holds the other).
    pub triangle_pairs: u64,
    /// True when one closed body lies wholly inside the other with no surface contact.
    pub contained: bool,
    /// Intersection segments (world coordinates), when the checker was asked for them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub segments: Vec<[[f64; 3]; 2]>,
    /// The touching triangle pairs `[tri_a, tri_b]` (indices into the bodies' meshes as
    /// loaded), sorted, when the run was asked for them (`frcd check --pairs`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub triangles: Vec<[u32; 2]>,
}

/// The result of one frame.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameReport {
    /// Frame index in the scene.
    pub index: usize,
    /// Detection time of the frame in microseconds.
    pub time_us: f64,
    /// Interfering pairs, in canonical order (by body index of `a`, then `b`).
    pub interferences: Vec<Interference>,
}

/// Over the whole run, when one pair of bodies interfered.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PairSummary {
    /// First body's name.
    pub a: String,
    /// Second body's name.
    pub b: String,
    /// First frame index with interference.
    pub first_frame: usize,
    /// Last frame index with interference.
    pub last_frame: usize,
    /// Number of frames with interference.
    pub frames: usize,
    /// Largest triangle-pair count over those frames.
    pub max_triangle_pairs: u64,
    /// True when, in some frame, one body lay wholly inside the other (solid mode) with no
    /// touching triangle pair.
    #[serde(default)]
    pub contained: bool,
    /// Runs of consecutive interfering frames, `[first, last]` inclusive.
    pub intervals: Vec<[usize; 2]>,
}

/// The units of a report's numbers.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Units {
    /// Lengths (segments): frcd keeps the mesh files' coordinates as they are, so lengths are
    /// in whatever unit the files use.
    pub length: String,
    /// Times (`time_us`, `median_time_us`).
    pub time: String,
}

impl Default for Units {
    fn default() -> Self {
        Self {
            length: "as in the mesh files".into(),
            time: "microseconds, rounded to 0.1".into(),
        }
    }
}

/// An interference-check report.
///
/// JSON: `{"frcd_version", "backend", "mode", "units", "frame_range", "frames": [{"index", "time_us", "interferences": [{"a", "b",
/// "triangle_pairs", "contained"}]}], "pairs": [...]}` (plus optional fields). CSV: one row
/// per interference, `frame,time_us,a,b,triangle_pairs,contained`; a frame without any has one
/// row with empty `a`, `b` so its time is kept.
///
/// ```
/// use frcd_io::{Report, FrameReport, Interference};
/// let mut r = Report::new("cpu", "exact");
/// for index in 0..4 {
///     let hit = index == 1 || index == 2;
///     r.frames.push(FrameReport { index, time_us: 10.0, interferences: if hit {
///         vec![Interference { a: "x".into(), b: "y".into(), triangle_pairs: 3, ..Default::default() }]
///     } else { vec![] } });
/// }
/// r.summarize();
/// assert_eq!(r.pairs[0].intervals, vec![[1, 2]]);
/// ```
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// Version of frcd that wrote the report.
    #[serde(default)]
    pub frcd_version: String,
    /// Backend that produced the report (`cpu`, `gpgpu`, `image`, `hybrid`, ...).
    pub backend: String,
    /// `exact` or `fast`.
    pub mode: String,
    /// The scene file, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scene: Option<String>,
    /// Units of lengths and times.
    #[serde(default)]
    pub units: Units,
    /// The frames checked, `[first, last]` inclusive (`None` when no frame was checked).
    #[serde(default)]
    pub frame_range: Option<[usize; 2]>,
    /// Per-frame results.
    pub frames: Vec<FrameReport>,
    /// Per-pair summary (fill with [`Report::summarize`]).
    #[serde(default)]
    pub pairs: Vec<PairSummary>,
}

impl Report {
    /// An empty report for a backend and mode.
    pub fn new(backend: impl Into<String>, mode: impl Into<String>) -> Self {
        Self {
            frcd_version: env!("CARGO_PKG_VERSION").into(),
            backend: backend.into(),
            mode: mode.into(),
            ..Default::default()
        }
    }

    /// Fills [`Report::pairs`] from the frames: first and last frame, frame count, largest
    /// triangle-pair count and runs of consecutive frames for every pair that interfered,
    /// ordered by first frame, then names.
    pub fn summarize(&mut self) {
        let mut map: BTreeMap<(String, String), PairSummary> = BTreeMap::new();
        for f in &self.frames {
            for i in &f.interferences {
                let s = map
                    .entry((i.a.clone(), i.b.clone()))
                    .or_insert_with(|| PairSummary {
                        a: i.a.clone(),
                        b: i.b.clone(),
                        first_frame: f.index,
                        last_frame: f.index,
                        ..Default::default()
                    });
                s.first_frame = s.first_frame.min(f.index);
                s.last_frame = s.last_frame.max(f.index);
                s.frames += 1;
                s.max_triangle_pairs = s.max_triangle_pairs.max(i.triangle_pairs);
                s.contained |= i.contained;
                match s.intervals.last_mut() {
                    Some(last) if last[1] + 1 == f.index => last[1] = f.index,
                    _ => s.intervals.push([f.index, f.index]),
                }
            }
        }
        let mut pairs: Vec<PairSummary> = map.into_values().collect();
        pairs.sort_by(|x, y| (x.first_frame, &x.a, &x.b).cmp(&(y.first_frame, &y.a, &y.b)));
        self.pairs = pairs;
    }

    /// Median frame time in microseconds (`None` without frames).
    pub fn median_time_us(&self) -> Option<f64> {
        let mut t: Vec<f64> = self.frames.iter().map(|f| f.time_us).collect();
        if t.is_empty() {
            return None;
        }
        t.sort_by(f64::total_cmp);
        Some(t[t.len() / 2])
    }

    /// Pretty-printed JSON.
    pub fn to_json_string(&self) -> String {
        serde_json::to_string_pretty(self).expect("a report always serialises")
    }

    /// Writes the JSON report atomically (see [`crate::write_atomic`]).
    pub fn write_json(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        crate::write_atomic(path, (self.to_json_string() + "\n").as_bytes())
    }

    /// Reads a JSON report.
    pub fn read_json(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let text = crate::read_text_limited(path, crate::MAX_JSON_BYTES)?;
        serde_json::from_str(&text).map_err(|e| crate::scene::json_error(&e, path))
    }

    /// The CSV text (see the type's documentation).
    pub fn to_csv_string(&self) -> String {
        let mut s = String::from("frame,time_us,a,b,triangle_pairs,contained\n");
        let quote = |x: &str| {
            if x.contains([',', '"', '\n']) {
                format!("\"{}\"", x.replace('"', "\"\""))
            } else {
                x.to_owned()
            }
        };
        for f in &self.frames {
            if f.interferences.is_empty() {
                let _ = writeln!(s, "{},{},,,0,false", f.index, f.time_us);
            }
            for i in &f.interferences {
                let _ = writeln!(
                    s,
                    "{},{},{},{},{},{}",
                    f.index,
                    f.time_us,
                    quote(&i.a),
                    quote(&i.b),
                    i.triangle_pairs,
                    i.contained
                );
            }
        }
        s
    }

    /// Writes the CSV report atomically (see [`crate::write_atomic`]).
    pub fn write_csv(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        crate::write_atomic(path, self.to_csv_string().as_bytes())
    }
}
