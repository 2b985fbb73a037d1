//! The conservative correction's system at order 1 assembled on the nodes.
//!
//! At order 1 (`Q = 1`) the operator of [`super::VcCorrection`]'s solve is
//!
//! ```text
//! (K ζ)_I = A_I ζ_I − Σ_J B_IJ ζ_J,   A_I = Σ_p V_p w_Ip,   B_IJ = Σ_p V_p w_Ip w_Jp / W_p
//! ```
//!
//! (`w_Ip = |Ψ_I(x_p)|`, `W_p = Σ_J w_Jp`), the same for every direction. Applied matrix-free it
//! takes a gather and a scatter over every particle's stencil per conjugate-gradient iteration;
//! assembled once per step (one pass over the particles' stencil pairs), an iteration costs a
//! product with a sparse matrix of `(2w − 1)^D` entries per node, `w` nodes per axis of a
//! stencil: a few per particle instead of two stencil passes. On wide grids [`Multilevel`]
//! preconditions it, so that the iterations stop growing with the grid's width.

use crate::grid::{Bins, Grid, GridNodes, SharedSlice};
use crate::shape::Stencils;
use rayon::prelude::*;

/// `K` of order 1 on the active nodes (slots): per slot a row of at most `(2w − 1)^D` entries,
/// packed at the front of its block of that length.
pub(crate) struct NodeOperator<const D: usize> {
    /// Per row: the lattice multi-index of its node (of its aggregate on coarse levels).
    index: Vec<[i64; D]>,
    /// Per row: the diagonal entry.
    diagonal: Vec<f64>,
    /// How far (in nodes of this level, per axis) a row's columns reach.
    radius: usize,
    /// Entries a row's block holds, `(2 radius + 1)^D`.
    block: usize,
    /// Per slot: how many entries its row has.
    count: Vec<u32>,
    /// Per row block: the column slots, then the values.
    column: Vec<u32>,
    value: Vec<f64>,
}

