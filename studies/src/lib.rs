//! The validation studies of rkmpm: the scenes they run (vibrating bar, colliding disks, granular
//! collapse, Taylor bar, penetration) and the verification problems with exact solutions
//! (manufactured solutions, self-weight column), built on the engine's public API.
//! `examples/` regenerates the tables and plots under `docs/`; `tests/` checks them.

#![forbid(unsafe_code)]

pub mod scenes;
pub mod verification;
