//! The simulation: grid, options, materials, particles, and the safe API that the C layer wraps.

mod stepping;
mod timestep;

pub use timestep::{Progress, DEFAULT_MAX_STEPS_PER_ADVANCE};

/// Every how many steps VC finds the surface of the particles anew by default
/// ([`Sim::set_vc_surface_refresh`]).
pub const DEFAULT_VC_SURFACE_REFRESH: u32 = 4;

use crate::energy::EnergyLedger;
use crate::error::{check_finite, check_positive, Error, ErrorKind, Result};
use crate::grid::Grid;
use crate::integration::{carried_sweeps_for, BoundaryPoints, VcCorrection};
use crate::material::{Constitutive, Material};
use crate::options::{FastPaths, Shape, Side, Wall};
pub use crate::options::{Integration, Options, Scheme, Transfer};
use crate::particles::{Field, Particles};
use crate::shape::ShapeFunction;
use crate::step::Workspace;
use crate::{Matrix, Vector};
use rayon::prelude::*;

/// A body-force field, evaluated once per step for all particles at once.
///
/// `accelerations(time, reference, current, out)` writes the body force per unit mass (an
/// acceleration, added to gravity) of every particle into `out`; an `Err` stops the step.
///
/// [`Sim::step`] calls it on the thread that calls `step`, before the rest of the step runs on
/// rayon's threads; it is `Send` so that a `Sim` is (and can be stepped from the pool).
pub trait BodyForce<const D: usize>: Send {
    fn accelerations(
        &mut self,
        time: f64,
        reference_positions: &[Vector<D>],
        positions: &[Vector<D>],
        out: &mut [Vector<D>],
    ) -> std::result::Result<(), String>;
}

impl<const D: usize, F> BodyForce<D> for F
where
    F: FnMut(f64, &[Vector<D>], &[Vector<D>], &mut [Vector<D>]) -> std::result::Result<(), String>
        + Send,
{
    fn accelerations(
        &mut self,
        time: f64,
        reference_positions: &[Vector<D>],
        positions: &[Vector<D>],
        out: &mut [Vector<D>],
    ) -> std::result::Result<(), String> {
        self(time, reference_positions, positions, out)
    }
}

/// The energies of the particles at one instant (per unit thickness in 2D).
///
/// What they do not hold is what the run dissipated or was given: plastic work and damage,
/// friction and impacts at walls, contact between bodies, the numerical dissipation of the
/// transfer (PIC above all) and of the time integration, and the work of a body-force callback
/// (a potential is known for gravity only). The change of [`Energies::total`] over a run is their
/// sum.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Energies {
    /// `½ Σ m_p |v_p|²`.
    pub kinetic: f64,
    /// `Σ V0_p W(F_p)`: the stored (elastic) energy of every material.
    pub stored: f64,
    /// `−Σ m_p g·x_p`: the potential of today's gravity `g`, zero at the coordinates' origin.
    pub gravitational: f64,
}

impl Energies {
    /// Kinetic + stored + gravitational.
    pub fn total(&self) -> f64 {
        self.kinetic + self.stored + self.gravitational
    }
}

/// Where a run's energy went, since the accounting started ([`Sim::set_energy_accounting`];
/// per unit thickness in 2D). The balance
///
/// ```text
/// now.total() = start + external_work − material_dissipation − friction_dissipation
///               − contact_dissipation − other_dissipation
/// ```
///
/// holds by the definition of `other_dissipation`, which is what no term measured on its own
/// holds: the normal loss of impacts (on walls and between bodies in contact) and the scheme's
/// numerical dissipation (the transfer's, PIC above all, and the time integration's; for a
/// body in free fall `½ M |g|² Δt²` per step).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EnergyBalance {
    /// The energies now.
    pub now: Energies,
    /// The total energy when the accounting started, plus what the caller gave since:
    /// particles added, a rigid body's velocity or gravity changed.
    pub start: f64,
    /// The work of the body-force callback and of the boundary points' tractions.
    pub external_work: f64,
    /// The work of the stresses, `Σ V0 ½(Pⁿ + Pⁿ⁺¹) : (Fⁿ⁺¹ − Fⁿ)` over the steps.
    pub stress_work: f64,
    /// The stress work less the change of the stored energy: what plasticity and damage
    /// dissipated (for an elastic material, the trapezoidal rule's error, `O(Δt²)` over a run).
    pub material_dissipation: f64,
    /// The friction walls' work on the slip: `Σ m_I (v_I − v_I*)·v_I*` over the nodes they
    /// changed (`v*` the velocity they leave) and the steps. Its normal part is zero: the normal
    /// loss of an impact on the wall is in `other_dissipation`.
    pub friction_dissipation: f64,
    /// The same sum for the contact correction, over the deformable bodies' fields at the nodes
    /// bodies share: the contact friction's work on the slip (the normal impulses balance and
    /// leave equal normal velocities, so frictionless contact counts 0 to round-off), less the
    /// work of a rigid body pushing one.
    pub contact_dissipation: f64,
    /// The rest: impacts (on walls and between bodies) and the scheme (see the type's
    /// documentation).
    pub other_dissipation: f64,
}

