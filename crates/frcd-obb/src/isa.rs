//! The instruction set the wide traversal's hot loop runs with, chosen per query at run time.
//!
//! The four-lane box test (`wide.rs`) is written as plain arrays that the compiler vectorises
//! for whatever target it builds for. The Rust target for x86-64 defaults to SSE2 only, where
//! every lane operation is a two-operand instruction: the test's thirty-odd live lane values
//! need register copies and spills (1,020 `movaps` in the baseline build of the traversal
//! loop against 388 `vmovaps` in the AVX2 build), and the lanes' f64 centres take two 128-bit
//! registers. Engines rarely build with `-C target-cpu`, so the traversal is compiled twice:
//! once for the baseline and once with AVX2 (`#[target_feature]`), and each query takes the
//! AVX2 build when the running CPU has it (`is_x86_feature_detected!`, cached by the standard
//! library). Measured on a Zen 3 EPYC: disjoint near-contact queries 1.3-1.6× faster.
//!
//! Both builds perform the same IEEE operations in the same order: Rust never contracts a
//! multiply and an add into a fused multiply-add, and FMA is not enabled for the AVX2 build
//! either, so every lane's verdict, every recorded margin, counter and answer is bit for bit
//! the same (tested in `query/tests.rs`), and the error bounds of `wide.rs` hold for both. (The AVX2
//! build runs two steps' lanes as one eight-lane test that stops once both are done; where no
//! front is recorded a lane's margin there may come from more axes, never its verdict.)
//!
//! **A third build, with AVX-512 VL, on AMD CPUs that have it (Zen 4 and later).** The same
//! 256-bit AVX2 code compiled with `avx512f,avx512vl` is EVEX-encoded and gets 32 vector
//! registers instead of 16, so the eight-lane test (about 33 live lane values) spills about
//! half as often (ymm operands on the stack in the traversal function: 1,238 → 629).
//! Measured in one process, the two builds alternated over 25 rounds on a Zen 4 EPYC
//! (2026-12-01, `benches/benches/isa_builds.rs`; `docs/performance/cpu-core.md`, eighteenth
//! sitting): the near-contact knots 0.898× (first contact) and 0.970× (all pairs) the AVX2
//! build's time (0.887× / 0.942× in an earlier 15-round session), the slow knots 0.90-0.93×,
//! the dense sweep's all pairs 0.95×, the CAD pairs 0.94-1.00× (within the host's noise). On
//! an Intel Xeon (Emerald Rapids) the same build was about 15 % *slower* (sixteenth sitting),
//! so Intel CPUs keep the AVX2 build. Rust never contracts into FMA here either (the `fma`
//! feature that `avx512f` implies only makes the instructions available), so all three builds
//! give the same bits.
//!
//! `FRCD_OBB_ISA` in the environment (read once per process) overrides the choice:
//! `baseline`, `avx2`, or `avx512` (taken only where the CPU has AVX-512 F and VL, on any
//! vendor), to measure one build against another with the same binary;
//! [`set_wide_traversal_isa`] does the same from code, for benchmarks that alternate the
//! builds in one process (`benches/benches/isa_builds.rs`).

use std::sync::atomic::{AtomicU8, Ordering};

/// One build of the wide traversal's hot loop.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Isa {
    /// SSE2 on x86-64; the target's own vector unit elsewhere.
    Baseline,
    /// AVX2 (`#[target_feature(enable = "avx2")]`).
    Avx2,
    /// AVX2 code with AVX-512 F and VL enabled: EVEX encoding, 32 vector registers.
    Avx512,
}

impl Isa {
    /// The name [`wide_traversal_isa`] reports.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Isa::Baseline => "baseline",
            Isa::Avx2 => "avx2",
            Isa::Avx512 => "avx512",
        }
    }
}

/// Which build of the wide traversal this process's queries run: `"avx512"` (AVX2 code with
/// AVX-512 VL's 32 registers, on AMD CPUs that have it), `"avx2"` or `"baseline"` (SSE2 on
/// x86-64, the target's own vector unit elsewhere), for benchmarks and logs to report next to
/// their timings. Every build gives the same answers bit for bit.
///
/// ```
/// let isa = frcd_obb::wide_traversal_isa();
/// assert!(["avx512", "avx2", "baseline"].contains(&isa));
/// ```
pub fn wide_traversal_isa() -> &'static str {
    best().name()
}

/// True when the running CPU has AVX2 and the environment does not ask for the baseline build
/// (always false off x86-64): the AVX2 builds of the `World`'s box updates.
#[inline]
pub(crate) fn has_avx2() -> bool {
    best() != Isa::Baseline
}

