//! Reproducing kernel (RK) shape functions of any basis order on the grid nodes
//! (Chen, Pan, Wu & Liu 1996; METHOD.md section 2).
//!
//! `Ψ_I(x) = b(x)ᵀ H(z_I) φ_I(x)`, `z_I = (x − x_I)/a`, `a = ã h`, `H` the monomials of degree
//! ≤ n, `φ_I` the tensor-product cubic B-spline kernel of support `a`, `b = M⁻¹ H(0)` with the
//! moment matrix `M = Σ_I H Hᵀ φ_I`, solved by a dense Cholesky factorization per point. The
//! gradients are exact: `∂b = −M⁻¹ (∂M) b`.
//!
//! The grid's ghost layers make the node set a full lattice around every point of the domain, so
//! `M` is the same (up to translation by a cell) everywhere: its conditioning is checked once,
//! over one cell, when the shape function is built, and a support that makes `M` singular or badly
//! conditioned is refused.

use super::{Monomials, ShapeFunction};
use crate::error::{Error, Result};
use crate::grid::Grid;
use crate::Vector;
use nalgebra::{DMatrix, DVector};

/// Largest accepted condition number of the moment matrix (normalized by `a`, so O(1)–O(1e4) for
/// sensible supports; a support too small for the order drives it to infinity).
pub const MAX_CONDITION: f64 = 1e10;

/// The cubic B-spline kernel of METHOD.md section 2 with support 1, and its derivative.
#[inline]
pub fn cubic_kernel(s: f64) -> (f64, f64) {
    let r = s.abs();
    let sg = s.signum();
    if r <= 0.5 {
        (
            2.0 / 3.0 - 4.0 * r * r + 4.0 * r * r * r,
            sg * (-8.0 * r + 12.0 * r * r),
        )
    } else if r <= 1.0 {
        (
            4.0 / 3.0 - 4.0 * r + 4.0 * r * r - 4.0 / 3.0 * r * r * r,
            sg * (-4.0 + 8.0 * r - 4.0 * r * r),
        )
    } else {
        (0.0, 0.0)
    }
}

/// RK shape function of basis order `order` and normalized support `support` (`ã`).
#[derive(Debug, Clone)]
pub struct ReproducingKernel<const D: usize> {
    pub order: u32,
    pub support: f64,
    /// The basis `H`: monomials of degree ≤ order.
    basis: Monomials<D>,
    /// Nodes per axis in the stencil.
    width: usize,
    /// Whether `Ψ_I` is negative somewhere (measured once in `new`).
    signed: bool,
}

impl<const D: usize> ReproducingKernel<D> {
    /// Builds the shape function; fails for an order outside 1..=5, a non-finite or out-of-range
    /// support, or a support whose moment matrix is singular or worse conditioned than
    /// [`MAX_CONDITION`].
    pub fn new(order: u32, support: f64) -> Result<Self> {
        if !(1..=5).contains(&order) {
            return Err(Error::invalid(format!(
                "rk_order must lie in 1..=5, got {order}"
            )));
        }
        if !(support.is_finite() && support > 0.5 && support <= 8.0) {
            return Err(Error::invalid(format!(
                "rk_support (normalized support ã) must lie in (0.5, 8], got {support}"
            )));
        }
        let rk = ReproducingKernel {
            order,
            support,
            basis: Monomials::up_to(order),
            width: (2.0 * support).ceil() as usize + 1,
            signed: false,
        };
        let worst = rk.worst_condition();
        if worst.is_nan() || worst > MAX_CONDITION {
            return Err(Error::invalid(format!(
                "rk_support {support} is too small for rk_order {order}: the moment matrix has condition number {worst:.3e} (limit {MAX_CONDITION:.0e}); try ã ≥ {:.1}",
                (order as f64 + 1.0) / 2.0 + 0.5
            )));
        }
        let signed = rk.most_negative_value() < -1e-12;
        Ok(ReproducingKernel { signed, ..rk })
    }

