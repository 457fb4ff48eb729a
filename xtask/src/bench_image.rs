//! `cargo xtask bench image`: the image-space detector's run time against resolution against
//! error, written to `testdata/bench/image.md` (table) and `testdata/bench/image.svg` (plot).
//!
//! Scenes with analytic answers:
//! - `boxes`: a unit cube and a 1×1×0.5 box turned 0.5 rad about z; exact volume by polygon
//!   clipping. Volume error against it.
//! - `lens`: two level-5 icospheres (20,480 triangles each) 1.5 apart along the diagonal (the
//!   overlap box is much larger than the lens, so resolution matters). Volume error against the
//!   lens of the volume-equivalent spheres (the tessellation's own share is shown as `tess`).
//! - `corner`: a cube turned 45° about z and x pressed corner-first into a cube's face; the
//!   largest penetration depth still missed, from a scan of depths `0.1 · 2^(-k/2)`, worst over
//!   four lateral offsets (the pixel grid's phase).
//! - `edge`: a cube turned 45° about z pressed into a cube's vertical edge along the diagonal;
//!   the largest missed penetration likewise.
//!
//! Options: `--resolutions 64,128,...` (default 64..2048 by powers of two), `--runs N` timed runs
//! per point (median, default 5), `--out DIR` (default testdata/bench).

use anyhow::{Result, bail};
use frcd_geom::{DQuat, DVec2, DVec3, Pose, TriMesh, shapes};
use frcd_image::{ImageDetector, ImageMesh, ImageOptions, ImageScratch};
use std::f64::consts::PI;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

struct Row {
    scene: &'static str,
    resolution: u32,
    pixels: (u32, u32),
    layers: [u32; 2],
    ms: f64,
    /// Relative volume error (volume scenes).
    volume_error: Option<f64>,
    /// Relative a-posteriori estimate (volume scenes).
    volume_estimate: Option<f64>,
    /// Largest missed penetration depth (penetration scenes), absolute units (bodies ~1).
    missed: Option<f64>,
    pixel_size: f64,
    depth_bound: f64,
}

fn lens(r: f64, d: f64) -> f64 {
    if d >= 2.0 * r {
        0.0
    } else {
        PI / 12.0 * (4.0 * r + d) * (2.0 * r - d).powi(2)
    }
}

fn clip_area(subject: &[DVec2], clip: &[DVec2]) -> f64 {
    let mut poly = subject.to_vec();
    for k in 0..clip.len() {
        let (p, q) = (clip[k], clip[(k + 1) % clip.len()]);
        let side = |x: DVec2| (q - p).perp_dot(x - p);
        let input = std::mem::take(&mut poly);
        for i in 0..input.len() {
            let (c, n) = (input[i], input[(i + 1) % input.len()]);
            let (sc, sn) = (side(c), side(n));
            if sc >= 0.0 {
                poly.push(c);
            }
            if (sc >= 0.0) != (sn >= 0.0) {
                poly.push(c + (n - c) * (sc / (sc - sn)));
            }
        }
    }
    0.5 * (0..poly.len())
        .map(|i| poly[i].perp_dot(poly[(i + 1) % poly.len()]))
        .sum::<f64>()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

struct Bench<'a> {
    det: &'a ImageDetector,
    scratch: ImageScratch,
    runs: usize,
}

impl Bench<'_> {
    /// Median query time (ms) and the last result.
    fn time(
        &mut self,
        a: &ImageMesh,
        b: &ImageMesh,
        pose_b: &Pose,
        res: u32,
    ) -> Result<(f64, frcd_image::ImageResult)> {
        let o = ImageOptions {
            resolution: res,
            ..Default::default()
        };
        let mut r = self
            .det
            .query(&mut self.scratch, a, &Pose::IDENTITY, b, pose_b, &o)?;
        let mut times = Vec::new();
        for _ in 0..self.runs {
            let t0 = Instant::now();
            r = self
                .det
                .query(&mut self.scratch, a, &Pose::IDENTITY, b, pose_b, &o)?;
            times.push(t0.elapsed().as_secs_f64() * 1e3);
        }
        Ok((median(times), r))
    }

    /// Largest penetration depth in the scan that is missed (`None`: none missed).
    /// Worst over `OFFSETS` lateral shifts `(o, −o, 0)` of B.
    fn largest_missed(
        &mut self,
        a: &ImageMesh,
        b: &ImageMesh,
        pose_at: &dyn Fn(f64) -> Pose,
        res: u32,
    ) -> Result<Option<f64>> {
        const OFFSETS: [f64; 4] = [0.0, 0.0113, 0.0239, 0.0371];
        let o = ImageOptions {
            resolution: res,
            ..Default::default()
        };
        let mut worst: Option<f64> = None;
        for off in OFFSETS {
            for k in 0..40 {
                let d = 0.1 * 2f64.powf(-(k as f64) / 2.0);
                let mut pose = pose_at(d);
                pose.translation += DVec3::new(off, -off, 0.0);
                let r = self
                    .det
                    .query(&mut self.scratch, a, &Pose::IDENTITY, b, &pose, &o)?;
                if !r.collide {
                    worst = Some(worst.map_or(d, |w| w.max(d)));
                    break;
                }
            }
        }
        Ok(worst)
    }
}

