//! Variationally consistent (VC) integration (Chen, Hillman & Rüter 2013; METHOD.md section 3),
//! in a form that conserves linear momentum.
//!
//! Particles are the quadrature points. The test-function gradients are corrected so that the
//! discrete divergence equality of order `n` holds at every node `I`: for every monomial `Q` of
//! degree ≤ n − 1 (written in `(x − x_I)/h`),
//!
//! ```text
//! Σ_p ∇̂Ψ_I Q V_p + Σ_p Ψ_I ∇Q V_p = Σ_b Ψ_I Q n_b a_b
//! ```
//!
//! **Conservation.** The seed's per-node correction `∇̂Ψ_I = ∇Ψ_I + ξ_I` meets each node's
//! equality on its own, but `Σ_I ∇̂Ψ_Ip = Σ_I ξ_I ≠ 0`: the internal forces no longer cancel
//! and a free body pushes itself (0.1–1 % of `M v` in 1000 steps). Here the correction is
//!
//! ```text
//! ∇̂Ψ_I(x_p) = ∇Ψ_I(x_p) + w_Ip (ζ_I·Q_I(x_p) − μ_p),   μ_p = Σ_J w_Jp ζ_J·Q_J(x_p) / Σ_J w_Jp
//! ```
//!
//! with `w_Ip = |Ψ_I(x_p)|`, so `Σ_I w_Ip (ζ_I·Q_I − μ_p) = 0` at every particle whatever `ζ` is:
//! the corrected gradients sum to zero (linear momentum is conserved to round-off), and a node
//! at a body's edge, with a small mass, gets a correction as small as its weights (no force
//! floor is needed). At order 1, when switched on (`Sim::set_vc_linear_fit`, experimental and
//! off by default, docs/METHOD.md) and for the shapes
//! with at least three nodes per axis in every support (`Shape::vc_linear_fit`: the cubic
//! B-spline, RK of support ≥ 2), the particle subtracts its weighted linear fit instead of the
//! mean, `w_Ip (ζ_I − μ_p − C_p u_Ip)` with
//! `u_Ip` the node offsets in the particle's frame ([`linear_frame`]), so that the correction's
//! first moment `Σ_I (x_I − x_p) ⊗ (∇̂Ψ_I − ∇Ψ_I)` vanishes too and a symmetric stress exerts no
//! torque; linear hats and the quadratic B-spline take the mean (two nodes per axis in
//! places: the fit would leave free values per particle). Whatever the fit, the step removes
//! the internal forces' torque per body (`crate::step` `vc_torque`), so that angular momentum
//! is conserved with APIC.
//! The equalities then couple the nodes through the fits:
//! `K ζ = rhs`, `(K ζ)_I = A_I ζ_I − Σ_p V_p w_Ip Q_I(x_p) μ_p` (the fitted value at order 1),
//! `A_I = Σ_p V_p w_Ip Q Qᵀ`, a symmetric positive semi-definite system (a weighted residual:
//! `⟨ζ, Kζ⟩ = Σ_p V_p Σ_I w_Ip (ζ_I·Q_I − fit_p)²`), solved by conjugate gradients
//! preconditioned with the node blocks `A_I`, whose first iterate is the per-node correction;
//! the iterations grow with the grid's width. `K` is assembled on the nodes once per step, and
//! on wide grids (order 1: at least 20 nodes wide; order ≥ 2: whenever the hierarchy has a
//! level below the nodes) preconditioned by an aggregation multigrid cycle instead
//! (`node_operator`; a V-cycle at order 1, a W-cycle at order ≥ 2): about a dozen iterations
//! whatever the grid with the mean fit, 40–110 with the linear fit (80 to 160 cells), 5–16 at
//! order 2 with the default stopping rule (more with the exact one), where round-off lets
//! the residual reach the tolerance only just, and a best residual within
//! `VC_SOLVE_ATTAINABLE` of it that stops improving is accepted. `K`'s null space is the
//! corrections that change no gradient (over a whole body, a polynomial of degree < n; at
//! order 1 the constants with the mean fit, the linear fields with the linear fit); the
//! right-hand side's part along it is what no force-free correction can meet, `Σ_b n_b a_b` per
//! body at order 1, zero for a closed surface. It is projected out per connected body before
//! the solve (`Σ_b P n_b a_b − Σ_p V_p ∇P` for every null polynomial P: the surface
//! and the particles disagreeing on P's divergence theorem; with the linear fit obliquely, in
//! the reach-weighted inner product). At order 1 the conjugate gradients are projected too
//! (every preconditioned residual, every product `K d` and the solution lose their part along
//! the null space, [`NullSpace`]): without it round-off carried the iterates along the linear
//! fields to `10^10` at nodes the particles barely reach, and a block dropped onto a slip floor
//! lost its mirror symmetry (3.6e-3, `tests/vc_conservation.rs`). With the linear fit a node
//! whose reach `A_I` is below `WEAK_REACH` of the largest joins no body: where two bodies'
//! supports first meet, such nodes made one body of two, each body's own linear fields became
//! near-null directions of `K` with the right-hand side's part along them left in, and the
//! solve amplified it (two approaching disks inverted a particle as their supports met). Alone
//! in its body, such a node's equality is not imposed. A node whose `A_I` is
//! singular (too few particles in its support for the order) is preconditioned with its
//! constant part only, and so corrected to order 1 ([`VcCorrection::reduced_to_first_order`]).
//! A node that the particles barely reach while a surface point is near it has an equality the
//! particles can meet only with a large correction on a node of almost no mass; the grid
//! update's edge-mass floor limits its acceleration and hands the force it holds back to the
//! receiving nodes as a rigid-body acceleration (a translation and a rotation), so that linear
//! and angular momentum are still conserved (`crate::step::grid_update`).
//!
//! At order 1 such a node's coefficients are also bounded (`VC_MAX_CORRECTION`): since any `ζ`
//! keeps the gradients summing to zero, the bound costs that node's equality and nothing of
//! conservation.
//!
//! The corrected gradient is used in the internal force only (METHOD.md section 7).
//!
//! **The test function.** Signed shape functions (RK of order ≥ 2) transfer mass, momentum and
//! the body force with the weights `Φ` of `crate::step` `edge_lumping`, which differ from `Ψ`
//! at a body's edge. The equalities' two test-function terms, `Σ_p Ψ_I ∇Q V_p` and
//! `Σ_b Ψ_I Q n_b a_b` above, then take `Φ` (at the boundary points from the nodes' blend of
//! this step), so that the internal force and the body force are weighed by one test function
//! and a stress in equilibrium with the body force is in equilibrium at every node (METHOD.md
//! section 3). The correction itself stays of `∇Ψ`, weighted by `|Ψ|`.

pub mod boundary_points;
mod carried;
mod lattice_rows;
mod node_operator;

pub use boundary_points::BoundaryPoints;

use crate::error::{Error, Result};
use crate::grid::{Bins, Grid, GridNodes, NodeScatter, SharedSlice};
use crate::options::ShapeKind;
use crate::shape::{Monomials, Stencils, SupportNodes, TensorFactors};
use crate::{Matrix, Vector};
pub(crate) use carried::CarriedCoefficients;
use nalgebra::{DMatrix, DVectorViewMut};
use node_operator::{Multilevel, NodeOperator, OperatorStorage};
use rayon::prelude::*;

/// A node's order-`n` correction needs its particle moment matrix `A_I = Σ V_p Q Qᵀ` to be well
/// conditioned; below this smallest-to-largest eigenvalue ratio (a node whose support holds only
/// a thin sliver of the body) the node gets the order-1 (constant) correction only.
pub const VC_MIN_RELATIVE_EIGENVALUE: f64 = 1e-4;

/// The conservative correction's solve stops, by default at order 1, when the preconditioned
/// residual norm has fallen by this factor (see `VcSolve`): the convergence study's errors stay
/// within 0.2 % of the exact solve's (docs/convergence/FINDINGS.md, "The VC solve's stopping
/// rule"), and the VC granular collapse runs at every Courant number measured (0.25–0.5).
pub const VC_SOLVE_TOLERANCE: f64 = 1e-4;

/// The exact solve's tolerance (`VcSolve::EXACT`): the divergence equalities met to round-off.
pub const VC_SOLVE_EXACT_TOLERANCE: f64 = 1e-12;

/// At most this many conjugate-gradient iterations per step, by default (see `VcSolve`).
pub const VC_SOLVE_MAX_ITERATIONS: usize = 2000;

/// At order ≥ 2 the default solve stops at this tolerance on grids of at most
/// `VC_SOLVE_REFERENCE_CELLS` cells across, and at `1e-4 (32 / N)^3` on a grid of `N` cells
/// across its widest axis ([`VcSolve::automatic`]): the quadrature error that VC removes falls
/// as `h^3` at order 2, and so must the residual the solve leaves. Measured: within 1 % of the
/// exact solve's errors to 64 cells (docs/convergence/FINDINGS.md).
pub const VC_SOLVE_HIGHER_ORDER_TOLERANCE: f64 = 1e-4;

/// The grid width (cells across) up to which `VC_SOLVE_HIGHER_ORDER_TOLERANCE` (1e-4) holds as
/// it is.
pub const VC_SOLVE_REFERENCE_CELLS: usize = 32;

/// The rule of VC's conservative solve: conjugate gradients stop when the preconditioned
/// residual norm has fallen to `tolerance` of the right-hand side's, or after
/// `max_iterations`; the solve runs every `interval` steps, and the steps between take the
/// coefficients of the last solve, carried by grid node, after sweeps of the node blocks on
/// their own system (two with B-splines, one with RK: `carried_sweeps_for`). At order 1 the
/// next solve starts from them and runs to the tolerance too: a solve stopped short of it (at
/// a tenth of the carried coefficients' residual) let a fast collapse go chaotic and throw
/// particles out of the grid.
/// Conservation does not depend on it: the corrected gradients sum to zero over a particle's
/// nodes whatever the coefficients are; the divergence equalities are met to the tolerance on
/// the steps that solve. A simulation takes [`VcSolve::automatic`] unless given a rule: 1e-4
/// at order 1, every eighth step with RK shape functions and every second with B-splines to
/// 256 cells across, halved with every doubling of the grid beyond (the study's errors
/// within 1 % of a solve at every step, [`VcSolve::interval_for`]), and at order ≥ 2 a tolerance of
/// 1e-4 that falls as `h^3` on grids finer than 32 cells across, at every step (a quarter to a
/// half of the exact solve's iterations, errors within 1 %). [`VcSolve::EXACT`] names the exact solve
/// at every step for tests that check the equalities or mirror symmetry to round-off.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VcSolve {
    pub tolerance: f64,
    pub max_iterations: usize,
    /// Steps from one solve to the next (1: every step). Order 1 only, without contact: VC of
    /// order ≥ 2 and the bodies' corrections under contact solve at every step.
    pub interval: u32,
}

impl Default for VcSolve {
    fn default() -> Self {
        VcSolve::DEFAULT
    }
}

impl VcSolve {
    /// The default rule at order 1: 1e-4 of the right-hand side's residual
    /// (`VC_SOLVE_TOLERANCE`), at most 2000 iterations, at every step (the automatic rule
    /// solves every [`VcSolve::BSPLINE_INTERVAL`] steps with B-splines, every
    /// [`VcSolve::RK_INTERVAL`] with RK shape functions).
    pub const DEFAULT: VcSolve = VcSolve {
        tolerance: VC_SOLVE_TOLERANCE,
        max_iterations: VC_SOLVE_MAX_ITERATIONS,
        interval: 1,
    };

    /// With RK shape functions at order 1 the automatic rule solves every this many steps on
    /// grids up to [`VcSolve::RK_CARRIED_CELLS`] cells across ([`VcSolve::interval_for`], which
    /// gives the errors measured); the steps between take the last solve's coefficients,
    /// carried by node and extrapolated along the line through the last two solves, and one
    /// sweep on their own system (`VC_RK_CARRIED_SWEEPS`). Linear and angular momentum are
    /// conserved whatever the coefficients.
    pub const RK_INTERVAL: u32 = 8;

    /// The widest grid (cells across) on which RK's automatic interval is
    /// [`VcSolve::RK_INTERVAL`].
    pub const RK_CARRIED_CELLS: usize = 256;

    /// As [`VcSolve::RK_INTERVAL`], with the quadratic and cubic B-splines (every 4th step
    /// moved the errors on quarter points with slip walls by 1.4–2.1 % at 128 cells, with the
    /// sweeps between).
    pub const BSPLINE_INTERVAL: u32 = 2;

