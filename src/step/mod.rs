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
//!    from the particles (`surface`), under contact each body's (`contact`);
//! 3. [`particle_to_grid`]: mass, momentum (APIC term only under APIC), force; tractions
//!    (`surface`); under contact one field per body (`contact`);
//! 4. [`grid_update`]: velocities, wall conditions; under contact one field per body, then the
//!    contact correction (`contact`);
//! 5. [`grid_to_particle`]: velocity (PIC/FLIP or APIC), position, velocity gradient, `F`;
//!    under MUSL the new particle momenta are mapped to the grid again (`musl`) and `F` taken
//!    from those velocities; boundary points move with the grid (`surface`);
//! 6. the constitutive update (`constitutive_update`): under USL inside grid to particle's pass,
//!    each particle while it is in cache; under MUSL after the second map;
//!
//! then the checks (`checks`), the commit, and the grid reset where it was written (while the
//! next step bins).
//!
//! The new particle state is built in arrays of the workspace ([`NewState`]) and swapped with the
//! particles' only when every particle passed the checks (finite, `det F > 0`, inside the grid),
//! so a failed step leaves the last good state. `crate::reference` (tests only) is the same
//! step written plainly, node by node, and the oracle of the fast one.
//! [`PhaseTimes`] accumulates the time per phase.
//!
//! # The method on one screen
//!
//! The step with the quadratic B-spline, APIC, a linear elastic material and gravity, written
//! plainly for a reader who wants the idea before the code above (mpm88-sized): particle to
//! grid, grid update, grid to particle with the constitutive update; then checked against
//! [`crate::Sim`] on the same particles (the sums taken in another order: round-off apart).
//!
//! ```
//! use rkmpm::{Material, Matrix, Shape, Sim, Transfer, Vector};
//! let (n, h, dt, g) = (16usize, 1.0 / 16.0, 2e-4, Vector::<2>::new(0.0, -9.81));
//! let (rho, young, nu) = (1000.0, 1e5, 0.3);
//! let (mu, lambda) = (young / (2.0 * (1.0 + nu)), young * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)));
//! // A block of 8 x 8 particles, two per cell and direction, spinning.
//! let mut x: Vec<Vector<2>> = (0..64)
//!     .map(|k| Vector::<2>::new(0.3 + (k % 8) as f64 * h / 2.0, 0.4 + (k / 8) as f64 * h / 2.0))
//!     .collect();
//! let spin = |p: &Vector<2>| Vector::<2>::new(0.4 - p[1], p[0] - 0.4);
//! let mut v: Vec<Vector<2>> = x.iter().map(spin).collect();
//! let volume = h * h / 4.0;
//! let (mut c, mut stress) = (vec![Matrix::<2>::zeros(); 64], vec![Matrix::<2>::zeros(); 64]);
//! let mut f = vec![Matrix::<2>::identity(); 64];
//! let mut sim = Sim::<2>::new([0.0, 0.0], [n, n], h).unwrap();
//! sim.set_shape(Shape::BSpline2).unwrap();
//! sim.set_transfer(Transfer::Apic).unwrap();
//! sim.set_gravity(g).unwrap();
//! let m = sim.add_material(Material::linear_elastic(rho, young, nu).unwrap());
//! sim.add_particles(m, &x, &vec![volume; 64], Some(&v)).unwrap();
//! // The quadratic B-spline's three nodes per axis from `base`, values and derivatives.
//! let weights = |xp: f64| {
//!     let base = (xp / h - 0.5).floor();
//!     let t = xp / h - base;
//!     let w = [0.5 * (1.5 - t).powi(2), 0.75 - (t - 1.0).powi(2), 0.5 * (t - 0.5).powi(2)];
//!     (base as usize, w, [(t - 1.5) / h, -2.0 * (t - 1.0) / h, (t - 0.5) / h])
//! };
//! let nodes = n + 1;
//! for _ in 0..20 {
//!     // Particle to grid: mass, momentum with APIC's affine part, force.
//!     let mut mass = vec![0.0; nodes * nodes];
//!     let mut momentum = vec![Vector::<2>::zeros(); nodes * nodes];
//!     let mut force = momentum.clone();
//!     for p in 0..64 {
//!         let ((bx, wx, dx), (by, wy, dy)) = (weights(x[p][0]), weights(x[p][1]));
//!         let (mp, vp) = (rho * volume, volume * f[p].determinant());
//!         for (i, j) in (0..3).flat_map(|i| (0..3).map(move |j| (i, j))) {
//!             let node = (bx + i) + (by + j) * nodes;
//!             let offset = Vector::<2>::new((bx + i) as f64 * h, (by + j) as f64 * h) - x[p];
//!             let (w, grad) = (wx[i] * wy[j], Vector::<2>::new(dx[i] * wy[j], wx[i] * dy[j]));
//!             mass[node] += w * mp;
//!             momentum[node] += w * mp * (v[p] + c[p] * offset);
//!             force[node] += -vp * stress[p] * grad + w * mp * g;
//!         }
//!     }
//!     // Grid update (no walls).
//!     let velocity: Vec<Vector<2>> = (0..nodes * nodes)
//!         .map(|k| match mass[k] > 0.0 {
//!             true => (momentum[k] + dt * force[k]) / mass[k],
//!             false => Vector::zeros(),
//!         })
//!         .collect();
//!     // Grid to particle: velocity, APIC's `C_p = B_p (4 / h²)`, position, `F`, then the stress.
//!     for p in 0..64 {
//!         let ((bx, wx, dx), (by, wy, dy)) = (weights(x[p][0]), weights(x[p][1]));
//!         let (mut vp, mut b) = (Vector::<2>::zeros(), Matrix::<2>::zeros());
//!         let mut l = Matrix::<2>::zeros();
//!         for (i, j) in (0..3).flat_map(|i| (0..3).map(move |j| (i, j))) {
//!             let vi = velocity[(bx + i) + (by + j) * nodes];
//!             let offset = Vector::<2>::new((bx + i) as f64 * h, (by + j) as f64 * h) - x[p];
//!             vp += wx[i] * wy[j] * vi;
//!             b += wx[i] * wy[j] * vi * offset.transpose();
//!             l += vi * Vector::<2>::new(dx[i] * wy[j], wx[i] * dy[j]).transpose();
//!         }
//!         (v[p], c[p], x[p]) = (vp, b * (4.0 / (h * h)), x[p] + dt * vp);
//!         f[p] = (Matrix::identity() + dt * l) * f[p];
//!         let strain = 0.5 * (f[p] + f[p].transpose()) - Matrix::identity();
//!         stress[p] = Matrix::identity() * (lambda * strain.trace()) + 2.0 * mu * strain;
//!     }
//!     sim.step(dt).unwrap();
//! }
//! let engine = sim.field(rkmpm::Field::Position);
//! for (p, xp) in x.iter().enumerate() {
//!     let d = (Vector::<2>::new(engine[2 * p], engine[2 * p + 1]) - xp).norm();
//!     assert!(d < 1e-12, "particle {p} is {d:e} from the engine's");
//! }
//! ```

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

