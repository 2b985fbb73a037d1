//! Exact solutions for verification (METHOD.md section 6) and the error measures over particles
//! (METHOD.md section 4).

use rkmpm::error::Result;
use rkmpm::material::Material;
use rkmpm::options::{Integration, Shape, Side, Transfer, Wall};
use rkmpm::sim::Sim;
use rkmpm::UniformRng;
use rkmpm::{Matrix, Vector};
use std::f64::consts::PI;

/// The axis-aligned manufactured solution of Wallstedt & Guilkey (2008) for a compressible
/// neo-Hookean solid on the unit square (cube):
///
/// `u_a(X, t) = A sin(2π X_a) sin(c π t + a π)`, `c = sqrt(E/ρ0)`,
///
/// with slip walls on every face (`u_a = 0` where `X_a` is 0 or 1) and the body force
/// `b = ü − (1/ρ0) ∇_X·P` that makes it exact. `F` is diagonal:
/// `F_aa = 1 + 2πA cos(2π X_a) sin(cπt + aπ)`; in 2D plane strain (`F_33 = 1`).
///
/// With [`MmsWalls::FixedLowSlipHigh`] each component is also multiplied by `sin(π X_b / 2)` for
/// every other axis `b`: it vanishes on the fixed faces `X_b = 0` and is even about the slip
/// faces `X_b = 1`, so the mirror images of both wall kinds continue it smoothly (`F` is then
/// full, and the body force comes from the neo-Hookean elasticity tensor).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisAlignedMms {
    pub amplitude: f64,
    pub young: f64,
    pub poisson: f64,
    pub density: f64,
    pub walls: MmsWalls,
    /// The stopping rule of VC's solve in the runs ([`rkmpm::VcSolve`]); `None` for the
    /// engine's automatic rule ([`rkmpm::VcSolve::automatic`]).
    pub vc_solve: Option<rkmpm::VcSolve>,
}

/// The walls of the manufactured solution's box.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MmsWalls {
    /// Slip walls on every face: the published solution.
    #[default]
    Slip,
    /// Fixed (no-slip) walls on the low faces (`X_a = 0`), slip walls on the high faces (`X_a = 1`).
    FixedLowSlipHigh,
}

impl MmsWalls {
    /// The walls to give the grid: `(low, high)` on every axis.
    pub fn faces(&self) -> (Wall, Wall) {
        match self {
            MmsWalls::Slip => (Wall::Slip, Wall::Slip),
            MmsWalls::FixedLowSlipHigh => (Wall::Fixed, Wall::Slip),
        }
    }
}

impl Default for AxisAlignedMms {
    /// The published parameters: E = 1e7 Pa, ν = 0.3, ρ0 = 1000 kg/m³, A = 0.01 m.
    fn default() -> Self {
        AxisAlignedMms {
            amplitude: 0.01,
            young: 1e7,
            poisson: 0.3,
            density: 1000.0,
            walls: MmsWalls::Slip,
            vc_solve: None,
        }
    }
}

