//! Clearance in reports: per frame the body pairs closer than their threshold, per pair the
//! minimum over the run, and the CSV table with a row per pair and frame.

use crate::Report;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// One body pair closer than its clearance threshold in one frame.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ClearanceRecord {
    /// First body's name.
    pub a: String,
    /// Second body's name.
    pub b: String,
    /// Smallest distance between the two surfaces (scene units); 0 when the pair interferes.
    pub distance: f64,
    /// Closest points in world coordinates: on `a`, on `b`.
    pub points: [[f64; 3]; 2],
    /// The triangle pair `[tri_a, tri_b]` the closest points lie on.
    pub triangles: [u32; 2],
    /// True when one closed body lies wholly inside the other (solid mode): `distance` is 0 and
    /// `points` are the closest surface points.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub contained: bool,
}

/// Over the whole run, the clearance of one body pair.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ClearanceSummary {
    /// First body's name.
    pub a: String,
    /// Second body's name.
    pub b: String,
    /// Minimum clearance over the run (0 when the pair interferes in some frame).
    pub min_distance: f64,
    /// The first frame where the minimum occurs.
    pub min_frame: usize,
    /// The closest points at that frame (on `a`, on `b`).
    pub min_points: [[f64; 3]; 2],
    /// Frames in which the pair was closer than its threshold.
    pub frames: usize,
    /// Runs of consecutive frames with clearance 0 (interference), `[first, last]` inclusive.
    pub zero_intervals: Vec<[usize; 2]>,
}

/// Summarises per-frame clearances (`frames`: the frame index and its records): one entry per
/// pair that came closer than its threshold, ordered by minimum clearance, then names.
///
/// ```
/// use frcd_io::{ClearanceRecord, summarize_clearances};
/// let rec = |d: f64| ClearanceRecord { a: "x".into(), b: "y".into(), distance: d, ..Default::default() };
/// let frames = vec![(0, vec![rec(0.004)]), (1, vec![rec(0.0)]), (2, vec![rec(0.0)]), (3, vec![])];
/// let s = summarize_clearances(frames.iter().map(|(i, r)| (*i, r.as_slice())));
/// assert_eq!((s[0].min_distance, s[0].min_frame, s[0].frames), (0.0, 1, 3));
/// assert_eq!(s[0].zero_intervals, vec![[1, 2]]);
/// ```
pub fn summarize_clearances<'a>(
    frames: impl IntoIterator<Item = (usize, &'a [ClearanceRecord])>,
) -> Vec<ClearanceSummary> {
    let mut map: BTreeMap<(&str, &str), ClearanceSummary> = BTreeMap::new();
    for (index, records) in frames {
        for r in records {
            let s = map
                .entry((r.a.as_str(), r.b.as_str()))
                .or_insert_with(|| ClearanceSummary {
                    a: r.a.clone(),
                    b: r.b.clone(),
                    min_distance: f64::INFINITY,
                    min_frame: index,
                    ..Default::default()
                });
            s.frames += 1;
            if r.distance < s.min_distance {
                s.min_distance = r.distance;
                s.min_frame = index;
                s.min_points = r.points;
            }
            if r.distance == 0.0 {
                match s.zero_intervals.last_mut() {
                    Some(last) if last[1] + 1 == index => last[1] = index,
                    _ => s.zero_intervals.push([index, index]),
                }
            }
        }
    }
    let mut v: Vec<ClearanceSummary> = map.into_values().collect();
    v.sort_by(|x, y| {
        x.min_distance
            .total_cmp(&y.min_distance)
            .then_with(|| (&x.a, &x.b).cmp(&(&y.a, &y.b)))
    });
    v
}

fn quote(x: &str) -> String {
    if x.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", x.replace('"', "\"\""))
    } else {
        x.to_owned()
    }
}

/// The CSV report with clearance: one row per body pair and frame where the pair interferes or
/// is closer than its threshold, `frame,time_us,a,b,triangle_pairs,contained,distance,
/// point_a_x,point_a_y,point_a_z,point_b_x,point_b_y,point_b_z,tri_a,tri_b`. An interfering pair
/// without a clearance threshold leaves the clearance columns empty; a frame with neither has
/// one row with empty `a`, `b` so its time is kept (as [`Report::to_csv_string`]).
/// `clearances[k]` belongs to `report.frames[k]` (missing entries mean none).
pub fn clearance_csv(report: &Report, clearances: &[Vec<ClearanceRecord>]) -> String {
    let mut s = String::from(
        "frame,time_us,a,b,triangle_pairs,contained,distance,point_a_x,point_a_y,point_a_z,point_b_x,point_b_y,point_b_z,tri_a,tri_b\n",
    );
    for (k, f) in report.frames.iter().enumerate() {
        let recs: &[ClearanceRecord] = clearances.get(k).map_or(&[], Vec::as_slice);
        // Rows keyed by pair names, interferences first in their order, then clearance-only.
        let mut rows: Vec<(
            &str,
            &str,
            Option<&crate::Interference>,
            Option<&ClearanceRecord>,
        )> = f
            .interferences
            .iter()
            .map(|i| (i.a.as_str(), i.b.as_str(), Some(i), None))
            .collect();
        for r in recs {
            match rows.iter_mut().find(|x| x.0 == r.a && x.1 == r.b) {
                Some(row) => row.3 = Some(r),
                None => rows.push((&r.a, &r.b, None, Some(r))),
            }
        }
        if rows.is_empty() {
            let _ = writeln!(s, "{},{},,,0,false,,,,,,,,,", f.index, f.time_us);
        }
        for (a, b, i, c) in rows {
            let (tp, contained) = i.map_or((0, false), |i| (i.triangle_pairs, i.contained));
            let _ = write!(
                s,
                "{},{},{},{},{},{}",
                f.index,
                f.time_us,
                quote(a),
                quote(b),
                tp,
                contained || c.is_some_and(|c| c.contained)
            );
            match c {
                Some(c) => {
                    let [p, q] = c.points;
                    let _ = writeln!(
                        s,
                        ",{},{},{},{},{},{},{},{},{}",
                        c.distance,
                        p[0],
                        p[1],
                        p[2],
                        q[0],
                        q[1],
                        q[2],
                        c.triangles[0],
                        c.triangles[1]
                    );
                }
                None => s.push_str(",,,,,,,,,\n"),
            }
        }
    }
    s
}
