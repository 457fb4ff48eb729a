// The one unsafe call (setting XDG_RUNTIME_DIR before any thread exists) is allowed locally.
#![deny(unsafe_code)]
//! `frcd`: interference checking of an assembly along a trajectory.
//!
//! - `frcd check SCENE [--backend cpu|gpgpu|image|hybrid] [--mode exact|fast] [--json OUT]
//!   [--csv OUT] [--segments]`: per frame the interfering body pairs, their touching triangle
//!   pairs, the time per frame; a summary of when each pair interferes. With `--clearance M`
//!   (or the scene's `"clearance"` / `"clearances"`) also every checked pair closer than its
//!   threshold: distance, closest points, triangle pair; `--plot-clearance OUT.svg` plots it.
//! - `frcd plot-clearance SCENE --clearance M -o OUT.svg`: the same run, writing only the plot
//!   of clearance against frame per body pair (interfering intervals marked) and printing the
//!   per-pair minima.
//! - `frcd render SCENE --frame N -o out.png`: an offscreen picture with the interfering
//!   triangles highlighted (feature `gpu`).
//! - `frcd bench SCENE`: time per frame of every backend and mode.
//! - `frcd calibrate [-o FILE]`: measures the scheduler's cost model on this machine.

mod clearance;
mod clearance_run;
mod commands;
mod plot;
#[cfg(feature = "gpu")]
mod render;

use clap::{Parser, Subcommand, ValueEnum};
use std::path::PathBuf;
use std::process::ExitCode;

/// Exact real-time collision detection between triangle meshes: interference checks of CAD
/// assemblies along dynamics trajectories.
#[derive(Parser, Debug)]
#[command(name = "frcd", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// Backend choice on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum BackendArg {
    /// CPU only: sweep and prune, OBB trees, exact triangle tests.
    Cpu,
    /// GPU pair traversal for every pair; the box pass on the GPU from 1,024 bodies.
    Gpgpu,
    /// Image-space accurate colliding set (fast mode).
    Image,
    /// Per stage by the cost model.
    Hybrid,
}

/// Mode on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ModeArg {
    /// Equal to the exact oracle.
    Exact,
    /// Image-space pipeline, resolution-bounded.
    Fast,
}

/// Options shared by the commands that run the checker.
#[derive(clap::Args, Debug, Clone)]
pub struct CheckerArgs {
    /// Backend.
    #[arg(long, value_enum, default_value = "hybrid")]
    pub backend: BackendArg,
    /// Mode.
    #[arg(long, value_enum, default_value = "exact")]
    pub mode: ModeArg,
    /// Cost model JSON (from `frcd calibrate`); default: $FRCD_COST_MODEL, else the built-in
    /// figures (a model file in the working folder is used only when named).
    #[arg(long)]
    pub cost: Option<PathBuf>,
    /// Allow the scene to name meshes and trajectories outside its own folder (absolute paths,
    /// `..`, symbolic links leading out).
    #[arg(long)]
    pub allow_outside: bool,
    /// Image-space resolution (pixels across a pair's overlap region).
    #[arg(long, default_value_t = 256)]
    pub resolution: u32,
    /// Extra trajectory CSV (`frame,body,x,y,z,qx,qy,qz,qw`) merged into the scene's frames.
    #[arg(long)]
    pub trajectory: Option<PathBuf>,
    /// OBB tree: most triangles per leaf (4, frcd-hybrid's default, measured fastest on the
    /// bogie demo: long thin tread triangles a few millimetres from the brake blocks).
    #[arg(long, default_value_t = 4)]
    pub leaf: u32,
    /// OBB tree of the clearance distance searches (built only with a clearance threshold):
    /// most triangles per leaf (1, measured about twice as fast as 4 on the bogie's brake
    /// blocks, conformal to the treads a few millimetres off).
    #[arg(long, default_value_t = 1)]
    pub clearance_leaf: u32,
    /// Do not use the meridian bound of bodies that are solids of revolution (wheelsets): every
    /// pair the motion bound cannot skip gets a distance search (for comparison; same answers).
    #[arg(long)]
    pub no_spin_bound: bool,
    /// OBB tree: box fitting rule.
    #[arg(long, value_enum, default_value = "vertex")]
    pub fit: FitArg,
    /// OBB tree: where each node splits its triangles.
    #[arg(long, value_enum, default_value = "surface")]
    pub split: SplitArg,
}