    /// The widest grid (cells across) on which the B-splines' automatic interval is
    /// [`VcSolve::BSPLINE_INTERVAL`].
    pub const BSPLINE_CARRIED_CELLS: usize = 256;

    /// The exact solve: 1e-12 of the right-hand side's residual (`VC_SOLVE_EXACT_TOLERANCE`),
    /// at most 2000 iterations, at every step.
    pub const EXACT: VcSolve = VcSolve {
        tolerance: VC_SOLVE_EXACT_TOLERANCE,
        max_iterations: VC_SOLVE_MAX_ITERATIONS,
        interval: 1,
    };

    /// The rule a simulation takes unless given one, for VC of `order` on a grid of
    /// `cells_across` cells along its widest axis with shape functions of kind `shape`:
    /// [`VcSolve::DEFAULT`] (1e-4) at order 1, every [`VcSolve::BSPLINE_INTERVAL`] steps with
    /// B-splines and [`VcSolve::RK_INTERVAL`] with RK shape functions (linear hats every
    /// step); at order ≥ 2 `VC_SOLVE_HIGHER_ORDER_TOLERANCE` (1e-4), times
    /// `(32 / cells_across)^3` on grids wider than 32 cells (`VC_SOLVE_REFERENCE_CELLS`), never
    /// below the exact solve's tolerance, at every step.
    pub fn automatic(order: u32, cells_across: usize, shape: ShapeKind) -> VcSolve {
        if order < 2 {
            return VcSolve {
                interval: VcSolve::interval_for(shape, cells_across),
                ..VcSolve::DEFAULT
            };
        }
        let refined = (VC_SOLVE_REFERENCE_CELLS as f64 / cells_across.max(1) as f64).min(1.0);
        VcSolve {
            tolerance: (VC_SOLVE_HIGHER_ORDER_TOLERANCE * refined.powi(3))
                .max(VC_SOLVE_EXACT_TOLERANCE),
            max_iterations: VC_SOLVE_MAX_ITERATIONS,
            interval: 1,
        }
    }

    /// The automatic rule's interval at order 1 on a grid of `cells_across` cells along its
    /// widest axis: with RK shape functions [`VcSolve::RK_INTERVAL`] up to
    /// [`VcSolve::RK_CARRIED_CELLS`], with B-splines [`VcSolve::BSPLINE_INTERVAL`] up to
    /// [`VcSolve::BSPLINE_CARRIED_CELLS`], halved with every doubling of the grid beyond (at
    /// least 1); with linear hats 1. What the carried coefficients move grows with the grid's
    /// width while the error they move falls, so no fixed interval holds the errors within
    /// 1 % of a solve at every step on every grid. Without sweeps between solves a fixed
    /// interval `k` moved the manufactured solution's error by about `k^2 N^2.4` on `N` cells
    /// (RK1 + VC1 on jittered particles every 8th step 2.4–3.6 % at 128 cells, every 4th 3.0 %
    /// at 256); with the sweeps of `carried_sweeps_for` on grids wider than `VC_SWEPT_CELLS`
    /// RK1 + VC1 every 8th step is within 0.7 % at 128 and 256 cells, B-spline 2 + VC1 every
    /// 2nd on quarter points with slip walls within 0.3 % at 128 cells and 0.9 % at 256; to 64
    /// cells, without sweeps, within 0.4 % and 0.6 % (docs/convergence/FINDINGS.md, "Sweeps
    /// between solves").
    pub fn interval_for(shape: ShapeKind, cells_across: usize) -> u32 {
        let (mut interval, mut widest) = match shape {
            ShapeKind::Rk => (VcSolve::RK_INTERVAL, VcSolve::RK_CARRIED_CELLS),
            ShapeKind::Bspline2 | ShapeKind::Bspline3 => {
                (VcSolve::BSPLINE_INTERVAL, VcSolve::BSPLINE_CARRIED_CELLS)
            }
            ShapeKind::Linear => return 1,
        };
        while cells_across > widest && interval > 1 {
            interval /= 2;
            widest *= 2;
        }
        interval
    }

    /// Refuses a tolerance outside `(0, 1]` (or not finite), zero iterations and an interval of
    /// zero steps.
    pub fn check(&self) -> Result<()> {
        if !(self.tolerance > 0.0 && self.tolerance <= 1.0) {
            return Err(Error::invalid(format!(
                "the VC solve's tolerance must lie in (0, 1], got {}",
                self.tolerance
            )));
        }
        if self.max_iterations == 0 {
            return Err(Error::invalid(
                "the VC solve needs at least one iteration".to_string(),
            ));
        }
        if self.interval == 0 {
            return Err(Error::invalid(
                "the VC solve's interval must be at least one step".to_string(),
            ));
        }
        Ok(())
    }
}

/// On a step between solves (`VcSolve::interval`) on a grid wider than [`VC_SWEPT_CELLS`]
/// cells across, the carried coefficients take this many sweeps of the node blocks on the
/// step's own system with B-splines, `ζ ← ζ + A⁻¹ (rhs − K ζ)` with `K` applied matrix-free (a
/// gather and a scatter over the particles' stencils): the particles have moved since the
/// solve, and a sweep takes up the local part of what that moved, which the line through the
/// last two solves does not. Measured on the manufactured solution
/// (docs/convergence/FINDINGS.md, "Sweeps between solves"): with B-splines every 2nd step one
/// sweep moved the error by 2.8 % at 256 cells, two by 0.9 %.
pub(crate) const VC_CARRIED_SWEEPS: usize = 2;

/// As [`VC_CARRIED_SWEEPS`], with RK shape functions: one sweep holds their interval (every
/// 8th step within 0.7 % at 256 cells, 0.3 % at 128), and on their stored stencils a sweep
/// costs three times what it does on the B-splines' factors.
pub(crate) const VC_RK_CARRIED_SWEEPS: usize = 1;

/// The sweeps a step between solves takes with shape functions of kind `shape`, on grids wider
/// than [`VC_SWEPT_CELLS`].
pub(crate) fn carried_sweeps_for(shape: ShapeKind) -> usize {
    match shape {
        ShapeKind::Rk => VC_RK_CARRIED_SWEEPS,
        _ => VC_CARRIED_SWEEPS,
    }
}

/// The widest grid (cells across its widest axis) whose steps between solves take no sweeps:
/// there the carried coefficients hold without them (RK1 + VC1 every 8th step within 0.4 % and
/// B-spline 2 + VC1 every 2nd within 0.6 % of a solve at every step, to 64 cells), and a sweep
/// costs what it saves (3D `bspline2` + VC1 on 35 cells: 1.13 of the step with two).
pub(crate) const VC_SWEPT_CELLS: usize = 64;

/// The sweeps a step between solves takes on `grid`: `per_step` ([`carried_sweeps_for`]) on
/// grids wider than [`VC_SWEPT_CELLS`], none on others.
fn sweeps<const D: usize>(grid: &Grid<D>, per_step: usize) -> usize {
    match grid.cells_across() > VC_SWEPT_CELLS {
        true => per_step,
        false => 0,
    }
}

/// Calls `visit(p)` for the particles `counted`, bin by bin in the bins' colour order: the
/// blocks of one colour in parallel (their stencils write disjoint nodes, [`Bins`]), each
/// block's particles in order, so that every node's sums take the particles in one order.
fn by_colour<const D: usize>(
    bins: &Bins<D>,
    counted: impl Fn(usize) -> bool + Sync,
    visit: impl Fn(usize) + Sync,
) {
    for colour in &bins.colours {
        colour.par_iter().for_each(|&b| {
            for &p in &bins.order[bins.occupied[b as usize].1.clone()] {
                if counted(p as usize) {
                    visit(p as usize);
                }
            }
        });
    }
}

/// What [`mean_fit_product`] reads: the field's particles (those `counted`), their supports
/// and volumes, and the nodes' slots and moments `A_I`.
struct MeanFitInputs<'a, const D: usize, C> {
    support: SupportNodes<'a, D>,
    bins: &'a Bins<D>,
    nodes: &'a GridNodes<D>,
    volumes: &'a [f64],
    moment: &'a [f64],
    counted: &'a C,
}

/// `K ζ` at order 1 with the mean fit (`ζ` and `out` by slot, `D` values each):
/// `(K ζ)_I = A_I ζ_I − Σ_p V_p |Ψ_Ip| μ_p`, `μ_p = Σ_J |Ψ_Jp| ζ_J / Σ_J |Ψ_Jp|`, each particle's
/// mean taken in the pass that scatters it. `by_node` (twice the grid's node count) holds `ζ`
/// and the product by grid node, so that a stencil's node is read and written where it lies,
/// with no slot looked up and no gradient formed: on the 2D benchmark block a sweep between
/// solves in 3.1 ms where the slots' pass took 6.3 (B-spline 2, one thread). Each node's sum
/// in the particles' order: the bits of the slots' pass, with any number of threads.
fn mean_fit_product<const D: usize, C: Fn(usize) -> bool + Sync>(
    inputs: &MeanFitInputs<'_, D, C>,
    zeta: &[f64],
    out: &mut [f64],
    by_node: &SharedSlice<'_, Vector<D>>,
) {
    let MeanFitInputs {
        support,
        bins,
        nodes,
        volumes,
        moment,
        counted,
    } = inputs;
    let count = nodes.mass.len();
    let active = &nodes.active;
    // SAFETY: the two halves are disjoint, and this product is the room's only user.
    let (zeta_at, out_at) = unsafe { (by_node.range(0, count), by_node.range(count, count)) };
    let (zeta_at, out_at) = (SharedSlice::new(zeta_at), SharedSlice::new(out_at));
    active
        .par_iter()
        .zip(zeta.par_chunks_exact(D))
        .zip(moment.par_iter())
        .for_each(|((&n, z), &a)| {
            let z = Vector::<D>::from_fn(|k, _| z[k]);
            // SAFETY: every active node is listed once.
            unsafe {
                zeta_at.range(n, 1)[0] = z;
                out_at.range(n, 1)[0] = a * z;
            }
        });
    by_colour(bins, counted, |p| {
        let (mut mu, mut weight) = (Vector::<D>::zeros(), 0.0);
        support.for_each_value(p, |n, w| {
            let w = w.abs();
            weight += w;
            // SAFETY: `ζ` by node is only read in this pass.
            mu += w * unsafe { zeta_at.range(n, 1)[0] };
        });
        if weight > 0.0 {
            mu /= weight;
        }
        let v = volumes[p];
        support.for_each_value(p, |n, w| {
            let v = v * w.abs();
            // SAFETY: blocks of one colour write disjoint nodes (`Bins`).
            let o = unsafe { &mut out_at.range(n, 1)[0] };
            for k in 0..D {
                o[k] -= v * mu[k];
            }
        });
    });
    out.par_chunks_exact_mut(D)
        .zip(active.par_iter())
        .for_each(|(o, &n)| {
            // SAFETY: read only, after the writes above.
            let on = unsafe { out_at.range(n, 1)[0] };
            o.copy_from_slice(on.as_slice());
        });
}

/// At most this many restarts of the solve from its best iterate after a breakdown.
pub(crate) const VC_SOLVE_MAX_RESTARTS: usize = 5;

/// At order ≥ 2 the residual that round-off lets the solve reach lies at the tolerance itself:
/// RK2 + VC2 on the manufactured solution's box (quarter points, 16 and 32 cells) reaches
/// 1.0–1.8e-12 of the right-hand side in about 20 and 40 iterations, then wanders there (up to
/// 1e-5) until it breaks down or happens below 1e-12: 25 and 93 iterations per step on average
/// (619 and 1985 in the first step) where 19 and 46 give the same errors to four digits. So a
/// best residual within this factor of the tolerance is accepted when the iterations stop
/// improving it (`VC_SOLVE_STAGNATION` in a row, or a breakdown).
pub(crate) const VC_SOLVE_ATTAINABLE: f64 = 10.0;

/// See [`VC_SOLVE_ATTAINABLE`].
pub(crate) const VC_SOLVE_STAGNATION: usize = 10;

/// The largest correction any node takes at order 1, in units of `1/h` (the norm of its
/// coefficients `ζ_I`, written in `(x − x_I)/h`). A node that the particles barely reach while
/// a surface point sees it has an equality the particles can meet only with a large coefficient
/// on almost no mass. Under a uniform stress that is exact and balanced: the patch test's
/// jittered box (`patch_test_uniform_stress_stays_uniform_with_vc`) needs up to `428 / h` at its
/// edge nodes. On the granular column (B-spline 2 + VC1, 16 cells) such nodes reached
/// `10^3`–`3·10^11 / h`, their forces were not balanced, and a particle next to one inverted.
/// The ceiling sits between; below it, a node's bound falls with its reach
/// ([`first_order_correction_bound`]). It applies at order 1 only: at order 2 the same box's
/// edge nodes need up to `6.7·10^3 / h` (`second_order_divergence_equality`), and no flow is
/// known yet that fails at order 2.
pub(crate) const VC_MAX_CORRECTION: f64 = 1e3;

