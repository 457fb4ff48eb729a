use frcd_geom::MeshError;
use std::fmt;
use std::path::PathBuf;

/// Where in a file a problem is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Location {
    /// A 1-based line of a text file.
    Line(usize),
    /// A 1-based line and column of a text file.
    LineColumn(usize, usize),
    /// A 0-based triangle record of a binary STL file.
    Record(usize),
    /// The end of the file (something was missing).
    EndOfFile,
    /// The whole file (e.g. a binary header or size problem).
    File,
}

impl Location {
    /// The 1-based line, when the location is a line.
    pub fn line(&self) -> Option<usize> {
        match *self {
            Location::Line(l) | Location::LineColumn(l, _) => Some(l),
            _ => None,
        }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Location::Line(l) => write!(f, "line {l}"),
            Location::LineColumn(l, c) => write!(f, "line {l}, column {c}"),
            Location::Record(r) => write!(f, "triangle record {r}"),
            Location::EndOfFile => f.write_str("end of file"),
            Location::File => f.write_str("file"),
        }
    }
}

/// Everything that can go wrong reading or writing frcd files. Every variant names the file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating-system error.
        source: std::io::Error,
    },
    /// The file's content does not follow its format.
    #[error("{}: {location}: {msg}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// Where in the file.
        location: Location,
        /// What is wrong.
        msg: String,
    },
    /// The file parsed, but frcd-geom refused the mesh (empty, non-finite, too large).
    #[error("{}{}: invalid mesh: {source}", path.display(), object.as_ref().map(|o| format!(" (object '{o}')")).unwrap_or_default())]
    Mesh {
        /// The file.
        path: PathBuf,
        /// The OBJ object, when the file was split into objects.
        object: Option<String>,
        /// Why the mesh was refused.
        source: MeshError,
    },
    /// The file extension names no format frcd reads.
    #[error("{}: unsupported mesh format (expected .stl or .obj)", path.display())]
    UnsupportedFormat {
        /// The file.
        path: PathBuf,
    },
    /// Two bodies of a scene have the same name.
    #[error("{}: body name '{name}' is used twice", path.display())]
    DuplicateBody {
        /// The scene file.
        path: PathBuf,
        /// The repeated name.
        name: String,
    },
    /// A frame, exclusion or trajectory row names a body the scene does not have.
    #[error("{}: {place}: unknown body '{name}'", path.display())]
    UnknownBody {
        /// The scene or trajectory file.
        path: PathBuf,
        /// The unknown name.
        name: String,
        /// Where it was named ("frame 12", "exclude pair 3", "line 40").
        place: String,
    },
    /// A pose is not finite or its quaternion is not of unit length.
    #[error("{}: {place}: bad pose: {msg}", path.display())]
    BadPose {
        /// The scene or trajectory file.
        path: PathBuf,
        /// Where ("body 'rail'", "frame 12, body 'wheelset_1'", "line 40").
        place: String,
        /// What is wrong.
        msg: String,
    },
    /// A body declared static is given a pose in a frame.
    #[error("{}: {place}: body '{name}' is static but is given a pose", path.display())]
    StaticBodyMoves {
        /// The scene or trajectory file.
        path: PathBuf,
        /// The body.
        name: String,
        /// Where ("frame 12", "line 40").
        place: String,
    },
    /// The path is a directory, FIFO, device or socket, not a regular file (a FIFO would block,
    /// a device such as `/dev/zero` never ends).
    #[error("{}: is {kind}, not a regular file", path.display())]
    NotAFile {
        /// The path.
        path: PathBuf,
        /// What it is ("a directory", "a FIFO (named pipe)", ...).
        kind: &'static str,
    },
    /// The file is larger than the limit frcd reads (see [`crate::Limits`]).
    #[error("{}: {} exceeds the limit of {limit} bytes (see docs/limits.md)", path.display(), size.map_or_else(|| "the file".to_string(), |s| format!("{s} bytes")))]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// Its size, when known before reading.
        size: Option<u64>,
        /// The limit.
        limit: u64,
    },
    /// A scene names a file outside its own folder (an absolute path, `..`, or a symbolic link
    /// leading out) and the caller did not allow that ([`crate::SceneOptions::allow_outside`],
    /// `frcd --allow-outside`).
    #[error("{}: {what} '{}' is outside the scene's folder {} (pass --allow-outside to allow it)", path.display(), file.display(), folder.display())]
    OutsideSceneFolder {
        /// The scene file.
        path: PathBuf,
        /// Which entry ("mesh of body 'rail'", "trajectory").
        what: String,
        /// The path as the scene gives it.
        file: PathBuf,
        /// The scene's folder.
        folder: PathBuf,
    },
    /// A count or index is past a documented limit or would overflow.
    #[error("{}: {place}: {msg}", path.display())]
    Limit {
        /// The file.
        path: PathBuf,
        /// Where ("line 40", "frame 12").
        place: String,
        /// What is too large.
        msg: String,
    },
    /// A clearance threshold is negative or not finite, or a per-pair threshold names a pair
    /// that is never checked (one body twice, excluded, both static) or is given twice.
    #[error("{}: {place}: bad clearance: {msg}", path.display())]
    BadClearance {
        /// The scene file.
        path: PathBuf,
        /// Where ("clearance", "clearances entry 2").
        place: String,
        /// What is wrong.
        msg: String,
    },
    /// Anything else a scene, trajectory or report file gets wrong (said in the message).
    #[error("{}: {msg}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong and where.
        msg: String,
    },
}

impl Error {
    /// The file the error is about.
    pub fn path(&self) -> &std::path::Path {
        match self {
            Error::Io { path, .. }
            | Error::Parse { path, .. }
            | Error::Mesh { path, .. }
            | Error::UnsupportedFormat { path }
            | Error::DuplicateBody { path, .. }
            | Error::UnknownBody { path, .. }
            | Error::BadPose { path, .. }
            | Error::BadClearance { path, .. }
            | Error::StaticBodyMoves { path, .. }
            | Error::Invalid { path, .. }
            | Error::NotAFile { path, .. }
            | Error::TooLarge { path, .. }
            | Error::OutsideSceneFolder { path, .. }
            | Error::Limit { path, .. } => path,
        }
    }

    /// The location inside the file, for parse errors.
    pub fn location(&self) -> Option<Location> {
        match self {
            Error::Parse { location, .. } => Some(*location),
            _ => None,
        }
    }

    pub(crate) fn io(path: &std::path::Path, source: std::io::Error) -> Self {
        Error::Io {
            path: path.to_path_buf(),
            source,
        }
    }

    pub(crate) fn parse(
        path: &std::path::Path,
        location: Location,
        msg: impl Into<String>,
    ) -> Self {
        Error::Parse {
            path: path.to_path_buf(),
            location,
            msg: msg.into(),
        }
    }
}
