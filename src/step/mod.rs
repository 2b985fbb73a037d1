//! One explicit MPM step (METHOD.md section 1), phase by phase, each in the file named after it.
//! `Sim::step` checks the step and calls the body-force callback on the calling thread, then
//! runs a `Step` on the simulation's worker threads: `Step::run` computes the shape functions
//! and bins and calls `run_phases`, whose lines are the phases in order, then commits. What the
//! phases share (the workspace, their read-only inputs, the plans) is in `context`.
//!
//! 1. shape functions of every particle, once per step: B-splines as 1D factors
//!    ([`crate::shape::TensorStencils`]), RK and every shape under VC as node lists
//!    ([`crate::shape::Stencils`]); and the particles binned by grid block, the blocks coloured
//!    ([`Bins`], beside the grid), for the lock-free, thread-count-independent parallel maps to
//!    the grid (B-splines take each particle's block from its factors' first node);
//!    signed shapes blend their transfer weights at a body's edge (`edge_lumping`);
//! 2. body forces (the callback, once per step with whole arrays); the boundary points and the
//!    VC corrections (`vc_corrections`), over the given boundary points or the surface found
//!    from the particles (`surface`);
//! 3. [`particle_to_grid`]: mass, momentum (APIC term only under APIC), force; tractions
//!    (`surface`);
//! 4. [`grid_update`]: velocities, wall conditions; under contact one field per body, then the
//!    contact correction (`contact`);
//! 5. [`grid_to_particle`]: velocity (PIC/FLIP or APIC), position, velocity gradient, `F`;
//!    under USL each particle's constitutive update (`constitutive_update`) follows in the same
//!    pass, while it is in cache; under MUSL the new particle momenta are mapped to the grid
//!    again first (`musl`) and the constitutive update runs after; boundary points move with
//!    the grid (`surface`);
//! 6. the checks (`checks`), the commit, and the grid reset where it was written (while the
//!    next step bins).
//!
//! The new particle state is built in arrays of the workspace ([`NewState`]) and swapped with the
//! particles' only when every particle passed the checks (finite, `det F > 0`, inside the grid),
//! so a failed step leaves the last good state. `crate::reference` (tests only) is the same
//! step written plainly, node by node, and the oracle of the fast one.
//! [`PhaseTimes`] accumulates the time per phase.

mod checks;
mod constitutive_update;
mod contact;
mod context;
pub(crate) mod edge_lumping;
mod grid_to_particle;
mod grid_update;
mod musl;
mod particle_to_grid;
mod profile;
mod surface;
mod vc_corrections;
mod vc_torque;
pub(crate) use checks::StepLabel;
pub(crate) use profile::bytes as profile_bytes;
pub(crate) use profile::lap;
pub use profile::{MemoryUse, PhaseTimes};
#[cfg(test)]
pub(crate) use surface::found_surface;

use context::clear_grid;
pub(crate) use context::{surface_age_after, StepInputs, SurfacePlan};
pub use context::{Reorder, TransferPlan, Workspace};

pub use crate::grid::{Bins, BlockLayout};
#[cfg_attr(not(feature = "internals"), allow(unused_imports))] // for the benchmarks
pub use grid_to_particle::{
    grid_to_particle, mls_velocity_gradient, velocity_gradient, Fields, Finish, FromGrid, NewState,
    NewStateWriter, NoFinish, ParticleUpdate,
};
pub use grid_update::grid_update;
pub use particle_to_grid::{particle_to_grid, Forces, ToGrid};

use crate::cpu::Lanes;
use crate::energy::{traction_work, EnergyLedger, NodeLosses, StepStates};
use crate::error::Result;
use crate::grid::{Grid, GridNodes};
use crate::integration::{BoundaryPoints, VcCorrection};
use crate::material::{Constitutive, Material};
use crate::options::{FastPaths, Options, Scheme, Shape, Transfer};
use crate::particles::Particles;
use crate::shape::{BSpline, BSplineOrder, ShapeFunction, StencilView, Stencils, TensorStencils};
use crate::Vector;
use constitutive_update::ConstitutiveUpdate;
pub use contact::BodyFields;
use rayon::prelude::*;
pub use surface::BoundaryUpdate;
use surface::{apply_tractions, move_boundary_points};