impl AxisAlignedMms {
    pub fn c(&self) -> f64 {
        (self.young / self.density).sqrt()
    }
    fn lame(&self) -> (f64, f64) {
        let (e, nu) = (self.young, self.poisson);
        (
            e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
            e / (2.0 * (1.0 + nu)),
        )
    }
    fn phase(&self, a: usize, t: f64) -> (f64, f64) {
        let w = self.c() * PI;
        let arg = w * t + a as f64 * PI;
        (arg.sin(), w * arg.cos())
    }
    /// The factor of component `c` along axis `b` and its first two derivatives at `x`: the
    /// published `sin(2π X_c)` along its own axis, and along the others 1 (slip walls) or
    /// `sin(π X_b / 2)` (fixed low faces).
    fn factor(&self, c: usize, b: usize, x: f64) -> [f64; 3] {
        let k = match (c == b, self.walls) {
            (true, _) => 2.0 * PI,
            (false, MmsWalls::Slip) => return [1.0, 0.0, 0.0],
            (false, MmsWalls::FixedLowSlipHigh) => 0.5 * PI,
        };
        let (s, co) = (k * x).sin_cos();
        [s, k * co, -k * k * s]
    }
    /// `∂^(d_0 + … ) u_c / ∂X_0^d_0 …` without its time factor and amplitude, for derivative
    /// orders `d` (each 0, 1 or 2).
    fn shape_derivative<const D: usize>(&self, c: usize, x: &Vector<D>, d: [usize; D]) -> f64 {
        (0..D).map(|b| self.factor(c, b, x[b])[d[b]]).product()
    }
    pub fn displacement<const D: usize>(&self, x: &Vector<D>, t: f64) -> Vector<D> {
        if self.walls != MmsWalls::Slip {
            return Vector::<D>::from_fn(|c, _| {
                self.amplitude * self.shape_derivative(c, x, [0; D]) * self.phase(c, t).0
            });
        }
        Vector::<D>::from_fn(|a, _| self.amplitude * (2.0 * PI * x[a]).sin() * self.phase(a, t).0)
    }
    pub fn velocity<const D: usize>(&self, x: &Vector<D>, t: f64) -> Vector<D> {
        if self.walls != MmsWalls::Slip {
            return Vector::<D>::from_fn(|c, _| {
                self.amplitude * self.shape_derivative(c, x, [0; D]) * self.phase(c, t).1
            });
        }
        Vector::<D>::from_fn(|a, _| self.amplitude * (2.0 * PI * x[a]).sin() * self.phase(a, t).1)
    }
    pub fn deformation_gradient<const D: usize>(&self, x: &Vector<D>, t: f64) -> Matrix<D> {
        if self.walls != MmsWalls::Slip {
            return Matrix::<D>::from_fn(|c, j| {
                let mut d = [0; D];
                d[j] = 1;
                let grad = self.amplitude * self.shape_derivative(c, x, d) * self.phase(c, t).0;
                grad + if c == j { 1.0 } else { 0.0 }
            });
        }
        Matrix::<D>::from_diagonal(&Vector::<D>::from_fn(|a, _| {
            1.0 + 2.0 * PI * self.amplitude * (2.0 * PI * x[a]).cos() * self.phase(a, t).0
        }))
    }
    /// Body force per unit mass at reference position `x` and time `t`.
    pub fn body_force<const D: usize>(&self, x: &Vector<D>, t: f64) -> Vector<D> {
        if self.walls != MmsWalls::Slip {
            return self.body_force_full(x, t);
        }
        let (lambda, mu) = self.lame();
        let f = self.deformation_gradient(x, t);
        let lnj = (0..D).map(|a| f[(a, a)]).product::<f64>().ln();
        let w = self.c() * PI;
        Vector::<D>::from_fn(|a, _| {
            let s = self.phase(a, t).0;
            let faa = f[(a, a)];
            let dfaa = -4.0 * PI * PI * self.amplitude * (2.0 * PI * x[a]).sin() * s;
            let dp = (mu * (1.0 + 1.0 / (faa * faa)) + lambda * (1.0 - lnj) / (faa * faa)) * dfaa;
            let acc = -w * w * self.amplitude * (2.0 * PI * x[a]).sin() * s;
            acc - dp / self.density
        })
    }
    /// The body force `ü − (1/ρ0) ∇_X·P` for a full `F`: with `G_j = ∂F/∂X_j`, the neo-Hookean
    /// `P = μ F + (λ ln J − μ) F⁻ᵀ` gives `∂P/∂X_j = μ G_j + λ tr(F⁻¹ G_j) F⁻ᵀ
    /// − (λ ln J − μ) F⁻ᵀ G_jᵀ F⁻ᵀ` (plane strain in 2D: `F_33 = 1`).
    fn body_force_full<const D: usize>(&self, x: &Vector<D>, t: f64) -> Vector<D> {
        let (lambda, mu) = self.lame();
        let f = self.deformation_gradient(x, t);
        let finv = f.try_inverse().expect("the manufactured F is invertible");
        let finv_t = finv.transpose();
        let lnj = rkmpm::determinant(&f).ln();
        let w = self.c() * PI;
        let mut div = Vector::<D>::zeros();
        for j in 0..D {
            // (G_j)_kl = ∂²u_k / ∂X_l ∂X_j
            let g = Matrix::<D>::from_fn(|k, l| {
                let mut d = [0; D];
                d[l] += 1;
                d[j] += 1;
                self.amplitude * self.shape_derivative(k, x, d) * self.phase(k, t).0
            });
            let dp = g * mu + finv_t * (lambda * (finv * g).trace())
                - finv_t * g.transpose() * finv_t * (lambda * lnj - mu);
            div += dp.column(j);
        }
        -self.displacement(x, t) * (w * w) - div / self.density
    }
}

/// Relative errors over particles: `sqrt(Σ|e|² V0 / Σ|exact|² V0)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Errors {
    /// Displacement, L2.
    pub l2: f64,
    /// Deformation gradient (`F − F_exact` against `F_exact − I`): the energy-norm measure.
    pub energy: f64,
}

/// A manufactured-solution run: grid cells per side, method, the errors at the end.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MmsRun {
    pub cells: usize,
    pub errors: Errors,
    pub steps: u64,
    pub seconds: f64,
}

/// Runs the manufactured solution on `cells` cells per side with 2 particles per cell per
/// direction at the two-point Gauss abscissae of each cell (equal weights `h/2`), `shape`, `integration`, `transfer`, to
/// `t_end` with `dt = cfl · h / c_max` of the initial state. The particle velocities start at the
/// exact velocity at `−Δt/2` (leapfrog-consistent for the symplectic update of the step).
pub fn run_mms<const D: usize>(
    mms: &AxisAlignedMms,
    cells: usize,
    shape: Shape,
    integration: Integration,
    transfer: Transfer,
    t_end: f64,
    cfl: f64,
) -> Result<MmsRun> {
    run_mms_with_particles::<D>(mms, cells, 2, shape, integration, transfer, t_end, cfl)
}

