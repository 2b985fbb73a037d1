//! The conservative correction's system assembled on the nodes, and its multilevel
//! preconditioner.
//!
//! With `m` test polynomials per node (`Q = 1` at order 1; `1, z_1, …, z_D` at order 2, `z`
//! written in `(x − x_I)/h`) the operator of [`super::VcCorrection`]'s solve is, per direction,
//!
//! ```text
//! (K ζ)_I = A_I ζ_I − Σ_J B_IJ ζ_J,   A_I = Σ_p V_p w_Ip Q_I Q_Iᵀ,
//! B_IJ = Σ_p V_p w_Ip w_Jp / W_p Q_I(x_p) Q_J(x_p)ᵀ
//! ```
//!
//! (`w_Ip = |Ψ_I(x_p)|`, `W_p = Σ_J w_Jp`), an `m × m` block per pair of nodes. Applied
//! matrix-free it takes a gather and a scatter over every particle's stencil per
//! conjugate-gradient iteration; assembled once per step (one pass over the particles' stencil
//! pairs; at order ≥ 2 over half of them, `B_JI = B_IJᵀ` mirrored; at order 1 on a
//! tensor-product stencil per axis, [`tensor_rows`]), an iteration costs a
//! product with a sparse block matrix of `(2w − 1)^D` blocks per node, `w` nodes per axis of a
//! stencil. [`Multilevel`] preconditions it, so that the
//! iterations stop growing with the grid's width.

use super::lattice_rows::LatticeRows;
use crate::cpu::Lanes;
use crate::grid::{Bins, Grid, GridNodes, SharedSlice};
use crate::shape::{Stencils, TensorFactors};
use nalgebra::DMatrix;
use rayon::prelude::*;

/// The assembled system is used when it holds at most this many values (about 0.5 GB, twice
/// while it is assembled); larger ones (RK of order 2 in 3D on wide grids, whose `6^3`-node
/// stencils give rows of `11^3` blocks of `4 × 4`) are applied matrix-free.
const MAX_ASSEMBLED_VALUES: usize = 1 << 26;

/// The order-1 rows of `B` with the mean fit on a tensor-product stencil (B-splines on the
/// lattice), into `dense` (`block` entries a row, at the slots of `nodes`): per pair of nodes
/// `(I, J)` of a particle's stencil `c_p w_Ip w_Jp`, `c_p = V_p / Σ_I w_Ip`, a product of one
/// factor pair per axis, `w_Ip w_Jp = Π_a w_a[i_a] w_a[j_a]`. So the particles of one box
/// stencil (one bin's, sorted by first node as [`NodeOperator::assemble`] sorts them) are
/// summed per unordered pair of factors on each axis, `T = Σ_p c_p ⊗_a (w_a[i] w_a[j])_{i ≤ j}`
/// (`P = W(W + 1)/2` pairs an axis, `P^D` sums: 36 in 2D with three nodes an axis, 216 in 3D,
/// 1000 with four), and each pair of nodes reads its sum once per stencil: a particle costs
/// `P^D` products where the pairs of nodes cost `W^{2D}` (81, 729, 4096). `keys` are the
/// stencil slots' keys and storage steps, the block's centre and its size, as `assemble` forms
/// them; the rows go to `dense`. Clears `boxes` when a particle's support is not a box of nodes
/// with positive weights.
fn tensor_rows<const D: usize>(
    tensor: &TensorFactors<'_, D>,
    bins: &Bins<D>,
    nodes: &GridNodes<D>,
    volumes: &[f64],
    counted: &(impl Fn(usize) -> bool + Sync),
    keys: (&[isize], &[usize], usize, usize),
    out: (&mut [f64], &std::sync::atomic::AtomicBool),
) {
    // The width known to the compiler, which unrolls the loops over a stencil's nodes and
    // factor pairs; the same sums in the same order.
    match tensor.width {
        2 => tensor_rows_of::<D, 2>(tensor, bins, nodes, volumes, counted, keys, out),
        3 => tensor_rows_of::<D, 3>(tensor, bins, nodes, volumes, counted, keys, out),
        4 => tensor_rows_of::<D, 4>(tensor, bins, nodes, volumes, counted, keys, out),
        w => unreachable!("B-spline stencils of width {w}"),
    }
}

/// [`tensor_rows`] with `W` nodes per axis.
fn tensor_rows_of<const D: usize, const W: usize>(
    tensor: &TensorFactors<'_, D>,
    bins: &Bins<D>,
    nodes: &GridNodes<D>,
    volumes: &[f64],
    counted: &(impl Fn(usize) -> bool + Sync),
    (box_key, box_step, centre, block): (&[isize], &[usize], usize, usize),
    (dense, boxes): (&mut [f64], &std::sync::atomic::AtomicBool),
) {
    let (w, len) = (W, W.pow(D as u32));
    debug_assert_eq!(len, box_key.len());
    let pairs = w * (w + 1) / 2;
    // The unordered pair of factors `(i, j)` of one axis.
    let pair = |i: usize, j: usize| {
        let (lo, hi) = (i.min(j), i.max(j));
        lo * w - lo * (lo + 1) / 2 + hi
    };
    let local = |s: usize, a: usize| (s / w.pow(a as u32)) % w;
    // Per pair of stencil slots (s, j): the entry of row s and the sum it reads.
    let (mut entry, mut sum) = (vec![0u32; len * len], vec![0u32; len * len]);
    for s in 0..len {
        for j in 0..len {
            entry[s * len + j] = (centre as isize - box_key[s] + box_key[j]) as u32;
            sum[s * len + j] = (0..D)
                .map(|a| pair(local(s, a), local(j, a)) * pairs.pow(a as u32))
                .sum::<usize>() as u32;
        }
    }
    let sums = pairs.pow(D as u32);
    let rows = SharedSlice::new(dense);
    for colour in &bins.colours {
        colour.par_iter().for_each(|&b| {
            let mut particles: Vec<(usize, usize)> = bins.order
                [bins.occupied[b as usize].1.clone()]
            .iter()
            .map(|&p| p as usize)
            .filter(|&p| counted(p))
            .map(|p| (tensor.base(p), p))
            .collect();
            particles.sort_unstable();
            let mut total = vec![0.0; sums];
            // The outer products of the axes' pairs, axis by axis (`P^a` values after axis a).
            let (mut outer, mut next) = (vec![0.0; sums], vec![0.0; sums]);
            let mut factor_pairs = vec![0.0; pairs];
            // Per particle of the stencil whose support is not the whole box: its nonzero
            // factors, a bit per node of each axis.
            let mut partial: Vec<[u32; D]> = Vec::new();
            // Whether a particle of the stencil has the whole box in its support.
            let mut whole = false;
            let mut live = vec![false; len];
            let mut flush =
                |first: usize, total: &mut [f64], partial: &mut Vec<[u32; D]>, whole: &mut bool| {
                    // A node takes a row when some particle's weight there is not zero.
                    for (s, live) in live.iter_mut().enumerate() {
                        *live = *whole
                            || partial
                                .iter()
                                .any(|bits| (0..D).all(|a| bits[a] & (1 << local(s, a)) != 0));
                    }
                    for s in (0..len).filter(|&s| live[s]) {
                        let slot = nodes.slot(first + box_step[s]);
                        // SAFETY: the row belongs to a node that only this block writes in this
                        // colour (`Bins`); rows of different slots are disjoint ranges.
                        let r = unsafe { rows.range(slot * block, block) };
                        let (entry, sum) = (&entry[s * len..][..len], &sum[s * len..][..len]);
                        for (&e, &t) in entry.iter().zip(sum) {
                            r[e as usize] += total[t as usize];
                        }
                    }
                    total.fill(0.0);
                    partial.clear();
                    *whole = false;
                };
            let mut current = usize::MAX;
            for &(first, p) in &particles {
                let (f, df) = (tensor.values(p), tensor.derivatives(p));
                // Σ_I w_Ip = Π_a Σ_k w_a[k]; a zero factor with a nonzero derivative is a node
                // in the support without weight.
                let mut weight = 1.0;
                let mut bits = [0u32; D];
                for a in 0..D {
                    let (f, df) = (&f[a * w..(a + 1) * w], &df[a * w..(a + 1) * w]);
                    weight *= f.iter().sum::<f64>();
                    for k in 0..w {
                        if f[k] != 0.0 {
                            bits[a] |= 1 << k;
                        } else if df[k] != 0.0 {
                            boxes.store(false, std::sync::atomic::Ordering::Relaxed);
                        }
                    }
                }
                if weight == 0.0 {
                    continue;
                }
                if first != current {
                    if current != usize::MAX {
                        flush(current, &mut total, &mut partial, &mut whole);
                    }
                    current = first;
                }
                if bits.iter().all(|&b| b == (1 << w) - 1) {
                    whole = true;
                } else {
                    partial.push(bits);
                }
                // c_p ⊗_a (w_a[i] w_a[j]), then added to the stencil's sums.
                outer[0] = volumes[p] / weight;
                let mut size = 1;
                for a in 0..D {
                    let f = &f[a * w..(a + 1) * w];
                    // The pairs `i ≤ j` in the order `pair` numbers them.
                    let mut t = 0;
                    for i in 0..w {
                        for j in i..w {
                            factor_pairs[t] = f[i] * f[j];
                            t += 1;
                        }
                    }
                    if a + 1 == D {
                        for (t, &q) in total.chunks_exact_mut(size).zip(&factor_pairs) {
                            for (t, &o) in t.iter_mut().zip(&outer[..size]) {
                                *t += o * q;
                            }
                        }
                    } else {
                        for (n, &q) in next.chunks_exact_mut(size).zip(&factor_pairs) {
                            for (n, &o) in n.iter_mut().zip(&outer[..size]) {
                                *n = o * q;
                            }
                        }
                        size *= pairs;
                        std::mem::swap(&mut outer, &mut next);
                    }
                }
            }
            if current != usize::MAX {
                flush(current, &mut total, &mut partial, &mut whole);
            }
        });
    }
}

/// At order ≥ 2, the particles of one bin whose stencils hold the same nodes (sorted by their
/// first node: in practice the particles of one cell) are assembled together, up to this many at
/// a time: their blocks `c_p (w_Ip Q_I)(w_Jp Q_J)ᵀ` summed in registers, so that a row's memory
/// takes one update per batch instead of one per particle.
const ASSEMBLY_BATCH: usize = 8;

/// The particles of one stencil gathered for [`NodeOperator::assemble`] at order ≥ 2.
struct BoxBatch {
    /// The stencil's nodes, and how many particles the batch holds.
    nodes: Vec<usize>,
    n: usize,
    /// Per particle, `c_p = V_p / Σ_I w_Ip`.
    c: [f64; ASSEMBLY_BATCH],
    /// Per stencil slot, particle and polynomial: `w_Ip Q_a(x_p)` (zero off the support).
    u: Vec<f64>,
    /// Per stencil slot: its node's row and key (valid where `live`), and whether any particle
    /// of the batch has the node in its support.
    row: Vec<usize>,
    key: Vec<isize>,
    live: Vec<bool>,
}