/// One step of a simulation: what it reads of the simulation and what it changes
/// (`Sim::step` makes one after its checks and runs it on the simulation's worker threads).
pub(crate) struct Step<'a, const D: usize> {
    pub grid: &'a Grid<D>,
    pub shape: &'a dyn ShapeFunction<D>,
    pub options: &'a Options<D>,
    pub materials: &'a [Material],
    pub fast_paths: FastPaths,
    /// Whether the body-force callback gave `work.body_acceleration` for this step.
    pub body_force: bool,
    /// The step's number and start time, for messages.
    pub label: StepLabel,
    pub particles: &'a mut Particles<D>,
    pub boundary: &'a mut BoundaryPoints<D>,
    /// The surface VC finds from the particles when no boundary points are given.
    pub surface: &'a mut BoundaryPoints<D>,
    /// How the found surface is taken this step: found anew or carried ([`SurfacePlan`]).
    pub surface_plan: SurfacePlan,
    /// Steps the found surface has been carried since it was found (`u32::MAX`: to be found
    /// anew); the commit advances it.
    pub surface_age: &'a mut u32,
    pub vc: &'a mut Option<VcCorrection<D>>,
    pub work: &'a mut Workspace<D>,
    /// The energy ledger, which the commit adds the step's work to when it is on.
    pub energy: &'a mut EnergyLedger,
}

