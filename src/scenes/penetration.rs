//! A hard projectile perforating a ductile plate (Johnson–Cook plasticity and damage, contact),
//! in plane strain (half model) and in 3D (quarter model).
//!
//! The set-up follows Børvik, Langseth, Hopperstad & Malo (2002), "Perforation of 12 mm thick
//! steel plates by 20 mm diameter projectiles with flat, hemispherical and conical noses", Int.
//! J. Impact Eng. 27: a blunt, hardened steel projectile (20 mm diameter, 80 mm long, 197 g) hits
//! a 12 mm Weldox 460 E plate; the measured ballistic limit of the blunt projectile is 184.5 m/s.
//! The plate's Johnson–Cook constants are the ones commonly cited from Børvik et al. (2001):
//! A = 490 MPa, B = 807 MPa, n = 0.73, C = 0.0114 (ε̇0 = 5e-4 s⁻¹), m = 0.94, T_melt = 1800 K,
//! D1 = 0.0705, D2 = 1.732, D3 = −0.54, D4 = −0.015, D5 = 0 (not checked against the paper
//! here; Børvik's rate term is `(1 + ε̇*)^C`, rkmpm's is `1 + C ln ε̇*`). The projectile is
//! elastic steel (it stays nearly elastic in the tests). Only a square of plate `2 × width`
//! across is modelled, clamped at its edge (Børvik's plates are 500 mm across), so the plate is
//! stiffer than in the test.

use crate::boundary::{Boundary, Side};
use crate::error::{Error, Result};
use crate::material::{JohnsonCookParameters, Material};
use crate::sim::{Sim, Transfer};
use crate::Vector;

/// The scene; lengths in m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Penetration {
    pub impact_speed: f64,
    pub plate_thickness: f64,
    /// Half the modelled plate width (the plate is clamped there).
    pub plate_half_width: f64,
    pub projectile_radius: f64,
    pub projectile_length: f64,
    /// Cells across the plate thickness.
    pub cells_through_plate: usize,
    /// Simulated time (s).
    pub duration: f64,
    pub friction: f64,
}

impl Default for Penetration {
    fn default() -> Self {
        Penetration {
            impact_speed: 300.0,
            plate_thickness: 12e-3,
            plate_half_width: 30e-3,
            projectile_radius: 10e-3,
            projectile_length: 80e-3,
            cells_through_plate: 6,
            duration: 300e-6,
            friction: 0.0,
        }
    }
}

/// Weldox 460 E as cited (see the module documentation).
pub fn weldox_460e() -> JohnsonCookParameters {
    JohnsonCookParameters {
        density: 7850.0,
        young: 200e9,
        poisson: 0.33,
        a: 490e6,
        b: 807e6,
        n: 0.73,
        c: 0.0114,
        reference_strain_rate: 5e-4,
        m: 0.94,
        room_temperature: 293.0,
        melt_temperature: 1800.0,
        specific_heat: 452.0,
        taylor_quinney: 0.9,
        damage: Some([0.0705, 1.732, -0.54, -0.015, 0.0]),
        eos: None,
    }
}

/// What a penetration run measured.
#[derive(Debug, Clone, PartialEq)]
pub struct PenetrationResult {
    pub impact_speed: f64,
    /// Mean velocity of the projectile along the shot line at the end (positive: onward).
    pub residual_speed: f64,
    /// How far the projectile's nose ended below the plate's original back face (m; negative:
    /// above it).
    pub nose_depth: f64,
    /// Perforated: the nose ended more than a plate thickness below the original back face and
    /// the projectile still moves onward (dishing alone does not reach that far).
    pub perforated: bool,
    /// Time at the end of the run (the plug may stop it before `duration`).
    pub time: f64,
    /// Plate particles that failed (`D = 1`) and the largest damage.
    pub failed_particles: usize,
    pub max_damage: f64,
    pub particles: usize,
    pub steps: u64,
    pub seconds: f64,
}

