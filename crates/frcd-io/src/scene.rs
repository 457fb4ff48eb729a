//! Scene files: bodies, meshes, exclusions and a trajectory of poses.

use crate::{Error, Result, Trajectory};
use frcd_geom::{DQuat, DVec3, Pose, TriMesh};
use serde::de::{MapAccess, Visitor};
use serde::ser::SerializeMap;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// How far a quaternion's length may be from 1 before it is refused (it is then normalised).
/// Files print a handful of digits; 1e-6 accepts 7 significant digits.
pub const UNIT_QUATERNION_TOLERANCE: f64 = 1e-6;

/// A pose as written in files: translation `t` and unit quaternion `q` = `[x, y, z, w]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseSpec {
    /// Translation `[x, y, z]`.
    pub t: [f64; 3],
    /// Rotation as a unit quaternion `[x, y, z, w]`.
    pub q: [f64; 4],
}

impl Default for PoseSpec {
    fn default() -> Self {
        Self {
            t: [0.0; 3],
            q: [0.0, 0.0, 0.0, 1.0],
        }
    }
}

impl PoseSpec {
    /// The written form of a pose (quaternion as stored, not renormalised).
    pub fn from_pose(pose: &Pose) -> Self {
        let q = pose.rotation;
        Self {
            t: pose.translation.to_array(),
            q: [q.x, q.y, q.z, q.w],
        }
    }

    /// Checks the pose (finite, unit quaternion within [`UNIT_QUATERNION_TOLERANCE`]) and
    /// returns it with the quaternion normalised; the error says what is wrong.
    pub fn to_pose(&self) -> std::result::Result<Pose, String> {
        pose_from_parts(self.t, self.q)
    }
}

pub(crate) fn pose_from_parts(t: [f64; 3], q: [f64; 4]) -> std::result::Result<Pose, String> {
    if t.iter().any(|x| !x.is_finite()) {
        return Err(format!("translation {t:?} is not finite"));
    }
    if q.iter().any(|x| !x.is_finite()) {
        return Err(format!("quaternion {q:?} is not finite"));
    }
    let quat = DQuat::from_xyzw(q[0], q[1], q[2], q[3]);
    let len = quat.length();
    if (len - 1.0).abs() > UNIT_QUATERNION_TOLERANCE {
        return Err(format!(
            "quaternion {q:?} has length {len}, not 1 (tolerance {UNIT_QUATERNION_TOLERANCE})"
        ));
    }
    Ok(Pose {
        translation: DVec3::from_array(t),
        rotation: quat / len,
    })
}

/// One body of a scene file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneBody {
    /// Unique name.
    pub name: String,
    /// Mesh file (`.stl` or `.obj`), relative to the scene file's folder.
    pub mesh: String,
    /// A static body never moves (frames may not list it); default `false`.
    #[serde(rename = "static", default)]
    pub is_static: bool,
    /// Pose before the first frame; default identity.
    #[serde(default)]
    pub pose: PoseSpec,
}

/// The bodies one frame moves, with their new world poses, in file order.
///
/// Serialised as a JSON object `{"<body>": {"t": [...], "q": [...]}, ...}`; a body named twice
/// in one frame is an error, not a silent overwrite.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FramePoses(pub Vec<(String, PoseSpec)>);

impl Serialize for FramePoses {
    fn serialize<S: Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        let mut map = s.serialize_map(Some(self.0.len()))?;
        for (name, pose) in &self.0 {
            map.serialize_entry(name, pose)?;
        }
        map.end()
    }
}

impl<'de> Deserialize<'de> for FramePoses {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = FramePoses;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an object mapping body names to poses")
            }
            fn visit_map<A: MapAccess<'de>>(
                self,
                mut map: A,
            ) -> std::result::Result<FramePoses, A::Error> {
                let mut out: Vec<(String, PoseSpec)> = Vec::new();
                while let Some((name, pose)) = map.next_entry::<String, PoseSpec>()? {
                    if out.iter().any(|(n, _)| *n == name) {
                        return Err(serde::de::Error::custom(format!(
                            "body '{name}' is listed twice in one frame"
                        )));
                    }
                    out.push((name, pose));
                }
                Ok(FramePoses(out))
            }
        }
        d.deserialize_map(V)
    }
}