/// The particles' momenta at one instant (per unit thickness in 2D).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Momenta<const D: usize> {
    /// `Σ m_p v_p`.
    pub linear: Vector<D>,
    /// `Σ m_p x_p × v_p` about the origin, as a 3D vector (in 2D only its third component is
    /// not zero), plus, under APIC and MLS with a B-spline or RK1 with ã = 2, the angular momentum the
    /// particles' affine velocities carry (Jiang et al. 2015): `Σ m_p d ε : C_p` with the
    /// weights' inertia `D_p = d I` (`d = h²/4` quadratic, `h²/3` cubic and RK1 with ã = 2), that is
    /// `m d (C_zy − C_yz, C_xz − C_zx, C_yx − C_xy)`. That total is what the transfers
    /// conserve. With shape functions whose inertia is not a multiple of the identity (linear
    /// hats, RK) `C_p` is the velocity gradient and its part is left out.
    pub angular: nalgebra::Vector3<f64>,
}

/// An explicit MPM simulation in `D` dimensions (2 or 3).
pub struct Sim<const D: usize> {
    pub(crate) grid: Grid<D>,
    pub(crate) options: Options<D>,
    pub(crate) shape: Box<dyn ShapeFunction<D>>,
    pub(crate) materials: Vec<Material>,
    pub(crate) particles: Particles<D>,
    pub(crate) body_force: Option<Box<dyn BodyForce<D>>>,
    pub(crate) boundary: BoundaryPoints<D>,
    /// The surface VC found from the particles (when no boundary points are given): as found
    /// for the last step, or carried by the grid since ([`Sim::set_vc_surface_refresh`]).
    pub(crate) surface: BoundaryPoints<D>,
    /// Steps the surface has been carried since it was found (`u32::MAX`: to be found anew).
    pub(crate) surface_age: u32,
    /// The found surface is found anew at least every this many steps.
    pub(crate) vc_surface_refresh: u32,
    pub(crate) vc: Option<VcCorrection<D>>,
    /// Whether VC of order 1 subtracts the particles' linear fit ([`Sim::set_vc_linear_fit`]).
    vc_linear_fit: bool,
    /// The stopping rule of VC's solve given to [`Sim::set_vc_solve`]; `None` for
    /// [`crate::VcSolve::automatic`].
    vc_solve: Option<crate::VcSolve>,
    pub(crate) time: f64,
    pub(crate) steps: u64,
    pub(crate) work: Workspace<D>,
    pub(crate) fast_paths: FastPaths,
    /// What the steps did to the energy, when the accounting is on.
    pub(crate) energy: EnergyLedger,
    /// The bound on the steps of one adaptive run ([`Sim::set_max_steps_per_advance`]): a
    /// setting of the caller's run, like the fast paths and the body force, so not part of a
    /// checkpoint (a loaded simulation has the default).
    pub(crate) max_steps_per_advance: u64,
    /// The simulation's own worker threads ([`Sim::set_threads`]); `None`: rayon's global pool.
    /// A setting of the caller's process, not part of a checkpoint.
    pub(crate) threads: Option<std::sync::Arc<rayon::ThreadPool>>,
}

/// The most worker threads [`Sim::set_threads`] starts for one simulation.
pub const MAX_THREADS: usize = 4096;

impl<const D: usize> Sim<D> {
    /// A simulation on a grid of `cells` cells of size `cell_size` from `origin`, with the default
    /// options, no materials and no particles.
    pub fn new(origin: impl Into<Vector<D>>, cells: [usize; D], cell_size: f64) -> Result<Self> {
        if D != 2 && D != 3 {
            return Err(Error::invalid(format!("dimension must be 2 or 3, got {D}")));
        }
        let mut grid = Grid::new(origin.into(), cells, cell_size)?;
        let options = Options::default();
        let shape = options.shape.build::<D>()?;
        grid.set_ghost_layers(shape.ghost_layers())?;
        Ok(Sim {
            grid,
            options,
            shape,
            materials: Vec::new(),
            particles: Particles::default(),
            body_force: None,
            boundary: BoundaryPoints::default(),
            surface: BoundaryPoints::default(),
            surface_age: u32::MAX,
            vc_surface_refresh: DEFAULT_VC_SURFACE_REFRESH,
            vc: None,
            vc_linear_fit: false,
            vc_solve: None,
            time: 0.0,
            steps: 0,
            work: Workspace::default(),
            fast_paths: FastPaths::default(),
            energy: EnergyLedger::default(),
            max_steps_per_advance: DEFAULT_MAX_STEPS_PER_ADVANCE,
            threads: None,
        })
    }

    fn before_stepping(&self, what: &str) -> Result<()> {
        if self.steps > 0 {
            Err(Error::state(format!(
                "{what} can only be changed before the first step (this simulation has taken {})",
                self.steps
            )))
        } else {
            Ok(())
        }
    }

    /// Wall-clock seconds spent in each phase of the steps so far (benchmarks, tuning).
    ///
    /// ```
    /// # use rkmpm::{Material, Sim};
    /// let mut sim = Sim::<2>::new([0.0, 0.0], [8, 8], 0.125).unwrap();
    /// let m = sim.add_material(Material::linear_elastic(1000.0, 1e6, 0.3).unwrap());
    /// sim.add_particles(m, &[[0.5, 0.5].into()], &[1e-3], None).unwrap();
    /// sim.step(sim.stable_dt(0.3).unwrap()).unwrap();
    /// let times: rkmpm::PhaseTimes = sim.phase_times();
    /// let memory: rkmpm::MemoryUse = sim.memory();
    /// assert!(times.shape >= 0.0 && memory.particles > 0);
    /// ```
    pub fn phase_times(&self) -> crate::step::PhaseTimes {
        self.work.times
    }