impl<const D: usize> Step<'_, D> {
    /// Runs the phases and, when every check passed, commits the new state; a rejected step
    /// changes nothing of the simulation but its scratch space.
    pub(crate) fn run(mut self, dt: f64) -> Result<()> {
        // A surface VC finds from the particles this step replaces the last one, which a
        // rejected step restores (a carried one changes only in the commit).
        let last_surface = self.surface_plan.find.then(|| std::mem::take(self.surface));
        let result = self.compute_step(dt);
        if let (Err(_), Some(last)) = (&result, last_surface) {
            *self.surface = last;
        }
        let mut clock = std::time::Instant::now();
        self.work.active_nodes = self.work.nodes.active.len();
        result?;
        self.commit();
        self.work.times.commit += lap(&mut clock);
        Ok(())
    }

    fn transfer_plan(&self) -> TransferPlan {
        match self.options.transfer {
            Transfer::PicFlip { flip } => TransferPlan {
                flip,
                apic: false,
                inverse_inertia: None,
                mls: false,
            },
            Transfer::Apic | Transfer::Mls => TransferPlan {
                flip: 0.0,
                apic: true,
                inverse_inertia: self
                    .shape
                    .apic_inertia(self.grid.cell_size)
                    .map(|d| 1.0 / d),
                mls: self.options.transfer == Transfer::Mls,
            },
        }
    }

    /// Runs the phases and returns the checked new particle state (in the workspace).
    fn compute_step(&mut self, dt: f64) -> Result<()> {
        let grid = &self.grid;
        let work = &mut self.work;
        let signed = self.shape.is_signed();
        // Signed shapes and VC keep the body force apart so that edge nodes' internal force
        // can be limited (grid_update).
        work.nodes
            .ensure(grid, signed, false, signed || self.vc.is_some())?;
        if self.options.contact.is_some() {
            work.bodies
                .nodes
                .resize_with(self.materials.len(), GridNodes::default);
            for b in work.bodies.nodes.iter_mut() {
                b.ensure(grid, signed, true, signed || self.vc.is_some())?;
            }
        }
        // 1. Shape functions, once per particle: B-splines (and RK1 with ã = 2) as 1D factors,
        //    with VC beside the stored lists its sums read. The nodes the last step wrote are
        //    cleared meanwhile.
        let order = (self.shape.tensor_order()).filter(|_| self.fast_paths.factored_stencils);
        match order {
            Some(BSplineOrder::Linear) => self.tensor_phases(dt, |w| &mut w.linear),
            Some(BSplineOrder::Quadratic) => self.tensor_phases(dt, |w| &mut w.quadratic),
            Some(BSplineOrder::Cubic) => self.tensor_phases(dt, |w| &mut w.cubic),
            None => {
                let mut clock = std::time::Instant::now();
                self.work.clear_grid();
                crate::shape::bin_particles(
                    &mut self.work.bins,
                    self.shape,
                    self.grid,
                    &self.particles.position,
                );
                self.work.times.bins += lap(&mut clock);
                let mut stencils = std::mem::take(&mut self.work.stencils);
                stencils.lanes = Lanes::chosen(self.fast_paths.vector_instructions);
                stencils.compute(self.shape, self.grid, &self.particles.position);
                if self.shape.is_signed() {
                    self.blend_transfer_weights(&mut stencils);
                }
                self.work.times.shape += lap(&mut clock);
                let result = self.phases(dt, &stencils, Some(&stencils));
                self.work.stencils = stencils;
                result
            }
        }
    }

    /// Signed shape functions: the stencils' transfer weights ([`edge_lumping`]), per body
    /// under contact.
    fn blend_transfer_weights(&mut self, stencils: &mut Stencils<D>) {
        let (grid, walls, ps) = (&self.grid, &self.options.walls, &self.particles);
        let work = &mut self.work;
        if self.options.contact.is_some() {
            for (b, nodes) in work.bodies.nodes.iter_mut().enumerate() {
                edge_lumping::blend_transfer_weights(
                    grid,
                    walls,
                    ps,
                    Some(b as u32),
                    stencils,
                    nodes,
                );
            }
        } else {
            edge_lumping::blend_transfer_weights(grid, walls, ps, None, stencils, &mut work.nodes);
        }
    }

    /// The phases with B-spline stencils stored as factors (`W` nodes per axis).
    fn tensor_phases<const W: usize>(
        &mut self,
        dt: f64,
        storage: impl Fn(&mut Workspace<D>) -> &mut TensorStencils<D, W>,
    ) -> Result<()> {
        let order = match W {
            2 => BSplineOrder::Linear,
            3 => BSplineOrder::Quadratic,
            _ => BSplineOrder::Cubic,
        };
        let mut stencils = std::mem::take(storage(self.work));
        stencils.lanes = Lanes::chosen(self.fast_paths.vector_instructions);
        // MLS reads no shape-function gradient, except for the mass gradient of contact and
        // VC's sums.
        let derivatives = self.options.transfer != Transfer::Mls
            || self.options.contact.is_some()
            || self.vc.is_some();
        // The particles' blocks are found with the factors, from their stencils' first nodes.
        let layout = BlockLayout::new(W, self.grid);
        let (grid, position) = (&self.grid, &self.particles.position);
        let work = &mut self.work;
        let (bins, times) = (&mut work.bins, &mut work.times);
        let (nodes, bodies) = (&mut work.nodes, &mut work.bodies.nodes);
        let mut clock = std::time::Instant::now();
        stencils.compute_with(&BSpline::new(order), grid, position, derivatives, &layout);
        times.shape += lap(&mut clock);
        // The nodes the last step wrote are cleared meanwhile: below 2^17 particles the bins
        // sort on one thread, and the other clears.
        rayon::join(
            || bins.compute_from_keys(&layout, stencils.block_keys()),
            || clear_grid(nodes, bodies),
        );
        times.bins += lap(&mut clock);
        // VC's sums and its part of the internal force read the stencils as stored lists too.
        let mut stored = self
            .vc
            .is_some()
            .then(|| std::mem::take(&mut self.work.stencils));
        if let Some(stored) = stored.as_mut() {
            stored.lanes = stencils.lanes;
            // The shape is the B-spline of width `W` on the lattice (`tensor_order`): its
            // lists from the factors just computed, not evaluated again.
            stored.fill_from_factors(&stencils);
            self.work.times.shape += lap(&mut clock);
        }
        let result = self.phases(dt, &stencils.local(), stored.as_ref());
        *storage(self.work) = stencils;
        if let Some(stored) = stored {
            self.work.stencils = stored;
        }
        result
    }

    /// The phases after the shape functions, with the particles' stencils (`stored`: the same
    /// as stored lists, when they are).
    fn phases<S: StencilView<D>>(
        &mut self,
        dt: f64,
        stencils: &S,
        stored: Option<&Stencils<D>>,
    ) -> Result<()> {
        let plan = self.transfer_plan();
        let rigid: Vec<Option<Vector<D>>> =
            self.materials.iter().map(|m| m.rigid_velocity()).collect();
        let work = &mut *self.work;
        // Every phase reads the bins and the body accelerations: out of the workspace meanwhile.
        let bins = std::mem::take(&mut work.bins);
        let body_acceleration = std::mem::take(&mut work.body_acceleration);
        let inputs = StepInputs {
            grid: self.grid,
            particles: &*self.particles,
            stencils,
            stored,
            bins: &bins,
            walls: &self.options.walls,
            options: self.options,
            shape: self.shape,
            materials: self.materials,
            rigid: &rigid,
            body_acceleration: self.body_force.then_some(&body_acceleration[..]),
            boundary: &*self.boundary,
            fast_paths: self.fast_paths,
            label: self.label,
            plan,
            surface_plan: self.surface_plan,
            dt,
        };
        let result = run_phases(&inputs, &mut *self.vc, &mut *self.surface, work);
        work.bins = bins;
        work.body_acceleration = body_acceleration;
        result
    }

    /// Swaps the checked new state into the particles (the old one becomes the next step's
    /// storage) and copies the new history of history particles.
    fn commit(&mut self) {
        if self.energy.on {
            self.add_work_to_ledger();
        }
        let ps = &mut self.particles;
        let new = &mut self.work.new_state;
        std::mem::swap(&mut ps.position, &mut new.position);
        std::mem::swap(&mut ps.velocity, &mut new.velocity);
        std::mem::swap(&mut ps.deformation_gradient, &mut new.deformation_gradient);
        std::mem::swap(&mut ps.stress, &mut new.stress);
        std::mem::swap(&mut ps.pressure, &mut new.pressure);
        if new.affine.len() == ps.affine.len() {
            std::mem::swap(&mut ps.affine, &mut new.affine);
        }
        // The new state came out in block order: the rest follows it, history included (of
        // which the history particles' new one is copied in next).
        let order = &self.work.bins.order;
        if self.work.reorder == Reorder::InGather {
            ps.permute_carried(order, &mut self.work.spare);
        }
        let materials = &self.materials;
        ps.history
            .par_iter_mut()
            .zip(&ps.material)
            .zip(&new.history)
            .filter(|((_, &m), _)| !materials[m as usize].is_elastic())
            .for_each(|((state, _), new)| *state = *new);
        self.work.signal_speed = Some(self.work.new_signal_speed);
        if self.work.reorder == Reorder::AtCommit {
            ps.permute(order, &mut self.work.spare);
        }
        // The found surface's age: the steps it has been carried since it was found; one not
        // carried (or whose points could not be carried) is found anew by the next step.
        let plan = self.surface_plan;
        let carried = plan.carry && self.work.boundary_updates.len() == self.surface.len();
        *self.surface_age = surface_age_after(*self.surface_age, plan, carried);
        // The moved points: the given boundary points', or the carried surface's.
        let b = match plan.carry {
            true => &mut *self.surface,
            false => &mut *self.boundary,
        };
        for (k, u) in self.work.boundary_updates.iter().enumerate() {
            b.position[k] = u.position;
            b.deformation_gradient[k] = u.deformation_gradient;
            b.area_normal[k] = u.area_normal;
        }
    }
}