/// The largest correction, in units of `1/h`, of an order-1 node whose reach `A_I` is at least
/// [`VC_EDGE_REACH`] of the largest: what the explicit step stays stable with. The corrected
/// gradient stiffens its node: by Gershgorin's bound, the correction part of node `I`'s
/// stiffness over its mass is about `c² g |ζ_I|` (`c` the wave speed, `g = Σ_J |∇Ψ_J| ≈ 1.5 / h`
/// for the quadratic B-spline), so `ω Δt ≤ 2` at the Courant number `C = c Δt / h` needs
/// `|ζ_I| h ≤ 4 / (C² g h)`: 30 at `C` = 0.3, 11 at 0.5. A node of smaller reach has a mass
/// below the grid update's edge-mass floor (1 % of the largest), which divides its force by
/// more than its mass, so its bound grows as `1 / A_I` up to [`VC_MAX_CORRECTION`]. Measured on
/// the granular column (B-spline 2 + VC1, 16 cells): with the ceiling alone, the velocities at
/// the resting toe grew by about 10 % a step from 0.05 to 26 m/s and a particle inverted
/// (Courant 0.35 and 0.4 with the exact solve, 0.25 with 1e-4); with a flat bound of `10 / h`,
/// and with this one, all of them end (docs/convergence/FINDINGS.md). No error of
/// the manufactured solution moves (every digit printed, RK1 + VC1 and B-spline 2 + VC1, 2D and
/// 3D, jittered, found surface).
pub(crate) const VC_STABLE_CORRECTION: f64 = 10.0;

/// The bound on the norm of an order-1 node's coefficients, times `h`, for a node of reach
/// `reach` (`A_I = Σ_p V_p |Ψ_I(x_p)|`) when the largest reach is `largest`:
/// [`VC_STABLE_CORRECTION`], times `VC_EDGE_REACH · largest / reach` when that exceeds one,
/// never above [`VC_MAX_CORRECTION`].
pub(crate) fn first_order_correction_bound(reach: f64, largest: f64) -> f64 {
    let edge = VC_EDGE_REACH * largest / reach;
    (VC_STABLE_CORRECTION * edge.max(1.0)).min(VC_MAX_CORRECTION)
}

/// At order ≥ 2 the solve is of `(K + ε E A) ζ = rhs`: `A` the node blocks `A_I` (of a node
/// corrected to order 1, its constant part), `E` the nodes at a body's edge (reach `A_I`'s
/// constant entry below [`VC_EDGE_REACH`] of the largest, or corrected to order 1), and this `ε`:
/// a Tikhonov damping of the directions along which `K` is nearly singular, which live on those
/// nodes. There conjugate gradients carried the free jittered block's coefficients to
/// `2.6·10^14`–`4.8·10^16 / h` at a few steps (`1.2·10^5 / h` otherwise) and the round-off of
/// the sum `Σ_I w_Ip (ζ_I·Q_I − μ_p)` reached a quarter of a particle's correction: linear
/// momentum leaked (2D cubic B-spline + VC2, angular drift 5.8e-5 over 1000 steps) and a block
/// dropped on a slip floor lost its mirror symmetry (6.0e-3). Damped: 1.7e-13 and 1.4e-10;
/// the manufactured solution's errors unchanged to three digits (RK2 + VC2, 16 and 32 cells,
/// quarter points and jittered) and the solve about twice as fast. Measured and not kept:
/// damping every node (`K + ε A`) leaves the interior equalities met to `~40 ε` only (the
/// smooth fields' eigenvalues of `K` fall with the grid) and at `ε = 10^-8` still drifts 2e-12;
/// edge nodes at `ε = 10^-6` drift 4e-12; damping the part of `ζ` along the body's polynomials
/// (the null space where every node takes them) fixes no drift below `ε = 1`.
pub(crate) const VC_REGULARISATION: f64 = 1e-3;

/// See [`VC_REGULARISATION`]: a node whose reach `A_I` (constant entry) is below this fraction
/// of the largest is at a body's edge.
pub(crate) const VC_EDGE_REACH: f64 = 1e-2;

/// See [`VC_REGULARISATION`]: an edge node's damping `ε A_I` is scaled up so that its constant
/// entry is at least this fraction of `ε` times the largest reach. A node that the particles
/// have only just reached (a ghost row below a floor as a dropped block's lowest particles come
/// within its support) has a reach of round-off size, so `ε A_I` damped nothing there: its
/// coefficient came out at `2.6·10^11 / h` with round-off of `5·10^6 / h` that was not mirror
/// symmetric (docs/convergence/FINDINGS.md, "Mirror symmetry with RK2 + VC2"). With the floor
/// the slip and fixed drops of `tests/vc_conservation.rs` end 2.1e-14 and 1.8e-14 off symmetry
/// (1.2e-10 and 4.5e-10 without). The damping is held in the assembled operator (its diagonal
/// blocks, and `(1 + d_I) A_I` in the blocks that bound the smoother), so that the V-cycle sees
/// it: added on top of an undamped V-cycle it made the tests of that file run over four times
/// as long.
pub(crate) const VC_EDGE_DAMPING_FLOOR: f64 = 1e-4;

/// With the linear fit, nodes whose reach `A_I` is below this fraction of the largest join no
/// body of `K`'s null space.
const WEAK_REACH: f64 = 1e-2;

/// Test polynomials at most (order 4 in 3D: the monomials of degree ≤ 3).
const MAX_BASIS: usize = 20;

/// What VC's correction of one step reads.
#[derive(Clone, Copy)]
pub struct VcInputs<'a, const D: usize> {
    pub grid: &'a Grid<D>,
    /// The particles binned for this step (the colours of the parallel node sums).
    pub bins: &'a Bins<D>,
    /// The particles' positions and current volumes, and their stored stencils.
    pub positions: &'a [Vector<D>],
    pub volumes: &'a [f64],
    pub stencils: &'a Stencils<D>,
    /// The same stencils as their 1D factors, when they are a tensor product
    /// ([`crate::shape::StencilView::tensor_factors`]): the order-1 system is then assembled
    /// per axis.
    pub tensor: Option<TensorFactors<'a, D>>,
    /// The boundary points (under contact the body's own surface) and their stencils.
    pub boundary: &'a BoundaryPoints<D>,
    pub boundary_stencils: &'a Stencils<D>,
    /// Under contact `(materials, b)`: only the particles of material `b` count.
    pub body: Option<(&'a [u32], u32)>,
}

/// Every particle's support in the terms of the solve at order ≥ 2 applied matrix-free: per
/// stencil slot its node's slot, `w_Ip = |Ψ_I(x_p)|` and `Q_I(x_p)`, found once per solve. The
/// products read them instead of evaluating the polynomials at the node positions again (3D
/// RK2 + VC2, whose `K` is too large to assemble).
#[derive(Debug, Clone, Default)]
struct Supports {
    /// Stencil slots per particle and test polynomials per node.
    len: usize,
    m: usize,
    /// Per particle and stencil slot: the node's slot, `Supports::OFF` off the support.
    slot: Vec<u32>,
    weight: Vec<f64>,
    /// `m` values per particle and stencil slot.
    q: Vec<f64>,
}

impl Supports {
    const OFF: u32 = u32::MAX;

    /// `node(p, n, q)` writes `Q` of the node `n` in the support of particle `p` and returns
    /// its slot, or `None` for a particle the solve leaves out.
    fn fill<const D: usize>(
        &mut self,
        particles: usize,
        stencils: &Stencils<D>,
        m: usize,
        node: impl Fn(usize, usize, &mut [f64]) -> Option<usize> + Sync,
    ) {
        let len = stencils.len;
        (self.len, self.m) = (len, m);
        self.slot.resize(particles * len, Self::OFF);
        self.weight.resize(particles * len, 0.0);
        self.q.resize(particles * len * m, 0.0);
        self.slot
            .par_chunks_exact_mut(len)
            .zip(self.weight.par_chunks_exact_mut(len))
            .zip(self.q.par_chunks_exact_mut(len * m))
            .enumerate()
            .for_each(|(p, ((slot, weight), q))| {
                slot.fill(Self::OFF);
                stencils.for_each_shape(p, |k, s| {
                    if s.in_support() {
                        if let Some(found) = node(p, s.node, &mut q[k * m..(k + 1) * m]) {
                            slot[k] = found as u32;
                            weight[k] = s.value.abs();
                        }
                    }
                });
            });
    }

    /// Calls `f(slot, w_Ip, Q_I(x_p))` for every node in the support of particle `p`.
    #[inline(always)]
    fn for_each(&self, p: usize, mut f: impl FnMut(usize, f64, &[f64])) {
        let r = p * self.len..(p + 1) * self.len;
        for (k, (&slot, &w)) in self.slot[r.clone()].iter().zip(&self.weight[r]).enumerate() {
            if slot != Self::OFF {
                let q = &self.q[(p * self.len + k) * self.m..][..self.m];
                f(slot as usize, w, q);
            }
        }
    }

    /// The fit of `ζ` at particle `p`: `μ_p = Σ_I w_Ip ζ_I·Q_I(x_p) / Σ_I w_Ip` per direction
    /// (zero without weight).
    fn fit<const D: usize>(&self, p: usize, zeta: &[f64]) -> Vector<D> {
        // The block sizes of order 2 (2D, 3D) known to the compiler, which unrolls them; the
        // same sums in the same order.
        match self.m {
            3 => self.fit_of::<D, 3>(p, zeta),
            4 => self.fit_of::<D, 4>(p, zeta),
            _ => self.fit_of::<D, 0>(p, zeta),
        }
    }

    /// [`Supports::fit`] with `M` test polynomials (`0`: `self.m`).
    #[inline(always)]
    fn fit_of<const D: usize, const M: usize>(&self, p: usize, zeta: &[f64]) -> Vector<D> {
        let m = if M > 0 { M } else { self.m };
        let (mut mu, mut weight) = (Vector::<D>::zeros(), 0.0);
        self.for_each(p, |slot, w, q| {
            weight += w;
            let (z, q) = (&zeta[slot * m * D..][..m * D], &q[..m]);
            for k in 0..D {
                mu[k] += w * (0..m).map(|j| z[k * m + j] * q[j]).sum::<f64>();
            }
        });
        if weight > 0.0 {
            mu /= weight;
        }
        mu
    }

    /// `−V_p w_Ip Q_I(x_p) μ_p` added to the rows of `out` (`m D` values a slot) of the nodes
    /// in the support of particle `p` (`v` is `V_p`).
    ///
    /// # Safety
    /// No other thread writes those rows meanwhile.
    unsafe fn subtract_fit<const D: usize>(
        &self,
        p: usize,
        v: f64,
        mu: &Vector<D>,
        out: &SharedSlice<f64>,
    ) {
        // SAFETY: the caller's.
        unsafe {
            match self.m {
                3 => self.subtract_fit_of::<D, 3>(p, v, mu, out),
                4 => self.subtract_fit_of::<D, 4>(p, v, mu, out),
                _ => self.subtract_fit_of::<D, 0>(p, v, mu, out),
            }
        }
    }

    /// [`Supports::subtract_fit`] with `M` test polynomials (`0`: `self.m`).
    ///
    /// # Safety
    /// As [`Supports::subtract_fit`].
    #[inline(always)]
    unsafe fn subtract_fit_of<const D: usize, const M: usize>(
        &self,
        p: usize,
        v: f64,
        mu: &Vector<D>,
        out: &SharedSlice<f64>,
    ) {
        let m = if M > 0 { M } else { self.m };
        self.for_each(p, |slot, w, q| {
            let v = v * w;
            // SAFETY: the caller's.
            let o = unsafe { out.range(slot * m * D, m * D) };
            let q = &q[..m];
            for k in 0..D {
                for j in 0..m {
                    o[k * m + j] -= v * q[j] * mu[k];
                }
            }
        });
    }
}