/// At order 1, the particles of one bin whose stencils are the same box of nodes (in practice
/// the `2^D` particles nearest one node of a quadratic B-spline, or of one cell of a cubic one),
/// up to this many at a time: [`FactoredBatch`].
const FACTORED_BATCH: usize = 8;

/// The particles of one box stencil gathered for [`NodeOperator::assemble`] at order 1. A
/// particle's block is `c_p w_Ip w_Jp` with the mean fit, one product `a_Ip a_Jp` of the column
/// `a = √c_p w`; with the linear fit `c_p w_Ip w_Jp (1 + W_p u_Ip·u_Jp)`, the sum of `D + 1`,
/// the columns `√c_p w` and `√(c_p W_p) w u_k`. The batch's blocks are the sums of its columns'
/// products: each row takes them with the whole box at once, one update of the row's memory per
/// batch instead of one per particle (3D `bspline2` + VC1, 10^5 particles: the particles' pass
/// 80 → 52 ms; in 2D, with 4 particles a batch, 12.8 → 14.6 ms).
struct FactoredBatch {
    /// The box's first node (`usize::MAX` when empty), and how many columns the batch holds.
    first: usize,
    columns: usize,
    /// The columns (at most `FACTORED_BATCH (D + 1)`), each a value per stencil slot (zero
    /// off the support).
    a: Vec<f64>,
    /// Per stencil slot: its node's row (valid where `live`), and whether any particle of the
    /// batch has the node in its support.
    row: Vec<usize>,
    live: Vec<bool>,
}

/// The buffers of an assembled `K` (its packed rows and their lattice layout), handed from
/// one step's operator to the next so that their pages are mapped once (a fresh allocation of
/// tens of MB a step faults every page in again: a tenth of a 3D VC step).
#[derive(Debug, Clone, Default)]
pub(crate) struct OperatorStorage {
    value: Vec<f64>,
    column: Vec<u32>,
    laid: Vec<f64>,
}

/// `K` on the active nodes (slots): per slot a row of at most `(2w − 1)^D` blocks of `m × m`
/// values, packed at the front of its room of that many blocks.
pub(crate) struct NodeOperator<const D: usize> {
    /// Per row: the lattice multi-index of its node (of its aggregate on coarse levels).
    index: Vec<[i64; D]>,
    /// Test polynomials per node.
    m: usize,
    /// Per row: the diagonal block, `m × m` by rows. Its first entry (the constant
    /// polynomial's) is zero for a row without particles, which takes no part.
    diagonal: Vec<f64>,
    /// Per row (`m > 1`, and at order 1 with the linear fit): the moment matrix `A_I` (the
    /// reach at order 1; on coarse levels `Σ Pᵀ A P` over the aggregate), `m × m` by rows,
    /// which bounds the row's part of `K` from above.
    moment: Vec<f64>,
    /// Per row (`m > 1`): the inverse of `moment` that the smoother applies, or of its constant
    /// entry alone where it is singular (see [`block_inverse`]).
    inverse: Vec<f64>,
    /// How far (in nodes of this level, per axis) a row's columns reach.
    radius: usize,
    /// Blocks a row's room holds, `(2 radius + 1)^D`.
    block: usize,
    /// Per slot: how many blocks its row has.
    count: Vec<u32>,
    /// Per row room: the column slots, then the blocks.
    column: Vec<u32>,
    value: Vec<f64>,
    /// At order 1, the rows on their lattice box too, which [`NodeOperator::apply`] then
    /// takes (see [`LatticeRows`]).
    lattice: Option<LatticeRows>,
    /// A buffer for the lattice layout's values.
    spare: Vec<f64>,
    /// On the fine level, when every particle's support is a box of nodes with positive
    /// weights: per row, the slot of its lattice neighbour one node up each axis where a
    /// particle joins the two (`u32::MAX` where none does). See [`NodeOperator::bodies`].
    joined: Option<Vec<[u32; D]>>,
}

/// The lattice step of every entry of a row's room of `(2 radius + 1)^D` blocks, entry `e`
/// holding the digits of `e` in base `2 radius + 1` (axis 0 first), each less `radius`.
pub(super) fn entry_steps<const D: usize>(radius: usize) -> Vec<[i64; D]> {
    let span = 2 * radius + 1;
    (0..span.pow(D as u32))
        .map(|e| std::array::from_fn(|a| ((e / span.pow(a as u32)) % span) as i64 - radius as i64))
        .collect()
}

/// The inverse that a row's smoothing step applies: of its moment block `d` (`m × m`), or,
/// where that block is singular for the order (a node whose support holds too few particles,
/// as [`super::VC_MIN_RELATIVE_EIGENVALUE`] decides for the moment matrices), of its constant
/// entry alone.
fn block_inverse(d: &[f64], m: usize) -> Vec<f64> {
    let mut out = vec![0.0; m * m];
    if d[0] <= 0.0 {
        return out;
    }
    let a = DMatrix::from_row_slice(m, m, d);
    let eig = a.clone().symmetric_eigenvalues();
    match (eig.min() > super::VC_MIN_RELATIVE_EIGENVALUE * eig.max())
        .then(|| a.cholesky())
        .flatten()
    {
        Some(c) => {
            let inv = c.inverse();
            for i in 0..m {
                for j in 0..m {
                    out[i * m + j] = inv[(i, j)];
                }
            }
        }
        None => out[0] = 1.0 / d[0],
    }
    out
}

