//! The checks of a step's new state: every particle finite, not inverted and inside the grid
//! (decided per particle by the constitutive update, [`super::ParticleUpdate::check`]), every
//! boundary point inside the walls. A step that fails them is rejected with a message naming
//! the first offender and the step, and the simulation keeps its last good state.

use super::{NewState, Reorder, StepInputs, Workspace};
use crate::error::{Error, ErrorKind, Result};

/// Which step a message is about: its number (counted from 1) and the time it starts at.
#[derive(Debug, Clone, Copy)]
pub(crate) struct StepLabel {
    pub number: u64,
    pub time: f64,
}

/// Checks the new state of `work` (`all_admissible`: every particle passed its own checks) and
/// settles the boundary points' new positions inside the walls; the error for the first
/// offender.
pub(super) fn check_new_state<const D: usize, S>(
    inputs: &StepInputs<'_, D, S>,
    all_admissible: bool,
    work: &mut Workspace<D>,
) -> Result<()> {
    // Slot `k` of the new state holds particle `source[k]` when grid to particle sorted it.
    let source = (work.reorder == Reorder::InGather).then_some(&inputs.bins.order[..]);
    if !all_admissible {
        if let Some(error) =
            first_rejected_particle(inputs, &work.new_state, &work.admissible, source)
        {
            return Err(error);
        }
    }
    if inputs.surface_plan.carry && inputs.boundary.is_empty() {
        settle_carried_surface(inputs, &mut work.boundary_updates);
        return Ok(());
    }
    match settle_boundary_points(inputs, &mut work.boundary_updates) {
        Some(error) => Err(error),
        None => Ok(()),
    }
}

/// The error for the first particle (lowest id) whose new state failed the checks, if any.
/// Slot `k` of `new` holds particle `source[k]` (or `k`).
fn first_rejected_particle<const D: usize, S>(
    inputs: &StepInputs<'_, D, S>,
    new: &NewState<D>,
    admissible: &[bool],
    source: Option<&[u32]>,
) -> Option<Error> {
    let (ps, dt, label) = (inputs.particles, inputs.dt, inputs.label);
    let id_of = |k: usize| ps.id[source.map_or(k, |s| s[k] as usize)];
    let k = admissible
        .iter()
        .enumerate()
        .filter(|(_, ok)| !**ok)
        .min_by_key(|&(k, _)| id_of(k))
        .map(|(k, _)| k)?;
    let (kind, what) = new.get(k).check(&inputs.grid.domain()).unwrap_err();
    let id = id_of(k);
    let message = format!(
        "step {} (t = {:e}, dt = {dt:e}) rejected: particle {id} {what}; the simulation keeps its last good state",
        label.number, label.time
    );
    Some(Error::new(kind, message))
}

/// A carried found surface is the engine's own quadrature, not the caller's points: its moved
/// points are kept inside the grid's box (the surface found from the particles ends at the box
/// too), and where one cannot be carried (a non-finite value, an inverted `F_b`) none is: the
/// updates are dropped and the next step finds the surface anew, where given boundary points
/// would refuse the step.
fn settle_carried_surface<const D: usize, S>(
    inputs: &StepInputs<'_, D, S>,
    updates: &mut Vec<super::BoundaryUpdate<D>>,
) {
    let domain = inputs.grid.domain();
    for u in updates.iter_mut() {
        for a in 0..D {
            if u.position[a].is_finite() {
                u.position[a] = u.position[a].max(domain.lower[a]).min(domain.upper[a]);
            }
        }
    }
    if super::surface::settle_boundary_points(inputs.walls, &domain, updates).is_some() {
        updates.clear();
    }
}

/// Keeps the boundary points' new positions inside the walls; the error for the first one
/// outside the grid, if any.
fn settle_boundary_points<const D: usize, S>(
    inputs: &StepInputs<'_, D, S>,
    updates: &mut [super::BoundaryUpdate<D>],
) -> Option<Error> {
    let domain = inputs.grid.domain();
    let bad = super::surface::settle_boundary_points(inputs.walls, &domain, updates);
    let (b, what) = bad?;
    let message = format!(
        "step {} (t = {:e}, dt = {:e}) rejected: boundary point {b} {what}",
        inputs.label.number, inputs.label.time, inputs.dt
    );
    Some(Error::new(ErrorKind::OutsideGrid, message))
}
