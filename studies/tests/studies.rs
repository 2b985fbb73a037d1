//! The studies' fast checks, one module per file of this directory, linked into one test binary
//! (each binary instantiates the engine's generic step anew in a release build). Run one file's
//! tests with `cargo test --release -p rkmpm-studies --test studies collapse::`.

mod checkpoint;
mod collapse;
mod convergence;
mod impact;
mod scene_files;
mod vibrating_bar;