impl<const D: usize> NodeOperator<D> {
    /// Assembles `K` from the particles that `counted` admits, visited by the colours of `bins`
    /// (blocks of one colour write disjoint rows: the same bits with any number of threads).
    /// `moment[slot]` is `A_I`. `None` when the stencils are not a box of `w^D` nodes.
    pub fn assemble(
        grid: &Grid<D>,
        bins: &Bins<D>,
        stencils: &Stencils<D>,
        nodes: &GridNodes<D>,
        volumes: &[f64],
        moment: &[f64],
        counted: impl Fn(usize) -> bool + Sync,
    ) -> Option<Self> {
        let len = stencils.len;
        let width = (1..=len).find(|w| w.pow(D as u32) >= len)?;
        if width.pow(D as u32) != len {
            return None;
        }
        let span = 2 * width - 1;
        let block = span.pow(D as u32);
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
        let step: Vec<isize> = (0..block)
            .map(|e| {
                (0..D)
                    .map(|a| {
                        let d = (e / span.pow(a as u32)) % span;
                        (d as isize - (width as isize - 1)) * strides[a] as isize
                    })
                    .sum()
            })
            .collect();
        let slots = nodes.active.len();
        // B, dense per row block.
        let mut dense = vec![0.0; slots * block];
        {
            let rows = SharedSlice::new(&mut dense);
            for colour in &bins.colours {
                colour.par_iter().for_each(|&b| {
                    let mut w = vec![0.0; len];
                    let mut row = vec![0usize; len];
                    let mut key = vec![0isize; len];
                    for &p in &bins.order[bins.occupied[b as usize].1.clone()] {
                        let p = p as usize;
                        if !counted(p) {
                            continue;
                        }
                        let (ns, vs, gs) = stencils.of(p);
                        let mut total = 0.0;
                        for s in 0..len {
                            w[s] = if crate::shape::in_support(vs[s], &gs[s]) {
                                row[s] = nodes.slot(ns[s]);
                                vs[s].abs()
                            } else {
                                0.0
                            };
                            total += w[s];
                        }
                        if total == 0.0 {
                            continue;
                        }
                        if (0..len).all(|s| ns[s] == ns[0] + box_step[s]) {
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
                        let c = volumes[p] / total;
                        for i in 0..len {
                            if w[i] == 0.0 {
                                continue;
                            }
                            let ci = c * w[i];
                            // SAFETY: the row belongs to a node that only this block writes in
                            // this colour (`Bins`); rows of different slots are disjoint ranges.
                            let r = unsafe { rows.range(row[i] * block, block) };
                            let base = centre as isize - key[i];
                            for j in 0..len {
                                if w[j] != 0.0 {
                                    r[(base + key[j]) as usize] += ci * w[j];
                                }
                            }
                        }
                    }
                });
            }
        }
        // K = diag(A) − B, packed.
        let mut count = vec![0u32; slots];
        let mut column = vec![0u32; slots * block];
        let mut value = vec![0.0; slots * block];
        count
            .par_iter_mut()
            .zip(column.par_chunks_mut(block))
            .zip(value.par_chunks_mut(block))
            .zip(dense.par_chunks(block))
            .enumerate()
            .for_each(|(slot, (((count, column), value), b))| {
                let node = nodes.active[slot] as isize;
                let mut k = 0;
                for e in 0..block {
                    let entry = if e == centre {
                        moment[slot] - b[e]
                    } else if b[e] != 0.0 {
                        -b[e]
                    } else {
                        continue;
                    };
                    column[k] = nodes.slot((node + step[e]) as usize) as u32;
                    value[k] = entry;
                    k += 1;
                }
                *count = k as u32;
            });
        let index = nodes
            .active
            .par_iter()
            .map(|&n| grid.node_multi_index(n))
            .collect();
        let diagonal = (0..slots)
            .into_par_iter()
            .map(|slot| moment[slot] - dense[slot * block + centre])
            .collect();
        Some(NodeOperator {
            index,
            diagonal,
            radius: width - 1,
            block,
            count,
            column,
            value,
        })
    }

    /// `out = K ζ` for `D` directions stored per slot (`ζ[slot * D + k]`).
    pub fn apply(&self, zeta: &[f64], out: &mut [f64]) {
        out.par_chunks_exact_mut(D)
            .enumerate()
            .for_each(|(slot, o)| {
                let start = slot * self.block;
                let n = self.count[slot] as usize;
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
            });
    }
}

/// Jacobi's damping in the smoother: `D⁻¹K`'s eigenvalues lie in [0, 2] (each row's
/// off-diagonal entries are negative and sum to minus its diagonal), so 2/3 damps the upper half
/// of the spectrum by at least 3 and keeps the V-cycle positive definite.
const JACOBI_DAMPING: f64 = 2.0 / 3.0;

/// Jacobi sweeps before and after the coarse correction.
const SMOOTHING_SWEEPS: usize = 2;

/// The coarse correction's weight. A piecewise-constant prolongation gives coarse functions of
/// too much energy, so the plain correction (1) undershoots; over-correcting is the usual
/// remedy of unsmoothed aggregation (Braess 1995; Notay's AGMG). The two-grid correction stays a
/// contraction in `K`'s norm for weights below 2. Conjugate-gradient iterations per step on the
/// throughput example's block (10^5 particles, quadratic B-spline + VC1, 2 sweeps): 2D 39–45
/// with 1, 18–20 with 1.5, 12 with 1.8, 11 with 2; 3D 17–21, 12–14, 12, 12.
const COARSE_WEIGHT: f64 = 1.8;

/// The V-cycle is used when the fine level has at least this many rows per axis
/// (`rows^(1/D)`), see [`Multilevel::pays`].
const MULTILEVEL_WIDTH: f64 = 48.0;

/// Rows whose diagonal is below this fraction of the largest (nodes that particles barely reach)
/// are preconditioned by their diagonal alone, outside the V-cycle.
const WEAK_ROW: f64 = 1e-3;

/// The coarsest level is solved directly when it has at most this many rows.
const COARSEST_ROWS: usize = 400;

/// A multilevel preconditioner for the order-1 system: aggregation of 2^D lattice neighbours
/// per level (piecewise-constant prolongation, Galerkin coarse operators `Pᵀ K P`, which keep
/// `K`'s zero row sums), damped-Jacobi smoothing, and a dense factor of the coarsest level.
/// One V-cycle with as many sweeps after as before the coarse correction is a fixed symmetric
/// positive definite operator, as conjugate gradients need. `K`'s iterations with the node
/// blocks alone grow with the grid's width (about 450 at 160 nodes across); with the V-cycle
/// they do not.
pub(crate) struct Multilevel<const D: usize> {
    /// Per fine row: its diagonal if the row is weak (preconditioned by it alone), else 0.
    weak: Vec<f64>,
    /// The operators, finest first.
    levels: Vec<NodeOperator<D>>,
    /// Per level but the coarsest: each row's aggregate on the next level (`u32::MAX` for a
    /// row without particles, which takes no part).
    parent: Vec<Vec<u32>>,
    /// The coarsest level's dense factor (its rows regularised by `1e-10` of their diagonal:
    /// `K` is singular along the constants of every body).
    coarsest: Option<nalgebra::Cholesky<f64, nalgebra::Dyn>>,
    /// Per row of the coarsest level: its connected body (`usize::MAX` for a row without
    /// particles), and the number of bodies.
    body: Vec<usize>,
    bodies: usize,
}

impl<const D: usize> NodeOperator<D> {
    /// The Galerkin operator of aggregates of 2^D lattice neighbours, and each row's aggregate.
    fn coarsen(&self) -> (NodeOperator<D>, Vec<u32>) {
        let rows = self.diagonal.len();
        let mut numbers = std::collections::HashMap::<[i64; D], u32>::new();
        let mut index = Vec::new();
        let parent: Vec<u32> = (0..rows)
            .map(|i| {
                if self.diagonal[i] <= 0.0 {
                    return u32::MAX;
                }
                let key = self.index[i].map(|k| k.div_euclid(2));
                *numbers.entry(key).or_insert_with(|| {
                    index.push(key);
                    index.len() as u32 - 1
                })
            })
            .collect();
        let coarse = index.len();
        let radius = self.radius.div_ceil(2);
        let span = 2 * radius + 1;
        let block = span.pow(D as u32);
        let centre = (block - 1) / 2;
        let mut dense = vec![0.0; coarse * block];
        for i in 0..rows {
            let a = parent[i];
            if a == u32::MAX {
                continue;
            }
            let start = i * self.block;
            let n = self.count[i] as usize;
            let ia = index[a as usize];
            for (&j, &v) in self.column[start..start + n]
                .iter()
                .zip(&self.value[start..start + n])
            {
                let b = parent[j as usize];
                if b == u32::MAX {
                    continue;
                }
                let ib = index[b as usize];
                let key: usize = (0..D)
                    .map(|k| (ib[k] - ia[k] + radius as i64) as usize * span.pow(k as u32))
                    .sum();
                dense[a as usize * block + key] += v;
            }
        }
        let mut count = vec![0u32; coarse];
        let mut column = vec![0u32; coarse * block];
        let mut value = vec![0.0; coarse * block];
        let steps: Vec<[i64; D]> = (0..block)
            .map(|e| {
                std::array::from_fn(|k| ((e / span.pow(k as u32)) % span) as i64 - radius as i64)
            })
            .collect();
        for a in 0..coarse {
            let mut k = 0;
            for e in 0..block {
                let v = dense[a * block + e];
                if v == 0.0 && e != centre {
                    continue;
                }
                let at: [i64; D] = std::array::from_fn(|c| index[a][c] + steps[e][c]);
                column[a * block + k] = numbers[&at];
                value[a * block + k] = v;
                k += 1;
            }
            count[a] = k as u32;
        }
        let diagonal = (0..coarse).map(|a| dense[a * block + centre]).collect();
        (
            NodeOperator {
                index,
                diagonal,
                radius,
                block,
                count,
                column,
                value,
            },
            parent,
        )
    }