impl<const D: usize> NodeOperator<D> {
    /// Assembles `K` from the particles that `counted` admits, visited by the colours of `bins`
    /// (blocks of one colour write disjoint rows: the same bits with any number of threads).
    /// `moment[slot]` is `A_I` (`m × m`), `basis(p, node, q)` writes `Q_I(x_p)`; with the
    /// order-1 linear fit, `frame_offset(p, node)` is the node's offset `u_Ip` in the particle's
    /// frame (`None` for the mean fit). The
    /// polynomials of degree ≥ 1 of a `reduced` node (corrected to order 1 only) are left out:
    /// their rows and columns are zero. `None` when the stencils are not a box of `w^D` nodes,
    /// or the system would hold more than `MAX_ASSEMBLED_VALUES` values.
    #[allow(clippy::too_many_arguments)]
    pub fn assemble(
        grid: &Grid<D>,
        bins: &Bins<D>,
        stencils: &Stencils<D>,
        nodes: &GridNodes<D>,
        volumes: &[f64],
        (moment, reduced, m): (&[f64], &[bool], usize),
        basis: impl Fn(usize, usize, &mut [f64]) + Sync,
        frame_offset: Option<&(impl Fn(usize, usize) -> crate::Vector<D> + Sync)>,
        counted: impl Fn(usize) -> bool + Sync,
        tensor: Option<TensorFactors<'_, D>>,
        storage: OperatorStorage,
    ) -> Option<Self> {
        // The stencil's size: the factors' box where there are factors (the lists are then
        // not stored at order 1, `VcCorrection::reads_lists`).
        let len = tensor.map_or(stencils.len, |t| t.width.pow(D as u32));
        let width = (1..=len).find(|w| w.pow(D as u32) >= len)?;
        if width.pow(D as u32) != len {
            return None;
        }
        let span = 2 * width - 1;
        let block = span.pow(D as u32);
        let mm = m * m;
        let slots = nodes.active.len();
        if slots * block * mm > MAX_ASSEMBLED_VALUES {
            return None;
        }
        // A node's key: its multi-index relative to the stencil's, Σ_a k_a span^a, so that the
        // block entry of a pair (I, J) of one stencil is `key_J − key_I + centre`. Stencils
        // stored as the box in order (axis 0 fastest: B-splines) take the keys of their slots;
        // others (RK, which keeps only the nodes where the kernel is positive) from the nodes'
        // multi-indices.
        let strides = grid.strides();
        let local = |s: usize, a: usize| (s / width.pow(a as u32)) % width;
        let box_key: Vec<isize> = (0..len)
            .map(|s| {
                (0..D)
                    .map(|a| (local(s, a) * span.pow(a as u32)) as isize)
                    .sum()
            })
            .collect();
        let box_step: Vec<usize> = (0..len)
            .map(|s| (0..D).map(|a| local(s, a) * strides[a]).sum())
            .collect();
        let centre = (block - 1) / 2;
        // The node-index step of every block entry.
        let step: Vec<isize> = entry_steps::<D>(width - 1)
            .iter()
            .map(|d| (0..D).map(|a| d[a] as isize * strides[a] as isize).sum())
            .collect();
        // B, dense per row room.
        let OperatorStorage {
            value: mut dense,
            mut column,
            laid,
        } = storage;
        dense.clear();
        dense.resize(slots * block * mm, 0.0);
        // At order 1 the columns a particle adds to a factored batch: `√c w`, and with the
        // linear fit `√(c W) w u_k` too.
        let per = if frame_offset.is_some() { D + 1 } else { 1 };
        // Whether every particle's support is a box of nodes with positive weights.
        let boxes = std::sync::atomic::AtomicBool::new(true);
        // The mean fit on a tensor-product stencil: per axis (`tensor_rows`).
        let tensor = tensor.filter(|t| m == 1 && frame_offset.is_none() && t.width == width);
        if let Some(tensor) = tensor {
            let keys = (&box_key[..], &box_step[..], centre, block);
            let out = (&mut dense[..], &boxes);
            tensor_rows(&tensor, bins, nodes, volumes, &counted, keys, out);
        } else {
            let rows = SharedSlice::new(&mut dense);
            for colour in &bins.colours {
                colour.par_iter().for_each(|&b| {
                    let mut w = vec![0.0; len];
                    let mut row = vec![0usize; len];
                    let mut key = vec![0isize; len];
                    let mut q = vec![0.0; len * m];
                    let mut u = vec![crate::Vector::<D>::zeros(); len];
                    // The bin's particles by their stencil's first node (then index), so that
                    // the particles of one stencil come in a row and are assembled as a batch.
                    let mut particles: Vec<(usize, usize)> = bins.order
                        [bins.occupied[b as usize].1.clone()]
                    .iter()
                    .map(|&p| p as usize)
                    .filter(|&p| counted(p))
                    .map(|p| (stencils.of(p).0[0], p))
                    .collect();
                    particles.sort_unstable();
                    let mut batch = (m > 1).then(|| BoxBatch {
                        nodes: vec![0; len],
                        n: 0,
                        c: [0.0; ASSEMBLY_BATCH],
                        u: vec![0.0; len * ASSEMBLY_BATCH * m],
                        row: vec![0; len],
                        key: vec![0; len],
                        live: vec![false; len],
                    });
                    let capacity = FACTORED_BATCH * per;
                    let mut factored = (m == 1).then(|| FactoredBatch {
                        first: usize::MAX,
                        columns: 0,
                        a: vec![0.0; len * capacity],
                        row: vec![0; len],
                        live: vec![false; len],
                    });
                    // Adds the factored batch's blocks to its rows and empties it.
                    let mut sums = vec![0.0; len];
                    let mut flush_factored = |batch: &mut FactoredBatch| {
                        let n = batch.columns;
                        if n == 0 {
                            return;
                        }
                        for i in (0..len).filter(|&i| batch.live[i]) {
                            // Row i's blocks with the whole box, `Σ_k a_ik a_jk`, as runs along
                            // axis 0 (a slot off every support adds +0, which changes no sum).
                            sums.fill(0.0);
                            for column in batch.a.chunks_exact(len).take(n) {
                                let ai = column[i];
                                for (t, &aj) in sums.iter_mut().zip(column) {
                                    *t += ai * aj;
                                }
                            }
                            // SAFETY: as below.
                            let r = unsafe { rows.range(batch.row[i] * block, block) };
                            let base = (centre as isize - box_key[i]) as usize;
                            for (run, t) in sums.chunks_exact(width).enumerate() {
                                let e = base + box_key[run * width] as usize;
                                for (r, &t) in r[e..e + width].iter_mut().zip(t) {
                                    *r += t;
                                }
                            }
                        }
                        batch.columns = 0;
                        batch.first = usize::MAX;
                        batch.live.fill(false);
                    };
                    let mut uc = vec![0.0; m * ASSEMBLY_BATCH];
                    // Adds the batch's blocks to its rows and empties it.
                    let mut flush = |batch: &mut BoxBatch| {
                        let n = batch.n;
                        if n == 0 {
                            return;
                        }
                        let at = |s: usize, k: usize| (s * ASSEMBLY_BATCH + k) * m;
                        for i in (0..len).filter(|&i| batch.live[i]) {
                            for k in 0..n {
                                for a in 0..m {
                                    uc[a * ASSEMBLY_BATCH + k] = batch.c[k] * batch.u[at(i, k) + a];
                                }
                            }
                            // SAFETY: as below.
                            let r = unsafe { rows.range(batch.row[i] * block * mm, block * mm) };
                            let base = centre as isize - batch.key[i];
                            // `K` is symmetric: a row takes its blocks with the nodes of larger
                            // keys (its entries from the centre on); the others are mirrored
                            // from their rows after the pass.
                            let upper = |&j: &usize| batch.live[j] && batch.key[j] >= batch.key[i];
                            for j in (0..len).filter(upper) {
                                let e = (base + batch.key[j]) as usize;
                                let r = &mut r[e * mm..(e + 1) * mm];
                                let uj = &batch.u[at(j, 0)..at(j, 0) + n * m];
                                // The block sizes of order 2 (2D, 3D) known to the compiler,
                                // which unrolls the block; the same sums in the same order.
                                match m {
                                    3 => add_batch_block::<3>(m, n, &uc, uj, r),
                                    4 => add_batch_block::<4>(m, n, &uc, uj, r),
                                    _ => add_batch_block::<0>(m, n, &uc, uj, r),
                                }
                            }
                        }
                        batch.n = 0;
                        batch.live.fill(false);
                    };
                    for &(_, p) in &particles {
                        let (ns, vs, gs) = stencils.of(p);
                        let mut total = 0.0;
                        for s in 0..len {
                            w[s] = if crate::shape::in_support(vs[s], &gs[s]) {
                                row[s] = nodes.slot(ns[s]);
                                if m > 1 {
                                    basis(p, ns[s], &mut q[s * m..(s + 1) * m]);
                                } else if let Some(frame_offset) = frame_offset {
                                    u[s] = frame_offset(p, ns[s]);
                                }
                                vs[s].abs()
                            } else {
                                0.0
                            };
                            total += w[s];
                        }
                        if total == 0.0 {
                            continue;
                        }
                        let in_box = (0..len).all(|s| ns[s] == ns[0] + box_step[s]);
                        let unweighted =
                            |s: usize| w[s] == 0.0 && crate::shape::in_support(vs[s], &gs[s]);
                        if !in_box || (0..len).any(unweighted) {
                            boxes.store(false, std::sync::atomic::Ordering::Relaxed);
                        }
                        let c = volumes[p] / total;
                        if let Some(batch) = factored.as_mut().filter(|_| in_box) {
                            if batch.columns + per > capacity || batch.first != ns[0] {
                                flush_factored(batch);
                            }
                            batch.first = ns[0];
                            let (root_c, root_cw) = (c.sqrt(), (c * total).sqrt());
                            let a = &mut batch.a[batch.columns * len..][..per * len];
                            for s in 0..len {
                                if w[s] == 0.0 {
                                    for k in 0..per {
                                        a[k * len + s] = 0.0;
                                    }
                                    continue;
                                }
                                batch.live[s] = true;
                                batch.row[s] = row[s];
                                a[s] = root_c * w[s];
                                for k in 1..per {
                                    a[k * len + s] = root_cw * w[s] * u[s][k - 1];
                                }
                            }
                            batch.columns += per;
                            continue;
                        }
                        if in_box {
                            key.copy_from_slice(&box_key);
                        } else {
                            let first = grid.node_multi_index(ns[0]);
                            for s in (0..len).filter(|&s| w[s] != 0.0) {
                                let k = grid.node_multi_index(ns[s]);
                                key[s] = (0..D)
                                    .map(|a| {
                                        (k[a] - first[a]) as isize * span.pow(a as u32) as isize
                                    })
                                    .sum();
                            }
                        }
                        if let Some(batch) = batch.as_mut() {
                            if batch.n == ASSEMBLY_BATCH || (batch.n > 0 && batch.nodes != ns) {
                                flush(batch);
                            }
                            let k = batch.n;
                            if k == 0 {
                                batch.nodes.copy_from_slice(ns);
                            }
                            batch.c[k] = c;
                            for s in 0..len {
                                let at = (s * ASSEMBLY_BATCH + k) * m;
                                if w[s] == 0.0 {
                                    batch.u[at..at + m].fill(0.0);
                                    continue;
                                }
                                batch.live[s] = true;
                                batch.row[s] = row[s];
                                batch.key[s] = key[s];
                                for a in 0..m {
                                    batch.u[at + a] = w[s] * q[s * m + a];
                                }
                            }
                            batch.n += 1;
                            continue;
                        }
                        for i in 0..len {
                            if w[i] == 0.0 {
                                continue;
                            }
                            let ci = c * w[i];
                            // SAFETY: the row belongs to a node that only this block writes in
                            // this colour (`Bins`); rows of different slots are disjoint ranges.
                            let r = unsafe { rows.range(row[i] * block * mm, block * mm) };
                            let base = centre as isize - key[i];
                            for j in 0..len {
                                if w[j] == 0.0 {
                                    continue;
                                }
                                let e = (base + key[j]) as usize;
                                if m == 1 && frame_offset.is_none() {
                                    r[e] += ci * w[j];
                                    continue;
                                }
                                if m == 1 {
                                    r[e] += ci * w[j] * (1.0 + total * u[i].dot(&u[j]));
                                    continue;
                                }
                                let cij = ci * w[j];
                                let (qi, qj) = (&q[i * m..(i + 1) * m], &q[j * m..(j + 1) * m]);
                                let r = &mut r[e * mm..(e + 1) * mm];
                                for a in 0..m {
                                    let ca = cij * qi[a];
                                    for b in 0..m {
                                        r[a * m + b] += ca * qj[b];
                                    }
                                }
                            }
                        }
                    }
                    if let Some(batch) = batch.as_mut() {
                        flush(batch);
                    }
                    if let Some(batch) = factored.as_mut() {
                        flush_factored(batch);
                    }
                });
            }
        }
        if m > 1 {
            // Each row's blocks below its centre, the transposes of those its columns' rows
            // hold above theirs: entry `e > centre` of row `I` (column `J`) is entry
            // `2 centre − e` of row `J`. Each row reads its own upper entries and writes lower
            // entries of other rows, each of those written by one row only.
            let rows = SharedSlice::new(&mut dense);
            (0..slots).into_par_iter().for_each(|slot| {
                let node = nodes.active[slot] as isize;
                // SAFETY: the upper entries of a row are read by that row only, and no row
                // writes them; a lower entry `(J, 2 centre − e)` is written by row `I` alone.
                let row = unsafe {
                    rows.range((slot * block + centre + 1) * mm, (block - centre - 1) * mm)
                };
                for (t, b) in row.chunks_exact(mm).enumerate() {
                    if b.iter().all(|&x| x == 0.0) {
                        continue;
                    }
                    let e = centre + 1 + t;
                    let col = nodes.slot((node + step[e]) as usize);
                    // SAFETY: as above.
                    let mirror = unsafe { rows.range((col * block + 2 * centre - e) * mm, mm) };
                    for a in 0..m {
                        for c in 0..m {
                            mirror[c * m + a] = b[a * m + c];
                        }
                    }
                }
            });
        }
        // K = diag(A) − B, packed in place (entry `k` of a row from its block entry `e ≥ k`);
        // a reduced node's rows and columns of degree ≥ 1 zero.
        let mut count = vec![0u32; slots];
        column.clear();
        column.resize(slots * block, 0);
        let mut value = dense;
        // The lattice neighbours one node up each axis that a particle joins to the row.
        let up: [usize; D] = std::array::from_fn(|a| centre + span.pow(a as u32));
        let mut joined = vec![[u32::MAX; D]; slots];
        count
            .par_iter_mut()
            .zip(column.par_chunks_mut(block))
            .zip(value.par_chunks_mut(block * mm))
            .zip(joined.par_iter_mut())
            .enumerate()
            .for_each(|(slot, (((count, column), row), joined))| {
                let node = nodes.active[slot] as isize;
                for (joined, &e) in joined.iter_mut().zip(&up) {
                    if row[e * mm..(e + 1) * mm].iter().any(|&x| x != 0.0) {
                        *joined = nodes.slot((node + step[e]) as usize) as u32;
                    }
                }
                let mut k = 0;
                if m == 1 {
                    // The same as below with blocks of one value (no reduced rows).
                    for e in 0..block {
                        let b = row[e];
                        if e != centre && b == 0.0 {
                            continue;
                        }
                        row[k] = if e == centre { moment[slot] - b } else { -b };
                        column[k] = nodes.slot((node + step[e]) as usize) as u32;
                        k += 1;
                    }
                    *count = k as u32;
                    return;
                }
                for e in 0..block {
                    if e != centre && row[e * mm..(e + 1) * mm].iter().all(|&x| x == 0.0) {
                        continue;
                    }
                    let col = nodes.slot((node + step[e]) as usize);
                    for i in 0..mm {
                        let b = row[e * mm + i];
                        let (a, c) = (i / m, i % m);
                        row[k * mm + i] = if (a > 0 && reduced[slot]) || (c > 0 && reduced[col]) {
                            0.0
                        } else if e == centre {
                            moment[slot * mm + i] - b
                        } else {
                            -b
                        };
                    }
                    column[k] = col as u32;
                    k += 1;
                }
                *count = k as u32;
            });
        let index = nodes
            .active
            .par_iter()
            .map(|&n| grid.node_multi_index(n))
            .collect();
        // The diagonal block: the row's entry at its own slot.
        let diagonal: Vec<f64> = (0..slots)
            .into_par_iter()
            .flat_map_iter(|slot| {
                let start = slot * block;
                let e = (0..count[slot] as usize)
                    .find(|&e| column[start + e] as usize == slot)
                    .expect("a row holds its diagonal block");
                value[(start + e) * mm..(start + e + 1) * mm].to_vec()
            })
            .collect();
        // The moment blocks, a reduced node's degree ≥ 1 part left out as in K.
        let moment = if m > 1 {
            moment
                .par_chunks_exact(mm)
                .zip(reduced.par_iter())
                .flat_map_iter(|(a, &reduced)| {
                    (0..mm).map(move |i| if reduced && i != 0 { 0.0 } else { a[i] })
                })
                .collect()
        } else {
            Vec::new()
        };
        let mut operator = NodeOperator::new(
            index,
            (m, diagonal, moment),
            width - 1,
            block,
            (count, column, value),
        );
        operator.spare = laid;
        operator.joined = boxes.into_inner().then_some(joined);
        Some(operator)
    }

