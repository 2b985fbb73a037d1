//! The C API called from Rust: every entry point, its errors, a fuzzer of call sequences, and the
//! committed header against what cbindgen generates from this crate.
//!
//! The tests call the C API as C does, invalid pointers and lengths included (that is what they
//! test), so the library's unsafe lints do not apply to them.
#![allow(unsafe_op_in_unsafe_fn, clippy::undocumented_unsafe_blocks)]

mod api_checks_table;
mod c_api;
mod fuzz;
mod header;
