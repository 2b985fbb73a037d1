//! The `rkmpm` command's parts: scene files (TOML in, a ready simulation out) and the PNG
//! snapshots of a run's particles. The command itself is `src/main.rs`.

#![forbid(unsafe_code)]

pub mod scene;
pub mod snapshot;
