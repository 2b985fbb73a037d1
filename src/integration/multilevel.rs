//! The multilevel preconditioner of the conservative VC solve.
//!
//! `K` is a weighted variance over the particles' node supports, so corrections that vary
//! slowly from node to node cost almost nothing: preconditioned by its node blocks alone, the
//! conjugate gradients need iterations in proportion to the grid's width. The coarse spaces
//! here are the node lattice with every second node, level by level. A coarse node `J` holds
//! the coefficients `c_J` of a polynomial of the VC degree about itself; a node `i` of the level
//! below gets the polynomials of its (up to 2^D) coarse neighbours re-expanded about itself and
//! blended by the multilinear hat `φ_J(x_i)` (weights 1 or ½ per axis):
//! `ζ_i = Σ_J φ_J(x_i) T_iJ c_J`. The coarse operator is the Galerkin `PᵀKP`: on the first level
//! assembled from the node blocks and the particles,
//!
//! ```text
//! PᵀKP = Σ_I Φ_Iᵀ A_I Φ_I − Σ_p V_p u_p u_pᵀ / W_p,   u_p = Σ_I w_Ip Φ_Iᵀ Q_I(x_p)
//! ```
//!
//! (`Φ_I` the prolongation's rows of node `I`, masked to the constant for a node that keeps the
//! constant correction only), on the next levels by `PᵀKP` from the last. The cycle is a
//! symmetric V-cycle: block-Jacobi smoothing with the blocks of `A` on the nodes (`K ≤ A`) and
//! with l1 blocks on the coarse levels (`K ≤` block diagonal plus absolute off-block row sums),
//! the coarsest level solved with a pseudo-inverse. Both smoothers converge and the coarse
//! operators are exact, so the cycle is symmetric and positive on `K`'s range, as conjugate
//! gradients need.

use super::Pairs;
use crate::grid::{Grid, GridNodes};
use crate::shape::Monomials;
use crate::Vector;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// Coarsening stops at this many coarse nodes; the coarsest level is solved densely.
const COARSEST: usize = 32;

/// Particles per partial sum of the first level (fixed, so that the sums are the same bits
/// with any number of threads).
const CHUNK: usize = 8192;

/// `out[e * n + f]` (`n = to.len()`): the coefficient of the monomial `from[e]` of
/// `y = (x − x_i)/H` in the monomial `to[f]` of `(x − x_a)/H'`, with `d = (x_i − x_a)/H` and
/// `rho = H/H'` (binomial expansion; where `from` lacks some of `to`'s monomials, the
/// re-expansion is truncated to those it has).
pub(crate) fn reexpansion<const D: usize>(
    from: &[[u32; D]],
    to: &[[u32; D]],
    d: &[f64; D],
    rho: f64,
    out: &mut [f64],
) {
    let n = to.len();
    let binomial =
        |n: u32, k: u32| -> f64 { (0..k).fold(1.0, |c, i| c * (n - i) as f64 / (i + 1) as f64) };
    for (e, ee) in from.iter().enumerate() {
        for (f, ff) in to.iter().enumerate() {
            out[e * n + f] = if (0..D).all(|a| ee[a] <= ff[a]) {
                (0..D)
                    .map(|a| {
                        binomial(ff[a], ee[a])
                            * d[a].powi((ff[a] - ee[a]) as i32)
                            * rho.powi(ff[a] as i32)
                    })
                    .product()
            } else {
                0.0
            };
        }
    }
}

