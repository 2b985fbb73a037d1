//! Variationally consistent (VC) integration (Chen, Hillman & Rüter 2013; METHOD.md section 3).
//!
//! Particles are the quadrature points. The test-function gradients are corrected per node so that
//! the discrete divergence equality of order `n` holds: for every monomial `Q` of degree ≤ n − 1,
//!
//! ```text
//! Σ_p ∇̂Ψ_I Q V_p + Σ_p Ψ_I ∇Q V_p = Σ_b Ψ_I Q n_b a_b,     ∇̂Ψ_I = ∇Ψ_I + Σ_j ξ_Ij Q_j
//! ```
//!
//! which is, per node and direction, one small linear system with the moment matrix
//! `A_I = Σ_p Q Qᵀ V_p` over the particles in the node's support. Order 1 is the seed's form
//! (`Q = 1`): `ξ_I = (B_I − D_I) / W_I`. `Q` is written in `(x − x_I)/h` to keep `A_I`
//! well conditioned. A node whose `A_I` is singular (too few particles in its support for the
//! order) falls back to the order-1 correction.
//!
//! The corrected gradient is used in the internal force only (METHOD.md section 7).

pub mod boundary_points;

pub use boundary_points::BoundaryPoints;

use crate::error::{Error, Result};
use crate::grid::{Grid, GridNodes, NodeScatter, SharedSlice};
use crate::shape::{Monomials, StencilNode, StencilView, Stencils};
use crate::step::Bins;
use crate::Vector;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// A node's order-`n` correction needs its particle moment matrix `A_I = Σ V_p Q Qᵀ` to be well
/// conditioned; below this smallest-to-largest eigenvalue ratio (a node whose support holds only
/// a thin sliver of the body) the node gets the order-1 (constant) correction only.
pub const VC_MIN_RELATIVE_EIGENVALUE: f64 = 1e-4;

/// Test polynomials at most (order 4 in 3D: the monomials of degree ≤ 3).
const MAX_BASIS: usize = 20;

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
}

