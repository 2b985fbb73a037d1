//! Shape-function values and gradients of every particle, computed once per step and read by
//! every phase through one interface, [`StencilView`]:
//!
//! * [`Stencils`] stores `(node, Ψ, ∇Ψ)` for every stencil node: any shape function (RK, and
//!   every shape under VC integration, which needs the stored lists).
//! * [`TensorStencils`] stores only the 1D factors of a tensor-product B-spline (first node,
//!   `D × W` values and derivatives) and forms `Ψ` and `∇Ψ` as products while a phase visits the
//!   nodes: about 1/3 (2D) to 1/7 (3D) of the bytes per particle, and the same bits as
//!   [`Stencils`] for the same shape.

use super::bspline::{tensor_product, BSpline};
use super::ShapeFunction;
use crate::grid::Grid;
use crate::Vector;
use rayon::prelude::*;

/// One node of a particle's stencil as a phase sees it.
#[derive(Debug, Clone, Copy)]
pub struct StencilNode<const D: usize> {
    /// Storage index of the node.
    pub node: usize,
    /// `Ψ_I(x_p)`.
    pub value: f64,
    /// `∇Ψ_I(x_p)`.
    pub gradient: Vector<D>,
}

/// The stencils of all particles of a step, visited node by node.
pub trait StencilView<const D: usize>: Sync {
    /// Calls `f(s, node)` for every slot `s` of the stencil of particle `p` (slots may have zero
    /// value and gradient).
    fn for_each(&self, p: usize, f: impl FnMut(usize, StencilNode<D>));

    /// `x_I − x_p` for the node of slot `s` of particle `p` at `x_p` (APIC).
    fn offset(&self, grid: &Grid<D>, p: usize, s: usize, node: usize, xp: &Vector<D>) -> Vector<D>;

    /// [`StencilView::for_each`] with `x_I − x_p` as the third argument when `xp` is given
    /// (the same bits as [`StencilView::offset`]; zero without `xp`).
    #[inline(always)]
    fn for_each_with_offset(
        &self,
        grid: &Grid<D>,
        p: usize,
        xp: Option<&Vector<D>>,
        mut f: impl FnMut(usize, StencilNode<D>, Vector<D>),
    ) {
        self.for_each(p, |s, node| {
            let offset = match xp {
                Some(xp) => self.offset(grid, p, s, node.node, xp),
                None => Vector::zeros(),
            };
            f(s, node, offset)
        });
    }
}

/// Shape-function values and gradients of every particle, stored node by node.
#[derive(Debug, Default, Clone)]
pub struct Stencils<const D: usize> {
    pub len: usize,
    pub nodes: Vec<usize>,
    pub values: Vec<f64>,
    pub gradients: Vec<Vector<D>>,
    /// Nonnegative lumping weights (same layout as `values`), only for signed shape functions;
    /// empty otherwise.
    pub lumping: Vec<f64>,
}

impl<const D: usize> Stencils<D> {
    /// Evaluates `shape` at every position (in parallel; each particle is independent).
    pub fn compute(&mut self, shape: &dyn ShapeFunction<D>, grid: &Grid<D>, x: &[Vector<D>]) {
        let len = shape.stencil_len();
        self.len = len;
        let total = len * x.len();
        self.nodes.resize(total, 0);
        self.values.resize(total, 0.0);
        self.gradients.resize(total, Vector::zeros());
        self.nodes
            .par_chunks_mut(len)
            .zip(self.values.par_chunks_mut(len))
            .zip(self.gradients.par_chunks_mut(len))
            .zip(x.par_iter())
            .for_each(|(((n, w), g), xp)| shape.evaluate(grid, xp, n, w, g));
        if shape.is_signed() {
            self.lumping.resize(total, 0.0);
            self.lumping
                .par_chunks_mut(len)
                .zip(x.par_iter())
                .for_each(|(l, xp)| shape.lumping_weights(grid, xp, l));
        } else {
            self.lumping.clear();
        }
    }

    /// Frees the storage (when a step uses [`TensorStencils`] instead).
    pub fn release(&mut self) {
        *self = Stencils::default();
    }

    /// The lumping weights of particle `p`, when the shape function is signed.
    #[inline]
    pub fn lumping_of(&self, p: usize) -> Option<&[f64]> {
        (!self.lumping.is_empty()).then(|| &self.lumping[p * self.len..(p + 1) * self.len])
    }

    /// The stencil of particle `p`: node indices, values, gradients.
    #[inline]
    pub fn of(&self, p: usize) -> (&[usize], &[f64], &[Vector<D>]) {
        let r = p * self.len..(p + 1) * self.len;
        (
            &self.nodes[r.clone()],
            &self.values[r.clone()],
            &self.gradients[r],
        )
    }

    /// Bytes allocated.
    pub fn bytes(&self) -> usize {
        self.nodes.capacity() * std::mem::size_of::<usize>()
            + (self.values.capacity() + self.lumping.capacity()) * 8
            + self.gradients.capacity() * std::mem::size_of::<Vector<D>>()
    }
}

impl<const D: usize> StencilView<D> for Stencils<D> {
    #[inline(always)]
    fn for_each(&self, p: usize, mut f: impl FnMut(usize, StencilNode<D>)) {
        let (ns, ws, gs) = self.of(p);
        for s in 0..ns.len() {
            f(
                s,
                StencilNode {
                    node: ns[s],
                    value: ws[s],
                    gradient: gs[s],
                },
            );
        }
    }