/// OBB tree split rule on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SplitArg {
    /// The cut of least surface cost across any box axis (fewer box tests, slower build).
    Surface,
    /// The plane through the mean across the major axis (PQP's rule; the fastest build).
    Mean,
}

/// OBB fitting rule on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum FitArg {
    /// Covariance of the vertices.
    Vertex,
    /// Area-weighted covariance of the triangles.
    Area,
    /// Covariance of the convex hull's surface.
    Hull,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Check every frame of a scene for interference.
    Check {
        /// Scene JSON file.
        scene: PathBuf,
        #[command(flatten)]
        checker: CheckerArgs,
        /// Write the JSON report here.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Write the CSV report here.
        #[arg(long)]
        csv: Option<PathBuf>,
        /// Include contact segments (world coordinates) in the JSON report.
        #[arg(long)]
        segments: bool,
        /// Include the touching triangle pairs of each interference in the JSON report.
        #[arg(long)]
        pairs: bool,
        /// First frame to check.
        #[arg(long, default_value_t = 0)]
        first: usize,
        /// Number of frames to check, at least 1 (default: all from --first; more than are left
        /// means all from --first).
        #[arg(long)]
        count: Option<usize>,
        /// Print nothing but errors (the reports are still written).
        #[arg(long, short)]
        quiet: bool,
        /// Print the body pairs that take the most narrow-phase time.
        #[arg(long)]
        pair_times: bool,
        /// Clearance threshold (scene units, e.g. metres): every checked body pair closer than
        /// this reports its distance, closest points and triangle pair each frame (interfering
        /// pairs: 0). Replaces the scene's "clearance"; its per-pair "clearances" stay.
        #[arg(long, value_name = "DISTANCE", allow_negative_numbers = true)]
        clearance: Option<f64>,
        /// Write an SVG plot of clearance against frame per body pair here.
        #[arg(long, value_name = "OUT.svg")]
        plot_clearance: Option<PathBuf>,
        /// Plot only the pairs with a body whose name contains this (repeatable).
        #[arg(long, value_name = "NAME")]
        plot_pairs: Vec<String>,
        /// Most points per pair in the plot (longer runs: the minimum per bin of frames).
        #[arg(long, default_value_t = 1500)]
        plot_points: usize,
    },
    /// Plot clearance against frame per body pair (SVG), with the interfering intervals marked;
    /// prints the minimum per pair (the clearance part of `check`).
    PlotClearance {
        /// Scene JSON file.
        scene: PathBuf,
        #[command(flatten)]
        checker: CheckerArgs,
        /// Output SVG.
        #[arg(short, long, value_name = "OUT.svg")]
        output: PathBuf,
        /// Clearance threshold (scene units); replaces the scene's "clearance" (its per-pair
        /// "clearances" stay). Needed unless the scene sets one.
        #[arg(long, value_name = "DISTANCE", allow_negative_numbers = true)]
        clearance: Option<f64>,
        /// Plot only the pairs with a body whose name contains this (repeatable).
        #[arg(long, value_name = "NAME")]
        pairs: Vec<String>,
        /// Most points per pair (longer runs: the minimum per bin of frames).
        #[arg(long, default_value_t = 1500)]
        points: usize,
        /// First frame.
        #[arg(long, default_value_t = 0)]
        first: usize,
        /// Number of frames, at least 1 (default: all from --first).
        #[arg(long)]
        count: Option<usize>,
        /// Print nothing but errors.
        #[arg(long, short)]
        quiet: bool,
    },
    /// Render one frame with the interfering triangles highlighted.
    Render {
        /// Scene JSON file.
        scene: PathBuf,
        /// Frame index.
        #[arg(long, default_value_t = 0)]
        frame: usize,
        /// Output PNG.
        #[arg(short, long)]
        output: PathBuf,
        /// Image width in pixels.
        #[arg(long, default_value_t = 1280)]
        width: u32,
        /// Image height in pixels.
        #[arg(long, default_value_t = 800)]
        height: u32,
        /// Frame the whole scene (default: the interfering bodies seen from the contact side,
        /// else the moving bodies).
        #[arg(long)]
        all: bool,
        #[command(flatten)]
        checker: CheckerArgs,
    },
    /// Time per frame of every backend and mode on a scene.
    Bench {
        /// Scene JSON file.
        scene: PathBuf,
        /// Frames timed per backend (from frame 0).
        #[arg(long, default_value_t = 500)]
        frames: usize,
        /// Cost model JSON for the hybrid rows.
        #[arg(long)]
        cost: Option<PathBuf>,
        /// Write the table as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Allow the scene to name files outside its own folder.
        #[arg(long)]
        allow_outside: bool,
    },
    /// Measure the cost model on this machine and store it as JSON.
    Calibrate {
        /// Output file.
        #[arg(short, long, default_value = "frcd-cost.json")]
        output: PathBuf,
        /// Timed repetitions per figure.
        #[arg(long, default_value_t = 5)]
        repetitions: usize,
        /// CPU figures only.
        #[arg(long)]
        cpu_only: bool,
    },
}

