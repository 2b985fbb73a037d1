//! Shape-function values and gradients of every particle, computed once per step and read by
//! every phase through one interface, [`StencilView`]:
//!
//! * [`Stencils`] stores `(node, Ψ, ∇Ψ)` for every stencil node: any shape function (RK, and
//!   every shape under VC integration, which needs the stored lists).
//! * [`TensorStencils`] stores only the 1D factors of a tensor-product B-spline (first node,
//!   `D × W` values and derivatives) and forms `Ψ` and `∇Ψ` as products while a phase visits the
//!   nodes: about 1/3 (2D) to 1/7 (3D) of the bytes per particle, with the same `Ψ` and `∇Ψ`
//!   bits as [`Stencils`] for the same shape. Its scatter and gather factor the sums row by row
//!   ([`StencilView::scatter`], [`StencilView::gather`]), which agree with the node-by-node sums
//!   to round-off.

use super::bspline::{tensor_product, BSpline};
use super::ShapeFunction;
use crate::cpu::Lanes;
use crate::grid::BlockLayout;
use crate::grid::{scatter_add, Grid, NodeScatter};
use crate::{Matrix, Vector};
use rayon::prelude::*;

impl<const D: usize> Gathered<D> {
    /// All sums zero.
    #[inline(always)]
    pub fn zero() -> Self {
        Gathered {
            velocity: Vector::zeros(),
            velocity_change: Vector::zeros(),
            affine: Matrix::zeros(),
            gradient: Matrix::zeros(),
        }
    }
}

/// What one particle scatters to the nodes of its stencil (particle to grid).
#[derive(Debug, Clone, Copy)]
pub struct ScatterInput<'a, const D: usize> {
    pub position: Vector<D>,
    pub mass: f64,
    /// `m v`.
    pub momentum: Vector<D>,
    /// `m C` under APIC.
    pub affine: Option<Matrix<D>>,
    /// Map the mass too (the first map of a step).
    pub with_mass: bool,
    /// `−V σ` and the body acceleration `b`, when the force is mapped too (not under MLS, whose
    /// force rides on the momentum).
    pub force: Option<(Matrix<D>, Vector<D>)>,
    /// Add `m Ψ b` (there is gravity or a body-force callback).
    pub with_body_force: bool,
    /// The body force goes to `body_force`, apart from `force`.
    pub keep_body_force: bool,
    /// Add `m ∇Ψ` to `mass_gradient` (contact).
    pub with_gradient: bool,
    /// With the force, VC's order-1 correction with the mean fit: its coefficients `ζ` by grid
    /// node (valid at the stencil's nodes of nonzero `Ψ`). The force then adds
    /// `−V σ (ζ_I − μ_p) |Ψ_I|`, `μ_p = Σ_I |Ψ_I| ζ_I / Σ_I |Ψ_I|` over the stencil, after the
    /// rest of the node's force
    /// ([`crate::integration::VcCorrection::mean_fit_coefficients`]).
    pub mean_fit: Option<&'a [Vector<D>]>,
}

/// The sums grid to particle takes over a particle's stencil.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gathered<const D: usize> {
    /// `Σ Ψ_I v_I`.
    pub velocity: Vector<D>,
    /// `Σ Ψ_I (v_I − v_I^old)` (FLIP; zero otherwise).
    pub velocity_change: Vector<D>,
    /// `Σ Ψ_I v_I (x_I − x_p)ᵀ` (APIC with a constant inertia; zero otherwise).
    pub affine: Matrix<D>,
    /// `Σ v_I ∇Ψ_Iᵀ`, the velocity gradient.
    pub gradient: Matrix<D>,
}

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

impl<const D: usize> StencilNode<D> {
    /// Whether the node is in the particle's support: its value or its gradient is not zero.
    #[inline(always)]
    pub fn in_support(&self) -> bool {
        in_support(self.value, &self.gradient)
    }
}

/// Whether a node with value `w` and gradient `g` at a particle is in its support.
#[inline(always)]
pub fn in_support<const D: usize>(w: f64, g: &Vector<D>) -> bool {
    w != 0.0 || *g != Vector::<D>::zeros()
}

/// The stencils of all particles of a step, visited node by node.
pub trait StencilView<const D: usize>: Sync {
    /// The view as plain values (slices and scalars) that a phase copies into each parallel
    /// task: held in registers, they are not reloaded after every store to the grid, which the
    /// compiler cannot prove leaves them alone.
    type Local<'a>: StencilView<D> + Copy
    where
        Self: 'a;

    /// See [`StencilView::Local`].
    fn local(&self) -> Self::Local<'_>;

    /// The instruction set of the loops that read these stencils.
    fn lanes(&self) -> Lanes;

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

    /// Scatters particle `p` to the nodes of its stencil in a factored form and returns true, or
    /// returns false when the view has none (the caller then visits node by node). Only for
    /// unsigned shape functions without VC.
    ///
    /// # Safety
    /// As [`NodeScatter`]: no other thread writes the nodes of this stencil meanwhile.
    #[inline(always)]
    unsafe fn scatter(
        &self,
        _p: usize,
        _input: &ScatterInput<'_, D>,
        _out: &NodeScatter<D>,
    ) -> bool {
        false
    }

