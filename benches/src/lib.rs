//! Shared scene and workload generators for the frcd criterion benches and `cargo xtask bench`.

pub mod scenes;
pub mod tritri_oracle;
pub mod tritri_pairs;