/// Visits the coarse nodes of the lattice node `i` (index on the level below): per axis `i/2`
/// with weight 1 for an even `i`, `(i ∓ 1)/2` with weights ½ for an odd one. Gives the coarse
/// index, the weight and the pattern of `d = i − 2J` (an index into the re-expansion table).
fn corners<const D: usize>(i: [i64; D], mut visit: impl FnMut([i64; D], f64, usize)) {
    for c in 0..1usize << D {
        let mut j = [0; D];
        let (mut weight, mut pattern, mut stride) = (1.0, 0, 1);
        let mut skip = false;
        for k in 0..D {
            let up = (c >> k) & 1;
            if i[k].rem_euclid(2) == 0 {
                if up == 1 {
                    skip = true;
                    break;
                }
                j[k] = i[k].div_euclid(2);
            } else {
                j[k] = i[k].div_euclid(2) + up as i64;
                weight *= 0.5;
            }
            pattern += ((i[k] - 2 * j[k] + 1) as usize) * stride;
            stride *= 3;
        }
        if !skip {
            visit(j, weight, pattern);
        }
    }
}

/// Per node of a level, its coarse nodes on the next: index, weight and re-expansion pattern.
#[derive(Default)]
struct Links {
    starts: Vec<usize>,
    links: Vec<(u32, f64, u32)>,
}

impl Links {
    fn new<const D: usize>(
        nodes: impl Iterator<Item = Option<[i64; D]>>,
        coarse: &Level<D>,
    ) -> Self {
        let mut links = Links {
            starts: vec![0],
            links: Vec::new(),
        };
        for i in nodes {
            if let Some(i) = i {
                corners(i, |j, w, pat| {
                    links
                        .links
                        .push((coarse.index(j).unwrap() as u32, w, pat as u32))
                });
            }
            links.starts.push(links.links.len());
        }
        links
    }

    fn of(&self, i: usize) -> &[(u32, f64, u32)] {
        &self.links[self.starts[i]..self.starts[i + 1]]
    }
}

/// One coarse level: the nodes of a box, the operator as `m × m` blocks per aggregate and
/// neighbour offset (within `radius` per axis), and the smoother's factors.
struct Level<const D: usize> {
    lo: [i64; D],
    extent: [usize; D],
    radius: i64,
    /// `[aggregate][offset]`, each block row-major (row: this aggregate's monomial).
    matrix: Vec<f64>,
    /// Per node and offset: the neighbour's index, `u32::MAX` outside the box.
    neighbours: Vec<u32>,
    /// Per node: its coarse nodes on the next level (empty on the coarsest).
    down: Links,
    /// Per aggregate: the inverse of its l1 block (`m × m`), zero where the block is empty.
    smoother: Vec<f64>,
}

impl<const D: usize> Level<D> {
    fn new(lo: [i64; D], hi: [i64; D], radius: i64, m: usize) -> Self {
        let extent = std::array::from_fn(|a| (hi[a] - lo[a] + 1) as usize);
        let mut level = Level {
            lo,
            extent,
            radius,
            matrix: Vec::new(),
            neighbours: Vec::new(),
            down: Links::default(),
            smoother: Vec::new(),
        };
        level.matrix = vec![0.0; level.len() * level.offsets() * m * m];
        level.neighbours = (0..level.len())
            .flat_map(|i| {
                let a = level.multi(i);
                (0..level.offsets()).map(move |o| (a, o))
            })
            .map(|(a, o)| {
                let off = level.offset(o);
                level
                    .index(std::array::from_fn(|k| a[k] + off[k]))
                    .map_or(u32::MAX, |j| j as u32)
            })
            .collect();
        level
    }

    fn len(&self) -> usize {
        self.extent.iter().product()
    }

    fn offsets(&self) -> usize {
        ((2 * self.radius + 1) as usize).pow(D as u32)
    }

    fn index(&self, a: [i64; D]) -> Option<usize> {
        let mut i = 0;
        for k in (0..D).rev() {
            let c = a[k] - self.lo[k];
            if c < 0 || c as usize >= self.extent[k] {
                return None;
            }
            i = i * self.extent[k] + c as usize;
        }
        Some(i)
    }

    fn multi(&self, mut i: usize) -> [i64; D] {
        std::array::from_fn(|k| {
            let a = self.lo[k] + (i % self.extent[k]) as i64;
            i /= self.extent[k];
            a
        })
    }

