//! # rkmpm
//!
//! An embeddable explicit Material Point Method (MPM) engine: Lagrangian material points on an
//! Eulerian background grid, in 2D and 3D from one code (`Sim<2>` and `Sim<3>`).
//!
//! One step (`Sim::step`) runs the phases of `METHOD.md` section 1:
//! shape functions → particle to grid → grid update (with boundary conditions) →
//! grid to particle → constitutive update → grid reset. USL and MUSL are selectable,
//! with a PIC/FLIP blend or APIC transfer.
//!
//! This crate is the engine a Rust program depends on. Its C face (`include/rkmpm.h`,
//! `librkmpm.a`, `librkmpm.so`) is the crate `rkmpm-capi` in `capi/`, a thin layer over this API;
//! the `rkmpm` command is `runner/`, the validation studies `studies/`. Options are declared once,
//! in [`options`], for the Rust API, the C API, scene files and checkpoints.
//!
//! ```
//! use rkmpm::{Sim, Shape, Material};
//! let mut sim = Sim::<2>::new([0.0, 0.0], [16, 16], 1.0 / 16.0).unwrap();
//! sim.set_shape(Shape::BSpline2).unwrap();
//! let steel = sim.add_material(Material::linear_elastic(7800.0, 200e9, 0.3).unwrap());
//! sim.add_particles(steel, &[[0.5, 0.5].into()], &[1e-3], None).unwrap();
//! let dt = sim.stable_dt(0.3).unwrap();
//! sim.step(dt).unwrap();
//! assert_eq!(sim.steps(), 1);
//! ```

// Where the engine uses `unsafe`, and why (every block carries a `SAFETY:` comment naming the
// contract it keeps; the runner and the studies forbid `unsafe`):
// - Parallel writes into one array, each element by one thread at a time: the primitives of
//   `grid/shared.rs` (`SharedSlice`, `NodeScatter`, `scatter_add`, `NodeList`; that invariant is
//   in its header) and `NewStateWriter` over them (`step/grid_to_particle.rs`). Their callers
//   keep the invariant by a schedule and name it: particle to grid's coloured tasks
//   (`Bins::run_tasks` in `grid/blocks.rs`) for the scatters of `step/particle_to_grid.rs`,
//   `shape/stencil.rs` and VC's sums in `integration/mod.rs`; one node per task in
//   `step/grid_update.rs`, the reset in `grid/mod.rs`, the active list in `grid/blocks.rs` and
//   the rows of `integration/node_operator.rs`; one particle per task in
//   `step/grid_to_particle.rs` and `step/constitutive_update.rs`; disjoint stretches in the
//   particles' sort (`grid/blocks.rs`).
// - The SIMD kernels of `shape/simd.rs`, `unsafe fn`s whose one precondition is AVX2 and FMA,
//   called from `shape/stencil.rs` only under `cpu::Lanes::avx2()`, which `cpu.rs` sets after
//   checking the processor.
// Miri runs the tests of the shared primitives, the coloured schedule and the new state's writer
// (`scripts/test-miri.sh`).
#![deny(unsafe_op_in_unsafe_fn)]
#![deny(clippy::undocumented_unsafe_blocks)]

pub mod walls;

/// The walls' old path.
#[deprecated(note = "renamed to `rkmpm::walls`")]
pub mod boundary {
    pub use crate::walls::*;
    #[deprecated(note = "renamed to `Wall`")]
    pub type Boundary = crate::options::Wall;
}
pub(crate) mod energy;
pub mod error;
pub mod io;
pub mod material;
pub mod math;
pub mod options;
pub mod particles;
/// The plain serial step the fast one is tested against (tests only).
#[cfg(test)]
mod reference;
pub mod sim;

// The engine's internals: private, or public with the feature `internals` (for the per-phase
// benchmarks, which call the phases one by one); not part of the supported API. Each is declared
// twice, not through a macro, so that rustfmt finds the files.
/// Multi-velocity-field contact between bodies.
#[cfg(feature = "internals")]
pub mod contact;
#[cfg(not(feature = "internals"))]
pub(crate) mod contact;
/// The instruction set the loops use.
#[cfg(feature = "internals")]
pub mod cpu;
#[cfg(not(feature = "internals"))]
pub(crate) mod cpu;
/// The background grid, its blocks and node storage.
#[cfg(feature = "internals")]
pub mod grid;
#[cfg(not(feature = "internals"))]
pub(crate) mod grid;
/// VC integration and the boundary points.
#[cfg(feature = "internals")]
pub mod integration;
#[cfg(not(feature = "internals"))]
pub(crate) mod integration;
/// Shape functions and their stencils.
#[cfg(feature = "internals")]
pub mod shape;
#[cfg(not(feature = "internals"))]
pub(crate) mod shape;
/// The step's phases.
#[cfg(feature = "internals")]
pub mod step;
#[cfg(not(feature = "internals"))]
pub(crate) mod step;

pub use error::{Error, ErrorKind, Result};
pub use grid::Grid;
pub use integration::{BoundaryPoints, VcSolve};
pub use material::Material;
pub use particles::{Field, Particles};
pub use shape::{Shape, UniformRng};
pub use sim::{
    BodyForce, Integration, Scheme, Sim, Transfer, DEFAULT_VC_SURFACE_REFRESH, MAX_THREADS,
};
pub use step::{MemoryUse, PhaseTimes};
pub use walls::{Side, Wall};

pub use math::{determinant, floor_index, Matrix, Vector};