impl<const D: usize> Step<'_, D> {
    /// Adds the step's stress work and external work to the energy ledger ([`crate::energy`]),
    /// from the old state (the particles) and the checked new one (the workspace).
    fn add_work_to_ledger(&mut self) {
        let (ps, work) = (&*self.particles, &*self.work);
        let new = &work.new_state;
        let states = StepStates {
            source: (work.reorder == Reorder::InGather).then_some(&work.bins.order[..]),
            reference_volume: &ps.reference_volume,
            mass: &ps.mass,
            old_position: &ps.position,
            new_position: &new.position,
            old_deformation_gradient: &ps.deformation_gradient,
            new_deformation_gradient: &new.deformation_gradient,
            old_stress: &ps.stress,
            new_stress: &new.stress,
            body_acceleration: self.body_force.then_some(&work.body_acceleration[..]),
        };
        let (stress, mut external) = states.work();
        let b = &*self.boundary;
        if b.has_tractions() && !work.boundary_updates.is_empty() {
            let moved = work.boundary_updates.iter().map(|u| u.position);
            external += traction_work(&b.traction, &b.area_normal, &b.position, moved);
        }
        self.energy.stress_work += stress;
        self.energy.external_work += external;
        self.energy.friction += work.node_losses.friction;
        self.energy.contact += work.node_losses.contact;
    }
}