    fn offset_index(&self, o: [i64; D]) -> Option<usize> {
        let w = 2 * self.radius + 1;
        let mut i = 0;
        for k in (0..D).rev() {
            if o[k].abs() > self.radius {
                return None;
            }
            i = i * w + (o[k] + self.radius);
        }
        Some(i as usize)
    }

    fn offset(&self, mut i: usize) -> [i64; D] {
        let w = (2 * self.radius + 1) as usize;
        let mut o = [0; D];
        for item in o.iter_mut() {
            *item = (i % w) as i64 - self.radius;
            i /= w;
        }
        o
    }

    /// `y = K x` on this level (vectors `[aggregate][direction][monomial]`).
    fn apply(&self, m: usize, x: &[f64], y: &mut [f64]) {
        let offsets = self.offsets();
        y.chunks_exact_mut(D * m).enumerate().for_each(|(i, y)| {
            y.fill(0.0);
            for o in 0..offsets {
                let j = self.neighbours[i * offsets + o] as usize;
                if j == u32::MAX as usize {
                    continue;
                }
                let block = &self.matrix[(i * offsets + o) * m * m..][..m * m];
                let x = &x[j * D * m..][..D * m];
                for k in 0..D {
                    for e in 0..m {
                        y[k * m + e] +=
                            (0..m).map(|f| block[e * m + f] * x[k * m + f]).sum::<f64>();
                    }
                }
            }
        });
    }

    /// `x = M⁻¹ b` with the l1 blocks.
    fn smooth(&self, m: usize, b: &[f64], x: &mut [f64]) {
        for ((x, b), inverse) in x
            .chunks_exact_mut(D * m)
            .zip(b.chunks_exact(D * m))
            .zip(self.smoother.chunks_exact(m * m))
        {
            for k in 0..D {
                for e in 0..m {
                    x[k * m + e] = (0..m).map(|f| inverse[e * m + f] * b[k * m + f]).sum();
                }
            }
        }
    }

    /// Factors the l1 blocks: the diagonal block plus, on its diagonal, the absolute row sums of
    /// the off-diagonal blocks (so that `K ≤ M` and the smoother converges without damping).
    fn factor_smoother(&mut self, m: usize) {
        let offsets = self.offsets();
        let centre = self.offset_index([0; D]).unwrap();
        self.smoother = (0..self.len())
            .flat_map(|i| {
                let mut b = DMatrix::from_row_slice(
                    m,
                    m,
                    &self.matrix[(i * offsets + centre) * m * m..][..m * m],
                );
                for o in (0..offsets).filter(|&o| o != centre) {
                    let block = &self.matrix[(i * offsets + o) * m * m..][..m * m];
                    for e in 0..m {
                        b[(e, e)] += (0..m).map(|f| block[e * m + f].abs()).sum::<f64>();
                    }
                }
                let trace = b.trace();
                let inverse = (trace > 0.0)
                    .then(|| {
                        for e in 0..m {
                            b[(e, e)] += 1e-14 * trace;
                        }
                        b.cholesky().map(|c| c.inverse())
                    })
                    .flatten()
                    .unwrap_or_else(|| DMatrix::zeros(m, m));
                // Row-major (the inverse is symmetric).
                inverse.as_slice().to_vec()
            })
            .collect();
    }
}

/// The coarse levels of one step's VC solve and the map from the nodes onto the first.
pub(crate) struct Multilevel<const D: usize> {
    /// Unknowns per node and direction (the VC basis).
    m: usize,
    /// Per slot: its lattice index, and the unknowns the solve uses (1 for a node that keeps
    /// the constant correction only, else `m`, 0 for a node without particles).
    index: Vec<[i64; D]>,
    kept: Vec<u8>,
    /// The re-expansions `T` (`m × m`) per pattern of `d = i − 2J` (3^D of them).
    t: Vec<f64>,
    /// Per slot, its coarse nodes on the first level (`links[starts[slot]..starts[slot + 1]]`).
    fine_links: Links,
    levels: Vec<Level<D>>,
    /// The coarsest level's pseudo-inverse (`[node][monomial]` squared).
    coarsest: DMatrix<f64>,
}

