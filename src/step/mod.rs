//! One explicit MPM step (METHOD.md section 1), phase by phase, each in the file named after it.
//! `Sim::step` checks the step and calls the body-force callback on the calling thread, then
//! runs a `Step` on rayon's pool: `Step::run` computes the shape functions and bins and
//! calls `run_phases`, whose lines are the phases in order, then commits.
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
//! so a failed step leaves the last good state. `reference` (tests only) is the same step
//! written plainly, node by node, and the oracle of the fast one.
//! [`PhaseTimes`] accumulates the time per phase.

mod checks;
mod constitutive_update;
mod contact;
pub(crate) mod edge_lumping;
mod grid_to_particle;
mod grid_update;
mod musl;
mod particle_to_grid;
mod profile;
#[cfg(test)]
mod reference;
mod surface;
mod vc_corrections;
mod vc_torque;
pub(crate) use checks::StepLabel;
pub(crate) use profile::bytes as profile_bytes;
pub(crate) use profile::lap;
pub use profile::{MemoryUse, PhaseTimes};

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
use crate::options::{FastPaths, Options, Scheme, Shape, Transfer, Walls};
use crate::particles::Particles;
use crate::shape::{BSpline, BSplineOrder, ShapeFunction, StencilView, Stencils, TensorStencils};
use crate::Vector;
use constitutive_update::ConstitutiveUpdate;
pub use contact::BodyFields;
use rayon::prelude::*;
pub use surface::BoundaryUpdate;
use surface::{apply_tractions, move_boundary_points};

/// Scratch space of a step, kept between steps so the hot loops do not allocate.
#[derive(Debug, Default)]
pub struct Workspace<const D: usize> {
    /// Particles binned by grid block (the coloured particle-to-grid map).
    pub bins: Bins<D>,
    /// Stored stencils (RK, and every shape under VC).
    pub stencils: Stencils<D>,
    /// B-spline stencils as 1D factors (linear hats, quadratic, cubic).
    pub linear: TensorStencils<D, 2>,
    pub quadratic: TensorStencils<D, 3>,
    pub cubic: TensorStencils<D, 4>,
    /// Buffers of the particles' sort.
    pub spare: crate::particles::SpareArrays<D>,
    /// How the step being taken stores its particles in block order (decided with its bins).
    pub reorder: Reorder,
    /// Permute every quantity at the commit even under USL (tests compare the two ways).
    pub reorder_at_commit: bool,
    /// `max_p (c_p + |v_p|)` of the particles as they are, when the last step computed it with
    /// their new state (`None` after anything else changed them: `Sim::signal_speed` then takes
    /// it afresh); and the value of the step being taken, which its commit makes current.
    pub signal_speed: Option<f64>,
    pub new_signal_speed: f64,
    /// Time per phase, summed over the steps.
    pub times: PhaseTimes,
    /// Nodes written by the last step.
    pub active_nodes: usize,
    pub boundary_stencils: Stencils<D>,
    /// Current particle volumes (for VC).
    pub volumes: Vec<f64>,
    pub boundary_updates: Vec<BoundaryUpdate<D>>,
    /// What the step's friction walls and contact correction took from the node velocities.
    pub node_losses: NodeLosses,
    pub nodes: GridNodes<D>,
    /// The bodies' node fields under contact; empty otherwise.
    pub bodies: BodyFields<D>,
    pub body_acceleration: Vec<Vector<D>>,
    /// The new particle state, swapped in by the commit.
    pub new_state: NewState<D>,
    /// Whether each new particle state passed the checks.
    pub admissible: Vec<bool>,
}

/// How a step stores its particles in the order of their grid blocks, once they have scattered
/// over them (`Bins::is_scattered`).
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub enum Reorder {
    /// Not this step: still sorted enough, or sorting is off.
    #[default]
    No,
    /// Grid to particle writes the new state in block order, and the commit permutes only the
    /// quantities a step carries unchanged (USL): a fifth of the bytes of a whole permutation.
    InGather,
    /// The commit permutes every quantity (MUSL, whose second map reads the new state by the
    /// particles' old slots).
    AtCommit,
}

/// What the transfer needs from the particles and the shape function.
#[derive(Debug, Clone, Copy)]
pub struct TransferPlan {
    /// FLIP weight (0 for pure PIC and for APIC).
    pub flip: f64,
    /// APIC is on.
    pub apic: bool,
    /// `1 / D_p` when the shape function's APIC inertia is a constant multiple of the identity.
    pub inverse_inertia: Option<f64>,
    /// MLS: the force rides on the affine momentum and the velocity gradient is `C_p` (then
    /// `apic` is on and `inverse_inertia` is given).
    pub mls: bool,
}

/// What the phases of one step read and none of them changes.
pub(crate) struct StepInputs<'a, const D: usize, S> {
    pub grid: &'a Grid<D>,
    pub particles: &'a Particles<D>,
    /// The particles' shape functions this step.
    pub stencils: &'a S,
    /// The same as stored lists, when they are (for VC and the lumping of signed shapes).
    pub stored: Option<&'a Stencils<D>>,
    /// The particles binned by grid block for the maps to the grid.
    pub bins: &'a Bins<D>,
    pub walls: &'a Walls<D>,
    pub options: &'a Options<D>,
    pub shape: &'a dyn ShapeFunction<D>,
    pub materials: &'a [Material],
    /// Each material's rigid velocity, `None` for a deformable one.
    pub rigid: &'a [Option<Vector<D>>],
    /// The body-force callback's accelerations this step, if there is one.
    pub body_acceleration: Option<&'a [Vector<D>]>,
    /// The given boundary points.
    pub boundary: &'a BoundaryPoints<D>,
    pub fast_paths: FastPaths,
    pub label: StepLabel,
    pub plan: TransferPlan,
    pub surface_plan: SurfacePlan,
    pub dt: f64,
}

/// The found surface's age after a step taken with `plan` (`carried`: its points moved): 1
/// after the step that found it and carried it, one more after each step that carried it,
/// `u32::MAX` (found anew by the next step) when not carried.
pub(crate) fn surface_age_after(age: u32, plan: SurfacePlan, carried: bool) -> u32 {
    match (carried, plan.find) {
        (true, true) => 1,
        (true, false) => age.saturating_add(1),
        (false, _) => u32::MAX,
    }
}

/// How a step takes the surface VC finds from the particles (no boundary points given):
/// found anew from the particles at its start, or the last one as the grid carried it; and
/// whether the step carries it on to the next (METHOD.md section 3: the found surface).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct SurfacePlan {
    /// Find the surface from the particles at the start of the step.
    pub find: bool,
    /// Move the surface with the grid like given boundary points, for the next step.
    pub carry: bool,
}

/// One step of a simulation: what it reads of the simulation and what it changes
/// (`Sim::step` makes one after its checks and runs it on rayon's pool).
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

/// Clears the nodes the last step wrote (all fields zero, none active), of the one field and of
/// each body's.
fn clear_grid<const D: usize>(nodes: &mut GridNodes<D>, bodies: &mut [GridNodes<D>]) {
    nodes.reset();
    for b in bodies.iter_mut() {
        b.reset();
    }
}

impl<const D: usize> Workspace<D> {
    /// Clears the nodes the last step wrote (all fields zero, none active), of the one field
    /// and of each body's; the step does it itself, while it bins.
    pub fn clear_grid(&mut self) {
        clear_grid(&mut self.nodes, &mut self.bodies.nodes);
    }
}

#[cfg(test)]
mod tests;