/// Gauss–Legendre abscissae on [0, 1] and weights (summing to 1) for 1 to 4 points.
fn gauss_rule(n: usize) -> Result<(Vec<f64>, Vec<f64>)> {
    let (x, w): (Vec<f64>, Vec<f64>) = match n {
        1 => (vec![0.0], vec![2.0]),
        2 => (vec![-1.0 / 3f64.sqrt(), 1.0 / 3f64.sqrt()], vec![1.0, 1.0]),
        3 => (
            vec![-(0.6f64).sqrt(), 0.0, 0.6f64.sqrt()],
            vec![5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0],
        ),
        4 => {
            let a = (3.0 / 7.0 - 2.0 / 7.0 * (1.2f64).sqrt()).sqrt();
            let b = (3.0 / 7.0 + 2.0 / 7.0 * (1.2f64).sqrt()).sqrt();
            let wa = (18.0 + 30f64.sqrt()) / 36.0;
            let wb = (18.0 - 30f64.sqrt()) / 36.0;
            (vec![-b, -a, a, b], vec![wb, wa, wa, wb])
        }
        _ => {
            return Err(rkmpm::Error::invalid(
                "particles per cell per direction must be 1 to 4",
            ))
        }
    };
    Ok((
        x.iter().map(|v| 0.5 * (v + 1.0)).collect(),
        w.iter().map(|v| 0.5 * v).collect(),
    ))
}

/// Where the particles of a manufactured-solution run sit inside each cell.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Placement {
    /// The `ppc`-point Gauss–Legendre abscissae per direction, the Gauss weights as volumes: the
    /// arrangement under which material-point integration is at its best.
    Gauss,
    /// The centres of `ppc` equal sub-cells per direction (the quarter points for `ppc = 2`),
    /// equal volumes: regular, but off the Gauss points.
    Uniform,
    /// [`Placement::Uniform`] with every particle moved by a uniform random amount of up to
    /// ±`fraction` of the particle spacing per direction (seeded, reproducible); equal volumes.
    Jittered { fraction: f64, seed: u64 },
}

impl Placement {
    /// The particles' reference positions and volumes on `cells` cells of size `h` per side,
    /// `ppc` per cell per direction, cell by cell in lexicographic order.
    pub fn particles<const D: usize>(
        &self,
        cells: usize,
        ppc: usize,
        h: f64,
    ) -> Result<(Vec<Vector<D>>, Vec<f64>)> {
        let (gx, gw) = match self {
            Placement::Gauss => gauss_rule(ppc)?,
            _ => {
                gauss_rule(ppc)?; // the same range of ppc
                let q = 1.0 / ppc as f64;
                (
                    (0..ppc).map(|i| (i as f64 + 0.5) * q).collect(),
                    vec![q; ppc],
                )
            }
        };
        let mut rng = match *self {
            Placement::Jittered { seed, .. } => Some(UniformRng::new(seed)),
            _ => None,
        };
        let fraction = match *self {
            Placement::Jittered { fraction, .. } => fraction,
            _ => 0.0,
        };
        let n = ppc * cells;
        let spacing = h / ppc as f64;
        let mut x = Vec::with_capacity(n.pow(D as u32));
        let mut vol = Vec::with_capacity(n.pow(D as u32));
        for k in 0..n.pow(D as u32) {
            let mut r = k;
            let mut v = 1.0;
            let mut site = Vector::<D>::from_fn(|_, _| {
                let i = r % n;
                r /= n;
                v *= gw[i % ppc] * h;
                ((i / ppc) as f64 + gx[i % ppc]) * h
            });
            if let Some(rng) = rng.as_mut() {
                for a in 0..D {
                    site[a] += (2.0 * rng.uniform() - 1.0) * fraction * spacing;
                }
            }
            x.push(site);
            vol.push(v);
        }
        Ok((x, vol))
    }
}

/// [`run_mms`] with `ppc` particles per cell per direction at the Gauss–Legendre points of each
/// cell, with the Gauss weights as volumes. With VC, the boundary points are the Gauss points of
/// the box's faces ([`unit_box_boundary`]).
#[allow(clippy::too_many_arguments)]
pub fn run_mms_with_particles<const D: usize>(
    mms: &AxisAlignedMms,
    cells: usize,
    ppc: usize,
    shape: Shape,
    integration: Integration,
    transfer: Transfer,
    t_end: f64,
    cfl: f64,
) -> Result<MmsRun> {
    run_mms_placed::<D>(
        mms,
        cells,
        ppc,
        Placement::Gauss,
        Surface::Exact,
        shape,
        integration,
        transfer,
        t_end,
        cfl,
    )
}

