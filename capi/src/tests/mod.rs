//! The C API called from Rust: every entry point, its errors, a fuzzer of call sequences, and the
//! committed header against what cbindgen generates from this crate.

mod api_checks_table;
mod c_api;
mod fuzz;
mod header;
