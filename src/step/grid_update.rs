//! Grid update: `v_I = ((mv)_I + Δt f_I) / m_I` with the wall conditions.

use crate::boundary::Walls;
use crate::grid::{Grid, GridNodes, LumpingShift, SharedSlice};
use crate::Vector;
use rayon::prelude::*;

/// Signed shape functions and VC integration: the smallest node mass, as a fraction of the
/// largest node mass, that a node's internal force is divided by. Nodes that barely overlap a
/// body have a tiny lumped mass but not a tiny (VC-corrected) force; without this limit, an
/// RK2 + VC2 column under its own weight at 32 cells lets the velocities above its free surface
/// grow until a boundary point inverts (t ≈ 1.2 s), and a quadratic B-spline + VC block with a
/// smooth small-strain velocity field stops at step 74 (2D) or 77 (3D) with an inverted boundary
/// point (found by the throughput benchmark). The body force is kept apart and not limited, so a
/// uniform gravity stays exact.
const EDGE_MASS_FRACTION: f64 = 1e-2;

/// Updates the velocities of the active nodes.
///
/// With `dt = Some(Δt)`: folds mass, momentum and force of mirrored walls, sets
/// `velocity_old = (mv)/m` and `velocity = ((mv) + Δt f)/m`, applies friction walls and sets the
/// ghost velocities. With `None` (the second map of MUSL): folds momentum only and sets
/// `velocity = (mv)/m`. Nodes with mass at or below `mass_floor` get zero velocity; nothing is
/// divided by a negligible mass.
///
/// With a lumping shift (signed shape functions), each node's mass, momentum and body force are
/// `(1 − θ)` of the way from the `Ψ` sums to the nonnegative-lumping sums, with `θ` from
/// [`LumpingShift::blend`] (1 inside a body, so nothing changes there).
pub fn grid_update<const D: usize>(
    grid: &Grid<D>,
    walls: &Walls<D>,
    nodes: &mut GridNodes<D>,
    dt: Option<f64>,
    mass_floor: f64,
) {
    walls.fold(grid, nodes, dt.is_some());
    // Signed shape functions: nodes at the edge of a body have a tiny mass but not a tiny
    // (VC-corrected) force; their acceleration is taken against at least a fraction of the
    // largest node mass (see [`EDGE_MASS_FRACTION`]).
    // The limit is on exactly when the body force is kept apart (signed shapes and VC).
    let force_mass_floor = match (!nodes.body_force.is_empty(), dt) {
        (true, Some(_)) => {
            EDGE_MASS_FRACTION
                * nodes
                    .active
                    .iter()
                    .map(|&n| nodes.mass[n])
                    .fold(0.0, f64::max)
        }
        _ => 0.0,
    };
    // Every active node on its own, in parallel (the list holds each node once).
    let GridNodes {
        mass,
        momentum,
        force,
        velocity_old,
        velocity,
        lumping,
        body_force,
        active,
        ..
    } = nodes;
    let (mass, momentum) = (SharedSlice::new(mass), SharedSlice::new(momentum));
    let (velocity_old, velocity) = (SharedSlice::new(velocity_old), SharedSlice::new(velocity));
    let (force, body_force) = (&*force, &*body_force);
    let lumping = lumping.as_mut().map(|l| {
        (
            SharedSlice::new(&mut l.blend),
            &l.mass,
            SharedSlice::new(&mut l.momentum),
            &l.body_force,
        )
    });
    active.par_iter().for_each(|&n| {
        // SAFETY: `active` lists each node once, so every node is written by one task only.
        let (m, p) = unsafe { (mass.at(n), momentum.at(n)) };
        // Body force apart from the internal force under lumping (it is limited by the mass
        // floor only in the internal part, so that a uniform gravity stays exact).
        let mut body = Vector::<D>::zeros();
        if let Some((blend, l_mass, l_momentum, l_body)) = &lumping {
            let blend = unsafe { blend.at(n) };
            if dt.is_some() {
                *blend = LumpingShift::<D>::blend(*m, *m + l_mass[n]);
            }
            let rest = 1.0 - *blend;
            *p += rest * unsafe { *l_momentum.at(n) };
            if dt.is_some() {
                *m += rest * l_mass[n];
                body = body_force[n] + rest * l_body[n];
            }
        } else if dt.is_some() && !body_force.is_empty() {
            body = body_force[n];
        }
        let (v_old, v) = unsafe { (velocity_old.at(n), velocity.at(n)) };
        if *m <= mass_floor {
            *v = Vector::zeros();
            *v_old = Vector::zeros();
            return;
        }
        match dt {
            Some(dt) => {
                *v_old = *p / *m;
                *v = (*p + dt * body) / *m + dt * force[n] / m.max(force_mass_floor);
            }
            None => *v = *p / *m,
        }
    });
    walls.apply_friction(grid, nodes);
    walls.unfold(grid, nodes);
}