    fn new(
        index: Vec<[i64; D]>,
        (m, diagonal, moment): (usize, Vec<f64>, Vec<f64>),
        radius: usize,
        block: usize,
        (count, column, value): (Vec<u32>, Vec<u32>, Vec<f64>),
    ) -> Self {
        let inverse = if m > 1 {
            moment
                .par_chunks_exact(m * m)
                .flat_map_iter(|d| block_inverse(d, m))
                .collect()
        } else {
            Vec::new()
        };
        NodeOperator {
            index,
            m,
            diagonal,
            moment,
            inverse,
            radius,
            block,
            count,
            column,
            value,
            lattice: None,
            spare: Vec::new(),
            joined: None,
        }
    }

    /// The connected bodies of the rows that particles join, numbered as
    /// [`super::bodies`] numbers them, from the rows' lattice neighbours: when every support is
    /// a box, two nodes share a particle exactly when a chain of neighbours one node apart, each
    /// pair sharing a particle, joins them (a box is joined along its axes), so this visits `D`
    /// pairs a row instead of every particle's stencil. `None` unless [`NodeOperator::assemble`]
    /// found every support a box.
    pub fn bodies(&self) -> Option<Vec<usize>> {
        let joined = self.joined.as_ref()?;
        let rows = self.rows();
        Some(super::bodies(
            rows,
            rows,
            |i, visit: &mut dyn FnMut(usize)| {
                visit(i);
                for &j in joined[i].iter().filter(|&&j| j != u32::MAX) {
                    visit(j as usize);
                }
            },
        ))
    }

    /// Lays the rows out on their lattice box for the products, at order 1 where they fill
    /// enough of it ([`LatticeRows::new`]); the packed rows stay for the coarse levels' sums.
    fn lay_out(&mut self) {
        if self.m == 1 {
            self.lattice = LatticeRows::new(
                &self.index,
                self.radius,
                self.block,
                (&self.count, &self.column, &self.value),
                Lanes::detect(),
                std::mem::take(&mut self.spare),
            );
        }
    }

    /// Adds the damping `d_I A_I` of [`super::VC_REGULARISATION`] to the diagonal blocks (the
    /// constant entry alone on the `reduced` rows, which are corrected to order 1), and
    /// `(1 + d_I) A_I` to the moment blocks that bound the rows from above, so that the smoother
    /// and the coarse levels built from this operator see it.
    pub fn add_damping(&mut self, damping: &[f64], reduced: &[bool]) {
        let (m, mm) = (self.m, self.m * self.m);
        for (slot, &d) in damping.iter().enumerate() {
            if d == 0.0 || self.diagonal[slot * mm] <= 0.0 {
                continue;
            }
            let a: Vec<f64> = self.moment[slot * mm..(slot + 1) * mm].to_vec();
            let entries = if reduced[slot] { 1 } else { m };
            let start = slot * self.block;
            let n = self.count[slot] as usize;
            let e = (0..n)
                .find(|&e| self.column[start + e] as usize == slot)
                .expect("a row holds its diagonal block");
            let value = &mut self.value[(start + e) * mm..(start + e + 1) * mm];
            let diagonal = &mut self.diagonal[slot * mm..(slot + 1) * mm];
            for i in 0..entries {
                for j in 0..entries {
                    value[i * m + j] += d * a[i * m + j];
                    diagonal[i * m + j] += d * a[i * m + j];
                }
            }
            let moment = &mut self.moment[slot * mm..(slot + 1) * mm];
            moment.iter_mut().for_each(|v| *v *= 1.0 + d);
            let inverse = block_inverse(moment, m);
            self.inverse[slot * mm..(slot + 1) * mm].copy_from_slice(&inverse);
        }
    }

    /// Rows (nodes, or aggregates).
    fn rows(&self) -> usize {
        self.index.len()
    }

    /// `out = K ζ` for `D` directions stored per slot (`ζ[(slot * D + k) * m + j]`).
    pub fn apply(&self, zeta: &[f64], out: &mut [f64]) {
        if let Some(lattice) = &self.lattice {
            return lattice.apply::<D>(zeta, out);
        }
        let (m, mm) = (self.m, self.m * self.m);
        let per = m * D;
        out.par_chunks_exact_mut(per)
            .enumerate()
            .for_each(|(slot, o)| {
                let start = slot * self.block;
                let n = self.count[slot] as usize;
                if m == 1 {
                    let mut sum = [0.0; D];
                    for (&c, &v) in self.column[start..start + n]
                        .iter()
                        .zip(&self.value[start..start + n])
                    {
                        let z = &zeta[c as usize * D..(c as usize + 1) * D];
                        for k in 0..D {
                            sum[k] += v * z[k];
                        }
                    }
                    o.copy_from_slice(&sum);
                    return;
                }
                let (column, value) = (
                    &self.column[start..start + n],
                    &self.value[start * mm..(start + n) * mm],
                );
                // The block sizes of order 2 (2D, 3D) and 3 (2D) with the size known to the
                // compiler, which unrolls the blocks' products; the same sums in the same order.
                match m {
                    3 => block_row::<D, 3>(column, value, zeta, o),
                    4 => block_row::<D, 4>(column, value, zeta, o),
                    6 => block_row::<D, 6>(column, value, zeta, o),
                    _ => {
                        o.fill(0.0);
                        for (e, &c) in column.iter().enumerate() {
                            let v = &value[e * mm..(e + 1) * mm];
                            let z = &zeta[c as usize * per..(c as usize + 1) * per];
                            for k in 0..D {
                                for a in 0..m {
                                    let v = &v[a * m..(a + 1) * m];
                                    o[k * m + a] +=
                                        (0..m).map(|b| v[b] * z[k * m + b]).sum::<f64>();
                                }
                            }
                        }
                    }
                }
            });
    }
}

/// One block of an order-≥ 2 batch's flush in [`NodeOperator::assemble`]:
/// `r[a M + b] += Σ_k uc[a B + k] u_j[k M + b]` over the batch's `n` particles (`B` =
/// `ASSEMBLY_BATCH`), with `M` known to the compiler (`0`: the block size `m`), as
/// `Supports::fit_of` takes it.
#[inline(always)]
fn add_batch_block<const M: usize>(m: usize, n: usize, uc: &[f64], uj: &[f64], r: &mut [f64]) {
    let m = if M > 0 { M } else { m };
    for a in 0..m {
        let ua = &uc[a * ASSEMBLY_BATCH..a * ASSEMBLY_BATCH + n];
        for b in 0..m {
            let t: f64 = (0..n).map(|k| ua[k] * uj[k * m + b]).sum();
            r[a * m + b] += t;
        }
    }
}

/// One row of [`NodeOperator::apply`] with `M × M` blocks: `o = Σ_e V_e ζ_{column_e}` per
/// direction.
#[inline(always)]
fn block_row<const D: usize, const M: usize>(
    column: &[u32],
    value: &[f64],
    zeta: &[f64],
    o: &mut [f64],
) {
    let mut sum = [[0.0; M]; D];
    for (&c, v) in column.iter().zip(value.chunks_exact(M * M)) {
        let z = &zeta[c as usize * M * D..(c as usize + 1) * M * D];
        for k in 0..D {
            for a in 0..M {
                sum[k][a] += (0..M).map(|b| v[a * M + b] * z[k * M + b]).sum::<f64>();
            }
        }
    }
    for k in 0..D {
        o[k * M..(k + 1) * M].copy_from_slice(&sum[k]);
    }
}

/// Jacobi's damping in the smoother: at order 1 `D⁻¹K`'s eigenvalues lie in [0, 2] (each row's
/// off-diagonal entries are negative and sum to minus its diagonal), so 2/3 damps the upper half
/// of the spectrum by at least 3 and keeps the V-cycle positive definite.
const JACOBI_DAMPING: f64 = 2.0 / 3.0;

/// The damping of the moment-block smoother at order ≥ 2 (`A⁻¹K`'s eigenvalues lie in [0, 1]).
const MOMENT_DAMPING: f64 = 1.0;

/// Jacobi sweeps before and after the coarse correction at order 1.
const SMOOTHING_SWEEPS: usize = 2;

/// Moment-block sweeps before and after the coarse correction at order ≥ 2. A sweep after the
/// first costs a product with the fine `K` (rows of `(2w − 1)^D` blocks), so one sweep halves a
/// V-cycle's fine products (four to two) for more iterations: RK2 + VC2 on the throughput
/// example's 2D block (10^4 particles, the default rule) 28 iterations a step against 23, the
/// step 14 % faster; the manufactured solution's errors within 0.2 % (BENCHMARKS.md).
const SMOOTHING_SWEEPS_HIGHER: usize = 1;

/// The coarse correction's weight. A piecewise-constant prolongation gives coarse functions of
/// too much energy, so the plain correction (1) undershoots; over-correcting is the usual
/// remedy of unsmoothed aggregation (Braess 1995; Notay's AGMG). The two-grid correction stays a
/// contraction in `K`'s norm for weights below 2. Conjugate-gradient iterations per step on the
/// throughput example's block (10^5 particles, quadratic B-spline + VC1, 2 sweeps): 2D 39–45
/// with 1, 18–20 with 1.5, 12 with 1.8, 11 with 2; 3D 17–21, 12–14, 12, 12.
const COARSE_WEIGHT: f64 = 1.8;

