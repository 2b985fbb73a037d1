//! Stepping a simulation: the checks before a step, the body-force callback on the calling
//! thread, then the step's phases ([`crate::step`]) on the simulation's worker threads.

use super::Sim;
use crate::error::{check_positive, Error, ErrorKind, Result};
use crate::options::{Scheme, Transfer};
use crate::step::{lap, Step, StepLabel, SurfacePlan};
use crate::Vector;

impl<const D: usize> Sim<D> {
    /// Advances the simulation by `dt`.
    ///
    /// Fails, leaving the simulation exactly as it was, when `dt` is not finite and positive, when
    /// `dt` exceeds the critical step `h / max(c + |v|)` (`UnstableTimeStep`), when the body force
    /// fails, or when the new state has a non-finite value (`NonFinite`), an inverted particle
    /// (`InvertedParticle`) or a particle outside the domain (`OutsideGrid`); the message names
    /// the first such particle and the step.
    pub fn step(&mut self, dt: f64) -> Result<()> {
        check_positive("dt", dt)?;
        let next = self.time + dt;
        if !next.is_finite() || next == self.time {
            return Err(Error::invalid(format!(
                "dt = {dt:e} at t = {:e} gives a time that is {}",
                self.time,
                if next.is_finite() {
                    "unchanged (below the resolution of the time)"
                } else {
                    "not finite"
                }
            )));
        }
        if self.particles.is_empty() {
            self.time += dt;
            self.steps += 1;
            return Ok(());
        }
        self.check_options()?;
        let critical = self.critical_dt()?;
        if dt > critical {
            return Err(Error::new(
                ErrorKind::UnstableTimeStep,
                format!(
                    "dt = {dt:e} exceeds the critical time step h / max(c + |v|) = {critical:e} \
                     (CFL {:.2}); take the stable time step (stable_dt) or a smaller one",
                    dt / critical
                ),
            ));
        }
        // The body force on the calling thread (a C callback is called from the thread that
        // steps), then the rest of the step on a thread of the pool.
        let mut clock = std::time::Instant::now();
        self.evaluate_body_force()?;
        self.work.times.forces_and_vc += lap(&mut clock);
        // The parallel passes of the step then run on the pool's threads without the calling
        // thread handing each one over and sleeping until it ends (two thread switches per
        // pass, about a dozen passes per step), which shows most on small problems.
        // On the simulation's own pool when it has one ([`Sim::set_threads`]).
        if let Some(vc) = self.vc.as_mut() {
            vc.discard_proposal();
        }
        let plan = self.surface_plan();
        match self.threads.clone() {
            Some(pool) => pool.scope(|_| self.step_of(plan).run(dt))?,
            None => rayon::scope(|_| self.step_of(plan).run(dt))?,
        }
        self.time += dt;
        self.steps += 1;
        Ok(())
    }

    /// How the next step takes the surface VC finds from the particles (only VC without given
    /// boundary points and without contact carries one): found anew when there is none or it
    /// has been carried `vc_surface_refresh` steps; carried on when it will be used again.
    pub(crate) fn surface_plan(&self) -> SurfacePlan {
        let own = self.vc.is_some() && self.boundary.is_empty() && self.options.contact.is_none();
        if !own {
            return SurfacePlan {
                find: true,
                carry: false,
            };
        }
        let find = self.surface.is_empty() || self.surface_age >= self.vc_surface_refresh;
        let age = if find { 0 } else { self.surface_age };
        SurfacePlan {
            find,
            carry: age + 1 < self.vc_surface_refresh,
        }
    }