/// Where VC takes the body's surface from in a manufactured-solution run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Surface {
    /// The box's faces at their Gauss points ([`unit_box_boundary`]): exact.
    Exact,
    /// None given: the step finds it from the particles ([`rkmpm::BoundaryPoints::of_particles`]),
    /// as for a user who gives no boundary points.
    Found,
}

/// [`run_mms_with_particles`] with the particles placed by `placement` and VC's surface from
/// `surface`.
#[allow(clippy::too_many_arguments)]
pub fn run_mms_placed<const D: usize>(
    mms: &AxisAlignedMms,
    cells: usize,
    ppc: usize,
    placement: Placement,
    surface: Surface,
    shape: Shape,
    integration: Integration,
    transfer: Transfer,
    t_end: f64,
    cfl: f64,
) -> Result<MmsRun> {
    let h = 1.0 / cells as f64;
    let mut sim = Sim::<D>::new(Vector::<D>::zeros(), [cells; D], h)?;
    sim.set_shape(shape)?;
    sim.set_transfer(transfer)?;
    sim.set_integration(integration)?;
    if let Some(solve) = mms.vc_solve {
        sim.set_vc_solve(solve)?;
    }
    let (low, high) = mms.walls.faces();
    for a in 0..D {
        sim.set_wall(a, Side::Low, low)?;
        sim.set_wall(a, Side::High, high)?;
    }
    let mat = sim.add_material(Material::neo_hookean(mms.density, mms.young, mms.poisson)?);
    let (x, vol) = placement.particles::<D>(cells, ppc, h)?;
    let (lambda, mu) = mms.lame();
    let c_max = ((lambda + 2.0 * mu) / mms.density).sqrt() + mms.amplitude * 2.0 * PI * mms.c();
    let steps = (t_end / (cfl * h / c_max)).ceil() as usize;
    let dt = t_end / steps as f64;
    // Leapfrog-consistent start: the velocity half a step before t = 0.
    let v: Vec<Vector<D>> = x.iter().map(|p| mms.velocity(p, -0.5 * dt)).collect();
    sim.add_particles(mat, &x, &vol, Some(&v))?;
    if matches!(integration, Integration::Vc { .. }) && surface == Surface::Exact {
        let (bx, bn) = unit_box_boundary::<D>(cells, ppc)?;
        sim.add_boundary_points(&bx, &bn, None)?;
    }
    let m = *mms;
    sim.set_body_force(Some(Box::new(
        move |t: f64, x0: &[Vector<D>], _x: &[Vector<D>], out: &mut [Vector<D>]| {
            for (o, p) in out.iter_mut().zip(x0) {
                *o = m.body_force(p, t);
            }
            Ok(())
        },
    )));
    let start = std::time::Instant::now();
    for _ in 0..steps {
        sim.step(dt)?;
    }
    let seconds = start.elapsed().as_secs_f64();
    Ok(MmsRun {
        cells,
        errors: mms_errors(mms, &sim, t_end),
        steps: sim.steps(),
        seconds,
    })
}

/// The errors of `sim` against the manufactured solution at time `t`.
pub fn mms_errors<const D: usize>(mms: &AxisAlignedMms, sim: &Sim<D>, t: f64) -> Errors {
    let ps = sim.particles();
    let (mut e2, mut u2, mut f2, mut g2) = (0.0, 0.0, 0.0, 0.0);
    for p in 0..ps.len() {
        let x0 = ps.reference_position()[p];
        let v0 = ps.reference_volume()[p];
        let u = mms.displacement(&x0, t);
        let f = mms.deformation_gradient(&x0, t);
        e2 += (ps.position()[p] - x0 - u).norm_squared() * v0;
        u2 += u.norm_squared() * v0;
        f2 += (ps.deformation_gradient()[p] - f).norm_squared() * v0;
        g2 += (f - Matrix::<D>::identity()).norm_squared() * v0;
    }
    Errors {
        l2: (e2 / u2).sqrt(),
        energy: (f2 / g2).sqrt(),
    }
}

/// Least-squares slope of `log(error)` against `log(h)`.
pub fn fitted_slope(h: &[f64], error: &[f64]) -> f64 {
    let points: Vec<(f64, f64)> = h.iter().zip(error).map(|(h, e)| (h.ln(), e.ln())).collect();
    least_squares_line(&points).0
}

/// How long a method takes to reach an error, from its runs on a sequence of refining grids.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TimeToError {
    /// Reached between two grids: the run time interpolated on log-log axes between the last
    /// grid above the error and the first at or below it.
    Between(f64),
    /// Already at or below it on the coarsest grid: at most that grid's run time.
    AtMost(f64),
    /// No grid reached it: the smallest error over the grids.
    Never(f64),
}