/// Mesa's Vulkan and EGL drivers print "error: XDG_RUNTIME_DIR is invalid or not set" when
/// the variable is missing or names no private folder, although frcd renders offscreen and
/// needs no display. Point it at a private folder of our own before any GPU code runs.
fn quiet_xdg_runtime_dir() {
    #[cfg(unix)]
    {
        use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
        let ok = std::env::var_os("XDG_RUNTIME_DIR").is_some_and(|d| {
            std::fs::metadata(&d).is_ok_and(|m| {
                m.is_dir() && m.permissions().mode() & 0o077 == 0 && m.uid() == uid_of_process()
            })
        });
        if ok {
            return;
        }
        let dir = std::env::temp_dir().join(format!("frcd-xdg-{}", uid_of_process()));
        let _ = std::fs::DirBuilder::new().mode(0o700).create(&dir);
        let private = std::fs::symlink_metadata(&dir).is_ok_and(|m| {
            m.is_dir() && m.permissions().mode() & 0o077 == 0 && m.uid() == uid_of_process()
        });
        if private {
            // SAFETY: called first thing in main, before any other thread exists.
            #[allow(unsafe_code)]
            unsafe {
                std::env::set_var("XDG_RUNTIME_DIR", &dir)
            };
        }
    }
}

/// The real user id, from the owner of a file this process just made (no libc needed).
#[cfg(unix)]
fn uid_of_process() -> u32 {
    use std::os::unix::fs::MetadataExt;
    static UID: std::sync::OnceLock<u32> = std::sync::OnceLock::new();
    *UID.get_or_init(|| {
        std::fs::metadata("/proc/self")
            .map(|m| m.uid())
            .unwrap_or(u32::MAX)
    })
}

fn main() -> ExitCode {
    quiet_xdg_runtime_dir();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Check {
            scene,
            checker,
            json,
            csv,
            segments,
            pairs,
            first,
            count,
            quiet,
            pair_times,
            clearance,
            plot_clearance,
            plot_pairs,
            plot_points,
        } => commands::check(&commands::CheckRun {
            scene,
            checker,
            json,
            csv,
            segments,
            first,
            count,
            quiet,
            pair_times,
            pairs,
            clearance: clearance_run::ClearanceArgs {
                threshold: clearance,
                plot: plot_clearance,
                plot_pairs,
                plot_points,
            },
            plot_only: false,
        }),
        Command::PlotClearance {
            scene,
            checker,
            output,
            clearance,
            pairs,
            points,
            first,
            count,
            quiet,
        } => commands::check(&commands::CheckRun {
            scene,
            checker,
            json: None,
            csv: None,
            segments: false,
            first,
            count,
            quiet,
            pair_times: false,
            pairs: false,
            clearance: clearance_run::ClearanceArgs {
                threshold: clearance,
                plot: Some(output),
                plot_pairs: pairs,
                plot_points: points,
            },
            plot_only: true,
        }),
        Command::Render {
            scene,
            frame,
            output,
            width,
            height,
            all,
            checker,
        } => commands::render(&scene, frame, &output, width, height, all, &checker),
        Command::Bench {
            scene,
            frames,
            cost,
            json,
            allow_outside,
        } => commands::bench(
            &scene,
            frames,
            cost.as_deref(),
            json.as_deref(),
            allow_outside,
        ),
        Command::Calibrate {
            output,
            repetitions,
            cpu_only,
        } => commands::calibrate(&output, repetitions, cpu_only),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", commands::term(&format!("{e:#}")));
            ExitCode::FAILURE
        }
    }
}
