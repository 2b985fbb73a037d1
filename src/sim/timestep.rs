//! Adaptive time stepping: advance over a span of time with steps that stay a fixed fraction
//! (the CFL number) of the critical step, recomputed before every step.
//!
//! A run is bounded in steps ([`Sim::set_max_steps_per_advance`]): a duration or a material
//! that would need an absurd number of steps (a stable step of 1e-150 s, a duration of 1e300 s)
//! is refused before the first step instead of running for ever.

use super::Sim;
use crate::error::{check_finite, Error, ErrorKind, Result};

/// The bound on the steps of one [`Sim::advance`] unless the caller sets another
/// ([`Sim::set_max_steps_per_advance`]). It is a guard against runs that could never end, not a
/// budget: a long real run takes 10^5 to 10^7 steps, and 10^9 steps of even a handful of
/// particles take the better part of an hour, while a stable step made tiny by a mistake
/// (a modulus in the wrong units, a duration of 1e300 s) asks for 10^20 steps and more.
pub const DEFAULT_MAX_STEPS_PER_ADVANCE: u64 = 1_000_000_000;

/// Where an adaptive run stands, after one of its steps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress {
    /// Steps taken by the simulation so far (all runs).
    pub steps: u64,
    /// The simulated time now.
    pub time: f64,
    /// The time the run started at and the time it ends at.
    pub start: f64,
    pub end: f64,
    /// The step just taken.
    pub dt: f64,
}

/// A step count estimated in floating point, for a message.
fn count(estimate: f64) -> String {
    if estimate.is_finite() {
        format!("{estimate:.3e}")
    } else {
        format!("more than {:.3e}", f64::MAX)
    }
}

impl<const D: usize> Sim<D> {
    /// Advances by `duration` (> 0) with steps of `cfl · h / max_p(c_p + |v_p|)`, the stable step
    /// recomputed from the current state before each step, `cfl` in `(0, 1]`. The last steps are
    /// shortened so that the run ends at `time + duration` exactly (the final span shorter than
    /// two stable steps is split into two equal steps, so no sliver step is taken). Returns the
    /// number of steps taken.
    ///
    /// Each step is all or nothing ([`Sim::step`]): when one fails, the simulation keeps the
    /// state after the last good step, and the error message says how many steps were taken
    /// and at which time it stopped.
    ///
    /// The number of steps is bounded ([`Sim::set_max_steps_per_advance`], default
    /// [`DEFAULT_MAX_STEPS_PER_ADVANCE`]): before the first step, a run whose estimate
    /// `duration / stable_dt(cfl)` exceeds the bound is refused with `InvalidArgument` and a
    /// message that gives the estimate, changing nothing; and since the stable step can shrink
    /// as the run goes, a run that has taken the bound's number of steps short of its end stops
    /// there with `InvalidArgument` (the steps taken stand, as for a failed step). A host that
    /// wants to stop a run earlier, by its own measure (wall time, a cancel button), can do so
    /// from the progress callback of [`Sim::advance_observed`].
    pub fn advance(&mut self, duration: f64, cfl: f64) -> Result<u64> {
        self.advance_observed(duration, cfl, &mut |_, _| true)
    }

    /// [`Sim::advance`], calling `observe` after every step with the simulation and the
    /// progress (to write output at the steps the run takes anyway); when it returns `false` the
    /// run stops there (the steps taken stand) with a `Callback` error.
    pub fn advance_observed(
        &mut self,
        duration: f64,
        cfl: f64,
        observe: &mut dyn FnMut(&Sim<D>, Progress) -> bool,
    ) -> Result<u64> {
        check_finite("duration", duration)?;
        if duration <= 0.0 {
            return Err(Error::invalid(format!(
                "duration must be positive, got {duration:e}"
            )));
        }
        let end = self.time + duration;
        if end == self.time {
            return Err(Error::invalid(format!(
                "duration {duration:e} is below the resolution of the time {:e}",
                self.time
            )));
        }
        // Validate cfl (and that there are particles) before the first step.
        let first = self.stable_dt(cfl)?;
        let max = self.max_steps_per_advance;
        // The steps of a constant stable step `s` are `ceil(duration / s)` (the last span
        // shorter than two steps is taken in one or two): the estimate, `inf` when the
        // quotient overflows or the stable step underflows to 0.
        let estimate = (duration / first).ceil();
        if estimate > max as f64 {
            return Err(Error::invalid(format!(
                "advancing by {duration:e} s needs about {} steps of {first:.3e} s \
                 (cfl {cfl} of the stable step now), above the bound of {max} steps per advance: \
                 advance by less, or raise the bound (set_max_steps_per_advance) if so long a \
                 run is meant",
                count(estimate)
            )));
        }
        let start = self.time;
        let mut taken = 0u64;
        while self.time < end {
            let stable = self.stable_dt(cfl)?;
            if taken >= max {
                // The stable step shrank as the run went (faster particles, a stiffer state).
                let more = count(((end - self.time) / stable).ceil());
                return Err(Error::invalid(format!(
                    "the run from t = {start:e} to t = {end:e} took the bound of {max} steps per \
                     advance and stopped at t = {:e} (kept): about {more} more steps of \
                     {stable:.3e} s were needed, the stable step having shrunk from {first:.3e} s; \
                     advance by less, or raise the bound (set_max_steps_per_advance)",
                    self.time
                )));
            }
            let left = end - self.time;
            let dt = if left <= stable {
                left
            } else if left < 2.0 * stable {
                0.5 * left
            } else {
                stable
            };
            if self.time + dt == self.time {
                return Err(Error::invalid(format!(
                    "the step {dt:e} (cfl {cfl} of the stable step) is below the resolution of \
                     the time {:e}: the run cannot advance ({taken} steps taken)",
                    self.time
                )));
            }
            if let Err(mut e) = self.step(dt) {
                e.message = format!(
                    "{} (advancing from t = {start:e} to t = {end:e}: {taken} steps taken, \
                     the refused step would have started at t = {:e})",
                    e.message, self.time
                );
                return Err(e);
            }
            taken += 1;
            if left <= stable {
                // The rounded sum of the steps may miss `end` by an ulp: land on it.
                self.time = end;
            }
            let progress = Progress {
                steps: self.steps,
                time: self.time,
                start,
                end,
                dt,
            };
            if !observe(self, progress) {
                return Err(Error::new(
                    ErrorKind::Callback,
                    format!(
                        "stopped by the progress callback at t = {:e} of {end:e} ({taken} steps \
                         taken, kept)",
                        self.time
                    ),
                ));
            }
        }
        Ok(taken)
    }
}