/// The phases of METHOD.md section 1 after the shape functions, in order. The new particle
/// state is left in `work.new_state` when every check passed.
fn run_phases<const D: usize, S: StencilView<D>>(
    inputs: &StepInputs<'_, D, S>,
    vc: &mut Option<VcCorrection<D>>,
    surface: &mut BoundaryPoints<D>,
    work: &mut Workspace<D>,
) -> Result<()> {
    let mut clock = std::time::Instant::now();
    // Whether to store the particles in block order this step (with the bins' time).
    let lanes = inputs.stencils.lanes();
    let scattered = inputs.fast_paths.particle_sorting && inputs.bins.is_scattered(lanes);
    work.times.bins += lap(&mut clock);
    // 2. Body forces (the callback ran before the pool took over), the boundary points and
    //    the VC corrections.
    let found = vc_corrections::boundary_and_corrections(inputs, vc, surface, work)?;
    let boundary = if found { &*surface } else { inputs.boundary };
    // 3–4. Particle to grid and the grid update: one field, or one per body and contact.
    let vc = vc.as_ref();
    let (mass_floor, body_surfaces) = particle_to_grid_and_update(inputs, vc, boundary, work)?;
    // 5–6. Grid to particle and the constitutive update; boundary points move with the grid.
    let moving =
        (vc.is_some() || boundary.has_tractions()) && (!found || inputs.surface_plan.carry);
    let moving = moving.then_some(boundary);
    let all_admissible = grid_to_particle_and_update(inputs, moving, scattered, mass_floor, work);
    // The checks: every particle, every boundary point.
    clock = std::time::Instant::now();
    checks::check_new_state(inputs, all_admissible, work)?;
    if found && inputs.options.contact.is_some() {
        *surface = body_surfaces;
    }
    work.times.checks += lap(&mut clock);
    Ok(())
}

/// Particle to grid and the grid update with the wall conditions (and the tractions of
/// `boundary`): one field, or under contact one per body and the contact correction. Returns
/// the mass floor of the grid update and, under contact with VC, the bodies' surfaces.
fn particle_to_grid_and_update<const D: usize, S: StencilView<D>>(
    inputs: &StepInputs<'_, D, S>,
    vc: Option<&VcCorrection<D>>,
    boundary: &BoundaryPoints<D>,
    work: &mut Workspace<D>,
) -> Result<(f64, BoundaryPoints<D>)> {
    let (grid, ps, plan, dt) = (inputs.grid, inputs.particles, inputs.plan, inputs.dt);
    let mut clock = std::time::Instant::now();
    let (v, c) = (&ps.velocity[..], &ps.affine[..]);
    let velocity = move |p: usize| v[p];
    let affine_map = plan.apic.then_some(move |p: usize| c[p]);
    let forces = Forces {
        gravity: inputs.options.gravity,
        body: inputs.body_acceleration,
        vc,
        mls: plan
            .inverse_inertia
            .filter(|_| plan.mls)
            .map(|inverse_inertia| (dt, inverse_inertia)),
    };
    // Nodes at or below this mass get no velocity. Signed shape functions and linear hats:
    // a fraction of the largest particle mass (which particle to grid returns), since their
    // node masses may be tiny where the force or the velocity gradient is not. The smooth
    // nonnegative ones (B-splines, RK1): only empty nodes, so that no node's momentum or
    // force is dropped and a free body's momentum is kept to round-off (with the floor a
    // cubic B-spline block drifted by 1e-10 of M·v in 1000 steps).
    let floored = inputs.shape.is_signed() || matches!(inputs.options.shape, Shape::Linear);
    let mass_floor_fraction = if floored { 1e-10 } else { 0.0 };
    if let Some(contact) = inputs.options.contact {
        let body_inputs = contact::BodyInputs {
            contact,
            forces,
            volumes: &work.volumes,
            mass_floor_fraction,
        };
        work.node_losses = NodeLosses::default();
        let result = contact::particle_to_grid_per_body(
            inputs,
            &body_inputs,
            &mut work.bodies,
            &mut work.boundary_stencils,
            &mut work.times,
            &mut work.node_losses,
        );
        work.times.grid_update += lap(&mut clock);
        return result;
    }
    let mass_floor = mass_floor_fraction
        * particle_to_grid(
            &ToGrid {
                grid,
                particles: ps,
                bins: inputs.bins,
                stencils: inputs.stencils,
                shape: inputs.stored,
            },
            velocity,
            affine_map,
            Some(forces),
            None,
            &mut work.nodes,
        );
    if let (Some(vc), Some(stored)) = (vc, inputs.stored) {
        let (walls, all) = (inputs.walls, |_| true);
        let found = vc.bodies();
        vc_torque::remove_vc_torque(grid, walls, stored, ps.len(), all, found, &mut work.nodes);
    }
    if boundary.has_tractions() {
        apply_tractions(boundary, &work.boundary_stencils, &mut work.nodes);
    }
    work.times.particle_to_grid += lap(&mut clock);
    let no_force = forces.mls.is_some() && !boundary.has_tractions();
    let friction = grid_update(
        grid,
        inputs.walls,
        &mut work.nodes,
        Some(dt),
        mass_floor,
        no_force,
    );
    work.node_losses = NodeLosses {
        friction,
        contact: 0.0,
    };
    work.times.grid_update += lap(&mut clock);
    Ok((mass_floor, BoundaryPoints::default()))
}

