//! The runner's integration tests, one module per file of this directory, linked into one test
//! binary (each binary instantiates the engine's generic step anew in a release build).

mod cli;
mod pictures;