/// The per-node gradient corrections of one step.
#[derive(Debug, Clone)]
pub struct VcCorrection<const D: usize> {
    pub order: u32,
    /// The test polynomials `Q`: monomials of degree ≤ order − 1.
    basis: Monomials<D>,
    /// Per active node (slot): the moment matrix `A_I`, `m × m`.
    moment: Vec<f64>,
    /// Per slot: right-hand sides, then the solutions `ξ`, `m` values per direction.
    xi: Vec<f64>,
    /// Slots with at least one particle in their support.
    used: Vec<bool>,
    /// Slots whose moment matrix was singular, corrected to order 1 only.
    reduced: Vec<bool>,
    /// At order ≥ 2, the slots at a body's edge, where the solve is damped
    /// (`VC_REGULARISATION`).
    edge: Vec<bool>,
    /// Per particle: the mean `μ_p` of the node corrections over its support, per direction,
    /// and at order 1 the slope `C_p` of their linear fit (zero at order ≥ 2).
    fit: Vec<(Vector<D>, Matrix<D>)>,
    /// Per particle with the order-1 linear fit: its frame `(T_p, o_p)`, see [`linear_frame`]
    /// (empty with the mean fit).
    frame: Vec<(Matrix<D>, Vector<D>)>,
    /// At order 1 with the mean fit on a tensor-product stencil (B-splines): the coefficients
    /// `ζ` by grid node (valid at the active nodes), which particle to grid reads with the
    /// stencil's factors, taking each particle's mean `μ_p` as it scatters
    /// ([`VcCorrection::mean_fit_coefficients`]); `fit` is then not kept. Empty otherwise.
    on_nodes: Vec<Vector<D>>,
    /// Room for [`mean_fit_product`]'s values by grid node.
    by_node: Vec<Vector<D>>,
    /// At order 1, per grid node: the particle sums `A_I` and `rhs_I` (`1 + D` values, zero
    /// between steps), taken in the pass that marks the nodes, before the nodes have slots.
    node_sums: Vec<f64>,
    /// The last step's storage of the assembled `K`, reused (its pages already mapped).
    storage: OperatorStorage,
    /// At order ≥ 2 applied matrix-free: the particles' supports in the solve's terms.
    supports: Supports,
    /// Per slot, the connected body of the nodes that the field's particles join (see
    /// [`bodies`]), when the solve took every such node (the mean fit; with the linear fit
    /// weakly reached nodes join no body): the bodies whose torque the step removes, so that
    /// they are not found twice. Empty otherwise.
    body_of: Vec<usize>,
    /// At order 1, whether the correction subtracts the particles' linear fit (else their
    /// mean): [`crate::options::Shape::vc_linear_fit`].
    pub linear_fit: bool,
    /// The solve's stopping rule.
    pub solve: VcSolve,
    /// Conjugate-gradient iterations of the last solve (zero on a step that took the carried
    /// coefficients).
    iterations: usize,
    /// The last committed solve's coefficients by node, which the steps up to the next solve
    /// take (`VcSolve::interval`); empty at an interval of one step, or per body.
    carried: CarriedCoefficients,
    /// This step's solve (its nodes and coefficients), carried when the step commits.
    proposed: Option<(Vec<usize>, Vec<f64>)>,
    /// Applies the order-1 system matrix-free, as orders ≥ 2 do (to test the assembled one).
    #[cfg(test)]
    matrix_free: bool,
    /// Preconditions the order-1 system with the V-cycle whatever the grid's size.
    #[cfg(test)]
    multilevel: bool,
    /// Solves `K ζ = rhs` at order ≥ 2 without the damping `VC_REGULARISATION`.
    #[cfg(test)]
    undamped: bool,
    /// Whether the last solve took its bodies from the operator's lattice neighbours.
    #[cfg(test)]
    lattice_bodies: bool,
    /// The sweeps a step between solves takes on a grid wider than `VC_SWEPT_CELLS`
    /// ([`carried_sweeps_for`] the simulation's shape functions).
    pub(crate) carried_sweeps: usize,
}

impl<const D: usize> VcCorrection<D> {
    /// Order 1 to 4.
    /// Whether the correction reads the stencils as stored lists: at order ≥ 2 (the basis at
    /// each node) and with the linear fit; at order 1 with the mean fit it reads a
    /// tensor-product stencil's factors ([`SupportNodes`]), and B-spline steps need not list
    /// them.
    pub fn reads_lists(&self) -> bool {
        self.order > 1 || self.linear_fit
    }

    pub fn new(order: u32) -> Result<Self> {
        if !(1..=4).contains(&order) {
            return Err(Error::invalid(format!(
                "vc_order must lie in 1..=4, got {order}"
            )));
        }
        Ok(VcCorrection {
            order,
            basis: Monomials::up_to(order - 1),
            moment: Vec::new(),
            xi: Vec::new(),
            used: Vec::new(),
            reduced: Vec::new(),
            edge: Vec::new(),
            fit: Vec::new(),
            frame: Vec::new(),
            on_nodes: Vec::new(),
            by_node: Vec::new(),
            node_sums: Vec::new(),
            storage: OperatorStorage::default(),
            supports: Supports::default(),
            body_of: Vec::new(),
            linear_fit: false,
            solve: VcSolve::default(),
            iterations: 0,
            carried: CarriedCoefficients::default(),
            proposed: None,
            #[cfg(test)]
            matrix_free: false,
            #[cfg(test)]
            multilevel: false,
            #[cfg(test)]
            undamped: false,
            #[cfg(test)]
            lattice_bodies: false,
            carried_sweeps: VC_CARRIED_SWEEPS,
        })
    }

    fn m(&self) -> usize {
        self.basis.len()
    }

    /// `Q(z)` and, when `dq` is given, `∂Q/∂z_k` for every k (`dq[k * m + j]`).
    #[inline]
    fn basis_at(&self, z: &Vector<D>, q: &mut [f64], dq: Option<&mut [f64]>) {
        let m = self.m();
        self.basis.values(z, &mut q[..m]);
        if let Some(dq) = dq {
            for k in 0..D {
                self.basis.derivatives(z, k, &mut dq[k * m..(k + 1) * m]);
            }
        }
    }

    /// Computes `ξ_I` for every node touched by a particle: the particle sums over their
    /// stencils, the boundary sums over the stencils of the boundary points. Marks the nodes
    /// active in `nodes`.
    ///
    /// The particle sums run in parallel by the colours of `bins` (the particles binned for
    /// this step), the per-node solves in parallel: the same bits with any number of threads.
    pub fn compute(&mut self, inputs: VcInputs<'_, D>, nodes: &mut GridNodes<D>) {
        let VcInputs {
            grid,
            bins,
            positions,
            volumes,
            stencils,
            boundary,
            boundary_stencils,
            body,
            tensor,
            ..
        } = inputs;
        let m = self.m();
        let h = grid.cell_size;
        let support = SupportNodes {
            stored: stencils,
            tensor,
        };
        self.body_of.clear();
        // A step between solves (`VcSolve::interval`) takes no right-hand side, unless its
        // carried coefficients take sweeps on its system (`carried_sweeps`).
        let between_solves =
            self.between_solves(body.is_some()) && sweeps(grid, self.carried_sweeps) == 0;
        let counted = |p: usize| body.is_none_or(|(materials, b)| materials[p] == b);
        let by_colour = |visit: &(dyn Fn(usize) + Sync)| by_colour(bins, counted, visit);
        // The nodes: those of particle stencils (listed block by block), then those that only
        // boundary points reach. At order 1 the particle sums go with the marks, by node
        // (`node_sums`): A_I += V |Ψ_I|, rhs_Ik −= V ∂_k Ψ_I (Q = 1 and ∇Q = 0: neither a
        // position nor the test function), only A_I on a step between solves without sweeps
        // (the reach that bounds the carried coefficients); each node's sums in the particles'
        // order, as by slot.
        let per = 1 + D;
        if m == 1 {
            self.node_sums.resize(nodes.mass.len() * per, 0.0);
        }
        // The step clears the grid before this pass: the nodes it lists first are the
        // particles' (`reached`, below).
        debug_assert!(nodes.active.is_empty());
        {
            let out = NodeScatter::new(nodes);
            let sums = SharedSlice::new(&mut self.node_sums);
            by_colour(&|p| {
                if m > 1 {
                    // SAFETY: blocks of one colour write disjoint nodes (`Bins`).
                    return support.for_each(p, |s| unsafe { out.touch(s.node) });
                }
                let v = volumes[p];
                support.for_each(p, |s| {
                    // SAFETY: blocks of one colour write disjoint nodes (`Bins`), and a node's
                    // sums are its own range.
                    unsafe {
                        out.touch(s.node);
                        let r = sums.range(s.node * per, per);
                        r[0] += v * s.value.abs();
                        if !between_solves {
                            for (r, g) in r[1..].iter_mut().zip(s.gradient.iter()) {
                                *r -= v * g;
                            }
                        }
                    }
                });
            });
        }
        bins.collect_active(grid, nodes);
        // The nodes of particle stencils, listed before those of boundary points alone.
        let reached = nodes.active.len();
        for b in 0..boundary.len() {
            let (ns, ws, _) = boundary_stencils.of(b);
            for (&n, &w) in ns.iter().zip(ws) {
                if w != 0.0 {
                    nodes.touch(n);
                }
            }
        }
        let slots = nodes.active.len();
        let rhs = if between_solves { 0 } else { m * D };
        for (v, per) in [(&mut self.moment, m * m), (&mut self.xi, rhs)] {
            v.clear();
            v.resize(slots * per, 0.0);
        }
        for v in [&mut self.used, &mut self.reduced] {
            v.clear();
            v.resize(slots, false);
        }
        if m == 1 {
            // The node sums to the slots, and zero again for the next step.
            let sums = SharedSlice::new(&mut self.node_sums);
            let xi = SharedSlice::new(&mut self.xi);
            let active = &nodes.active;
            (self.moment.par_iter_mut().zip(self.used.par_iter_mut()))
                .enumerate()
                .take(reached)
                .for_each(|(slot, (a, used))| {
                    // SAFETY: every active node is listed once, and has a slot of its own.
                    unsafe {
                        let sum = sums.range(active[slot] * per, per);
                        (*a, *used) = (sum[0], true);
                        if !between_solves {
                            xi.range(slot * D, D).copy_from_slice(&sum[1..]);
                        }
                        sum.fill(0.0);
                    }
                });
        }
        // Particle sums at order ≥ 2: A_I += V Q Qᵀ; rhs_Ik −= V (∂_k Ψ Q + Ψ ∂_k Q).
        if m > 1 {
            let moment = SharedSlice::new(&mut self.moment);
            let xi = SharedSlice::new(&mut self.xi);
            let used = SharedSlice::new(&mut self.used);
            let nodes = &*nodes;
            let basis = &self.basis;
            by_colour(&|p| {
                let (mut q, mut dq) = ([0.0; MAX_BASIS], [0.0; 3 * MAX_BASIS]);
                let v = volumes[p];
                let phi = stencils.transfer_of(p);
                stencils.for_each_shape(p, |k, s| {
                    if !s.in_support() {
                        return;
                    }
                    // The test function: the transfer weight `Φ` where it differs from `Ψ`.
                    let test = phi.map_or(s.value, |phi| phi[k]);
                    let slot = nodes.slot(s.node);
                    let x_node = grid.node_position(grid.node_multi_index(s.node));
                    let z = (positions[p] - x_node) / h;
                    basis.values(&z, &mut q[..m]);
                    for k in 0..D {
                        basis.derivatives(&z, k, &mut dq[k * m..(k + 1) * m]);
                    }
                    // SAFETY: the slot belongs to a node that only this block writes in this
                    // colour (`Bins`); slots of different nodes are disjoint ranges.
                    unsafe {
                        let a = moment.range(slot * m * m, m * m);
                        let vw = v * s.value.abs();
                        for i in 0..m {
                            for j in 0..m {
                                a[i * m + j] += vw * q[i] * q[j];
                            }
                        }
                        let r = xi.range(slot * m * D, m * D);
                        for k in 0..D {
                            for j in 0..m {
                                r[k * m + j] -=
                                    v * (s.gradient[k] * q[j] + test * dq[k * m + j] / h);
                            }
                        }
                        used.range(slot, 1)[0] = true;
                    }
                });
            });
        }
        // Boundary sums: rhs_Ik += Ψ_I Q (n a)_k, only at nodes whose support meets a point.
        let mut q = [0.0; MAX_BASIS];
        let mut blended = Vec::new();
        for b in (0..boundary.len()).filter(|_| !between_solves) {
            let (ns, ws, _) = boundary_stencils.of(b);
            let na = boundary.area_normal[b];
            // The test function at the point: the transfer weights `Φ` for signed shapes.
            let phi = match (boundary_stencils.lumping_of(b), nodes.lumping.as_ref()) {
                (Some(ls), Some(l)) => {
                    crate::step::edge_lumping::transfer_weights(ns, ws, ls, &l.blend, &mut blended);
                    &blended[..]
                }
                _ => ws,
            };
            for s in 0..ns.len() {
                if ws[s] == 0.0 {
                    continue;
                }
                let n = ns[s];
                let slot = nodes.slot(n);
                if m == 1 {
                    // Order 1: Q = 1 (no position needed).
                    q[0] = 1.0;
                } else {
                    let x_node = grid.node_position(grid.node_multi_index(n));
                    self.basis_at(&((boundary.position[b] - x_node) / h), &mut q, None);
                }
                let r = &mut self.xi[slot * m * D..(slot + 1) * m * D];
                for k in 0..D {
                    for j in 0..m {
                        r[k * m + j] += phi[s] * q[j] * na[k];
                    }
                }
            }
        }
        self.solve_conserving(inputs, nodes);
    }

