//! Shared scene and workload generators for the frcd criterion benches and `cargo xtask bench`.

pub mod scenes;
pub mod tritri_oracle;
pub mod tritri_pairs;

/// This thread's CPU time in seconds (Linux: `CLOCK_THREAD_CPUTIME_ID`), `None` elsewhere. On a
/// machine shared with other work a build's wall time includes the time it waited for a core,
/// which penalises the longer build more; its CPU time does not.
#[cfg(target_os = "linux")]
pub fn thread_cpu() -> Option<f64> {
    #[repr(C)]
    struct Timespec {
        sec: i64,
        nsec: i64,
    }
    unsafe extern "C" {
        fn clock_gettime(clock: i32, tp: *mut Timespec) -> i32;
    }
    const CLOCK_THREAD_CPUTIME_ID: i32 = 3;
    let mut t = Timespec { sec: 0, nsec: 0 };
    // SAFETY: `t` is a valid, writable timespec; the call writes only to it.
    let rc = unsafe { clock_gettime(CLOCK_THREAD_CPUTIME_ID, &mut t) };
    (rc == 0).then_some(t.sec as f64 + t.nsec as f64 * 1e-9)
}

#[cfg(not(target_os = "linux"))]
pub fn thread_cpu() -> Option<f64> {
    None
}