#[cfg_attr(not(feature = "internals"), allow(unused_imports))] // for the benchmarks
pub use crate::grid::Bins;
pub use crate::grid::BlockLayout;
#[cfg_attr(not(feature = "internals"), allow(unused_imports))] // for the benchmarks
pub use grid_to_particle::{
    grid_to_particle, mls_velocity_gradient, velocity_gradient, Fields, Finish, FromGrid, NewState,
    NewStateWriter, NoFinish, ParticleUpdate,
};
pub use grid_update::grid_update;
pub use particle_to_grid::{particle_to_grid, Forces, ToGrid};

use crate::cpu::Lanes;
use crate::energy::{traction_work, EnergyLedger, StepStates};
use crate::error::Result;
use crate::grid::{Grid, GridNodes};
use crate::integration::{BoundaryPoints, VcCorrection};
use crate::material::{Constitutive, Material};
use crate::options::{FastPaths, Options, Scheme, Transfer};
use crate::particles::Particles;
use crate::shape::{BSpline, BSplineOrder, ShapeFunction, StencilView, Stencils, TensorStencils};
use crate::Vector;
use constitutive_update::ConstitutiveUpdate;
pub use contact::BodyFields;
use rayon::prelude::*;
pub use surface::BoundaryUpdate;

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
    /// One step, METHOD.md section 1: the shape functions (phase 1), the phases after them in
    /// order ([`Step::run_phases`]) and, when every check passed, the commit of the new state;
    /// a rejected step changes nothing of the simulation but its scratch space.
    pub(crate) fn run(mut self, dt: f64) -> Result<()> {
        // A surface VC finds from the particles this step replaces the last one, which a
        // rejected step restores (a carried one changes only in the commit).
        let last_surface = self.surface_plan.find.then(|| std::mem::take(self.surface));
        // 1. Shape functions of every particle; then phases 2–6, compiled for the stencils'
        //    own storage.
        let result = self.shape_functions().and_then(|shapes| {
            let result = match &shapes {
                ShapeFunctions::Linear(s, stored) => {
                    self.run_phases(dt, &s.local(), stored.as_ref())
                }
                ShapeFunctions::Quadratic(s, stored) => {
                    self.run_phases(dt, &s.local(), stored.as_ref())
                }
                ShapeFunctions::Cubic(s, stored) => {
                    self.run_phases(dt, &s.local(), stored.as_ref())
                }
                ShapeFunctions::Lists(s) => self.run_phases(dt, s, Some(s)),
            };
            shapes.put_back(self.work);
            result
        });
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

    /// The phases of METHOD.md section 1 after the shape functions, in order, with the
    /// particles' `stencils` (`stored`: the same as stored lists, when they are). The new
    /// particle state is left in `work.new_state` when every check passed.
    fn run_phases<S: StencilView<D>>(
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
        let (vc, surface) = (&mut *self.vc, &mut *self.surface);
        let result = (|| {
            let mut clock = std::time::Instant::now();
            // Whether to store the particles in block order this step (with the bins' time).
            let lanes = inputs.stencils.lanes();
            let scattered = inputs.fast_paths.particle_sorting && inputs.bins.is_scattered(lanes);
            work.times.bins += lap(&mut clock);
            // 2. Forces that do not come from stress (gravity and the body force, whose
            //    callback ran before the pool took over, go with particle to grid); the
            //    boundary points and the VC corrections, per body under contact.
            let (found, body_surfaces) =
                vc_corrections::boundary_and_corrections(&inputs, vc, surface, work)?;
            let boundary = if found { &*surface } else { inputs.boundary };
            let vc = vc.as_ref();
            // 3. Particle to grid: one field, or one per body under contact.
            let mass_floor = particle_to_grid::phase(&inputs, vc, boundary, work);
            // 4. Grid update with the walls; under contact per body, then the contact correction.
            grid_update::phase(&inputs, mass_floor, boundary, work);
            // 5. Grid to particle (under MUSL the second map); boundary points move with the grid.
            let update = ConstitutiveUpdate::of(&inputs);
            let moving =
                (vc.is_some() || boundary.has_tractions()) && (!found || inputs.surface_plan.carry);
            let moving = moving.then_some(boundary);
            let gathered =
                grid_to_particle::phase(&inputs, &update, moving, scattered, mass_floor, work);
            // 6. Constitutive update: under USL inside grid to particle's pass, under MUSL now.
            let usl = inputs.options.scheme == Scheme::Usl;
            let all_admissible = update.phase(usl, gathered, work);
            // The checks: every particle, every boundary point.
            clock = std::time::Instant::now();
            checks::check_new_state(&inputs, all_admissible, work)?;
            if found && inputs.options.contact.is_some() {
                *surface = body_surfaces;
            }
            work.times.checks += lap(&mut clock);
            Ok(())
        })();
        work.bins = bins;
        work.body_acceleration = body_acceleration;
        result
    }

    /// Phase 1: every particle's shape functions, once per step: B-splines (and RK1 with
    /// ã = 2) as 1D factors, with VC beside them as the stored lists its sums read; other
    /// shapes as stored lists, the transfer weights of signed shapes blended at a body's edge.
    /// The particles are binned by grid block meanwhile, and the nodes the last step wrote are
    /// cleared.
    fn shape_functions(&mut self) -> Result<ShapeFunctions<D>> {
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
        let order = (self.shape.tensor_order()).filter(|_| self.fast_paths.factored_stencils);
        Ok(match order {
            Some(BSplineOrder::Linear) => {
                let (s, stored) = self.tensor_stencils(|w| &mut w.linear);
                ShapeFunctions::Linear(s, stored)
            }
            Some(BSplineOrder::Quadratic) => {
                let (s, stored) = self.tensor_stencils(|w| &mut w.quadratic);
                ShapeFunctions::Quadratic(s, stored)
            }
            Some(BSplineOrder::Cubic) => {
                let (s, stored) = self.tensor_stencils(|w| &mut w.cubic);
                ShapeFunctions::Cubic(s, stored)
            }
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
                ShapeFunctions::Lists(stencils)
            }
        })
    }

    /// B-spline stencils as factors (`W` nodes per axis, taken from the workspace's `storage`),
    /// with VC the same as stored lists.
    fn tensor_stencils<const W: usize>(
        &mut self,
        storage: impl Fn(&mut Workspace<D>) -> &mut TensorStencils<D, W>,
    ) -> (TensorStencils<D, W>, Option<Stencils<D>>) {
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
            // lists from the factors just computed, not evaluated again; none where VC reads
            // the factors (`VcCorrection::reads_lists`).
            match self.vc.as_ref().is_some_and(|vc| vc.reads_lists()) {
                true => stored.fill_from_factors(&stencils),
                false => stored.clear(),
            }
            self.work.times.shape += lap(&mut clock);
        }
        (stencils, stored)
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

    /// Swaps the checked new state into the particles (the old one becomes the next step's
    /// storage) and copies the new history of history particles.
    fn commit(&mut self) {
        if self.energy.on {
            self.add_work_to_ledger();
        }
        // VC's solve of this step is carried to the steps up to the next (`VcSolve::interval`).
        if let Some(vc) = self.vc.as_mut() {
            vc.commit_step(self.grid.node_count());
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

/// The particles' shape functions for a step (phase 1), in the storage the phases read:
/// B-spline factors, with VC the same as stored lists beside them; or stored lists.
enum ShapeFunctions<const D: usize> {
    Linear(TensorStencils<D, 2>, Option<Stencils<D>>),
    Quadratic(TensorStencils<D, 3>, Option<Stencils<D>>),
    Cubic(TensorStencils<D, 4>, Option<Stencils<D>>),
    Lists(Stencils<D>),
}

impl<const D: usize> ShapeFunctions<D> {
    /// Back into the workspace, for the next step to fill without allocating.
    fn put_back(self, work: &mut Workspace<D>) {
        let stored = match self {
            ShapeFunctions::Linear(s, stored) => {
                work.linear = s;
                stored
            }
            ShapeFunctions::Quadratic(s, stored) => {
                work.quadratic = s;
                stored
            }
            ShapeFunctions::Cubic(s, stored) => {
                work.cubic = s;
                stored
            }
            ShapeFunctions::Lists(s) => Some(s),
        };
        if let Some(stored) = stored {
            work.stencils = stored;
        }
    }
}

#[cfg(test)]
mod tests;
