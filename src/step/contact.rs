//! Contact (METHOD.md section 6): one node field per body, phase by phase. Under VC each
//! deformable body gets its own surface and correction (phase 2); each body maps to its own field
//! (phase 3) and gets its own grid update, a rigid body's nodes its velocity; then the nodes that
//! more than one body touched get the contact correction (phase 4,
//! [`crate::contact::correct_velocities`]).

use super::profile::lap;
use super::{grid_update, particle_to_grid, Forces, PhaseTimes, StepInputs, ToGrid};
use crate::energy::NodeLosses;
use crate::error::Result;
use crate::grid::GridNodes;
use crate::integration::{BoundaryPoints, VcCorrection, VcInputs};
use crate::options::Contact;
use crate::shape::{StencilView, Stencils, SupportNodes};
use crate::Vector;

/// The node fields of the bodies under contact, kept between steps.
#[derive(Debug, Default)]
pub struct BodyFields<const D: usize> {
    /// One node field per body (material); empty without contact.
    pub nodes: Vec<GridNodes<D>>,
    /// Each body's VC correction (VC under contact); empty otherwise.
    pub vc: Vec<VcCorrection<D>>,
    /// Nodes touched by more than one body this step.
    pub shared: Vec<usize>,
    /// Each body's mass floor this step (particle to grid gives it to the grid update).
    pub mass_floor: Vec<f64>,
}

/// Phase 2 under contact with VC: each deformable body's surface, found from its particles,
/// and its own correction (`volumes`: the particles' current volumes). Returns the bodies'
/// surfaces, one set of points.
pub(super) fn vc_per_body<const D: usize, S: StencilView<D>>(
    inputs: &StepInputs<'_, D, S>,
    volumes: &[f64],
    bodies: &mut BodyFields<D>,
    boundary_stencils: &mut Stencils<D>,
    times: &mut PhaseTimes,
) -> Result<BoundaryPoints<D>> {
    let (grid, ps, rigid) = (inputs.grid, inputs.particles, inputs.rigid);
    let mut clock = std::time::Instant::now();
    let mut surfaces = BoundaryPoints::default();
    for (b, nodes) in bodies.nodes.iter_mut().enumerate() {
        let Some(vc) = bodies.vc.get_mut(b).filter(|_| rigid[b].is_none()) else {
            continue;
        };
        let surface = super::surface::found_surface(grid, ps, Some(b as u32))?;
        times.surface += lap(&mut clock);
        boundary_stencils.compute(inputs.shape, grid, &surface.position);
        let vc_inputs = VcInputs {
            grid,
            bins: inputs.bins,
            positions: &ps.position,
            volumes,
            stencils: inputs.stored.expect("VC runs with stored stencils"),
            tensor: inputs.stencils.tensor_factors(),
            boundary: &surface,
            boundary_stencils,
            body: Some((&ps.material, b as u32)),
        };
        vc.compute(vc_inputs, nodes);
        surfaces.add(&surface.position, &surface.area_normal, None)?;
        times.forces_and_vc += lap(&mut clock);
    }
    Ok(surfaces)
}

/// Phase 3 under contact: each body's particles to its own field (with its VC correction, and
/// VC's torque removed body by body). Each body's mass floor, `mass_floor_fraction` of its
/// largest particle mass, goes to `bodies.mass_floor`; returns the last body's.
pub(super) fn particle_to_grid_per_body<const D: usize, S: StencilView<D>>(
    inputs: &StepInputs<'_, D, S>,
    forces: Forces<'_, D>,
    mass_floor_fraction: f64,
    bodies: &mut BodyFields<D>,
) -> f64 {
    let (grid, ps, plan, rigid) = (inputs.grid, inputs.particles, inputs.plan, inputs.rigid);
    let (v, c) = (&ps.velocity[..], &ps.affine[..]);
    let velocity = move |p: usize| v[p];
    let affine = plan.apic.then_some(move |p: usize| c[p]);
    bodies.mass_floor.clear();
    for (b, nodes) in bodies.nodes.iter_mut().enumerate() {
        let vc = bodies.vc.get(b).filter(|_| rigid[b].is_none());
        let largest_mass = particle_to_grid(
            &ToGrid::of(inputs),
            velocity,
            affine,
            Some(Forces { vc, ..forces }),
            Some(b as u32),
            nodes,
        );
        bodies.mass_floor.push(mass_floor_fraction * largest_mass);
        if let (Some(vc), Some(stored)) = (vc, inputs.stored) {
            let material = &ps.material;
            let in_body = |p: usize| material[p] == b as u32;
            let (found, n) = (vc.bodies(), ps.len());
            let walls = inputs.walls;
            let tensor = inputs.stencils.tensor_factors();
            let support = SupportNodes { stored, tensor };
            super::vc_torque::remove_vc_torque(grid, walls, support, n, in_body, found, nodes);
        }
    }
    bodies.mass_floor.last().copied().unwrap_or(0.0)
}

/// Phase 4 under contact: each body's grid update with the walls (a rigid body's nodes take
/// its velocity), then the contact correction on the nodes more than one body touched. Returns
/// what the deformable bodies' friction walls and the correction took.
pub(super) fn grid_update_per_body<const D: usize, S: StencilView<D>>(
    inputs: &StepInputs<'_, D, S>,
    contact: Contact,
    bodies: &mut BodyFields<D>,
) -> NodeLosses {
    let (grid, walls, rigid, dt) = (inputs.grid, inputs.walls, inputs.rigid, inputs.dt);
    let mut losses = NodeLosses::default();
    for ((b, nodes), &mass_floor) in bodies.nodes.iter_mut().enumerate().zip(&bodies.mass_floor) {
        let friction = grid_update(grid, walls, nodes, Some(dt), mass_floor, false);
        if rigid[b].is_none() {
            losses.friction += friction;
        }
        if let Some(v) = rigid[b] {
            for &n in &nodes.active {
                nodes.velocity[n] = v;
                nodes.velocity_old[n] = v;
            }
        }
    }
    find_shared_nodes(&bodies.nodes, &mut bodies.shared);
    let before: Vec<Vec<Vector<D>>> = bodies
        .nodes
        .iter()
        .map(|f| bodies.shared.iter().map(|&n| f.velocity[n]).collect())
        .collect();
    crate::contact::correct_velocities(&contact, &mut bodies.nodes, rigid, &bodies.shared);
    let mut taken = 0.0;
    for (k, &n) in bodies.shared.iter().enumerate() {
        for ((field, v), _) in bodies
            .nodes
            .iter()
            .zip(&before)
            .zip(rigid)
            .filter(|(_, r)| r.is_none())
        {
            if field.is_touched(n) {
                let after = field.velocity[n];
                taken += field.mass[n] * (v[k] - after).dot(&after);
            }
        }
    }
    losses.contact = taken;
    losses
}

/// The nodes that more than one of `bodies` touched, each once: those of the first body that a
/// later one touched, then for each later body those it touched first and a still later one
/// touched too.
fn find_shared_nodes<const D: usize>(bodies: &[GridNodes<D>], shared: &mut Vec<usize>) {
    shared.clear();
    for &n in &bodies[0].active {
        if bodies[1..].iter().any(|b| b.is_touched(n)) {
            shared.push(n);
        }
    }
    for (k, body) in bodies.iter().enumerate().skip(1) {
        for &n in &body.active {
            if !bodies[..k].iter().any(|b| b.is_touched(n))
                && bodies[k + 1..].iter().any(|b| b.is_touched(n))
            {
                shared.push(n);
            }
        }
    }
}