    /// The grid-to-particle sums of particle `p` at `x_p` from the node velocities `v` (and
    /// `v_old` for FLIP); the `affine` and `gradient` sums only when asked for (zero otherwise).
    /// Node by node here; a view may factor the sums (tensor-product stencils do, row by row).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn gather(
        &self,
        grid: &Grid<D>,
        p: usize,
        xp: &Vector<D>,
        v: &[Vector<D>],
        v_old: Option<&[Vector<D>]>,
        affine: bool,
        gradient: bool,
    ) -> Gathered<D> {
        gather_node_by_node(self, grid, p, xp, v, v_old, affine, gradient)
    }

    /// The stencils' 1D factors, when they are a tensor product stored as such (B-splines on
    /// the lattice): sums over pairs of a stencil's nodes can then be formed per axis.
    fn tensor_factors(&self) -> Option<TensorFactors<'_, D>> {
        None
    }
}

/// A tensor-product stencil as its 1D factors, without its width in the type: what VC's
/// assembly reads ([`StencilView::tensor_factors`]). Particle `p`'s stencil is the box of
/// `width^D` nodes from [`TensorFactors::base`], axis 0 fastest (the slot order of the stored
/// lists), and its value at the node `k` of the box is `Π_a w_a[k_a]`, the product taken in
/// ascending axis order as [`tensor_product`] takes it.
#[derive(Debug, Clone, Copy)]
pub struct TensorFactors<'a, const D: usize> {
    /// Nodes per axis.
    pub width: usize,
    /// Storage steps of the node index along each axis.
    pub strides: [usize; D],
    zero_index: usize,
    first: &'a [[i32; D]],
    /// Per particle `D × width` values, axis by axis.
    values: &'a [f64],
    /// As `values`, the derivatives (per unit length); empty when not computed.
    derivatives: &'a [f64],
}

impl<const D: usize> TensorFactors<'_, D> {
    /// The storage index of particle `p`'s first stencil node.
    #[inline(always)]
    pub fn base(&self, p: usize) -> usize {
        let mut n = self.zero_index as i64;
        for (&i, &stride) in self.first[p].iter().zip(&self.strides) {
            n += i64::from(i) * stride as i64;
        }
        n as usize
    }

    /// Particle `p`'s factors, `values[a · width + k]`.
    #[inline(always)]
    pub fn values(&self, p: usize) -> &[f64] {
        let n = D * self.width;
        &self.values[p * n..(p + 1) * n]
    }

    /// Particle `p`'s derivative factors, as [`TensorFactors::values`].
    #[inline(always)]
    pub fn derivatives(&self, p: usize) -> &[f64] {
        let n = D * self.width;
        &self.derivatives[p * n..(p + 1) * n]
    }

    /// Calls `f(node)` for the nodes of particle `p`'s stencil in its support, in slot order,
    /// with the value and gradient the stored lists hold ([`Stencils::fill_from_factors`]: the
    /// products of [`tensor_product`], the same bits), computed from the factors instead of
    /// read from the lists.
    #[inline(always)]
    pub fn for_each_in_support(&self, p: usize, f: impl FnMut(StencilNode<D>)) {
        match self.width {
            2 => self.visit::<2>(p, f),
            3 => self.visit::<3>(p, f),
            4 => self.visit::<4>(p, f),
            w => unreachable!("B-spline stencils of width {w}"),
        }
    }

    /// Calls `f(node, value)` for the nodes of particle `p`'s stencil where the value is not
    /// zero, in slot order, with the value of [`TensorFactors::for_each_in_support`] (the same
    /// bits) and no gradient computed.
    #[inline(always)]
    pub fn for_each_value(&self, p: usize, f: impl FnMut(usize, f64)) {
        match self.width {
            2 => self.visit_values::<2>(p, f),
            3 => self.visit_values::<3>(p, f),
            4 => self.visit_values::<4>(p, f),
            w => unreachable!("B-spline stencils of width {w}"),
        }
    }

    #[inline(always)]
    fn visit_values<const W: usize>(&self, p: usize, mut f: impl FnMut(usize, f64)) {
        let v = self.values(p);
        let w: [[f64; W]; D] = std::array::from_fn(|a| std::array::from_fn(|k| v[a * W + k]));
        let mut k = [0usize; D];
        let mut node = self.base(p);
        for _ in 0..W.pow(D as u32) {
            // As `tensor_product` takes it: in ascending axis order, from one.
            let mut value = 1.0;
            for a in 0..D {
                value *= w[a][k[a]];
            }
            if value != 0.0 {
                f(node, value);
            }
            next_in_box::<D, W>(&mut k, &mut node, &self.strides);
        }
    }

    #[inline(always)]
    fn visit<const W: usize>(&self, p: usize, mut f: impl FnMut(StencilNode<D>)) {
        let factors = |v: &[f64]| -> [[f64; W]; D] {
            std::array::from_fn(|a| std::array::from_fn(|k| v[a * W + k]))
        };
        let (w, dw) = (factors(self.values(p)), factors(self.derivatives(p)));
        let mut k = [0usize; D];
        let mut node = self.base(p);
        for _ in 0..W.pow(D as u32) {
            let (value, gradient) = tensor_product(&w, &dw, &k);
            if in_support(value, &gradient) {
                f(StencilNode {
                    node,
                    value,
                    gradient,
                });
            }
            next_in_box::<D, W>(&mut k, &mut node, &self.strides);
        }
    }
}