    /// Solves for the node coefficients `ζ` of the momentum-conserving correction
    /// `g_Ip = ζ_I·Q_I(x_p) − μ_p`, `μ_p` the mean of `ζ_J·Q_J(x_p)` over the nodes `J` of the
    /// particle's support, so that `Σ_I g_Ip = 0` at every particle: the constraints
    /// `Σ_p V_p g_Ip Q_I(x_p) = rhs_I` form the symmetric positive semi-definite system
    /// `K ζ = rhs`, `(K ζ)_I = A_I ζ_I − Σ_p V_p Q_I(x_p) μ_p`, solved by conjugate gradients
    /// preconditioned with the node blocks `A_I` (the per-node correction is its first
    /// iterate). `K` is singular along the corrections that change no particle's gradient
    /// (a polynomial of degree < n over a whole body): the part of `rhs` along them is what no
    /// force-free correction can meet (a surface whose quadrature disagrees with the particles'
    /// divergence theorem), projected out first.
    fn solve_conserving(&mut self, inputs: VcInputs<'_, D>, nodes: &GridNodes<D>) {
        let VcInputs {
            grid,
            bins,
            positions,
            volumes,
            stencils,
            tensor,
            body,
            ..
        } = inputs;
        let m = self.m();
        let slots = nodes.active.len();
        let len = slots * m * D;
        let support = SupportNodes {
            stored: stencils,
            tensor,
        };
        // Solving every few steps (`VcSolve::interval`), the last solve's coefficients, carried
        // by node: the steps between take them and the next solve starts from them. At order 1
        // only (order-2 coefficients carried to moved particles: jittered RK2 + VC2 54 % off at
        // 16 cells, a free block unstable), and not per body under contact (those corrections
        // are not committed with the step). Solving at every step starts from zero, so that a
        // body under contact alone steps as it does without contact, to the last bit.
        let carry = self.solve.interval > 1 && body.is_none() && m == 1;
        if !carry {
            self.carried.clear();
        }
        self.proposed = None;
        let carried = !self.carried.is_empty();
        let reuse = self.between_solves(body.is_some());
        // The preconditioner: per node, A_I's Cholesky factor, or the constant part alone for
        // a node whose moment matrix is singular (marked reduced) or of order 1.
        let factors: Vec<Option<nalgebra::Cholesky<f64, nalgebra::Dyn>>> = self
            .moment
            .par_chunks_exact(m * m)
            .zip(self.used.par_iter())
            .zip(self.reduced.par_iter_mut())
            .map(|((a, &used), reduced)| {
                if !used || m == 1 {
                    return None;
                }
                let a = DMatrix::from_row_slice(m, m, a);
                let eig = a.clone().symmetric_eigenvalues();
                let chol = (eig.min() > VC_MIN_RELATIVE_EIGENVALUE * eig.max())
                    .then(|| a.cholesky())
                    .flatten();
                *reduced = chol.is_none();
                chol
            })
            .collect();
        // K assembled on the nodes once and, on a grid wide enough for it to pay,
        // preconditioned by a V-cycle (see `node_operator`).
        #[cfg(not(test))]
        let (assembled, force_cycle) = (!reuse, false);
        #[cfg(test)]
        let (assembled, force_cycle) = (!self.matrix_free && !reuse, self.multilevel);
        #[cfg(not(test))]
        let damping = VC_REGULARISATION;
        #[cfg(test)]
        let damping = if self.undamped {
            0.0
        } else {
            VC_REGULARISATION
        };
        let h = grid.cell_size;
        let basis = &self.basis;
        let q_of = |p: usize, n: usize, q: &mut [f64]| {
            if m == 1 {
                q[0] = 1.0;
            } else {
                let z = (positions[p] - grid.node_position(grid.node_multi_index(n))) / h;
                basis.values(&z, &mut q[..m]);
            }
        };
        let moment = &self.moment;
        let used = &self.used;
        let reduced = &self.reduced;
        let counted = |p: usize| body.is_none_or(|(materials, b)| materials[p] == b);
        // At order 1, every particle's frame of the linear fit (see [`linear_frame`]).
        let offset = |p: usize, n: usize| -> Vector<D> {
            (grid.node_position(grid.node_multi_index(n)) - positions[p]) / h
        };
        // With the mean fit there is no frame: its slope and offsets are zero.
        let linear_fit = m == 1 && self.linear_fit;
        let mut frame = std::mem::take(&mut self.frame);
        frame.clear();
        if linear_fit {
            frame.par_extend((0..positions.len()).into_par_iter().map(|p| {
                let (mut weight, mut first, mut second) = (0.0, Vector::zeros(), Matrix::zeros());
                if counted(p) {
                    support.for_each(p, |s| {
                        let (w, d) = (s.value.abs(), offset(p, s.node));
                        weight += w;
                        first += w * d;
                        second += w * d * d.transpose();
                    });
                }
                linear_frame(weight, first, second)
            }));
        }
        let frame_offset = |p: usize, n: usize| -> Vector<D> {
            let (t, o) = &frame[p];
            t * offset(p, n) - o
        };
        // The largest reach (the moment's constant entry), which the edge nodes, the weak
        // nodes and the order-1 bound are taken against.
        let reach = (0..slots)
            .filter(|&slot| used[slot])
            .map(|slot| moment[slot * m * m])
            .fold(0.0, f64::max);
        // The edge nodes and their damping `d_I` of `(K + ε E A) ζ` at order ≥ 2
        // (`VC_REGULARISATION`), with the floor `VC_EDGE_DAMPING_FLOOR`.
        let mut edge = std::mem::take(&mut self.edge);
        edge.clear();
        edge.extend((0..slots).map(|slot| {
            used[slot] && (reduced[slot] || moment[slot * m * m] < VC_EDGE_REACH * reach)
        }));
        let edge = edge;
        let edge_damping: Vec<f64> = (0..slots)
            .map(|slot| {
                let a = moment[slot * m * m];
                match m > 1 && damping > 0.0 && edge[slot] && a > 0.0 {
                    true => damping * (VC_EDGE_DAMPING_FLOOR * reach / a).max(1.0),
                    // A row without reach takes no part (nothing to damp).
                    false => 0.0,
                }
            })
            .collect();
        let multilevel = assembled
            .then(|| {
                NodeOperator::assemble(
                    grid,
                    bins,
                    stencils,
                    nodes,
                    volumes,
                    (moment, reduced, m),
                    q_of,
                    linear_fit.then_some(&frame_offset),
                    counted,
                    tensor,
                    std::mem::take(&mut self.storage),
                )
            })
            .flatten()
            .map(|mut fine| {
                fine.add_damping(&edge_damping, reduced);
                let cycle = force_cycle || Multilevel::<D>::pays(&fine);
                let reach = linear_fit.then_some(&moment[..]);
                Multilevel::new(fine, cycle, basis.exponents(), reduced, reach)
            });
        let operator = multilevel.as_ref().map(|m| m.fine());
        // Applied matrix-free at order ≥ 2: the supports found once, for every product.
        let mut supports = std::mem::take(&mut self.supports);
        let matrix_free = operator.is_none() && m > 1;
        if matrix_free {
            supports.fill(positions.len(), stencils, m, |p, n, q| {
                counted(p).then(|| {
                    q_of(p, n, q);
                    nodes.slot(n)
                })
            });
        }
        // The V-cycle, until a breakdown (below) turns to the node blocks.
        let with_multilevel =
            std::cell::Cell::new(multilevel.as_ref().is_some_and(|m| m.has_cycle()));
        let node_blocks = |r: &[f64], z: &mut [f64]| {
            z.par_chunks_exact_mut(m * D)
                .zip(r.par_chunks_exact(m * D))
                .enumerate()
                .for_each(|(slot, (z, r))| {
                    z.fill(0.0);
                    if !used[slot] {
                        return;
                    }
                    for k in 0..D {
                        match &factors[slot] {
                            // Solved in place (nalgebra's own solve, without its two vectors
                            // allocated per node and direction).
                            Some(c) => {
                                z[k * m..(k + 1) * m].copy_from_slice(&r[k * m..(k + 1) * m]);
                                let mut z =
                                    DVectorViewMut::from_slice(&mut z[k * m..(k + 1) * m], m);
                                c.solve_mut(&mut z);
                            }
                            None => z[k * m] = r[k * m] / moment[slot * m * m],
                        }
                    }
                    // The damped block `(1 + d_I) A_I` (its constant entry where reduced).
                    z.iter_mut().for_each(|z| *z /= 1.0 + edge_damping[slot]);
                });
        };
        // With the mean fit on the B-spline factors particle to grid takes the fits itself
        // (`mean_fit_coefficients`): the coefficients go to the nodes instead.
        let on_nodes = m == 1 && !linear_fit && tensor.is_some();
        let mut fit = std::mem::take(&mut self.fit);
        fit.clear();
        // Room for the fits where they are taken: kept, or in the products of a matrix-free
        // solve.
        if !on_nodes || (!reuse && operator.is_none()) {
            fit.resize(
                positions.len(),
                (Vector::<D>::zeros(), Matrix::<D>::zeros()),
            );
        }
        // The mean fit at order 1: the weighted mean of the coefficients (nodes of zero value
        // weigh nothing).
        let mean_fit = |p: usize, zeta: &[f64]| {
            let (mut mu, mut weight) = (Vector::<D>::zeros(), 0.0);
            support.for_each_value(p, |n, w| {
                let w = w.abs();
                weight += w;
                let z = &zeta[nodes.slot(n) * D..];
                mu += w * Vector::<D>::from_fn(|k, _| z[k]);
            });
            if weight > 0.0 {
                mu /= weight;
            }
            mu
        };
        // The fits of ζ at the particles: the weighted mean `μ_p` of `ζ_J·Q_J(x_p)` and, at
        // order 1, the slope `C_p = Σ_J w_Jp ζ_J ⊗ u_Jp` of the weighted linear fit.
        let fits = |zeta: &[f64], fit: &mut [(Vector<D>, Matrix<D>)]| {
            fit.par_iter_mut().enumerate().for_each(|(p, (mu, slope))| {
                *mu = Vector::<D>::zeros();
                *slope = Matrix::<D>::zeros();
                if !counted(p) {
                    return;
                }
                let mut q = [0.0; MAX_BASIS];
                let mut weight = 0.0;
                if matrix_free {
                    *mu = supports.fit(p, zeta);
                    return;
                }
                if m == 1 && !linear_fit {
                    *mu = mean_fit(p, zeta);
                    return;
                }
                support.for_each(p, |s| {
                    let w = s.value.abs();
                    weight += w;
                    let z = &zeta[nodes.slot(s.node) * m * D..];
                    if m == 1 {
                        let z = Vector::<D>::from_fn(|k, _| z[k]);
                        *mu += w * z;
                        if linear_fit {
                            *slope += w * z * frame_offset(p, s.node).transpose();
                        }
                        return;
                    }
                    q_of(p, s.node, &mut q);
                    for k in 0..D {
                        mu[k] += w * (0..m).map(|j| z[k * m + j] * q[j]).sum::<f64>();
                    }
                });
                if weight > 0.0 {
                    *mu /= weight;
                }
            });
        };
        // Order 1 with the mean fit, not assembled: `K ζ` by grid node (`mean_fit_product`).
        let by_node_product = m == 1 && !linear_fit && !matrix_free && operator.is_none();
        let mut by_node_room = std::mem::take(&mut self.by_node);
        if by_node_product {
            by_node_room.resize(2 * nodes.mass.len(), Vector::<D>::zeros());
        }
        let by_node = SharedSlice::new(&mut by_node_room[..]);
        let mean_fit_inputs = MeanFitInputs {
            support,
            bins,
            nodes,
            volumes,
            moment,
            counted: &counted,
        };
        // K ζ: assembled, or the fits of ζ at the particles, then the node sums.
        let product = |zeta: &[f64], out: &mut [f64], fit: &mut [(Vector<D>, Matrix<D>)]| {
            if let Some(operator) = &operator {
                operator.apply(zeta, out);
                return;
            }
            // The mean fit at order 1 is taken in the scatter's own pass, particle by particle
            // (the same sums as `fits` in the same order), instead of kept.
            if by_node_product {
                return mean_fit_product(&mean_fit_inputs, zeta, out, &by_node);
            }
            fits(zeta, fit);
            out.par_chunks_exact_mut(m * D)
                .zip(zeta.par_chunks_exact(m * D))
                .enumerate()
                .for_each(|(slot, (o, z))| {
                    let a = &moment[slot * m * m..(slot + 1) * m * m];
                    for k in 0..D {
                        for i in 0..m {
                            o[k * m + i] = (0..m).map(|j| a[i * m + j] * z[k * m + j]).sum::<f64>();
                        }
                    }
                });
            let shared = SharedSlice::new(out);
            let fit = &*fit;
            by_colour(bins, counted, |p| {
                let v = volumes[p];
                let (mu, slope) = (&fit[p].0, &fit[p].1);
                if matrix_free {
                    // SAFETY: blocks of one colour write disjoint nodes (`Bins`).
                    unsafe { supports.subtract_fit(p, v, mu, &shared) };
                    return;
                }
                // Order 1 (orders ≥ 2 without the assembled `K` take the supports).
                support.for_each(p, |s| {
                    let v = v * s.value.abs();
                    // SAFETY: blocks of one colour write disjoint nodes (`Bins`).
                    let o = unsafe { shared.range(nodes.slot(s.node) * D, D) };
                    let fitted = match linear_fit {
                        true => mu + slope * frame_offset(p, s.node),
                        false => *mu,
                    };
                    for k in 0..D {
                        o[k] -= v * fitted[k];
                    }
                });
            });
        };
        // A step between solves takes the carried coefficients, bounded and fitted at the
        // particles as a solve's are.
        if reuse {
            let mut zeta = self.carried.at(&nodes.active, m * D);
            self.iterations = 0;
            // Node-block sweeps on this step's system, matrix-free (`carried_sweeps`).
            let sweeps = sweeps(grid, self.carried_sweeps);
            if sweeps > 0 {
                // The fits' room is there where the product takes kept fits (not `on_nodes`).
                let rhs = std::mem::take(&mut self.xi);
                let (mut r, mut z) = (vec![0.0; len], vec![0.0; len]);
                for _ in 0..sweeps {
                    product(&zeta, &mut r, &mut fit);
                    r.par_iter_mut().zip(&rhs).for_each(|(r, b)| *r = b - *r);
                    node_blocks(&r, &mut z);
                    zeta.par_iter_mut().zip(&z).for_each(|(x, z)| *x += z);
                }
            }
            self.bound_first_order(&mut zeta, reach, h);
            match on_nodes {
                true => self.lay_on_nodes(&zeta, nodes, &mut fit),
                false => {
                    self.on_nodes.clear();
                    fits(&zeta, &mut fit)
                }
            }
            self.keep(fit, frame, edge, zeta, supports);
            self.by_node = by_node_room;
            return;
        }
        // K's null space per body (the nodes that particles connect), removed from the
        // right-hand side (see below) and from every preconditioned residual, so that round-off
        // does not carry the iterates along it (projected conjugate gradients).
        // With the linear fit, nodes the particles barely reach (`WEAK_REACH`) join no body.
        let weak = match linear_fit {
            true => WEAK_REACH * reach,
            false => 0.0,
        };
        // Where every support is a box, from the assembled operator (`NodeOperator::bodies`).
        let from_lattice = operator.filter(|_| weak == 0.0).and_then(|o| o.bodies());
        #[cfg(test)]
        {
            self.lattice_bodies = from_lattice.is_some();
        }
        let body_of = from_lattice.unwrap_or_else(|| {
            bodies(slots, positions.len(), |p, visit: &mut dyn FnMut(usize)| {
                if counted(p) {
                    support.for_each(p, |s| {
                        let slot = nodes.slot(s.node);
                        if weak == 0.0 || moment[slot] >= weak {
                            visit(slot);
                        }
                    });
                }
            })
        });
        let exps = self.basis.exponents();
        let degree = match m {
            1 => linear_fit as u32,
            _ => self.order - 1,
        };
        let null = NullSpace::new(
            degree,
            exps,
            used,
            grid,
            nodes,
            &body_of,
            (m == 1).then_some(&moment[..]),
        );
        let project = m == 1;
        let precondition = |r: &[f64], z: &mut [f64]| {
            match multilevel.as_ref().filter(|_| with_multilevel.get()) {
                Some(multilevel) => multilevel.precondition(r, z),
                None => node_blocks(r, z),
            }
            if project {
                null.remove_from_coefficients(z);
            }
        };
        // Off the null space (projected at order 1); at order ≥ 2, `(K + ε E A) ζ`
        // (`VC_REGULARISATION`; the assembled operator holds it).
        let apply = |zeta: &[f64], out: &mut [f64], fit: &mut [(Vector<D>, Matrix<D>)]| {
            product(zeta, out, fit);
            if operator.is_none() && m > 1 && damping > 0.0 {
                out.par_chunks_exact_mut(m * D)
                    .zip(zeta.par_chunks_exact(m * D))
                    .enumerate()
                    .for_each(|(slot, (o, z))| {
                        if !edge[slot] {
                            return;
                        }
                        let a = &moment[slot * m * m..(slot + 1) * m * m];
                        let mm = if reduced[slot] { 1 } else { m };
                        for k in 0..D {
                            for i in 0..mm {
                                o[k * m + i] += edge_damping[slot]
                                    * (0..mm).map(|j| a[i * m + j] * z[k * m + j]).sum::<f64>();
                            }
                        }
                    });
            }
            if project {
                null.remove(out);
            }
        };
        // Sums in fixed chunks, added in order: the same bits with any number of threads.
        let dot = |a: &[f64], b: &[f64]| -> f64 {
            let parts: Vec<f64> = a
                .par_chunks(4096)
                .zip(b.par_chunks(4096))
                .map(|(a, b)| a.iter().zip(b).map(|(x, y)| x * y).sum())
                .collect();
            parts.iter().sum()
        };
        let mut rhs = std::mem::take(&mut self.xi);
        // The part of the right-hand side along K's null space (per body, the nodes that
        // particles connect: at order 1 the sum of its surface's area normals, zero for a closed
        // surface up to round-off) is removed, so that the solve does not amplify it.
        if linear_fit {
            null.remove(&mut rhs);
        } else {
            NullSpace::new(degree, exps, used, grid, nodes, &body_of, None).remove(&mut rhs);
        }
        // A node corrected to order 1 meets its constant equality only: its other right-hand
        // sides are left out (the node blocks never read them; the assembled `K` has zero rows
        // there).
        rhs.par_chunks_exact_mut(m * D)
            .zip(self.reduced.par_iter())
            .filter(|(_, &reduced)| reduced)
            .for_each(|(r, _)| {
                for k in 0..D {
                    r[k * m + 1..(k + 1) * m].fill(0.0);
                }
            });
        // Started from the carried coefficients, or from zero, stopping when the preconditioned
        // residual has fallen to `solve.tolerance` of the right-hand side's.
        // Near a free surface the system is badly conditioned (nodes the particles barely
        // reach), and conjugate gradients can lose positive curvature to round-off (`dᵀKd ≤ 0`)
        // or let the residual grow: the solve then restarts from its best iterate with the
        // true residual, and returns the iterate of smallest residual, never a later, worse one.
        let mut r = rhs.clone();
        let mut z = vec![0.0; len];
        let mut kd = vec![0.0; len];
        precondition(&r, &mut z);
        let rhs_rz = dot(&r, &z);
        let mut zeta = match carry && carried {
            true => {
                let mut zeta = self.carried.at(&nodes.active, m * D);
                if project {
                    null.remove_from_coefficients(&mut zeta);
                }
                apply(&zeta, &mut kd, &mut fit);
                r.par_iter_mut()
                    .zip(&rhs)
                    .zip(&kd)
                    .for_each(|((r, b), kz)| *r = b - kz);
                precondition(&r, &mut z);
                zeta
            }
            false => vec![0.0; len],
        };
        let mut d = z.clone();
        let mut rz = dot(&r, &z);
        // At order ≥ 2 the V-cycle's coarsest solve is a pseudo-inverse, whose norm of the
        // residual can fall to the tolerance while the equalities are met to 1e-11 only (a
        // product with `K` of coefficients up to `10^3 / h`): the node blocks' norm measures.
        let measured = m > 1 && with_multilevel.get();
        let mut w = vec![0.0; if measured { len } else { 0 }];
        let mut size = |r: &[f64], rz: f64| {
            if measured {
                node_blocks(r, &mut w);
                dot(r, &w)
            } else {
                rz
            }
        };
        let VcSolve {
            tolerance,
            max_iterations,
            ..
        } = self.solve;
        let mut current = size(&r, rz);
        let rhs_size = size(&rhs, rhs_rz);
        let mut target = tolerance * tolerance * rhs_size;
        let (mut best, mut best_rz) = (zeta.clone(), current);
        let (mut iterations, mut restarts) = (0, 0);
        // At order ≥ 2, whether the best iterate is as good as round-off allows and the last
        // iterations did not improve it (see `VC_SOLVE_ATTAINABLE`).
        let mut since_best = 0;
        let attained = |best: f64, target: f64| {
            m > 1 && best <= VC_SOLVE_ATTAINABLE * VC_SOLVE_ATTAINABLE * target
        };
        while current > target && iterations < max_iterations {
            apply(&d, &mut kd, &mut fit);
            let dkd = dot(&d, &kd);
            if dkd.is_nan() || dkd <= 0.0 {
                if attained(best_rz, target) {
                    break;
                }
                if restarts == VC_SOLVE_MAX_RESTARTS {
                    break;
                }
                restarts += 1;
                zeta.copy_from_slice(&best);
                apply(&zeta, &mut kd, &mut fit);
                r.par_iter_mut()
                    .zip(&rhs)
                    .zip(&kd)
                    .for_each(|((r, b), kz)| *r = b - kz);
                if with_multilevel.replace(false) {
                    // The V-cycle brings the near-null directions of nodes that particles
                    // barely reach into the search directions, whose curvature round-off then
                    // swamps; the node blocks do not. Their norm measures from here on (the
                    // tolerance's alone: the carried residual was measured in the other).
                    precondition(&rhs, &mut z);
                    target = tolerance * tolerance * dot(&rhs, &z);
                    precondition(&r, &mut z);
                    best_rz = dot(&r, &z);
                }
                precondition(&r, &mut z);
                d.copy_from_slice(&z);
                rz = dot(&r, &z);
                current = size(&r, rz);
                continue;
            }
            let alpha = rz / dkd;
            zeta.par_iter_mut()
                .zip(&d)
                .for_each(|(x, d)| *x += alpha * d);
            r.par_iter_mut()
                .zip(&kd)
                .for_each(|(r, kd)| *r -= alpha * kd);
            precondition(&r, &mut z);
            let rz_new = dot(&r, &z);
            current = size(&r, rz_new);
            if current < best_rz {
                best_rz = current;
                best.copy_from_slice(&zeta);
                since_best = 0;
            } else {
                since_best += 1;
                if since_best >= VC_SOLVE_STAGNATION && attained(best_rz, target) {
                    iterations += 1;
                    break;
                }
            }
            let beta = rz_new / rz;
            rz = rz_new;
            d.par_iter_mut()
                .zip(&z)
                .for_each(|(d, z)| *d = z + beta * *d);
            iterations += 1;
        }
        let mut zeta = best;
        if project {
            null.remove_from_coefficients(&mut zeta);
        }
        self.iterations = iterations;
        if carry {
            self.proposed = Some((nodes.active.clone(), zeta.clone()));
        }
        self.bound_first_order(&mut zeta, reach, h);
        // The particle fits of the solution, which the corrected gradients subtract.
        match on_nodes {
            true => self.lay_on_nodes(&zeta, nodes, &mut fit),
            false => {
                self.on_nodes.clear();
                fits(&zeta, &mut fit)
            }
        }
        self.keep(fit, frame, edge, zeta, supports);
        self.by_node = by_node_room;
        if let Some(multilevel) = multilevel {
            self.storage = multilevel.into_storage();
        }
        if weak == 0.0 {
            self.body_of = body_of;
        }
    }

