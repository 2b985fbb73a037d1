//! Plane-strain collapse of a granular column (aluminium-rod-like material) against a wall, and
//! the power laws measured for true two-dimensional columns.

use rkmpm::error::{Error, Result};
use rkmpm::material::{DruckerPrager, ElasticConstants, InertialRheology, Material};
use rkmpm::sim::{Integration, Sim, Transfer};
use rkmpm::walls::{Side, Wall};
use rkmpm::Shape;
use rkmpm::Vector;

/// Measured laws for true 2D columns of aluminium rods, Nguyen, Bui & Fukagawa (2015), "Failure
/// mechanism of true 2D granular flows" (J. Chem. Eng. Japan 48(6); arXiv:1512.05180), with
/// `a = H0 / L0`: for `a ≥ 0.65`, `H0 / H∞ = 1.42 a^(2/3)`; run-out
/// `(L∞ − L0) / L0 = 3.25 a^0.96` for `0.65 ≤ a ≤ 1.5` and `3.80 a^0.73` for `a ≥ 1.5`; for
/// `a < 0.65` the top of the column is not reached (`H∞ = H0`).
pub struct PowerLaws;

pub const NGUYEN_BUI_FUKAGAWA: PowerLaws = PowerLaws;

impl PowerLaws {
    /// `(L∞ − L0) / L0` at aspect ratio `a` (`None` below 0.65, where no law was fitted).
    pub fn runout(&self, a: f64) -> Option<f64> {
        if a < 0.65 {
            None
        } else if a <= 1.5 {
            Some(3.25 * a.powf(0.96))
        } else {
            Some(3.80 * a.powf(0.73))
        }
    }

    /// `H∞ / L0` at aspect ratio `a`.
    pub fn final_height(&self, a: f64) -> f64 {
        if a < 0.65 {
            a
        } else {
            a / (1.42 * a.powf(2.0 / 3.0))
        }
    }
}

/// A column `L0` wide and `a L0` high, standing on a floor against a smooth (slip) wall at
/// `x = 0`, released at rest under gravity. Drucker–Prager with the rods' parameters as the SPH
/// and MPM studies of Bui et al. (2008) use them: ρ = 2650 kg/m³, E = 0.84 MPa, ν = 0.3, φ = 19.8°,
/// no cohesion, no dilatancy. The floor is a Coulomb friction wall with `μ = tan φ`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GranularColumn {
    /// Initial width `L0` (m).
    pub width: f64,
    /// Aspect ratio `a = H0 / L0`.
    pub aspect: f64,
    /// Cells across `L0`.
    pub cells_across: usize,
    pub density: f64,
    pub young: f64,
    pub poisson: f64,
    pub friction_degrees: f64,
    pub dilatancy_degrees: f64,
    pub cohesion: f64,
    pub floor_friction: f64,
    /// The wall at `x = 0` the column stands against (slip by default, as in the experiments'
    /// smooth glass; `Friction(μ)` or `Fixed` for the sensitivity study).
    pub wall: Wall,
    pub gravity: f64,
    /// Simulated time, in units of `sqrt(H0 / g)` (the flow stops after about 3–4).
    pub duration: f64,
    pub shape: Shape,
    pub integration: Integration,
    pub transfer: Transfer,
    /// The μ(I) rate dependence of the soil's friction (none by default).
    pub rheology: Option<InertialRheology>,
    /// The gate that holds the column before the release: `None` (the default) releases the
    /// whole column at once, as if the gate vanished.
    pub gate: Option<Gate>,
    /// VC's solve (`None`, the default: the engine's automatic rule).
    pub vc_solve: Option<rkmpm::VcSolve>,
}

/// How far the gate reaches above the column's top at the start, and how far above it the lifted
/// gate is held, in cells: beyond the reach of every shape function here (support radius up to
/// 2 cells on either side), so the gate's ends never share a grid node with the column's top.
pub const GATE_CLEARANCE: f64 = 5.0;