/// The same at order ≥ 2, with the polynomial prolongation and the W-cycle
/// (`COARSE_VISITS_HIGHER`): iterations per step of RK2 + VC2 on the throughput example's 2D
/// block (10^4 particles), 20–21 with 1, 17 with 1.2, 15–16 with 1.4, 14 with 1.6, 13 with 1.8,
/// 16–17 with 2; the step with 1.6 0.95 of that with 1.4. (In a V-cycle, on the manufactured
/// solution's box at 16 cells: 27 with 1, 19 with 1.4, 20–21 with 1.8.)
const COARSE_WEIGHT_HIGHER: f64 = 1.6;

/// At order ≥ 2, each level below the fine one is cycled this many times per visit of the level
/// above (a W-cycle: the second from the residual the first leaves), so that the coarse
/// correction, weak with pairs of nodes and an unsmoothed prolongation, is solved better than
/// one V-cycle does; a level's cost is a quarter (2D) or an eighth (3D) of the one above.
/// RK2 + VC2, one thread, the default rule, iterations per step with one visit against two:
/// the throughput example's 2D block (10^4 particles) 27–28 against 14, the step 0.861 of the
/// V-cycle's (BENCHMARKS.md); the manufactured solution's box on quarter points, 64 cells
/// (weight 1.4), 26.7 against 14, the run 297 against 249 s, L2 3.324e-5 and 3.321e-5 (exact
/// 3.322e-5); at 32 cells 8 against 5 (jittered 11 against 7), the run 0.994 of the V-cycle's.
/// Three visits took 11–12 iterations, no faster. At order 1 two visits took 3 iterations a step
/// instead of 4 (2D `bspline2` + VC1, 10^5 particles) and the step was no faster (1.008).
const COARSE_VISITS_HIGHER: usize = 2;

/// At order 1 the V-cycle is used when the fine level has at least this many rows per axis
/// (`rows^(1/D)`), see [`Multilevel::pays`]. One thread, `throughput --method bspline2 --vc`,
/// ms a step with the node blocks against the V-cycle: 3D 10^5 particles (26 rows across) 457
/// against 392, 2D 6 400 (about 42) 15.2–16.4 against 7.6–9.4, 2D 2 500 (about 28) 4.6–5.1
/// against 3.3–3.4; from 12 rows the V-cycle was slower (3D 10 648 particles, 40 against 48; 2D
/// 1 024, 1.7–2.4 against 2.9–4.0).
const MULTILEVEL_WIDTH: f64 = 20.0;

/// Rows whose diagonal is below this fraction of the largest (nodes that particles barely reach)
/// are preconditioned by their diagonal alone, outside the V-cycle.
const WEAK_ROW: f64 = 1e-3;

/// At order ≥ 2, the coarsest level's eigenvalues below this fraction of the largest are taken
/// as its null space. The polynomials' are round-off (1e-16); the coarsest level also has
/// near-null directions between 1e-10 and 1e-6 (6e-9, 5e-8 at a body's corners; none between
/// 1e-6 and 1e-4: a threshold of 1e-6 changed no iteration), which the V-cycle inverts. Left to
/// the conjugate gradients (a threshold of 1e-4), each took its own iterations and the residual
/// climbed back while it did: exact solves (1e-12), iterations per step, 1e-4 against 1e-10:
/// the 2D benchmark block
/// (`throughput --method rk2 --vc --particles 10000`) 88 against 58–61, the manufactured
/// solution's box at 16 cells 18 against 11 (quarter points) and 26 against 13 (jittered), at
/// 32 cells 41 against 24 and 63 against 32, with the same errors to four digits and no
/// restart, and the RK2 + VC2 mirror-symmetry and checkpoint tests hold.
const COARSEST_EIGENVALUE: f64 = 1e-10;

/// The same for order 1 with the linear fit, whose coarse levels carry `1, Z`: at 1e-10 its
/// solve on the jittered box of 80 cells did not converge in 2000 iterations (41 at 1e-4).
const COARSEST_EIGENVALUE_LINEAR_FIT: f64 = 1e-4;

/// The coarsest level is solved directly when it has at most this many unknowns per direction
/// (rows times test polynomials).
const COARSEST_ROWS: usize = 400;

/// A multilevel preconditioner: aggregation of 2^D lattice neighbours per level, Galerkin coarse
/// operators `Pᵀ K P`, damped block-Jacobi smoothing, and a dense factor of the coarsest level.
/// The prolongation `P` re-expands an aggregate's polynomial about each of its nodes (at order 1
/// it is piecewise constant with the mean fit; with the linear fit, whose null space is the linear
/// fields, the coarse levels carry `1, Z` per aggregate), so that every level holds `K`'s null
/// space over a whole body. One cycle with as many sweeps after as before the coarse
/// correction is a fixed symmetric positive semi-definite operator, as conjugate gradients need:
/// a V-cycle at order 1, a W-cycle at order ≥ 2 (`COARSE_VISITS_HIGHER`).
/// `K`'s iterations with the node blocks alone grow with the grid's width (about 450 at 160
/// nodes across with the mean fit); with the V-cycle they do not. The linear fit's `K` weighs a
/// field's departure from linear, a fourth-order operator (node blocks: 80 iterations at 20
/// cells, over 2000 at 160), and its V-cycle's iterations still grow: 41 at 80 cells, 108 at
/// 160 (cubic B-spline + VC1, the test `first_order_solve_iterations_grow_slowly_with_the_linear_fit`;
/// piecewise-constant coarse levels took 134 and 287, quadratic ones 67 and 215, a W-cycle
/// 30 and 60 at twice the cost per level).
pub(crate) struct Multilevel<const D: usize> {
    /// Per fine row: its diagonal if the row is weak (preconditioned by its diagonal block
    /// alone), else 0.
    weak: Vec<f64>,
    /// Per fine row: whether its node is corrected to order 1 only (its polynomials of
    /// degree ≥ 1 left out).
    reduced: Vec<bool>,
    /// The operators, finest first.
    levels: Vec<NodeOperator<D>>,
    /// Per level but the coarsest: how its rows make the next level's.
    aggregation: Vec<Aggregation>,
    /// The coarsest level's dense factor (its rows regularised by `1e-10` of their diagonal:
    /// `K` is singular along the polynomials of degree < n over every body).
    coarsest: Option<nalgebra::Cholesky<f64, nalgebra::Dyn>>,
    /// Per row of the coarsest level: its connected body (`usize::MAX` for a row without
    /// particles), and the number of bodies.
    body: Vec<usize>,
    bodies: usize,
    /// At order ≥ 2, the coarsest level's pseudo-inverse, `V diag(1/λ) Vᵀ` over the
    /// eigenvalues above `COARSEST_EIGENVALUE` of the largest, dense (its null space holds the
    /// polynomials of degree < n over every body, and of a body with nodes corrected to order 1
    /// only the constants: the eigenvalues find which).
    pseudo_inverse: Option<DMatrix<f64>>,
}

/// The coefficients of the monomial `f` of `Z = (x − x_c)/H` re-expanded about a point `d H`
/// away in a scale `s H`: `(d + s z)^f = Σ_e P[e][f] z^e`, for the `exponents` (closed under
/// lowering any exponent, as complete bases are). `m × m` by rows.
fn re_expansion<const D: usize>(exponents: &[[u32; D]], d: [f64; D], s: f64) -> Vec<f64> {
    let m = exponents.len();
    let binomial =
        |n: u32, k: u32| -> f64 { (0..k).fold(1.0, |c, i| c * (n - i) as f64 / (i + 1) as f64) };
    let mut out = vec![0.0; m * m];
    for (e, ee) in exponents.iter().enumerate() {
        for (f, ff) in exponents.iter().enumerate() {
            if (0..D).all(|a| ee[a] <= ff[a]) {
                out[e * m + f] = (0..D)
                    .map(|a| {
                        binomial(ff[a], ee[a])
                            * d[a].powi((ff[a] - ee[a]) as i32)
                            * s.powi(ee[a] as i32)
                    })
                    .product();
            }
        }
    }
    out
}

/// Aggregates along a row of `n` lattice nodes (each node's aggregate, numbered from the low
/// end), their own mirror image about the row's centre: pairs of neighbours, and of an odd
/// count the middle node with its two neighbours, and where the count on each side of those
/// three is odd, the three nodes at each end together. A body symmetric about a node plane then
/// gets a symmetric V-cycle: pairs counted from one end (`k div 2`) put the plane's node with
/// one of its neighbours, and a solve stopped at 1e-4 left the drop of
/// `tests/vc_conservation.rs` 3.5e-6 off symmetry (5.5e-13 with these). Used at order ≥ 2
/// (RK2 + VC2 on the throughput example's 2D block: 93 iterations a step against 90 with pairs
/// from one end). At order 1 with the mean fit they took 17 iterations a step where pairs from
/// one end take 12 (2D `bspline2` + VC1, 10^5 particles, 161 nodes across; 16–17 with coarse
/// weights 1.6 to 2, 17 with the middle node alone), so order 1 keeps pairs counted from one end.
fn mirrored_pairs(n: usize) -> Vec<usize> {
    if n.is_multiple_of(2) {
        return (0..n).map(|t| t / 2).collect();
    }
    // The nodes below the middle three.
    let side = (n / 2).saturating_sub(1);
    if side == 1 {
        return vec![0; n];
    }
    let low = |t: usize| match side % 2 {
        0 => t / 2,
        _ => t.saturating_sub(1) / 2,
    };
    let below = side / 2;
    (0..n)
        .map(|t| {
            if t < side {
                low(t)
            } else if t < side + 3 {
                below
            } else {
                2 * below - low(n - 1 - t)
            }
        })
        .collect()
}

/// A level's rows' positions along each axis, in nodes of the fine grid: `position[a][t]` is
/// that of the rows whose multi-index along `a` is `lowest[a] + t`.
struct Lattice<const D: usize> {
    lowest: [i64; D],
    position: [Vec<f64>; D],
}

impl<const D: usize> Lattice<D> {
    /// The fine level's: its nodes, over the box of those with particles.
    fn of_nodes(fine: &NodeOperator<D>) -> Self {
        let mm = fine.m * fine.m;
        let active = || (0..fine.rows()).filter(|&i| fine.diagonal[i * mm] > 0.0);
        let lowest = std::array::from_fn(|a| active().map(|i| fine.index[i][a]).min().unwrap_or(0));
        let highest: [i64; D] =
            std::array::from_fn(|a| active().map(|i| fine.index[i][a]).max().unwrap_or(-1));
        Lattice {
            lowest,
            position: std::array::from_fn(|a| (lowest[a]..=highest[a]).map(|k| k as f64).collect()),
        }
    }
}

/// A level's aggregates along one axis: each of its nodes' aggregate (numbered from `lowest`),
/// its offset from the aggregate's centre in the next level's spacing, and the aggregates'
/// centres.
struct AxisAggregates {
    aggregate: Vec<usize>,
    offset: Vec<f64>,
    centre: Vec<f64>,
    lowest: i64,
}