    #[inline(always)]
    fn offset(
        &self,
        grid: &Grid<D>,
        _p: usize,
        _s: usize,
        node: usize,
        xp: &Vector<D>,
    ) -> Vector<D> {
        grid.node_position(grid.node_multi_index(node)) - xp
    }
}

/// The stencils of a tensor-product B-spline with `W` nodes per axis, stored as 1D factors.
#[derive(Debug, Clone)]
pub struct TensorStencils<const D: usize, const W: usize> {
    strides: [usize; D],
    origin: Vector<D>,
    cell_size: f64,
    /// Integer index of the first stencil node.
    first: Vec<[i64; D]>,
    /// Storage index of the first stencil node.
    base: Vec<usize>,
    values: Vec<[[f64; W]; D]>,
    derivatives: Vec<[[f64; W]; D]>,
}

impl<const D: usize, const W: usize> Default for TensorStencils<D, W> {
    fn default() -> Self {
        TensorStencils {
            strides: [0; D],
            origin: Vector::zeros(),
            cell_size: 0.0,
            first: Vec::new(),
            base: Vec::new(),
            values: Vec::new(),
            derivatives: Vec::new(),
        }
    }
}

impl<const D: usize, const W: usize> TensorStencils<D, W> {
    /// Evaluates the factors of `shape` (whose width must be `W`) at every position.
    pub fn compute(&mut self, shape: &BSpline, grid: &Grid<D>, x: &[Vector<D>]) {
        assert_eq!(shape.order.width(), W, "tensor stencil width");
        self.strides = std::array::from_fn(|a| {
            let mut e = [0i64; D];
            e[a] = 1;
            grid.node_index(e) - grid.node_index([0; D])
        });
        self.origin = grid.origin;
        self.cell_size = grid.cell_size;
        let n = x.len();
        self.first.resize(n, [0; D]);
        self.base.resize(n, 0);
        self.values.resize(n, [[0.0; W]; D]);
        self.derivatives.resize(n, [[0.0; W]; D]);
        self.first
            .par_iter_mut()
            .zip(self.base.par_iter_mut())
            .zip(self.values.par_iter_mut())
            .zip(self.derivatives.par_iter_mut())
            .zip(x.par_iter())
            .for_each(|((((first, base), w), dw), xp)| {
                let f = shape.factors(grid, xp);
                *first = f.first;
                *base = grid.node_index(f.first);
                for a in 0..D {
                    w[a].copy_from_slice(&f.values[a][..W]);
                    dw[a].copy_from_slice(&f.derivatives[a][..W]);
                }
            });
    }

    /// Bytes allocated.
    pub fn bytes(&self) -> usize {
        self.first.capacity() * 8 * D
            + self.base.capacity() * std::mem::size_of::<usize>()
            + (self.values.capacity() + self.derivatives.capacity()) * 8 * D * W
    }
}

impl<const D: usize, const W: usize> TensorStencils<D, W> {
    /// Visits the stencil of particle `p`, with `x_I − x_p` when `xp` is given (zero otherwise).
    #[inline(always)]
    fn visit(
        &self,
        p: usize,
        xp: Option<&Vector<D>>,
        mut f: impl FnMut(usize, StencilNode<D>, Vector<D>),
    ) {
        let (base, w, dw) = (self.base[p], &self.values[p], &self.derivatives[p]);
        // 1D offsets per axis, as `Grid::node_position` forms them, so that both views give
        // the same bits.
        let mut offsets = [[0.0; W]; D];
        if let Some(xp) = xp {
            let first = &self.first[p];
            for (a, o) in offsets.iter_mut().enumerate() {
                for (k, o) in o.iter_mut().enumerate() {
                    *o = self.origin[a] + (first[a] + k as i64) as f64 * self.cell_size - xp[a];
                }
            }
        }
        // Same slot order as `ShapeFunction::evaluate`: axis 0 fastest.
        let mut k = [0usize; D];
        let mut node = base;
        for s in 0..W.pow(D as u32) {
            let (value, gradient) = tensor_product(w, dw, &k);
            let offset = Vector::<D>::from_fn(|a, _| offsets[a][k[a]]);
            f(
                s,
                StencilNode {
                    node,
                    value,
                    gradient,
                },
                offset,
            );
            for (ka, stride) in k.iter_mut().zip(self.strides) {
                *ka += 1;
                node += stride;
                if *ka < W {
                    break;
                }
                *ka = 0;
                node -= W * stride;
            }
        }
    }
}

impl<const D: usize, const W: usize> StencilView<D> for TensorStencils<D, W> {
    #[inline(always)]
    fn for_each(&self, p: usize, mut f: impl FnMut(usize, StencilNode<D>)) {
        self.visit(p, None, |s, node, _| f(s, node));
    }

    #[inline(always)]
    fn for_each_with_offset(
        &self,
        _grid: &Grid<D>,
        p: usize,
        xp: Option<&Vector<D>>,
        f: impl FnMut(usize, StencilNode<D>, Vector<D>),
    ) {
        self.visit(p, xp, f);
    }

    #[inline(always)]
    fn offset(
        &self,
        _grid: &Grid<D>,
        p: usize,
        s: usize,
        _node: usize,
        xp: &Vector<D>,
    ) -> Vector<D> {
        // As `Grid::node_position`, so that both views give the same bits.
        let first = &self.first[p];
        let mut r = s;
        Vector::<D>::from_fn(|a, _| {
            let k = (r % W) as i64;
            r /= W;
            self.origin[a] + (first[a] + k) as f64 * self.cell_size - xp[a]
        })
    }
}
