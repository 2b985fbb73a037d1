//! The torque of VC's internal forces, removed per body (METHOD.md section 3, "Angular
//! momentum").
//!
//! VC's corrected gradients sum to zero over a particle's nodes, so the internal forces keep
//! linear momentum; but their first moment `A_p = Σ_I (x_I − x_p) ⊗ (∇̂Ψ_Ip − ∇Ψ_Ip)` does not
//! vanish (with the mean fit, or at order ≥ 2), so a symmetric stress exerts the torque
//! `−V_p ε : (σ_p A_p)` and a free body's internal forces turn it (a jittered block lost 1e-4
//! of its angular momentum in 100 steps). The linear fit makes `A_p` vanish particle by
//! particle, but only for shapes with three nodes per axis in every support and at order 1.
//!
//! Here, for every shape and order, the internal forces of each free connected body of nodes
//! (the nodes that its particles join) lose the rigid rotation that carries their total torque:
//! `f_I ← f_I − m_I Ω (x_I − x_c)`, `x_c` the body's node mass centre and `Ω` antisymmetric
//! with `Σ_I m_I (x_I − x_c) × Ω (x_I − x_c) = Σ_I (x_I − x_c) × f_I`. Of all changes that
//! leave the forces' sum alone and make their torque zero, it is the one of least
//! `Σ_I |δf_I|² / m_I` (the accelerations change by least in the mass norm): it removes the
//! accelerations' rigid-rotation part, which the exact internal forces do not have. A body's
//! torque is the sum of its particles' (their forces sum to zero), so bodies that share no
//! node keep their own. Sums in node order: the same bits with any number of threads.
//!
//! Only free bodies: a body that a wall acts on (one of its nodes on a wall's face or beyond)
//! is not removed of its torque. Walls take angular momentum anyway, and there the torque is
//! not small against the body's own forces: in a granular column collapsing against its walls
//! (quadratic B-spline + VC1, mean fit, 16 cells) the correction's torque comes from local
//! errors at the breaking surface, and removing it as one rotation of the whole heap added an
//! acceleration of the order of gravity across it; a particle inverted at t = 0.80 s. With
//! walls elsewhere in the grid, the torque is that of the forces as the grid update applies
//! them: a node below the edge-mass floor (`grid_update`) keeps only `m_I / m_floor` of its
//! force, the rest is dropped (without walls it is handed to the whole field, its torque
//! included, so the whole force counts).

use super::grid_update::{edge_mass_floor, rigid_acceleration};
use crate::grid::{Grid, GridNodes};
use crate::integration::{bodies, box_bodies};
use crate::options::Walls;
use crate::shape::SupportNodes;
use crate::{Matrix, Vector};

/// Removes the torque of the internal forces in `nodes.force` per connected body of the
/// particles `in_field` (their stencils in `stencils`, their nodes active in `nodes`). `found`
/// is the body of every active node if the VC solve of this field found them
/// ([`crate::integration::VcCorrection::bodies`]: the same particles, stencils and nodes), else empty.
pub(super) fn remove_vc_torque<const D: usize>(
    grid: &Grid<D>,
    walls: &Walls<D>,
    stencils: SupportNodes<D>,
    particles: usize,
    in_field: impl Fn(usize) -> bool + Sync,
    found: &[usize],
    nodes: &mut GridNodes<D>,
) {
    // The fraction of a node's force the grid update applies where it drops the rest.
    let floor = match walls.any_wall() {
        true => edge_mass_floor(nodes),
        false => 0.0,
    };
    let applied = |m: f64| if m < floor { m / floor } else { 1.0 };
    let slots = nodes.active.len();
    let computed;
    let body_of = if found.len() == slots {
        found
    } else {
        let nodes = &*nodes;
        let from_boxes = stencils
            .tensor
            .as_ref()
            .and_then(|t| box_bodies(grid, nodes, t, particles, &in_field));
        computed = from_boxes.unwrap_or_else(|| {
            bodies(slots, particles, |p, visit: &mut dyn FnMut(usize)| {
                if in_field(p) {
                    stencils.for_each(p, |s| visit(nodes.slot(s.node)));
                }
            })
        });
        &computed
    };
    let count = body_of.iter().copied().max().map_or(0, |b| b + 1);
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); count];
    for (slot, &b) in body_of.iter().enumerate() {
        members[b].push(slot);
    }
    let position = |n: usize| grid.node_position(grid.node_multi_index(n));
    let walled = |n: usize| walls.any_wall() && walls.acts_on(grid, &grid.node_multi_index(n));
    for slots in members.iter().filter(|s| s.len() > 1) {
        let at = |slot: usize| nodes.active[slot];
        if slots.iter().any(|&s| walled(at(s))) {
            continue;
        }
        let receivers: Vec<(Vector<D>, f64)> = slots
            .iter()
            .map(|&s| (position(at(s)), nodes.mass[at(s)]))
            .collect();
        let forces: Vec<(Vector<D>, Vector<D>)> = slots
            .iter()
            .map(|&s| {
                let n = at(s);
                (position(n), applied(nodes.mass[n]) * nodes.force[n])
            })
            .collect();
        let Some((centre, _, rotation)) = rigid_acceleration(&receivers, &forces) else {
            continue;
        };
        if rotation == Matrix::<D>::zeros() {
            continue;
        }
        for (&s, (x, m)) in slots.iter().zip(&receivers) {
            nodes.force[nodes.active[s]] -= *m * (rotation * (x - centre));
        }
    }
}