/// How a level's rows make the next level's: each row's aggregate (`u32::MAX` for a row
/// without particles, which takes no part) and `P`'s block.
struct Aggregation {
    parent: Vec<u32>,
    /// Each aggregate's rows in row order: `children[first[a]..first[a + 1]]`.
    first: Vec<usize>,
    children: Vec<usize>,
    /// Per row: which of `prolongation`'s blocks is its.
    child: Vec<u16>,
    /// Per offset of a row from its aggregate's centre, `P`'s `mc × mc` block: row `e` a
    /// node's polynomial, column `f` the aggregate's.
    prolongation: Vec<Vec<f64>>,
}

impl Aggregation {
    fn block(&self, row: usize) -> &[f64] {
        &self.prolongation[self.child[row] as usize]
    }

    /// The rows of aggregate `a`, in row order.
    fn children(&self, a: usize) -> &[usize] {
        &self.children[self.first[a]..self.first[a + 1]]
    }
}

impl<const D: usize> NodeOperator<D> {
    /// The Galerkin operator of aggregates of lattice neighbours (along each axis
    /// [`mirrored_pairs`] with `mirrored`, else pairs counted from one end), each row's
    /// aggregate and `P`'s block, and the next level's lattice. `lattice` holds this level's
    /// rows' positions per axis (in nodes of the fine grid), `spacing` the next level's scale
    /// in the same unit, and `exponents` the next level's polynomials; a row of this level with
    /// `m ≤ mc` polynomials (its exponents the first `m` of the coarse ones) takes the first `m`
    /// rows of its block.
    fn coarsen(
        &self,
        lattice: &Lattice<D>,
        spacing: f64,
        exponents: &[[u32; D]],
        mirrored: bool,
    ) -> (NodeOperator<D>, Aggregation, Lattice<D>) {
        let (m, mm) = (self.m, self.m * self.m);
        let mc = exponents.len();
        let mcc = mc * mc;
        let rows = self.rows();
        // Per axis: each node's aggregate and its offset from the aggregate's centre.
        // Pairs keep the lattice's global numbering (node `k` in aggregate `k div 2`), so
        // that every level is a uniform lattice whose node `k` sits at `s k + (s − 1)/2`, `s`
        // its spacing; mirrored aggregates are numbered from the low end, their centres the
        // means of their nodes'.
        let axes: [AxisAggregates; D] = std::array::from_fn(|a| {
            let position = &lattice.position[a];
            let (aggregate, lowest) = match mirrored {
                true => (mirrored_pairs(position.len()), 0),
                false => {
                    let lowest = lattice.lowest[a];
                    let base = lowest.div_euclid(2);
                    let aggregate = (0..position.len() as i64)
                        .map(|t| ((lowest + t).div_euclid(2) - base) as usize)
                        .collect();
                    (aggregate, base)
                }
            };
            let count = aggregate.last().map_or(0, |&g| g + 1);
            let centre: Vec<f64> = match mirrored {
                true => {
                    let mut sums = vec![(0.0, 0.0); count];
                    for (&g, &x) in aggregate.iter().zip(position) {
                        sums[g] = (sums[g].0 + x, sums[g].1 + 1.0);
                    }
                    sums.iter().map(|&(s, n)| s / n).collect()
                }
                false => (0..count)
                    .map(|g| spacing * (lowest + g as i64) as f64 + (spacing - 1.0) / 2.0)
                    .collect(),
            };
            let offset = aggregate
                .iter()
                .zip(position)
                .map(|(&g, &x)| (x - centre[g]) / spacing)
                .collect();
            AxisAggregates {
                aggregate,
                offset,
                centre,
                lowest,
            }
        });
        let at = |i: usize, a: usize| (self.index[i][a] - lattice.lowest[a]) as usize;
        // The aggregates numbered in the order their first rows come, through a table over
        // the box of aggregates (`place`); the offsets' kinds (a few) by search.
        let counts: [usize; D] = std::array::from_fn(|a| axes[a].centre.len());
        let place = |key: &[i64; D]| -> usize {
            (0..D)
                .rev()
                .fold(0, |n, a| n * counts[a] + (key[a] - axes[a].lowest) as usize)
        };
        let mut numbers = vec![u32::MAX; counts.iter().product()];
        let mut kinds = Vec::<[u64; D]>::new();
        let mut index = Vec::new();
        let mut prolongation = Vec::new();
        let mut child = vec![0u16; rows];
        let parent: Vec<u32> = (0..rows)
            .map(|i| {
                if self.diagonal[i * mm] <= 0.0 {
                    return u32::MAX;
                }
                let key: [i64; D] =
                    std::array::from_fn(|a| axes[a].lowest + axes[a].aggregate[at(i, a)] as i64);
                let offset: [f64; D] = std::array::from_fn(|a| axes[a].offset[at(i, a)]);
                let bits = offset.map(f64::to_bits);
                child[i] = match kinds.iter().position(|k| *k == bits) {
                    Some(kind) => kind as u16,
                    None => {
                        kinds.push(bits);
                        prolongation.push(re_expansion(exponents, offset, 0.5));
                        prolongation.len() as u16 - 1
                    }
                };
                let number = &mut numbers[place(&key)];
                if *number == u32::MAX {
                    index.push(key);
                    *number = index.len() as u32 - 1;
                }
                *number
            })
            .collect();
        // Each aggregate's rows in row order (a counting sort), so that its coarse row can be
        // summed on its own in the order of the rows.
        let coarse = index.len();
        let mut first = vec![0usize; coarse + 1];
        for &a in parent.iter().filter(|&&a| a != u32::MAX) {
            first[a as usize + 1] += 1;
        }
        for a in 0..coarse {
            first[a + 1] += first[a];
        }
        let mut children = vec![0usize; first[coarse]];
        let mut next = first.clone();
        for (i, &a) in parent.iter().enumerate().filter(|(_, &a)| a != u32::MAX) {
            children[next[a as usize]] = i;
            next[a as usize] += 1;
        }

        let aggregation = Aggregation {
            parent,
            first,
            children,
            child,
            prolongation,
        };
        let children_of = |a: usize| aggregation.children(a);
        let parent = &aggregation.parent;
        let child = |i: usize| -> &[f64] { aggregation.block(i) };
        // How far the aggregates of rows `radius` apart can be.
        let radius = (0..D)
            .flat_map(|a| {
                let g = &axes[a].aggregate;
                (0..g.len()).flat_map(move |t| {
                    (t..g.len().min(t + self.radius + 1)).map(move |u| g[u] - g[t])
                })
            })
            .max()
            .unwrap_or(0);
        let span = 2 * radius + 1;
        let block = span.pow(D as u32);
        let centre = (block - 1) / 2;
        // An aggregate's place on the lattice of coarse rows, `Σ_k index_k span^k`, so that the
        // entry of aggregates (a, b) is `place_b − place_a + centre`; per row of this level,
        // its aggregate's (`None` for a row without one).
        let on_rows =
            |key: &[i64; D]| -> i64 { (0..D).map(|k| key[k] * span.pow(k as u32) as i64).sum() };
        let row_place: Vec<Option<i64>> = parent
            .iter()
            .map(|&b| (b != u32::MAX).then(|| on_rows(&index[b as usize])))
            .collect();
        // Per aggregate `a`, `Σ_{i in a} Σ_j P_iᵀ K_ij P_j` over its rows in row order (the
        // same sums whatever the threads).
        let mut dense = vec![0.0; coarse * block * mcc];
        dense
            .par_chunks_mut(block * mcc)
            .enumerate()
            .for_each(|(a, row)| {
                let mut vp = vec![0.0; m * mc];
                let base = centre as i64 - on_rows(&index[a]);
                for &i in children_of(a) {
                    let start = i * self.block;
                    let n = self.count[i] as usize;
                    for e in 0..n {
                        let j = self.column[start + e] as usize;
                        let Some(at) = row_place[j] else {
                            continue;
                        };
                        let key = (base + at) as usize;
                        let v = &self.value[(start + e) * mm..(start + e + 1) * mm];
                        let out = &mut row[key * mcc..][..mcc];
                        if mc == 1 {
                            out[0] += v[0];
                            continue;
                        }
                        // P_iᵀ V P_j.
                        let (pi, pj) = (child(i), child(j));
                        for r in 0..m {
                            for g in 0..mc {
                                vp[r * mc + g] =
                                    (0..m).map(|h| v[r * m + h] * pj[h * mc + g]).sum();
                            }
                        }
                        for f in 0..mc {
                            for g in 0..mc {
                                out[f * mc + g] +=
                                    (0..m).map(|r| pi[r * mc + f] * vp[r * mc + g]).sum::<f64>();
                            }
                        }
                    }
                }
            });
        let mut count = vec![0u32; coarse];
        let mut column = vec![0u32; coarse * block];
        let mut value = vec![0.0; coarse * block * mcc];
        let steps = entry_steps::<D>(radius);
        count
            .par_iter_mut()
            .zip(column.par_chunks_mut(block))
            .zip(value.par_chunks_mut(block * mcc))
            .enumerate()
            .for_each(|(a, ((count, column), value))| {
                let mut k = 0;
                for e in 0..block {
                    let v = &dense[(a * block + e) * mcc..(a * block + e + 1) * mcc];
                    if e != centre && v.iter().all(|&x| x == 0.0) {
                        continue;
                    }
                    let at: [i64; D] = std::array::from_fn(|c| index[a][c] + steps[e][c]);
                    column[k] = numbers[place(&at)];
                    value[k * mcc..(k + 1) * mcc].copy_from_slice(v);
                    k += 1;
                }
                *count = k as u32;
            });
        let diagonal = (0..coarse)
            .flat_map(|a| {
                dense[(a * block + centre) * mcc..(a * block + centre + 1) * mcc].to_vec()
            })
            .collect();
        // Σ_i P_iᵀ A_i P_i over each aggregate: block diagonal, as every node has one parent.
        let mut moment = vec![0.0; if mc > 1 { coarse * mcc } else { 0 }];
        moment.par_chunks_mut(mcc).enumerate().for_each(|(c, out)| {
            for &i in children_of(c) {
                let (p, a) = (child(i), &self.moment[i * mm..(i + 1) * mm]);
                for f in 0..mc {
                    for g in 0..mc {
                        out[f * mc + g] += (0..m)
                            .map(|r| {
                                p[r * mc + f]
                                    * (0..m).map(|h| a[r * m + h] * p[h * mc + g]).sum::<f64>()
                            })
                            .sum::<f64>();
                    }
                }
            }
        });
        let coarse_lattice = Lattice {
            lowest: std::array::from_fn(|a| axes[a].lowest),
            position: std::array::from_fn(|a| axes[a].centre.clone()),
        };
        (
            NodeOperator::new(
                index,
                (mc, diagonal, moment),
                radius,
                block,
                (count, column, value),
            ),
            aggregation,
            coarse_lattice,
        )
    }

