//! Tensor-product B-splines on the grid nodes: linear hats, quadratic and cubic B-splines.

use super::ShapeFunction;
use crate::grid::Grid;
use crate::Vector;

/// Polynomial order of a grid B-spline.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BSplineOrder {
    Linear,
    Quadratic,
    Cubic,
}

impl BSplineOrder {
    /// Nodes per axis in the stencil.
    pub fn width(self) -> usize {
        match self {
            BSplineOrder::Linear => 2,
            BSplineOrder::Quadratic => 3,
            BSplineOrder::Cubic => 4,
        }
    }

    /// First stencil node (integer index along one axis) for a point at `xi` cell units.
    #[inline]
    fn first_node(self, xi: f64) -> i64 {
        match self {
            BSplineOrder::Linear => crate::floor_index(xi),
            BSplineOrder::Quadratic => crate::floor_index(xi - 0.5),
            BSplineOrder::Cubic => crate::floor_index(xi) - 1,
        }
    }
}

/// The 1D factors of a tensor-product B-spline at one point: the stencil's first node and, per
/// axis, the values and derivatives (per length) at its `width ≤ 4` nodes. `Ψ` and `∇Ψ` at stencil
/// node `first + k` are products of them ([`Factors::at`]).
#[derive(Debug, Clone, Copy)]
pub struct Factors<const D: usize> {
    pub first: [i64; D],
    pub values: [[f64; 4]; D],
    pub derivatives: [[f64; 4]; D],
}

impl<const D: usize> Factors<D> {
    /// `(Ψ, ∇Ψ)` at the stencil node `first + k`, multiplied in axis order (so that every path
    /// that uses the factors gives the same bits).
    #[inline(always)]
    pub fn at(&self, k: &[usize; D]) -> (f64, Vector<D>) {
        tensor_product(&self.values, &self.derivatives, k)
    }
}

/// `(Π_a w_a[k_a], (Π_b (b = a ? dw_b : w_b)[k_b])_a)`, multiplied in axis order.
#[inline(always)]
pub(crate) fn tensor_product<const D: usize, const W: usize>(
    w: &[[f64; W]; D],
    dw: &[[f64; W]; D],
    k: &[usize; D],
) -> (f64, Vector<D>) {
    let mut value = 1.0;
    for a in 0..D {
        value *= w[a][k[a]];
    }
    let grad = Vector::<D>::from_fn(|a, _| {
        let mut g = 1.0;
        for b in 0..D {
            g *= if a == b { dw[b][k[b]] } else { w[b][k[b]] };
        }
        g
    });
    (value, grad)
}

/// A tensor-product B-spline shape function of the given order.
#[derive(Debug, Clone, Copy)]
pub struct BSpline {
    pub order: BSplineOrder,
}

impl BSpline {
    pub fn new(order: BSplineOrder) -> Self {
        BSpline { order }
    }
}

impl BSpline {
    /// The 1D factors of the stencil of `x` (inside the domain of `grid`).
    #[inline(always)]
    pub fn factors<const D: usize>(&self, grid: &Grid<D>, x: &Vector<D>) -> Factors<D> {
        let mut f = Factors {
            first: [0; D],
            values: [[0.0; 4]; D],
            derivatives: [[0.0; 4]; D],
        };
        let width = self.order.width();
        let xi = grid.to_cell_units(x);
        let inv_h = 1.0 / grid.cell_size;
        for a in 0..D {
            f.first[a] = self.order.first_node(xi[a]);
            let t = xi[a] - f.first[a] as f64;
            axis_factors(
                self.order,
                t,
                inv_h,
                &mut f.values[a][..width],
                &mut f.derivatives[a][..width],
            );
        }
        f
    }

    /// [`BSpline::factors`] written straight into a stencil's storage (`W` = the width): the
    /// first node, the values and, when `derivatives` is given, the derivatives. The same
    /// arithmetic, so the same bits.
    #[inline(always)]
    pub fn factors_into<const D: usize, const W: usize>(
        &self,
        grid: &Grid<D>,
        x: &Vector<D>,
        first: &mut [i64; D],
        values: &mut [[f64; W]; D],
        mut derivatives: Option<&mut [[f64; W]; D]>,
    ) {
        let xi = grid.to_cell_units(x);
        let inv_h = 1.0 / grid.cell_size;
        for a in 0..D {
            first[a] = self.order.first_node(xi[a]);
            let t = xi[a] - first[a] as f64;
            let mut scratch = [0.0; W];
            let dw = match derivatives.as_mut() {
                Some(d) => &mut d[a],
                None => &mut scratch,
            };
            axis_factors(self.order, t, inv_h, &mut values[a], dw);
        }
    }
}