/// The run time to reach the error `target`, from the `(error, seconds)` of one method's runs on
/// refining grids in order. Between the last grid above `target` and the first at or below it,
/// `log t` is interpolated linearly in `log error` (a run time of zero is taken as one
/// millisecond, the resolution of the records).
pub fn time_to_error(runs: &[(f64, f64)], target: f64) -> TimeToError {
    let Some(k) = runs.iter().position(|&(e, _)| e <= target) else {
        let best = runs.iter().map(|r| r.0).fold(f64::INFINITY, f64::min);
        return TimeToError::Never(best);
    };
    let seconds = |t: f64| t.max(1e-3);
    if k == 0 {
        return TimeToError::AtMost(seconds(runs[0].1));
    }
    let ((e0, t0), (e1, t1)) = (runs[k - 1], runs[k]);
    let (t0, t1) = (seconds(t0), seconds(t1));
    let s = (target.ln() - e0.ln()) / (e1.ln() - e0.ln());
    TimeToError::Between((t0.ln() + s * (t1.ln() - t0.ln())).exp())
}

/// The least-squares line `y = slope x + intercept` through `(x, y)` points: `(slope,
/// intercept)` (NaN with fewer than two distinct `x`).
pub fn least_squares_line(points: &[(f64, f64)]) -> (f64, f64) {
    let n = points.len() as f64;
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), (x, y)| (a + x / n, b + y / n));
    let (sxy, sxx) = points.iter().fold((0.0, 0.0), |(a, b), (x, y)| {
        (a + (x - mx) * (y - my), b + (x - mx).powi(2))
    });
    let slope = sxy / sxx;
    (slope, my - slope * mx)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The body force is `ü − ∇·P/ρ0`: checked against finite differences of the displacement
    /// in time and of the first Piola stress in space.
    #[test]
    fn body_force_balances_the_momentum_equation() {
        let mms = AxisAlignedMms::default();
        let piola = |x: &Vector<2>, t: f64| piola(&mms, &mms.deformation_gradient(x, t));
        let x = Vector::<2>::new(0.37, 0.81);
        let t = 0.0031;
        let (ht, hx) = (1e-6, 1e-5);
        let acc = (mms.displacement(&x, t + ht) - 2.0 * mms.displacement(&x, t)
            + mms.displacement(&x, t - ht))
            / (ht * ht);
        let mut div = Vector::<2>::zeros();
        for a in 0..2 {
            let mut e = Vector::<2>::zeros();
            e[a] = hx;
            let dp = (piola(&(x + e), t) - piola(&(x - e), t)) / (2.0 * hx);
            for i in 0..2 {
                div[i] += dp[(i, a)];
            }
        }
        let b = mms.body_force(&x, t);
        let expected = acc - div / mms.density;
        // FD truncation ~1e-10 relative of accelerations ~1e4.
        assert!(
            (b - expected).norm() < 1e-4 * expected.norm(),
            "{b} vs {expected}"
        );
        let v = (mms.displacement(&x, t + ht) - mms.displacement(&x, t - ht)) / (2.0 * ht);
        assert!((mms.velocity(&x, t) - v).norm() < 1e-6 * v.norm());
    }

    #[test]
    fn slope_of_exact_powers() {
        let h = [0.1, 0.05, 0.025];
        let e: Vec<f64> = h.iter().map(|v: &f64| 3.0 * v.powf(2.5)).collect();
        assert!((fitted_slope(&h, &e) - 2.5).abs() < 1e-12);
    }

    /// On log-log axes the interpolation is exact for a power law `t = c e^(−k)`; a target above
    /// the coarsest grid's error or below every grid's is said so.
    #[test]
    fn time_to_error_interpolates_a_power_law() {
        let runs: Vec<(f64, f64)> = [1e-2, 2.5e-3, 6.25e-4, 1.5625e-4]
            .iter()
            .map(|&e: &f64| (e, 3.0 * e.powf(-1.5)))
            .collect();
        let TimeToError::Between(t) = time_to_error(&runs, 1e-3) else {
            panic!("1e-3 lies between the second and third grids");
        };
        assert!((t / (3.0 * 1e-3f64.powf(-1.5)) - 1.0).abs() < 1e-12);
        assert_eq!(time_to_error(&runs, 2e-2), TimeToError::AtMost(runs[0].1));
        assert_eq!(time_to_error(&runs, 1e-4), TimeToError::Never(1.5625e-4));
        // A stalled method: the error stops falling above the target.
        let stalled = [(9e-3, 0.1), (6e-3, 1.0), (6.1e-3, 10.0)];
        assert_eq!(time_to_error(&stalled, 1e-3), TimeToError::Never(6e-3));
    }

    fn points<const D: usize>() -> Vec<Vector<D>> {
        let mut rng = UniformRng::new(7);
        (0..20)
            .map(|_| Vector::<D>::from_fn(|_, _| rng.uniform()))
            .collect()
    }

    /// With slip walls the full-`F` body force is the published diagonal one, to round-off
    /// (`1e-12` of its size; both sum about ten terms of size `μ A (2π)²`).
    fn full_body_force_is_the_diagonal_one_with_slip_walls<const D: usize>() {
        let mms = AxisAlignedMms::default();
        for (k, x) in points::<D>().iter().enumerate() {
            let t = 1e-3 * k as f64;
            let (b, full) = (mms.body_force(x, t), mms.body_force_full(x, t));
            assert!(
                (b - full).norm() <= 1e-12 * b.norm(),
                "{D}D: {b} against {full}"
            );
        }
    }

    #[test]
    fn full_body_force_is_the_diagonal_one_with_slip_walls_2d_3d() {
        full_body_force_is_the_diagonal_one_with_slip_walls::<2>();
        full_body_force_is_the_diagonal_one_with_slip_walls::<3>();
    }

    /// The neo-Hookean first Piola–Kirchhoff stress (plane strain in 2D).
    fn piola<const D: usize>(mms: &AxisAlignedMms, f: &Matrix<D>) -> Matrix<D> {
        let (lambda, mu) = mms.lame();
        let finv_t = f.try_inverse().unwrap().transpose();
        f * mu + finv_t * (lambda * rkmpm::determinant(f).ln() - mu)
    }

    /// Fixed low faces, slip high faces: the displacement vanishes on `X_a = 0`; on `X_a = 1`
    /// its normal component vanishes and the tangential ones are even (zero normal
    /// derivative); and the body force closes the momentum balance, checked against `∇·P`
    /// from fourth-order central differences of `P(F(X))` (step 1e-3: truncation about
    /// `1e-12 (2π)⁵ A μ`, round-off about `1e-16 μ / 1e-3`, both below 1e-8 of `ρ0 |b|`).
    fn mixed_walls_solution_is_exact<const D: usize>() {
        let mms = AxisAlignedMms {
            walls: MmsWalls::FixedLowSlipHigh,
            ..AxisAlignedMms::default()
        };
        let t = 3e-3;
        for x in points::<D>() {
            for a in 0..D {
                let (mut low, mut high) = (x, x);
                low[a] = 0.0;
                high[a] = 1.0;
                assert!(mms.displacement(&low, t).norm() < 1e-17, "{D}D at {low}");
                assert!(
                    mms.displacement(&high, t)[a].abs() < 1e-17,
                    "{D}D at {high}"
                );
                let f = mms.deformation_gradient(&high, t);
                for c in (0..D).filter(|&c| c != a) {
                    assert!(f[(c, a)].abs() < 1e-17, "{D}D ∂u_{c}/∂X_{a} at {high}");
                }
            }
            let delta = 1e-3;
            let mut div = Vector::<D>::zeros();
            for j in 0..D {
                let p = |s: f64| {
                    let mut y = x;
                    y[j] += s * delta;
                    piola(&mms, &mms.deformation_gradient(&y, t))
                };
                let dp = (p(-2.0) - p(-1.0) * 8.0 + p(1.0) * 8.0 - p(2.0)) / (12.0 * delta);
                div += dp.column(j);
            }
            let w = mms.c() * PI;
            let expected = -mms.displacement(&x, t) * (w * w) - div / mms.density;
            let b = mms.body_force(&x, t);
            assert!(
                (b - expected).norm() <= 1e-8 * b.norm(),
                "{D}D at {x}: {b} against {expected}"
            );
        }
    }

    #[test]
    fn mixed_walls_solution_is_exact_2d_3d() {
        mixed_walls_solution_is_exact::<2>();
        mixed_walls_solution_is_exact::<3>();
    }
}

