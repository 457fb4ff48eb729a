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
//! `FRCD_OBB_ISA=baseline` in the environment (read once per process) makes every query take
//! the baseline build, to measure one against the other in the same binary.

/// Which build of the wide traversal this process's queries run: `"avx2"` or `"baseline"`
/// (SSE2 on x86-64, the target's own vector unit elsewhere), for benchmarks and logs to
/// report next to their timings. Both builds give the same answers bit for bit.
///
/// ```
/// let isa = frcd_obb::wide_traversal_isa();
/// assert!(isa == "avx2" || isa == "baseline");
/// ```
pub fn wide_traversal_isa() -> &'static str {
    if has_avx2() { "avx2" } else { "baseline" }
}

/// True when the running CPU has AVX2 and the environment does not ask for the baseline build
/// (always false off x86-64).
#[inline]
pub(crate) fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        static BASELINE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
        std::arch::is_x86_feature_detected!("avx2")
            && !*BASELINE.get_or_init(|| {
                std::env::var("FRCD_OBB_ISA").is_ok_and(|v| v.eq_ignore_ascii_case("baseline"))
            })
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