impl<const D: usize> VcCorrection<D> {
    /// Order 1 to 4.
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
    /// active in `nodes`. With `body = Some((materials, b))` (contact: one field per body) only
    /// the particles of material `b` count, and `boundary` is that body's surface.
    ///
    /// The particle sums run in parallel by the colours of `bins` (the particles of `positions`
    /// binned for this step), the per-node solves in parallel: the same bits with any number of
    /// threads.
    #[allow(clippy::too_many_arguments)]
    pub fn compute(
        &mut self,
        grid: &Grid<D>,
        bins: &Bins<D>,
        positions: &[Vector<D>],
        volumes: &[f64],
        stencils: &Stencils<D>,
        boundary: &BoundaryPoints<D>,
        boundary_stencils: &Stencils<D>,
        nodes: &mut GridNodes<D>,
        body: Option<(&[u32], u32)>,
    ) {
        let m = self.m();
        let h = grid.cell_size;
        let in_support = |s: &StencilNode<D>| s.value != 0.0 || s.gradient != Vector::<D>::zeros();
        let by_colour = |visit: &(dyn Fn(usize) + Sync)| {
            for colour in &bins.colours {
                colour.par_iter().for_each(|&b| {
                    for &p in &bins.order[bins.occupied[b as usize].1.clone()] {
                        if body.is_none_or(|(materials, b)| materials[p as usize] == b) {
                            visit(p as usize);
                        }
                    }
                });
            }
        };
        // The nodes: those of particle stencils (listed block by block), then those that only
        // boundary points reach.
        {
            let out = NodeScatter::new(nodes);
            by_colour(&|p| {
                stencils.for_each(p, |_, s| {
                    if in_support(&s) {
                        // SAFETY: blocks of one colour write disjoint nodes (`Bins`).
                        unsafe { out.touch(s.node) }
                    }
                })
            });
        }
        bins.collect_active(grid, nodes);
        for b in 0..boundary.len() {
            let (ns, ws, _) = boundary_stencils.of(b);
            for (&n, &w) in ns.iter().zip(ws) {
                if w != 0.0 {
                    nodes.touch(n);
                }
            }
        }
        let slots = nodes.active.len();
        for (v, per) in [(&mut self.moment, m * m), (&mut self.xi, m * D)] {
            v.clear();
            v.resize(slots * per, 0.0);
        }
        for v in [&mut self.used, &mut self.reduced] {
            v.clear();
            v.resize(slots, false);
        }
        // Particle sums: A_I += V Q Qᵀ; rhs_Ik −= V (∂_k Ψ Q + Ψ ∂_k Q).
        {
            let moment = SharedSlice::new(&mut self.moment);
            let xi = SharedSlice::new(&mut self.xi);
            let used = SharedSlice::new(&mut self.used);
            let nodes = &*nodes;
            let basis = &self.basis;
            by_colour(&|p| {
                let (mut q, mut dq) = ([0.0; MAX_BASIS], [0.0; 3 * MAX_BASIS]);
                let v = volumes[p];
                stencils.for_each(p, |_, s| {
                    if !in_support(&s) {
                        return;
                    }
                    let slot = nodes.slot(s.node);
                    if m == 1 {
                        // Order 1: Q = 1, ∇Q = 0 (no position needed).
                        q[0] = 1.0;
                    } else {
                        let x_node = grid.node_position(grid.node_multi_index(s.node));
                        let z = (positions[p] - x_node) / h;
                        basis.values(&z, &mut q[..m]);
                        for k in 0..D {
                            basis.derivatives(&z, k, &mut dq[k * m..(k + 1) * m]);
                        }
                    }
                    // SAFETY: the slot belongs to a node that only this block writes in this
                    // colour (`Bins`); slots of different nodes are disjoint ranges.
                    unsafe {
                        let a = moment.range(slot * m * m, m * m);
                        for i in 0..m {
                            for j in 0..m {
                                a[i * m + j] += v * q[i] * q[j];
                            }
                        }
                        let r = xi.range(slot * m * D, m * D);
                        for k in 0..D {
                            for j in 0..m {
                                r[k * m + j] -=
                                    v * (s.gradient[k] * q[j] + s.value * dq[k * m + j] / h);
                            }
                        }
                        used.range(slot, 1)[0] = true;
                    }
                });
            });
        }
        // Boundary sums: rhs_Ik += Ψ_I Q (n a)_k, only at nodes whose support meets a point.
        let mut q = [0.0; MAX_BASIS];
        for b in 0..boundary.len() {
            let (ns, ws, _) = boundary_stencils.of(b);
            let na = boundary.area_normal[b];
            for s in 0..ns.len() {
                if ws[s] == 0.0 {
                    continue;
                }
                let n = ns[s];
                let slot = nodes.slot(n);
                let z = (boundary.position[b] - grid.node_position(grid.node_multi_index(n))) / h;
                self.basis_at(&z, &mut q, None);
                let r = &mut self.xi[slot * m * D..(slot + 1) * m * D];
                for k in 0..D {
                    for j in 0..m {
                        r[k * m + j] += ws[s] * q[j] * na[k];
                    }
                }
            }
        }
        // Solve A_I ξ_Ik = rhs_Ik per node.
        self.moment
            .par_chunks_exact(m * m)
            .zip(self.xi.par_chunks_exact_mut(m * D))
            .zip(self.used.par_iter())
            .zip(self.reduced.par_iter_mut())
            .filter(|((_, &used), _)| used)
            .for_each(|(((a, r), _), reduced)| {
                let a = DMatrix::from_row_slice(m, m, a);
                // A moment matrix whose particles lie (nearly) on a lower-dimensional set cannot
                // carry the higher constraints: relative smallest eigenvalue below
                // [`VC_MIN_RELATIVE_EIGENVALUE`].
                let well_posed = m > 1 && {
                    let eig = a.clone().symmetric_eigenvalues();
                    eig.min() > VC_MIN_RELATIVE_EIGENVALUE * eig.max()
                };
                let chol = if well_posed {
                    a.clone().cholesky()
                } else {
                    None
                };
                *reduced = m > 1 && chol.is_none();
                for k in 0..D {
                    let rhs = DVector::from_column_slice(&r[k * m..(k + 1) * m]);
                    match &chol {
                        Some(c) => r[k * m..(k + 1) * m].copy_from_slice(c.solve(&rhs).as_slice()),
                        None => {
                            // Order 1, or a singular A_I: the constant correction alone.
                            let c0 = rhs[0] / a[(0, 0)];
                            r[k * m..(k + 1) * m].fill(0.0);
                            r[k * m] = c0;
                        }
                    }
                }
            });
    }

    /// Whether node `n` (active) had a singular moment matrix and got the order-1 correction only.
    pub fn reduced_to_first_order(&self, nodes: &GridNodes<D>, n: usize) -> bool {
        self.reduced.get(nodes.slot(n)).copied().unwrap_or(false)
    }

    /// The correction `Σ_j ξ_Ij Q_j(x)` to add to `∇Ψ_I(x)` for the node `n` (already active).
    #[inline]
    pub fn gradient_correction(
        &self,
        grid: &Grid<D>,
        nodes: &GridNodes<D>,
        n: usize,
        x: &Vector<D>,
    ) -> Vector<D> {
        self.gradient_correction_at(grid, nodes.slot(n) as u32, n, x)
    }

    /// [`VcCorrection::gradient_correction`] for the node `n` listed at `slot`.
    #[inline]
    pub fn gradient_correction_at(
        &self,
        grid: &Grid<D>,
        slot: u32,
        n: usize,
        x: &Vector<D>,
    ) -> Vector<D> {
        let m = self.m();
        let slot = slot as usize;
        let r = &self.xi[slot * m * D..(slot + 1) * m * D];
        if m == 1 {
            return Vector::<D>::from_fn(|k, _| r[k]);
        }
        let mut q = [0.0; 64];
        let z = (x - grid.node_position(grid.node_multi_index(n))) / grid.cell_size;
        self.basis_at(&z, &mut q[..m], None);
        Vector::<D>::from_fn(|k, _| (0..m).map(|j| r[k * m + j] * q[j]).sum())
    }
}

#[cfg(test)]
mod tests;