/// The JSON scene file, as written:
///
/// ```json
/// {"bodies": [{"name": "a", "mesh": "a.stl", "static": false,
///              "pose": {"t": [0, 0, 0], "q": [0, 0, 0, 1]}}],
///  "exclude": [["a", "b"]],
///  "trajectory": "trajectory.csv",
///  "frames": [{"a": {"t": [0, 0, 0.1], "q": [0, 0, 0, 1]}}]}
/// ```
///
/// A frame lists the bodies that move, with world poses; the others keep their last pose.
/// `trajectory` (optional, an frcd extension) names a CSV file whose rows are merged into the
/// frames (see [`Trajectory`]). Unknown fields are refused, so typos do not pass silently.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// The bodies.
    pub bodies: Vec<SceneBody>,
    /// Pairs of body names never to test against each other (parts assembled in contact).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub exclude: Vec<[String; 2]>,
    /// CSV trajectory file, relative to the scene file's folder.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trajectory: Option<String>,
    /// Per frame, the bodies that move.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub frames: Vec<FramePoses>,
    /// Scene-wide clearance threshold (scene units; see [`crate::Clearances`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clearance: Option<f64>,
    /// Per-pair clearance thresholds.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub clearances: Vec<crate::ClearanceSpec>,
}

impl SceneFile {
    /// Parses a scene file's JSON text; `path` is used in errors only.
    pub fn parse(text: &str, path: &Path) -> Result<Self> {
        serde_json::from_str(text).map_err(|e| json_error(&e, path))
    }

    /// Reads and parses a scene file (at most [`crate::MAX_SCENE_BYTES`]; a FIFO, device or
    /// directory is refused).
    pub fn read(path: impl AsRef<Path>) -> Result<Self> {
        Self::read_with(path.as_ref(), crate::MAX_SCENE_BYTES)
    }

    fn read_with(path: &Path, limit: u64) -> Result<Self> {
        let text = crate::read_text_limited(path, limit)?;
        Self::parse(&text, path)
    }

    /// Writes the scene file as pretty-printed JSON.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let text = serde_json::to_string_pretty(self).map_err(|e| Error::Invalid {
            path: path.into(),
            msg: e.to_string(),
        })?;
        crate::write_atomic(path, (text + "\n").as_bytes())
    }
}

pub(crate) fn json_error(e: &serde_json::Error, path: &Path) -> Error {
    let msg = e.to_string();
    let suffix = format!(" at line {} column {}", e.line(), e.column());
    let msg = msg.strip_suffix(&suffix).unwrap_or(&msg).to_owned();
    let location = if e.line() == 0 {
        crate::Location::File
    } else {
        crate::Location::LineColumn(e.line(), e.column())
    };
    Error::parse(path, location, msg)
}

/// A body of a loaded scene.
#[derive(Clone, Debug)]
pub struct Body {
    /// Unique name.
    pub name: String,
    /// Its mesh, shared with every body that names the same file.
    pub mesh: Arc<TriMesh>,
    /// Index of the mesh in [`Scene::meshes`].
    pub mesh_index: usize,
    /// A static body never moves.
    pub is_static: bool,
    /// The pose before the first frame.
    pub initial_pose: Pose,
}

/// One frame of a loaded scene: every body's pose, and which bodies moved.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// World pose of every body, indexed like [`Scene::bodies`] (bodies the frame does not
    /// list keep their previous pose).
    pub poses: Vec<Pose>,
    /// Bodies whose pose differs from the previous frame's (for frame 0: from the initial
    /// pose), ascending. A checker may reuse last frame's answer for pairs in which neither
    /// body moved.
    pub moved: Vec<usize>,
}