    /// The step's view of the simulation: what it reads and what it changes.
    fn step_of(&mut self, surface_plan: SurfacePlan) -> Step<'_, D> {
        Step {
            grid: &self.grid,
            shape: self.shape.as_ref(),
            options: &self.options,
            materials: &self.materials,
            fast_paths: self.fast_paths,
            body_force: self.body_force.is_some(),
            label: StepLabel {
                number: self.steps + 1,
                time: self.time,
            },
            particles: &mut self.particles,
            boundary: &mut self.boundary,
            surface: &mut self.surface,
            surface_plan,
            surface_age: &mut self.surface_age,
            vc: &mut self.vc,
            work: &mut self.work,
            energy: &mut self.energy,
        }
    }

    /// Evaluates the body-force callback, if any, into `work.body_acceleration` (in storage
    /// order; the callback sees the particles in id order). Fails, changing nothing else, when
    /// the callback fails or returns a non-finite value.
    fn evaluate_body_force(&mut self) -> Result<()> {
        let Some(bf) = self.body_force.as_mut() else {
            return Ok(());
        };
        let ps = &self.particles;
        // The callback sees the particles in id order (the storage order until a sort).
        let slots = (!ps.in_id_order()).then(|| ps.slots());
        let acceleration = &mut self.work.body_acceleration;
        acceleration.clear();
        acceleration.resize(ps.len(), Vector::zeros());
        let result = match &slots {
            Some(slots) => {
                let by_id =
                    |v: &[Vector<D>]| -> Vec<Vector<D>> { slots.iter().map(|&p| v[p]).collect() };
                let (reference, current) = (by_id(&ps.reference_position), by_id(&ps.position));
                bf.accelerations(self.time, &reference, &current, acceleration)
            }
            None => bf.accelerations(
                self.time,
                &ps.reference_position,
                &ps.position,
                acceleration,
            ),
        };
        result.map_err(|m| Error::new(ErrorKind::Callback, format!("body force failed: {m}")))?;
        if let Some(p) = acceleration
            .iter()
            .position(|a| a.iter().any(|c| !c.is_finite()))
        {
            return Err(Error::new(
                ErrorKind::Callback,
                format!("body force returned a non-finite value for particle {p}"),
            ));
        }
        // Back to storage order: slot `p` holds particle `id[p]`.
        if slots.is_some() {
            *acceleration = ps.id.iter().map(|&id| acceleration[id as usize]).collect();
        }
        Ok(())
    }

    /// Refuses combinations of options that cannot run (`Unsupported`), as every step does
    /// before it computes anything: call it to check a set-up without stepping.
    pub fn check_options(&self) -> Result<()> {
        self.options.walls.check_fits(&self.grid)?;
        if self.options.contact.is_some()
            && (!self.boundary.is_empty() || self.options.scheme == Scheme::Musl)
        {
            return Err(Error::new(
                ErrorKind::Unsupported,
                "contact works with USL, without given boundary points (MUSL and tractions are \
                 not supported with contact yet; VC finds each body's surface itself)",
            ));
        }
        if self.options.contact.is_none()
            && self
                .materials
                .iter()
                .any(|m| m.rigid_velocity::<D>().is_some())
        {
            return Err(Error::new(
                ErrorKind::Unsupported,
                "a rigid material needs contact between bodies (set_contact)",
            ));
        }
        if matches!(self.options.transfer, Transfer::Apic) && self.shape.reproduction_order() >= 2 {
            // D_p = Σ Ψ (x_I − x_p)(x_I − x_p)ᵀ vanishes for shape functions that reproduce
            // quadratics, and replacing it by the velocity gradient amplifies the round trip
            // (METHOD.md section 7).
            return Err(Error::new(
                ErrorKind::Unsupported,
                "APIC with a shape function that reproduces quadratics (RK order >= 2) is unstable; \
                 use the PIC/FLIP transfer",
            ));
        }
        if self.options.transfer == Transfer::Mls {
            if self.shape.apic_inertia(self.grid.cell_size).is_none() {
                return Err(Error::new(
                    ErrorKind::Unsupported,
                    "the MLS transfer needs the quadratic or cubic B-spline shape function, or \
                     RK1 with support 2 (a constant APIC inertia); use the APIC or PIC/FLIP \
                     transfer with other shape functions",
                ));
            }
            if self.vc.is_some() {
                return Err(Error::new(
                    ErrorKind::Unsupported,
                    "the MLS transfer does not go with VC integration (MLS replaces the gradients \
                     VC corrects); use the APIC or PIC/FLIP transfer with VC",
                ));
            }
        }
        Ok(())
    }
}