    /// Bytes this simulation holds: particles, per-particle step storage and grid nodes (see
    /// `BENCHMARKS.md` for the figures).
    pub fn memory(&self) -> crate::step::MemoryUse {
        use crate::step::profile_bytes as bytes;
        let w = &self.work;
        crate::step::MemoryUse {
            particles: self.particles.bytes(),
            particle_workspace: w.stencils.bytes()
                + w.linear.bytes()
                + w.quadratic.bytes()
                + w.cubic.bytes()
                + w.bins.bytes()
                + bytes(&w.volumes)
                + w.new_state.bytes()
                + w.spare.bytes()
                + bytes(&w.admissible),
            grid: w.nodes.bytes() + w.bodies.nodes.iter().map(|b| b.bytes()).sum::<usize>(),
            active_nodes: w.active_nodes,
            particle_count: self.particles.len(),
            node_count: self.grid.node_count(),
        }
    }

    /// Chooses the step's fast paths ([`FastPaths`]; all on by default). Off, a path gives the
    /// same physics by the plain route: the same bits without vector instructions; node sums
    /// taken in another order (round-off) with stored stencils or without particle sorting.
    /// Any time, also between steps.
    pub fn set_fast_paths(&mut self, paths: FastPaths) {
        self.fast_paths = paths;
    }

    /// The step's fast paths.
    pub fn fast_paths(&self) -> FastPaths {
        self.fast_paths
    }

    /// Gives the simulation its own `threads` worker threads (0: one per core the process may
    /// use, `std::thread::available_parallelism`), on which its steps and its other parallel
    /// passes run, whatever other simulations or the host's threads do. Until this is called a
    /// simulation runs on rayon's global pool (`RAYON_NUM_THREADS` threads, or one per core),
    /// shared by every simulation of the process. Results are the same to the last bit for any
    /// count. Any time, also between steps; a setting of the caller's process, not saved in a
    /// checkpoint (a loaded simulation runs on the global pool). Refuses more than
    /// [`MAX_THREADS`]; a pool the system cannot start (`OutOfMemory`) changes nothing.
    pub fn set_threads(&mut self, threads: usize) -> Result<()> {
        if threads > MAX_THREADS {
            return Err(Error::invalid(format!(
                "threads must be at most {MAX_THREADS} (0 for one per core), got {threads}"
            )));
        }
        let count = match threads {
            0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
            n => n,
        };
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(count)
            .thread_name(|i| format!("rkmpm-{i}"))
            .build()
            .map_err(|e| {
                Error::new(
                    ErrorKind::OutOfMemory,
                    format!("cannot start {count} worker threads: {e}"),
                )
            })?;
        self.threads = Some(std::sync::Arc::new(pool));
        Ok(())
    }

    /// The number of worker threads the simulation's steps run on ([`Sim::set_threads`], or the
    /// size of rayon's global pool).
    pub fn threads(&self) -> usize {
        self.on_threads(rayon::current_num_threads)
    }

    /// Runs `work` on the simulation's worker threads: its own pool, or the pool of the caller
    /// (rayon's global pool outside any).
    pub(crate) fn on_threads<R: Send>(&self, work: impl FnOnce() -> R + Send) -> R {
        match &self.threads {
            Some(pool) => pool.install(work),
            None => work(),
        }
    }

    /// Bounds the steps one [`Sim::advance`] may take (at least 1; default
    /// [`DEFAULT_MAX_STEPS_PER_ADVANCE`], 10^9): a run whose estimate exceeds it is refused
    /// before its first step, and a run whose stable step shrinks on the way stops there. Raise
    /// it for a run that is meant to be that long; a host that wants to stop a run by its own
    /// measure does so from the progress callback ([`Sim::advance_observed`]). Any time, also
    /// between steps; a setting of the run, not saved in a checkpoint.
    pub fn set_max_steps_per_advance(&mut self, max_steps: u64) -> Result<()> {
        if max_steps == 0 {
            return Err(Error::invalid(
                "max_steps_per_advance must be at least 1, got 0",
            ));
        }
        self.max_steps_per_advance = max_steps;
        Ok(())
    }

    /// The bound on the steps of one [`Sim::advance`] ([`Sim::set_max_steps_per_advance`]).
    pub fn max_steps_per_advance(&self) -> u64 {
        self.max_steps_per_advance
    }

    /// Chooses the shape function. Before stepping only.
    pub fn set_shape(&mut self, shape: Shape) -> Result<()> {
        self.before_stepping("the shape function")?;
        let f = shape.build::<D>()?;
        let mut grid = self.grid.clone();
        grid.set_ghost_layers(f.ghost_layers())?;
        self.grid = grid;
        self.shape = f;
        self.options.shape = shape;
        if let Some(vc) = &mut self.vc {
            vc.linear_fit = self.vc_linear_fit && shape.vc_linear_fit();
        }
        // The automatic rule depends on the shape functions' kind.
        self.apply_vc_solve();
        Ok(())
    }