    /// The most negative `Ψ_I` over a lattice of points in one cell (the node set is a full
    /// lattice, so this holds everywhere in the domain).
    fn most_negative_value(&self) -> f64 {
        let samples = 8usize;
        let mut grid = Grid::<D>::new(Vector::<D>::zeros(), [1; D], 1.0).expect("unit grid");
        grid.set_ghost_layers(self.ghost_layers()).expect("ghosts");
        let len = self.stencil_len();
        let (mut n, mut w, mut g) = (
            vec![0; len],
            vec![0.0; len],
            vec![Vector::<D>::zeros(); len],
        );
        let mut lowest: f64 = 0.0;
        for k in 0..samples.pow(D as u32) {
            let mut r = k;
            let x = Vector::<D>::from_fn(|_, _| {
                let t = (r % samples) as f64 / samples as f64;
                r /= samples;
                t
            });
            self.evaluate(&grid, &x, &mut n, &mut w, &mut g);
            lowest = w.iter().copied().fold(lowest, f64::min);
        }
        lowest
    }

    /// Number of basis monomials.
    pub fn basis_len(&self) -> usize {
        self.basis.len()
    }

    fn first_node(&self, xi: f64) -> i64 {
        (xi - self.support).floor() as i64 + 1
    }

    /// Moment matrix at a point `xi` (cell units) of an unbounded unit lattice.
    fn moment_matrix(&self, xi: &Vector<D>) -> DMatrix<f64> {
        let m = self.basis_len();
        let mut mm = DMatrix::zeros(m, m);
        let mut h = DVector::zeros(m);
        self.for_each_node(xi, |_, z, phi, _| {
            self.basis(z, &mut h);
            mm.ger(phi, &h, &h, 1.0);
        });
        mm
    }

    /// Largest condition number of `M` over a lattice of points in one cell.
    fn worst_condition(&self) -> f64 {
        let samples = 5usize;
        let mut worst: f64 = 0.0;
        for k in 0..samples.pow(D as u32) {
            let mut r = k;
            let xi = Vector::<D>::from_fn(|_, _| {
                let t = (r % samples) as f64 / samples as f64;
                r /= samples;
                t
            });
            let eig = self.moment_matrix(&xi).symmetric_eigenvalues();
            let (lo, hi) = (eig.min(), eig.max());
            worst = worst.max(if lo > 0.0 { hi / lo } else { f64::INFINITY });
        }
        worst
    }

    /// Calls `f(offset, z, φ, ∂φ/∂ξ)` for every stencil node of the point `xi` (cell units), where
    /// `offset` is the node's integer index and `z = (ξ − ξ_I)/ã`.
    fn for_each_node(
        &self,
        xi: &Vector<D>,
        mut f: impl FnMut([i64; D], &Vector<D>, f64, &Vector<D>),
    ) {
        let w = self.width;
        let mut first = [0i64; D];
        for a in 0..D {
            first[a] = self.first_node(xi[a]);
        }
        let mut k = [0usize; D];
        for _ in 0..w.pow(D as u32) {
            let mut idx = [0i64; D];
            let mut z = Vector::<D>::zeros();
            let mut w1 = [(0.0, 0.0); D];
            for a in 0..D {
                idx[a] = first[a] + k[a] as i64;
                z[a] = (xi[a] - idx[a] as f64) / self.support;
                w1[a] = cubic_kernel(z[a]);
            }
            let phi: f64 = w1.iter().map(|p| p.0).product();
            if phi > 0.0 {
                let dphi = Vector::<D>::from_fn(|a, _| {
                    (0..D)
                        .map(|b| {
                            if a == b {
                                w1[b].1 / self.support
                            } else {
                                w1[b].0
                            }
                        })
                        .product()
                });
                f(idx, &z, phi, &dphi);
            }
            for kk in k.iter_mut() {
                *kk += 1;
                if *kk < w {
                    break;
                }
                *kk = 0;
            }
        }
    }

    /// `H(z)`: the monomials at `z`.
    fn basis(&self, z: &Vector<D>, h: &mut DVector<f64>) {
        self.basis.values(z, h.as_mut_slice());
    }