/// The next node of a stencil box in slot order (axis 0 fastest): its multi-index `k` in the
/// box and its storage index `node`.
#[inline(always)]
fn next_in_box<const D: usize, const W: usize>(
    k: &mut [usize; D],
    node: &mut usize,
    strides: &[usize; D],
) {
    for (ka, stride) in k.iter_mut().zip(strides) {
        *ka += 1;
        *node += stride;
        if *ka < W {
            break;
        }
        *ka = 0;
        *node -= W * stride;
    }
}

/// The nodes in the particles' supports, as the stored lists give them or, for a
/// tensor-product stencil, computed from its factors ([`TensorFactors::for_each_in_support`]:
/// the same nodes, values and gradients, in the same order): the passes over the stencils that
/// VC takes read the factors where there are some, a fraction of the lists' bytes.
#[derive(Debug, Clone, Copy)]
pub struct SupportNodes<'a, const D: usize> {
    pub stored: &'a Stencils<D>,
    pub tensor: Option<TensorFactors<'a, D>>,
}

impl<const D: usize> SupportNodes<'_, D> {
    /// Calls `f(node)` for every node in the support of particle `p`, with the shape
    /// function's own values (not the transfer weights of [`StencilView::for_each`]).
    #[inline(always)]
    pub fn for_each(&self, p: usize, mut f: impl FnMut(StencilNode<D>)) {
        match &self.tensor {
            Some(tensor) => tensor.for_each_in_support(p, f),
            None => self.stored.for_each_shape(p, |_, s| {
                if s.in_support() {
                    f(s)
                }
            }),
        }
    }

    /// Calls `f(node, value)` for every node of particle `p`'s stencil where the shape
    /// function's value is not zero (no gradient computed from factors).
    #[inline(always)]
    pub fn for_each_value(&self, p: usize, mut f: impl FnMut(usize, f64)) {
        match &self.tensor {
            Some(tensor) => tensor.for_each_value(p, f),
            None => {
                let (nodes, values, _) = self.stored.of(p);
                for (&n, &w) in nodes.iter().zip(values) {
                    if w != 0.0 {
                        f(n, w)
                    }
                }
            }
        }
    }
}