    /// Chooses the integration. Before stepping only.
    pub fn set_integration(&mut self, integration: Integration) -> Result<()> {
        self.before_stepping("the integration")?;
        self.vc = match integration {
            Integration::MaterialPoint => None,
            Integration::Vc { order } => {
                let mut vc = VcCorrection::new(order)?;
                vc.linear_fit = self.vc_linear_fit && self.options.shape.vc_linear_fit();
                Some(vc)
            }
        };
        self.options.integration = integration;
        self.apply_vc_solve();
        Ok(())
    }

    /// **Experimental.** Whether VC of order 1 corrects with each particle's weighted linear fit
    /// of the node coefficients instead of their mean (off by default; before stepping only;
    /// not kept by checkpoints). With the shapes that allow it ([`Shape::vc_linear_fit`]: the
    /// cubic B-spline, RK of support ≥ 2) each particle's correction then has no first moment
    /// and exerts no torque on its own (with the mean, every step removes the internal forces'
    /// torque per body instead: angular momentum is conserved with APIC either way, METHOD.md
    /// section 3). The default scene's colliding disks (RK1 + VC1) lose energy with it as with the
    /// mean, 2.54 to 1.98 J/m (mean: 1.98). It is off by default until the convergence study
    /// has been rerun with it and its cost measured: its solve takes 40–110 iterations a step
    /// where the mean's takes about 12 (docs/METHOD.md, section 3).
    pub fn set_vc_linear_fit(&mut self, on: bool) -> Result<()> {
        self.before_stepping("the VC fit")?;
        self.vc_linear_fit = on;
        let shape = self.options.shape;
        if let Some(vc) = &mut self.vc {
            vc.linear_fit = on && shape.vc_linear_fit();
        }
        Ok(())
    }

    /// The rule of VC's conservative solve (kept by checkpoints, with the coefficients carried
    /// between solves). Unless given one, a simulation takes [`crate::VcSolve::automatic`] for
    /// its VC order, grid and shape functions: at order 1 a residual of 1e-4 of the right-hand
    /// side's, solved every fourth step with RK shape functions to 128 cells across, every
    /// second with the B-splines to 64, halved with every doubling of the grid beyond
    /// ([`crate::VcSolve::interval_for`]), and at every step with linear hats; at order ≥ 2 1e-4
    /// on grids of up to 32 cells across, falling as `(32 / N)^3` on wider ones, at every step.
    /// Linear and angular momentum are conserved whatever the rule; a looser rule meets the divergence equalities less exactly and costs less
    /// (docs/convergence/FINDINGS.md, "The VC solve's stopping rule"). Refuses a tolerance
    /// outside `(0, 1]`, zero iterations and an interval of zero steps.
    pub fn set_vc_solve(&mut self, solve: crate::VcSolve) -> Result<()> {
        solve.check()?;
        self.vc_solve = Some(solve);
        self.apply_vc_solve();
        Ok(())
    }

    /// VC of order 1 whose solve runs every `interval` steps, the rest of the rule in force
    /// kept (the tests of the coefficients carried between solves).
    #[cfg(test)]
    pub(crate) fn set_vc1_every(&mut self, interval: u32) {
        self.set_integration(crate::Integration::Vc { order: 1 })
            .unwrap();
        let solve = crate::VcSolve {
            interval,
            ..self.vc_solve()
        };
        self.set_vc_solve(solve).unwrap();
    }

    /// Returns to the rule a simulation takes unless given one ([`crate::VcSolve::automatic`]).
    pub fn set_vc_solve_automatic(&mut self) {
        self.vc_solve = None;
        self.apply_vc_solve();
    }

    /// Hands the rule in force, and the sweeps between solves of the shape functions, to the
    /// correction.
    fn apply_vc_solve(&mut self) {
        let solve = self.vc_solve();
        let sweeps = carried_sweeps_for(self.options.shape.kind());
        if let Some(vc) = &mut self.vc {
            vc.solve = solve;
            vc.carried_sweeps = sweeps;
        }
    }

    /// The stopping rule of VC's solve in force ([`Sim::set_vc_solve`]): the one given, or the
    /// automatic rule for the simulation's VC order (order 1 without VC) and grid.
    pub fn vc_solve(&self) -> crate::VcSolve {
        let order = self.vc.as_ref().map_or(1, |vc| vc.order);
        let shape = self.options.shape.kind();
        self.vc_solve
            .unwrap_or_else(|| crate::VcSolve::automatic(order, self.grid.cells_across(), shape))
    }

    /// Whether the solve follows the automatic rule (no rule given, [`Sim::set_vc_solve`]).
    pub fn vc_solve_is_automatic(&self) -> bool {
        self.vc_solve.is_none()
    }