/// A gate lifted at a finite speed instead of an instant release: a rigid plate one cell thick
/// against the column's free side, from the floor to [`GATE_CLEARANCE`] cells above the top,
/// moving up at `speed` until its lower edge is that far above the column's top, then held
/// there. Its ends so stay out of reach of the soil's shape functions: where they overlap, the
/// contact normal tilts round the gate's corner and the moving gate would kick the soil's top.
/// It meets the soil through the grid contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gate {
    /// Lifting speed (m/s).
    pub speed: f64,
    /// Coulomb friction coefficient between gate and soil (0: a smooth gate).
    pub friction: f64,
}

impl Default for GranularColumn {
    fn default() -> Self {
        let friction = 19.8f64;
        GranularColumn {
            width: 0.1,
            aspect: 1.0,
            cells_across: 16,
            density: 2650.0,
            young: 0.84e6,
            poisson: 0.3,
            friction_degrees: friction,
            dilatancy_degrees: 0.0,
            cohesion: 0.0,
            floor_friction: friction.to_radians().tan(),
            wall: Wall::Slip,
            gravity: 9.81,
            duration: 8.0,
            shape: Shape::BSpline2,
            integration: Integration::MaterialPoint,
            transfer: Transfer::Apic,
            rheology: None,
            gate: None,
            vc_solve: None,
        }
    }
}

/// What a collapse run measured.
#[derive(Debug, Clone, PartialEq)]
pub struct CollapseResult {
    pub aspect: f64,
    /// Final run-out `L∞`: the front of the continuous deposit (see [`deposit_front`]).
    pub runout: f64,
    /// Final height `H∞` (the highest particle plus half a particle spacing).
    pub height: f64,
    /// `(L∞ − L0) / L0`.
    pub normalized_runout: f64,
    /// `H∞ / L0`.
    pub normalized_height: f64,
    /// Kinetic energy at the end over `m g H0` (how settled the heap is).
    pub final_kinetic: f64,
    /// Largest yield function `f(τ) / E` over the particles at the end (≤ 0 up to round-off).
    pub worst_yield: f64,
    /// Relative change of the total mass (zero: particles carry it).
    pub mass_change: f64,
    pub steps: usize,
    pub particles: usize,
    pub seconds: f64,
}

impl GranularColumn {
    /// Builds the simulation: domain long enough for the measured run-out plus margin.
    pub fn build(&self) -> Result<Sim<2>> {
        if !(self.aspect > 0.0 && self.aspect.is_finite()) || self.cells_across < 2 {
            return Err(Error::invalid(
                "aspect must be positive and cells_across >= 2",
            ));
        }
        if let Some(gate) = self.gate {
            if !(gate.speed > 0.0 && gate.speed.is_finite()) {
                return Err(Error::invalid(format!(
                    "the gate's speed must be positive, got {}",
                    gate.speed
                )));
            }
        }
        let h = self.width / self.cells_across as f64;
        let h0 = self.aspect * self.width;
        let reach = 1.0 + 1.6 * NGUYEN_BUI_FUKAGAWA.runout(self.aspect.max(0.65)).unwrap();
        let cells_x = (reach * self.width / h).ceil() as usize + 4;
        // A lifted gate ends with its lower edge GATE_CLEARANCE cells above the column, its
        // top H0 + GATE_CLEARANCE h higher.
        let room = match self.gate {
            Some(_) => 2.0 * (h0 + GATE_CLEARANCE * h),
            None => h0,
        };
        let cells_y = (room / h).ceil() as usize + 4;
        let mut sim = Sim::<2>::new([0.0, 0.0], [cells_x, cells_y], h)?;
        sim.set_shape(self.shape)?;
        sim.set_integration(self.integration)?;
        if let Some(solve) = self.vc_solve {
            sim.set_vc_solve(solve)?;
        }
        sim.set_transfer(self.transfer)?;
        sim.set_wall(0, Side::Low, self.wall)?;
        sim.set_wall(1, Side::Low, Wall::Friction(self.floor_friction))?;
        sim.set_gravity([0.0, -self.gravity])?;
        let soil = DruckerPrager::new(
            ElasticConstants::new(self.density, self.young, self.poisson)?,
            self.friction_degrees,
            self.cohesion,
            self.dilatancy_degrees,
        )?;
        let mat = sim.add_material(Material::DruckerPrager(soil.with_rheology(self.rheology)));
        let q = h / 2.0;
        let (nx, ny) = (2 * self.cells_across, (h0 / q).round() as usize);
        // Particles on a lattice of spacing q, `nx × ny` of them from `x0` along the floor.
        let lattice = |x0: f64, nx: usize, ny: usize| -> Vec<Vector<2>> {
            (0..nx * ny)
                .map(|k| {
                    let (i, j) = ((k % nx) as f64, (k / nx) as f64);
                    Vector::<2>::new(x0 + (i + 0.5) * q, (j + 0.5) * q)
                })
                .collect()
        };
        let x = lattice(0.0, nx, ny);
        sim.add_particles(mat, &x, &vec![q * q; x.len()], None)?;
        if let Some(gate) = self.gate {
            sim.set_contact(Some(gate.friction))?;
            let plate = sim.add_material(Material::rigid(self.density, [0.0, gate.speed, 0.0])?);
            // Rows of q = h/2 up to GATE_CLEARANCE cells above the column.
            let rows = ny + 2 * GATE_CLEARANCE as usize;
            let x = lattice(self.width, 2, rows);
            sim.add_particles(plate, &x, &vec![q * q; x.len()], None)?;
        }
        Ok(sim)
    }

