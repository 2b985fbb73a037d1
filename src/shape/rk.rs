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

/// Stencil nodes per axis at most (support ã ≤ 8).
const MAX_WIDTH: usize = 17;

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
        let inv_a = 1.0 / self.support;
        let inv_h = 1.0 / grid.cell_size;
        SCRATCH.with(|cell| {
            let mut guard = cell.borrow_mut();
            let sc = &mut *guard;
            sc.prepare(m, D, nodes.len());
            // Pass 1: the kernel nodes with their H(z), ∂H/∂z_k, φ and ∂φ/∂ξ (cell units), and
            // the moment matrix M = Σ φ H Hᵀ (upper triangle, then mirrored).
            let mut count = 0;
            self.for_each_node(&xi, |idx, z, phi, dphi| {
                let h = &mut sc.h[count * m..(count + 1) * m];
                self.basis.values(z, h);
                for k in 0..D {
                    let dh = &mut sc.dh[(count * D + k) * m..(count * D + k + 1) * m];
                    self.basis.derivatives(z, k, dh);
                }
                for (i, row) in sc.moment.chunks_exact_mut(m).enumerate() {
                    let phi_hi = phi * h[i];
                    for (mij, hj) in row[i..].iter_mut().zip(&h[i..]) {
                        *mij += phi_hi * hj;
                    }
                }
                sc.phi[count] = phi;
                sc.dphi[count * D..(count + 1) * D].copy_from_slice(dphi.as_slice());
                nodes[count] = grid.node_index(idx);
                count += 1;
            });
            for i in 0..m {
                for j in 0..i {
                    sc.moment[i * m + j] = sc.moment[j * m + i];
                }
            }
            if !cholesky_in_place(&mut sc.moment, m) {
                // Cannot happen for a support that passed the check in `new`; NaN makes the step
                // fail.
                values.fill(f64::NAN);
                gradients.fill(Vector::from_element(f64::NAN));
                nodes.fill(grid.node_index(grid.node_multi_index(0)));
                return;
            }
            // b = M⁻¹ H(0); ∂_k b = −M⁻¹ (∂_k M) b with
            // (∂_k M) b = Σ [∂_k φ H (H·b) + φ/ã (∂H/∂z_k (H·b) + H (∂H/∂z_k · b))].
            let (b, db) = (&mut sc.b, &mut sc.db);
            b[0] = 1.0;
            cholesky_solve(&sc.moment, m, b);
            for i in 0..count {
                let h = &sc.h[i * m..(i + 1) * m];
                let hb = dot(h, b);
                sc.hb[i] = hb;
                for k in 0..D {
                    let dh = &sc.dh[(i * D + k) * m..(i * D + k + 1) * m];
                    let dhb = dot(dh, b);
                    sc.dhb[i * D + k] = dhb;
                    let (phi, dphi) = (sc.phi[i], sc.dphi[i * D + k]);
                    let out = &mut db[k * m..(k + 1) * m];
                    for j in 0..m {
                        out[j] -= dphi * h[j] * hb + phi * inv_a * (dh[j] * hb + h[j] * dhb);
                    }
                }
            }
            for k in 0..D {
                cholesky_solve(&sc.moment, m, &mut db[k * m..(k + 1) * m]);
            }
            // Pass 2: Ψ_I = φ (b·H), ∂_k Ψ_I = (φ (∂_k b·H) + φ/ã (b·∂H/∂z_k) + ∂_k φ (b·H)) / h.
            for i in 0..count {
                let h = &sc.h[i * m..(i + 1) * m];
                let (phi, hb) = (sc.phi[i], sc.hb[i]);
                values[i] = hb * phi;
                gradients[i] = Vector::<D>::from_fn(|k, _| {
                    let dbh = dot(&db[k * m..(k + 1) * m], h);
                    (dbh * phi + sc.dhb[i * D + k] * inv_a * phi + hb * sc.dphi[i * D + k]) * inv_h
                });
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
/// nothing once a thread has seen the largest stencil.
#[derive(Default)]
struct Scratch {
    moment: Vec<f64>,
    b: Vec<f64>,
    /// `∂_k b`, `D` blocks of `m`.
    db: Vec<f64>,
    /// Per kernel node: `H` (m), `∂H/∂z_k` (D × m), `φ`, `∂φ/∂ξ` (D), `H·b`, `∂H/∂z_k · b` (D).
    h: Vec<f64>,
    dh: Vec<f64>,
    phi: Vec<f64>,
    dphi: Vec<f64>,
    hb: Vec<f64>,
    dhb: Vec<f64>,
}

impl Scratch {
    /// Sizes and zeroes the sums for `m` monomials, dimension `d` and `n` stencil nodes.
    fn prepare(&mut self, m: usize, d: usize, n: usize) {
        let zeroed = |v: &mut Vec<f64>, len: usize| {
            v.clear();
            v.resize(len, 0.0);
        };
        zeroed(&mut self.moment, m * m);
        zeroed(&mut self.b, m);
        zeroed(&mut self.db, d * m);
        for (v, len) in [
            (&mut self.h, n * m),
            (&mut self.dh, n * d * m),
            (&mut self.phi, n),
            (&mut self.dphi, n * d),
            (&mut self.hb, n),
            (&mut self.dhb, n * d),
        ] {
            if v.len() < len {
                v.resize(len, 0.0);
            }
        }
    }
}

thread_local! {
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
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
