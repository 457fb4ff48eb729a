//! Clearance thresholds of a scene: a scene-wide `"clearance"` and per-pair `"clearances"`.
//!
//! ```json
//! {"bodies": [...],
//!  "clearance": 0.005,
//!  "clearances": [{"a": "brake_block_1L", "b": "wheelset_1", "threshold": 0.01}]}
//! ```
//!
//! Thresholds are lengths in the scene's unit (the mesh files' coordinates). A pair of bodies
//! closer than its threshold reports its distance each frame (interfering pairs report 0). The
//! pair's own threshold wins over the scene-wide one. Refused, each with a typed error naming
//! the entry: a negative or non-finite threshold ([`crate::Error::BadClearance`]), an unknown
//! body ([`crate::Error::UnknownBody`]), a pair naming one body twice, a pair given twice, an
//! excluded pair and a pair of two static bodies (neither is ever checked, so a threshold there
//! would be silently ignored).

use crate::{Error, Result, SceneFile};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::Path;

/// A per-pair clearance threshold as written in a scene file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClearanceSpec {
    /// First body's name.
    pub a: String,
    /// Second body's name.
    pub b: String,
    /// Threshold (scene units, `>= 0`, finite).
    pub threshold: f64,
}

/// The clearance thresholds of a loaded scene, by body index.
///
/// ```
/// use frcd_io::Clearances;
/// let c = Clearances { default: Some(0.005), pairs: vec![(1, 3, 0.01)] };
/// assert_eq!(c.threshold(3, 1), Some(0.01));
/// assert_eq!(c.threshold(0, 2), Some(0.005));
/// assert_eq!(c.with_default(None).threshold(0, 2), None);
/// assert_eq!(c.max_threshold(), Some(0.01));
/// ```
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Clearances {
    /// Scene-wide threshold for every checked pair without its own.
    pub default: Option<f64>,
    /// Per-pair thresholds `(a, b, threshold)`, `a < b`, sorted by `(a, b)`, no pair twice.
    pub pairs: Vec<(usize, usize, f64)>,
}

impl Clearances {
    /// The threshold of the pair `a`, `b` (either order): its own, else the scene-wide one.
    pub fn threshold(&self, a: usize, b: usize) -> Option<f64> {
        let key = (a.min(b), a.max(b));
        match self.pairs.binary_search_by(|p| (p.0, p.1).cmp(&key)) {
            Ok(i) => Some(self.pairs[i].2),
            Err(_) => self.default,
        }
    }

    /// The same per-pair thresholds with another scene-wide one (`frcd check --clearance`
    /// replaces the scene's `"clearance"`; `None` keeps only the per-pair thresholds).
    pub fn with_default(&self, default: Option<f64>) -> Self {
        Self {
            default,
            pairs: self.pairs.clone(),
        }
    }

    /// True when no pair has a threshold.
    pub fn is_empty(&self) -> bool {
        self.default.is_none() && self.pairs.is_empty()
    }

    /// The largest threshold of any pair (`None` when [`Clearances::is_empty`]).
    pub fn max_threshold(&self) -> Option<f64> {
        self.pairs
            .iter()
            .map(|p| p.2)
            .chain(self.default)
            .reduce(f64::max)
    }
}

/// Checks a clearance threshold: finite and `>= 0` (0 reports interfering pairs only). The error
/// says what is wrong.
///
/// ```
/// assert_eq!(frcd_io::check_clearance(0.005), Ok(0.005));
/// assert!(frcd_io::check_clearance(-1e-3).unwrap_err().contains("negative"));
/// assert!(frcd_io::check_clearance(f64::NAN).is_err());
/// ```
pub fn check_clearance(value: f64) -> std::result::Result<f64, String> {
    if !value.is_finite() {
        return Err(format!("threshold {value} is not finite"));
    }
    if value < 0.0 {
        return Err(format!(
            "threshold {value} is negative (a clearance is a distance, >= 0)"
        ));
    }
    // -0.0 compares equal to 0: store +0.
    Ok(value.max(0.0))
}

/// Resolves the scene file's thresholds against its bodies (`index`: name to body index,
/// `is_static` per body, `exclude`: sorted excluded pairs `a < b`).
pub(crate) fn resolve(
    spec: &SceneFile,
    path: &Path,
    index: &HashMap<&str, usize>,
    is_static: &[bool],
    exclude: &[(usize, usize)],
) -> Result<Clearances> {
    let bad = |place: String, msg: String| Error::BadClearance {
        path: path.into(),
        place,
        msg,
    };
    let default = spec
        .clearance
        .map(|v| check_clearance(v).map_err(|msg| bad("clearance".into(), msg)))
        .transpose()?;
    let mut pairs: Vec<(usize, usize, f64)> = Vec::with_capacity(spec.clearances.len());
    let mut given: HashMap<(usize, usize), usize> = HashMap::new();
    for (k, c) in spec.clearances.iter().enumerate() {
        let place = || format!("clearances entry {k}");
        let lookup = |name: &str| {
            index.get(name).copied().ok_or_else(|| Error::UnknownBody {
                path: path.into(),
                name: name.to_owned(),
                place: place(),
            })
        };
        let (ia, ib) = (lookup(&c.a)?, lookup(&c.b)?);
        let threshold = check_clearance(c.threshold).map_err(|msg| bad(place(), msg))?;
        if ia == ib {
            return Err(bad(place(), format!("names body '{}' twice", c.a)));
        }
        let key = (ia.min(ib), ia.max(ib));
        if exclude.binary_search(&key).is_ok() {
            return Err(bad(
                place(),
                format!(
                    "the pair '{}' / '{}' is excluded from checking (\"exclude\"), so it has no clearance",
                    c.a, c.b
                ),
            ));
        }
        if is_static[ia] && is_static[ib] {
            return Err(bad(
                place(),
                format!(
                    "'{}' and '{}' are both static: the pair is never checked",
                    c.a, c.b
                ),
            ));
        }
        if let Some(first) = given.insert(key, k) {
            return Err(bad(
                place(),
                format!(
                    "the pair '{}' / '{}' already has a threshold (clearances entry {first})",
                    c.a, c.b
                ),
            ));
        }
        pairs.push((key.0, key.1, threshold));
    }
    pairs.sort_by_key(|p| (p.0, p.1));
    Ok(Clearances { default, pairs })
}