impl Penetration {
    /// Builds the simulation in `D` = 2 (plane strain, half model about `x = 0`) or 3 (quarter
    /// model about `x = 0` and `y = 0`). The shot line is the last axis, downward.
    pub fn build<const D: usize>(&self) -> Result<Sim<D>> {
        if self.cells_through_plate < 2 {
            return Err(Error::invalid("cells_through_plate must be >= 2"));
        }
        let h = self.plate_thickness / self.cells_through_plate as f64;
        let below = 4.0 * self.plate_thickness;
        let gap = h;
        let height = below + self.plate_thickness + gap + self.projectile_length + 2.0 * h;
        let across = (self.plate_half_width / h).round() as usize;
        let mut cells = [across; D];
        cells[D - 1] = (height / h).ceil() as usize;
        let mut sim = Sim::<D>::new(Vector::<D>::zeros(), cells, h)?;
        sim.set_transfer(Transfer::Apic)?;
        sim.set_contact(Some(self.friction))?;
        for axis in 0..D - 1 {
            sim.set_boundary(axis, Side::Low, Boundary::Slip)?;
            sim.set_boundary(axis, Side::High, Boundary::Fixed)?;
        }
        let plate = sim.add_material(Material::johnson_cook(weldox_460e())?);
        let projectile = sim.add_material(Material::neo_hookean(7850.0, 204e9, 0.33)?);
        let q = h / 2.0;
        let lattice = |lo: f64, hi: f64, inside: &dyn Fn(&Vector<D>) -> bool| {
            let n_across = 2 * across;
            let n_up = ((hi - lo) / q).round() as usize;
            let mut x = Vec::new();
            let total = n_across.pow(D as u32 - 1) * n_up;
            for k in 0..total {
                let mut r = k;
                let p = Vector::<D>::from_fn(|a, _| {
                    if a + 1 == D {
                        return 0.0;
                    }
                    let i = r % n_across;
                    r /= n_across;
                    (i as f64 + 0.5) * q
                });
                let mut p = p;
                p[D - 1] = lo + (r as f64 + 0.5) * q;
                if inside(&p) {
                    x.push(p);
                }
            }
            x
        };
        let radius = self.projectile_radius;
        let xp = lattice(below, below + self.plate_thickness, &|_| true);
        sim.add_particles(plate, &xp, &vec![q.powi(D as i32); xp.len()], None)?;
        let top = below + self.plate_thickness + gap;
        let xs = lattice(top, top + self.projectile_length, &|p| {
            p.rows(0, D - 1).norm() < radius
        });
        let mut v = Vector::<D>::zeros();
        v[D - 1] = -self.impact_speed;
        sim.add_particles(
            projectile,
            &xs,
            &vec![q.powi(D as i32); xs.len()],
            Some(&vec![v; xs.len()]),
        )?;
        Ok(sim)
    }

    /// Runs for `duration`, or until debris (the plug) comes within two cells of the bottom face,
    /// calling `on_frame` `frames` times, and measures the outcome.
    pub fn run_observed<const D: usize>(
        &self,
        frames: usize,
        mut on_frame: impl FnMut(&Sim<D>) -> Result<()>,
    ) -> Result<(PenetrationResult, Sim<D>)> {
        let mut sim = self.build::<D>()?;
        let near_bottom = |sim: &Sim<D>| {
            let floor = 2.0 * sim.grid().cell_size;
            sim.particles().position.iter().any(|x| x[D - 1] < floor)
        };
        let seconds = super::run_with_frames(
            &mut sim,
            self.duration,
            0.3,
            frames,
            &mut on_frame,
            &near_bottom,
        )?;
        let back = 4.0 * self.plate_thickness;
        let ps = sim.particles();
        let (mut vsum, mut msum, mut lowest) = (0.0, 0.0, f64::INFINITY);
        let (mut failed, mut max_damage) = (0, 0.0f64);
        for p in 0..ps.len() {
            if ps.material[p] == 1 {
                vsum -= ps.mass[p] * ps.velocity[p][D - 1];
                msum += ps.mass[p];
                lowest = lowest.min(ps.position[p][D - 1]);
            } else {
                let d = ps.plastic[p].damage;
                max_damage = max_damage.max(d);
                failed += usize::from(d >= 1.0);
            }
        }
        let result = PenetrationResult {
            impact_speed: self.impact_speed,
            residual_speed: vsum / msum,
            nose_depth: back - lowest,
            perforated: back - lowest > self.plate_thickness && vsum > 0.0,
            time: sim.time(),
            failed_particles: failed,
            max_damage,
            particles: ps.len(),
            steps: sim.steps(),
            seconds,
        };
        Ok((result, sim))
    }

    pub fn run<const D: usize>(&self) -> Result<PenetrationResult> {
        Ok(self.run_observed::<D>(0, |_| Ok(()))?.0)
    }
}
