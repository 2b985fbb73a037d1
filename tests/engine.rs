//! The engine's integration tests, one module per file of this directory, linked into one test
//! binary: a release build instantiates the engine's generic step once per binary, so one binary
//! instead of five saves most of their build time. Run one file's tests with
//! `cargo test --release --test engine vc_conservation::`.

mod contact;
mod energies;
mod run_bounds;
mod stress;
mod vc_conservation;
