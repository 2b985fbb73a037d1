//! The SIMD kernels (AVX2 on x86-64): the shape functions' factors of four particles at once
//! ([`BSpline::factors_4`]) and the gathers of grid to particle ([`gather_3d`], [`gather_2d`]).
//! With the parallel node sums' primitives (`grid/shared.rs`) this is where the engine's unsafe
//! operations are defined.
//!
//! Every kernel is an `unsafe fn` with one precondition: the processor has AVX2 and FMA. Callers
//! take these paths only when their `Lanes` says so (`Lanes::avx2`, `Lanes::wide`), and a `Lanes`
//! with AVX2 comes only from `Lanes::detect`. The functions are `#[inline(always)]` and not
//! `#[target_feature]`: inlined into the body `Lanes::wide` compiles for AVX2, the intrinsics
//! become AVX2 instructions there (out of line, behind a `#[target_feature]` call, most of the
//! gain is lost). Each computes the same operations in the same order as the portable code, so
//! the same bits (`results_do_not_depend_on_the_instruction_set` checks it).

use super::stencil::{Factors, Gathered, TensorView};
use super::{BSpline, BSplineOrder};
use crate::grid::Grid;
use crate::{Matrix, Vector};
use std::arch::x86_64::*;

impl BSpline {
    /// [`BSpline::factors_into`] for four positions at once, as the lanes of AVX2 registers:
    /// the same operations in the same order for each, so the same bits. Returns false, having
    /// written nothing, when some coordinate is not finite or lies 2^30 cells or more from the
    /// origin (the scalar code takes those).
    ///
    /// # Safety
    /// The processor has AVX2 (the caller runs this inside [`crate::cpu::Lanes::wide`]).
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

// The 3D gather with each 3-vector in one AVX2 register (`x, y, z, 0`). The compiler takes the
// 3-vectors of the portable gather a component or two at a time and spills its sums; here
// every sum is one register. Lane by lane the same multiplications and additions in the same
// order (no fused multiply-add), so the same bits as the portable gather
// (`results_do_not_depend_on_the_instruction_set` checks it).
//
// The 2D gather (`gather_2d`) puts two nodes of a row in one register.

/// `s + a x`, lane by lane.
#[inline(always)]
unsafe fn add_scaled(s: __m256d, a: f64, x: __m256d) -> __m256d {
    // SAFETY: only this module's AVX2 kernels call this, inside `Lanes::wide`: the
    // processor has AVX2 and FMA.
    unsafe { _mm256_add_pd(s, _mm256_mul_pd(_mm256_set1_pd(a), x)) }
}

/// The three components of `v[n]` and a zero (`n < v.len()`, checked by the caller).
#[inline(always)]
unsafe fn load(v: &[Vector<3>], n: usize) -> __m256d {
    // SAFETY: the kernels pass an index `n` of `v` (a node of the stencil), so the three
    // unmasked lanes read `v[n]` alone (the fourth is masked off); the processor has AVX2,
    // as for the helpers above.
    unsafe {
        let mask = _mm256_set_epi64x(0, -1, -1, -1);
        _mm256_maskload_pd(v.as_ptr().add(n) as *const f64, mask)
    }
}

#[inline(always)]
unsafe fn vector(x: __m256d) -> Vector<3> {
    // SAFETY: only this module's AVX2 kernels call this, inside `Lanes::wide`: the
    // processor has AVX2 and FMA.
    unsafe {
        let mut l = [0.0; 4];
        _mm256_storeu_pd(l.as_mut_ptr(), x);
        Vector::<3>::new(l[0], l[1], l[2])
    }
}

/// [`StencilView::gather`](super::StencilView::gather) of a 3D view, as the portable one.
///
/// # Safety
/// The processor has AVX2 and FMA (`D == 3` is asserted).
#[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
#[inline(always)]
pub(super) unsafe fn gather_3d<const D: usize, const W: usize>(
    view: &TensorView<'_, D, W>,
    p: usize,
    xp: &Vector<D>,
    v: &[Vector<D>],
    v_old: Option<&[Vector<D>]>,
    affine: bool,
    gradient: bool,
) -> Gathered<D> {
    // SAFETY: the caller keeps the contract above (AVX2 and FMA present); the loads read
    // node velocities at indices of the stencil, which lie inside the node arrays.
    unsafe {
        assert_eq!(D, 3);
        // SAFETY (of the casts): `D == 3`, so each is the same type.
        let view = &*(view as *const TensorView<'_, D, W> as *const TensorView<'_, 3, W>);
        let xp = &*(xp as *const Vector<D> as *const Vector<3>);
        let cast =
            |v: &[Vector<D>]| std::slice::from_raw_parts(v.as_ptr() as *const Vector<3>, v.len());
        let (v, v_old) = (cast(v), v_old.map(cast));
        let Factors {
            base,
            w,
            dw,
            offsets,
        } = view.factors(p, gradient, affine.then_some(xp));
        let offset = |a: usize, k: usize| offsets[a][k];
        let off0 = offsets[0];
        let (zero, minus0) = (_mm256_setzero_pd(), _mm256_set1_pd(-0.0));
        let (mut velocity, mut velocity_change) = (zero, zero);
        let (mut gradient_sum, mut affine_sum) = ([zero; 3], [zero; 3]);
        let mut k = [0usize; 3];
        let mut row = base;
        for _ in 0..W * W {
            assert!(row + W <= v.len() && v_old.is_none_or(|o| row + W <= o.len()));
            // From −0, as the portable gather.
            let (mut s_w, mut s_dw, mut s_wo, mut s_dv) = (minus0, minus0, minus0, minus0);
            for k0 in 0..W {
                let vi = load(v, row + k0);
                let (wk, dwk) = (w[0][k0], dw[0][k0]);
                s_w = add_scaled(s_w, wk, vi);
                if gradient {
                    s_dw = add_scaled(s_dw, dwk, vi);
                }
                if affine {
                    s_wo = add_scaled(s_wo, wk * off0[k0], vi);
                }
                if let Some(v_old) = v_old {
                    let dv = _mm256_sub_pd(vi, load(v_old, row + k0));
                    s_dv = add_scaled(s_dv, wk, dv);
                }
            }
            let mut c = 1.0;
            for a in 1..3 {
                c *= w[a][k[a]];
            }
            velocity = add_scaled(velocity, c, s_w);
            if v_old.is_some() {
                velocity_change = add_scaled(velocity_change, c, s_dv);
            }
            if gradient {
                gradient_sum[0] = add_scaled(gradient_sum[0], c, s_dw);
            }
            if affine {
                affine_sum[0] = add_scaled(affine_sum[0], c, s_wo);
            }
            for a in 1..3 {
                if gradient {
                    let mut c_a = 1.0;
                    for b in 1..3 {
                        c_a *= if a == b { dw[b][k[b]] } else { w[b][k[b]] };
                    }
                    gradient_sum[a] = add_scaled(gradient_sum[a], c_a, s_w);
                }
                if affine {
                    affine_sum[a] = add_scaled(affine_sum[a], c * offset(a, k[a]), s_w);
                }
            }
            view.next_row(&mut k, &mut row);
        }
        let columns = |sums: [__m256d; 3]| {
            let c = sums.map(|x| vector(x));
            Matrix::<3>::from_columns(&c)
        };
        let g = Gathered::<3> {
            velocity: vector(velocity),
            velocity_change: vector(velocity_change),
            affine: columns(affine_sum),
            gradient: columns(gradient_sum),
        };
        std::mem::transmute_copy(&g)
    }
}

/// `lo + hi` of the two nodes of a pair, after the sum `s` of the nodes before them.
#[inline(always)]
unsafe fn add_pair(s: Option<__m128d>, pair: __m256d) -> __m128d {
    // SAFETY: only this module's AVX2 kernels call this, inside `Lanes::wide`: the
    // processor has AVX2 and FMA.
    unsafe {
        let (lo, hi) = (
            _mm256_castpd256_pd128(pair),
            _mm256_extractf128_pd::<1>(pair),
        );
        match s {
            Some(s) => _mm_add_pd(_mm_add_pd(s, lo), hi),
            None => _mm_add_pd(lo, hi),
        }
    }
}

/// `s + a x`, lane by lane.
#[inline(always)]
unsafe fn add_scaled_2(s: __m128d, a: f64, x: __m128d) -> __m128d {
    // SAFETY: only this module's AVX2 kernels call this, inside `Lanes::wide`: the
    // processor has AVX2 and FMA.
    unsafe { _mm_add_pd(s, _mm_mul_pd(_mm_set1_pd(a), x)) }
}

#[inline(always)]
unsafe fn vector_2(x: __m128d) -> Vector<2> {
    // SAFETY: only this module's AVX2 kernels call this, inside `Lanes::wide`: the
    // processor has AVX2 and FMA.
    unsafe {
        let mut l = [0.0; 2];
        _mm_storeu_pd(l.as_mut_ptr(), x);
        Vector::<2>::new(l[0], l[1])
    }
}

/// [`StencilView::gather`](super::StencilView::gather) of a 2D view (`W ≤ 4`), as the
/// portable one. Two nodes of a row (two 2-vectors) share a register: their products with
/// the axis-0 factors `[w_k, w_k, w_{k+1}, w_{k+1}]` are taken at once, and the row sum adds
/// them in node order, `((w_0 v_0 + w_1 v_1) + w_2 v_2) + …`, which is the portable sum
/// from −0. The rows are weighted and added as the portable gather does, in 2-vectors.
///
/// # Safety
/// The processor has AVX2 and FMA (`D == 2` and `W ≤ 4` are asserted).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) unsafe fn gather_2d<const D: usize, const W: usize>(
    view: &TensorView<'_, D, W>,
    p: usize,
    xp: &Vector<D>,
    v: &[Vector<D>],
    v_old: Option<&[Vector<D>]>,
    affine: bool,
    gradient: bool,
) -> Gathered<D> {
    // SAFETY: the caller keeps the contract above (AVX2 and FMA present); the loads read
    // node velocities at indices of the stencil, which lie inside the node arrays.
    unsafe {
        assert!(D == 2 && (2..=4).contains(&W));
        // SAFETY (of the casts): `D == 2`, so each is the same type.
        let view = &*(view as *const TensorView<'_, D, W> as *const TensorView<'_, 2, W>);
        let xp = &*(xp as *const Vector<D> as *const Vector<2>);
        let cast =
            |v: &[Vector<D>]| std::slice::from_raw_parts(v.as_ptr() as *const f64, 2 * v.len());
        let (v, v_old) = (cast(v), v_old.map(cast));
        let Factors {
            base,
            w,
            dw,
            offsets,
        } = view.factors(p, gradient, affine.then_some(xp));
        // The axis-0 factors of the pairs of nodes and of the last node when `W` is odd.
        let wo: [f64; W] = std::array::from_fn(|k| w[0][k] * offsets[0][k]);
        let pair =
            |f: &[f64; W], j: usize| _mm256_set_pd(f[2 * j + 1], f[2 * j + 1], f[2 * j], f[2 * j]);
        let zero = _mm256_setzero_pd();
        let (mut w_pair, mut dw_pair, mut wo_pair) = ([zero; 2], [zero; 2], [zero; 2]);
        for j in 0..W / 2 {
            w_pair[j] = pair(&w[0], j);
            dw_pair[j] = pair(&dw[0], j);
            wo_pair[j] = pair(&wo, j);
        }
        let odd = W % 2 == 1;
        let single = |f: &[f64; W]| _mm_set1_pd(f[W - 1]);
        let (w_last, dw_last, wo_last) = (single(&w[0]), single(&dw[0]), single(&wo));
        let zero = _mm_setzero_pd();
        let (mut velocity, mut velocity_change) = (zero, zero);
        let (mut gradient_sum, mut affine_sum) = ([zero; 2], [zero; 2]);
        let mut row = base;
        for k1 in 0..W {
            assert!(2 * (row + W) <= v.len() && v_old.is_none_or(|o| 2 * (row + W) <= o.len()));
            let (mut s_w, mut s_dw, mut s_wo, mut s_dv) = (None, None, None, None);
            for j in 0..W / 2 {
                let at = 2 * (row + 2 * j);
                let vj = _mm256_loadu_pd(v.as_ptr().add(at));
                s_w = Some(add_pair(s_w, _mm256_mul_pd(w_pair[j], vj)));
                if gradient {
                    s_dw = Some(add_pair(s_dw, _mm256_mul_pd(dw_pair[j], vj)));
                }
                if affine {
                    s_wo = Some(add_pair(s_wo, _mm256_mul_pd(wo_pair[j], vj)));
                }
                if let Some(v_old) = v_old {
                    let dv = _mm256_sub_pd(vj, _mm256_loadu_pd(v_old.as_ptr().add(at)));
                    s_dv = Some(add_pair(s_dv, _mm256_mul_pd(w_pair[j], dv)));
                }
            }
            if odd {
                let at = 2 * (row + W - 1);
                let vl = _mm_loadu_pd(v.as_ptr().add(at));
                // `W ≥ 3` here, so every sum has its first pair.
                let add = |s: Option<__m128d>, f: __m128d, x: __m128d| {
                    Some(_mm_add_pd(s.unwrap(), _mm_mul_pd(f, x)))
                };
                s_w = add(s_w, w_last, vl);
                if gradient {
                    s_dw = add(s_dw, dw_last, vl);
                }
                if affine {
                    s_wo = add(s_wo, wo_last, vl);
                }
                if let Some(v_old) = v_old {
                    let dv = _mm_sub_pd(vl, _mm_loadu_pd(v_old.as_ptr().add(at)));
                    s_dv = add(s_dv, w_last, dv);
                }
            }
            let s_w = s_w.unwrap();
            let c = w[1][k1];
            velocity = add_scaled_2(velocity, c, s_w);
            if let Some(s_dv) = s_dv {
                velocity_change = add_scaled_2(velocity_change, c, s_dv);
            }
            if let Some(s_dw) = s_dw {
                gradient_sum[0] = add_scaled_2(gradient_sum[0], c, s_dw);
                gradient_sum[1] = add_scaled_2(gradient_sum[1], dw[1][k1], s_w);
            }
            if let Some(s_wo) = s_wo {
                affine_sum[0] = add_scaled_2(affine_sum[0], c, s_wo);
                affine_sum[1] = add_scaled_2(affine_sum[1], c * offsets[1][k1], s_w);
            }
            row += view.strides[1];
        }
        let columns = |sums: [__m128d; 2]| Matrix::<2>::from_columns(&sums.map(|x| vector_2(x)));
        let g = Gathered::<2> {
            velocity: vector_2(velocity),
            velocity_change: vector_2(velocity_change),
            affine: columns(affine_sum),
            gradient: columns(gradient_sum),
        };
        std::mem::transmute_copy(&g)
    }
}
