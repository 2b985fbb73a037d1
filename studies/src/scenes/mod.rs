//! Ready-made scenes with exact answers, shared by the tests, the examples and the runner.

use rkmpm::error::Result;
use rkmpm::material::Material;
use rkmpm::sim::{Sim, Transfer};
use rkmpm::walls::{Side, Wall};
use rkmpm::Shape;
use rkmpm::Vector;
use std::f64::consts::PI;

/// Two elastic disks on a collision course (Sulsky, Chen & Schreyer 1994): the default scene of
/// the runner. Unit square, disks of radius 0.2 at (0.25, 0.25) and (0.75, 0.75) moving toward
/// each other at 0.1 m/s along the diagonal, neo-Hookean (E = 1000 Pa, ν = 0.3, ρ = 1000 kg/m³),
/// `cells` cells per side, 2 particles per cell per direction, free faces, APIC, quadratic B-spline.
pub fn colliding_disks(cells: usize) -> Result<Sim<2>> {
    let h = 1.0 / cells as f64;
    let mut sim = Sim::<2>::new([0.0, 0.0], [cells, cells], h)?;
    let m = sim.add_material(Material::neo_hookean(1000.0, 1000.0, 0.3)?);
    let q = h / 2.0;
    for (centre, v) in [(0.25, 0.1), (0.75, -0.1)] {
        let mut x = Vec::new();
        for j in 0..2 * cells {
            for i in 0..2 * cells {
                let p = Vector::<2>::new((i as f64 + 0.5) * q, (j as f64 + 0.5) * q);
                if (p - Vector::<2>::new(centre, centre)).norm() < 0.2 {
                    x.push(p);
                }
            }
        }
        let vel = vec![Vector::<2>::new(v, v); x.len()];
        sim.add_particles(m, &x, &vec![q * q; x.len()], Some(&vel))?;
    }
    Ok(sim)
}

/// The axial vibrating bar of METHOD.md section 6.5: length `L = 1` along x, fixed at `x = 0`,
/// free at `x = L`, `v(x, t) = v0 cos(ωt) sin(βx)`, `β = π / (2L)`, `ω = β sqrt(E/ρ)`.
///
/// Linear elastic with `ν = 0`, so the motion is exactly one-dimensional in 2D and 3D.
/// The grid has `cells_along + 8` cells along x and 4 across; the bar is 2 cells thick and
/// starts one cell above the low faces; 2 particles per cell per direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VibratingBar {
    pub cells_along: usize,
    pub length: f64,
    pub young: f64,
    pub density: f64,
    pub v0: f64,
}

impl Default for VibratingBar {
    fn default() -> Self {
        VibratingBar {
            cells_along: 32,
            length: 1.0,
            young: 100.0,
            density: 1.0,
            v0: 0.01,
        }
    }
}

impl VibratingBar {
    pub fn beta(&self) -> f64 {
        PI / (2.0 * self.length)
    }
    pub fn omega(&self) -> f64 {
        self.beta() * (self.young / self.density).sqrt()
    }
    pub fn period(&self) -> f64 {
        2.0 * PI / self.omega()
    }
    /// Exact axial velocity at reference position `x` and time `t`.
    pub fn velocity(&self, x: f64, t: f64) -> f64 {
        self.v0 * (self.omega() * t).cos() * (self.beta() * x).sin()
    }
    pub fn cell_size(&self) -> f64 {
        self.length / self.cells_along as f64
    }

    /// Particle positions: 2 per cell per direction, x fastest, then y, then z.
    pub fn positions<const D: usize>(&self) -> Vec<Vector<D>> {
        let h = self.cell_size();
        let q = h / 2.0;
        let nx = 2 * self.cells_along;
        let mut out = Vec::new();
        let across = if D == 3 { 4 } else { 1 };
        for k in 0..across {
            for j in 0..4 {
                for i in 0..nx {
                    let mut x = Vector::<D>::zeros();
                    x[0] = (i as f64 + 0.5) * q;
                    x[1] = h + (j as f64 + 0.5) * q;
                    if D == 3 {
                        x[2] = h + (k as f64 + 0.5) * q;
                    }
                    out.push(x);
                }
            }
        }
        out
    }

    /// The simulation, ready to step: quadratic B-spline, APIC, USL.
    pub fn build<const D: usize>(&self) -> Result<Sim<D>> {
        let h = self.cell_size();
        let mut cells = [4; D];
        cells[0] = self.cells_along + 8;
        let mut sim = Sim::<D>::new(Vector::<D>::zeros(), cells, h)?;
        sim.set_shape(Shape::BSpline2)?;
        sim.set_transfer(Transfer::Apic)?;
        sim.set_wall(0, Side::Low, Wall::Fixed)?;
        let m = sim.add_material(Material::linear_elastic(self.density, self.young, 0.0)?);
        let x = self.positions::<D>();
        let vol = vec![(h / 2.0).powi(D as i32); x.len()];
        let v: Vec<Vector<D>> = x
            .iter()
            .map(|p| {
                let mut v = Vector::<D>::zeros();
                v[0] = self.velocity(p[0], 0.0);
                v
            })
            .collect();
        sim.add_particles(m, &x, &vol, Some(&v))?;
        Ok(sim)
    }
}