    /// `∂H/∂z_k`.
    fn basis_derivative(&self, z: &Vector<D>, k: usize, dh: &mut DVector<f64>) {
        self.basis.derivatives(z, k, dh.as_mut_slice());
    }
}

impl<const D: usize> ShapeFunction<D> for ReproducingKernel<D> {
    fn stencil_len(&self) -> usize {
        self.width.pow(D as u32)
    }

    fn stencil_width(&self) -> usize {
        self.width
    }

    fn stencil_origin(&self, xi: &Vector<D>) -> [i64; D] {
        std::array::from_fn(|a| self.first_node(xi[a]))
    }

    fn ghost_layers(&self) -> usize {
        self.support.ceil() as usize + 1
    }

    fn apic_inertia(&self, _cell_size: f64) -> Option<f64> {
        None
    }

    fn reproduction_order(&self) -> u32 {
        self.order
    }

    fn is_signed(&self) -> bool {
        self.signed
    }

    /// The Shepard functions of the kernel, `φ_I / Σ_J φ_J`: positive, a partition of unity.
    fn lumping_weights(&self, grid: &Grid<D>, x: &Vector<D>, weights: &mut [f64]) {
        let xi = grid.to_cell_units(x);
        let mut s = 0;
        self.for_each_node(&xi, |_, _, phi, _| {
            weights[s] = phi;
            s += 1;
        });
        weights[s..].fill(0.0);
        let total: f64 = weights.iter().sum();
        weights.iter_mut().for_each(|w| *w /= total);
    }

    fn evaluate(
        &self,
        grid: &Grid<D>,
        x: &Vector<D>,
        nodes: &mut [usize],
        values: &mut [f64],
        gradients: &mut [Vector<D>],
    ) {
        let xi = grid.to_cell_units(x);
        let m = self.basis_len();
        // Derivatives in ξ (cell units) first; divided by h at the end.
        let mut mm = DMatrix::<f64>::zeros(m, m);
        let mut dmm = vec![DMatrix::<f64>::zeros(m, m); D];
        let mut h = DVector::<f64>::zeros(m);
        let mut dh = DVector::<f64>::zeros(m);
        self.for_each_node(&xi, |_, z, phi, dphi| {
            self.basis(z, &mut h);
            mm.ger(phi, &h, &h, 1.0);
            for k in 0..D {
                self.basis_derivative(z, k, &mut dh);
                // ∂_k H = (1/ã) ∂H/∂z_k in cell units.
                let s = phi / self.support;
                dmm[k].ger(s, &dh, &h, 1.0);
                dmm[k].ger(s, &h, &dh, 1.0);
                dmm[k].ger(dphi[k], &h, &h, 1.0);
            }
        });
        let Some(chol) = mm.cholesky() else {
            // Cannot happen for a support that passed the check in `new`; NaN makes the step fail.
            values.fill(f64::NAN);
            gradients.fill(Vector::from_element(f64::NAN));
            nodes.fill(grid.node_index(grid.node_multi_index(0)));
            return;
        };
        let mut h0 = DVector::<f64>::zeros(m);
        h0[0] = 1.0;
        let b = chol.solve(&h0);
        let db: Vec<DVector<f64>> = (0..D).map(|k| -chol.solve(&(&dmm[k] * &b))).collect();

        // Every slot gets a node; slots past the nonzero ones repeat a valid node with zero weight.
        let mut s = 0;
        let inv_h = 1.0 / grid.cell_size;
        self.for_each_node(&xi, |idx, z, phi, dphi| {
            self.basis(z, &mut h);
            let bh = b.dot(&h);
            nodes[s] = grid.node_index(idx);
            values[s] = bh * phi;
            gradients[s] = Vector::<D>::from_fn(|k, _| {
                self.basis_derivative(z, k, &mut dh);
                (db[k].dot(&h) * phi + b.dot(&dh) / self.support * phi + bh * dphi[k]) * inv_h
            });
            s += 1;
        });
        for k in s..nodes.len() {
            nodes[k] = nodes[0];
            values[k] = 0.0;
            gradients[k] = Vector::zeros();
        }
    }
}