    /// Chooses the velocity transfer. Before stepping only.
    pub fn set_transfer(&mut self, transfer: Transfer) -> Result<()> {
        self.before_stepping("the transfer")?;
        if let Transfer::PicFlip { flip } = transfer {
            if !(0.0..=1.0).contains(&flip) {
                return Err(Error::invalid(format!(
                    "flip_ratio must lie in [0, 1], got {flip}"
                )));
            }
        }
        self.options.transfer = transfer;
        // Affine matrices exist only under APIC and MLS.
        if transfer.is_affine() {
            self.particles
                .affine
                .resize(self.particles.len(), Matrix::<D>::zeros());
        } else {
            self.particles.affine = Vec::new();
        }
        Ok(())
    }

    /// Turns on contact between bodies (every material is a body with its own velocity field;
    /// Bardenhagen et al. 2000, docs/DESIGN.md) with Coulomb friction `friction ≥ 0`, or off
    /// with `None`. Before stepping only; not with given boundary points or MUSL. With VC each deformable body gets
    /// its own correction, over its own particles and the surface found from them.
    pub fn set_contact(&mut self, friction: Option<f64>) -> Result<()> {
        self.before_stepping("contact")?;
        if let Some(mu) = friction {
            check_finite("friction", mu)?;
            if mu < 0.0 {
                return Err(Error::invalid(format!("friction must be >= 0, got {mu}")));
            }
        }
        self.options.contact = friction.map(|friction| crate::options::Contact { friction });
        Ok(())
    }

    /// Chooses USL or MUSL. Before stepping only.
    pub fn set_scheme(&mut self, scheme: Scheme) -> Result<()> {
        self.before_stepping("the scheme")?;
        self.options.scheme = scheme;
        Ok(())
    }

    /// Sets gravity (an acceleration); may change between steps.
    pub fn set_gravity(&mut self, g: impl Into<Vector<D>>) -> Result<()> {
        let g = g.into();
        for a in 0..D {
            check_finite("gravity", g[a])?;
        }
        if self.energy.on {
            // The potential changes with `g`; the ledger counts the jump as given.
            let ps = &self.particles;
            let dg = g - self.options.gravity;
            let jump: f64 = ps
                .mass
                .iter()
                .zip(&ps.position)
                .map(|(m, x)| m * dg.dot(x))
                .sum();
            self.energy.start -= jump;
        }
        self.options.gravity = g;
        Ok(())
    }

    /// Sets the wall on one face of the grid; may change between steps.
    pub fn set_wall(&mut self, axis: usize, side: Side, wall: Wall) -> Result<()> {
        if axis >= D {
            return Err(Error::invalid(format!(
                "axis must be below the dimension {D}, got {axis}"
            )));
        }
        wall.validate()?;
        self.options.walls.faces[axis][side as usize] = wall;
        Ok(())
    }

    /// The old name of [`Sim::set_wall`].
    #[deprecated(note = "renamed to `set_wall`")]
    pub fn set_boundary(&mut self, axis: usize, side: Side, wall: Wall) -> Result<()> {
        self.set_wall(axis, side, wall)
    }

    /// Sets (or with `None` removes) the body-force field.
    pub fn set_body_force(&mut self, body_force: Option<Box<dyn BodyForce<D>>>) {
        self.body_force = body_force;
    }

    /// Adds boundary points (surface quadrature points for VC integration and tractions):
    /// positions on the surface, outward normals times area (length in 2D), and tractions (force
    /// per current area) or `None`. All or nothing. They move with the grid (Nanson for the
    /// normals). Without any, VC finds the surface of the particles itself
    /// ([`BoundaryPoints::of_particles`], [`Sim::vc_surface`], [`Sim::set_vc_surface_refresh`]).
    pub fn add_boundary_points(
        &mut self,
        positions: &[Vector<D>],
        area_normals: &[Vector<D>],
        tractions: Option<&[Vector<D>]>,
    ) -> Result<()> {
        if let Some(p) = positions
            .iter()
            .position(|x| x.iter().any(|c| !c.is_finite()))
        {
            return Err(Error::invalid(format!(
                "position of boundary point {p} is not finite"
            )));
        }
        if let Some(p) = positions.iter().position(|x| !self.grid.contains(x)) {
            return Err(Error::new(
                ErrorKind::OutsideGrid,
                format!("boundary point {p} lies outside the grid domain"),
            ));
        }
        self.boundary.add(positions, area_normals, tractions)
    }

    /// How often VC finds the surface of the particles anew (when no boundary points are given,
    /// without contact): every `steps` steps, the grid carrying it between like given boundary
    /// points (positions with the grid velocity, `n a` by Nanson's formula); 1 finds it at every
    /// step. The default, [`DEFAULT_VC_SURFACE_REFRESH`] steps, takes a quarter of finding it
    /// at every step, with the errors of the convergence study and the collapses within a few
    /// per cent either way (docs/convergence/FINDINGS.md, "The found surface, carried"). A
    /// body that breaks apart gets its new faces when the surface is next found. Kept by
    /// checkpoints with the carried surface; any time. Refuses 0.
    pub fn set_vc_surface_refresh(&mut self, steps: u32) -> Result<()> {
        if steps == 0 {
            return Err(Error::invalid(
                "the found surface's refresh interval must be at least one step",
            ));
        }
        self.vc_surface_refresh = steps;
        Ok(())
    }

    /// Every how many steps VC finds the surface of the particles anew
    /// ([`Sim::set_vc_surface_refresh`]).
    pub fn vc_surface_refresh(&self) -> u32 {
        self.vc_surface_refresh
    }

