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

use super::{BSpline, BSplineOrder, Monomials, ShapeFunction};
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

/// Stencil nodes per axis at most (support ã ≤ 8).
const MAX_WIDTH: usize = 17;
/// Highest basis order.
const MAX_ORDER: usize = 5;
/// Powers `z^p` the 1D moment sums need, `p ≤ 2 n`.
const MOMENTS: usize = 2 * MAX_ORDER + 1;

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
        if !(1..=MAX_ORDER as u32).contains(&order) {
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
        crate::floor_index(xi - self.support) + 1
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
        // 1D offsets z and kernel values per axis, then their tensor product.
        let mut first = [0i64; D];
        let mut z1 = [[0.0; MAX_WIDTH]; D];
        let mut k1 = [[(0.0, 0.0); MAX_WIDTH]; D];
        for a in 0..D {
            first[a] = self.first_node(xi[a]);
            for k in 0..w {
                z1[a][k] = (xi[a] - (first[a] + k as i64) as f64) / self.support;
                k1[a][k] = cubic_kernel(z1[a][k]);
            }
        }
        let mut k = [0usize; D];
        for _ in 0..w.pow(D as u32) {
            let mut phi = 1.0;
            for a in 0..D {
                phi *= k1[a][k[a]].0;
            }
            if phi > 0.0 {
                let idx: [i64; D] = std::array::from_fn(|a| first[a] + k[a] as i64);
                let z = Vector::<D>::from_fn(|a, _| z1[a][k[a]]);
                let dphi = Vector::<D>::from_fn(|a, _| {
                    let mut d = 1.0;
                    for b in 0..D {
                        d *= if a == b {
                            k1[b][k[b]].1 / self.support
                        } else {
                            k1[b][k[b]].0
                        };
                    }
                    d
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
}

/// RK of order 1 with normalized support ã = 2. On the grid's full lattice (the ghost layers
/// make it one everywhere) its moment matrix is the same in every cell and the correction is the
/// identity: the functions are the cubic B-spline's (METHOD.md section 2; equal to 1e-13 in
/// `shape/tests.rs`). So they are computed as the B-spline's, with its factored and vectorised
/// stencils, and APIC and MLS take its inertia `D_p = h²/3`: the same step as the cubic
/// B-spline's, but for the RK's ghost layers.
#[derive(Debug, Clone, Copy)]
pub struct LatticeRk1 {
    cubic: BSpline,
}

impl LatticeRk1 {
    pub fn new() -> Self {
        LatticeRk1 {
            cubic: BSpline::new(BSplineOrder::Cubic),
        }
    }
}

impl Default for LatticeRk1 {
    fn default() -> Self {
        Self::new()
    }
}

impl<const D: usize> ShapeFunction<D> for LatticeRk1 {
    fn stencil_len(&self) -> usize {
        ShapeFunction::<D>::stencil_len(&self.cubic)
    }

    fn stencil_width(&self) -> usize {
        ShapeFunction::<D>::stencil_width(&self.cubic)
    }

    fn stencil_origin(&self, xi: &Vector<D>) -> [i64; D] {
        self.cubic.stencil_origin(xi)
    }

    /// As [`ReproducingKernel`] with ã = 2.
    fn ghost_layers(&self) -> usize {
        3
    }

    /// The cubic B-spline's `h²/3`: APIC and MLS transfer the affine velocities as they do for
    /// the cubic B-spline, and so conserve angular momentum (the velocity gradient in its place,
    /// as a general RK function has it, loses 4e-3 of a spinning block's in 100 steps).
    fn apic_inertia(&self, cell_size: f64) -> Option<f64> {
        ShapeFunction::<D>::apic_inertia(&self.cubic, cell_size)
    }

    fn reproduction_order(&self) -> u32 {
        1
    }

    fn tensor_order(&self) -> Option<BSplineOrder> {
        Some(BSplineOrder::Cubic)
    }

    fn evaluate(
        &self,
        grid: &Grid<D>,
        x: &Vector<D>,
        nodes: &mut [usize],
        values: &mut [f64],
        gradients: &mut [Vector<D>],
    ) {
        self.cubic.evaluate(grid, x, nodes, values, gradients)
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

    /// The moment matrix and its derivatives from 1D sums: the kernel is a tensor product and
    /// each monomial a product of powers, so `M_ij = Σ_I φ_I z_I^(e_i + e_j)` is the product over
    /// the axes of `S_a[p] = Σ_k φ_a(z_k) z_k^p`, and `∂_k M_ij` replaces the factor of axis `k`
    /// by `Σ_k ∂(φ_k z_k^p)/∂ξ_k` (`D · W · 2n` terms instead of `W^D · m²`). The stencil's
    /// values and gradients then take one pass over the nodes, with the powers from 1D tables.
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
        let w = self.width;
        let degree = self.order as usize;
        let inv_a = 1.0 / self.support;
        let inv_h = 1.0 / grid.cell_size;
        // Per axis and stencil node: z = (ξ − ξ_k)/ã, φ, ∂φ/∂ξ, and z^p for p ≤ 2n.
        let mut first = [0i64; D];
        let mut kernel = [[(0.0, 0.0); MAX_WIDTH]; D];
        let mut powers = [[[1.0; MOMENTS]; MAX_WIDTH]; D];
        let mut sums = [[0.0; MOMENTS]; D];
        let mut derivative_sums = [[0.0; MOMENTS]; D];
        for a in 0..D {
            first[a] = self.first_node(xi[a]);
            for k in 0..w {
                let z = (xi[a] - (first[a] + k as i64) as f64) / self.support;
                let (phi, dphi) = cubic_kernel(z);
                let dphi = dphi / self.support;
                kernel[a][k] = (phi, dphi);
                let pw = &mut powers[a][k];
                for p in 1..=2 * degree {
                    pw[p] = pw[p - 1] * z;
                }
                for p in 0..=2 * degree {
                    sums[a][p] += phi * pw[p];
                    let lower = if p == 0 {
                        0.0
                    } else {
                        p as f64 * pw[p - 1] * inv_a
                    };
                    derivative_sums[a][p] += dphi * pw[p] + phi * lower;
                }
            }
        }
        let exponents = self.basis.exponents();
        SCRATCH.with(|cell| {
            let mut guard = cell.borrow_mut();
            let sc = &mut *guard;
            sc.prepare(m, D);
            // M and (∂_k M) b, b = M⁻¹ H(0), ∂_k b = −M⁻¹ (∂_k M) b.
            for i in 0..m {
                for j in i..m {
                    let mut mij = 1.0;
                    for a in 0..D {
                        mij *= sums[a][(exponents[i][a] + exponents[j][a]) as usize];
                    }
                    sc.moment[i * m + j] = mij;
                    sc.moment[j * m + i] = mij;
                }
            }
            let (b, db) = (&mut sc.b, &mut sc.db);
            b[0] = 1.0;
            let factored = cholesky_in_place(&mut sc.moment, m);
            if factored {
                cholesky_solve(&sc.moment, m, b);
                for k in 0..D {
                    let out = &mut db[k * m..(k + 1) * m];
                    for i in 0..m {
                        let mut row = 0.0;
                        for j in 0..m {
                            let mut dmij = 1.0;
                            for a in 0..D {
                                let e = (exponents[i][a] + exponents[j][a]) as usize;
                                dmij *= if a == k {
                                    derivative_sums[a][e]
                                } else {
                                    sums[a][e]
                                };
                            }
                            row += dmij * b[j];
                        }
                        out[i] = -row;
                    }
                    cholesky_solve(&sc.moment, m, out);
                }
            }
            if !factored {
                // Cannot happen for a support that passed the check in `new`; NaN makes the step
                // fail.
                values.fill(f64::NAN);
                gradients.fill(Vector::from_element(f64::NAN));
                nodes.fill(grid.node_index(grid.node_multi_index(0)));
                return;
            }
            // Ψ_I = φ (b·H), ∂_k Ψ_I = (φ (∂_k b·H) + φ/ã (b·∂H/∂z_k) + ∂_k φ (b·H)) / h, over
            // the nodes with φ > 0 in the order of `for_each_node` (axis 0 fastest).
            let mut count = 0;
            let mut k = [0usize; D];
            for _ in 0..w.pow(D as u32) {
                let mut phi = 1.0;
                for a in 0..D {
                    phi *= kernel[a][k[a]].0;
                }
                if phi > 0.0 {
                    let (mut hb, mut dbh, mut dhb) = (0.0, [0.0; D], [0.0; D]);
                    for (i, e) in exponents.iter().enumerate() {
                        let mut h = 1.0;
                        for a in 0..D {
                            h *= powers[a][k[a]][e[a] as usize];
                        }
                        hb += h * b[i];
                        for c in 0..D {
                            dbh[c] += h * db[c * m + i];
                            if e[c] > 0 {
                                let mut dh = e[c] as f64 * b[i];
                                for a in 0..D {
                                    dh *= powers[a][k[a]][e[a] as usize - usize::from(a == c)];
                                }
                                dhb[c] += dh;
                            }
                        }
                    }
                    values[count] = hb * phi;
                    gradients[count] = Vector::<D>::from_fn(|c, _| {
                        let mut dphi = kernel[c][k[c]].1;
                        for a in 0..D {
                            if a != c {
                                dphi *= kernel[a][k[a]].0;
                            }
                        }
                        (dbh[c] * phi + dhb[c] * inv_a * phi + hb * dphi) * inv_h
                    });
                    let idx: [i64; D] = std::array::from_fn(|a| first[a] + k[a] as i64);
                    nodes[count] = grid.node_index(idx);
                    count += 1;
                }
                for kk in k.iter_mut() {
                    *kk += 1;
                    if *kk < w {
                        break;
                    }
                    *kk = 0;
                }
            }
            // Every slot gets a node; slots past the nonzero ones repeat a valid node with zero
            // weight.
            for k in count..nodes.len() {
                nodes[k] = nodes[0];
                values[k] = 0.0;
                gradients[k] = Vector::zeros();
            }
        });
    }
}

/// Per-thread scratch of [`ReproducingKernel::evaluate`], so that evaluating a point allocates
/// nothing once a thread has seen the largest basis.
#[derive(Default)]
struct Scratch {
    moment: Vec<f64>,
    b: Vec<f64>,
    /// `∂_k b`, `D` blocks of `m`.
    db: Vec<f64>,
}

impl Scratch {
    /// Sizes and zeroes the sums for `m` monomials in dimension `d`.
    fn prepare(&mut self, m: usize, d: usize) {
        for (v, len) in [
            (&mut self.moment, m * m),
            (&mut self.b, m),
            (&mut self.db, d * m),
        ] {
            v.clear();
            v.resize(len, 0.0);
        }
    }
}

thread_local! {
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// Cholesky factorization `A = L Lᵀ` of the symmetric `m × m` row-major `a`, in place (`L` in
/// the lower triangle). False when `A` is not positive definite.
fn cholesky_in_place(a: &mut [f64], m: usize) -> bool {
    for j in 0..m {
        let mut d = a[j * m + j];
        for k in 0..j {
            d -= a[j * m + k] * a[j * m + k];
        }
        if d.is_nan() || d <= 0.0 {
            return false;
        }
        let l = d.sqrt();
        a[j * m + j] = l;
        for i in j + 1..m {
            let mut s = a[i * m + j];
            for k in 0..j {
                s -= a[i * m + k] * a[j * m + k];
            }
            a[i * m + j] = s / l;
        }
    }
    true
}

/// Solves `L Lᵀ x = r` in place with the factor of [`cholesky_in_place`].
fn cholesky_solve(l: &[f64], m: usize, r: &mut [f64]) {
    for i in 0..m {
        let mut s = r[i];
        for k in 0..i {
            s -= l[i * m + k] * r[k];
        }
        r[i] = s / l[i * m + i];
    }
    for i in (0..m).rev() {
        let mut s = r[i];
        for k in i + 1..m {
            s -= l[k * m + i] * r[k];
        }
        r[i] = s / l[i * m + i];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dot(a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(x, y)| x * y).sum()
    }

    /// The reference evaluation: `M`, `∂M b` and the stencil summed node by node with `H` and
    /// `∂H` per node.
    fn evaluate_by_node_sums<const D: usize>(
        rk: &ReproducingKernel<D>,
        grid: &Grid<D>,
        x: &Vector<D>,
    ) -> (Vec<usize>, Vec<f64>, Vec<Vector<D>>) {
        let xi = grid.to_cell_units(x);
        let m = rk.basis_len();
        let (inv_a, inv_h) = (1.0 / rk.support, 1.0 / grid.cell_size);
        let (mut nodes, mut hs, mut dhs, mut phis, mut dphis) =
            (vec![], vec![], vec![], vec![], vec![]);
        let mut moment = DMatrix::<f64>::zeros(m, m);
        rk.for_each_node(&xi, |idx, z, phi, dphi| {
            let mut h = vec![0.0; m];
            rk.basis.values(z, &mut h);
            let dh: Vec<Vec<f64>> = (0..D)
                .map(|k| {
                    let mut d = vec![0.0; m];
                    rk.basis.derivatives(z, k, &mut d);
                    d
                })
                .collect();
            for i in 0..m {
                for j in 0..m {
                    moment[(i, j)] += phi * h[i] * h[j];
                }
            }
            nodes.push(grid.node_index(idx));
            hs.push(h);
            dhs.push(dh);
            phis.push(phi);
            dphis.push(*dphi);
        });
        let chol = moment.cholesky().expect("positive definite");
        let mut e0 = DVector::zeros(m);
        e0[0] = 1.0;
        let b = chol.solve(&e0);
        let db: Vec<DVector<f64>> = (0..D)
            .map(|k| {
                let mut r = DVector::zeros(m);
                for i in 0..nodes.len() {
                    let (h, dh) = (&hs[i], &dhs[i][k]);
                    let (hb, dhb) = (dot(h, b.as_slice()), dot(dh, b.as_slice()));
                    for j in 0..m {
                        r[j] -=
                            dphis[i][k] * h[j] * hb + phis[i] * inv_a * (dh[j] * hb + h[j] * dhb);
                    }
                }
                chol.solve(&r)
            })
            .collect();
        let values = (0..nodes.len())
            .map(|i| phis[i] * dot(&hs[i], b.as_slice()))
            .collect();
        let gradients = (0..nodes.len())
            .map(|i| {
                let hb = dot(&hs[i], b.as_slice());
                Vector::<D>::from_fn(|k, _| {
                    (dot(db[k].as_slice(), &hs[i]) * phis[i]
                        + dot(&dhs[i][k], b.as_slice()) * inv_a * phis[i]
                        + hb * dphis[i][k])
                        * inv_h
                })
            })
            .collect();
        (nodes, values, gradients)
    }

    fn compare<const D: usize>(order: u32, support: f64) {
        let rk = ReproducingKernel::<D>::new(order, support).unwrap();
        let mut grid = Grid::<D>::new(Vector::<D>::zeros(), [4; D], 0.25).unwrap();
        grid.set_ghost_layers(rk.ghost_layers()).unwrap();
        let len = rk.stencil_len();
        let (mut n, mut w, mut g) = (
            vec![0; len],
            vec![0.0; len],
            vec![Vector::<D>::zeros(); len],
        );
        let mut r = 0.123_f64;
        for _ in 0..40 {
            let x = Vector::<D>::from_fn(|_, _| {
                r = (r * 7919.0 + 0.3719).fract();
                r
            });
            rk.evaluate(&grid, &x, &mut n, &mut w, &mut g);
            let (rn, rw, rg) = evaluate_by_node_sums(&rk, &grid, &x);
            assert_eq!(&n[..rn.len()], &rn[..]);
            assert!(w[rn.len()..].iter().all(|&v| v == 0.0));
            for i in 0..rn.len() {
                assert!(
                    (w[i] - rw[i]).abs() < 1e-13,
                    "{order} {support} {x}: Ψ {} vs {}",
                    w[i],
                    rw[i]
                );
                // Gradients are O(1/h) = O(4); relative to that, round-off of the solves.
                assert!(
                    (g[i] - rg[i]).norm() < 1e-12,
                    "{order} {support} {x}: ∇Ψ {} vs {}",
                    g[i],
                    rg[i]
                );
            }
        }
    }

    /// The 1D-moment evaluation gives the node-by-node sums' values and gradients to round-off
    /// (measured: at most about 1e-15 for Ψ), for orders 1–3 in 2D and 1–2 in 3D.
    #[test]
    fn tensor_moments_equal_the_node_by_node_sums() {
        for (order, support) in [(1, 2.0), (1, 1.5), (2, 3.0), (3, 3.0)] {
            compare::<2>(order, support);
        }
        for (order, support) in [(1, 2.0), (2, 2.5)] {
            compare::<3>(order, support);
        }
    }
}