/// An elastic column compressed under its own weight (METHOD.md 6.6), in plane strain between
/// slip walls, on a fixed floor: in equilibrium the vertical Cauchy stress at the material point
/// that started at height `Y` is `σ_yy = −ρ0 g (H − Y)` exactly, for any material and any
/// deformation (slip walls keep `F = diag(1, λ(Y))`, so `σ_yy = P_yy`).
///
/// Neo-Hookean, E = 1e5 Pa, ν = 0.3, ρ0 = 1000 kg/m³, H = 1 m, g = 10 m/s²: the bottom is compressed
/// by about 10%, so particles cross cells. Gravity ramps up over 2 s and is held for 1 s; PIC
/// damps the oscillations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SelfWeightColumn {
    pub height: f64,
    pub young: f64,
    pub poisson: f64,
    pub density: f64,
    pub gravity: f64,
    pub ramp: f64,
    pub hold: f64,
    /// Particles are moved from their lattice sites by up to `jitter` times the particle
    /// spacing in each direction (0 for a regular lattice); the boundary points stay on the
    /// lattice's faces.
    pub jitter: f64,
    /// `Some(n)`: a block `n` cells wide standing free on the floor, its sides free surfaces with
    /// empty cells beside them, instead of the column between slip walls. Its stress is not
    /// uniaxial, so the stress and pressure errors measure the column's solution against it:
    /// only its motion (settling) is meaningful.
    pub free_block: Option<usize>,
    /// With VC: `Some(k)` integrates over the surface VC finds from the particles, found anew
    /// every `k` steps (`Sim::set_vc_surface_refresh`), instead of the lattice's faces given as
    /// boundary points.
    pub found_surface: Option<u32>,
}

