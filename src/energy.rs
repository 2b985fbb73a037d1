//! The energy ledger: what the steps did to a simulation's energy, so that its change over a run
//! is told apart ([`crate::sim::EnergyBalance`], `Sim::set_energy_accounting`; docs/METHOD.md
//! section 8).
//!
//! Each step adds, over the particles (`n` the step's start, `n+1` its end):
//! - the **stress work** `Σ_p V0_p ½(P_p^n + P_p^{n+1}) : (F_p^{n+1} − F_p^n)`, with the nominal
//!   stress `P = J σ F⁻ᵀ`: the trapezoidal rule along the step's straight path of `F` (the
//!   update `F^{n+1} = (I + Δt L) F^n` is linear in time). For a hyperelastic material
//!   `P = ∂W/∂F`, so this is the change of the stored energy up to the rule's error, `O(Δt³)`
//!   per step; for plasticity and damage the excess over the stored energy's change is what
//!   they dissipated;
//! - what the friction walls and the contact correction took from the node velocities
//!   ([`NodeLosses`]);
//! - the **external work** of the body-force callback, `Σ_p m_p b_p · (x_p^{n+1} − x_p^n)`, and
//!   of the tractions, `Σ_b t_b |n a|_b · (x_b^{n+1} − x_b^n)` (gravity is a potential and not
//!   counted here).
//!
//! The sums run in chunks of a fixed size, in storage order: the same bits with any number of
//! threads.

use crate::{Matrix, Vector};
use rayon::prelude::*;

/// Particles per chunk of the ledger's sums (fixed, so the sums do not depend on the threads).
const CHUNK: usize = 4096;

/// What the steps did to the energy since the accounting started.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EnergyLedger {
    /// Whether the steps keep this ledger.
    pub on: bool,
    /// The total energy (kinetic + stored + gravitational) when the accounting started, plus
    /// what the caller gave since: particles added, a rigid velocity or gravity changed.
    pub start: f64,
    /// The stored energy when the accounting started (particles are added unstrained).
    pub stored_start: f64,
    /// Σ over the steps of the stress work.
    pub stress_work: f64,
    /// Σ over the steps of the work of the body-force callback and the tractions.
    pub external_work: f64,
    /// Σ over the steps of what the friction walls and the contact correction took from the
    /// node velocities ([`NodeLosses`]).
    pub friction: f64,
    pub contact: f64,
}

/// What one step's friction walls and contact correction took from the node velocities: the
/// work of their impulses against the velocities they leave, `Σ m_I (v_I − v_I*)·v_I*` over the
/// nodes they changed (contact over the deformable bodies' fields, so a rigid body that pushes
/// one gives a negative part, its work). The normal parts vanish (a wall leaves no normal
/// velocity; contact leaves every body the same one, with balanced impulses): what is counted
/// is friction on the slip. The node kinetic energy's change itself would also count the
/// normal stop, which at nodes of small mass carrying the step's force over their mass is
/// many times what the particles lose (a frictionless head-on impact: 227 against 37).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct NodeLosses {
    pub friction: f64,
    pub contact: f64,
}

/// One step's particle states for the ledger: `old` in the particles' storage order, `new` in
/// the order grid to particle wrote it (`source[k]` the old slot of new slot `k`, or the same
/// slot without `source`).
pub(crate) struct StepStates<'a, const D: usize> {
    pub source: Option<&'a [u32]>,
    pub reference_volume: &'a [f64],
    pub mass: &'a [f64],
    pub old_position: &'a [Vector<D>],
    pub new_position: &'a [Vector<D>],
    pub old_deformation_gradient: &'a [Matrix<D>],
    pub new_deformation_gradient: &'a [Matrix<D>],
    pub old_stress: &'a [Matrix<D>],
    pub new_stress: &'a [Matrix<D>],
    /// The body-force callback's accelerations this step (old order), if there is one.
    pub body_acceleration: Option<&'a [Vector<D>]>,
}

/// The nominal stress `P = J σ F⁻ᵀ = σ cof(F)`, with the cofactor matrix `cof(F) = J F⁻ᵀ`
/// (no division: row `i` of `cof(F)` is `r_{i+1} × r_{i+2}` of `F`'s rows in 3D).
fn nominal_stress<const D: usize>(f: &Matrix<D>, sigma: &Matrix<D>) -> Matrix<D> {
    let cofactor = match D {
        2 => Matrix::<D>::from_fn(|i, j| {
            let sign = if i == j { 1.0 } else { -1.0 };
            sign * f[(1 - i, 1 - j)]
        }),
        _ => Matrix::<D>::from_fn(|i, j| {
            let (a, b) = ((i + 1) % 3, (i + 2) % 3);
            let (c, d) = ((j + 1) % 3, (j + 2) % 3);
            f[(a, c)] * f[(b, d)] - f[(a, d)] * f[(b, c)]
        }),
    };
    sigma * cofactor
}

impl<const D: usize> StepStates<'_, D> {
    /// The step's stress work and the body-force callback's work (see the module header).
    pub fn work(&self) -> (f64, f64) {
        let n = self.new_position.len();
        let chunk = |c: usize| {
            let (mut stress, mut external) = (0.0, 0.0);
            for k in c * CHUNK..((c + 1) * CHUNK).min(n) {
                let p = self.source.map_or(k, |s| s[k] as usize);
                let (f0, f1) = (
                    &self.old_deformation_gradient[p],
                    &self.new_deformation_gradient[k],
                );
                let (p0, p1) = (
                    nominal_stress(f0, &self.old_stress[p]),
                    nominal_stress(f1, &self.new_stress[k]),
                );
                stress += self.reference_volume[p] * 0.5 * (p0 + p1).dot(&(f1 - f0));
                if let Some(b) = self.body_acceleration {
                    let dx = self.new_position[k] - self.old_position[p];
                    external += self.mass[p] * b[p].dot(&dx);
                }
            }
            (stress, external)
        };
        let chunks: Vec<(f64, f64)> = (0..n.div_ceil(CHUNK)).into_par_iter().map(chunk).collect();
        chunks
            .iter()
            .fold((0.0, 0.0), |(s, e), &(cs, ce)| (s + cs, e + ce))
    }
}

/// The work of the tractions `t_b |n a|_b` of boundary points moving from `old` to `new`.
pub(crate) fn traction_work<const D: usize>(
    traction: &[Vector<D>],
    area_normal: &[Vector<D>],
    old: &[Vector<D>],
    new: impl Iterator<Item = Vector<D>>,
) -> f64 {
    new.enumerate()
        .map(|(b, x)| (traction[b] * area_normal[b].norm()).dot(&(x - old[b])))
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `σ cof(F)` is `J σ F⁻ᵀ` (2D and 3D, a general `F`).
    fn cofactor_form<const D: usize>() {
        let f = Matrix::<D>::from_fn(|i, j| {
            (1.3 * i as f64 + 0.7 * j as f64).sin() + if i == j { 1.5 } else { 0.0 }
        });
        let sigma = Matrix::<D>::from_fn(|i, j| 1.0 + (i + j) as f64 * 0.25);
        let expected = crate::determinant(&f) * sigma * f.try_inverse().unwrap().transpose();
        let p = nominal_stress(&f, &sigma);
        assert!(
            (p - expected).norm() <= 1e-14 * expected.norm(),
            "{p} {expected}"
        );
    }

    #[test]
    fn nominal_stress_is_j_sigma_f_inverse_transposed() {
        cofactor_form::<2>();
        cofactor_form::<3>();
    }
}
