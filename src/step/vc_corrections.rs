//! The boundary points and the VC corrections of a step (METHOD.md section 3): the given
//! boundary points, or for VC without any the surface found from the particles as they are now
//! (under contact each body's own, with its correction, `contact::vc_per_body`); their
//! stencils; and the corrections of the test-function gradients ([`VcCorrection::compute`]).

use super::profile::lap;
use super::surface::found_surface;
use super::{StepInputs, Workspace};
use crate::error::Result;
use crate::integration::{BoundaryPoints, VcCorrection, VcInputs};
use crate::shape::StencilView;

/// Phase 2: sets up the boundary points the step needs (VC or tractions) and computes the VC
/// corrections of the one field, or under contact each body's. Returns whether the boundary
/// points are the surface found from the particles (then in `surface`) and, under contact with
/// VC, the bodies' surfaces.
pub(super) fn boundary_and_corrections<const D: usize, S: StencilView<D>>(
    inputs: &StepInputs<'_, D, S>,
    vc: &mut Option<VcCorrection<D>>,
    surface: &mut BoundaryPoints<D>,
    work: &mut Workspace<D>,
) -> Result<(bool, BoundaryPoints<D>)> {
    let (grid, ps, contact) = (inputs.grid, inputs.particles, inputs.options.contact);
    let mut clock = std::time::Instant::now();
    let found = vc.is_some() && inputs.boundary.is_empty();
    work.times.forces_and_vc += lap(&mut clock);
    if found && contact.is_none() && inputs.surface_plan.find {
        *surface = found_surface(grid, ps, None)?;
    }
    work.times.surface += lap(&mut clock);
    let boundary = if found { &*surface } else { inputs.boundary };
    let with_boundary = vc.is_some() || boundary.has_tractions();
    if with_boundary && contact.is_none() {
        work.boundary_stencils
            .compute(inputs.shape, grid, &boundary.position);
    }

    // VC corrections of the test-function gradients (per body under contact, in `contact`).
    if vc.is_none() || contact.is_none() {
        // No per-body corrections left from a step that had them.
        work.bodies.vc.clear();
    }
    if let Some(vc) = vc.as_ref() {
        work.volumes.clear();
        work.volumes.extend((0..ps.len()).map(|p| ps.volume(p)));
        let bodies = inputs.materials.len();
        if contact.is_some()
            && (work.bodies.vc.len() != bodies
                || work.bodies.vc.iter().any(|c| c.order != vc.order))
        {
            work.bodies.vc = vec![vc.clone(); bodies];
        }
    }
    if let Some(vc) = vc.as_mut().filter(|_| contact.is_none()) {
        let vc_inputs = VcInputs {
            grid,
            bins: inputs.bins,
            positions: &ps.position,
            volumes: &work.volumes,
            stencils: inputs.stored.expect("VC runs with stored stencils"),
            tensor: inputs.stencils.tensor_factors(),
            boundary,
            boundary_stencils: &work.boundary_stencils,
            body: None,
        };
        vc.compute(vc_inputs, &mut work.nodes);
    }
    work.times.forces_and_vc += lap(&mut clock);
    let mut body_surfaces = BoundaryPoints::default();
    if vc.is_some() && contact.is_some() {
        let (volumes, bodies) = (&work.volumes, &mut work.bodies);
        let stencils = &mut work.boundary_stencils;
        let times = &mut work.times;
        body_surfaces = super::contact::vc_per_body(inputs, volumes, bodies, stencils, times)?;
    }
    Ok((found, body_surfaces))
}
