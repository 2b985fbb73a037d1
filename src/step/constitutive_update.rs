//! The constitutive update of one particle, run inside grid to particle under USL and after the
//! second map under MUSL: elastic models from `F`, history models by return mapping from their
//! state and the increment `ΔF = F^{n+1} (F^n)⁻¹`; the particle kept inside the walls; the
//! checks of its new state (finite, `det F > 0`, inside the grid).

use super::grid_to_particle::{Chunk, Finish, NewState, ParticleUpdate, CHUNK};
use super::profile::lap;
use super::{StepInputs, Workspace};
use crate::grid::DomainBox;
use crate::material::{block, embed3, pressure, Constitutive, History, Material};
use crate::options::Walls;
use crate::particles::Particles;
use crate::Matrix;
use nalgebra::Matrix3;
use rayon::prelude::*;

/// Step 6, the constitutive update of one particle (run inside the gather under USL): elastic
/// models from `F`, history models by return mapping from their state and the increment
/// `ΔF = F^{n+1} (F^n)⁻¹`; particles kept inside the walls; the checks.
pub(super) struct ConstitutiveUpdate<'a, const D: usize> {
    pub(super) domain: DomainBox<D>,
    pub(super) particles: &'a Particles<D>,
    pub(super) materials: &'a [Material],
    pub(super) walls: &'a Walls<D>,
    pub(super) any_wall: bool,
    pub(super) dt: f64,
}

impl<const D: usize> Finish<D> for ConstitutiveUpdate<'_, D> {
    // Always inlined into the gather, which keeps the new state in registers.
    #[inline(always)]
    fn finish(&self, p: usize, u: &mut ParticleUpdate<D>, history: &mut History) -> Option<f64> {
        let j = crate::determinant(&u.deformation_gradient);
        if j.is_nan() || j <= 0.0 {
            // Inverted or not finite: the checks reject the step; no stress to compute.
            u.stress = Matrix::zeros();
            u.pressure = 0.0;
            return None;
        }
        let ps = self.particles;
        let material = &self.materials[ps.material[p] as usize];
        let mut wave_speed = None;
        (u.stress, u.pressure) = if material.is_elastic() {
            let (stress, c) = material.elastic_stress_and_wave_speed(&u.deformation_gradient, j);
            wave_speed = Some(c);
            stress
        } else {
            let f = embed3(&u.deformation_gradient);
            let f_old = embed3(&ps.deformation_gradient[p]);
            let df = f * f_old.try_inverse().unwrap_or_else(Matrix3::identity);
            let (state, s3) = material.plastic_update(&ps.history[p], &df, j, self.dt);
            *history = state;
            (block(&s3), pressure(&s3))
        };
        self.complete(u, j, || {
            wave_speed.unwrap_or_else(|| material.wave_speed(j))
        })
    }

    /// A chunk of one neo-Hookean material with no particle inverted: the steps of `finish`
    /// over the chunk's particles as lanes (`NeoHookean::stress_lanes`), which the compiler
    /// runs in vector registers; the same operations per particle, so the same bits.
    #[inline(always)]
    fn finish_chunk(
        &self,
        chunk: Chunk<'_>,
        us: &mut [ParticleUpdate<D>],
        speeds: &mut [Option<f64>],
    ) -> bool {
        let n = us.len();
        let ps = self.particles;
        let id = ps.material[chunk.particle(0)];
        if !chunk.all(|p| ps.material[p] == id) {
            return false;
        }
        let Material::NeoHookean(m) = &self.materials[id as usize] else {
            return false;
        };
        // Lanes past `n` hold the identity (J = 1), and nothing reads them back.
        let (mut f, mut j) = ([[[0.0; CHUNK]; D]; D], [1.0; CHUNK]);
        for (k, u) in us.iter().enumerate() {
            j[k] = crate::determinant(&u.deformation_gradient);
            for (a, row) in f.iter_mut().enumerate() {
                for (b, lane) in row.iter_mut().enumerate() {
                    lane[k] = u.deformation_gradient[(a, b)];
                }
            }
        }
        for (a, row) in f.iter_mut().enumerate() {
            row[a][n..].fill(1.0);
        }
        // NaN or not positive: `finish` handles it (and says why).
        if !j[..n].iter().all(|&j| j > 0.0) {
            return false;
        }
        let mut ln_j = [0.0; CHUNK];
        for (l, j) in ln_j.iter_mut().zip(&j) {
            *l = j.ln();
        }
        let (mut s, mut pressure) = ([[[0.0; CHUNK]; D]; D], [0.0; CHUNK]);
        m.stress_lanes(&f, &j, &ln_j, &mut s, &mut pressure);
        let wave_speed: [f64; CHUNK] = std::array::from_fn(|k| m.wave_speed_from_log(ln_j[k]));
        for (k, (u, speed)) in us.iter_mut().zip(speeds.iter_mut()).enumerate() {
            u.stress = Matrix::<D>::from_fn(|a, b| s[a][b][k]);
            u.pressure = pressure[k];
            *speed = self.complete(u, j[k], || wave_speed[k]);
        }
        true
    }
}