/// How a scene is loaded: which files it may name, and the input limits.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SceneOptions {
    /// Allow mesh and trajectory paths outside the scene file's folder (absolute paths, `..`,
    /// symbolic links leading out). Off by default: a scene from elsewhere cannot make frcd
    /// read `/etc/passwd` or a device ([`Error::OutsideSceneFolder`]).
    pub allow_outside: bool,
    /// Input limits (file sizes, frame indices).
    pub limits: crate::Limits,
    /// Extra trajectory CSV files merged into the frames (given by the user, so never checked
    /// against the scene's folder).
    pub trajectories: Vec<PathBuf>,
}

/// One pose given in a file: the body, the frame, where it came from.
#[derive(Clone, Copy, Debug)]
struct Key {
    frame: u32,
    body: u32,
    /// Source: 0 the scene file's frames, 1 its trajectory, 2.. the extra trajectories.
    source: u32,
    /// Line in a trajectory, frame index in the scene file.
    line: u32,
    pose: Pose,
}

/// A loaded, validated scene: meshes loaded once per distinct file, frames stored **sparsely**
/// (one entry per pose given in the files: memory grows with the rows given, not with the frame
/// count times the body count) and expanded on demand by [`Scene::frame`] and
/// [`Scene::frames`]. A body not listed in a frame holds its last pose (no interpolation).
#[derive(Clone, Debug)]
pub struct Scene {
    path: PathBuf,
    bodies: Vec<Body>,
    meshes: Vec<Arc<TriMesh>>,
    mesh_paths: Vec<PathBuf>,
    trajectory_paths: Vec<PathBuf>,
    exclude: Vec<(usize, usize)>,
    clearances: crate::Clearances,
    /// Every pose given, sorted by (frame, body).
    keys: Vec<Key>,
    /// Per body, the positions in `keys` of its entries (ascending frame).
    by_body: Vec<Vec<u32>>,
    frame_count: usize,
}

/// The frames of a scene, expanded one at a time (see [`Scene::frames`]).
#[derive(Clone, Copy, Debug)]
pub struct Frames<'a> {
    scene: &'a Scene,
}

impl<'a> Frames<'a> {
    /// Number of frames.
    pub fn len(&self) -> usize {
        self.scene.frame_count
    }

    /// Never true: a scene has at least one frame.
    pub fn is_empty(&self) -> bool {
        self.scene.frame_count == 0
    }

    /// Frame `k`, if it exists (see [`Scene::frame`]).
    pub fn get(&self, k: usize) -> Option<Frame> {
        (k < self.scene.frame_count).then(|| self.scene.frame(k))
    }

    /// The frames in order; each costs O(bodies + poses given in it).
    pub fn iter(&self) -> FrameIter<'a> {
        self.range(0..self.scene.frame_count)
    }

    /// Frames `range` (clamped to the scene), in order; starting costs one [`Scene::frame`].
    pub fn range(&self, range: std::ops::Range<usize>) -> FrameIter<'a> {
        let end = range.end.min(self.scene.frame_count);
        let start = range.start.min(end);
        let (poses, cursor) = if start == 0 {
            (self.scene.initial_poses(), 0)
        } else {
            let f = self.scene.frame(start - 1);
            let cursor = self
                .scene
                .keys
                .partition_point(|k| (k.frame as usize) < start);
            (f.poses, cursor)
        };
        FrameIter {
            scene: self.scene,
            next: start,
            end,
            poses,
            cursor,
        }
    }
}

impl<'a> IntoIterator for Frames<'a> {
    type Item = Frame;
    type IntoIter = FrameIter<'a>;
    fn into_iter(self) -> FrameIter<'a> {
        self.iter()
    }
}

/// Iterator over expanded frames (see [`Frames::iter`]).
#[derive(Clone, Debug)]
pub struct FrameIter<'a> {
    scene: &'a Scene,
    next: usize,
    end: usize,
    poses: Vec<Pose>,
    cursor: usize,
}

