//! Shared scene and workload generators for the frcd criterion benches and `cargo xtask bench`.
