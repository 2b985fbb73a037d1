//! Shape functions: one interface, a per-particle stencil of any (fixed per shape) size.
//!
//! Every shape function fills, for a position `x`, the storage indices of its stencil nodes, the
//! values `Ψ_I(x)` and the gradients `∇Ψ_I(x)`. The step computes them once per particle per step
//! into [`Stencils`] and every phase reuses them, so a new shape function (RK) slots in by
//! implementing [`ShapeFunction`] and nothing in the step changes.

mod bspline;
mod monomials;
mod rk;
#[cfg(target_arch = "x86_64")]
mod simd;
mod stencil;

pub use bspline::{BSpline, BSplineOrder};
pub use monomials::Monomials;
#[cfg_attr(not(feature = "internals"), allow(unused_imports))] // for the benchmarks
pub use rk::{cubic_kernel, LatticeRk1, ReproducingKernel, MAX_CONDITION};
#[cfg_attr(not(feature = "internals"), allow(unused_imports))] // for the benchmarks
pub use stencil::{
    in_support, Gathered, ScatterInput, StencilNode, StencilView, Stencils, SupportNodes,
    TensorFactors, TensorStencils, TensorView,
};

use crate::error::Result;
use crate::grid::{Bins, Grid};
use crate::Vector;

#[cfg_attr(not(feature = "internals"), allow(unused_imports))] // for the benchmarks
pub use crate::options::{Shape, ShapeKind};

impl Shape {
    /// Builds the shape function for dimension `D`.
    pub fn build<const D: usize>(&self) -> Result<Box<dyn ShapeFunction<D>>> {
        match *self {
            Shape::Linear => Ok(Box::new(BSpline::new(BSplineOrder::Linear))),
            Shape::BSpline2 => Ok(Box::new(BSpline::new(BSplineOrder::Quadratic))),
            Shape::BSpline3 => Ok(Box::new(BSpline::new(BSplineOrder::Cubic))),
            // On the grid's full lattice RK1 with ã = 2 is the cubic B-spline (to round-off,
            // `rk_order_one_support_two_is_the_cubic_bspline`): computed as one.
            Shape::Rk {
                order: 1,
                support: 2.0,
            } => Ok(Box::new(LatticeRk1::new())),
            Shape::Rk { order, support } => {
                Ok(Box::new(ReproducingKernel::<D>::new(order, support)?))
            }
        }
    }
}

/// Bins the particles at `x` on `grid` by the block of their stencil's first node under `shape`
/// ([`Bins::compute`]).
pub fn bin_particles<const D: usize>(
    bins: &mut Bins<D>,
    shape: &dyn ShapeFunction<D>,
    grid: &Grid<D>,
    x: &[Vector<D>],
) {
    bins.compute(shape.stencil_width(), grid, x, |xi| {
        shape.stencil_origin(xi)
    });
}

/// What every shape function provides.
pub trait ShapeFunction<const D: usize>: Send + Sync {
    /// Number of nodes in every particle's stencil (entries may have zero weight).
    fn stencil_len(&self) -> usize;
    /// Nodes per axis of the box that holds every stencil: the nodes with nonzero value or
    /// gradient at `x` have integer indices in `origin_a ..= origin_a + width − 1`, with `origin`
    /// from [`ShapeFunction::stencil_origin`]. The coloured particle-to-grid map relies on it.
    fn stencil_width(&self) -> usize;
    /// Lowest integer node index per axis of the stencil box of a point at `xi` (cell units).
    fn stencil_origin(&self, xi: &Vector<D>) -> [i64; D];
    /// Ghost node layers needed around the domain so that the stencil of any point inside the
    /// domain lies on the grid.
    fn ghost_layers(&self) -> usize;
    /// `D_p = Σ_I Ψ_I (x_I − x_p)(x_I − x_p)ᵀ` when it is the same multiple of the identity for every
    /// `x_p` (B-splines of order ≥ 2); `None` otherwise (APIC then uses `Σ_I v_I ⊗ ∇Ψ_I`).
    fn apic_inertia(&self, cell_size: f64) -> Option<f64>;
    /// Polynomial degree the shape function reproduces.
    fn reproduction_order(&self) -> u32;
    /// The B-spline whose 1D factors give this shape function on the lattice, when there is
    /// one: the step then takes the factored, vectorised stencils (without VC).
    fn tensor_order(&self) -> Option<BSplineOrder> {
        None
    }
    /// Whether `Ψ_I` takes negative values somewhere (RK of order ≥ 2). The lumped mass
    /// `Σ_p m_p Ψ_I(x_p)` of a node that barely overlaps a body can then be negative or tiny, and
    /// the step blends in [`ShapeFunction::lumping_weights`] there (METHOD.md section 1, and
    /// `docs/convergence/FINDINGS.md`).
    fn is_signed(&self) -> bool {
        false
    }
    /// Nonnegative partition-of-unity weights on the stencil of `evaluate` (same node order), used
    /// for the lumped mass, momentum and body force of nodes at the edge of a body when the shape
    /// function is signed. Only called when [`ShapeFunction::is_signed`] is true.
    fn lumping_weights(&self, _grid: &Grid<D>, _x: &Vector<D>, _weights: &mut [f64]) {
        unreachable!("only signed shape functions have lumping weights")
    }
    /// Fills `nodes`, `values` and `gradients` (each `stencil_len()` long) for a point `x` inside
    /// the domain of `grid`.
    fn evaluate(
        &self,
        grid: &Grid<D>,
        x: &Vector<D>,
        nodes: &mut [usize],
        values: &mut [f64],
        gradients: &mut [Vector<D>],
    );
}

#[cfg(test)]
pub(crate) mod tests;

/// A small deterministic generator of uniform numbers in [0, 1) (xorshift64*), for jittered
/// particle sets in verification scenes and tests.
#[derive(Debug, Clone)]
pub struct UniformRng(u64);

impl UniformRng {
    pub fn new(seed: u64) -> Self {
        UniformRng(seed.wrapping_mul(0x9E3779B97F4A7C15) | 1)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545F4914F6CDD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
}