/// The build this process's queries run: detected on first use, then one relaxed load.
#[inline]
pub(crate) fn best() -> Isa {
    if let Some(isa) = decode(CHOSEN.load(Ordering::Relaxed)) {
        return isa;
    }
    let forced = std::env::var("FRCD_OBB_ISA").ok();
    let isa = choose(detect(), forced.as_deref());
    // A concurrent `set_wide_traversal_isa` wins: store only over "not yet chosen".
    let _ = CHOSEN.compare_exchange(0, code(isa), Ordering::Relaxed, Ordering::Relaxed);
    decode(CHOSEN.load(Ordering::Relaxed)).unwrap_or(isa)
}

/// The process's build: 0 not yet chosen, else [`code`] of it.
static CHOSEN: AtomicU8 = AtomicU8::new(0);

fn code(isa: Isa) -> u8 {
    match isa {
        Isa::Baseline => 1,
        Isa::Avx2 => 2,
        Isa::Avx512 => 3,
    }
}

fn decode(c: u8) -> Option<Isa> {
    match c {
        1 => Some(Isa::Baseline),
        2 => Some(Isa::Avx2),
        3 => Some(Isa::Avx512),
        _ => None,
    }
}

/// Makes the queries this process starts from now on run the wide traversal's build `name`
/// (`"baseline"`, `"avx2"` or `"avx512"`, as `FRCD_OBB_ISA` takes them) where the CPU has it,
/// else the build the CPU would get by default; returns the build now in force. For
/// benchmarks that compare the builds in one process: every build gives the same answers bit
/// for bit, so nothing but speed depends on it. A query already running keeps its build.
///
/// ```
/// let now = frcd_obb::set_wide_traversal_isa("baseline");
/// assert_eq!(now, "baseline");
/// assert_eq!(frcd_obb::wide_traversal_isa(), "baseline");
/// ```
pub fn set_wide_traversal_isa(name: &str) -> &'static str {
    let isa = choose(detect(), Some(name));
    CHOSEN.store(code(isa), Ordering::Relaxed);
    isa.name()
}

/// What the running CPU offers: (AVX2, AVX-512 F and VL, made by AMD).
fn detect() -> (bool, bool, bool) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::is_x86_feature_detected as has;
        let avx512 = has!("avx512f") && has!("avx512vl");
        (has!("avx2"), avx512, amd())
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        (false, false, false)
    }
}

/// True on an AMD CPU (vendor string `AuthenticAMD`).
#[cfg(target_arch = "x86_64")]
fn amd() -> bool {
    // SAFETY: `cpuid` exists on every x86-64 CPU; leaf 0 returns the vendor string.
    #[allow(unused_unsafe, unsafe_code)]
    let r = unsafe { std::arch::x86_64::__cpuid(0) };
    let mut v = [0u8; 12];
    v[..4].copy_from_slice(&r.ebx.to_le_bytes());
    v[4..8].copy_from_slice(&r.edx.to_le_bytes());
    v[8..].copy_from_slice(&r.ecx.to_le_bytes());
    &v == b"AuthenticAMD"
}

/// The build for a CPU with `(avx2, avx512, amd)` and the `FRCD_OBB_ISA` value `forced`: an
/// override is taken only where the CPU has what it names (an unknown value is ignored).
fn choose((avx2, avx512, amd): (bool, bool, bool), forced: Option<&str>) -> Isa {
    let auto = if avx2 && avx512 && amd {
        Isa::Avx512
    } else if avx2 {
        Isa::Avx2
    } else {
        Isa::Baseline
    };
    match forced.map(str::to_ascii_lowercase).as_deref() {
        Some("baseline") => Isa::Baseline,
        Some("avx2") if avx2 => Isa::Avx2,
        Some("avx512") if avx2 && avx512 => Isa::Avx512,
        _ => auto,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn avx512_only_on_amd_unless_forced_and_never_beyond_the_cpu() {
        let (none, avx2, intel512, amd512) = (
            (false, false, false),
            (true, false, true),
            (true, true, false),
            (true, true, true),
        );
        assert_eq!(choose(none, None), Isa::Baseline);
        assert_eq!(choose(avx2, None), Isa::Avx2);
        assert_eq!(choose(intel512, None), Isa::Avx2);
        assert_eq!(choose(amd512, None), Isa::Avx512);
        // Overrides: down always, up only as far as the CPU goes; unknown values ignored.
        assert_eq!(choose(amd512, Some("AVX2")), Isa::Avx2);
        assert_eq!(choose(amd512, Some("baseline")), Isa::Baseline);
        assert_eq!(choose(intel512, Some("avx512")), Isa::Avx512);
        assert_eq!(choose(avx2, Some("avx512")), Isa::Avx2);
        assert_eq!(choose(none, Some("avx2")), Isa::Baseline);
        assert_eq!(choose(amd512, Some("sse9")), Isa::Avx512);
    }

    #[test]
    fn the_reported_build_is_one_the_cpu_runs() {
        let (avx2, avx512, _) = detect();
        match best() {
            Isa::Avx512 => assert!(avx2 && avx512),
            Isa::Avx2 => assert!(avx2),
            Isa::Baseline => {}
        }
    }
}