impl<'a, const D: usize> ConstitutiveUpdate<'a, D> {
    /// The update of the step's particles: elastic models from `F`, history models by return
    /// mapping from their state and the increment `ΔF = F^{n+1} (F^n)⁻¹`; particles kept
    /// inside the walls; the checks.
    pub(super) fn of<S>(inputs: &StepInputs<'a, D, S>) -> Self {
        ConstitutiveUpdate {
            domain: inputs.grid.domain(),
            particles: inputs.particles,
            materials: inputs.materials,
            walls: inputs.walls,
            any_wall: inputs.walls.any_wall(),
            dt: inputs.dt,
        }
    }

    /// Phase 6: under MUSL the update of every particle's new state after the second map
    /// (under USL grid to particle ran it in its pass, `gathered` is its result). Leaves the
    /// signal speed in `work.new_signal_speed`; returns whether every particle passed its checks.
    pub(super) fn phase(&self, usl: bool, gathered: (f64, bool), work: &mut Workspace<D>) -> bool {
        let mut clock = std::time::Instant::now();
        let (speed, all_admissible) = match usl {
            true => gathered,
            false => {
                let result = self.run_all(&mut work.new_state, &mut work.admissible);
                work.times.constitutive += lap(&mut clock);
                result
            }
        };
        work.new_signal_speed = speed;
        all_admissible
    }
}

impl<const D: usize> ConstitutiveUpdate<'_, D> {
    /// `finish` of every particle of `new` in place, in parallel (MUSL, where it runs after the
    /// second map); `admissible[p]` says whether particle `p` passed its checks. Returns the
    /// largest signal speed `c + |v|` and whether every particle passed.
    pub(super) fn run_all(&self, new: &mut NewState<D>, admissible: &mut Vec<bool>) -> (f64, bool) {
        let writer = new.writer();
        admissible.clear();
        admissible.resize(self.particles.len(), false);
        admissible
            .par_iter_mut()
            .enumerate()
            .map_init(History::default, |scratch, (p, ok)| {
                // SAFETY: every particle index is visited by one task only.
                unsafe {
                    let mut u = writer.get(p);
                    let finished = self.finish(p, &mut u, writer.history(p).unwrap_or(scratch));
                    writer.store(p, &u);
                    *ok = finished.is_some();
                    (finished.unwrap_or(0.0), *ok)
                }
            })
            .reduce(|| (0.0, true), |a, b| (a.0.max(b.0), a.1 && b.1))
    }

    /// The end of `finish` once the stress is in `u` (`j = det F > 0`): the particle kept
    /// inside the walls (`Walls::clamp_to_walls`), and its signal speed `c + |v|` as
    /// `Sim::signal_speed` takes it from the committed state, or `None` when the new state is
    /// not admissible.
    #[inline(always)]
    fn complete(
        &self,
        u: &mut ParticleUpdate<D>,
        j: f64,
        wave_speed: impl FnOnce() -> f64,
    ) -> Option<f64> {
        if self.any_wall {
            self.walls.clamp_to_walls(&self.domain, &mut u.position);
        }
        u.is_admissible(&self.domain, j)
            .then(|| wave_speed() + u.velocity.norm())
    }
}