/// The 1D factors along one axis at `t` cells from the first stencil node: the kernel at
/// `t − k` in closed form (the branches of `BSplineOrder::kernel` are known from the range of
/// `t`) into `w`, its derivative times `inv_h` into `dw`.
#[inline(always)]
fn axis_factors(order: BSplineOrder, t: f64, inv_h: f64, w: &mut [f64], dw: &mut [f64]) {
    match order {
        BSplineOrder::Linear => {
            // The two nodes of the cell, with the cell's one-sided gradient also on a node.
            // t ∈ [0, 1].
            (w[0], w[1]) = (1.0 - t, t);
            (dw[0], dw[1]) = (-1.0, 1.0);
        }
        BSplineOrder::Quadratic => {
            // t ∈ [0.5, 1.5).
            let (u, c, l) = (1.5 - t, t - 1.0, t - 0.5);
            (w[0], w[1], w[2]) = (0.5 * u * u, 0.75 - c * c, 0.5 * l * l);
            (dw[0], dw[1], dw[2]) = (-u, -2.0 * c, l);
        }
        BSplineOrder::Cubic => {
            // t ∈ [1, 2): distances t, t − 1, 2 − t (mirrored) and 3 − t from the nodes.
            let (u, r1, r2, l) = (2.0 - t, t - 1.0, 2.0 - t, t - 1.0);
            let inner = |r: f64| (0.5 * r * r * r - r * r + 2.0 / 3.0, 1.5 * r * r - 2.0 * r);
            let ((w1, d1), (w2, d2)) = (inner(r1), inner(r2));
            (w[0], w[1], w[2], w[3]) = (u * u * u / 6.0, w1, w2, l * l * l / 6.0);
            (dw[0], dw[1], dw[2], dw[3]) = (-0.5 * u * u, d1, -d2, 0.5 * l * l);
        }
    }
    for d in dw.iter_mut() {
        *d *= inv_h;
    }
}

impl<const D: usize> ShapeFunction<D> for BSpline {
    fn stencil_len(&self) -> usize {
        self.order.width().pow(D as u32)
    }

    fn ghost_layers(&self) -> usize {
        // The stencil of a point on the upper face reaches `width - 1` nodes past it at most.
        match self.order {
            BSplineOrder::Linear => 1,
            BSplineOrder::Quadratic | BSplineOrder::Cubic => 2,
        }
    }

    fn apic_inertia(&self, h: f64) -> Option<f64> {
        match self.order {
            BSplineOrder::Linear => None,
            BSplineOrder::Quadratic => Some(h * h / 4.0),
            BSplineOrder::Cubic => Some(h * h / 3.0),
        }
    }

    fn reproduction_order(&self) -> u32 {
        1
    }

    fn tensor_order(&self) -> Option<BSplineOrder> {
        Some(self.order)
    }

    fn stencil_width(&self) -> usize {
        self.order.width()
    }

    fn stencil_origin(&self, xi: &Vector<D>) -> [i64; D] {
        std::array::from_fn(|a| self.order.first_node(xi[a]))
    }

    fn evaluate(
        &self,
        grid: &Grid<D>,
        x: &Vector<D>,
        nodes: &mut [usize],
        values: &mut [f64],
        gradients: &mut [Vector<D>],
    ) {
        let width = self.order.width();
        let f = self.factors(grid, x);
        let mut k = [0usize; D];
        for s in 0..nodes.len() {
            nodes[s] = grid.node_index(std::array::from_fn(|a| f.first[a] + k[a] as i64));
            (values[s], gradients[s]) = f.at(&k);
            for kk in k.iter_mut() {
                *kk += 1;
                if *kk < width {
                    break;
                }
                *kk = 0;
            }
        }
    }
}