impl Iterator for FrameIter<'_> {
    type Item = Frame;
    fn next(&mut self) -> Option<Frame> {
        if self.next >= self.end {
            return None;
        }
        let k = self.next;
        self.next += 1;
        let keys = &self.scene.keys;
        let mut moved = Vec::new();
        while self.cursor < keys.len() && keys[self.cursor].frame as usize == k {
            let key = &keys[self.cursor];
            let b = key.body as usize;
            if self.poses[b] != key.pose {
                moved.push(b);
            }
            self.poses[b] = key.pose;
            self.cursor += 1;
        }
        Some(Frame {
            poses: self.poses.clone(),
            moved,
        })
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let n = self.end - self.next;
        (n, Some(n))
    }
}

impl ExactSizeIterator for FrameIter<'_> {}

impl Scene {
    /// Loads a scene file, its meshes and its trajectory CSV (if it names one), with the
    /// default [`SceneOptions`] (files outside the scene's folder refused, default limits).
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        Self::load_with(path, &SceneOptions::default())
    }

    /// Loads a scene file and merges the rows of an extra trajectory CSV into its frames.
    pub fn load_with_trajectory(path: impl AsRef<Path>, csv: impl AsRef<Path>) -> Result<Self> {
        let options = SceneOptions {
            trajectories: vec![csv.as_ref().to_path_buf()],
            ..SceneOptions::default()
        };
        Self::load_with(path, &options)
    }

    /// Loads a scene file with options (outside paths, limits, extra trajectories).
    pub fn load_with(path: impl AsRef<Path>, options: &SceneOptions) -> Result<Self> {
        let path = path.as_ref();
        let spec = SceneFile::read_with(path, options.limits.scene_bytes)?;
        Self::build(&spec, path, None, options)
    }

    /// Builds a scene from a parsed scene file. Mesh and trajectory paths are relative to
    /// `path`'s folder (and must lie inside it); `path` also names the file in errors. `extra`
    /// rows are merged into the frames like the file's own trajectory.
    pub fn from_spec(spec: &SceneFile, path: &Path, extra: Option<&Trajectory>) -> Result<Self> {
        Self::build(spec, path, extra, &SceneOptions::default())
    }

    /// [`Scene::from_spec`] with options.
    pub fn from_spec_with(
        spec: &SceneFile,
        path: &Path,
        extra: Option<&Trajectory>,
        options: &SceneOptions,
    ) -> Result<Self> {
        Self::build(spec, path, extra, options)
    }

    fn build(
        spec: &SceneFile,
        path: &Path,
        extra: Option<&Trajectory>,
        options: &SceneOptions,
    ) -> Result<Self> {
        let base = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        if spec.bodies.len() > u32::MAX as usize {
            return Err(Error::Invalid {
                path: path.into(),
                msg: format!(
                    "{} bodies: more than u32 indices address",
                    spec.bodies.len()
                ),
            });
        }
        let mut index: HashMap<&str, usize> = HashMap::new();
        for (i, b) in spec.bodies.iter().enumerate() {
            if b.name.is_empty() {
                return Err(Error::Invalid {
                    path: path.into(),
                    msg: format!("body {i} has an empty name"),
                });
            }
            if index.insert(&b.name, i).is_some() {
                return Err(Error::DuplicateBody {
                    path: path.into(),
                    name: b.name.clone(),
                });
            }
        }
        let inside = |file: &str, what: &dyn Fn() -> String| -> Result<PathBuf> {
            resolve_inside(path, base, file, options.allow_outside, what)
        };
        // Meshes, loaded once per distinct file.
        let load = crate::LoadOptions {
            max_bytes: options.limits.mesh_bytes,
            ..crate::LoadOptions::default()
        };
        let mut meshes: Vec<Arc<TriMesh>> = Vec::new();
        let mut mesh_paths: Vec<PathBuf> = Vec::new();
        let mut by_file: HashMap<PathBuf, usize> = HashMap::new();
        let mut bodies = Vec::with_capacity(spec.bodies.len());
        for b in &spec.bodies {
            let file = inside(&b.mesh, &|| format!("mesh of body '{}'", b.name))?;
            let key = std::fs::canonicalize(&file).map_err(|e| Error::io(&file, e))?;
            let mesh_index = match by_file.get(&key) {
                Some(&i) => i,
                None => {
                    let mesh = crate::load_mesh_with(&file, &load)?;
                    meshes.push(Arc::new(mesh));
                    mesh_paths.push(file.clone());
                    by_file.insert(key, meshes.len() - 1);
                    meshes.len() - 1
                }
            };
            let initial_pose = b.pose.to_pose().map_err(|msg| Error::BadPose {
                path: path.into(),
                place: format!("body '{}'", b.name),
                msg,
            })?;
            bodies.push(Body {
                name: b.name.clone(),
                mesh: meshes[mesh_index].clone(),
                mesh_index,
                is_static: b.is_static,
                initial_pose,
            });
        }
        let lookup = |name: &str, file: &Path, place: &dyn Fn() -> String| -> Result<usize> {
            index.get(name).copied().ok_or_else(|| Error::UnknownBody {
                path: file.into(),
                name: name.to_owned(),
                place: place(),
            })
        };
        let mut exclude = Vec::with_capacity(spec.exclude.len());
        for (k, [a, b]) in spec.exclude.iter().enumerate() {
            let place = || format!("exclude pair {k}");
            let (ia, ib) = (lookup(a, path, &place)?, lookup(b, path, &place)?);
            if ia == ib {
                return Err(Error::Invalid {
                    path: path.into(),
                    msg: format!("exclude pair {k} names body '{a}' twice"),
                });
            }
            exclude.push((ia.min(ib), ia.max(ib)));
        }
        exclude.sort_unstable();
        exclude.dedup();
        let is_static: Vec<bool> = bodies.iter().map(|b| b.is_static).collect();
        let clearances = crate::clearance::resolve(spec, path, &index, &is_static, &exclude)?;

        let max_frames = options.limits.frames.min(u32::MAX as u64);
        if spec.frames.len() as u64 > max_frames {
            return Err(Error::Limit {
                path: path.into(),
                place: "frames".into(),
                msg: format!(
                    "{} frames are past the limit of {max_frames}",
                    spec.frames.len()
                ),
            });
        }
        // Every pose given, with where it came from (sources: the scene, then trajectories).
        let mut sources: Vec<PathBuf> = vec![path.to_path_buf()];
        let mut keys: Vec<Key> = Vec::new();
        let static_error = |b: usize, file: &Path, place: String| Error::StaticBodyMoves {
            path: file.into(),
            name: bodies[b].name.clone(),
            place,
        };
        for (f, frame) in spec.frames.iter().enumerate() {
            for (name, pose) in &frame.0 {
                let b = lookup(name, path, &|| format!("frame {f}"))?;
                let pose = pose.to_pose().map_err(|msg| Error::BadPose {
                    path: path.into(),
                    place: format!("frame {f}, body '{name}'"),
                    msg,
                })?;
                if bodies[b].is_static {
                    return Err(static_error(b, path, format!("frame {f}")));
                }
                keys.push(Key {
                    frame: f as u32,
                    body: b as u32,
                    source: 0,
                    line: f as u32,
                    pose,
                });
            }
        }
        let mut trajectory_paths = Vec::new();
        let mut csv_files: Vec<PathBuf> = Vec::new();
        if let Some(csv) = &spec.trajectory {
            csv_files.push(inside(csv, &|| "trajectory".to_string())?);
        }
        csv_files.extend(options.trajectories.iter().cloned());
        for file in &csv_files {
            let bytes = crate::read_limited(file, options.limits.trajectory_bytes)?;
            let source = sources.len() as u32;
            sources.push(file.clone());
            trajectory_paths.push(file.clone());
            crate::trajectory::parse_rows(&bytes, file, max_frames, |r| {
                let place = || format!("line {}", r.line);
                let b = lookup(r.body, file, &place)?;
                if bodies[b].is_static {
                    return Err(static_error(b, file, place()));
                }
                keys.push(Key {
                    frame: r.frame,
                    body: b as u32,
                    source,
                    line: r.line.min(u32::MAX as usize) as u32,
                    pose: r.pose,
                });
                Ok(())
            })?;
        }
        if let Some(traj) = extra {
            let source = sources.len() as u32;
            sources.push(traj.path.clone());
            for r in &traj.rows {
                let place = || format!("line {}", r.line);
                let b = lookup(&r.body, &traj.path, &place)?;
                if bodies[b].is_static {
                    return Err(static_error(b, &traj.path, place()));
                }
                if r.frame as u64 >= max_frames {
                    return Err(Error::Limit {
                        path: traj.path.clone(),
                        place: place(),
                        msg: format!("frame {} is past the limit of {max_frames} frames", r.frame),
                    });
                }
                keys.push(Key {
                    frame: r.frame as u32,
                    body: b as u32,
                    source,
                    line: r.line.min(u32::MAX as usize) as u32,
                    pose: r.pose,
                });
            }
        }
        if keys.len() > u32::MAX as usize {
            return Err(Error::Limit {
                path: path.into(),
                place: "trajectory".into(),
                msg: format!("{} poses: more than u32 indices address", keys.len()),
            });
        }
        // Sorted by (frame, body), file order kept for ties, so a body given twice in one frame
        // is two neighbours: name both places.
        keys.sort_by_key(|k| (k.frame, k.body, k.source, k.line));
        let place_of = |k: &Key| {
            if k.source == 0 {
                format!("frame {}", k.line)
            } else {
                format!("line {}", k.line)
            }
        };
        for w in keys.windows(2) {
            if w[0].frame == w[1].frame && w[0].body == w[1].body {
                let (first, second) = (&w[0], &w[1]);
                return Err(Error::Invalid {
                    path: sources[second.source as usize].clone(),
                    msg: format!(
                        "{}: body '{}' in frame {} was already given a pose ({}: {})",
                        place_of(second),
                        bodies[second.body as usize].name,
                        second.frame,
                        sources[first.source as usize].display(),
                        place_of(first)
                    ),
                });
            }
        }
        let mut by_body: Vec<Vec<u32>> = vec![Vec::new(); bodies.len()];
        for (i, k) in keys.iter().enumerate() {
            by_body[k.body as usize].push(i as u32);
        }
        let frame_count = keys
            .last()
            .map_or(0, |k| k.frame as usize + 1)
            .max(spec.frames.len())
            .max(1);
        Ok(Self {
            path: path.into(),
            bodies,
            meshes,
            mesh_paths,
            trajectory_paths,
            exclude,
            clearances,
            keys,
            by_body,
            frame_count,
        })
    }

    fn initial_poses(&self) -> Vec<Pose> {
        self.bodies.iter().map(|b| b.initial_pose).collect()
    }

    /// The scene file this scene was loaded from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Every file the scene was read from: the scene file, its meshes, its trajectories (for
    /// refusing to write a report over one of them).
    pub fn input_paths(&self) -> Vec<PathBuf> {
        let mut v = vec![self.path.clone()];
        v.extend(self.mesh_paths.iter().cloned());
        v.extend(self.trajectory_paths.iter().cloned());
        v
    }

    /// The trajectory CSV files merged into the frames.
    pub fn trajectory_paths(&self) -> &[PathBuf] {
        &self.trajectory_paths
    }

    /// The bodies, in file order.
    pub fn bodies(&self) -> &[Body] {
        &self.bodies
    }

    /// The index of the body with this name.
    pub fn body_index(&self, name: &str) -> Option<usize> {
        self.bodies.iter().position(|b| b.name == name)
    }

    /// The distinct meshes (bodies share them through [`Body::mesh_index`]).
    pub fn meshes(&self) -> &[Arc<TriMesh>] {
        &self.meshes
    }

    /// The file each of [`Scene::meshes`] was loaded from.
    pub fn mesh_paths(&self) -> &[PathBuf] {
        &self.mesh_paths
    }

    /// The clearance thresholds the scene file sets (`"clearance"`, `"clearances"`).
    pub fn clearances(&self) -> &crate::Clearances {
        &self.clearances
    }

    /// Excluded pairs `(a, b)` with `a < b`, sorted.
    pub fn exclusions(&self) -> &[(usize, usize)] {
        &self.exclude
    }

    /// True when the pair of bodies `a`, `b` (either order) is excluded from checking.
    pub fn is_excluded(&self, a: usize, b: usize) -> bool {
        self.exclude.binary_search(&(a.min(b), a.max(b))).is_ok()
    }

    /// The frames (at least one: a scene without frames has the initial poses as its frame),
    /// expanded on demand: `scene.frames().iter()` walks them in order at O(bodies) each.
    pub fn frames(&self) -> Frames<'_> {
        Frames { scene: self }
    }

    /// Frame `k` expanded: every body's pose (its latest pose given at a frame `<= k`, else its
    /// initial pose) and the bodies whose pose changed at `k`. O(bodies · log poses).
    ///
    /// # Panics
    /// When `k >= frame_count()` (use [`Frames::get`] for a checked lookup).
    pub fn frame(&self, k: usize) -> Frame {
        assert!(
            k < self.frame_count,
            "frame {k} of a scene with {} frames",
            self.frame_count
        );
        let mut poses = self.initial_poses();
        let mut moved = Vec::new();
        for (b, list) in self.by_body.iter().enumerate() {
            let n = list.partition_point(|&i| self.keys[i as usize].frame as usize <= k);
            if n == 0 {
                continue;
            }
            let key = &self.keys[list[n - 1] as usize];
            let before = if n >= 2 {
                self.keys[list[n - 2] as usize].pose
            } else {
                self.bodies[b].initial_pose
            };
            poses[b] = key.pose;
            if key.frame as usize == k && key.pose != before {
                moved.push(b);
            }
        }
        Frame { poses, moved }
    }

    /// Number of frames: one past the largest frame index given (in the scene's `frames` or a
    /// trajectory row), at least 1.
    pub fn frame_count(&self) -> usize {
        self.frame_count
    }

    /// Number of poses stored (one per pose given in the files): what the frames' memory grows
    /// with.
    pub fn pose_count(&self) -> usize {
        self.keys.len()
    }

    /// Total triangles over all bodies (a body's mesh counted once per body).
    pub fn triangle_count(&self) -> usize {
        self.bodies.iter().map(|b| b.mesh.triangle_count()).sum()
    }
}

