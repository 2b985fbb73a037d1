//! Contact (METHOD.md section 6): one node field per body. Each body maps to its own field and
//! gets its own grid update (a deformable body under VC its own surface and correction; a
//! rigid body's nodes take its velocity); then the nodes that more than one body touched get
//! the contact correction ([`crate::contact::correct_velocities`]).

use super::profile::lap;
use super::{grid_update, particle_to_grid, Forces, PhaseTimes, StepInputs, ToGrid};
use crate::energy::NodeLosses;
use crate::error::Result;
use crate::grid::GridNodes;
use crate::integration::{BoundaryPoints, VcCorrection, VcInputs};
use crate::options::Contact;
use crate::shape::{StencilView, Stencils};
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
}

/// What the per-body maps read besides the step's inputs.
pub(super) struct BodyInputs<'a, const D: usize> {
    pub contact: Contact,
    /// The forces of the one-field map (each body's VC correction replaces `vc`).
    pub forces: Forces<'a, D>,
    /// The particles' current volumes, for VC.
    pub volumes: &'a [f64],
    /// Nodes at or below this fraction of the largest particle mass get no velocity.
    pub mass_floor_fraction: f64,
}

/// Particle to grid, grid update and the contact correction, body by body. Returns the mass
/// floor of the grid updates and, under VC, the bodies' surfaces together (what
/// `Sim::vc_surface` shows).
pub(super) fn particle_to_grid_per_body<const D: usize, S: StencilView<D>>(
    inputs: &StepInputs<'_, D, S>,
    body_inputs: &BodyInputs<'_, D>,
    bodies: &mut BodyFields<D>,
    boundary_stencils: &mut Stencils<D>,
    times: &mut PhaseTimes,
    losses: &mut NodeLosses,
) -> Result<(f64, BoundaryPoints<D>)> {
    let StepInputs {
        grid,
        particles: ps,
        stencils,
        stored,
        bins,
        walls,
        shape,
        rigid,
        plan,
        dt,
        ..
    } = *inputs;
    let BodyInputs {
        contact,
        forces,
        volumes,
        mass_floor_fraction,
    } = *body_inputs;
    let (v, c) = (&ps.velocity[..], &ps.affine[..]);
    let velocity = move |p: usize| v[p];
    let affine = plan.apic.then_some(move |p: usize| c[p]);
    let mut clock = std::time::Instant::now();
    let mut mass_floor = 0.0;
    let mut surfaces = BoundaryPoints::default();
    for (b, nodes) in bodies.nodes.iter_mut().enumerate() {
        // VC of a deformable body: its surface and its correction on its own field.
        let vc = match bodies.vc.get_mut(b).filter(|_| rigid[b].is_none()) {
            Some(vc) => {
                let surface = super::surface::found_surface(grid, ps, Some(b as u32))?;
                times.surface += lap(&mut clock);
                boundary_stencils.compute(shape, grid, &surface.position);
                let vc_inputs = VcInputs {
                    grid,
                    bins,
                    positions: &ps.position,
                    volumes,
                    stencils: stored.expect("VC runs with stored stencils"),
                    boundary: &surface,
                    boundary_stencils,
                    body: Some((&ps.material, b as u32)),
                };
                vc.compute(vc_inputs, nodes);
                surfaces.add(&surface.position, &surface.area_normal, None)?;
                times.forces_and_vc += lap(&mut clock);
                Some(&*vc)
            }
            None => None,
        };
        let to = ToGrid {
            grid,
            particles: ps,
            bins,
            stencils,
            shape: stored,
        };
        let largest_mass = particle_to_grid(
            &to,
            velocity,
            affine,
            Some(Forces { vc, ..forces }),
            Some(b as u32),
            nodes,
        );
        mass_floor = mass_floor_fraction * largest_mass;
        if let (Some(vc), Some(stored)) = (vc, stored) {
            let material = &ps.material;
            let in_body = |p: usize| material[p] == b as u32;
            let (found, n) = (vc.bodies(), ps.len());
            super::vc_torque::remove_vc_torque(grid, walls, stored, n, in_body, found, nodes);
        }
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
    // The work of the correction's impulses on the deformable bodies' velocities after it,
    // `Σ m (v − v*)·v*` at the shared nodes (in node order): their normal parts cancel (every
    // body leaves a node with the same normal velocity, and the impulses balance), so what is
    // counted is friction on the slip, and a rigid body's push (negative: its work).
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
    Ok((mass_floor, surfaces))
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
