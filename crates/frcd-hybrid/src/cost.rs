//! The cost model: measured per-operation costs of each backend on the present machine, and the
//! thresholds derived from them.

use serde::{Deserialize, Serialize};
use std::path::Path;

/// Measured costs of the stages' backends (microseconds and nanoseconds of wall time) on one
/// machine. `frcd calibrate` measures it ([`crate::calibrate`]) and stores it as JSON; the
/// scheduler derives its thresholds from it. GPU fields are `None` when no adapter was found at
/// calibration: those backends are then never chosen automatically.
///
/// The model is linear on purpose: a fixed cost per GPU submission (dispatch, one readback)
/// plus a cost per unit of work. The units are what the scheduler knows before it runs a stage:
/// body pairs for the broad phase, triangles of the two bodies for a pair query.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CostModel {
    /// Adapter the GPU figures were measured on (empty when none).
    #[serde(default)]
    pub adapter: String,
    /// Worker threads of the CPU figures (rayon's pool size at calibration).
    pub threads: usize,
    /// CPU sweep and prune: nanoseconds per body (sort under coherence + sweep).
    pub cpu_broad_ns_per_body: f64,
    /// GPU all-pairs box pass: fixed microseconds per pass.
    pub gpu_broad_us: Option<f64>,
    /// GPU all-pairs box pass: nanoseconds per body pair.
    pub gpu_broad_ns_per_pair: Option<f64>,
    /// CPU exact pair query (OBB trees): nanoseconds per triangle of the two bodies, measured on
    /// pairs whose boxes overlap, one thread.
    pub cpu_narrow_ns_per_triangle: f64,
    /// GPU exact pair query: fixed microseconds per query (one submission, one readback).
    pub gpu_narrow_us: Option<f64>,
    /// GPU exact pair query: nanoseconds per triangle of the two bodies.
    pub gpu_narrow_ns_per_triangle: Option<f64>,
    /// Image-space pass (with the colliding set): microseconds per body pair.
    pub image_us: Option<f64>,
}

impl Default for CostModel {
    /// Conservative figures for an uncalibrated machine: the CPU figures of a 2-core laptop,
    /// GPU submissions at 300 µs (so GPU stages are chosen only for heavy work).
    fn default() -> Self {
        Self {
            adapter: String::new(),
            threads: 2,
            cpu_broad_ns_per_body: 40.0,
            gpu_broad_us: Some(300.0),
            gpu_broad_ns_per_pair: Some(0.002),
            cpu_narrow_ns_per_triangle: 40.0,
            gpu_narrow_us: Some(300.0),
            gpu_narrow_ns_per_triangle: Some(5.0),
            image_us: Some(1000.0),
        }
    }
}

/// A cost model could not be read or written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CostModelError {
    /// The file could not be read or written.
    #[error("cost model file {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
    /// The file is not a cost model.
    #[error("cost model file {path}: {source}")]
    Json {
        /// The file.
        path: String,
        /// The cause (with line and column).
        source: serde_json::Error,
    },
    /// A figure is negative or not finite.
    #[error("cost model file {path}: field {field} is {value}, expected a finite value >= 0")]
    Invalid {
        /// The file.
        path: String,
        /// The field.
        field: &'static str,
        /// Its value.
        value: f64,
    },
}