    /// The boundary points given with [`Sim::add_boundary_points`], as they have moved.
    pub fn boundary_points(&self) -> &BoundaryPoints<D> {
        &self.boundary
    }

    /// The surface VC integrates over: the given boundary points, or without any the surface
    /// found from the particles at the start of the last step, or carried since for the next
    /// ([`Sim::set_vc_surface_refresh`]; empty before the first step and without VC).
    pub fn vc_surface(&self) -> &BoundaryPoints<D> {
        if self.boundary.is_empty() {
            &self.surface
        } else {
            &self.boundary
        }
    }

    /// Adds a material and returns its id.
    pub fn add_material(&mut self, material: Material) -> u32 {
        self.materials.push(material);
        (self.materials.len() - 1) as u32
    }

    /// Gives the Drucker–Prager material `material` the μ(I) rate dependence of its friction, or
    /// takes it away with `None`. May change between steps. Fails for an unknown material or one
    /// that is not Drucker–Prager.
    pub fn set_rheology(
        &mut self,
        material: u32,
        rheology: Option<crate::material::InertialRheology>,
    ) -> Result<()> {
        let count = self.materials.len();
        match self.materials.get_mut(material as usize) {
            Some(Material::DruckerPrager(soil)) => {
                soil.rheology = rheology;
                // (The wave speed does not depend on the rheology; any change of a material
                // drops the last step's signal speed all the same.)
                self.work.signal_speed = None;
                Ok(())
            }
            Some(_) => Err(Error::invalid(format!(
                "material {material} is not Drucker–Prager; only its friction has a μ(I) rheology"
            ))),
            None => Err(Error::invalid(format!(
                "material {material} does not exist ({count} materials)"
            ))),
        }
    }

    /// Changes the prescribed velocity of the rigid material `material` (only the first `D`
    /// components are used), for the steps that follow: a gate lifted and then stopped, a piston
    /// that reverses. Fails for an unknown material, one that is not rigid, or a non-finite
    /// velocity, and then changes nothing.
    pub fn set_rigid_velocity(&mut self, material: u32, velocity: [f64; 3]) -> Result<()> {
        for v in velocity {
            check_finite("velocity", v)?;
        }
        let count = self.materials.len();
        match self.materials.get_mut(material as usize) {
            Some(Material::Rigid(body)) => {
                body.velocity = velocity;
                // Its particles move with it from now on, and the stable step sees their speed.
                let v = Vector::<D>::from_fn(|i, _| velocity[i]);
                let ps = &mut self.particles;
                let mut given = 0.0;
                for ((vp, m), _) in ps
                    .velocity
                    .iter_mut()
                    .zip(&ps.mass)
                    .zip(&ps.material)
                    .filter(|(_, &b)| b == material)
                {
                    given += 0.5 * m * (v.norm_squared() - vp.norm_squared());
                    *vp = v;
                }
                if self.energy.on {
                    self.energy.start += given;
                }
                self.work.signal_speed = None;
                Ok(())
            }
            Some(_) => Err(Error::invalid(format!(
                "material {material} is not rigid; only a rigid body has a prescribed velocity"
            ))),
            None => Err(Error::new(
                ErrorKind::UnknownMaterial,
                format!("material {material} does not exist ({count} added so far)"),
            )),
        }
    }