impl<const D: usize> Multilevel<D> {
    /// Builds the levels for the nodes `nodes.active` (slots) with the node blocks `moment`
    /// (`A_I`), of which `used` hold particles and `reduced` keep the constant correction only;
    /// `basis` is the VC basis and `pairs` the supports of the particles that count.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        grid: &Grid<D>,
        nodes: &GridNodes<D>,
        basis: &Monomials<D>,
        moment: &[f64],
        used: &[bool],
        reduced: &[bool],
        positions: &[Vector<D>],
        volumes: &[f64],
        pairs: &Pairs,
    ) -> Self {
        let m = basis.len();
        let exps = basis.exponents();
        let h = grid.cell_size;
        let slots = nodes.active.len();
        let mut t = vec![0.0; 3usize.pow(D as u32) * m * m];
        for (c, t) in t.chunks_exact_mut(m * m).enumerate() {
            let d = std::array::from_fn(|k| ((c / 3usize.pow(k as u32)) % 3) as f64 - 1.0);
            reexpansion(exps, exps, &d, 0.5, t);
        }
        let mut ml = Multilevel {
            m,
            index: nodes
                .active
                .iter()
                .map(|&n| grid.node_multi_index(n))
                .collect(),
            kept: (0..slots)
                .map(|s| match (used[s], reduced[s]) {
                    (false, _) => 0,
                    (true, true) => 1,
                    (true, false) => m as u8,
                })
                .collect(),
            t,
            fine_links: Links::default(),
            levels: Vec::new(),
            coarsest: DMatrix::zeros(0, 0),
        };
        let (mut lo, mut hi) = ([i64::MAX; D], [i64::MIN; D]);
        for slot in (0..slots).filter(|&s| used[s]) {
            corners(ml.index[slot], |j, _, _| {
                for k in 0..D {
                    lo[k] = lo[k].min(j[k]);
                    hi[k] = hi[k].max(j[k]);
                }
            });
        }
        if lo[0] > hi[0] {
            return ml;
        }
        // The widest span of a particle's coarse nodes.
        let radius = (0..positions.len())
            .into_par_iter()
            .map(|p| {
                let (mut a0, mut a1) = ([i64::MAX; D], [i64::MIN; D]);
                for i in pairs.of_particle(p) {
                    corners(ml.index[pairs.slot[i] as usize], |j, _, _| {
                        for k in 0..D {
                            a0[k] = a0[k].min(j[k]);
                            a1[k] = a1[k].max(j[k]);
                        }
                    });
                }
                (0..D).map(|k| a1[k] - a0[k]).max().unwrap_or(0)
            })
            .max()
            .unwrap_or(0)
            .max(1);
        let mut first = Level::new(lo, hi, radius, m);
        let offsets = first.offsets();
        ml.fine_links = Links::new((0..slots).map(|s| used[s].then_some(ml.index[s])), &first);
        let block_of = |level: &Level<D>, j: [i64; D], jb: [i64; D]| -> usize {
            let a = level.index(j).unwrap();
            let o = level
                .offset_index(std::array::from_fn(|k| jb[k] - j[k]))
                .unwrap();
            (a * level.offsets() + o) * m * m
        };
        // Σ_I Φ_Iᵀ A_I Φ_I, node by node.
        let mut tmp = vec![0.0; m * m];
        for slot in (0..slots).filter(|&s| used[s]) {
            let kept = ml.kept[slot] as usize;
            let a = &moment[slot * m * m..][..m * m];
            let mut list = Vec::with_capacity(1 << D);
            corners(ml.index[slot], |j, w, pat| list.push((j, w, pat)));
            for &(ja, wa, pa) in &list {
                let ta = &ml.t[pa * m * m..][..m * m];
                for &(jb, wb, pb) in &list {
                    let tb = &ml.t[pb * m * m..][..m * m];
                    // tmp = A T_b (kept rows and columns of A only).
                    for e in 0..kept {
                        for f in 0..m {
                            tmp[e * m + f] = (0..kept).map(|g| a[e * m + g] * tb[g * m + f]).sum();
                        }
                    }
                    let out = block_of(&first, ja, jb);
                    let out = &mut first.matrix[out..][..m * m];
                    for e in 0..m {
                        for f in 0..m {
                            out[e * m + f] += wa
                                * wb
                                * (0..kept)
                                    .map(|g| ta[g * m + e] * tmp[g * m + f])
                                    .sum::<f64>();
                        }
                    }
                }
            }
        }
        // − Σ_p V_p u_p u_pᵀ / W_p, in fixed chunks added in order.
        let chunk = CHUNK.max(positions.len() / 8 + 1);
        let partials: Vec<Vec<f64>> = (0..positions.len())
            .collect::<Vec<_>>()
            .par_chunks(chunk)
            .map(|ps| {
                let mut part = vec![0.0; first.matrix.len()];
                let mut local: Vec<(u32, [i64; D])> = Vec::new();
                let mut u: Vec<f64> = Vec::new();
                let mut q = vec![0.0; m];
                for &p in ps {
                    local.clear();
                    u.clear();
                    let mut weight = 0.0;
                    for i in pairs.of_particle(p) {
                        let (slot, w) = (pairs.slot[i] as usize, pairs.weight[i]);
                        let kept = ml.kept[slot] as usize;
                        if m > 1 {
                            let x = grid.node_position(ml.index[slot]);
                            basis.values(&((positions[p] - x) / h), &mut q);
                        } else {
                            q[0] = 1.0;
                        }
                        weight += w;
                        for &(j, phi, pat) in ml.fine_links.of(slot) {
                            let at = match local.iter().position(|l| l.0 == j) {
                                Some(at) => at,
                                None => {
                                    local.push((j, first.multi(j as usize)));
                                    u.resize(local.len() * m, 0.0);
                                    local.len() - 1
                                }
                            };
                            let tj = &ml.t[pat as usize * m * m..][..m * m];
                            for f in 0..m {
                                u[at * m + f] +=
                                    w * phi * (0..kept).map(|e| tj[e * m + f] * q[e]).sum::<f64>();
                            }
                        }
                    }
                    if weight == 0.0 {
                        continue;
                    }
                    let v = volumes[p] / weight;
                    for (a, &(ia, ja)) in local.iter().enumerate() {
                        for (b, &(_, jb)) in local.iter().enumerate() {
                            let o = first
                                .offset_index(std::array::from_fn(|k| jb[k] - ja[k]))
                                .unwrap();
                            let out = &mut part[(ia as usize * offsets + o) * m * m..][..m * m];
                            for e in 0..m {
                                for f in 0..m {
                                    out[e * m + f] -= v * u[a * m + e] * u[b * m + f];
                                }
                            }
                        }
                    }
                }
                part
            })
            .collect();
        for part in partials {
            for (k, p) in first.matrix.iter_mut().zip(part) {
                *k += p;
            }
        }
        debug_assert_eq!(offsets, first.offsets());
        ml.levels.push(first);
        while ml.levels.last().unwrap().len() > COARSEST {
            let last = ml.levels.last_mut().unwrap();
            let next = Self::coarsen(&ml.t, m, last);
            last.down = Links::new((0..last.len()).map(|i| Some(last.multi(i))), &next);
            ml.levels.push(next);
        }
        let last = ml.levels.len() - 1;
        for level in &mut ml.levels[..last] {
            level.factor_smoother(m);
        }
        ml.coarsest = ml.pseudo_inverse(&ml.levels[last]);
        ml
    }

    /// The next level: every second node of `fine`, its operator `PᵀKP`.
    fn coarsen(t: &[f64], m: usize, fine: &Level<D>) -> Level<D> {
        let lo = std::array::from_fn(|k| fine.lo[k].div_euclid(2));
        let hi = std::array::from_fn(|k| {
            let top = fine.lo[k] + fine.extent[k] as i64 - 1;
            top.div_euclid(2) + top.rem_euclid(2)
        });
        let mut coarse = Level::new(lo, hi, fine.radius / 2 + 1, m);
        let (fine_offsets, offsets) = (fine.offsets(), coarse.offsets());
        let shape = Level::<D> {
            matrix: Vec::new(),
            neighbours: Vec::new(),
            down: Links::default(),
            smoother: Vec::new(),
            ..coarse
        };
        coarse
            .matrix
            .par_chunks_exact_mut(offsets * m * m)
            .enumerate()
            .for_each(|(a, row)| {
                let ja = shape.multi(a);
                let mut tmp = vec![0.0; m * m];
                // The fine nodes that J interpolates to: 2J + {−1, 0, 1}^D.
                for c in 0..3usize.pow(D as u32) {
                    let d: [i64; D] =
                        std::array::from_fn(|k| ((c / 3usize.pow(k as u32)) % 3) as i64 - 1);
                    let im: [i64; D] = std::array::from_fn(|k| 2 * ja[k] + d[k]);
                    let Some(i) = fine.index(im) else { continue };
                    let wi: f64 = d.iter().map(|&d| if d == 0 { 1.0 } else { 0.5 }).product();
                    let ti = &t[c * m * m..][..m * m];
                    for o in 0..fine_offsets {
                        let j = fine.neighbours[i * fine_offsets + o];
                        if j == u32::MAX {
                            continue;
                        }
                        let block = &fine.matrix[(i * fine_offsets + o) * m * m..][..m * m];
                        if block.iter().all(|&b| b == 0.0) {
                            continue;
                        }
                        corners(fine.multi(j as usize), |jb, wj, pat| {
                            let tj = &t[pat * m * m..][..m * m];
                            let co = shape
                                .offset_index(std::array::from_fn(|k| jb[k] - ja[k]))
                                .unwrap();
                            for e in 0..m {
                                for f in 0..m {
                                    tmp[e * m + f] =
                                        (0..m).map(|g| block[e * m + g] * tj[g * m + f]).sum();
                                }
                            }
                            let out = &mut row[co * m * m..][..m * m];
                            for e in 0..m {
                                for f in 0..m {
                                    out[e * m + f] += wi
                                        * wj
                                        * (0..m)
                                            .map(|g| ti[g * m + e] * tmp[g * m + f])
                                            .sum::<f64>();
                                }
                            }
                        });
                    }
                }
            });
        coarse
    }

    fn pseudo_inverse(&self, level: &Level<D>) -> DMatrix<f64> {
        let m = self.m;
        let n = level.len() * m;
        let offsets = level.offsets();
        let mut k = DMatrix::zeros(n, n);
        for i in 0..level.len() {
            for o in 0..offsets {
                let j = level.neighbours[i * offsets + o];
                if j == u32::MAX {
                    continue;
                }
                let block = &level.matrix[(i * offsets + o) * m * m..][..m * m];
                for e in 0..m {
                    for f in 0..m {
                        k[(i * m + e, j as usize * m + f)] = block[e * m + f];
                    }
                }
            }
        }
        let k = (&k + k.transpose()) * 0.5;
        let eig = k.symmetric_eigen();
        let largest = eig.eigenvalues.iter().fold(0.0f64, |a, &l| a.max(l.abs()));
        let inverted = eig
            .eigenvalues
            .map(|l| if l > 1e-9 * largest { 1.0 / l } else { 0.0 });
        &eig.eigenvectors * DMatrix::from_diagonal(&inverted) * eig.eigenvectors.transpose()
    }

    /// Whether there is a coarse level at all.
    pub(crate) fn is_empty(&self) -> bool {
        self.levels.is_empty()
    }

    /// The coarse correction `x += P C Pᵀ r` of the node vector `r`
    /// (`[slot][direction][monomial]`), `C` the V-cycle on the levels.
    pub(crate) fn correct(&self, r: &[f64], x: &mut [f64]) {
        if self.is_empty() {
            return;
        }
        let m = self.m;
        let first = &self.levels[0];
        // Pᵀ r, node by node (in slot order: the same bits with any number of threads).
        let mut b = vec![0.0; first.len() * D * m];
        for (slot, r) in r.chunks_exact(D * m).enumerate() {
            let kept = self.kept[slot] as usize;
            if kept == 0 {
                continue;
            }
            for &(j, w, pat) in self.fine_links.of(slot) {
                let t = &self.t[pat as usize * m * m..][..m * m];
                let b = &mut b[j as usize * D * m..][..D * m];
                for k in 0..D {
                    for f in 0..m {
                        b[k * m + f] +=
                            w * (0..kept).map(|e| t[e * m + f] * r[k * m + e]).sum::<f64>();
                    }
                }
            }
        }
        let mut c = vec![0.0; b.len()];
        self.cycle(0, &b, &mut c);
        x.par_chunks_exact_mut(D * m)
            .enumerate()
            .for_each(|(slot, x)| {
                let kept = self.kept[slot] as usize;
                for &(j, w, pat) in self.fine_links.of(slot) {
                    let t = &self.t[pat as usize * m * m..][..m * m];
                    let c = &c[j as usize * D * m..][..D * m];
                    for k in 0..D {
                        for e in 0..kept {
                            x[k * m + e] +=
                                w * (0..m).map(|f| t[e * m + f] * c[k * m + f]).sum::<f64>();
                        }
                    }
                }
            });
    }

    /// `x = C b` on level `l`: a symmetric V-cycle.
    fn cycle(&self, l: usize, b: &[f64], x: &mut [f64]) {
        let m = self.m;
        let level = &self.levels[l];
        if l + 1 == self.levels.len() {
            let n = level.len();
            for k in 0..D {
                let rhs = DVector::from_iterator(
                    n * m,
                    (0..n * m).map(|i| b[(i / m) * D * m + k * m + i % m]),
                );
                let sol = &self.coarsest * rhs;
                for i in 0..n * m {
                    x[(i / m) * D * m + k * m + i % m] = sol[i];
                }
            }
            return;
        }
        let coarse = &self.levels[l + 1];
        let mut t = vec![0.0; b.len()];
        let mut y = vec![0.0; b.len()];
        level.smooth(m, b, x);
        let residual = |x: &[f64], t: &mut [f64], y: &mut [f64]| {
            level.apply(m, x, y);
            t.iter_mut()
                .zip(b.iter().zip(y.iter()))
                .for_each(|(t, (b, y))| *t = b - y);
        };
        residual(x, &mut t, &mut y);
        // Restrict to the next level, solve there, prolong back.
        let mut bc = vec![0.0; coarse.len() * D * m];
        for (i, t) in t.chunks_exact(D * m).enumerate() {
            for &(j, w, pat) in level.down.of(i) {
                let tr = &self.t[pat as usize * m * m..][..m * m];
                let bc = &mut bc[j as usize * D * m..][..D * m];
                for k in 0..D {
                    for f in 0..m {
                        bc[k * m + f] +=
                            w * (0..m).map(|e| tr[e * m + f] * t[k * m + e]).sum::<f64>();
                    }
                }
            }
        }
        let mut xc = vec![0.0; bc.len()];
        self.cycle(l + 1, &bc, &mut xc);
        for (i, x) in x.chunks_exact_mut(D * m).enumerate() {
            for &(j, w, pat) in level.down.of(i) {
                let tr = &self.t[pat as usize * m * m..][..m * m];
                let xc = &xc[j as usize * D * m..][..D * m];
                for k in 0..D {
                    for e in 0..m {
                        x[k * m + e] +=
                            w * (0..m).map(|f| tr[e * m + f] * xc[k * m + f]).sum::<f64>();
                    }
                }
            }
        }
        residual(x, &mut t, &mut y);
        level.smooth(m, &t, &mut y);
        x.iter_mut().zip(&y).for_each(|(x, y)| *x += y);
    }
}