    /// `x += ω D⁻¹ (r − K x)` (rows without particles stay zero): at order 1 with the mean fit
    /// `D` is `K`'s diagonal; otherwise the moment blocks (the reach with the linear fit), since `K ⪯ A` (`⟨ζ, Kζ⟩` is a weighted variance,
    /// `⟨ζ, Aζ⟩` the weighted mean square it is taken of) keeps `A⁻¹K`'s eigenvalues in [0, 1]
    /// on any particles, where `K`'s diagonal blocks give no such bound.
    /// With `from_zero` (`x` is zero) `K x` is not computed.
    fn smooth(&self, r: &[f64], x: &mut [f64], kx: &mut [f64], from_zero: bool) {
        if from_zero {
            kx.fill(0.0);
        } else {
            self.apply(x, kx);
        }
        let (m, mm) = (self.m, self.m * self.m);
        if m == 1 {
            x.par_chunks_exact_mut(D)
                .zip(r.par_chunks_exact(D).zip(kx.par_chunks_exact(D)))
                .zip(self.diagonal.par_iter())
                .enumerate()
                .for_each(|(i, ((x, (r, kx)), &d))| {
                    if d > 0.0 {
                        let (w, d) = match self.moment.get(i) {
                            Some(&a) => (MOMENT_DAMPING, a),
                            None => (JACOBI_DAMPING, d),
                        };
                        for k in 0..D {
                            x[k] += w * (r[k] - kx[k]) / d;
                        }
                    }
                });
            return;
        }
        let per = m * D;
        x.par_chunks_exact_mut(per)
            .zip(r.par_chunks_exact(per).zip(kx.par_chunks_exact(per)))
            .enumerate()
            .for_each(|(i, (x, (r, kx)))| {
                if self.diagonal[i * mm] > 0.0 {
                    let inv = &self.inverse[i * mm..(i + 1) * mm];
                    for k in 0..D {
                        for a in 0..m {
                            let s: f64 = (0..m)
                                .map(|b| inv[a * m + b] * (r[k * m + b] - kx[k * m + b]))
                                .sum();
                            x[k * m + a] += MOMENT_DAMPING * s;
                        }
                    }
                }
            });
    }
}

impl<const D: usize> Multilevel<D> {
    /// The levels below `fine`, coarsened until the coarsest has at most `COARSEST_ROWS`
    /// unknowns per direction or stops shrinking; `exponents` are the test polynomials'
    /// (as [`crate::shape::Monomials`] lists them), `reduced` the nodes corrected to order 1,
    /// `reach` the nodes' reaches `A_I` at order 1 with the linear fit (`None` otherwise).
    /// Without `cycle`, only the fine operator (preconditioned by the caller).
    pub fn new(
        mut fine: NodeOperator<D>,
        cycle: bool,
        exponents: &[[u32; D]],
        reduced: &[bool],
        reach: Option<&[f64]>,
    ) -> Self {
        if !cycle {
            fine.lay_out();
            return Multilevel {
                weak: Vec::new(),
                reduced: Vec::new(),
                levels: vec![fine],
                aggregation: Vec::new(),
                coarsest: None,
                body: Vec::new(),
                bodies: 0,
                pseudo_inverse: None,
            };
        }
        let (m, mm) = (fine.m, fine.m * fine.m);
        // With the linear fit (`reach`, order 1) the coarse levels carry `1, Z` per aggregate.
        let linear: Vec<[u32; D]> = std::iter::once([0; D])
            .chain((0..D).map(|a| std::array::from_fn(|b| (a == b) as u32)))
            .collect();

        let coarse_exponents = match reach {
            Some(reach) if m == 1 => {
                fine.moment = reach.to_vec();
                &linear[..]
            }
            _ => exponents,
        };
        let largest = (0..fine.rows()).fold(0.0f64, |a, i| a.max(fine.diagonal[i * mm]));
        // At order ≥ 2 no row is left out: the weak rows' blocks, outside the V-cycle, doubled
        // the iterations (RK2 + VC2 at 16 cells: 44 against 19).
        let threshold = if m == 1 { WEAK_ROW } else { 0.0 };
        let weak: Vec<f64> = fine
            .diagonal
            .chunks_exact_mut(mm)
            .map(|d| {
                if d[0] > 0.0 && d[0] < threshold * largest {
                    std::mem::replace(&mut d[0], 0.0)
                } else {
                    0.0
                }
            })
            .collect();
        let mut lattice = Lattice::of_nodes(&fine);
        let mut levels = vec![fine];
        let mut aggregation = Vec::new();
        loop {
            let last = levels.last().expect("the fine level");
            let rows = last.rows();
            if rows * last.m <= COARSEST_ROWS {
                break;
            }
            // Each level's polynomials are written in its spacing, twice the level's above.
            let spacing = (2u64 << aggregation.len()) as f64;
            let (coarse, up, next) = last.coarsen(&lattice, spacing, coarse_exponents, m > 1);
            if coarse.rows() * 3 > rows * 2 {
                break;
            }
            levels.push(coarse);
            aggregation.push(up);
            lattice = next;
        }
        let last = levels.last().expect("the fine level");
        let n = last.rows();
        let (m, mm) = (last.m, last.m * last.m);
        let mut dense = DMatrix::<f64>::zeros(n * m, n * m);
        for i in 0..n {
            let start = i * last.block;
            for e in 0..last.count[i] as usize {
                let j = last.column[start + e] as usize;
                let v = &last.value[(start + e) * mm..(start + e + 1) * mm];
                for a in 0..m {
                    for b in 0..m {
                        dense[(i * m + a, j * m + b)] += v[a * m + b];
                    }
                }
            }
            for a in 0..m {
                let d = last.diagonal[i * mm + a * m + a];
                dense[(i * m + a, i * m + a)] += if last.diagonal[i * mm] > 0.0 && d > 0.0 {
                    1e-10 * d
                } else {
                    1.0
                };
            }
        }
        // The bodies: rows joined by an entry (rows without particles in none).
        let numbers = super::bodies(n, n, |i, visit: &mut dyn FnMut(usize)| {
            visit(i);
            let start = i * last.block;
            for e in 0..last.count[i] as usize {
                if last.value[(start + e) * mm..(start + e + 1) * mm]
                    .iter()
                    .any(|&v| v != 0.0)
                {
                    visit(last.column[start + e] as usize);
                }
            }
        });
        let bodies = numbers.iter().max().map_or(0, |&b| b + 1);
        let body: Vec<usize> = (0..n)
            .map(|i| {
                if last.diagonal[i * mm] > 0.0 {
                    numbers[i]
                } else {
                    usize::MAX
                }
            })
            .collect();
        let pseudo_inverse = (m > 1).then(|| {
            // Without the regularisation (the unknowns without particles are zero rows).
            for i in 0..n * m {
                let d = last.diagonal[(i / m) * mm + (i % m) * (m + 1)];
                dense[(i, i)] -= if last.diagonal[(i / m) * mm] > 0.0 && d > 0.0 {
                    1e-10 * d
                } else {
                    1.0
                };
            }
            let eig = dense.clone().symmetric_eigen();
            let largest = eig.eigenvalues.iter().fold(0.0f64, |a, &l| a.max(l));
            let threshold = match levels[0].m {
                1 => COARSEST_EIGENVALUE_LINEAR_FIT,
                _ => COARSEST_EIGENVALUE,
            };
            let inverse = eig.eigenvalues.map(|l| {
                if l > threshold * largest {
                    1.0 / l
                } else {
                    0.0
                }
            });
            &eig.eigenvectors * DMatrix::from_diagonal(&inverse) * eig.eigenvectors.transpose()
        });
        levels.iter_mut().for_each(NodeOperator::lay_out);
        Multilevel {
            weak,
            reduced: reduced.to_vec(),
            levels,
            aggregation,
            coarsest: if m == 1 { dense.cholesky() } else { None },
            body,
            bodies,
            pseudo_inverse,
        }
    }

    /// The fine level's buffers, for the next step's [`NodeOperator::assemble`].
    pub fn into_storage(mut self) -> OperatorStorage {
        let fine = self.levels.swap_remove(0);
        OperatorStorage {
            value: fine.value,
            column: fine.column,
            laid: fine.lattice.map_or(fine.spare, LatticeRows::into_values),
        }
    }

    /// The fine level's operator.
    pub fn fine(&self) -> &NodeOperator<D> {
        &self.levels[0]
    }

    /// Whether [`Multilevel::precondition`] runs a V-cycle (else the caller preconditions).
    pub fn has_cycle(&self) -> bool {
        !self.weak.is_empty()
    }

    /// Whether a V-cycle pays for the fine operator `K`. At order 1: with the node blocks
    /// alone the iterations grow with the width of the nodes (about 3 per node across: 457 at
    /// 161 nodes across in 2D, 82 at 26 in 3D, on the throughput example's blocks), while a
    /// V-cycle costs about six products with `K` and takes about a dozen iterations
    /// (`COARSE_WEIGHT`): from about 20 nodes across it pays (`MULTILEVEL_WIDTH`). At order ≥ 2 the node blocks take about 8 per node across (63 at 13,
    /// 174 at 21: RK of order 2 on the manufactured solution's box) and the W-cycle 5–16,
    /// so it is used whenever the hierarchy has a level below the nodes (on a single level the
    /// coarsest pseudo-inverse, whose norm measures nothing of its dropped directions, stopped
    /// a solve short of the equalities by 1e-11).
    pub fn pays<const E: usize>(fine: &NodeOperator<E>) -> bool {
        if fine.m == 1 {
            return (fine.rows() as f64).powf(1.0 / E as f64) >= MULTILEVEL_WIDTH;
        }
        fine.rows() * fine.m > COARSEST_ROWS
    }

    /// `z = M⁻¹ r`: one cycle from zero.
    pub fn precondition(&self, r: &[f64], z: &mut [f64]) {
        self.cycle(0, r, z);
        let fine = &self.levels[0];
        let m = fine.m;
        let mm = m * m;
        z.par_chunks_exact_mut(m * D)
            .zip(r.par_chunks_exact(m * D))
            .zip(self.weak.par_iter())
            .enumerate()
            .for_each(|(i, ((z, r), &d))| {
                if d > 0.0 {
                    if m == 1 {
                        for k in 0..D {
                            z[k] = r[k] / d;
                        }
                        return;
                    }
                    let inv = &fine.inverse[i * mm..(i + 1) * mm];
                    for k in 0..D {
                        for a in 0..m {
                            z[k * m + a] = (0..m).map(|b| inv[a * m + b] * r[k * m + b]).sum();
                        }
                    }
                }
            });
    }