    /// Adds particles of one material. All-or-nothing: on any error no particle is added.
    ///
    /// Requires finite positions inside the domain, finite positive volumes, finite velocities
    /// (`None` means at rest) and an existing material. Mass is `density × volume`.
    pub fn add_particles(
        &mut self,
        material: u32,
        positions: &[Vector<D>],
        volumes: &[f64],
        velocities: Option<&[Vector<D>]>,
    ) -> Result<()> {
        let mat = self.materials.get(material as usize).ok_or_else(|| {
            Error::new(
                ErrorKind::UnknownMaterial,
                format!(
                    "material {material} does not exist ({} added so far)",
                    self.materials.len()
                ),
            )
        })?;
        let n = positions.len();
        if volumes.len() != n || velocities.is_some_and(|v| v.len() != n) {
            return Err(Error::invalid(
                "positions, volumes and velocities differ in length",
            ));
        }
        let domain: f64 = (0..D)
            .map(|a| self.grid.cells[a] as f64 * self.grid.cell_size)
            .product();
        for (p, x) in positions.iter().enumerate() {
            if x.iter().any(|c| !c.is_finite()) {
                return Err(Error::invalid(format!(
                    "position of particle {p} is not finite"
                )));
            }
            if !self.grid.contains(x) {
                return Err(Error::new(
                    ErrorKind::OutsideGrid,
                    format!(
                        "particle {p} at {:?} lies outside the grid domain {:?} .. {:?}",
                        x.as_slice(),
                        self.grid.origin.as_slice(),
                        self.grid.upper().as_slice()
                    ),
                ));
            }
            check_positive(&format!("volume of particle {p}"), volumes[p])?;
            if volumes[p] > domain {
                return Err(Error::invalid(format!(
                    "volume of particle {p} ({:e}) exceeds the volume of the whole domain ({domain:e})",
                    volumes[p]
                )));
            }
            if let Some(v) = velocities {
                if v[p].iter().any(|c| !c.is_finite()) {
                    return Err(Error::invalid(format!(
                        "velocity of particle {p} is not finite"
                    )));
                }
            }
        }
        let rho = mat.density();
        if let Some(p) = (0..n).find(|&p| !(rho * volumes[p]).is_finite()) {
            return Err(Error::invalid(format!(
                "the mass of particle {p} (density {rho:e} × volume {:e}) is not finite",
                volumes[p]
            )));
        }
        let ps = &mut self.particles;
        let first_id = ps.len();
        if first_id + n > u32::MAX as usize {
            return Err(Error::invalid(format!(
                "{} particles would exceed the limit of {} per simulation",
                first_id + n,
                u32::MAX
            )));
        }
        if self.energy.on {
            // The new particles' kinetic and gravitational energy (they are unstrained).
            let g = self.options.gravity;
            let given: f64 = (0..n)
                .map(|p| {
                    let m = rho * volumes[p];
                    let v = velocities.map_or(0.0, |v| v[p].norm_squared());
                    0.5 * m * v - m * g.dot(&positions[p])
                })
                .sum();
            self.energy.start += given;
        }
        let apic = self.options.transfer.is_affine();
        ps.id.extend(first_id as u32..(first_id + n) as u32);
        self.work.signal_speed = None;
        ps.position.extend_from_slice(positions);
        ps.reference_position.extend_from_slice(positions);
        match velocities {
            Some(v) => ps.velocity.extend_from_slice(v),
            None => ps.velocity.extend(std::iter::repeat_n(Vector::zeros(), n)),
        }
        ps.deformation_gradient
            .extend(std::iter::repeat_n(Matrix::<D>::identity(), n));
        ps.reference_volume.extend_from_slice(volumes);
        ps.mass.extend(volumes.iter().map(|v| rho * v));
        ps.stress
            .extend(std::iter::repeat_n(Matrix::<D>::zeros(), n));
        ps.pressure.extend(std::iter::repeat_n(0.0, n));
        ps.material.extend(std::iter::repeat_n(material, n));
        // History (F_e, plastic strain) only once a history material has particles.
        if !mat.is_elastic() || !ps.history.is_empty() {
            ps.history
                .resize(ps.position.len(), crate::material::History::default());
        }
        if apic {
            ps.affine.resize(ps.position.len(), Matrix::<D>::zeros());
        }
        // New particles: the next step finds the surface anew.
        self.surface_age = u32::MAX;
        Ok(())
    }

    /// The largest stable time step times `cfl`: `cfl · h / max_p(c_p + |v_p|)`.
    ///
    /// Fails for a `cfl` outside `(0, 1]` and when there are no particles.
    pub fn stable_dt(&self, cfl: f64) -> Result<f64> {
        if !(cfl > 0.0 && cfl <= 1.0) {
            return Err(Error::invalid(format!("cfl must lie in (0, 1], got {cfl}")));
        }
        Ok(cfl * self.critical_dt()?)
    }

    /// `h / max_p(c_p + |v_p|)`, the step above which explicit MPM is unstable.
    /// `max_p (c_p + |v_p|)` over the particles, taken afresh. A step computes the same value
    /// from the new state while it has it in registers (`ConstitutiveUpdate`), so that the
    /// next step's check does not read every particle again.
    pub(crate) fn signal_speed(&self) -> f64 {
        let (ps, materials) = (&self.particles, &self.materials);
        // In parallel: the maximum is exact, so any thread count gives the same value.
        self.on_threads(|| {
            (0..ps.len())
                .into_par_iter()
                .map(|p| {
                    let j = crate::determinant(&ps.deformation_gradient[p]);
                    materials[ps.material[p] as usize].wave_speed(j) + ps.velocity[p].norm()
                })
                .reduce(|| 0.0, f64::max)
        })
    }

    pub(crate) fn critical_dt(&self) -> Result<f64> {
        if self.particles.is_empty() {
            return Err(Error::state(
                "no particles: the stable time step is undefined",
            ));
        }
        let speed = self
            .work
            .signal_speed
            .unwrap_or_else(|| self.signal_speed());
        if !(speed > 0.0 && speed.is_finite()) {
            return Err(Error::state(format!(
                "the largest signal speed max(c + |v|) over the particles is {speed:e}: no \
                 stable time step follows from it (only resting rigid bodies?)"
            )));
        }
        Ok(self.grid.cell_size / speed)
    }

    pub fn time(&self) -> f64 {
        self.time
    }
    pub fn steps(&self) -> u64 {
        self.steps
    }
    pub fn grid(&self) -> &Grid<D> {
        &self.grid
    }
    pub fn options(&self) -> &Options<D> {
        &self.options
    }
    /// A copy of the particles in id order: entry `i` of every array is particle `i`, the `i`-th
    /// added ([`Sim::add_particles`]), the order of [`Sim::field`], the VTK files and the C API.
    /// The engine stores them sorted by grid block as the steps go ([`Sim::set_fast_paths`]),
    /// an order it keeps to itself. Costs a copy of every particle: for the count alone,
    /// [`Sim::particle_count`]; for one quantity, [`Sim::field`].
    pub fn particles(&self) -> Particles<D> {
        self.particles.in_id_order_copy()
    }

