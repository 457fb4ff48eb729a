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
/// bodies for the broad phase (both backends' broad phases sort and sweep, so their cost grows
/// about linearly with the bodies), triangles of the two bodies for a pair query.
///
/// Files written before the GPU box pass was modelled per body hold `gpu_broad_ns_per_pair`
/// instead of [`CostModel::gpu_broad_ns_per_body`]: they load, without a GPU box-pass figure
/// (so the CPU broad phase is kept) until `frcd calibrate` is run again.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CostModel {
    /// Adapter the GPU figures were measured on (empty when none).
    #[serde(default)]
    pub adapter: String,
    /// Worker threads of the CPU figures (rayon's pool size at calibration).
    pub threads: usize,
    /// CPU broad phase ([`frcd_obb::overlapping_boxes`], one thread, a fresh frame):
    /// nanoseconds per body.
    pub cpu_broad_ns_per_body: f64,
    /// GPU box pass (`frcd-gpgpu`'s sort-and-sweep, one submission and one readback): fixed
    /// microseconds per pass.
    pub gpu_broad_us: Option<f64>,
    /// GPU box pass: nanoseconds per body beyond the fixed cost.
    #[serde(default)]
    pub gpu_broad_ns_per_body: Option<f64>,
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
    /// GPU submissions at 300 µs (so GPU stages are chosen only for heavy work). The broad
    /// phase's per-body figures, 300 ns on the CPU and 150 ns on the GPU, are rounded from an
    /// H200 host's bench (CPU `overlapping_boxes` 267-373 ns per body on one thread, the GPU
    /// sort-and-sweep about 164, 2026-11-28): with the fixed cost, the GPU box pass from 2,000
    /// bodies on.
    fn default() -> Self {
        Self {
            adapter: String::new(),
            threads: 2,
            cpu_broad_ns_per_body: 300.0,
            gpu_broad_us: Some(300.0),
            gpu_broad_ns_per_body: Some(150.0),
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
    /// The path is not a regular file (a FIFO, a device, a directory): refused unread.
    #[error("cost model file {path}: not a regular file")]
    NotAFile {
        /// The path.
        path: String,
    },
    /// The file is longer than [`CostModel::MAX_FILE_BYTES`].
    #[error("cost model file {path}: longer than {limit} bytes, not a cost model")]
    TooLarge {
        /// The file.
        path: String,
        /// The limit in bytes.
        limit: u64,
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
    /// The largest cost model file [`CostModel::load`] reads: a model is a few hundred bytes, so
    /// anything near this is not one (and `/dev/zero` is refused before it is read).
    pub const MAX_FILE_BYTES: u64 = 1 << 20;

    /// Reads a model written by [`CostModel::save`] (or by hand) and checks every figure.
    ///
    /// Only a regular file of at most [`CostModel::MAX_FILE_BYTES`] is read: a FIFO, a device
    /// or a directory is refused with [`CostModelError::NotAFile`] before it is opened for
    /// reading, a longer file with [`CostModelError::TooLarge`].
    pub fn load(path: impl AsRef<Path>) -> Result<Self, CostModelError> {
        use std::io::Read;
        let p = path.as_ref();
        let name = p.display().to_string();
        let io = |source| CostModelError::Io {
            path: name.clone(),
            source,
        };
        if !std::fs::metadata(p).map_err(io)?.is_file() {
            return Err(CostModelError::NotAFile { path: name });
        }
        let mut text = String::new();
        std::fs::File::open(p)
            .map_err(io)?
            // One byte past the limit tells a file at the limit from a longer one.
            .take(Self::MAX_FILE_BYTES + 1)
            .read_to_string(&mut text)
            .map_err(io)?;
        if text.len() as u64 > Self::MAX_FILE_BYTES {
            return Err(CostModelError::TooLarge {
                path: name,
                limit: Self::MAX_FILE_BYTES,
            });
        }
        let model: CostModel =
            serde_json::from_str(&text).map_err(|source| CostModelError::Json {
                path: name.clone(),
                source,
            })?;
        model.validate(&name)?;
        Ok(model)
    }

    /// Writes the model as pretty JSON, atomically: to a temporary file in the same folder,
    /// then renamed over `path`, so a failed write (a full disk) never leaves a truncated model
    /// or destroys the previous one.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), CostModelError> {
        use std::io::Write;
        let p = path.as_ref();
        let io = |source| CostModelError::Io {
            path: p.display().to_string(),
            source,
        };
        let text = serde_json::to_string_pretty(self).expect("plain data serializes");
        let file_name = p.file_name().ok_or_else(|| {
            io(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "the path names no file",
            ))
        })?;
        let mut tmp_name = std::ffi::OsString::from(".");
        tmp_name.push(file_name);
        tmp_name.push(format!(".{}.tmp", std::process::id()));
        let tmp = p.with_file_name(tmp_name);
        let written = std::fs::File::create(&tmp).and_then(|mut f| {
            f.write_all(text.as_bytes())?;
            f.write_all(b"\n")?;
            f.sync_all()
        });
        match written.and_then(|()| std::fs::rename(&tmp, p)) {
            Ok(()) => Ok(()),
            Err(e) => {
                // Never leave the half-written temporary behind.
                std::fs::remove_file(&tmp).ok();
                Err(io(e))
            }
        }
    }

    fn validate(&self, path: &str) -> Result<(), CostModelError> {
        let fields: [(&'static str, Option<f64>); 8] = [
            ("cpu_broad_ns_per_body", Some(self.cpu_broad_ns_per_body)),
            ("gpu_broad_us", self.gpu_broad_us),
            ("gpu_broad_ns_per_body", self.gpu_broad_ns_per_body),
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
            if let Some(value) = v
                && (!value.is_finite() || value < 0.0)
            {
                return Err(CostModelError::Invalid {
                    path: path.to_string(),
                    field,
                    value,
                });
            }
        }
        Ok(())
    }

    /// A model with every GPU figure removed (CPU only).
    pub fn cpu_only(mut self) -> Self {
        self.gpu_broad_us = None;
        self.gpu_broad_ns_per_body = None;
        self.gpu_narrow_us = None;
        self.gpu_narrow_ns_per_triangle = None;
        self.image_us = None;
        self
    }

    /// Smallest body count from which the GPU box pass is predicted to beat the CPU broad
    /// phase, and keeps beating it for every larger count (`None`: never, or no GPU figures).
    /// Both are linear in the bodies, the GPU's with a fixed cost on top, so the GPU wins from
    /// `fixed / (cpu − gpu)` bodies on when its per-body cost is the lower one.
    pub fn gpu_broad_min_bodies(&self) -> Option<usize> {
        let (fixed_ns, gpu) = (self.gpu_broad_us? * 1e3, self.gpu_broad_ns_per_body?);
        let saved = self.cpu_broad_ns_per_body - gpu;
        if saved <= 0.0 {
            return None;
        }
        // The smallest n with fixed + gpu·n < cpu·n, at least 2.
        let n = (fixed_ns / saved).floor() + 1.0;
        (n <= 1e15).then(|| (n as usize).max(2))
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
        // The threshold is where the predicted costs cross, and the GPU stays ahead above it.
        let cost = |n: usize| {
            let nf = n as f64;
            (
                m.gpu_broad_us.unwrap() * 1e3 + m.gpu_broad_ns_per_body.unwrap() * nf,
                m.cpu_broad_ns_per_body * nf,
            )
        };
        for k in [n, n + 1, 10 * n, 1000 * n] {
            let (gpu, cpu) = cost(k);
            assert!(gpu < cpu, "{k} bodies: GPU {gpu} ns against CPU {cpu} ns");
        }
        let (gpu, cpu) = cost(n - 1);
        assert!(
            gpu >= cpu,
            "{} bodies: GPU {gpu} ns against CPU {cpu} ns",
            n - 1
        );
        // A GPU slower per body than the CPU never wins, however many bodies.
        let slow = CostModel {
            gpu_broad_ns_per_body: Some(m.cpu_broad_ns_per_body),
            ..m.clone()
        };
        assert_eq!(slow.gpu_broad_min_bodies(), None);
        // A free GPU pass wins from two bodies on.
        let free = CostModel {
            gpu_broad_us: Some(0.0),
            gpu_broad_ns_per_body: Some(0.0),
            ..m.clone()
        };
        assert_eq!(free.gpu_broad_min_bodies(), Some(2));
        assert!(!m.prefer_gpu_narrow(100));
        let t = m.gpu_narrow_min_triangles().expect("threshold");
        assert!(m.prefer_gpu_narrow(t) && !m.prefer_gpu_narrow(t - 1));
        let cpu = m.clone().cpu_only();
        assert_eq!(cpu.gpu_broad_min_bodies(), None);
        assert_eq!(cpu.gpu_narrow_min_triangles(), None);
    }

    /// A fresh folder in the system temp folder, removed with its contents when the guard
    /// drops (at the end of the test, pass or fail).
    struct TempDir(std::path::PathBuf);

    impl std::ops::Deref for TempDir {
        type Target = Path;
        fn deref(&self) -> &Path {
            &self.0
        }
    }

    impl AsRef<Path> for TempDir {
        fn as_ref(&self) -> &Path {
            &self.0
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    fn temp_dir(name: &str) -> TempDir {
        let dir = TempDir(std::env::temp_dir().join(format!("{name}-{}", std::process::id())));
        let _ = std::fs::remove_dir_all(&*dir);
        std::fs::create_dir_all(&*dir).unwrap();
        dir
    }

    #[test]
    fn json_round_trip_and_bad_files() {
        let dir = temp_dir("frcd-hybrid-cost");
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
    }

    #[test]
    fn files_of_the_all_pairs_model_load_without_a_gpu_box_pass_figure() {
        // Before 2026-11-28 the GPU box pass was costed per body pair; such a file loads, its
        // per-pair figure is not taken as a per-body one, and the box pass stays on the CPU.
        let dir = temp_dir("frcd-hybrid-cost-old");
        let p = dir.join("old.json");
        std::fs::write(
            &p,
            r#"{"adapter": "NVIDIA H200", "threads": 16, "cpu_broad_ns_per_body": 40.0,
                "gpu_broad_us": 300.0, "gpu_broad_ns_per_pair": 0.002,
                "cpu_narrow_ns_per_triangle": 40.0, "gpu_narrow_us": 300.0,
                "gpu_narrow_ns_per_triangle": 5.0, "image_us": 1000.0}"#,
        )
        .unwrap();
        let m = CostModel::load(&p).unwrap();
        assert_eq!(
            (m.gpu_broad_us, m.gpu_broad_ns_per_body),
            (Some(300.0), None)
        );
        assert_eq!(m.gpu_broad_min_bodies(), None);
        // The rest of the model is kept.
        assert_eq!(m.gpu_narrow_ns_per_triangle, Some(5.0));
    }

    #[test]
    fn load_refuses_non_files_and_huge_files_unread() {
        let dir = temp_dir("frcd-hybrid-cost-big");
        // A directory and (on Unix) an endless device are refused before any read.
        assert!(matches!(
            CostModel::load(&dir),
            Err(CostModelError::NotAFile { .. })
        ));
        if Path::new("/dev/zero").exists() {
            assert!(matches!(
                CostModel::load("/dev/zero"),
                Err(CostModelError::NotAFile { .. })
            ));
        }
        // A file one byte over the limit is refused by size, not parsed.
        let big = dir.join("big.json");
        std::fs::write(&big, vec![b' '; CostModel::MAX_FILE_BYTES as usize + 1]).unwrap();
        let e = CostModel::load(&big).unwrap_err();
        assert!(matches!(e, CostModelError::TooLarge { .. }), "{e}");
        // At the limit it is read (and fails only as JSON: blanks are no model).
        std::fs::write(&big, vec![b' '; CostModel::MAX_FILE_BYTES as usize]).unwrap();
        assert!(matches!(
            CostModel::load(&big),
            Err(CostModelError::Json { .. })
        ));
    }

    #[test]
    fn save_is_atomic_and_leaves_no_temporary() {
        let dir = temp_dir("frcd-hybrid-cost-save");
        let p = dir.join("cost.json");
        let m = CostModel::default();
        m.save(&p).unwrap();
        let mut other = m.clone();
        other.threads = 7;
        other.save(&p).unwrap();
        assert_eq!(CostModel::load(&p).unwrap(), other);
        // Only the model is in the folder: the temporary was renamed, not left behind.
        let names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("cost.json")]);
        // A save that cannot happen (the target is a directory) keeps the folder clean and
        // reports an error naming the path.
        let sub = dir.join("sub");
        std::fs::create_dir_all(&sub).unwrap();
        let e = m.save(&sub).unwrap_err();
        assert!(e.to_string().contains("sub"), "{e}");
        assert!(
            std::fs::read_dir(&dir).unwrap().count() == 2,
            "no temporary left"
        );
    }
}