/// `file` (as a scene gives it) joined to the scene's folder, refused when it leads outside
/// that folder and `allow_outside` is off: an absolute path, `..` past the folder, or a
/// symbolic link whose target is outside.
fn resolve_inside(
    scene: &Path,
    base: &Path,
    file: &str,
    allow_outside: bool,
    what: &dyn Fn() -> String,
) -> Result<PathBuf> {
    let joined = base.join(file);
    if allow_outside {
        return Ok(joined);
    }
    let outside = || Error::OutsideSceneFolder {
        path: scene.into(),
        what: what(),
        file: file.into(),
        folder: base.into(),
    };
    if Path::new(file).is_absolute() {
        return Err(outside());
    }
    let folder = std::fs::canonicalize(base).map_err(|e| Error::io(base, e))?;
    match std::fs::canonicalize(&joined) {
        Ok(real) if real.starts_with(&folder) => Ok(joined),
        Ok(_) => Err(outside()),
        // Missing file: judge by the words (no `..` may climb above the folder), and let the
        // read report the missing file.
        Err(_) => {
            let mut depth = 0i64;
            for c in Path::new(file).components() {
                match c {
                    std::path::Component::ParentDir => depth -= 1,
                    std::path::Component::Normal(_) => depth += 1,
                    _ => {}
                }
                if depth < 0 {
                    return Err(outside());
                }
            }
            Ok(joined)
        }
    }
}
