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

impl BSpline {
    /// [`BSpline::factors_into`] for four positions at once, as the lanes of AVX2 registers:
    /// the same operations in the same order for each, so the same bits. Returns false, having
    /// written nothing, when some coordinate is not finite or lies 2^30 cells or more from the
    /// origin (the scalar code takes those).
    ///
    /// # Safety
    /// The processor has AVX2 (the caller runs this inside [`crate::cpu::Lanes::wide`]).
    #[cfg(target_arch = "x86_64")]
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    pub(crate) unsafe fn factors_4<const D: usize, const W: usize>(
        &self,
        grid: &Grid<D>,
        x: &[Vector<D>],
        first: &mut [[i32; D]],
        values: &mut [[[f64; W]; D]],
        derivatives: Option<&mut [[[f64; W]; D]]>,
    ) -> bool {
        // SAFETY: the caller runs this inside `Lanes::wide`, so the processor has AVX2 and FMA;
        // every load and store stays inside the four particles' arrays, whose lengths are
        // asserted.
        unsafe {
            use std::arch::x86_64::*;
            assert!(
                x.len() == 4 && first.len() == 4 && values.len() == 4 && W == self.order.width()
            );
            // Functions, not closures: a closure is not inlined by force, and the intrinsics in it
            // would become calls.
            #[inline(always)]
            unsafe fn set(x: f64) -> __m256d {
                // SAFETY: only `factors_4` calls this, inside `Lanes::wide`: the processor has
                // AVX2 and FMA.
                unsafe { _mm256_set1_pd(x) }
            }
            #[inline(always)]
            unsafe fn mul(a: __m256d, b: __m256d) -> __m256d {
                // SAFETY: only `factors_4` calls this, inside `Lanes::wide`: the processor has
                // AVX2 and FMA.
                unsafe { _mm256_mul_pd(a, b) }
            }
            #[inline(always)]
            unsafe fn sub(a: __m256d, b: __m256d) -> __m256d {
                // SAFETY: only `factors_4` calls this, inside `Lanes::wide`: the processor has
                // AVX2 and FMA.
                unsafe { _mm256_sub_pd(a, b) }
            }
            #[inline(always)]
            unsafe fn add(a: __m256d, b: __m256d) -> __m256d {
                // SAFETY: only `factors_4` calls this, inside `Lanes::wide`: the processor has
                // AVX2 and FMA.
                unsafe { _mm256_add_pd(a, b) }
            }
            /// `−a` (the sign flipped, as the scalar negation).
            #[inline(always)]
            unsafe fn negate(a: __m256d) -> __m256d {
                // SAFETY: only `factors_4` calls this, inside `Lanes::wide`: the processor has
                // AVX2 and FMA.
                unsafe { _mm256_xor_pd(a, set(-0.0)) }
            }
            #[inline(always)]
            unsafe fn floor(a: __m256d) -> __m256d {
                // SAFETY: only `factors_4` calls this, inside `Lanes::wide`: the processor has
                // AVX2 and FMA.
                unsafe { _mm256_round_pd::<{ _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC }>(a) }
            }
            /// The cubic's inner branch at distance `r`: value and derivative.
            #[inline(always)]
            unsafe fn inner(r: __m256d) -> (__m256d, __m256d) {
                // SAFETY: only `factors_4` calls this, inside `Lanes::wide`: the processor has
                // AVX2 and FMA.
                unsafe {
                    let value = add(
                        sub(mul(mul(mul(set(0.5), r), r), r), mul(r, r)),
                        set(2.0 / 3.0),
                    );
                    let derivative = sub(mul(mul(set(1.5), r), r), mul(set(2.0), r));
                    (value, derivative)
                }
            }
            // The coordinates per axis as lanes: in 2D two loads of the four interleaved positions
            // and a shuffle (`x0 y0 x1 y1 | x2 y2 x3 y3` → `x0 x1 x2 x3`, `y0 y1 y2 y3`), else
            // value by value.
            let mut coordinates = [set(0.0); D];
            if D == 2 {
                let p = x.as_ptr() as *const f64;
                let (a, b) = (_mm256_loadu_pd(p), _mm256_loadu_pd(p.add(4)));
                coordinates[0] = _mm256_permute4x64_pd::<0xD8>(_mm256_unpacklo_pd(a, b));
                coordinates[1] = _mm256_permute4x64_pd::<0xD8>(_mm256_unpackhi_pd(a, b));
            } else {
                for a in 0..D {
                    coordinates[a] = _mm256_set_pd(x[3][a], x[2][a], x[1][a], x[0][a]);
                }
            }
            // Cell units, `(x − origin) / h`, per axis; within 2^30 cells of the origin, so that
            // the first nodes convert to 32-bit integers exactly.
            let mut xi = [set(0.0); D];
            let mut inside = true;
            for a in 0..D {
                xi[a] = _mm256_div_pd(
                    sub(coordinates[a], set(grid.origin[a])),
                    set(grid.cell_size),
                );
                let magnitude = _mm256_andnot_pd(set(-0.0), xi[a]);
                let limit = set((1u64 << 30) as f64);
                inside &=
                    _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_LT_OQ>(magnitude, limit)) == 0b1111;
            }
            if !inside {
                return false;
            }
            let inv_h = set(1.0 / grid.cell_size);
            let mut first_lanes = [_mm_setzero_si128(); D];
            let mut w = [[set(0.0); W]; D];
            let mut dw = [[set(0.0); W]; D];
            for a in 0..D {
                // The first node, an integer in floating point (exact), and `t = xi − first`.
                let f = match self.order {
                    BSplineOrder::Linear => floor(xi[a]),
                    BSplineOrder::Quadratic => floor(sub(xi[a], set(0.5))),
                    BSplineOrder::Cubic => sub(floor(xi[a]), set(1.0)),
                };
                let t = sub(xi[a], f);
                // Exact: `f` is an integer below 2^30 in magnitude.
                first_lanes[a] = _mm256_cvtpd_epi32(f);
                let (w, dw) = (&mut w[a], &mut dw[a]);
                match self.order {
                    BSplineOrder::Linear => {
                        (w[0], w[1]) = (sub(set(1.0), t), t);
                        (dw[0], dw[1]) = (set(-1.0), set(1.0));
                    }
                    BSplineOrder::Quadratic => {
                        let (u, c, l) = (sub(set(1.5), t), sub(t, set(1.0)), sub(t, set(0.5)));
                        w[0] = mul(mul(set(0.5), u), u);
                        w[1] = sub(set(0.75), mul(c, c));
                        w[2] = mul(mul(set(0.5), l), l);
                        (dw[0], dw[1], dw[2]) = (negate(u), mul(set(-2.0), c), l);
                    }
                    BSplineOrder::Cubic => {
                        let (u, r1, r2, l) = (
                            sub(set(2.0), t),
                            sub(t, set(1.0)),
                            sub(set(2.0), t),
                            sub(t, set(1.0)),
                        );
                        let ((w1, d1), (w2, d2)) = (inner(r1), inner(r2));
                        w[0] = _mm256_div_pd(mul(mul(u, u), u), set(6.0));
                        (w[1], w[2]) = (w1, w2);
                        w[3] = _mm256_div_pd(mul(mul(l, l), l), set(6.0));
                        dw[0] = mul(mul(set(-0.5), u), u);
                        (dw[1], dw[2]) = (d1, negate(d2));
                        dw[3] = mul(mul(set(0.5), l), l);
                    }
                }
                for d in dw.iter_mut() {
                    *d = mul(*d, inv_h);
                }
            }
            // The first nodes, `first[q][a]`: in 2D interleaved in registers and stored as two
            // rows, else lane by lane.
            if D == 2 {
                let o = first.as_mut_ptr() as *mut __m128i;
                _mm_storeu_si128(o, _mm_unpacklo_epi32(first_lanes[0], first_lanes[1]));
                _mm_storeu_si128(o.add(1), _mm_unpackhi_epi32(first_lanes[0], first_lanes[1]));
            } else {
                for a in 0..D {
                    let lanes: [i32; 4] = std::mem::transmute(first_lanes[a]);
                    for (q, first) in first.iter_mut().enumerate() {
                        first[a] = lanes[q];
                    }
                }
            }
            store_transposed(values, &w);
            if let Some(derivatives) = derivatives {
                store_transposed(derivatives, &dw);
            }
            true
        }
    }
}

