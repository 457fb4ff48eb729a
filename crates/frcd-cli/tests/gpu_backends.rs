//! Which GPU adapter the CLI gets from wgpu's environment, and what happens without one:
//! `WGPU_BACKEND=gl` finds the GL adapter (the binary compiles wgpu's `gles` backend in) and
//! renders and checks there, except the image-space backend, which GL cannot run and refuses
//! with a typed error; a machine whose Vulkan driver is missing
//! (`VK_ICD_FILENAMES=/nonexistent.json`) falls back to GL, and with Vulkan forced it gets a
//! "no GPU adapter" error (or a CPU fallback where the backend allows one), never a panic.
//! Runs that need an adapter the machine lacks print SKIP unless FRCD_REQUIRE_GPU=1.
#![cfg(feature = "gpu")]

mod common;
use common::*;
use frcd_geom::{DVec3, shapes};
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn gpu_required() -> bool {
    std::env::var("FRCD_REQUIRE_GPU").as_deref() == Ok("1")
}

/// Runs frcd in `dir` with `env` set (wgpu's own variables removed first), killed after 120 s.
fn frcd_env(args: &[&str], dir: &Path, env: &[(&str, &str)]) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_frcd"));
    cmd.args(args)
        .current_dir(dir)
        .env_remove("FRCD_COST_MODEL")
        .env_remove("WGPU_BACKEND")
        .env_remove("WGPU_ADAPTER_NAME")
        .env_remove("VK_ICD_FILENAMES")
        .env_remove("VK_DRIVER_FILES")
        .env_remove("VK_ADD_DRIVER_FILES")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    for (k, v) in env {
        cmd.env(k, v);
    }
    let mut child = cmd.spawn().expect("run frcd");
    let t0 = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t0.elapsed() > Duration::from_secs(120) {
            child.kill().ok();
            panic!("frcd {args:?} with {env:?} did not finish in 120 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

/// Two cubes that interfere in frame 1 and not in frame 0.
fn scene(dir: &Path) {
    frcd_io::write_obj(
        dir.join("cube.obj"),
        &shapes::cuboid(DVec3::splat(0.5)),
        "cube",
    )
    .unwrap();
    let scene = r#"{"bodies": [
  {"name": "a", "mesh": "cube.obj", "static": true, "pose": {"t": [0, 0, 0], "q": [0, 0, 0, 1]}},
  {"name": "b", "mesh": "cube.obj", "static": false, "pose": {"t": [-2, 0, 0], "q": [0, 0, 0, 1]}}
 ],
 "frames": [{"b": {"t": [-2, 0.1, 0.05], "q": [0, 0, 0, 1]}},
            {"b": {"t": [0.7, 0.1, 0.05], "q": [0, 0, 0, 1]}}]}"#;
    std::fs::write(dir.join("scene.json"), scene).unwrap();
}

/// The environment of a machine without a Vulkan driver: the loader reads `VK_DRIVER_FILES`
/// before `VK_ICD_FILENAMES` (loader 1.3.207 on), so both point nowhere.
const NO_VULKAN_DRIVER: [(&str, &str); 2] = [
    ("VK_ICD_FILENAMES", "/nonexistent.json"),
    ("VK_DRIVER_FILES", "/nonexistent.json"),
];

/// True (after printing SKIP) when `o` failed for want of an adapter, or because the adapter
/// refused to create a device (a typed error: NVIDIA's GL through headless EGL answers "Parent
/// device is lost"), and none is required.
fn skip(o: &Output, what: &str) -> bool {
    let t = text(o);
    if o.status.success() || gpu_required() {
        return false;
    }
    if t.contains("no GPU adapter") {
        println!("SKIP {what}: no such adapter here");
        return true;
    }
    if t.contains("could not create a device on adapter") && !t.contains("panicked") {
        println!("SKIP {what}: the adapter refused to create a device (typed error)");
        return true;
    }
    false
}

/// Per frame of a JSON report: its interfering pairs as `(a, b, triangle pairs)`.
fn hits(dir: &Path, file: &str) -> Vec<Vec<(String, String, u64)>> {
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join(file)).unwrap()).unwrap();
    v["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            f["interferences"]
                .as_array()
                .unwrap()
                .iter()
                .map(|h| {
                    (
                        h["a"].as_str().unwrap().to_string(),
                        h["b"].as_str().unwrap().to_string(),
                        h["triangle_pairs"].as_u64().unwrap(),
                    )
                })
                .collect()
        })
        .collect()
}

#[test]
fn wgpu_backend_gl_renders_and_checks() {
    let dir = tempdir("gl");
    scene(&dir);
    let gl = [("WGPU_BACKEND", "gl")];
    let o = frcd_env(
        &["render", "scene.json", "--frame", "1", "-o", "f.png"],
        &dir,
        &gl,
    );
    if skip(&o, "render on GL") {
        return;
    }
    assert!(o.status.success(), "{}", text(&o));
    let png = std::fs::read(dir.join("f.png")).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    // The GPGPU backend runs on GL and answers as the CPU does.
    let cpu = frcd_env(
        &[
            "check",
            "scene.json",
            "--backend",
            "cpu",
            "--json",
            "cpu.json",
        ],
        &dir,
        &gl,
    );
    assert!(cpu.status.success(), "{}", text(&cpu));
    let o = frcd_env(
        &[
            "check",
            "scene.json",
            "--backend",
            "gpgpu",
            "--json",
            "gl.json",
        ],
        &dir,
        &gl,
    );
    assert!(o.status.success(), "{}", text(&o));
    let (want, got) = (hits(&dir, "cpu.json"), hits(&dir, "gl.json"));
    assert_eq!(want, got);
    assert!(got[0].is_empty() && got[1].len() == 1, "{got:?}");
    // Image space cannot run on GL: a typed refusal, no panic.
    let o = frcd_env(
        &[
            "check",
            "scene.json",
            "--backend",
            "image",
            "--mode",
            "fast",
        ],
        &dir,
        &gl,
    );
    assert_clean_failure(&o, "GL");
}

#[test]
fn a_missing_vulkan_driver_falls_back_or_fails_cleanly() {
    let dir = tempdir("novk");
    scene(&dir);
    let none = [
        NO_VULKAN_DRIVER[0],
        NO_VULKAN_DRIVER[1],
        ("WGPU_BACKEND", "vulkan"),
    ];
    // Vulkan forced and no Vulkan driver: a typed error for what needs a GPU...
    let o = frcd_env(
        &["render", "scene.json", "--frame", "1", "-o", "f.png"],
        &dir,
        &none,
    );
    assert_clean_failure(&o, "no GPU adapter");
    assert!(!dir.join("f.png").exists());
    let o = frcd_env(&["check", "scene.json", "--backend", "gpgpu"], &dir, &none);
    assert_clean_failure(&o, "GPU");
    // ... and the CPU where the backend may fall back to it.
    let o = frcd_env(
        &[
            "check",
            "scene.json",
            "--backend",
            "hybrid",
            "--json",
            "h.json",
        ],
        &dir,
        &none,
    );
    assert!(o.status.success(), "{}", text(&o));
    let h = hits(&dir, "h.json");
    assert!(h[0].is_empty() && h[1].len() == 1, "{h:?}");
    // No backend forced: wgpu falls back to the GL driver (compiled into the CLI).
    let o = frcd_env(
        &["render", "scene.json", "--frame", "1", "-o", "g.png"],
        &dir,
        &NO_VULKAN_DRIVER,
    );
    if skip(&o, "render with GL only") {
        return;
    }
    assert!(o.status.success(), "{}", text(&o));
    assert!(dir.join("g.png").exists());
}