    /// The number of particles.
    pub fn particle_count(&self) -> usize {
        self.particles.len()
    }
    pub fn materials(&self) -> &[Material] {
        &self.materials
    }

    /// Total stored elastic energy `Σ_p V0_p W(F_p)` (per unit thickness in 2D).
    pub fn strain_energy(&self) -> f64 {
        let ps = &self.particles;
        (0..ps.len())
            .map(|p| {
                let f = crate::material::embed3(&ps.deformation_gradient[p]);
                ps.reference_volume[p]
                    * self.materials[ps.material[p] as usize].stored_energy(&f, ps.history.get(p))
            })
            .sum()
    }

    /// The energies of the particles now ([`Energies`]; per unit thickness in 2D), summed in
    /// storage order.
    pub fn energies(&self) -> Energies {
        let ps = &self.particles;
        let g = self.options.gravity;
        Energies {
            kinetic: ps.kinetic_energy(),
            stored: self.strain_energy(),
            // `0 − Σ`, not `−Σ`: zero without gravity, not −0.
            gravitational: 0.0
                - ps.mass
                    .iter()
                    .zip(&ps.position)
                    .map(|(m, x)| m * g.dot(x))
                    .sum::<f64>(),
        }
    }

    /// Switches the energy accounting on (from the energies now, with nothing dissipated yet;
    /// switching it on again starts it afresh) or off. While it is on, every step adds its
    /// stress work and external work to the ledger that [`Sim::energy_balance`] reads (one more
    /// pass over the particles per step) and checkpoints keep it.
    pub fn set_energy_accounting(&mut self, on: bool) {
        self.energy = EnergyLedger::default();
        if on {
            let e = self.energies();
            self.energy = EnergyLedger {
                on: true,
                start: e.total(),
                stored_start: e.stored,
                ..EnergyLedger::default()
            };
        }
    }

    /// Whether the energy accounting is on.
    pub fn energy_accounting(&self) -> bool {
        self.energy.on
    }

    /// Where the energy went since the accounting started ([`EnergyBalance`]). Fails with
    /// `InvalidState` when the accounting is off.
    pub fn energy_balance(&self) -> Result<EnergyBalance> {
        let ledger = &self.energy;
        if !ledger.on {
            return Err(Error::state(
                "the energy accounting is off; switch it on (set_energy_accounting) before \
                 the steps it should account for",
            ));
        }
        let now = self.energies();
        let material_dissipation = ledger.stress_work - (now.stored - ledger.stored_start);
        Ok(EnergyBalance {
            now,
            start: ledger.start,
            external_work: ledger.external_work,
            stress_work: ledger.stress_work,
            material_dissipation,
            friction_dissipation: ledger.friction,
            contact_dissipation: ledger.contact,
            other_dissipation: ledger.start + ledger.external_work
                - material_dissipation
                - ledger.friction
                - ledger.contact
                - now.total(),
        })
    }

    /// The particles' total linear momentum `Σ m_p v_p` and angular momentum about the origin,
    /// `Σ m_p x_p × v_p` and the affine velocities' part under APIC and MLS ([`Momenta`]; per
    /// unit thickness in 2D).
    pub fn momenta(&self) -> Momenta<D> {
        let ps = &self.particles;
        let embed =
            |v: &Vector<D>| nalgebra::Vector3::from_fn(|k, _| if k < D { v[k] } else { 0.0 });
        let inertia = (self.options.transfer.is_affine() && ps.affine.len() == ps.len())
            .then(|| self.shape.apic_inertia(self.grid.cell_size))
            .flatten();
        // `ε : C` as a 3D vector: `(C_zy − C_yz, C_xz − C_zx, C_yx − C_xy)`.
        let spin = |c: &Matrix<D>| {
            let at = |i: usize, j: usize| if i < D && j < D { c[(i, j)] } else { 0.0 };
            nalgebra::Vector3::new(
                at(2, 1) - at(1, 2),
                at(0, 2) - at(2, 0),
                at(1, 0) - at(0, 1),
            )
        };
        let angular = (0..ps.len())
            .map(|p| {
                let (m, x, v) = (ps.mass[p], &ps.position[p], &ps.velocity[p]);
                let own = m * embed(x).cross(&embed(v));
                match inertia {
                    Some(d) => own + (m * d) * spin(&ps.affine[p]),
                    None => own,
                }
            })
            .sum();
        Momenta {
            linear: ps.momentum(),
            angular,
        }
    }

    /// Values of `field` for every particle, particle-major, in id order (the order they were
    /// added).
    pub fn field(&self, field: Field) -> Vec<f64> {
        let mut out = vec![0.0; field.components(D) * self.particles.len()];
        self.particles.write_field(field, &mut out);
        out
    }

    /// Whether some material of the simulation gives `field` values of its own
    /// ([`Material::carries`]): plastic strain and damage are zero for every particle without.
    pub fn carries(&self, field: Field) -> bool {
        self.materials.iter().any(|m| m.carries(field))
    }

    /// [`Sim::field`] into `out`, which must hold `field.components(D) * particle_count()`
    /// values (panics otherwise).
    pub fn write_field(&self, field: Field, out: &mut [f64]) {
        self.particles.write_field(field, out);
    }
}