/// Options of `cargo xtask bench image`.
#[derive(clap::Args, Debug)]
pub struct Opts {
    /// Resolutions (pixels across the overlap region's longer side).
    #[arg(
        long,
        value_name = "R,..",
        value_delimiter = ',',
        default_value = "64,128,256,512,1024,2048"
    )]
    pub resolutions: Vec<u32>,
    /// Timed runs per point (the median is reported).
    #[arg(long, value_name = "N", default_value_t = 5, value_parser = crate::positive::<usize>)]
    pub runs: usize,
    /// Folder for image.md and image.svg.
    #[arg(long, value_name = "DIR", default_value_os_t = crate::workspace_path("testdata/bench"))]
    pub out: PathBuf,
}

/// Runs the suite.
pub fn run(o: Opts) -> Result<()> {
    let Opts {
        resolutions,
        runs,
        out: out_dir,
    } = o;
    let det = match ImageDetector::headless() {
        Ok(d) => d,
        Err(e) => {
            if std::env::var("FRCD_REQUIRE_GPU").as_deref() == Ok("1") {
                bail!("FRCD_REQUIRE_GPU=1 but no device: {e}");
            }
            println!("SKIP bench image: {e}");
            return Ok(());
        }
    };
    let adapter = det.context().adapter_name();
    println!("bench image on {adapter}");
    let mut bench = Bench {
        det: &det,
        scratch: ImageScratch::default(),
        runs,
    };

    // Scenes.
    let cube = shapes::cuboid(DVec3::ONE);
    let slab = shapes::cuboid(DVec3::new(1.0, 1.0, 0.5));
    let g_cube = det.upload("cube", &cube)?;
    let g_slab = det.upload("slab", &slab)?;
    let (angle, t) = (0.5, DVec3::new(1.2, 0.3, 0.4));
    let boxes_pose = Pose::new(t, DQuat::from_rotation_z(angle));
    let square = |c: DVec2, rot: f64| -> Vec<DVec2> {
        [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
            .iter()
            .map(|&(x, y)| c + DVec2::from_angle(rot).rotate(DVec2::new(x, y)))
            .collect()
    };
    let boxes_exact = clip_area(&square(DVec2::ZERO, 0.0), &square(t.truncate(), angle))
        * (1.0f64.min(t.z + 0.5) - (-1.0f64).max(t.z - 0.5));

    let ball: TriMesh = shapes::icosphere(1.0, 5);
    let r_eq = (3.0 * ball.signed_volume() / (4.0 * PI)).cbrt();
    let g_ball = det.upload("ball", &ball)?;
    let diag = DVec3::ONE.normalize();
    let lens_pose = Pose::from_translation(diag * 1.5);
    let lens_exact = lens(r_eq, 1.5);
    let tess = (lens(1.0, 1.5) - lens_exact) / lens_exact;

    let rot = DQuat::from_rotation_z(PI / 4.0) * DQuat::from_rotation_x(PI / 4.0);
    let lowest = (0..8)
        .map(|i| {
            let c = DVec3::new(
                if i & 1 == 0 { -1.0 } else { 1.0 },
                if i & 2 == 0 { -1.0 } else { 1.0 },
                if i & 4 == 0 { -1.0 } else { 1.0 },
            );
            (rot * c).z
        })
        .fold(f64::INFINITY, f64::min);
    let corner_at = move |d: f64| Pose::new(DVec3::new(0.1, 0.2, 1.0 - lowest - d), rot);
    // B turned 45° about z, its face x + y = const pressed by `d` over A's edge x = y = 1.
    let edge_rot = DQuat::from_rotation_z(PI / 4.0);
    let edge_at = move |d: f64| {
        let c = 1.0 + std::f64::consts::FRAC_1_SQRT_2 * (1.0 - d);
        Pose::new(DVec3::new(c, c, 0.3), edge_rot)
    };

    let mut rows = Vec::new();
    for &res in &resolutions {
        let (ms, r) = bench.time(&g_cube, &g_slab, &boxes_pose, res)?;
        rows.push(Row {
            scene: "boxes",
            resolution: res,
            pixels: (r.image.width, r.image.height),
            layers: r.layers,
            ms,
            volume_error: Some((r.volume - boxes_exact).abs() / boxes_exact),
            volume_estimate: Some(r.volume_error_estimate / boxes_exact),
            missed: None,
            pixel_size: r.bounds.pixel_size,
            depth_bound: r.bounds.depth,
        });
        let (ms, r) = bench.time(&g_ball, &g_ball, &lens_pose, res)?;
        rows.push(Row {
            scene: "lens",
            resolution: res,
            pixels: (r.image.width, r.image.height),
            layers: r.layers,
            ms,
            volume_error: Some((r.volume - lens_exact).abs() / lens_exact),
            volume_estimate: Some(r.volume_error_estimate / lens_exact),
            missed: None,
            pixel_size: r.bounds.pixel_size,
            depth_bound: r.bounds.depth,
        });
        let scans: [(&'static str, &dyn Fn(f64) -> Pose); 2] =
            [("corner", &corner_at), ("edge", &edge_at)];
        for (scene, at) in scans {
            let missed = bench.largest_missed(&g_cube, &g_cube, at, res)?;
            let (ms, r) = bench.time(&g_cube, &g_cube, &at(0.01), res)?;
            rows.push(Row {
                scene,
                resolution: res,
                pixels: (r.image.width, r.image.height),
                layers: r.layers,
                ms,
                volume_error: None,
                volume_estimate: None,
                missed: Some(missed.unwrap_or(0.0)),
                pixel_size: r.bounds.pixel_size,
                depth_bound: r.bounds.depth,
            });
        }
        for row in &rows[rows.len() - 4..] {
            println!("{}", table_line(row));
        }
    }

    std::fs::create_dir_all(&out_dir)?;
    let mut md = String::new();
    writeln!(md, "# frcd-image: time against resolution against error\n")?;
    md.push_str(&intro(
        &adapter,
        det.context().is_software(),
        runs,
        std::thread::available_parallelism().map_or(0, |n| n.get()),
    ));
    writeln!(
        md,
        "- `boxes`: cube vs 1×1×0.5 box turned 0.5 rad, exact volume {boxes_exact:.6}.\n\
         - `lens`: two 20,480-triangle icospheres 1.5 apart on the diagonal; error against the \
         lens of volume-equivalent spheres ({lens_exact:.6}; tessellation alone differs from \
         the unit-sphere lens by {:.2}%).\n\
         - `corner`: cube corner pressed into a cube face (45°/45°); `missed` = largest \
         penetration depth of the scan 0.1·2^(-k/2) that is not detected (0: none missed down \
         to {:.1e}).\n\
         - `edge`: a cube turned 45° about z pressed by its face into a cube's vertical edge; \
         `missed` likewise. Both scans take the worst of four lateral offsets.\n",
        tess * 100.0,
        0.1 * 2f64.powf(-19.5)
    )?;
    writeln!(
        md,
        "| scene | resolution | image px | layers A/B | ms | volume error | error estimate | missed penetration | pixel | depth bound |"
    )?;
    writeln!(md, "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")?;
    for r in &rows {
        writeln!(md, "{}", table_line(r))?;
    }
    std::fs::write(out_dir.join("image.md"), &md)?;
    plot(&rows, &out_dir.join("image.svg"), &adapter)?;
    println!(
        "wrote {} and {}",
        out_dir.join("image.md").display(),
        out_dir.join("image.svg").display()
    );
    Ok(())
}

fn table_line(r: &Row) -> String {
    let opt = |v: Option<f64>, pct: bool| match v {
        Some(x) if pct => format!("{:.3}%", x * 100.0),
        Some(x) => format!("{x:.2e}"),
        None => "".into(),
    };
    format!(
        "| {} | {} | {}×{} | {}/{} | {:.1} | {} | {} | {} | {:.2e} | {:.1e} |",
        r.scene,
        r.resolution,
        r.pixels.0,
        r.pixels.1,
        r.layers[0],
        r.layers[1],
        r.ms,
        opt(r.volume_error, true),
        opt(r.volume_estimate, true),
        opt(r.missed, false),
        r.pixel_size,
        r.depth_bound
    )
}

/// The table's first paragraph: the adapter, and on a software adapter only, the caveat that no
/// real GPU ran it (it was written on every adapter until a real GPU's table said so).
fn intro(adapter: &str, software: bool, runs: usize, threads: usize) -> String {
    format!(
        "Generated by `cargo xtask bench image` on adapter **{adapter}**{}. Median of {runs} \
         queries per point (upload excluded, scratch reused, readback included), {threads} CPU \
         threads on the machine.{}\n\n",
        if software {
            " (software rasterizer)"
        } else {
            ""
        },
        if software {
            " No real GPU was available to this run: on a software rasterizer time grows with \
             pixels × layers, and other work on the machine adds noise."
        } else {
            ""
        }
    )
}

fn plot(rows: &[Row], path: &std::path::Path, adapter: &str) -> Result<()> {
    use crate::plot::{self, Axis, Chart, Legend, Series};
    let scenes = ["boxes", "lens", "corner", "edge"];
    let colors = [plot::RED, plot::BLUE, plot::GREEN, plot::MAGENTA];
    let res = |r: &Row| r.resolution as f64;
    let (rmin, rmax) = plot::extent(rows.iter().map(res)).unwrap_or((64.0, 2048.0));
    let tmax = rows.iter().map(|r| r.ms).fold(1.0, f64::max);
    let tmin = rows
        .iter()
        .map(|r| r.ms)
        .fold(f64::INFINITY, f64::min)
        .max(1e-3);
    // Volume scenes plot their relative volume error, penetration scenes the depth missed.
    let error = |r: &Row| r.volume_error.or(r.missed).filter(|e| *e > 0.0);
    let emax = rows.iter().filter_map(error).fold(1e-6, f64::max);
    let emin = rows
        .iter()
        .filter_map(error)
        .fold(f64::INFINITY, f64::min)
        .min(emax / 10.0);
    let x_axis = || {
        Axis::log(
            "resolution (pixels across the overlap)",
            rmin * 0.9..rmax * 1.1,
        )
    };
    let panel = |caption: String, size, y: Axis, y_labels, value: &dyn Fn(&Row) -> Option<f64>| {
        let mut chart = Chart::new(caption, x_axis(), y).caption_size(size);
        (chart.margin, chart.x_label_area, chart.y_label_area) = (10, 35, y_labels);
        chart.legend = Legend::MiddleRight;
        for (s, c) in scenes.iter().zip(colors) {
            let pts = rows.iter().filter(|r| r.scene == *s);
            let pts = pts.filter_map(|r| value(r).map(|v| (res(r), v)));
            chart = chart.series(Series::line(*s, c, pts.collect()));
        }
        chart
    };
    let time = panel(
        format!("query time ({adapter})"),
        14,
        Axis::log("ms per query", tmin * 0.8..tmax * 1.25),
        55,
        &|r| Some(r.ms),
    );
    let err = panel(
        "error: relative volume error (boxes, lens); missed depth (corner, edge)".into(),
        13,
        Axis::log("error", emin * 0.5..emax * 2.0),
        60,
        &error,
    );
    plot::write_svg(path, (1100, 460), &[time, err])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_a_software_adapter_is_called_no_real_gpu() {
        let real = intro("NVIDIA H200 (DiscreteGpu, Vulkan)", false, 5, 16);
        let soft = intro("llvmpipe (Cpu, Vulkan)", true, 5, 2);
        assert!(
            !real.contains("No real GPU") && !real.contains("software"),
            "{real}"
        );
        assert!(
            soft.contains("No real GPU") && soft.contains("(software rasterizer)"),
            "{soft}"
        );
        assert!(real.contains("**NVIDIA H200 (DiscreteGpu, Vulkan)**") && real.ends_with("\n\n"));
    }

    #[test]
    fn plot_writes_every_series() {
        let mut rows = Vec::new();
        for scene in ["boxes", "lens", "corner", "edge"] {
            for (k, resolution) in [64u32, 256, 1024].into_iter().enumerate() {
                let e = 0.1 / (k + 1) as f64;
                let volume = matches!(scene, "boxes" | "lens");
                rows.push(Row {
                    scene,
                    resolution,
                    pixels: (resolution, resolution),
                    layers: [2, 2],
                    ms: 0.5 * (k + 1) as f64,
                    volume_error: volume.then_some(e),
                    volume_estimate: volume.then_some(e),
                    missed: (!volume).then_some(e / 2.0),
                    pixel_size: 1.0 / resolution as f64,
                    depth_bound: 1e-6,
                });
            }
        }
        let path = crate::plot::TempFile(
            std::env::temp_dir().join(format!("frcd-xtask-image-{}.svg", std::process::id())),
        );
        plot(&rows, &path, "test adapter").unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        for s in [
            "boxes",
            "lens",
            "corner",
            "edge",
            "query time (test adapter)",
        ] {
            assert!(svg.contains(s), "{s} missing");
        }
    }
}