    /// Whether this step takes the coefficients carried from the last solve instead of
    /// solving (`VcSolve::interval`): at order 1, for the one field (not `per_body` under
    /// contact), while the carried solve is younger than the interval.
    fn between_solves(&self, per_body: bool) -> bool {
        let interval = self.solve.interval;
        interval > 1
            && !per_body
            && self.m() == 1
            && !self.carried.is_empty()
            && self.carried.age + 1 < interval
    }

    /// At order 1, bounds each node's correction (`first_order_correction_bound`) by its reach
    /// against the largest, `reach` (cells of size `h`); the fits are taken of the bounded
    /// coefficients, so the gradients still sum to zero.
    fn bound_first_order(&self, zeta: &mut [f64], reach: f64, h: f64) {
        if self.m() > 1 {
            return;
        }
        let moment = &self.moment;
        zeta.par_chunks_exact_mut(D).enumerate().for_each(|(s, z)| {
            let size = z.iter().map(|x| x * x).sum::<f64>().sqrt() * h;
            let bound = first_order_correction_bound(moment[s], reach);
            if size > bound {
                z.iter_mut().for_each(|x| *x *= bound / size);
            }
        });
    }

    /// Lays the order-1 coefficients `zeta` (per slot) on the grid's nodes for particle to
    /// grid to fit (`mean_fit_coefficients`), and drops the particle fits.
    fn lay_on_nodes(
        &mut self,
        zeta: &[f64],
        nodes: &GridNodes<D>,
        fit: &mut Vec<(Vector<D>, Matrix<D>)>,
    ) {
        fit.clear();
        let on_nodes = &mut self.on_nodes;
        on_nodes.resize(nodes.mass.len(), Vector::<D>::zeros());
        let shared = SharedSlice::new(on_nodes);
        nodes
            .active
            .par_iter()
            .zip(zeta.par_chunks_exact(D))
            .for_each(|(&n, z)| {
                // SAFETY: every active node is listed once.
                unsafe { shared.range(n, 1)[0] = Vector::<D>::from_fn(|k, _| z[k]) };
            });
    }