impl CostModel {
    /// Reads a model written by [`CostModel::save`] (or by hand) and checks every figure.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, CostModelError> {
        let p = path.as_ref();
        let name = p.display().to_string();
        let text = std::fs::read_to_string(p).map_err(|source| CostModelError::Io {
            path: name.clone(),
            source,
        })?;
        let model: CostModel =
            serde_json::from_str(&text).map_err(|source| CostModelError::Json {
                path: name.clone(),
                source,
            })?;
        model.validate(&name)?;
        Ok(model)
    }

    /// Writes the model as pretty JSON.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), CostModelError> {
        let p = path.as_ref();
        let text = serde_json::to_string_pretty(self).expect("plain data serializes");
        std::fs::write(p, text + "\n").map_err(|source| CostModelError::Io {
            path: p.display().to_string(),
            source,
        })
    }

    fn validate(&self, path: &str) -> Result<(), CostModelError> {
        let fields: [(&'static str, Option<f64>); 8] = [
            ("cpu_broad_ns_per_body", Some(self.cpu_broad_ns_per_body)),
            ("gpu_broad_us", self.gpu_broad_us),
            ("gpu_broad_ns_per_pair", self.gpu_broad_ns_per_pair),
            (
                "cpu_narrow_ns_per_triangle",
                Some(self.cpu_narrow_ns_per_triangle),
            ),
            ("gpu_narrow_us", self.gpu_narrow_us),
            (
                "gpu_narrow_ns_per_triangle",
                self.gpu_narrow_ns_per_triangle,
            ),
            ("image_us", self.image_us),
            ("threads", Some(self.threads as f64)),
        ];
        for (field, v) in fields {
            if let Some(value) = v {
                if !value.is_finite() || value < 0.0 {
                    return Err(CostModelError::Invalid {
                        path: path.to_string(),
                        field,
                        value,
                    });
                }
            }
        }
        Ok(())
    }

    /// A model with every GPU figure removed (CPU only).
    pub fn cpu_only(mut self) -> Self {
        self.gpu_broad_us = None;
        self.gpu_broad_ns_per_pair = None;
        self.gpu_narrow_us = None;
        self.gpu_narrow_ns_per_triangle = None;
        self.image_us = None;
        self
    }

    /// Smallest body count from which the GPU box pass is predicted to beat sweep and prune
    /// (`None`: never, or no GPU figures).
    pub fn gpu_broad_min_bodies(&self) -> Option<usize> {
        let (fixed, per_pair) = (self.gpu_broad_us?, self.gpu_broad_ns_per_pair?);
        // Sweep and prune is ~linear in n under coherence; the GPU pass is all pairs.
        (2..=1_000_000usize).find(|&n| {
            let nf = n as f64;
            let gpu = fixed * 1e3 + per_pair * nf * (nf - 1.0) / 2.0;
            gpu < self.cpu_broad_ns_per_body * nf
        })
    }

    /// True when the GPU exact pair query of a pair with `triangles` triangles in all is
    /// predicted to beat the CPU query (the CPU figure divided over `threads` workers, since CPU
    /// pairs run in parallel while GPU pairs run one after the other).
    pub fn prefer_gpu_narrow(&self, triangles: usize) -> bool {
        match (self.gpu_narrow_us, self.gpu_narrow_ns_per_triangle) {
            (Some(fixed), Some(per)) => {
                let t = triangles as f64;
                let cpu = self.cpu_narrow_ns_per_triangle * t / self.threads.max(1) as f64;
                fixed * 1e3 + per * t < cpu
            }
            _ => false,
        }
    }

    /// Smallest triangle count of a pair from which the GPU pair query is preferred (`None`:
    /// never below 2^32).
    pub fn gpu_narrow_min_triangles(&self) -> Option<usize> {
        let mut lo = 1usize;
        let hi = 1usize << 32;
        if !self.prefer_gpu_narrow(hi) {
            return None;
        }
        let mut h = hi;
        while lo < h {
            let mid = lo + (h - lo) / 2;
            if self.prefer_gpu_narrow(mid) {
                h = mid;
            } else {
                lo = mid + 1;
            }
        }
        Some(lo)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thresholds_follow_the_figures() {
        let m = CostModel::default();
        let n = m
            .gpu_broad_min_bodies()
            .expect("large scenes favour the GPU");
        assert!(n > 100, "{n}");
        assert!(!m.prefer_gpu_narrow(100));
        let t = m.gpu_narrow_min_triangles().expect("threshold");
        assert!(m.prefer_gpu_narrow(t) && !m.prefer_gpu_narrow(t - 1));
        let cpu = m.clone().cpu_only();
        assert_eq!(cpu.gpu_broad_min_bodies(), None);
        assert_eq!(cpu.gpu_narrow_min_triangles(), None);
    }

    #[test]
    fn json_round_trip_and_bad_files() {
        let dir = std::env::temp_dir().join(format!("frcd-hybrid-cost-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("cost.json");
        let m = CostModel::default();
        m.save(&p).unwrap();
        assert_eq!(CostModel::load(&p).unwrap(), m);
        std::fs::write(&p, "{\"threads\": 2}").unwrap();
        assert!(matches!(
            CostModel::load(&p),
            Err(CostModelError::Json { .. })
        ));
        let mut bad = m.clone();
        bad.cpu_narrow_ns_per_triangle = -1.0;
        bad.save(&p).unwrap();
        let e = CostModel::load(&p).unwrap_err();
        assert!(e.to_string().contains("cpu_narrow_ns_per_triangle"), "{e}");
        assert!(matches!(
            CostModel::load(dir.join("missing.json")),
            Err(CostModelError::Io { .. })
        ));
        std::fs::remove_dir_all(&dir).ok();
    }
}