/// The grid-to-particle sums of [`StencilView::gather`], node by node.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn gather_node_by_node<const D: usize, S: StencilView<D> + ?Sized>(
    view: &S,
    grid: &Grid<D>,
    p: usize,
    xp: &Vector<D>,
    v: &[Vector<D>],
    v_old: Option<&[Vector<D>]>,
    affine: bool,
    gradient: bool,
) -> Gathered<D> {
    let mut g = Gathered::zero();
    view.for_each_with_offset(grid, p, affine.then_some(xp), |_, node, offset| {
        let (n, w) = (node.node, node.value);
        let vi = v[n];
        g.velocity += w * vi;
        if let Some(v_old) = v_old {
            g.velocity_change += w * (vi - v_old[n]);
        }
        if affine {
            g.affine += (w * vi) * offset.transpose();
        }
        if gradient {
            g.gradient += vi * node.gradient.transpose();
        }
    });
    g
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
    /// The transfer weights of signed shape functions (`step::edge_lumping`), which
    /// [`StencilView::for_each`] gives in place of `values` when they are set; empty otherwise.
    pub transfer: Vec<f64>,
    /// The instruction set of the loops that read these stencils.
    pub lanes: Lanes,
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
        self.transfer.clear();
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

    /// No stencils (what a step that reads only the factors keeps; the storage stays).
    pub fn clear(&mut self) {
        self.len = 0;
        for v in [&mut self.values, &mut self.lumping, &mut self.transfer] {
            v.clear();
        }
        self.nodes.clear();
        self.gradients.clear();
    }

    /// The lists of B-spline stencils of width `W` from their factors (`factors` computed with
    /// derivatives), as [`TensorView`] visits them: the nodes, values and gradients
    /// [`BSpline`]'s `evaluate` gives, the same bits, without evaluating the shape again.
    pub fn fill_from_factors<const W: usize>(&mut self, factors: &TensorStencils<D, W>) {
        assert_eq!(
            factors.derivatives.len(),
            factors.first.len(),
            "factors computed with derivatives"
        );
        let len = W.pow(D as u32);
        self.len = len;
        let total = len * factors.first.len();
        self.nodes.resize(total, 0);
        self.values.resize(total, 0.0);
        self.gradients.resize(total, Vector::zeros());
        let view = factors.local();
        const CHUNK: usize = 256;
        self.nodes
            .par_chunks_mut(len * CHUNK)
            .zip(self.values.par_chunks_mut(len * CHUNK))
            .zip(self.gradients.par_chunks_mut(len * CHUNK))
            .enumerate()
            .for_each(|(c, ((ns, ws), gs))| {
                let particles = (c * CHUNK..).zip(
                    ns.chunks_exact_mut(len)
                        .zip(ws.chunks_exact_mut(len))
                        .zip(gs.chunks_exact_mut(len)),
                );
                for (p, ((ns, ws), gs)) in particles {
                    view.for_each(p, |s, node| {
                        (ns[s], ws[s], gs[s]) = (node.node, node.value, node.gradient);
                    });
                }
            });
        self.transfer.clear();
        self.lumping.clear();
    }

    /// The transfer weights of particle `p`, when they are set (signed shape functions).
    #[inline]
    pub fn transfer_of(&self, p: usize) -> Option<&[f64]> {
        (!self.transfer.is_empty()).then(|| &self.transfer[p * self.len..(p + 1) * self.len])
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

    /// Calls `f(s, node)` for every slot `s` of the stencil of particle `p` with the shape
    /// function's own values `Ψ` (where [`StencilView::for_each`] gives the transfer weights).
    #[inline(always)]
    pub fn for_each_shape(&self, p: usize, f: impl FnMut(usize, StencilNode<D>)) {
        self.visit(p, &self.values, f)
    }

    #[inline(always)]
    fn visit(&self, p: usize, values: &[f64], mut f: impl FnMut(usize, StencilNode<D>)) {
        let r = p * self.len..(p + 1) * self.len;
        let (ns, ws, gs) = (
            &self.nodes[r.clone()],
            &values[r.clone()],
            &self.gradients[r],
        );
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

    /// Bytes allocated.
    pub fn bytes(&self) -> usize {
        self.nodes.capacity() * std::mem::size_of::<usize>()
            + (self.values.capacity() + self.lumping.capacity() + self.transfer.capacity()) * 8
            + self.gradients.capacity() * std::mem::size_of::<Vector<D>>()
    }
}

impl<const D: usize> StencilView<D> for Stencils<D> {
    type Local<'a> = &'a Stencils<D>;

    #[inline(always)]
    fn local(&self) -> &Stencils<D> {
        self
    }

    #[inline(always)]
    fn lanes(&self) -> Lanes {
        self.lanes
    }

    /// The transfer weights when they are set, else `Ψ`.
    #[inline(always)]
    fn for_each(&self, p: usize, f: impl FnMut(usize, StencilNode<D>)) {
        match self.transfer.is_empty() {
            true => self.visit(p, &self.values, f),
            false => self.visit(p, &self.transfer, f),
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

impl<const D: usize> StencilView<D> for &Stencils<D> {
    type Local<'a>
        = Self
    where
        Self: 'a;

    #[inline(always)]
    fn local(&self) -> Self {
        self
    }

    #[inline(always)]
    fn lanes(&self) -> Lanes {
        self.lanes
    }

    #[inline(always)]
    fn for_each(&self, p: usize, f: impl FnMut(usize, StencilNode<D>)) {
        (**self).for_each(p, f)
    }

    #[inline(always)]
    fn offset(&self, grid: &Grid<D>, p: usize, s: usize, node: usize, xp: &Vector<D>) -> Vector<D> {
        (**self).offset(grid, p, s, node, xp)
    }
}

/// The stencils of a tensor-product B-spline with `W` nodes per axis, stored as 1D factors.
#[derive(Debug, Clone)]
pub struct TensorStencils<const D: usize, const W: usize> {
    strides: [usize; D],
    origin: Vector<D>,
    cell_size: f64,
    /// Integer index of the first stencil node; 32 bits suffice (a grid has at most 2^24 cells
    /// per axis and every particle lies in it), and 8 bytes per particle less in 2D (12 in 3D)
    /// for the shape phase to write and both transfers to read.
    first: Vec<[i32; D]>,
    /// The storage index of the integer node index 0 (`Grid::node_index([0; D])`); a stencil's
    /// storage index is formed from its first node rather than stored (8 bytes per particle
    /// less for the shape phase to write and the transfers to read).
    zero_index: usize,
    values: Vec<[[f64; W]; D]>,
    derivatives: Vec<[[f64; W]; D]>,
    /// Grid block of each particle under the layout of the last `compute_with`
    /// ([`BlockLayout::key`] of its first node), for the bins.
    keys: Vec<u32>,
    /// The instruction set of `compute_with` and of the loops that read these stencils.
    pub lanes: Lanes,
}

/// A particle's stencil as a transfer reads it ([`TensorView::factors`]).
pub(super) struct Factors<'a, const D: usize, const W: usize> {
    pub(super) base: usize,
    pub(super) w: &'a [[f64; W]; D],
    pub(super) dw: [[f64; W]; D],
    pub(super) offsets: [[f64; W]; D],
}

/// [`TensorStencils`] as slices and scalars ([`StencilView::Local`]).
#[derive(Debug, Clone, Copy)]
pub struct TensorView<'a, const D: usize, const W: usize> {
    pub(super) strides: [usize; D],
    origin: Vector<D>,
    cell_size: f64,
    first: &'a [[i32; D]],
    zero_index: usize,
    values: &'a [[[f64; W]; D]],
    derivatives: &'a [[[f64; W]; D]],
    lanes: Lanes,
}

impl<const D: usize, const W: usize> Default for TensorStencils<D, W> {
    fn default() -> Self {
        TensorStencils {
            strides: [0; D],
            origin: Vector::zeros(),
            cell_size: 0.0,
            first: Vec::new(),
            zero_index: 0,
            values: Vec::new(),
            derivatives: Vec::new(),
            keys: Vec::new(),
            lanes: Lanes::default(),
        }
    }
}

impl<const D: usize, const W: usize> TensorStencils<D, W> {
    /// Evaluates the factors of `shape` (whose width must be `W`) at every position.
    #[cfg(any(test, feature = "internals"))]
    pub fn compute(&mut self, shape: &BSpline, grid: &Grid<D>, x: &[Vector<D>]) {
        self.compute_with(shape, grid, x, true, &BlockLayout::new(W, grid));
    }

    /// As [`TensorStencils::compute`], with each particle's block under `layout`
    /// ([`TensorStencils::block_keys`]); without `derivatives` only the values are stored (the
    /// MLS transfer without contact reads no gradient), and asking for a gradient later panics.
    pub fn compute_with(
        &mut self,
        shape: &BSpline,
        grid: &Grid<D>,
        x: &[Vector<D>],
        derivatives: bool,
        layout: &BlockLayout<D>,
    ) {
        assert_eq!(shape.order.width(), W, "tensor stencil width");
        // The factored sums read a row of `W` nodes as contiguous storage.
        assert_eq!(
            grid.strides()[0],
            1,
            "axis 0 is the contiguous axis of node storage"
        );
        self.strides = std::array::from_fn(|a| {
            let mut e = [0i64; D];
            e[a] = 1;
            grid.node_index(e) - grid.node_index([0; D])
        });
        self.origin = grid.origin;
        self.cell_size = grid.cell_size;
        let n = x.len();
        self.zero_index = grid.node_index([0; D]);
        self.first.resize(n, [0; D]);
        self.values.resize(n, [[0.0; W]; D]);
        self.keys.resize(n, 0);

        // First node, its storage index and the values; the factors for the derivatives. In
        // chunks, each compiled for the processor's vector instructions (`Lanes::wide`).
        const CHUNK: usize = 1024;
        let derivatives = if derivatives {
            self.derivatives.resize(n, [[0.0; W]; D]);
            Some(&mut self.derivatives[..])
        } else {
            self.derivatives.clear();
            None
        };
        // A chunk of particles: four at a time as vector lanes (`BSpline::factors_4`) when the
        // processor has AVX2, the rest one by one; the same bits either way.
        let lanes = self.lanes;
        let fill = crate::cpu::inlined(
            #[inline(always)]
            |first: &mut [[i32; D]],
             keys: &mut [u32],
             w: &mut [[[f64; W]; D]],
             x: &[Vector<D>],
             mut dw: Option<&mut [[[f64; W]; D]]>| {
                let n = x.len();
                let mut i = 0;
                while i < n {
                    let four = i + 4 <= n && lanes.avx2();
                    // SAFETY: the processor has AVX2 (`Lanes::avx2`).
                    #[cfg(target_arch = "x86_64")]
                    let four = four
                        && unsafe {
                            shape.factors_4(
                                grid,
                                &x[i..i + 4],
                                &mut first[i..i + 4],
                                &mut w[i..i + 4],
                                dw.as_deref_mut().map(|d| &mut d[i..i + 4]),
                            )
                        };
                    let end = if four { i + 4 } else { i + 1 };
                    for q in i..end {
                        if !four {
                            let dw = dw.as_deref_mut().map(|d| &mut d[q]);
                            let mut wide_first = [0i64; D];
                            shape.factors_into(grid, &x[q], &mut wide_first, &mut w[q], dw);
                            // Saturated for a point off the grid (which no step takes).
                            first[q] = wide_first
                                .map(|f| f.clamp(i32::MIN.into(), i32::MAX.into()) as i32);
                        }
                        keys[q] = layout.key(&first[q].map(i64::from));
                    }
                    i = end;
                }
            },
        );
        let chunks = self
            .first
            .par_chunks_mut(CHUNK)
            .zip(self.keys.par_chunks_mut(CHUNK))
            .zip(self.values.par_chunks_mut(CHUNK))
            .zip(x.par_chunks(CHUNK));
        match derivatives {
            Some(derivatives) => chunks.zip(derivatives.par_chunks_mut(CHUNK)).for_each(
                |((((first, keys), w), x), dw)| {
                    lanes.wide(
                        #[inline(always)]
                        || fill(first, keys, w, x, Some(dw)),
                    )
                },
            ),
            None => chunks.for_each(|(((first, keys), w), x)| {
                lanes.wide(
                    #[inline(always)]
                    || fill(first, keys, w, x, None),
                )
            }),
        }
    }

    /// Each particle's block under the layout given to `compute_with`, found with the factors
    /// (for [`Bins::compute_from_keys`](crate::grid::Bins::compute_from_keys)).
    pub fn block_keys(&self) -> &[u32] {
        &self.keys
    }

    /// Bytes allocated.
    pub fn bytes(&self) -> usize {
        self.first.capacity() * 4 * D
            + self.keys.capacity() * 4
            + (self.values.capacity() + self.derivatives.capacity()) * 8 * D * W
    }
}

impl<const D: usize, const W: usize> TensorView<'_, D, W> {
    /// `(x_I − x_p)_a` for the node `k` of axis `a` of particle `p`'s stencil (`[a][k]`), as
    /// `Grid::node_position` forms it (so that every view gives the same bits). Once per
    /// particle: per row, the conversions took 8–12% of the 3D transfers.
    #[inline(always)]
    fn offsets(&self, p: usize, xp: &Vector<D>) -> [[f64; W]; D] {
        let first = &self.first[p];
        std::array::from_fn(|a| {
            std::array::from_fn(|k| {
                self.origin[a] + (i64::from(first[a]) + k as i64) as f64 * self.cell_size - xp[a]
            })
        })
    }

    /// The storage index of particle `p`'s first stencil node (`Grid::node_index` of it).
    #[inline(always)]
    fn base(&self, p: usize) -> usize {
        let mut n = self.zero_index as i64;
        for (&i, &stride) in self.first[p].iter().zip(&self.strides) {
            n += i64::from(i) * stride as i64;
        }
        n as usize
    }

    /// What a transfer of particle `p` reads of its stencil: the storage index of the first
    /// node, the factors, their derivatives (zeros unless `derivatives`) and the offsets
    /// `x_I − x_p` per axis (zeros unless `xp` is given).
    #[inline(always)]
    pub(super) fn factors(
        &self,
        p: usize,
        derivatives: bool,
        xp: Option<&Vector<D>>,
    ) -> Factors<'_, D, W> {
        Factors {
            base: self.base(p),
            w: &self.values[p],
            dw: match derivatives {
                true => self.derivatives[p],
                false => [[0.0; W]; D],
            },
            offsets: match xp {
                Some(xp) => self.offsets(p, xp),
                None => [[0.0; W]; D],
            },
        }
    }

    /// The next row of a stencil: `k = (k_1, …, k_{D−1})` with axis 1 fastest, and the storage
    /// index of the row's first node.
    #[inline(always)]
    // An index loop: the iterator form (`zip`, `skip`) compiles to a slower grid to particle.
    #[allow(clippy::needless_range_loop)]
    pub(super) fn next_row(&self, k: &mut [usize; D], row: &mut usize) {
        for a in 1..D {
            k[a] += 1;
            *row += self.strides[a];
            if k[a] < W {
                break;
            }
            k[a] = 0;
            *row -= W * self.strides[a];
        }
    }

    /// Visits the stencil of particle `p`, with `x_I − x_p` when `xp` is given (zero otherwise).
    #[inline(always)]
    fn visit(
        &self,
        p: usize,
        xp: Option<&Vector<D>>,
        mut f: impl FnMut(usize, StencilNode<D>, Vector<D>),
    ) {
        let Factors {
            base,
            w,
            dw,
            offsets,
        } = self.factors(p, true, xp);
        // Same slot order as `ShapeFunction::evaluate`: axis 0 fastest.
        let mut k = [0usize; D];
        let mut node = base;
        for s in 0..W.pow(D as u32) {
            let (value, gradient) = tensor_product(w, &dw, &k);
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
            next_in_box::<D, W>(&mut k, &mut node, &self.strides);
        }
    }
}

impl<const D: usize, const W: usize> TensorView<'_, D, W> {
    /// Scatter with the factors of each row: `Ψ = w_0 c`, `∇Ψ = (w_0' c, w_0 c_1, …)`, the
    /// momentum `m v + m C (x_I − x_p)` split into a row part and an axis-0 part, the force
    /// `−V σ ∇Ψ = w_0' (c σ_0) + w_0 (Σ_a c_a σ_a)` with the row sums taken once.
    ///
    /// `AFFINE`: `input.affine` is given; `MASS`: the mass is mapped; `FORCE`: `input.force` is
    /// given; `EXTRA`: the body force (with `FORCE`) or the mass gradient may be asked for
    /// (checked at run time). Nodes with a zero value and gradient are skipped; for `W ≥ 3`
    /// (B-splines that are C¹) a zero value implies a zero gradient, so the value alone decides.
    ///
    /// # Safety
    /// As [`StencilView::scatter`].
    // Index loops over the axes: each index reads several per-axis tables at once.
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    unsafe fn scatter_rows<
        const AFFINE: bool,
        const MASS: bool,
        const FORCE: bool,
        const EXTRA: bool,
    >(
        &self,
        p: usize,
        input: &ScatterInput<'_, D>,
        out: &NodeScatter<D>,
    ) {
        // SAFETY: the caller keeps the contract of `StencilView::scatter`: no other thread
        // writes these nodes; `check_box` accepted the whole stencil box, so every node written
        // lies inside the storage.
        unsafe {
            // The derivatives only for the force and the mass gradient (not stored under MLS).
            let derivatives = FORCE || (EXTRA && input.with_gradient);
            let Factors {
                base,
                w,
                dw,
                offsets,
            } = self.factors(p, derivatives, AFFINE.then_some(&input.position));
            out.check_box(base, &self.strides, W);
            let offset = |a: usize, k: usize| offsets[a][k];
            let m = input.mass;
            let mc = input.affine.unwrap_or_else(Matrix::zeros);
            let (vs, b) = input
                .force
                .unwrap_or_else(|| (Matrix::zeros(), Vector::zeros()));
            // VC's mean fit: the particle's mean of the coefficients over its stencil, with each
            // node's `|Ψ|` as `tensor_product` takes it (ascending axes from one), the sums of
            // the kept fits in their order.
            let mean_fit = input.mean_fit.filter(|_| FORCE);
            let product = |k: &[usize; D]| {
                let mut value = 1.0;
                for a in 0..D {
                    value *= w[a][k[a]];
                }
                value.abs()
            };
            let mut mu = Vector::<D>::zeros();
            if let Some(zeta) = mean_fit {
                let mut weight = 0.0;
                let (mut k, mut node) = ([0usize; D], base);
                for _ in 0..W.pow(D as u32) {
                    let value = product(&k);
                    if value != 0.0 {
                        weight += value;
                        mu += value * zeta[node];
                    }
                    next_in_box::<D, W>(&mut k, &mut node, &self.strides);
                }
                if weight > 0.0 {
                    mu /= weight;
                }
            }
            // Axis-0 part of the affine momentum, per node of a row.
            let mut affine0 = [Vector::<D>::zeros(); W];
            if AFFINE {
                for (k0, a0) in affine0.iter_mut().enumerate() {
                    *a0 = mc.column(0) * offset(0, k0);
                }
            }
            let mut k = [0usize; D];
            let mut row = base;
            for _ in 0..W.pow(D as u32 - 1) {
                let mut c = 1.0;
                for a in 1..D {
                    c *= w[a][k[a]];
                }
                let c_a: [f64; D] = std::array::from_fn(|a| {
                    if a == 0 {
                        return 0.0;
                    }
                    let mut c_a = 1.0;
                    for b in 1..D {
                        c_a *= if a == b { dw[b][k[b]] } else { w[b][k[b]] };
                    }
                    c_a
                });
                let mut momentum_row = input.momentum;
                if AFFINE {
                    for a in 1..D {
                        momentum_row += mc.column(a) * offset(a, k[a]);
                    }
                }
                let (mut force0, mut force_rest) = (Vector::<D>::zeros(), Vector::<D>::zeros());
                if FORCE {
                    for a in 1..D {
                        force_rest += c_a[a] * vs.column(a);
                    }
                    force0 = c * vs.column(0);
                }
                for k0 in 0..W {
                    let n = row + k0;
                    let value = w[0][k0] * c;
                    let gradient = Vector::<D>::from_fn(|a, _| {
                        if a == 0 {
                            dw[0][k0] * c
                        } else {
                            w[0][k0] * c_a[a]
                        }
                    });
                    if value == 0.0 && (W >= 3 || gradient == Vector::<D>::zeros()) {
                        continue;
                    }
                    if !MASS {
                        // A node that gets mass needs no mark: `GridNodes::collect_touched` lists
                        // the nodes with mass too.
                        out.touch_unchecked(n);
                    }
                    scatter_add(out.momentum, n, value * (momentum_row + affine0[k0]));
                    if MASS {
                        scatter_add(out.mass, n, m * value);
                        if EXTRA && input.with_gradient {
                            scatter_add(out.mass_gradient, n, m * gradient);
                        }
                    }
                    if FORCE {
                        let f = dw[0][k0] * force0 + w[0][k0] * force_rest;
                        scatter_add(out.force, n, f);
                        if EXTRA && input.with_body_force {
                            let field = if input.keep_body_force {
                                out.body_force
                            } else {
                                out.force
                            };
                            scatter_add(field, n, (m * value) * b);
                        }
                        // VC's correction last, as a pass of its own would add it (the same
                        // bits: a chaotic collapse is not indifferent to the last bit).
                        if let Some(zeta) = mean_fit {
                            let mut kn = k;
                            kn[0] = k0;
                            scatter_add(out.force, n, vs * ((zeta[n] - mu) * product(&kn)));
                        }
                    }
                }
                self.next_row(&mut k, &mut row);
            }
        }
    }
}