    /// At order 1 with the mean fit on a tensor-product stencil: the coefficients `ζ` by grid
    /// node (valid at the active nodes). Particle to grid takes each particle's correction
    /// `(ζ_I − μ_p) |Ψ_Ip|`, `μ_p = Σ_I |Ψ_Ip| ζ_I / Σ_I |Ψ_Ip|`, from them and the stencil's
    /// factors in its factored scatter ([`crate::shape::ScatterInput`]`::mean_fit`), as
    /// [`VcCorrection::gradient_correction_at`] does from kept fits (the same sums in the same
    /// order). `None` when the fits are kept instead.
    pub fn mean_fit_coefficients(&self) -> Option<&[Vector<D>]> {
        (!self.on_nodes.is_empty()).then_some(&self.on_nodes[..])
    }

    /// Keeps a step's particle fits, frames, edge nodes, coefficients and supports.
    fn keep(
        &mut self,
        fit: Vec<(Vector<D>, Matrix<D>)>,
        frame: Vec<(Matrix<D>, Vector<D>)>,
        edge: Vec<bool>,
        zeta: Vec<f64>,
        supports: Supports,
    ) {
        self.fit = fit;
        self.frame = frame;
        self.edge = edge;
        self.xi = zeta;
        self.supports = supports;
    }

    /// Conjugate-gradient iterations of the last step's solve (zero on a step between solves).
    #[cfg(test)]
    pub(crate) fn iterations(&self) -> usize {
        self.iterations
    }

    /// The coefficients carried between solves.
    pub(crate) fn carried(&self) -> &CarriedCoefficients {
        &self.carried
    }

    /// Restores coefficients carried between solves (`per` values a node of `nodes`, `age`
    /// steps since their solve, on a grid of `node_count` nodes) and the solve before them
    /// (`before`: its nodes, values and the steps from it to the last), as a checkpoint holds
    /// them. Refuses values of another size than this correction's.
    pub(crate) fn restore_carried(
        &mut self,
        (nodes, values): (Vec<usize>, &[f64]),
        before: (Vec<usize>, &[f64], u32),
        per: usize,
        age: u32,
        node_count: usize,
    ) -> Result<()> {
        self.carried.clear();
        if nodes.is_empty() {
            return Ok(());
        }
        if per != self.m() * D {
            return Err(Error::invalid(format!(
                "carried VC coefficients of {per} values a node, where VC of order {} takes {}",
                self.order,
                self.m() * D
            )));
        }
        self.carried.replace(nodes, values, per, node_count);
        let (nodes, values, span) = before;
        self.carried.restore_before(nodes, values, span);
        self.carried.age = age;
        Ok(())
    }

    /// At the start of a step: drops a solve proposed by an earlier step that was rejected
    /// (before its commit), so that a step that does not solve this correction (contact on,
    /// or another shape's grid since) cannot commit it.
    pub fn discard_proposal(&mut self) {
        self.proposed = None;
    }

    /// At the commit of a step: its solve becomes the carried coefficients (on a grid of
    /// `node_count` nodes), or the carried ones age by a step.
    pub fn commit_step(&mut self, node_count: usize) {
        match self.proposed.take() {
            Some((nodes, values)) => {
                let per = self.m() * D;
                self.carried.replace(nodes, &values, per, node_count)
            }
            None if !self.carried.is_empty() => self.carried.age += 1,
            None => {}
        }
    }

    /// Per slot of the nodes active now, the connected body of the nodes the field's particles
    /// join, as the last solve found them; empty when it found none or left weakly reached nodes
    /// out (the linear fit).
    pub fn bodies(&self) -> &[usize] {
        &self.body_of
    }

    /// Whether node `n` (active) had a singular moment matrix and got the order-1 correction only.
    #[cfg(test)]
    pub fn reduced_to_first_order(&self, nodes: &GridNodes<D>, n: usize) -> bool {
        self.reduced.get(nodes.slot(n)).copied().unwrap_or(false)
    }

    /// Whether node `n` (active) is at a body's edge, where the order-≥ 2 solve is damped
    /// (`VC_REGULARISATION`).
    #[cfg(test)]
    pub fn at_edge(&self, nodes: &GridNodes<D>, n: usize) -> bool {
        self.edge.get(nodes.slot(n)).copied().unwrap_or(false)
    }

    /// The correction `ζ_I·Q_I(x_p) − μ_p` to add to `∇Ψ_I(x_p)` for the node `n` (already
    /// active, in the support of particle `p` at `x`).
    #[cfg(test)]
    pub fn gradient_correction(
        &self,
        grid: &Grid<D>,
        nodes: &GridNodes<D>,
        n: usize,
        p: usize,
        x: &Vector<D>,
        weight: f64,
    ) -> Vector<D> {
        self.gradient_correction_at(grid, nodes.slot(n) as u32, n, p, x, weight)
    }

    /// [`VcCorrection::gradient_correction`] for the node `n` listed at `slot`.
    #[inline]
    pub fn gradient_correction_at(
        &self,
        grid: &Grid<D>,
        slot: u32,
        n: usize,
        p: usize,
        x: &Vector<D>,
        weight: f64,
    ) -> Vector<D> {
        let m = self.m();
        let slot = slot as usize;
        let r = &self.xi[slot * m * D..(slot + 1) * m * D];
        let (mu, slope) = &self.fit[p];
        if m == 1 && self.frame.is_empty() {
            return (Vector::<D>::from_fn(|k, _| r[k]) - mu) * weight.abs();
        }
        if m == 1 {
            let (t, o) = &self.frame[p];
            let u = t * ((grid.node_position(grid.node_multi_index(n)) - x) / grid.cell_size) - o;
            return (Vector::<D>::from_fn(|k, _| r[k]) - mu - slope * u) * weight.abs();
        }
        let mut q = [0.0; MAX_BASIS];
        let z = (x - grid.node_position(grid.node_multi_index(n))) / grid.cell_size;
        self.basis_at(&z, &mut q[..m], None);
        (Vector::<D>::from_fn(|k, _| (0..m).map(|j| r[k * m + j] * q[j]).sum()) - mu) * weight.abs()
    }
}

/// A particle's frame of the order-1 linear fit, from the weighted moments of its node offsets
/// `d_I = (x_I − x_p)/h` (`weight = Σ w_I`, `first = Σ w_I d_I`, `second = Σ w_I d_I d_Iᵀ`):
/// `(T, o)` such that `u_I = T d_I − o` has weighted mean zero and weighted second moment the
/// identity, `Σ_I w_I u_I = 0` and `Σ_I w_I u_I u_Iᵀ = 1`. `T = L⁻¹` for the Cholesky factor `L`
/// of the centred moment `S = second − first firstᵀ / weight`; a pivot at or below
/// `1e-10 weight` (the offsets do not span that direction: linear hats, a particle on a node
/// line) is dropped, its row of `T` zero, so that `u_I·u_J = (d_I − d̄)ᵀ S⁺ (d_J − d̄)` whatever
/// the rank. Zero for a particle without weight.
fn linear_frame<const D: usize>(
    weight: f64,
    first: Vector<D>,
    second: Matrix<D>,
) -> (Matrix<D>, Vector<D>) {
    if weight <= 0.0 {
        return (Matrix::zeros(), Vector::zeros());
    }
    let centre = first / weight;
    let s = second - first * centre.transpose();
    let mut l = Matrix::<D>::zeros();
    let mut kept = [false; D];
    for j in 0..D {
        let pivot = s[(j, j)] - (0..j).map(|k| l[(j, k)] * l[(j, k)]).sum::<f64>();
        if pivot <= 1e-10 * weight {
            continue;
        }
        kept[j] = true;
        l[(j, j)] = pivot.sqrt();
        for i in j + 1..D {
            l[(i, j)] =
                (s[(i, j)] - (0..j).map(|k| l[(i, k)] * l[(j, k)]).sum::<f64>()) / l[(j, j)];
        }
    }
    let mut t = Matrix::<D>::zeros();
    for i in (0..D).filter(|&i| kept[i]) {
        for c in 0..D {
            let unit = if i == c { 1.0 } else { 0.0 };
            t[(i, c)] = (unit - (0..i).map(|k| l[(i, k)] * t[(k, c)]).sum::<f64>()) / l[(i, i)];
        }
    }
    (t, t * centre)
}

/// `K`'s null space, per body: the node coefficients of every global polynomial `P` of the
/// null degree (`< n` at order n ≥ 2; at order 1, 1 with the linear fit, which reproduces the
/// linear fields, and 0 with the mean fit), re-expanded about each node, `P(x_c + h (d_I + z)) = Σ_e N_Ie z^e`,
/// `d_I = (x_I − x_c)/h` about the body's node centroid `x_c` (binomial coefficients).
struct NullSpace<'a, const D: usize> {
    grid: &'a Grid<D>,
    nodes: &'a GridNodes<D>,
    body_of: &'a [usize],
    used: &'a [bool],
    /// Per slot, the weight of the removed part (the oblique projection), or 1.
    weight: Option<&'a [f64]>,
    exps: Vec<[u32; D]>,
    nulls: Vec<[u32; D]>,
    centroid: Vec<Vector<D>>,
    /// Per slot, `N_I` ([`NullSpace::expansion`]), `m k` values (zero where unused): each
    /// projection reads it twice per slot.
    table: Vec<f64>,
    /// Per body, the pseudo-inverse of `G = Σ_I a_I N_Iᵀ N_I`.
    gram_inverse: Vec<DMatrix<f64>>,
}

impl<'a, const D: usize> NullSpace<'a, D> {
    fn new(
        degree: u32,
        exps: &[[u32; D]],
        used: &'a [bool],
        grid: &'a Grid<D>,
        nodes: &'a GridNodes<D>,
        body_of: &'a [usize],
        weight: Option<&'a [f64]>,
    ) -> Self {
        let exps = exps.to_vec();
        let nulls = Monomials::<D>::up_to(degree).exponents().to_vec();
        let bodies = body_of.iter().map(|&b| b + 1).max().unwrap_or(0);
        let mut sums = vec![(0.0, Vector::<D>::zeros()); bodies];
        for (slot, &b) in body_of.iter().enumerate() {
            if used[slot] {
                sums[b].0 += 1.0;
                sums[b].1 += grid.node_position(grid.node_multi_index(nodes.active[slot]));
            }
        }
        let centroid = sums
            .iter()
            .map(|&(c, x): &(f64, Vector<D>)| x / c.max(1.0))
            .collect();
        let mut space = NullSpace {
            grid,
            nodes,
            body_of,
            used,
            weight,
            exps,
            nulls,
            centroid,
            table: Vec::new(),
            gram_inverse: Vec::new(),
        };
        let (m, k) = (space.exps.len(), space.nulls.len());
        let mut table = vec![0.0; body_of.len() * m * k];
        table
            .par_chunks_exact_mut(m * k)
            .enumerate()
            .filter(|&(slot, _)| used[slot])
            .for_each(|(slot, n)| space.expansion(slot, n));
        space.table = table;
        let mut gram = vec![DMatrix::<f64>::zeros(k, k); bodies];
        for (slot, &b) in body_of.iter().enumerate() {
            if !used[slot] {
                continue;
            }
            let n = space.null_at(slot);
            let a = space.weight_of(slot);
            for f in 0..k {
                for g in 0..k {
                    gram[b][(f, g)] += a * (0..m).map(|e| n[e * k + f] * n[e * k + g]).sum::<f64>();
                }
            }
        }
        // A body too thin to fix a linear field (its nodes on one line) keeps the rest: the
        // pseudo-inverse of its Gram matrix.
        space.gram_inverse = gram
            .into_iter()
            .map(|g| {
                let tolerance = 1e-12 * g.norm();
                g.pseudo_inverse(tolerance)
                    .unwrap_or_else(|_| DMatrix::zeros(k, k))
            })
            .collect();
        space
    }