    /// `x += ω D⁻¹ (r − K x)` (rows without particles stay zero).
    fn smooth(&self, r: &[f64], x: &mut [f64], kx: &mut [f64]) {
        self.apply(x, kx);
        x.par_chunks_exact_mut(D)
            .zip(r.par_chunks_exact(D).zip(kx.par_chunks_exact(D)))
            .zip(self.diagonal.par_iter())
            .for_each(|((x, (r, kx)), &d)| {
                if d > 0.0 {
                    for k in 0..D {
                        x[k] += JACOBI_DAMPING * (r[k] - kx[k]) / d;
                    }
                }
            });
    }
}

impl<const D: usize> Multilevel<D> {
    /// The levels below `fine`, coarsened until the coarsest has at most `COARSEST_ROWS` rows or
    /// stops shrinking.
    /// Without `cycle`, only the fine operator (preconditioned by the caller).
    pub fn new(mut fine: NodeOperator<D>, cycle: bool) -> Self {
        if !cycle {
            return Multilevel {
                weak: Vec::new(),
                levels: vec![fine],
                parent: Vec::new(),
                coarsest: None,
                body: Vec::new(),
                bodies: 0,
            };
        }
        let largest = fine.diagonal.iter().fold(0.0f64, |a, &d| a.max(d));
        let threshold = WEAK_ROW;
        let weak: Vec<f64> = fine
            .diagonal
            .iter_mut()
            .map(|d| {
                if *d > 0.0 && *d < threshold * largest {
                    std::mem::replace(d, 0.0)
                } else {
                    0.0
                }
            })
            .collect();
        let mut levels = vec![fine];
        let mut parent = Vec::new();
        loop {
            let last = levels.last().expect("the fine level");
            let rows = last.diagonal.len();
            if rows <= COARSEST_ROWS {
                break;
            }
            let (coarse, up) = last.coarsen();
            if coarse.diagonal.len() * 3 > rows * 2 {
                break;
            }
            levels.push(coarse);
            parent.push(up);
        }
        let last = levels.last().expect("the fine level");
        let n = last.diagonal.len();
        let mut dense = nalgebra::DMatrix::<f64>::zeros(n, n);
        for i in 0..n {
            let start = i * last.block;
            for e in 0..last.count[i] as usize {
                dense[(i, last.column[start + e] as usize)] += last.value[start + e];
            }
            dense[(i, i)] += if last.diagonal[i] > 0.0 {
                1e-10 * last.diagonal[i]
            } else {
                1.0
            };
        }
        // The bodies: rows joined by an entry (rows without particles in none).
        let numbers = super::bodies(n, n, |i, visit: &mut dyn FnMut(usize)| {
            visit(i);
            let start = i * last.block;
            for e in 0..last.count[i] as usize {
                if last.value[start + e] != 0.0 {
                    visit(last.column[start + e] as usize);
                }
            }
        });
        let bodies = numbers.iter().max().map_or(0, |&b| b + 1);
        let body = (0..n)
            .map(|i| {
                if last.diagonal[i] > 0.0 {
                    numbers[i]
                } else {
                    usize::MAX
                }
            })
            .collect();
        Multilevel {
            weak,
            levels,
            parent,
            coarsest: dense.cholesky(),
            body,
            bodies,
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

    /// Whether a V-cycle pays for the fine operator `K`: with the node blocks alone the
    /// iterations grow with the width of the nodes (about 3 per node across: 457 at 161 nodes
    /// across in 2D, 82 at 26 in 3D, on the throughput example's blocks), while a V-cycle costs
    /// about six products with `K` and takes about a dozen iterations (`COARSE_WEIGHT`).
    pub fn pays<const E: usize>(fine: &NodeOperator<E>) -> bool {
        (fine.diagonal.len() as f64).powf(1.0 / E as f64) >= MULTILEVEL_WIDTH
    }

    /// `z = M⁻¹ r`: one V-cycle from zero.
    pub fn precondition(&self, r: &[f64], z: &mut [f64]) {
        self.cycle(0, r, z);
        z.par_chunks_exact_mut(D)
            .zip(r.par_chunks_exact(D))
            .zip(self.weak.par_iter())
            .for_each(|((z, r), &d)| {
                if d > 0.0 {
                    for k in 0..D {
                        z[k] = r[k] / d;
                    }
                }
            });
    }

    fn cycle(&self, l: usize, r: &[f64], x: &mut [f64]) {
        let level = &self.levels[l];
        x.fill(0.0);
        if l + 1 == self.levels.len() {
            // The right-hand side's constant part per body, which no solution meets (round-off
            // of the residual's sum, which `K`'s zero column sums keep at zero), removed before
            // the solve and the solution's after it: the regularisation would amplify them.
            if let Some(c) = &self.coarsest {
                let n = level.diagonal.len();
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
            return;
        }
        let mut kx = vec![0.0; r.len()];
        for _ in 0..SMOOTHING_SWEEPS {
            level.smooth(r, x, &mut kx);
        }
        // The residual, summed onto the aggregates in row order.
        level.apply(x, &mut kx);
        let parent = &self.parent[l];
        let coarse = self.levels[l + 1].diagonal.len();
        let mut rc = vec![0.0; coarse * D];
        for (i, &a) in parent.iter().enumerate() {
            if a != u32::MAX {
                for k in 0..D {
                    rc[a as usize * D + k] += r[i * D + k] - kx[i * D + k];
                }
            }
        }
        let mut xc = vec![0.0; coarse * D];
        self.cycle(l + 1, &rc, &mut xc);
        x.par_chunks_exact_mut(D)
            .zip(parent.par_iter())
            .for_each(|(x, &a)| {
                if a != u32::MAX {
                    for k in 0..D {
                        x[k] += COARSE_WEIGHT * xc[a as usize * D + k];
                    }
                }
            });
        for _ in 0..SMOOTHING_SWEEPS {
            level.smooth(r, x, &mut kx);
        }
    }
}