impl<const D: usize, const W: usize> TensorStencils<D, W> {
    /// The stencils as a [`StencilView`]: slices and scalars that a phase copies into each
    /// parallel task ([`StencilView::Local`]).
    #[inline(always)]
    pub fn local(&self) -> TensorView<'_, D, W> {
        TensorView {
            strides: self.strides,
            origin: self.origin,
            cell_size: self.cell_size,
            first: &self.first,
            zero_index: self.zero_index,
            values: &self.values,
            derivatives: &self.derivatives,
            lanes: self.lanes,
        }
    }
}

impl<const D: usize, const W: usize> StencilView<D> for TensorView<'_, D, W> {
    type Local<'a>
        = Self
    where
        Self: 'a;

    fn tensor_factors(&self) -> Option<TensorFactors<'_, D>> {
        Some(TensorFactors {
            width: W,
            strides: self.strides,
            zero_index: self.zero_index,
            first: self.first,
            values: self.values.as_flattened().as_flattened(),
            derivatives: self.derivatives.as_flattened().as_flattened(),
        })
    }

    #[inline(always)]
    fn local(&self) -> Self {
        *self
    }

    #[inline(always)]
    fn lanes(&self) -> Lanes {
        self.lanes
    }

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

    /// Scatter with the factors of each row (`TensorStencils::scatter_rows`, private), compiled
    /// for the common cases: with or without APIC, with or without mass and force, and a
    /// general version when there is a body force or a mass gradient to add.
    #[inline(always)]
    unsafe fn scatter(&self, p: usize, input: &ScatterInput<'_, D>, out: &NodeScatter<D>) -> bool {
        // SAFETY: the caller keeps `StencilView::scatter`'s contract (no other thread writes this
        // stencil's nodes); the AVX2 rows run only when `self.lanes` says the processor has it.
        unsafe {
            let extra = input.with_mass && (input.with_body_force || input.with_gradient);
            let (affine, mass, force) = (
                input.affine.is_some(),
                input.with_mass,
                input.force.is_some(),
            );
            match (affine, mass, force, extra) {
                // The second map of MUSL: momentum only.
                (true, false, _, _) => {
                    self.scatter_rows::<true, false, false, false>(p, input, out)
                }
                (false, false, _, _) => {
                    self.scatter_rows::<false, false, false, false>(p, input, out)
                }
                // APIC and PIC/FLIP: mass, momentum and force.
                (true, true, true, false) => {
                    self.scatter_rows::<true, true, true, false>(p, input, out)
                }
                (false, true, true, false) => {
                    self.scatter_rows::<false, true, true, false>(p, input, out)
                }
                (true, true, true, true) => {
                    self.scatter_rows::<true, true, true, true>(p, input, out)
                }
                (false, true, true, true) => {
                    self.scatter_rows::<false, true, true, true>(p, input, out)
                }
                // MLS: mass and momentum (the force is in the momentum).
                (true, true, false, false) => {
                    self.scatter_rows::<true, true, false, false>(p, input, out)
                }
                (true, true, false, true) => {
                    self.scatter_rows::<true, true, false, true>(p, input, out)
                }
                // Mass without force or affine term: not a case the step has; node by node.
                (false, true, false, _) => return false,
            }
            true
        }
    }

    // The row loop and its factors `c`, `c_a` are written out here and in `scatter` on purpose:
    // behind a shared row visitor the compiler no longer keeps the row sums in registers, and
    // both maps slow down (most in 3D).
    /// Sum factorization: along each row of the stencil (axis 0, contiguous nodes) the sums
    /// `Σ w_0 v`, `Σ w_0' v`, `Σ w_0 (x − x_p)_0 v` are taken once, then weighted by the row's
    /// factors of the other axes: `Ψ = w_0 c`, `∂_0 Ψ = w_0' c`, `∂_a Ψ = w_0 c_a` (a ≥ 1).
    /// About 2/3 of the flops of the node-by-node sums; the same sums to round-off.
    #[allow(clippy::needless_range_loop, clippy::too_many_arguments)]
    #[inline(always)]
    fn gather(
        &self,
        _grid: &Grid<D>,
        p: usize,
        xp: &Vector<D>,
        v: &[Vector<D>],
        v_old: Option<&[Vector<D>]>,
        affine: bool,
        gradient: bool,
    ) -> Gathered<D> {
        #[cfg(target_arch = "x86_64")]
        if D == 3 && self.lanes.avx2() {
            // SAFETY: with `D == 3` the types are the same; the processor has AVX2 and FMA.
            return unsafe { super::simd::gather_3d(self, p, xp, v, v_old, affine, gradient) };
        }
        #[cfg(target_arch = "x86_64")]
        if D == 2 && W <= 4 && self.lanes.avx2() {
            // SAFETY: as above, with `D == 2` and `W ≤ 4`.
            return unsafe { super::simd::gather_2d(self, p, xp, v, v_old, affine, gradient) };
        }
        let Factors {
            base,
            w,
            dw,
            offsets,
        } = self.factors(p, gradient, affine.then_some(xp));
        let offset = |a: usize, k: usize| offsets[a][k];
        let mut g = Gathered::zero();
        let off0 = offsets[0];
        // Rows: k = (k_1, …, k_{D−1}), axis 1 fastest.
        let mut k = [0usize; D];
        let mut row = base;
        for _ in 0..W.pow(D as u32 - 1) {
            // The row sums in plain arrays (faster in 3D than nalgebra's 3-vectors). They start
            // from −0, the neutral element of addition (`−0 + x = x` for every `x`, where
            // `+0 + (−0) = +0`): each sum is its first term plus the others, as the vector
            // gathers take it.
            let (mut s_w, mut s_dw, mut s_wo, mut s_dv) =
                ([-0.0; D], [-0.0; D], [-0.0; D], [-0.0; D]);
            let vs = &v[row..row + W];
            for k0 in 0..W {
                let vi = &vs[k0];
                let (wk, dwk) = (w[0][k0], dw[0][k0]);
                let wo = wk * off0[k0];
                for i in 0..D {
                    s_w[i] += wk * vi[i];
                    if gradient {
                        s_dw[i] += dwk * vi[i];
                    }
                    if affine {
                        s_wo[i] += wo * vi[i];
                    }
                }
                if let Some(v_old) = v_old {
                    let dv = vi - v_old[row + k0];
                    for i in 0..D {
                        s_dv[i] += wk * dv[i];
                    }
                }
            }
            let (s_w, s_dw, s_wo, s_dv) = (
                Vector::<D>::from(s_w),
                Vector::<D>::from(s_dw),
                Vector::<D>::from(s_wo),
                Vector::<D>::from(s_dv),
            );
            let mut c = 1.0;
            for a in 1..D {
                c *= w[a][k[a]];
            }
            g.velocity += c * s_w;
            // Without FLIP the sum adds zeros, which the compiler cannot drop (c may not be
            // finite). Skipping it frees registers in 3D; in 2D the branch costs more than the
            // sum, so 2D keeps it.
            if D == 2 || v_old.is_some() {
                g.velocity_change += c * s_dv;
            }
            if gradient {
                g.gradient.column_mut(0).axpy(c, &s_dw, 1.0);
            }
            if affine {
                g.affine.column_mut(0).axpy(c, &s_wo, 1.0);
            }
            for a in 1..D {
                if gradient {
                    let mut c_a = 1.0;
                    for b in 1..D {
                        c_a *= if a == b { dw[b][k[b]] } else { w[b][k[b]] };
                    }
                    g.gradient.column_mut(a).axpy(c_a, &s_w, 1.0);
                }
                if affine {
                    g.affine.column_mut(a).axpy(c * offset(a, k[a]), &s_w, 1.0);
                }
            }
            self.next_row(&mut k, &mut row);
        }
        g
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
            self.origin[a] + (i64::from(first[a]) + k) as f64 * self.cell_size - xp[a]
        })
    }
}
