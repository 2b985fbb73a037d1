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

// The unsafe operations are defined in two audited places: the parallel node sums' primitives
// (`grid/shared.rs`, whose header states the one invariant) and the SIMD kernels
// (`shape/simd.rs`, entered through `cpu::Lanes`). The phases call them in
// `unsafe` blocks, each with a `SAFETY:` comment naming the schedule that makes it sound.
// Miri runs the primitives' tests (`scripts/test-miri.sh`).
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
pub mod options;
pub mod particles;
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
pub use sim::{BodyForce, Integration, Scheme, Sim, Transfer, DEFAULT_VC_SURFACE_REFRESH};
pub use walls::{Side, Wall};

/// A column vector of the simulation's dimension.
pub type Vector<const D: usize> = nalgebra::SVector<f64, D>;
/// A square matrix of the simulation's dimension.
pub type Matrix<const D: usize> = nalgebra::SMatrix<f64, D, D>;

/// `⌊x⌋` as an integer, without the library call `f64::floor` makes on baseline x86-64 (the
/// same value for every `x`, saturating at the ends of `i64` like `x.floor() as i64`).
#[inline(always)]
pub fn floor_index(x: f64) -> i64 {
    let t = x as i64;
    t.saturating_sub(((t as f64) > x) as i64)
}

/// Determinant of a `D×D` matrix (closed form for 1, 2 and 3; LU beyond).
#[inline]
pub fn determinant<const D: usize>(m: &Matrix<D>) -> f64 {
    match D {
        1 => m[(0, 0)],
        2 => m[(0, 0)] * m[(1, 1)] - m[(0, 1)] * m[(1, 0)],
        3 => {
            m[(0, 0)] * (m[(1, 1)] * m[(2, 2)] - m[(1, 2)] * m[(2, 1)])
                - m[(0, 1)] * (m[(1, 0)] * m[(2, 2)] - m[(1, 2)] * m[(2, 0)])
                + m[(0, 2)] * (m[(1, 0)] * m[(2, 1)] - m[(1, 1)] * m[(2, 0)])
        }
        _ => nalgebra::DMatrix::from_column_slice(D, D, m.as_slice()).determinant(),
    }
}

#[cfg(test)]
mod tests {
    /// `floor_index` is `x.floor() as i64` everywhere: near integers, at ±0, at the ends of
    /// `i64`, beyond them, at infinities and NaN.
    #[test]
    fn floor_index_is_the_floor() {
        let mut xs = vec![0.0, -0.0, 0.5, -0.5, 1.0, -1.0, 2.5, -2.5, 1e300, -1e300];
        xs.extend([
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
        ]);
        xs.extend([
            9.2e18,
            -9.2e18,
            9.3e18,
            -9.3e18,
            -9_223_372_036_854_775_808.0,
        ]);
        for k in -1000..1000 {
            let x = k as f64 * 0.173;
            xs.extend([
                x,
                x.next_up(),
                x.next_down(),
                k as f64,
                (k as f64).next_down(),
            ]);
        }
        for x in xs {
            assert_eq!(super::floor_index(x), x.floor() as i64, "x = {x:e}");
        }
    }
}