    fn cycle(&self, l: usize, r: &[f64], x: &mut [f64]) {
        let level = &self.levels[l];
        let m = level.m;
        let per = m * D;
        x.fill(0.0);
        if l + 1 == self.levels.len() {
            if let Some(c) = &self.coarsest {
                self.solve_coarsest(c, r, x);
            }
            if let Some(inverse) = &self.pseudo_inverse {
                let n = level.rows() * m;
                for k in 0..D {
                    let rhs = nalgebra::DVector::from_iterator(
                        n,
                        (0..n).map(|i| r[(i / m) * per + k * m + i % m]),
                    );
                    let sol = inverse * rhs;
                    for i in 0..n {
                        x[(i / m) * per + k * m + i % m] = sol[i];
                    }
                }
            }
            return;
        }
        let mut kx = vec![0.0; r.len()];
        let sweeps = match self.levels[0].m {
            1 => SMOOTHING_SWEEPS,
            _ => SMOOTHING_SWEEPS_HIGHER,
        };
        for sweep in 0..sweeps {
            level.smooth(r, x, &mut kx, sweep == 0);
        }
        // The residual, restricted onto the aggregates in row order (at order 1 summed).
        level.apply(x, &mut kx);
        let aggregation = &self.aggregation[l];
        let parent = &aggregation.parent;
        let (coarse, mc) = (self.levels[l + 1].rows(), self.levels[l + 1].m);
        let pc = mc * D;
        let mut rc = vec![0.0; coarse * pc];
        let child = |i: usize| -> &[f64] { aggregation.block(i) };
        // Each coarse row sums its own rows in row order (the same bits on any threads).
        rc.par_chunks_exact_mut(pc).enumerate().for_each(|(a, rc)| {
            for &i in aggregation.children(a) {
                if mc == 1 {
                    for k in 0..D {
                        rc[k] += r[i * D + k] - kx[i * D + k];
                    }
                    continue;
                }
                let p = child(i);
                for k in 0..D {
                    for f in 0..mc {
                        rc[k * mc + f] += (0..m)
                            .map(|e| {
                                p[e * mc + f] * (r[i * per + k * m + e] - kx[i * per + k * m + e])
                            })
                            .sum::<f64>();
                    }
                }
            }
        });
        let mut xc = vec![0.0; coarse * pc];
        self.cycle(l + 1, &rc, &mut xc);
        let visits = match self.levels[0].m {
            1 => 1,
            _ => COARSE_VISITS_HIGHER,
        };
        if l + 2 < self.levels.len() && visits > 1 {
            // The coarse residual's own cycles, each from the residual the last left.
            let mut kxc = vec![0.0; xc.len()];
            let mut residual = vec![0.0; xc.len()];
            let mut dx = vec![0.0; xc.len()];
            for _ in 1..visits {
                self.levels[l + 1].apply(&xc, &mut kxc);
                residual
                    .par_iter_mut()
                    .zip(rc.par_iter().zip(&kxc))
                    .for_each(|(e, (r, k))| *e = r - k);
                self.cycle(l + 1, &residual, &mut dx);
                xc.par_iter_mut().zip(&dx).for_each(|(x, d)| *x += d);
            }
        }
        let reduced = if l == 0 { &self.reduced[..] } else { &[] };
        x.par_chunks_exact_mut(per)
            .zip(parent.par_iter())
            .enumerate()
            .for_each(|(i, (x, &a))| {
                if a == u32::MAX {
                    return;
                }
                let a = a as usize;
                if mc == 1 {
                    for k in 0..D {
                        x[k] += COARSE_WEIGHT * xc[a * D + k];
                    }
                    return;
                }
                let p = child(i);
                // A node corrected to order 1 takes the constant part only.
                let terms = if reduced.get(i) == Some(&true) { 1 } else { m };
                for k in 0..D {
                    for e in 0..terms {
                        x[k * m + e] += COARSE_WEIGHT_HIGHER
                            * (0..mc)
                                .map(|f| p[e * mc + f] * xc[a * pc + k * mc + f])
                                .sum::<f64>();
                    }
                }
            });
        for _ in 0..sweeps {
            level.smooth(r, x, &mut kx, false);
        }
    }

    /// The coarsest level's direct solve at order 1. The right-hand side's constant part per
    /// body (round-off of the residual's sum, which `K`'s zero column sums keep at zero),
    /// removed before the solve and the solution's after it: the regularisation would amplify
    /// them.
    fn solve_coarsest(&self, c: &nalgebra::Cholesky<f64, nalgebra::Dyn>, r: &[f64], x: &mut [f64]) {
        let n = self.levels.last().expect("a level").rows();
        let zero_means = |v: &mut nalgebra::DVector<f64>| {
            let mut sums = vec![(0.0, 0.0); self.bodies];
            for i in 0..n {
                if let Some(s) = sums.get_mut(self.body[i]) {
                    *s = (s.0 + v[i], s.1 + 1.0);
                }
            }
            for i in 0..n {
                match sums.get(self.body[i]) {
                    Some(s) => v[i] -= s.0 / s.1,
                    None => v[i] = 0.0,
                }
            }
        };
        for k in 0..D {
            let mut rhs = nalgebra::DVector::from_iterator(n, (0..n).map(|i| r[i * D + k]));
            zero_means(&mut rhs);
            let mut sol = c.solve(&rhs);
            zero_means(&mut sol);
            for i in 0..n {
                x[i * D + k] = sol[i];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{mirrored_pairs, NodeOperator, OperatorStorage};
    use crate::grid::{Bins, Grid, GridNodes};
    use crate::shape::tests::TestRng;
    use crate::shape::{BSpline, BSplineOrder, StencilView, Stencils, TensorStencils};
    use crate::Vector;

    /// The order-1 operator with the mean fit assembled per axis from the stencils' 1D factors
    /// (`tensor_rows`) is the one assembled from the stored lists, to round-off: the same rows
    /// and columns, every value within 1e-14 of the largest (the sums are taken in another
    /// order, a few units of the last place apart), and the same lattice neighbours joined. On jittered particles
    /// with a few put on node lines or half-way between nodes, where factors vanish (a support
    /// that is not the whole box: linear hats), for the linear, quadratic and cubic B-splines,
    /// 2D and 3D.
    fn tensor_assembly_is_the_stored_one<const D: usize, const W: usize>() {
        let order = match W {
            2 => BSplineOrder::Linear,
            3 => BSplineOrder::Quadratic,
            _ => BSplineOrder::Cubic,
        };
        let shape = BSpline::new(order);
        let cells = 12;
        let h = 1.0 / cells as f64;
        let grid = Grid::<D>::new(Vector::zeros(), [cells; D], h).unwrap();
        let mut rng = TestRng::new(3);
        let n = 6usize.pow(D as u32);
        let x: Vec<Vector<D>> = (0..n)
            .map(|k| {
                Vector::<D>::from_fn(|a, _| {
                    let i = (k / 6usize.pow(a as u32)) % 6;
                    let site = 0.3 + (i as f64 + 0.5) * 0.4 / 6.0;
                    match k % 7 {
                        // On a node line, and half-way between two.
                        0 if a == 0 => 0.5,
                        3 if a == D - 1 => 0.5 + h / 2.0,
                        _ => site + (rng.uniform() - 0.5) * 0.04,
                    }
                })
            })
            .collect();
        let volumes: Vec<f64> = (0..n)
            .map(|p| 1e-3 * (1.0 + 0.1 * (p % 5) as f64))
            .collect();
        let mut factors = TensorStencils::<D, W>::default();
        factors.compute(&shape, &grid, &x);
        let mut stored = Stencils::<D>::default();
        stored.fill_from_factors(&factors);
        let mut bins = Bins::<D>::default();
        crate::shape::bin_particles(&mut bins, &shape, &grid, &x);
        let mut nodes = GridNodes::<D>::default();
        nodes.ensure(&grid, false, false, false).unwrap();
        for p in 0..n {
            stored.for_each_shape(p, |_, s| {
                if s.in_support() {
                    nodes.touch(s.node);
                }
            });
        }
        let slots = nodes.active.len();
        let (moment, reduced) = (vec![1.0; slots], vec![false; slots]);
        let view = factors.local();
        let assemble = |tensor| {
            NodeOperator::assemble(
                &grid,
                &bins,
                &stored,
                &nodes,
                &volumes,
                (&moment, &reduced, 1),
                |_, _, q: &mut [f64]| q[0] = 1.0,
                None::<&fn(usize, usize) -> Vector<D>>,
                |_| true,
                tensor,
                OperatorStorage::default(),
            )
            .expect("box stencils")
        };
        let (a, b) = (assemble(None), assemble(view.tensor_factors()));
        assert_eq!(a.count, b.count, "W = {W}, {D}D");
        let largest = a.value.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for row in 0..slots {
            let r = row * a.block..row * a.block + a.count[row] as usize;
            assert_eq!(a.column[r.clone()], b.column[r.clone()], "W = {W}, {D}D");
            for k in r {
                let d = (a.value[k] - b.value[k]).abs();
                assert!(d <= 1e-14 * largest, "W = {W}, {D}D: {d:e} of {largest:e}");
            }
        }
        assert_eq!(a.joined, b.joined, "W = {W}, {D}D");
        // The linear hats' supports are not whole boxes on the node lines.
        assert_eq!(a.joined.is_none(), W == 2, "W = {W}, {D}D");
    }

    #[test]
    fn tensor_assembly_is_the_stored_one_2d_3d() {
        tensor_assembly_is_the_stored_one::<2, 2>();
        tensor_assembly_is_the_stored_one::<2, 3>();
        tensor_assembly_is_the_stored_one::<2, 4>();
        tensor_assembly_is_the_stored_one::<3, 2>();
        tensor_assembly_is_the_stored_one::<3, 3>();
        tensor_assembly_is_the_stored_one::<3, 4>();
    }

    /// Every row length to 64: the aggregates are numbered from 0 at the low end, each a run of
    /// neighbours; the row's mirror image gives the same aggregates (numbered from the other
    /// end); an even row is cut into pairs, an odd one into pairs and threes (the row of five,
    /// whose middle three leave one node at each end, is one aggregate), so each level has about
    /// half the nodes of the one above.
    #[test]
    fn mirrored_pairs_are_runs_of_two_or_three_symmetric_about_the_middle() {
        for n in 1..=64usize {
            let agg = mirrored_pairs(n);
            assert_eq!(agg.len(), n, "n = {n}");
            assert_eq!(agg[0], 0, "n = {n}");
            assert!(
                agg.windows(2).all(|w| w[1] == w[0] || w[1] == w[0] + 1),
                "n = {n}: not runs numbered in order: {agg:?}"
            );
            let last = agg[n - 1];
            assert!(
                (0..n).all(|t| agg[n - 1 - t] == last - agg[t]),
                "n = {n}: not mirror symmetric: {agg:?}"
            );
            let mut sizes = vec![0usize; last + 1];
            agg.iter().for_each(|&a| sizes[a] += 1);
            let allowed = match n {
                1 => vec![1],
                3 => vec![3],
                5 => vec![5],
                _ if n % 2 == 0 => vec![2],
                _ => vec![2, 3],
            };
            assert!(
                sizes.iter().all(|s| allowed.contains(s)),
                "n = {n}: aggregate sizes {sizes:?}"
            );
        }
    }
}