/// Grid to particle into `work.new_state`, in block order when the particles have `scattered`
/// (USL), with the constitutive update: inside the same pass under USL, after MUSL's second
/// map otherwise. The `moving` boundary points move with the grid. Returns whether every
/// particle passed its checks, and leaves the signal speed in `work.new_signal_speed`.
fn grid_to_particle_and_update<const D: usize, S: StencilView<D>>(
    inputs: &StepInputs<'_, D, S>,
    moving: Option<&BoundaryPoints<D>>,
    scattered: bool,
    mass_floor: f64,
    work: &mut Workspace<D>,
) -> bool {
    let (grid, ps, dt) = (inputs.grid, inputs.particles, inputs.dt);
    let mut clock = std::time::Instant::now();
    // 6. (defined here, run inside the gather under USL) Constitutive update: elastic models
    //    from F, history models by return mapping from their state and the increment
    //    ΔF = F^{n+1} (F^n)⁻¹; particles kept inside the walls; the checks.
    let finish = ConstitutiveUpdate {
        domain: grid.domain(),
        particles: ps,
        materials: inputs.materials,
        walls: inputs.walls,
        any_wall: inputs.walls.any_wall(),
        dt,
    };
    let mut admissible = std::mem::take(&mut work.admissible);

    // 5. Grid to particle, in block order when the particles have scattered (USL).
    let mut new = std::mem::take(&mut work.new_state);
    let usl = inputs.options.scheme == Scheme::Usl;
    work.reorder = match scattered {
        false => Reorder::No,
        true if usl && !work.reorder_at_commit => Reorder::InGather,
        true => Reorder::AtCommit,
    };
    let source = (work.reorder == Reorder::InGather).then_some(&inputs.bins.order[..]);
    let fields = match inputs.options.contact {
        Some(_) => Fields::PerBody(&work.bodies.nodes, &ps.material),
        None => Fields::One(&work.nodes),
    };
    let from = FromGrid {
        grid,
        particles: ps,
        stencils: inputs.stencils,
        fields,
        rigid: inputs.rigid,
        plan: inputs.plan,
        dt,
    };
    let (mut speed, mut all_admissible) = grid_to_particle(
        &from,
        usl.then_some(&finish),
        source,
        &mut new,
        &mut admissible,
    );
    if !usl {
        // MUSL: the new particle momenta mapped to the grid again, and `F` from those
        // grid velocities.
        musl::second_map(inputs, mass_floor, &mut work.nodes, &mut new);
    }

    // Boundary points move with the grid like massless particles.
    work.boundary_updates.clear();
    if let Some(boundary) = moving {
        let bs = &work.boundary_stencils;
        move_boundary_points(boundary, bs, &work.nodes, dt, &mut work.boundary_updates);
    }

    work.times.grid_to_particle += lap(&mut clock);
    if !usl {
        (speed, all_admissible) = finish.run_all(&mut new, &mut admissible);
        work.times.constitutive += lap(&mut clock);
    }
    work.admissible = admissible;
    work.new_state = new;
    work.new_signal_speed = speed;
    all_admissible
}

#[cfg(test)]
mod tests;