/// Mass-weighted mean x-velocity of the particles.
pub fn mean_axial_velocity<const D: usize>(sim: &Sim<D>) -> f64 {
    let ps = sim.particles();
    let m: f64 = ps.mass().iter().sum();
    ps.mass()
        .iter()
        .zip(ps.velocity())
        .map(|(m, v)| m * v[0])
        .sum::<f64>()
        / m
}

/// The result of running the bar for one period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BarResult {
    /// `max_t |v̄_h − v̄| / max_t |v̄|` of the mass-weighted mean velocity.
    pub velocity_error: f64,
    /// Measured period from the two zero crossings of the mean velocity.
    pub period: f64,
    pub exact_period: f64,
    pub steps: u64,
}

/// Runs the bar for one period with `dt = stable_dt(cfl)` taken once at the start (the last
/// step shortened to land on the period), and measures the mean-velocity history.
pub fn run_vibrating_bar<const D: usize>(
    bar: &VibratingBar,
    sim: &mut Sim<D>,
    cfl: f64,
) -> Result<BarResult> {
    let period = bar.period();
    let ps = sim.particles();
    let m_total: f64 = ps.mass().iter().sum();
    let shape_mean = ps
        .mass()
        .iter()
        .zip(ps.reference_position())
        .map(|(m, x)| m * (bar.beta() * x[0]).sin())
        .sum::<f64>()
        / m_total;
    let amplitude = bar.v0 * shape_mean;
    let dt = sim.stable_dt(cfl)?;
    let mut worst: f64 = 0.0;
    let mut crossings = Vec::new();
    let mut prev = (sim.time(), mean_axial_velocity(sim));
    while sim.time() < period * (1.0 - 1e-12) {
        let step = dt.min(period - sim.time());
        sim.step(step)?;
        let now = (sim.time(), mean_axial_velocity(sim));
        let exact = amplitude * (bar.omega() * now.0).cos();
        worst = worst.max((now.1 - exact).abs());
        if prev.1.signum() != now.1.signum() && now.1 != 0.0 {
            crossings.push(prev.0 + (now.0 - prev.0) * prev.1 / (prev.1 - now.1));
        }
        prev = now;
    }
    let measured = if crossings.len() >= 2 {
        2.0 * (crossings[1] - crossings[0])
    } else {
        f64::NAN
    };
    Ok(BarResult {
        velocity_error: worst / amplitude.abs(),
        period: measured,
        exact_period: period,
        steps: sim.steps(),
    })
}

/// Steps `sim` to `t_end` at `cfl` times the stable step, calling `on_frame` at the start,
/// `frames` times evenly over the run and at the end (none when `frames` is 0), and calling
/// `after_step(sim)` after every step: it may change what the scene prescribes (a rigid body's
/// velocity) and stops the run early by returning `true`. Returns the wall time in seconds.
pub fn run_with_frames<const D: usize>(
    sim: &mut Sim<D>,
    t_end: f64,
    cfl: f64,
    frames: usize,
    on_frame: &mut dyn FnMut(&Sim<D>) -> Result<()>,
    after_step: &mut dyn FnMut(&mut Sim<D>) -> Result<bool>,
) -> Result<f64> {
    let start = std::time::Instant::now();
    let mut next_frame = 0;
    while sim.time() < t_end {
        if frames > 0 && sim.time() >= next_frame as f64 * t_end / frames as f64 {
            on_frame(sim)?;
            next_frame += 1;
        }
        // The last step lands on t_end (the small excess keeps round-off from adding a step).
        let dt = sim.stable_dt(cfl)?.min(t_end - sim.time() + 1e-12 * t_end);
        sim.step(dt)?;
        if after_step(sim)? {
            break;
        }
    }
    if frames > 0 {
        on_frame(sim)?;
    }
    Ok(start.elapsed().as_secs_f64())
}

mod collapse;
pub use collapse::{
    deposit_front, log_log_slope, thick_front, CollapseResult, Gate, GranularColumn,
    GATE_CLEARANCE, NGUYEN_BUI_FUKAGAWA,
};

mod taylor;
pub use taylor::{TaylorBar, TaylorCase, TaylorResult};

mod penetration;
pub use penetration::{
    joined_to_the_clamp, recht_ipson_fit, weldox_460e, Penetration, PenetrationResult,
};