    /// When the gate's lower edge is [`GATE_CLEARANCE`] cells above the column's top.
    fn gate_lifted_at(&self) -> Option<f64> {
        let h = self.width / self.cells_across as f64;
        self.gate
            .map(|gate| (self.aspect * self.width + GATE_CLEARANCE * h) / gate.speed)
    }

    /// Runs the collapse to `duration · sqrt(H0 / g)` at CFL 0.3 and measures the heap.
    pub fn run(&self) -> Result<CollapseResult> {
        Ok(self.run_observed(0, |_| Ok(()))?.0)
    }

    /// [`GranularColumn::run`], calling `on_frame` at the start and `frames` times evenly over
    /// the run (for VTK output), and returning the final simulation too.
    pub fn run_observed(
        &self,
        frames: usize,
        mut on_frame: impl FnMut(&Sim<2>) -> Result<()>,
    ) -> Result<(CollapseResult, Sim<2>)> {
        let mut sim = self.build()?;
        let h0 = self.aspect * self.width;
        let t_end = self.duration * (h0 / self.gravity).sqrt();
        let ps = sim.particles();
        let mass0: f64 = (0..ps.len())
            .filter(|&p| ps.material()[p] == 0)
            .map(|p| ps.mass()[p])
            .sum();
        let mut lift = self.gate_lifted_at();
        let mut hold_the_gate = |sim: &mut Sim<2>| {
            if lift.is_some_and(|t| sim.time() >= t) {
                sim.set_rigid_velocity(1, [0.0; 3])?;
                lift = None;
            }
            Ok(false)
        };
        let seconds = super::run_with_frames(
            &mut sim,
            t_end,
            0.3,
            frames,
            &mut on_frame,
            &mut hold_the_gate,
        )?;
        let q = sim.grid().cell_size() / 2.0;
        let ps = sim.particles();
        // The soil only (the gate, if any, is material 1).
        let soil: Vec<usize> = (0..ps.len()).filter(|&p| ps.material()[p] == 0).collect();
        let position: Vec<Vector<2>> = soil.iter().map(|&p| ps.position()[p]).collect();
        let runout = deposit_front(&position, q);
        let height = position.iter().map(|x| x[1]).fold(0.0, f64::max) + q / 2.0;
        let mass: f64 = soil.iter().map(|&p| ps.mass()[p]).sum();
        let kinetic: f64 = soil
            .iter()
            .map(|&p| 0.5 * ps.mass()[p] * ps.velocity()[p].norm_squared())
            .sum();
        let Material::DruckerPrager(dp) = sim.materials()[0] else {
            unreachable!("the column is Drucker–Prager")
        };
        let worst_yield = soil
            .iter()
            .map(|&p| {
                let j = rkmpm::determinant(&ps.deformation_gradient()[p]);
                let mut tau = rkmpm::material::embed3(&ps.stress()[p]) * j;
                tau[(2, 2)] = out_of_plane_stress(&ps.stress()[p], ps.pressure()[p]) * j;
                dp.yield_function(&tau.symmetric_eigenvalues()) / dp.elastic.young
            })
            .fold(f64::NEG_INFINITY, f64::max);
        let result = CollapseResult {
            aspect: self.aspect,
            runout,
            height,
            normalized_runout: (runout - self.width) / self.width,
            normalized_height: height / self.width,
            final_kinetic: kinetic / (mass0 * self.gravity * h0),
            worst_yield,
            mass_change: (mass - mass0).abs() / mass0,
            steps: sim.steps() as usize,
            particles: soil.len(),
            seconds,
        };
        Ok((result, sim))
    }
}