impl Default for SelfWeightColumn {
    fn default() -> Self {
        SelfWeightColumn {
            height: 1.0,
            young: 1e5,
            poisson: 0.3,
            density: 1000.0,
            gravity: 10.0,
            ramp: 2.0,
            hold: 1.0,
            jitter: 0.0,
            free_block: None,
            found_surface: None,
        }
    }
}

/// The largest of `values` over each window of `window` seconds from `start` on: `samples` are
/// `(time, value)` in time order; the last window may be partial.
pub fn window_maxima(samples: &[(f64, f64)], start: f64, window: f64) -> Vec<f64> {
    let mut maxima: Vec<f64> = Vec::new();
    for &(t, v) in samples.iter().filter(|s| s.0 >= start) {
        let k = ((t - start) / window) as usize;
        if maxima.len() <= k {
            maxima.resize(k + 1, f64::NEG_INFINITY);
        }
        maxima[k] = maxima[k].max(v);
    }
    maxima
}

/// The result of a column run.
#[derive(Debug, Clone, PartialEq)]
pub struct ColumnRun {
    pub cells: usize,
    /// `sqrt(Σ (σ_yy − exact)² V0 / Σ exact² V0)` over all particles.
    pub stress_error: f64,
    /// The same for the pressure `−tr(σ)/3` against the exact pressure.
    pub pressure_error: f64,
    pub seconds: f64,
    /// Reference height, σ_yy and pressure of the particles of one vertical line of particles.
    pub profile: Vec<(f64, f64, f64)>,
}

impl SelfWeightColumn {
    /// Exact pressure at the material point that started at height `y0`: the stretch `λ` solves
    /// `σ_yy(λ) = μ (λ² − 1)/λ + Λ ln λ / λ = −ρ0 g (H − y0)` (Newton), then
    /// `σ_xx = σ_zz = Λ ln λ / λ` and `p = −(2 σ_xx + σ_yy)/3`.
    pub fn exact_pressure(&self, y0: f64) -> f64 {
        let c = rkmpm::material::ElasticConstants::new(self.density, self.young, self.poisson)
            .expect("valid constants");
        let target = -self.density * self.gravity * (self.height - y0);
        let mut l = 1.0f64;
        for _ in 0..50 {
            let f = c.mu * (l * l - 1.0) / l + c.lambda * l.ln() / l - target;
            let df = c.mu * (1.0 + 1.0 / (l * l)) + c.lambda * (1.0 - l.ln()) / (l * l);
            let step = f / df;
            l -= step;
            if step.abs() < 1e-15 {
                break;
            }
        }
        let sxx = c.lambda * l.ln() / l;
        -(2.0 * sxx + target) / 3.0
    }

    /// Runs the column with `cells` cells over its height, 2 particles per cell per direction. The
    /// column is as many cells wide as the shape function has ghost layers (at least 2), since the
    /// mirrored side walls need that many.
    pub fn run(
        &self,
        cells: usize,
        shape: Shape,
        integration: Integration,
        transfer: Transfer,
    ) -> Result<ColumnRun> {
        self.run_observed(cells, shape, integration, transfer, |_| Ok(()), |_| {})
    }

