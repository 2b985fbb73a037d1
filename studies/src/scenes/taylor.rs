//! Taylor bar impact in 3D: a copper rod hits a rigid, frictionless wall end on.
//!
//! One quarter of the rod is simulated between two slip (symmetry) walls, `x = 0` and `y = 0`;
//! the wall it hits is the slip face `z = 0`. Two published set-ups:
//!
//! * [`TaylorCase::Bilinear`]: `L0 = 32.4 mm`, `R0 = 3.2 mm`, `v = 227 m/s`, ρ = 8930 kg/m³,
//!   E = 117 GPa, ν = 0.35, J2 plasticity `σ_y = 400 MPa + 100 MPa ε̄`, 80 µs (Simo 1992 §7.2;
//!   Zienkiewicz et al. 1998; Foulk et al. 2021): final length 21.42–21.43 mm and foot radius
//!   7.11–7.22 mm (7.12 Simo, 7.11 Zienkiewicz, 7.22 Foulk).
//! * [`TaylorCase::OfhcCopper`]: the experiment of Johnson & Cook (1983) as compiled by Banerjee
//!   (Uintah's validation data, after Zerilli & Armstrong 1987): OFHC copper, `L0 = 25.4 mm`,
//!   `D0 = 7.62 mm`, `v = 190 m/s`: final length 16.21 mm, foot diameter 13.56 mm; Johnson–Cook
//!   constants of OFHC copper (A = 90 MPa, B = 292 MPa, n = 0.31, C = 0.025, m = 1.09).

use rkmpm::error::{Error, Result};
use rkmpm::material::{JohnsonCookParameters, Material};
use rkmpm::options::{Integration, Shape, Side, Transfer, Wall};
use rkmpm::sim::Sim;
use rkmpm::Vector;

/// Which published Taylor test.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TaylorCase {
    Bilinear,
    OfhcCopper,
}

impl TaylorCase {
    /// `(L0, R0, v, duration)` in SI units.
    pub fn geometry(self) -> (f64, f64, f64, f64) {
        match self {
            TaylorCase::Bilinear => (32.4e-3, 3.2e-3, 227.0, 80e-6),
            TaylorCase::OfhcCopper => (25.4e-3, 3.81e-3, 190.0, 100e-6),
        }
    }

    /// `(final length, foot radius)` of the reference, in m.
    pub fn reference(self) -> (f64, f64) {
        match self {
            TaylorCase::Bilinear => (21.42e-3, 7.12e-3),
            TaylorCase::OfhcCopper => (16.21e-3, 13.56e-3 / 2.0),
        }
    }

    pub fn material(self) -> JohnsonCookParameters {
        match self {
            TaylorCase::Bilinear => JohnsonCookParameters {
                density: 8930.0,
                young: 117e9,
                poisson: 0.35,
                a: 400e6,
                b: 100e6,
                n: 1.0,
                c: 0.0,
                reference_strain_rate: 1.0,
                m: 1.0,
                room_temperature: 298.0,
                melt_temperature: 1356.0,
                specific_heat: 383.0,
                taylor_quinney: 0.0,
                damage: None,
                eos: None,
            },
            TaylorCase::OfhcCopper => JohnsonCookParameters {
                damage: None,
                ..rkmpm::material::ofhc_copper()
            },
        }
    }
}

/// The scene and its discretization.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TaylorBar {
    pub case: TaylorCase,
    /// Cells across the initial radius.
    pub cells_per_radius: usize,
    pub shape: Shape,
    pub integration: Integration,
    pub transfer: Transfer,
    pub cfl: f64,
    /// Replaces the case's material (for sensitivity studies).
    pub material: Option<JohnsonCookParameters>,
}

impl Default for TaylorBar {
    fn default() -> Self {
        TaylorBar {
            case: TaylorCase::Bilinear,
            cells_per_radius: 8,
            shape: Shape::BSpline2,
            integration: Integration::MaterialPoint,
            transfer: Transfer::Apic,
            cfl: 0.3,
            material: None,
        }
    }
}

