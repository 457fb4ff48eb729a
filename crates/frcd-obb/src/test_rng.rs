//! The unit tests' seeded generator: xorshift64 (13, 7, 17), so that a test's draws depend on
//! its seed only.

/// The xorshift64 sequence from `seed` (not 0).
pub(crate) fn xorshift(mut seed: u64) -> impl FnMut() -> u64 {
    move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    }
}
