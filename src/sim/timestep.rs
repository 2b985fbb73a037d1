//! Adaptive time stepping: advance over a span of time with steps that stay a fixed fraction
//! (the CFL number) of the critical step, recomputed before every step.

use super::Sim;
use crate::error::{check_finite, Error, ErrorKind, Result};

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
        self.stable_dt(cfl)?;
        let start = self.time;
        let mut taken = 0u64;
        while self.time < end {
            let stable = self.stable_dt(cfl)?;
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