/// What a Taylor run measured (lengths in m).
#[derive(Debug, Clone, PartialEq)]
pub struct TaylorResult {
    pub final_length: f64,
    pub foot_radius: f64,
    pub reference_length: f64,
    pub reference_radius: f64,
    /// Largest equivalent plastic strain.
    pub max_plastic_strain: f64,
    /// Kinetic energy at the end over the initial.
    pub kinetic_left: f64,
    pub particles: usize,
    pub steps: u64,
    pub seconds: f64,
}

impl TaylorBar {
    pub fn build(&self) -> Result<Sim<3>> {
        if self.cells_per_radius < 2 {
            return Err(Error::invalid("cells_per_radius must be >= 2"));
        }
        let (l0, r0, v, _) = self.case.geometry();
        let h = r0 / self.cells_per_radius as f64;
        let across = (2.6 * r0 / h).ceil() as usize + 3;
        let along = (l0 / h).ceil() as usize + 3;
        let mut sim = Sim::<3>::new([0.0; 3], [across, across, along], h)?;
        sim.set_shape(self.shape)?;
        sim.set_integration(self.integration)?;
        sim.set_transfer(self.transfer)?;
        for axis in 0..3 {
            sim.set_wall(axis, Side::Low, Wall::Slip)?;
        }
        let mat = sim.add_material(Material::johnson_cook(
            self.material.unwrap_or(self.case.material()),
        )?);
        let q = h / 2.0;
        let (nr, nz) = ((r0 / q).round() as usize, (l0 / q).round() as usize);
        let mut x = Vec::new();
        for k in 0..nz {
            for j in 0..nr {
                for i in 0..nr {
                    let p = Vector::<3>::new(
                        (i as f64 + 0.5) * q,
                        (j as f64 + 0.5) * q,
                        (k as f64 + 0.5) * q,
                    );
                    if p[0].hypot(p[1]) < r0 {
                        x.push(p);
                    }
                }
            }
        }
        let vel = vec![Vector::<3>::new(0.0, 0.0, -v); x.len()];
        sim.add_particles(mat, &x, &vec![q * q * q; x.len()], Some(&vel))?;
        Ok(sim)
    }

    /// Runs the impact for the case's duration and measures the rod.
    pub fn run(&self) -> Result<TaylorResult> {
        Ok(self.run_observed(0, |_| Ok(()))?.0)
    }

    /// [`TaylorBar::run`], calling `on_frame` at the start and `frames` times over the run.
    pub fn run_observed(
        &self,
        frames: usize,
        mut on_frame: impl FnMut(&Sim<3>) -> Result<()>,
    ) -> Result<(TaylorResult, Sim<3>)> {
        let mut sim = self.build()?;
        let (_, _, _, t_end) = self.case.geometry();
        let ke0 = sim.particles().kinetic_energy();
        let seconds = super::run_with_frames(
            &mut sim,
            t_end,
            self.cfl,
            frames,
            &mut on_frame,
            &mut |_| Ok(false),
        )?;
        let q = sim.grid().cell_size() / 2.0;
        let ps = sim.particles();
        let final_length = ps.position().iter().map(|x| x[2]).fold(0.0, f64::max) + q / 2.0;
        let foot_radius = ps
            .position()
            .iter()
            .filter(|x| x[2] < q)
            .map(|x| x[0].hypot(x[1]))
            .fold(0.0, f64::max)
            + q / 2.0;
        let (reference_length, reference_radius) = self.case.reference();
        let result = TaylorResult {
            final_length,
            foot_radius,
            reference_length,
            reference_radius,
            max_plastic_strain: ps
                .history()
                .iter()
                .map(|s| s.plastic_strain)
                .fold(0.0, f64::max),
            kinetic_left: ps.kinetic_energy() / ke0,
            particles: ps.len(),
            steps: sim.steps(),
            seconds,
        };
        Ok((result, sim))
    }
}