/// Stores factors held as lanes (`lanes[a][k]`, lane `q` for particle `q`) into the four
/// particles' arrays (`out[q][a][k]`, `D · W` consecutive values each): four registers at a
/// time transposed in registers and stored as four whole rows, a remaining pair as 2-lane
/// stores, a last one value by value. Only data movement, so the same bits as storing each
/// value. Storing every value on its own (24 scalar stores in 2D) held a quarter of the shape
/// phase's samples on an Intel Xeon (BENCHMARKS.md).
///
/// # Safety
/// The processor has AVX2 (inside [`crate::cpu::Lanes::wide`]).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn store_transposed<const D: usize, const W: usize>(
    out: &mut [[[f64; W]; D]],
    lanes: &[[std::arch::x86_64::__m256d; W]; D],
) {
    // SAFETY: the caller runs this inside `Lanes::wide`, so the processor has AVX2 and FMA;
    // every load and store stays inside the four particles' arrays, whose lengths are
    // asserted.
    unsafe {
        use std::arch::x86_64::*;
        assert!(out.len() == 4);
        let count = D * W;
        // SAFETY: `[[[f64; W]; D]; 4]` and `[[__m256d; W]; D]` are arrays of f64 and of registers
        // without padding; `out` holds 4 · count values.
        let r = std::slice::from_raw_parts(lanes.as_ptr() as *const __m256d, count);
        let o = out.as_mut_ptr() as *mut f64;
        let mut j = 0;
        while j + 4 <= count {
            let (t0, t1) = (
                _mm256_unpacklo_pd(r[j], r[j + 1]),
                _mm256_unpackhi_pd(r[j], r[j + 1]),
            );
            let (t2, t3) = (
                _mm256_unpacklo_pd(r[j + 2], r[j + 3]),
                _mm256_unpackhi_pd(r[j + 2], r[j + 3]),
            );
            _mm256_storeu_pd(o.add(j), _mm256_permute2f128_pd::<0x20>(t0, t2));
            _mm256_storeu_pd(o.add(count + j), _mm256_permute2f128_pd::<0x20>(t1, t3));
            _mm256_storeu_pd(o.add(2 * count + j), _mm256_permute2f128_pd::<0x31>(t0, t2));
            _mm256_storeu_pd(o.add(3 * count + j), _mm256_permute2f128_pd::<0x31>(t1, t3));
            j += 4;
        }
        if j + 2 <= count {
            let (u0, u1) = (
                _mm256_unpacklo_pd(r[j], r[j + 1]),
                _mm256_unpackhi_pd(r[j], r[j + 1]),
            );
            _mm_storeu_pd(o.add(j), _mm256_castpd256_pd128(u0));
            _mm_storeu_pd(o.add(count + j), _mm256_castpd256_pd128(u1));
            _mm_storeu_pd(o.add(2 * count + j), _mm256_extractf128_pd::<1>(u0));
            _mm_storeu_pd(o.add(3 * count + j), _mm256_extractf128_pd::<1>(u1));
            j += 2;
        }
        if j < count {
            let l: [f64; 4] = std::mem::transmute(r[j]);
            for (q, value) in l.into_iter().enumerate() {
                *o.add(q * count + j) = value;
            }
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