    fn weight_of(&self, slot: usize) -> f64 {
        self.weight.map_or(1.0, |w| w[slot])
    }

    /// `N_I[e][f]` (`e k + f`), from the table.
    #[inline]
    fn null_at(&self, slot: usize) -> &[f64] {
        let mk = self.exps.len() * self.nulls.len();
        &self.table[slot * mk..(slot + 1) * mk]
    }

    /// `N_I[e][f]`: coefficient of `z^e` in the re-expansion of the null monomial `f`.
    fn expansion(&self, slot: usize, out: &mut [f64]) {
        let binomial = |n: u32, k: u32| -> f64 {
            (0..k).fold(1.0, |c, i| c * (n - i) as f64 / (i + 1) as f64)
        };
        let k = self.nulls.len();
        let x = self
            .grid
            .node_position(self.grid.node_multi_index(self.nodes.active[slot]));
        let d = (x - self.centroid[self.body_of[slot]]) / self.grid.cell_size;
        for (e, ee) in self.exps.iter().enumerate() {
            for (f, ff) in self.nulls.iter().enumerate() {
                out[e * k + f] = if (0..D).all(|a| ee[a] <= ff[a]) {
                    (0..D)
                        .map(|a| binomial(ff[a], ee[a]) * d[a].powi((ff[a] - ee[a]) as i32))
                        .product()
                } else {
                    0.0
                };
            }
        }
    }

    /// Removes from the coefficients `v` their part along the null space, orthogonally in the
    /// weights' inner product: `v_I −= N_I G⁻¹ Σ_J N_Jᵀ a_J v_J`, after which
    /// `Σ_J a_J N_Jᵀ v_J = 0` per body. `K v` is unchanged.
    fn remove_from_coefficients(&self, v: &mut [f64]) {
        self.project(v, true);
    }

    /// Removes from `v` (per slot, `m` values per direction) its part along the null space:
    /// `v_I −= a_I N_I G⁻¹ Σ_J N_Jᵀ v_J`, after which `Σ_J N_Jᵀ v_J = 0` per body.
    fn remove(&self, v: &mut [f64]) {
        self.project(v, false);
    }

    /// The two projections: the weights `a_J` in the sums (`coefficients`) or in the update.
    /// The sums run in slot order (the same bits with any number of threads), the update in
    /// parallel.
    fn project(&self, v: &mut [f64], coefficients: bool) {
        let (m, k) = (self.exps.len(), self.nulls.len());
        if (m, k) == (1, 1) {
            self.project_constants(v, coefficients);
            return;
        }
        let bodies = self.gram_inverse.len();
        // Per body, `Σ_J N_Jᵀ (a_J) v_J`, `k × D` row-major.
        let mut t = vec![0.0; bodies * k * D];
        for (slot, &b) in self.body_of.iter().enumerate() {
            if !self.used[slot] {
                continue;
            }
            let n = self.null_at(slot);
            let r = &v[slot * m * D..(slot + 1) * m * D];
            let t = &mut t[b * k * D..(b + 1) * k * D];
            for f in 0..k {
                for c in 0..D {
                    let sum = (0..m).map(|e| n[e * k + f] * r[c * m + e]).sum::<f64>();
                    t[f * D + c] += match coefficients {
                        true => self.weight_of(slot) * sum,
                        false => sum,
                    };
                }
            }
        }
        let alpha: Vec<DMatrix<f64>> = self
            .gram_inverse
            .iter()
            .zip(t.chunks_exact(k * D))
            .map(|(g, t)| g * DMatrix::from_row_slice(k, D, t))
            .collect();
        v.par_chunks_exact_mut(m * D)
            .enumerate()
            .filter(|&(slot, _)| self.used[slot])
            .for_each(|(slot, r)| {
                let (n, alpha) = (self.null_at(slot), &alpha[self.body_of[slot]]);
                for c in 0..D {
                    for e in 0..m {
                        let sum = (0..k).map(|f| n[e * k + f] * alpha[(f, c)]).sum::<f64>();
                        r[c * m + e] -= match coefficients {
                            true => sum,
                            false => self.weight_of(slot) * sum,
                        };
                    }
                }
            });
    }

    /// [`NullSpace::project`] at order 1 with the mean fit, where the null space is each body's
    /// constant (`m = k = 1`): the same sums in the same order, without the general loops.
    fn project_constants(&self, v: &mut [f64], coefficients: bool) {
        let mut t = vec![[0.0; D]; self.gram_inverse.len()];
        for (slot, &b) in self.body_of.iter().enumerate() {
            if self.used[slot] {
                let n = self.table[slot];
                let weight = if coefficients {
                    self.weight_of(slot)
                } else {
                    1.0
                };
                for c in 0..D {
                    t[b][c] += weight * (n * v[slot * D + c]);
                }
            }
        }
        let alpha: Vec<[f64; D]> = (self.gram_inverse.iter().zip(&t))
            .map(|(g, t)| t.map(|t| g[(0, 0)] * t))
            .collect();
        v.par_chunks_exact_mut(D)
            .enumerate()
            .filter(|&(slot, _)| self.used[slot])
            .for_each(|(slot, r)| {
                let (n, alpha) = (self.table[slot], &alpha[self.body_of[slot]]);
                let weight = if coefficients {
                    1.0
                } else {
                    self.weight_of(slot)
                };
                for c in 0..D {
                    r[c] -= weight * (n * alpha[c]);
                }
            });
    }
}

/// The connected bodies of the nodes (slots) that particles join: `stencil(p, visit)` visits
/// the slots of particle `p`'s support. Returns a body number per slot, numbered from 0.
/// [`bodies`] for stencils that are whole boxes of a tensor product (`tensor`, B-splines):
/// the same numbering from the cells the boxes cover instead of the nodes of every particle.
/// Two nodes share a body when a chain of stencil boxes, each overlapping the next in a node,
/// holds them; a box is the union of its cells, and two boxes overlap in a node exactly when
/// their cells are joined by cells that share a corner. So the bodies are the components of the
/// covered cells under corner contact, each active node in the component of a covered cell it is
/// a corner of (a node that no particle's box holds, reached by boundary points only, its own
/// body, as in [`bodies`]). The joins are those of the covered cells, not of the `W^D` nodes of
/// every particle (2D 4 to 9 times fewer at the benchmark block's 2.4 particles a cell, 3D 6 to
/// 27). `None` when a counted particle's support is not its whole box (a factor zero: a
/// particle on a node or a cell centre), which [`bodies`] then takes.
pub(crate) fn box_bodies<const D: usize>(
    grid: &Grid<D>,
    nodes: &GridNodes<D>,
    tensor: &TensorFactors<'_, D>,
    particles: usize,
    counted: impl Fn(usize) -> bool + Sync,
) -> Option<Vec<usize>> {
    let (w, dims, strides) = (tensor.width, grid.dims(), grid.strides());
    let whole = |p: usize| tensor.values(p).iter().all(|&v| v != 0.0);
    if !(0..particles)
        .into_par_iter()
        .all(|p| !counted(p) || whole(p))
    {
        return None;
    }
    // By slot of the active nodes: the boxes' first nodes, then the cells they cover (by the
    // cell's lower corner).
    let slots = nodes.active.len();
    let mut first = vec![false; slots];
    for p in (0..particles).filter(|&p| counted(p)) {
        first[nodes.slot_of(tensor.base(p))?] = true;
    }
    let corner =
        |n: usize| -> [i64; D] { std::array::from_fn(|a| ((n / strides[a]) % dims[a]) as i64) };
    // The slot of the node at `k + d` (storage multi-index `k`), if it is active.
    let at = |k: &[i64; D], d: &[i64; D]| -> Option<usize> {
        let mut m = 0usize;
        for a in 0..D {
            let j = k[a] + d[a];
            if !(0..dims[a] as i64).contains(&j) {
                return None;
            }
            m += j as usize * strides[a];
        }
        nodes.slot_of(m)
    };
    let mut covered = vec![false; slots];
    let in_cell = |c: usize, e: usize| -> [i64; D] {
        std::array::from_fn(|a| (c / e.pow(a as u32) % e) as i64)
    };
    for s in (0..slots).filter(|&s| first[s]) {
        let k = corner(nodes.active[s]);
        for c in 0..(w - 1).pow(D as u32) {
            covered[at(&k, &in_cell(c, w - 1))?] = true;
        }
    }
    // Components of the covered cells that share a corner: a join with each of the 3^D − 1
    // neighbours listed after it (the offsets whose last nonzero entry is +1).
    let mut parent: Vec<usize> = (0..slots).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    let offsets: Vec<[i64; D]> = (0..3usize.pow(D as u32))
        .map(|o| in_cell(o, 3).map(|x| x - 1))
        .filter(|d| d.iter().rev().find(|&&x| x != 0) == Some(&1))
        .collect();
    for s in (0..slots).filter(|&s| covered[s]) {
        let k = corner(nodes.active[s]);
        for d in &offsets {
            if let Some(t) = at(&k, d).filter(|&t| covered[t]) {
                let (a, b) = (root(&mut parent, s), root(&mut parent, t));
                if a != b {
                    parent[b] = a;
                }
            }
        }
    }
    // Each active node's body: that of a covered cell it is a corner of, numbered by first
    // slot as `bodies` numbers; a node of no box keys by its own slot (not covered, so no
    // covered cell's root).
    let mut number = vec![usize::MAX; slots];
    let mut next = 0;
    Some(
        (0..slots)
            .map(|s| {
                let k = corner(nodes.active[s]);
                let cell = (0..1usize << D)
                    .find_map(|c| at(&k, &in_cell(c, 2).map(|x| -x)).filter(|&t| covered[t]));
                let key = cell.map_or(s, |cell| root(&mut parent, cell));
                if number[key] == usize::MAX {
                    number[key] = next;
                    next += 1;
                }
                number[key]
            })
            .collect(),
    )
}

pub(crate) fn bodies(
    slots: usize,
    particles: usize,
    stencil: impl Fn(usize, &mut dyn FnMut(usize)) + Sync,
) -> Vec<usize> {
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    fn join(parent: &mut [usize], a: usize, b: usize) {
        let (a, b) = (root(parent, a), root(parent, b));
        if a != b {
            parent[b] = a;
        }
    }
    // One forest per thread over its share of the particles, then merged: the components, and
    // so the numbering below (by each body's first slot), are the same for any split.
    let chunks = rayon::current_num_threads().clamp(1, particles.max(1));
    let per = particles.div_ceil(chunks);
    let mut forests = (0..chunks)
        .into_par_iter()
        .map(|c| {
            let mut parent: Vec<usize> = (0..slots).collect();
            for p in c * per..((c + 1) * per).min(particles) {
                let mut first = None;
                stencil(p, &mut |slot| match first {
                    None => first = Some(slot),
                    Some(f) => join(&mut parent, f, slot),
                });
            }
            parent
        })
        .collect::<Vec<_>>()
        .into_iter();
    let mut parent = forests.next().unwrap_or_else(|| (0..slots).collect());
    for other in forests {
        for (i, &j) in other.iter().enumerate().filter(|&(i, &j)| i != j) {
            join(&mut parent, i, j);
        }
    }
    let mut number = vec![usize::MAX; slots];
    let mut next = 0;
    (0..slots)
        .map(|i| {
            let r = root(&mut parent, i);
            if number[r] == usize::MAX {
                number[r] = next;
                next += 1;
            }
            number[r]
        })
        .collect()
}

#[cfg(test)]
mod tests;