/// The front of the deposit: walking out from the wall over the particles sorted by `x`, the
/// last particle before the first gap wider than four particle spacings `q` along `x`, plus
/// `q/2` (the edge of its share of the body). Particles thrown ahead of the heap and separated
/// from it do not count, as scattered grains do not in the experiments' run-out.
pub fn deposit_front(positions: &[Vector<2>], q: f64) -> f64 {
    let mut x: Vec<f64> = positions.iter().map(|p| p[0]).collect();
    x.sort_by(f64::total_cmp);
    let mut front = x.first().copied().unwrap_or(0.0);
    for &xi in &x {
        if xi - front > 4.0 * q {
            break;
        }
        front = xi;
    }
    front + q / 2.0
}

/// The front of the part of the deposit thicker than `thickness`: walking out from the wall at
/// `x = 0` in columns `q` wide, the start of the first column whose highest particle (plus
/// `q/2`) lies below `thickness`. With `thickness` of a few particle spacings it leaves out the
/// thin layer a spreading heap leaves ahead of itself, which [`deposit_front`] counts.
pub fn thick_front(positions: &[Vector<2>], q: f64, thickness: f64) -> f64 {
    let columns = positions
        .iter()
        .map(|p| (p[0] / q).floor().max(0.0) as usize + 1)
        .max()
        .unwrap_or(0);
    let mut top = vec![0.0f64; columns];
    for p in positions {
        let c = (p[0] / q).floor().max(0.0) as usize;
        top[c] = top[c].max(p[1] + q / 2.0);
    }
    let first_thin = top.iter().position(|&t| t < thickness).unwrap_or(columns);
    first_thin as f64 * q
}

/// The least-squares slope of `ln y` against `ln x`: the exponent of a power law through the
/// points `(x, y)`.
pub fn log_log_slope(points: &[(f64, f64)]) -> f64 {
    let logs: Vec<(f64, f64)> = points.iter().map(|(x, y)| (x.ln(), y.ln())).collect();
    crate::verification::least_squares_line(&logs).0
}

/// `σ_zz` of a plane-strain particle from its in-plane stress and pressure `−tr(σ)/3`.
fn out_of_plane_stress(s: &rkmpm::Matrix<2>, pressure: f64) -> f64 {
    -3.0 * pressure - s.trace()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ramp of particles on a lattice of spacing `q`, `N − c` particles high in column `c`:
    /// the part thicker than `k q` ends where the ramp drops below `k` particles, and the whole
    /// deposit (no gaps) ends at the last column.
    #[test]
    fn thick_front_of_a_ramp() {
        let (q, n) = (0.01, 20usize);
        let x: Vec<Vector<2>> = (0..n)
            .flat_map(|c| {
                (0..n - c)
                    .map(move |r| Vector::<2>::new((c as f64 + 0.5) * q, (r as f64 + 0.5) * q))
            })
            .collect();
        for k in [1usize, 2, 5, 20] {
            // A threshold between particle layers, away from the round-off of the tops.
            let front = thick_front(&x, q, (k as f64 - 0.25) * q);
            assert!(
                (front - (n - k + 1) as f64 * q).abs() < 1e-12,
                "k {k}: {front}"
            );
        }
        assert!((deposit_front(&x, q) - n as f64 * q).abs() < 1e-12);
        assert_eq!(thick_front(&[], q, q), 0.0);
    }

    /// The slope of a power law's points is its exponent.
    #[test]
    fn log_log_slope_of_a_power_law() {
        let points: Vec<(f64, f64)> = [1.5, 2.0, 3.0, 4.0]
            .iter()
            .map(|&a: &f64| (a, 3.8 * a.powf(0.73)))
            .collect();
        assert!((log_log_slope(&points) - 0.73).abs() < 1e-12);
    }
}
