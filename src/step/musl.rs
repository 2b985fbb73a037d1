//! The second map of modified USL (Sulsky, Chen & Schreyer 1994; METHOD.md section 1): after
//! grid to particle, the new particle momenta go to the grid again, and the velocity gradient of
//! each particle's `F` comes from those grid velocities rather than from the grid update's.

use super::{grid_update, mls_velocity_gradient, particle_to_grid, velocity_gradient};
use super::{NewState, StepInputs, ToGrid};
use crate::grid::GridNodes;
use crate::shape::StencilView;
use crate::{Matrix, Vector};
use rayon::prelude::*;

/// Maps the momenta of `new` to `nodes` (whose masses the first map left), sets the grid
/// velocities (nodes at or below `mass_floor` get none) and writes each particle's new `F` into
/// `new`.
pub(super) fn second_map<const D: usize, S: StencilView<D>>(
    inputs: &StepInputs<'_, D, S>,
    mass_floor: f64,
    nodes: &mut GridNodes<D>,
    new: &mut NewState<D>,
) {
    let StepInputs {
        grid,
        particles: ps,
        stencils,
        bins,
        walls,
        plan,
        dt,
        ..
    } = *inputs;
    for &n in &nodes.active {
        nodes.momentum[n] = Vector::zeros();
    }
    let v = &new.velocity[..];
    let velocity = move |p: usize| v[p];
    let to = ToGrid {
        grid,
        particles: ps,
        bins,
        stencils,
        shape: None,
    };
    particle_to_grid(
        &to,
        velocity,
        plan.apic.then_some({
            let c = &new.affine[..];
            move |p: usize| c[p]
        }),
        None,
        None,
        nodes,
    );
    grid_update(grid, walls, nodes, None, mass_floor, false);
    let nodes = &*nodes;
    new.deformation_gradient
        .par_iter_mut()
        .enumerate()
        .for_each(|(p, f)| {
            let l = match plan.mls_inverse_inertia() {
                Some(inv) => mls_velocity_gradient(stencils, grid, nodes, p, &ps.position[p], inv),
                _ => velocity_gradient(stencils, nodes, p),
            };
            *f = (Matrix::<D>::identity() + dt * l) * ps.deformation_gradient[p];
        });
}