    /// [`SelfWeightColumn::run`] with `setup` called on the simulation before its first step
    /// (options the arguments do not name) and `observe` after every step.
    pub fn run_observed(
        &self,
        cells: usize,
        shape: Shape,
        integration: Integration,
        transfer: Transfer,
        setup: impl FnOnce(&mut Sim<2>) -> Result<()>,
        mut observe: impl FnMut(&Sim<2>),
    ) -> Result<ColumnRun> {
        let h = self.height / cells as f64;
        let ghosts = shape.build::<2>()?.ghost_layers();
        // A free block has 2 empty cells on each side (it bulges by about 3 % of its height).
        let (width, margin) = match self.free_block {
            Some(n) => (n, 2),
            None => (ghosts.max(2), 0),
        };
        let mut sim = Sim::<2>::new(
            Vector::<2>::new(-(margin as f64) * h, 0.0),
            [width + 2 * margin, cells + 2],
            h,
        )?;
        sim.set_shape(shape)?;
        sim.set_transfer(transfer)?;
        sim.set_integration(integration)?;
        if self.free_block.is_none() {
            sim.set_wall(0, Side::Low, Wall::Slip)?;
            sim.set_wall(0, Side::High, Wall::Slip)?;
        }
        sim.set_wall(1, Side::Low, Wall::Fixed)?;
        let mat = sim.add_material(Material::neo_hookean(
            self.density,
            self.young,
            self.poisson,
        )?);
        let q = h / 2.0;
        let mut sites = Vec::new();
        for j in 0..2 * cells {
            for i in 0..2 * width {
                sites.push(Vector::<2>::new((i as f64 + 0.5) * q, (j as f64 + 0.5) * q));
            }
        }
        let mut rng = rkmpm::UniformRng::new(17);
        let x: Vec<Vector<2>> = sites
            .iter()
            .map(|p| p + Vector::<2>::from_fn(|_, _| (2.0 * rng.uniform() - 1.0) * self.jitter * q))
            .collect();
        let vol = vec![q * q; x.len()];
        sim.add_particles(mat, &x, &vol, None)?;
        match self.found_surface {
            Some(refresh) => sim.set_vc_surface_refresh(refresh)?,
            None if matches!(integration, Integration::Vc { .. }) => {
                let (bx, bn) = rkmpm::BoundaryPoints::<2>::from_lattice(&sites, &vol);
                sim.add_boundary_points(&bx, &bn, None)?;
            }
            None => {}
        }
        setup(&mut sim)?;
        let dt = sim.stable_dt(0.3)? * 0.9;
        let t_end = self.ramp + self.hold;
        let steps = (t_end / dt).ceil() as usize;
        let dt = t_end / steps as f64;
        let start = std::time::Instant::now();
        for _ in 0..steps {
            let ramp = (sim.time() / self.ramp).min(1.0);
            sim.set_gravity([0.0, -self.gravity * ramp])?;
            sim.step(dt)?;
            observe(&sim);
        }
        let seconds = start.elapsed().as_secs_f64();
        let ps = sim.particles();
        let (mut e2, mut s2, mut pe2, mut p2) = (0.0, 0.0, 0.0, 0.0);
        let mut profile = Vec::new();
        for p in 0..ps.len() {
            let y0 = ps.reference_position()[p][1];
            let v0 = ps.reference_volume()[p];
            let exact = -self.density * self.gravity * (self.height - y0);
            let s = ps.stress()[p][(1, 1)];
            e2 += (s - exact).powi(2) * v0;
            s2 += exact * exact * v0;
            let pex = self.exact_pressure(y0);
            pe2 += (ps.pressure()[p] - pex).powi(2) * v0;
            p2 += pex * pex * v0;
            if p % (2 * width) == width {
                profile.push((y0, s, ps.pressure()[p]));
            }
        }
        Ok(ColumnRun {
            cells,
            stress_error: (e2 / s2).sqrt(),
            pressure_error: (pe2 / p2).sqrt(),
            seconds,
            profile,
        })
    }
}

/// Boundary points on the faces of the box `[0, 1]^D` at the `ppc`-point Gauss–Legendre points
/// of each cell face, with the Gauss weights as areas: an exact surface quadrature for VC.
pub fn unit_box_boundary<const D: usize>(
    cells: usize,
    ppc: usize,
) -> Result<(Vec<Vector<D>>, Vec<Vector<D>>)> {
    let h = 1.0 / cells as f64;
    let (gx, gw) = gauss_rule(ppc)?;
    let n = ppc * cells;
    let (mut x, mut na) = (Vec::new(), Vec::new());
    for axis in 0..D {
        for (side, normal) in [(0.0, -1.0), (1.0, 1.0)] {
            for k in 0..n.pow(D as u32 - 1) {
                let mut r = k;
                let mut area = 1.0;
                let p = Vector::<D>::from_fn(|a, _| {
                    if a == axis {
                        return side;
                    }
                    let i = r % n;
                    r /= n;
                    area *= gw[i % ppc] * h;
                    ((i / ppc) as f64 + gx[i % ppc]) * h
                });
                let mut nv = Vector::<D>::zeros();
                nv[axis] = normal * area;
                x.push(p);
                na.push(nv);
            }
        }
    }
    Ok((x, na))
}

#[cfg(test)]
mod box_tests {
    use super::*;

    /// The face quadrature integrates the closed surface exactly: normals sum to zero, areas to 2D.
    #[test]
    fn unit_box_boundary_is_a_closed_surface() {
        for ppc in 1..=4 {
            let (x, na) = unit_box_boundary::<3>(3, ppc).unwrap();
            assert_eq!(x.len(), 6 * (3 * ppc) * (3 * ppc));
            assert!(na.iter().sum::<Vector<3>>().norm() < 1e-13);
            let area: f64 = na.iter().map(|n| n.norm()).sum();
            assert!((area - 6.0).abs() < 1e-12, "{area}");
        }
    }
}
