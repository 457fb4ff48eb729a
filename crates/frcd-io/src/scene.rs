//! Scene files: bodies, meshes, exclusions and a trajectory of poses.

use crate::{Error, Result, Trajectory, load_mesh};
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
pub struct BodySpec {
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
    pub bodies: Vec<BodySpec>,
    /// Pairs of body names never to test against each other (parts assembled in contact).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub exclude: Vec<[String; 2]>,
    /// CSV trajectory file, relative to the scene file's folder.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trajectory: Option<String>,
    /// Per frame, the bodies that move.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub frames: Vec<FramePoses>,
}

impl SceneFile {
    /// Parses a scene file's JSON text; `path` is used in errors only.
    pub fn parse(text: &str, path: &Path) -> Result<Self> {
        serde_json::from_str(text).map_err(|e| json_error(&e, path))
    }

    /// Reads and parses a scene file.
    pub fn read(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Self::parse(&text, path)
    }

    /// Writes the scene file as pretty-printed JSON.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let text = serde_json::to_string_pretty(self).map_err(|e| Error::Invalid {
            path: path.into(),
            msg: e.to_string(),
        })?;
        std::fs::write(path, text + "\n").map_err(|e| Error::io(path, e))
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

/// A loaded, validated scene: meshes loaded once per distinct file, frames expanded to full pose
/// vectors.
#[derive(Clone, Debug)]
pub struct Scene {
    path: PathBuf,
    bodies: Vec<Body>,
    meshes: Vec<Arc<TriMesh>>,
    mesh_paths: Vec<PathBuf>,
    exclude: Vec<(usize, usize)>,
    frames: Vec<Frame>,
}

impl Scene {
    /// Loads a scene file, its meshes and its trajectory CSV (if it names one).
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let spec = SceneFile::read(path)?;
        Self::from_spec(&spec, path, None)
    }

    /// Loads a scene file and merges the rows of an extra trajectory CSV into its frames.
    pub fn load_with_trajectory(path: impl AsRef<Path>, csv: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let spec = SceneFile::read(path)?;
        let extra = Trajectory::load(csv)?;
        Self::from_spec(&spec, path, Some(&extra))
    }

    /// Builds a scene from a parsed scene file. Mesh and trajectory paths are relative to
    /// `path`'s folder; `path` also names the file in errors. `extra` rows are merged into the
    /// frames like the file's own trajectory.
    pub fn from_spec(spec: &SceneFile, path: &Path, extra: Option<&Trajectory>) -> Result<Self> {
        let base = path.parent().unwrap_or(Path::new(""));
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
        // Meshes, loaded once per distinct file.
        let mut meshes: Vec<Arc<TriMesh>> = Vec::new();
        let mut mesh_paths: Vec<PathBuf> = Vec::new();
        let mut by_file: HashMap<PathBuf, usize> = HashMap::new();
        let mut bodies = Vec::with_capacity(spec.bodies.len());
        for b in &spec.bodies {
            let file = base.join(&b.mesh);
            let key = std::fs::canonicalize(&file).map_err(|e| Error::io(&file, e))?;
            let mesh_index = match by_file.get(&key) {
                Some(&i) => i,
                None => {
                    let mesh = load_mesh(&file)?;
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

        // Per frame, the updates and where each came from (to name both sides of a conflict).
        let mut updates: Vec<Vec<(usize, Pose)>> = Vec::new();
        let mut origin: HashMap<(usize, usize), (PathBuf, String)> = HashMap::new();
        let mut add = |frame: usize,
                       body: usize,
                       pose: Pose,
                       file: &Path,
                       place: String,
                       bodies: &[Body]|
         -> Result<()> {
            if bodies[body].is_static {
                return Err(Error::StaticBodyMoves {
                    path: file.into(),
                    name: bodies[body].name.clone(),
                    place,
                });
            }
            if let Some((f0, p0)) = origin.get(&(frame, body)) {
                return Err(Error::Invalid {
                    path: file.into(),
                    msg: format!(
                        "{place}: body '{}' in frame {frame} was already given a pose ({}: {p0})",
                        bodies[body].name,
                        f0.display()
                    ),
                });
            }
            origin.insert((frame, body), (file.to_path_buf(), place));
            if updates.len() <= frame {
                updates.resize_with(frame + 1, Vec::new);
            }
            updates[frame].push((body, pose));
            Ok(())
        };
        for (f, frame) in spec.frames.iter().enumerate() {
            for (name, pose) in &frame.0 {
                let b = lookup(name, path, &|| format!("frame {f}"))?;
                let pose = pose.to_pose().map_err(|msg| Error::BadPose {
                    path: path.into(),
                    place: format!("frame {f}, body '{name}'"),
                    msg,
                })?;
                add(f, b, pose, path, format!("frame {f}"), &bodies)?;
            }
        }
        let own = match &spec.trajectory {
            Some(csv) => Some(Trajectory::load(base.join(csv))?),
            None => None,
        };
        for traj in own.iter().chain(extra) {
            for row in &traj.rows {
                let place = || format!("line {}", row.line);
                let b = lookup(&row.body, &traj.path, &place)?;
                add(row.frame, b, row.pose, &traj.path, place(), &bodies)?;
            }
        }
        // Expand to full pose vectors.
        let mut prev: Vec<Pose> = bodies.iter().map(|b| b.initial_pose).collect();
        let mut frames = Vec::with_capacity(updates.len().max(1));
        for list in &updates {
            let mut poses = prev.clone();
            let mut moved = Vec::new();
            for &(b, pose) in list {
                if poses[b] != pose {
                    moved.push(b);
                }
                poses[b] = pose;
            }
            moved.sort_unstable();
            prev = poses.clone();
            frames.push(Frame { poses, moved });
        }
        if frames.is_empty() {
            frames.push(Frame {
                poses: prev,
                moved: Vec::new(),
            });
        }
        Ok(Self {
            path: path.into(),
            bodies,
            meshes,
            mesh_paths,
            exclude,
            frames,
        })
    }

    /// The scene file this scene was loaded from.
    pub fn path(&self) -> &Path {
        &self.path
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

    /// Excluded pairs `(a, b)` with `a < b`, sorted.
    pub fn exclusions(&self) -> &[(usize, usize)] {
        &self.exclude
    }

    /// True when the pair of bodies `a`, `b` (either order) is excluded from checking.
    pub fn is_excluded(&self, a: usize, b: usize) -> bool {
        self.exclude.binary_search(&(a.min(b), a.max(b))).is_ok()
    }

    /// The frames (at least one: a scene without frames has the initial poses as its frame).
    pub fn frames(&self) -> &[Frame] {
        &self.frames
    }

    /// Number of frames.
    pub fn frame_count(&self) -> usize {
        self.frames.len()
    }

    /// Total triangles over all bodies (a body's mesh counted once per body).
    pub fn triangle_count(&self) -> usize {
        self.bodies.iter().map(|b| b.mesh.triangle_count()).sum()
    }
}
