//! Signed shape functions (RK of order ≥ 2) at the edge of a body: the transfer weights.
//!
//! `Σ_p m_p Ψ_I(x_p)` of a node that barely overlaps a body is tiny or negative, so such a node
//! takes the kernel's nonnegative Shepard functions `L_I` (a partition of unity) instead. Each
//! node gets a weight `θ_I` from its two masses ([`EdgeLumping::blend`]: 1 inside a body, 0 at
//! a node that barely overlaps it), and every particle transfers with
//!
//! `Φ_I(x_p) = (θ_I Ψ_I(x_p) + (1 − θ_I) L_I(x_p)) / S_p`, `S_p = Σ_J θ_J Ψ_J(x_p) + (1 − θ_J) L_J(x_p)`,
//!
//! in place of `Ψ`: mass, momentum and body force to the grid, velocity back. The weights of
//! each particle sum to one and the same weights go both ways, so the transfers conserve linear
//! momentum (`Σ_I (mv)_I = Σ_p m_p v_p` and `Σ_p m_p v_p = Σ_I m_I v_I`); the gradients stay
//! `∇Ψ` (internal force, velocity gradient), which sum to zero. A particle whose nodes all have
//! `θ = 1` keeps `Ψ` bit for bit, so nothing changes inside a body. VC's divergence equalities
//! take `Φ` as their test function (`crate::integration`), so that the internal force balances
//! the body force weighed by `Φ`; the nodes' `θ` stays set until the next step's transfer
//! weights for that, and [`transfer_weights`] gives the boundary points' `Φ`.
//!
//! `θ` comes from the masses the nodes have after the mirror walls folded their ghosts in; a
//! ghost takes its mirror node's `θ`, since its function is folded into that node's.

use crate::grid::{EdgeLumping, Grid, GridNodes};
use crate::options::Walls;
use crate::particles::Particles;
use crate::shape::Stencils;
use rayon::prelude::*;

/// Sets the transfer weights `Φ` of the particles' stencils (of material `body` only, when
/// given; the others keep theirs), with `θ` from the masses of `nodes`. Leaves `nodes` reset.
pub fn blend_transfer_weights<const D: usize>(
    grid: &Grid<D>,
    walls: &Walls<D>,
    ps: &Particles<D>,
    body: Option<u32>,
    stencils: &mut Stencils<D>,
    nodes: &mut GridNodes<D>,
) {
    if stencils.lumping.is_empty() || nodes.lumping.is_none() {
        return;
    }
    let member = |p: usize| body.is_none_or(|b| ps.material[p] == b);
    // The blend of the last step stays until now (VC reads it at the boundary points).
    if let Some(l) = nodes.lumping.as_mut() {
        l.blend.par_iter_mut().for_each(|t| *t = 1.0);
    }
    // Both masses of every node, in particle order (the same sums with any number of threads).
    for p in (0..ps.len()).filter(|&p| member(p)) {
        let (ns, ws, _) = stencils.of(p);
        let ls = stencils.lumping_of(p).expect("checked above");
        let m = ps.mass[p];
        for s in 0..ns.len() {
            nodes.touch(ns[s]);
            nodes.mass[ns[s]] += m * ws[s];
            if let Some(l) = nodes.lumping.as_mut() {
                l.mass[ns[s]] += m * ls[s];
            }
        }
    }
    walls.fold(grid, nodes, true);
    let GridNodes {
        mass,
        lumping,
        active,
        ..
    } = &mut *nodes;
    let EdgeLumping {
        mass: lumped,
        blend,
    } = lumping.as_mut().expect("checked above");
    for &n in active.iter() {
        blend[n] = EdgeLumping::blend(mass[n], lumped[n]);
    }
    walls.unfold_values(grid, active, blend);
    let blend = &*blend;
    let Stencils {
        len,
        nodes: stencil_nodes,
        values,
        lumping: lumping_weights,
        transfer,
        ..
    } = stencils;
    let len = *len;
    if transfer.len() != values.len() {
        transfer.clone_from(values);
    }
    transfer
        .par_chunks_mut(len)
        .zip(values.par_chunks(len))
        .zip(lumping_weights.par_chunks(len))
        .zip(stencil_nodes.par_chunks(len))
        .enumerate()
        .filter(|&(p, _)| member(p))
        .for_each(|(_, (((phi, w), l), ns))| blend_into(ns, w, l, blend, phi));
    nodes.reset();
}

/// `Φ` of one point from its stencil's nodes `ns`, shape values `w` and lumping weights `l`,
/// with the nodes' `blend`, into `phi`.
fn blend_into(ns: &[usize], w: &[f64], l: &[f64], blend: &[f64], phi: &mut [f64]) {
    if ns.iter().all(|&n| blend[n] == 1.0) {
        phi.copy_from_slice(w);
        return;
    }
    for s in 0..ns.len() {
        let theta = blend[ns[s]];
        phi[s] = theta * w[s] + (1.0 - theta) * l[s];
    }
    let sum: f64 = phi.iter().sum();
    if sum > 0.5 {
        phi.iter_mut().for_each(|w| *w /= sum);
    } else {
        // Not met in the tests (the blend keeps `S_p` near or above 1); the lumping
        // alone also sums to one.
        phi.copy_from_slice(l);
    }
}

/// The transfer weights `Φ` of a point that is not a particle (a boundary point), with the
/// nodes' `blend` of this step, into `out`.
pub fn transfer_weights(ns: &[usize], w: &[f64], l: &[f64], blend: &[f64], out: &mut Vec<f64>) {
    out.clear();
    out.resize(ns.len(), 0.0);
    blend_into(ns, w, l, blend, out);
}
