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
//! stencil: a few per particle instead of two stencil passes.

use crate::grid::{Bins, Grid, GridNodes, SharedSlice};
use crate::shape::Stencils;
use rayon::prelude::*;

/// `K` of order 1 on the active nodes (slots): per slot a row of at most `(2w − 1)^D` entries,
/// packed at the front of its block of that length.
pub(crate) struct NodeOperator {
    /// Entries a row's block holds.
    block: usize,
    /// Per slot: how many entries its row has.
    count: Vec<u32>,
    /// Per row block: the column slots, then the values.
    column: Vec<u32>,
    value: Vec<f64>,
}

impl NodeOperator {
    /// Assembles `K` from the particles that `counted` admits, visited by the colours of `bins`
    /// (blocks of one colour write disjoint rows: the same bits with any number of threads).
    /// `moment[slot]` is `A_I`. `None` when the stencils are not a box of `w^D` nodes.
    #[allow(clippy::too_many_arguments)]
    pub fn assemble<const D: usize>(
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
            let in_support =
                |w: f64, g: &crate::Vector<D>| w != 0.0 || *g != crate::Vector::<D>::zeros();
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
                            w[s] = if in_support(vs[s], &gs[s]) {
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
        Some(NodeOperator {
            block,
            count,
            column,
            value,
        })
    }

    /// `out = K ζ` for `D` directions stored per slot (`ζ[slot * D + k]`).
    pub fn apply<const D: usize>(&self, zeta: &[f64], out: &mut [f64]) {
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
