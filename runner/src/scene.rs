//! Scene files: a whole simulation (grid, options, walls, materials, bodies, run length and
//! output) described in TOML, read with serde. Unknown or misspelt keys, missing ones and values
//! of the wrong type are refused with the line, the column and the field
//! (`scene.toml: line 12, column 1: unknown field `densty` ...`); values the engine refuses are
//! reported with the table they came from (`materials[1] "steel": young must be positive`).
//!
//! ```toml
//! title = "two elastic disks collide"
//! [grid]
//! origin = [0.0, 0.0]          # its length is the dimension (2 or 3)
//! cells = [40, 40]
//! cell_size = 0.025
//! [options]                    # all optional; these are the defaults
//! shape = "bspline2"           # linear | bspline2 | bspline3 | rk (with rk_order, rk_support)
//! transfer = "apic"            # apic | pic_flip (with flip) | mls
//! [[materials]]
//! name = "rubber"
//! model = "neo_hookean"        # linear_elastic | neo_hookean | drucker_prager | johnson_cook | rigid
//! density = 1000.0
//! young = 1000.0
//! poisson = 0.3
//! [[bodies]]
//! material = "rubber"
//! sphere = { center = [0.25, 0.25], radius = 0.2 }   # or box, cylinder, file
//! velocity = [0.1, 0.1]
//! [run]
//! end_time = 3.0
//! frames = 30
//! ```
//!
//! `docs/SCENES.md` lists every key.

use rkmpm::error::{Error, ErrorKind, Result};
use rkmpm::material::{JohnsonCookParameters, Material, MieGruneisen};
use rkmpm::options::{
    Integration, IntegrationKind, Scheme, Shape, ShapeKind, Side, Transfer, TransferKind,
    VtkFormat, Wall, WallKind,
};
use rkmpm::sim::Sim;
use rkmpm::Vector;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// A whole scene as read from a file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// What the scene is, printed by the runner.
    #[serde(default)]
    pub title: String,
    pub grid: GridSpec,
    #[serde(default)]
    pub options: OptionsSpec,
    #[serde(default)]
    pub walls: Vec<WallSpec>,
    pub materials: Vec<MaterialSpec>,
    pub bodies: Vec<BodySpec>,
    pub run: RunSpec,
    /// The same scene once more with these options instead of `[options]` (keys and defaults
    /// as there): the runner's picture then shows both runs side by side on one colour scale.
    #[serde(default)]
    pub compare: Option<OptionsSpec>,
    /// Directory of the scene file: relative particle files are found from it.
    #[serde(skip)]
    pub base: PathBuf,
    /// The table the options came from, for messages: `options` (None) or `compare`.
    #[serde(skip)]
    pub options_table: Option<&'static str>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridSpec {
    /// Lower corner; its length (2 or 3) is the dimension of the scene.
    pub origin: Vec<f64>,
    pub cells: Vec<usize>,
    pub cell_size: f64,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OptionsSpec {
    #[serde(default)]
    pub shape: ShapeKind,
    /// RK only: the basis order (default 1).
    #[serde(default)]
    pub rk_order: Option<u32>,
    /// RK only: the kernel's support in cells (default 2).
    #[serde(default)]
    pub rk_support: Option<f64>,
    #[serde(default)]
    pub integration: IntegrationKind,
    /// VC only: the order of the divergence equalities (default 1).
    #[serde(default)]
    pub vc_order: Option<u32>,
    /// VC only: the solve's tolerance, in (0, 1] of the right-hand side's residual (default
    /// the engine's, 1e-12, the exact solve).
    #[serde(default)]
    pub vc_tolerance: Option<f64>,
    /// VC only: the solve's iteration bound (default the engine's, 2000).
    #[serde(default)]
    pub vc_max_iterations: Option<usize>,
    /// VC only: every how many steps the solve runs, the steps between taking its coefficients
    /// (default the engine's: 4 with RK shape functions at order 1, else 1).
    #[serde(default)]
    pub vc_solve_interval: Option<u32>,
    /// VC only: every how many steps the surface of the particles is found anew (default the
    /// engine's, 4; 1 at every step).
    #[serde(default)]
    pub vc_surface_refresh: Option<u32>,
    #[serde(default)]
    pub transfer: TransferKind,
    /// PIC/FLIP only: the FLIP fraction of the blend (default 0).
    #[serde(default)]
    pub flip: Option<f64>,
    #[serde(default)]
    pub scheme: Scheme,
    #[serde(default)]
    pub gravity: Option<Vec<f64>>,
    /// Multi-velocity-field contact between materials, with this Coulomb friction.
    #[serde(default)]
    pub contact_friction: Option<f64>,
}

impl OptionsSpec {
    pub fn shape(&self) -> Shape {
        Shape::from_kind(
            self.shape,
            self.rk_order.unwrap_or(1),
            self.rk_support.unwrap_or(2.0),
        )
    }

    pub fn integration(&self) -> Integration {
        Integration::from_kind(self.integration, self.vc_order.unwrap_or(1))
    }

    pub fn transfer(&self) -> Transfer {
        Transfer::from_kind(self.transfer, self.flip.unwrap_or(0.0))
    }

    /// The VC solve's rule given `automatic`, the engine's rule for the scene's order and
    /// grid: `None` (the automatic rule) without any of its keys, its values where a key is not
    /// given.
    pub fn vc_solve(&self, automatic: rkmpm::VcSolve) -> Option<rkmpm::VcSolve> {
        if self.vc_tolerance.is_none()
            && self.vc_max_iterations.is_none()
            && self.vc_solve_interval.is_none()
        {
            return None;
        }
        Some(rkmpm::VcSolve {
            tolerance: self.vc_tolerance.unwrap_or(automatic.tolerance),
            max_iterations: self.vc_max_iterations.unwrap_or(automatic.max_iterations),
            interval: self.vc_solve_interval.unwrap_or(automatic.interval),
        })
    }

    /// Refuses values out of range and settings that would do nothing in this scene, naming
    /// the key as the scene writes it (`table` is `options` or `compare`).
    pub fn check(&self, table: &str) -> Result<()> {
        let unused = |key: &str, what: &str| {
            Err(Error::invalid(format!(
                "{table}.{key} does nothing here: {what}; remove it"
            )))
        };
        if self.shape != ShapeKind::Rk {
            for (key, given) in [
                ("rk_order", self.rk_order.is_some()),
                ("rk_support", self.rk_support.is_some()),
            ] {
                if given {
                    return unused(
                        key,
                        "it sets the RK shape functions, and shape is not \"rk\"",
                    );
                }
            }
        }
        if self.integration != IntegrationKind::Vc {
            for (key, given) in [
                ("vc_order", self.vc_order.is_some()),
                ("vc_tolerance", self.vc_tolerance.is_some()),
                ("vc_max_iterations", self.vc_max_iterations.is_some()),
                ("vc_solve_interval", self.vc_solve_interval.is_some()),
                ("vc_surface_refresh", self.vc_surface_refresh.is_some()),
            ] {
                if given {
                    return unused(key, "it sets VC integration, and integration is not \"vc\"");
                }
            }
        }
        if let Some(flip) = self.flip {
            if self.transfer != TransferKind::PicFlip {
                return unused(
                    "flip",
                    "FLIP blends with PIC only, and transfer is not \"pic_flip\"",
                );
            }
            if !(0.0..=1.0).contains(&flip) {
                return Err(Error::invalid(format!(
                    "{table}.flip must lie in [0, 1], got {flip}"
                )));
            }
        }
        if let Some(mu) = self.contact_friction {
            if !(mu.is_finite() && mu >= 0.0) {
                return Err(Error::invalid(format!(
                    "{table}.contact_friction must be a finite coefficient >= 0, got {mu}"
                )));
            }
        }
        Ok(())
    }
}

fn default_cfl() -> f64 {
    0.3
}
fn default_max_steps() -> u64 {
    rkmpm::sim::DEFAULT_MAX_STEPS_PER_ADVANCE
}
fn default_ppc() -> usize {
    2
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WallSpec {
    /// 0, 1 or 2 (x, y, z).
    pub axis: usize,
    pub side: Side,
    pub kind: WallKind,
    /// Coulomb coefficient of a `friction` wall (required there, refused elsewhere).
    #[serde(default)]
    pub friction: Option<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Model {
    LinearElastic,
    NeoHookean,
    DruckerPrager,
    JohnsonCook,
    Rigid,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    /// The name bodies refer to.
    pub name: String,
    pub model: Model,
    pub density: f64,
    #[serde(default)]
    pub young: Option<f64>,
    #[serde(default)]
    pub poisson: Option<f64>,
    /// Drucker–Prager: friction angle (degrees), cohesion (Pa), dilatancy angle (degrees).
    #[serde(default)]
    pub friction_angle: Option<f64>,
    #[serde(default)]
    pub cohesion: Option<f64>,
    #[serde(default)]
    pub dilatancy_angle: Option<f64>,
    /// Johnson–Cook constants (see `RkmpmJohnsonCook` in the header).
    #[serde(default)]
    pub johnson_cook: Option<JohnsonCookSpec>,
    /// Rigid: the prescribed velocity.
    #[serde(default)]
    pub velocity: Option<Vec<f64>>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JohnsonCookSpec {
    pub a: f64,
    pub b: f64,
    pub n: f64,
    #[serde(default)]
    pub c: f64,
    #[serde(default = "unit")]
    pub reference_strain_rate: f64,
    #[serde(default = "unit")]
    pub m: f64,
    #[serde(default = "room")]
    pub room_temperature: f64,
    pub melt_temperature: f64,
    pub specific_heat: f64,
    #[serde(default)]
    pub taylor_quinney: f64,
    /// D1..D5 of Johnson–Cook damage; no damage when absent.
    #[serde(default)]
    pub damage: Option<[f64; 5]>,
    /// Mie–Grüneisen: bulk sound speed (m/s), Hugoniot slope, Grüneisen gamma.
    #[serde(default)]
    pub mie_gruneisen: Option<[f64; 3]>,
}

fn unit() -> f64 {
    1.0
}
fn room() -> f64 {
    293.0
}

/// Where a body's particles are: one of `box`, `sphere`, `cylinder` or `file`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodySpec {
    pub material: String,
    #[serde(default, rename = "box")]
    pub boxed: Option<BoxSpec>,
    #[serde(default)]
    pub sphere: Option<SphereSpec>,
    #[serde(default)]
    pub cylinder: Option<CylinderSpec>,
    /// A text file of particles, one per line: `x y [z] volume [vx vy [vz]]` (spaces or
    /// commas; `#` starts a comment).
    #[serde(default)]
    pub file: Option<PathBuf>,
    /// Particles per cell and direction for the shapes (on the lattice `origin + (i + ½) h/n`).
    #[serde(default = "default_ppc")]
    pub particles_per_cell: usize,
    #[serde(default)]
    pub velocity: Option<Vec<f64>>,
    /// A velocity field `amplitude · sin(wavenumber · x[along])` (a vibration mode), added to
    /// `velocity`.
    #[serde(default)]
    pub sine_velocity: Option<SineVelocity>,
    /// Keep only the part of the shape inside the grid (a model cut by a symmetry wall on a grid
    /// face). Without it a shape that reaches past the grid is refused.
    #[serde(default)]
    pub clip: bool,
    /// Moves each particle of a shape from its lattice site by a uniform random amount up to
    /// this fraction of the particle spacing in each direction (irregular particles, as large
    /// deformation makes them); in [0, 0.5), default 0. The same pattern on every run.
    #[serde(default)]
    pub jitter: f64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SineVelocity {
    pub amplitude: Vec<f64>,
    pub along: usize,
    pub wavenumber: f64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxSpec {
    pub min: Vec<f64>,
    pub max: Vec<f64>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SphereSpec {
    pub center: Vec<f64>,
    pub radius: f64,
}

/// A cylinder (a rectangle in 2D) along `axis` from `base` over `length`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CylinderSpec {
    pub base: Vec<f64>,
    pub axis: usize,
    pub radius: f64,
    pub length: f64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunSpec {
    pub end_time: f64,
    #[serde(default = "default_cfl")]
    pub cfl: f64,
    /// VTK frames written evenly over the run (plus the first); 0 writes none.
    #[serde(default)]
    pub frames: usize,
    /// Output prefix: `<output>_00000.vtu` ... and `<output>.pvd` (relative to the runner's
    /// output directory).
    #[serde(default = "default_output")]
    pub output: String,
    /// How the frames store their arrays: `binary` (raw bytes after the XML, as ParaView
    /// writes them) or `ascii`.
    #[serde(default)]
    pub vtk: VtkFormat,
    /// At the end, a PNG of the particles coloured by this field (`<output>.png`).
    #[serde(default)]
    pub png: Option<String>,
    /// 3D: the picture shows the section `y = section` (m); default the middle of the bodies.
    #[serde(default)]
    pub section: Option<f64>,
    /// The most steps the whole run may take (at least 1; default 10^9): a run whose estimate
    /// `end_time / stable step` exceeds it is refused before it starts, and one whose stable
    /// step shrinks on the way stops when it has taken them (its frames so far stay written).
    #[serde(default = "default_max_steps")]
    pub max_steps: u64,
    /// The simulation's own worker threads (0: one per core); default the process-wide pool.
    /// Results do not depend on it.
    #[serde(default)]
    pub threads: Option<usize>,
}

fn default_output() -> String {
    "scene".into()
}

/// A scene's simulation, 2D or 3D.
pub enum SceneSim {
    D2(Sim<2>),
    D3(Sim<3>),
}

impl Scene {
    /// Reads a scene from TOML text; `name` is used in messages (usually the file name).
    pub fn from_toml(text: &str, name: &str) -> Result<Self> {
        toml::from_str::<Scene>(text).map_err(|e| {
            let place = match e.span() {
                Some(span) => {
                    let line = text[..span.start].matches('\n').count() + 1;
                    let column =
                        span.start - text[..span.start].rfind('\n').map_or(0, |k| k + 1) + 1;
                    let here = text.lines().nth(line - 1).unwrap_or("").trim();
                    format!("line {line}, column {column} (`{here}`): ")
                }
                None => String::new(),
            };
            Error::invalid(format!("{name}: {place}{}", e.message()))
        })
    }

    /// Reads a scene file; particle files are found relative to its directory.
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| {
            Error::new(
                ErrorKind::Io,
                format!("cannot read {}: {e}", path.display()),
            )
        })?;
        let mut scene = Self::from_toml(&text, &path.display().to_string())?;
        scene.base = path.parent().map(Path::to_path_buf).unwrap_or_default();
        Ok(scene)
    }

    /// The dimension, from the grid's origin.
    pub fn dim(&self) -> Result<usize> {
        match self.grid.origin.len() {
            d @ (2 | 3) => Ok(d),
            d => Err(Error::invalid(format!(
                "grid.origin has {d} components: give 2 (2D) or 3 (3D)"
            ))),
        }
    }

    /// The scene to compare with: this one with the `[compare]` options, if it has them.
    pub fn comparison(&self) -> Option<Scene> {
        self.compare.as_ref().map(|options| Scene {
            options: options.clone(),
            compare: None,
            options_table: Some("compare"),
            ..self.clone()
        })
    }

    /// Builds the simulation: grid, options, walls, materials, then the bodies' particles.
    pub fn build(&self) -> Result<SceneSim> {
        Ok(match self.dim()? {
            2 => SceneSim::D2(self.build_dim::<2>()?),
            _ => SceneSim::D3(self.build_dim::<3>()?),
        })
    }

    fn build_dim<const D: usize>(&self) -> Result<Sim<D>> {
        let g = &self.grid;
        let origin = vector::<D>("grid.origin", &g.origin)?;
        if g.cells.len() != D {
            return Err(Error::invalid(format!(
                "grid.cells has {} entries for a {D}D grid",
                g.cells.len()
            )));
        }
        let cells: [usize; D] = std::array::from_fn(|a| g.cells[a]);
        let mut sim = Sim::<D>::new(origin, cells, g.cell_size).map_err(context("grid"))?;
        let o = &self.options;
        let table = self.options_table.unwrap_or("options");
        o.check(table)?;
        sim.set_shape(o.shape()).map_err(context(table))?;
        sim.set_integration(o.integration())
            .map_err(context(table))?;
        if let Some(solve) = o.vc_solve(sim.vc_solve()) {
            sim.set_vc_solve(solve).map_err(context(table))?;
        }
        if let Some(steps) = o.vc_surface_refresh {
            sim.set_vc_surface_refresh(steps).map_err(context(table))?;
        }
        sim.set_transfer(o.transfer()).map_err(context(table))?;
        sim.set_scheme(o.scheme).map_err(context(table))?;
        if let Some(g) = &o.gravity {
            sim.set_gravity(vector::<D>(&format!("{table}.gravity"), g)?)
                .map_err(context(table))?;
        }
        if let Some(mu) = o.contact_friction {
            sim.set_contact(Some(mu)).map_err(context(table))?;
        }
        for (k, w) in self.walls.iter().enumerate() {
            let here = format!("walls[{k}]");
            let friction = match (w.kind, w.friction) {
                (WallKind::Friction, Some(mu)) => mu,
                (WallKind::Friction, None) => {
                    return Err(Error::invalid(format!(
                        "{here}: a friction wall needs its coefficient, friction = ..."
                    )))
                }
                (_, Some(_)) => {
                    return Err(Error::invalid(format!(
                        "{here}.friction does nothing here: only a wall of kind \"friction\" \
                         reads it; remove it"
                    )))
                }
                (_, None) => 0.0,
            };
            sim.set_wall(w.axis, w.side, Wall::from_kind(w.kind, friction))
                .map_err(context(&here))?;
        }
        let mut ids = Vec::new();
        for (k, m) in self.materials.iter().enumerate() {
            let here = format!("materials[{k}] \"{}\"", m.name);
            if self.materials[..k].iter().any(|o| o.name == m.name) {
                return Err(Error::invalid(format!("{here}: the name is used twice")));
            }
            let material = m.material().map_err(context(&here))?;
            ids.push(sim.add_material(material));
        }
        let mut overlaps = Overlaps::<D>::default();
        for (k, b) in self.bodies.iter().enumerate() {
            let here = format!("bodies[{k}]");
            let id = self
                .materials
                .iter()
                .position(|m| m.name == b.material)
                .ok_or_else(|| {
                    Error::invalid(format!(
                        "{here}: material \"{}\" is not among the materials ({})",
                        b.material,
                        self.materials
                            .iter()
                            .map(|m| format!("\"{}\"", m.name))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ))
                })?;
            let (x, vol, v) = b.particles::<D>(&sim, &self.base).map_err(context(&here))?;
            if x.is_empty() {
                return Err(Error::invalid(format!(
                    "{here}: the body holds no particle (is it inside the grid?)"
                )));
            }
            overlaps.add(k, &x, &vol)?;
            let x = b.jittered(x, &vol).map_err(context(&here))?;
            sim.add_particles(ids[id], &x, &vol, v.as_deref())
                .map_err(context(&here))?;
        }
        if !(self.run.end_time.is_finite() && self.run.end_time > 0.0) {
            return Err(Error::invalid(format!(
                "run.end_time must be positive, got {}",
                self.run.end_time
            )));
        }
        if let Some(n) = self.run.threads {
            sim.set_threads(n).map_err(context("run"))?;
        }
        let first = sim.stable_dt(self.run.cfl).map_err(context("run"))?;
        let max = self.run.max_steps;
        if max == 0 {
            return Err(Error::invalid("run.max_steps must be at least 1, got 0"));
        }
        // As `Sim::advance` estimates a run: `ceil(duration / stable step)`.
        let estimate = (self.run.end_time / first).ceil();
        if estimate > max as f64 {
            return Err(Error::invalid(format!(
                "run: end_time = {:e} s needs about {estimate:.3e} steps of {first:.3e} s (cfl {} \
                 of the stable step at the start), above run.max_steps = {max}: shorten the run, \
                 or raise max_steps (--max-steps) if so long a run is meant",
                self.run.end_time, self.run.cfl
            )));
        }
        sim.set_max_steps_per_advance(max).map_err(context("run"))?;
        Ok(sim)
    }
}

impl MaterialSpec {
    fn need(&self, what: &str, v: Option<f64>) -> Result<f64> {
        v.ok_or_else(|| Error::invalid(format!("{what} is required for {:?}", self.model)))
    }

    fn material(&self) -> Result<Material> {
        let elastic = || -> Result<(f64, f64)> {
            Ok((
                self.need("young", self.young)?,
                self.need("poisson", self.poisson)?,
            ))
        };
        match self.model {
            Model::LinearElastic => {
                let (e, nu) = elastic()?;
                Material::linear_elastic(self.density, e, nu)
            }
            Model::NeoHookean => {
                let (e, nu) = elastic()?;
                Material::neo_hookean(self.density, e, nu)
            }
            Model::DruckerPrager => {
                let (e, nu) = elastic()?;
                Material::drucker_prager(
                    self.density,
                    e,
                    nu,
                    self.need("friction_angle", self.friction_angle)?,
                    self.cohesion.unwrap_or(0.0),
                    self.dilatancy_angle.unwrap_or(0.0),
                )
            }
            Model::JohnsonCook => {
                let (e, nu) = elastic()?;
                let j = self.johnson_cook.as_ref().ok_or_else(|| {
                    Error::invalid("a [materials.johnson_cook] table is required for johnson_cook")
                })?;
                Material::johnson_cook(JohnsonCookParameters {
                    density: self.density,
                    young: e,
                    poisson: nu,
                    a: j.a,
                    b: j.b,
                    n: j.n,
                    c: j.c,
                    reference_strain_rate: j.reference_strain_rate,
                    m: j.m,
                    room_temperature: j.room_temperature,
                    melt_temperature: j.melt_temperature,
                    specific_heat: j.specific_heat,
                    taylor_quinney: j.taylor_quinney,
                    damage: j.damage,
                    eos: j.mie_gruneisen.map(|[c0, s, gamma]| MieGruneisen {
                        sound_speed: c0,
                        slope: s,
                        gamma0: gamma,
                    }),
                })
            }
            Model::Rigid => {
                let v = self.velocity.clone().unwrap_or_default();
                if v.len() > 3 {
                    return Err(Error::invalid("velocity has more than 3 components"));
                }
                let mut w = [0.0; 3];
                w[..v.len()].copy_from_slice(&v);
                Material::rigid(self.density, w)
            }
        }
    }
}

impl BodySpec {
    /// Positions, volumes and (optional) velocities of the body's particles.
    /// The lattice sites `x` (of particles of volume `vol`) moved by `jitter`.
    fn jittered<const D: usize>(
        &self,
        mut x: Vec<Vector<D>>,
        vol: &[f64],
    ) -> Result<Vec<Vector<D>>> {
        let j = self.jitter;
        if !(0.0..0.5).contains(&j) {
            return Err(Error::invalid(format!(
                "jitter must lie in [0, 0.5), got {j}"
            )));
        }
        if j > 0.0 && self.file.is_some() {
            return Err(Error::invalid(
                "jitter does nothing for a file body (its particles are where the file puts \
                 them); remove it",
            ));
        }
        if j == 0.0 {
            return Ok(x);
        }
        let mut rng = rkmpm::UniformRng::new(7);
        for (p, v) in x.iter_mut().zip(vol) {
            let spacing = v.powf(1.0 / D as f64);
            *p += Vector::<D>::from_fn(|_, _| (2.0 * rng.uniform() - 1.0) * j * spacing);
        }
        Ok(x)
    }

    #[allow(clippy::type_complexity)]
    fn particles<const D: usize>(
        &self,
        sim: &Sim<D>,
        base: &Path,
    ) -> Result<(Vec<Vector<D>>, Vec<f64>, Option<Vec<Vector<D>>>)> {
        let given = [
            self.boxed.is_some(),
            self.sphere.is_some(),
            self.cylinder.is_some(),
            self.file.is_some(),
        ]
        .iter()
        .filter(|&&b| b)
        .count();
        if given != 1 {
            return Err(Error::invalid(format!(
                "give exactly one of box, sphere, cylinder and file (found {given})"
            )));
        }
        let velocity = match &self.velocity {
            Some(v) => Some(vector::<D>("velocity", v)?),
            None => None,
        };
        if let Some(file) = &self.file {
            let (x, vol, v) = read_particle_file::<D>(&base.join(file))?;
            let v = match (v, velocity) {
                (Some(v), _) => Some(v),
                (None, Some(u)) => Some(vec![u; x.len()]),
                (None, None) => None,
            };
            return Ok((x, vol, v));
        }
        // The shape, and the box that bounds it.
        let (inside, bounds): (Box<dyn Fn(&Vector<D>) -> bool>, _) = if let Some(b) = &self.boxed {
            let (lo, hi) = (
                vector::<D>("box.min", &b.min)?,
                vector::<D>("box.max", &b.max)?,
            );
            (
                Box::new(move |x| (0..D).all(|a| x[a] >= lo[a] && x[a] <= hi[a])),
                ("box", lo, hi),
            )
        } else if let Some(s) = &self.sphere {
            let c = vector::<D>("sphere.center", &s.center)?;
            let r = s.radius;
            let reach = Vector::<D>::from_element(r);
            (
                Box::new(move |x| (x - c).norm() <= r),
                ("sphere", c - reach, c + reach),
            )
        } else {
            let c = self.cylinder.as_ref().expect("one shape is given");
            let base = vector::<D>("cylinder.base", &c.base)?;
            if c.axis >= D {
                return Err(Error::invalid(format!(
                    "cylinder.axis {} is not an axis of a {D}D grid",
                    c.axis
                )));
            }
            let (axis, r, len) = (c.axis, c.radius, c.length);
            let lo = Vector::<D>::from_fn(|a, _| if a == axis { base[a] } else { base[a] - r });
            let hi = Vector::<D>::from_fn(|a, _| {
                if a == axis {
                    base[a] + len
                } else {
                    base[a] + r
                }
            });
            (
                Box::new(move |x| {
                    let d = x - base;
                    let mut radial = d;
                    radial[axis] = 0.0;
                    d[axis] >= 0.0 && d[axis] <= len && radial.norm() <= r
                }),
                ("cylinder", lo, hi),
            )
        };
        // A body that reaches past the grid is refused rather than clipped: the particles
        // cut off would be lost silently.
        let grid = sim.grid();
        let (shape, lo, hi) = bounds;
        let (origin, upper) = (grid.origin(), grid.upper());
        let slack = 1e-9 * grid.cell_size();
        for a in (0..D).filter(|_| !self.clip) {
            let (below, above) = (origin[a] - lo[a], hi[a] - upper[a]);
            if below > slack || above > slack {
                let (by, side, limit) = match below > slack {
                    true => (below, "below", origin[a]),
                    false => (above, "above", upper[a]),
                };
                return Err(Error::invalid(format!(
                    "the {shape} reaches {by:.6e} past the grid on axis {a} ({side} {limit}): \
                     move it, enlarge the grid (grid.cells, grid.origin), or keep the part \
                     inside with clip = true"
                )));
            }
        }
        let n = self.particles_per_cell;
        if n == 0 || n > 8 {
            return Err(Error::invalid(format!(
                "particles_per_cell must lie in 1..=8, got {n}"
            )));
        }
        let q = grid.cell_size() / n as f64;
        let counts: [usize; D] = std::array::from_fn(|a| grid.cells()[a] * n);
        let total: usize = counts.iter().product();
        let mut x = Vec::new();
        for k in 0..total {
            let mut r = k;
            let p = Vector::<D>::from_fn(|a, _| {
                let i = r % counts[a];
                r /= counts[a];
                grid.origin()[a] + (i as f64 + 0.5) * q
            });
            if inside(&p) {
                x.push(p);
            }
        }
        let vol = vec![q.powi(D as i32); x.len()];
        let v = match (&self.sine_velocity, velocity) {
            (None, None) => None,
            (None, Some(u)) => Some(vec![u; x.len()]),
            (Some(s), u) => {
                let amplitude = vector::<D>("sine_velocity.amplitude", &s.amplitude)?;
                if s.along >= D {
                    return Err(Error::invalid(format!(
                        "sine_velocity.along {} is not an axis of a {D}D grid",
                        s.along
                    )));
                }
                let u = u.unwrap_or_else(Vector::zeros);
                Some(
                    x.iter()
                        .map(|p| u + amplitude * (s.wavenumber * p[s.along]).sin())
                        .collect(),
                )
            }
        };
        Ok((x, vol, v))
    }
}

/// Reads `x y [z] volume [vx vy [vz]]` lines.
#[allow(clippy::type_complexity)]
fn read_particle_file<const D: usize>(
    path: &Path,
) -> Result<(Vec<Vector<D>>, Vec<f64>, Option<Vec<Vector<D>>>)> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        Error::new(
            ErrorKind::Io,
            format!("cannot read {}: {e}", path.display()),
        )
    })?;
    let (mut x, mut vol, mut v) = (Vec::new(), Vec::new(), Vec::new());
    for (k, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let at = || format!("{}: line {}", path.display(), k + 1);
        let values: Vec<f64> = line
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|s| !s.is_empty())
            .map(|s| {
                s.parse::<f64>()
                    .map_err(|_| Error::invalid(format!("{}: \"{s}\" is not a number", at())))
            })
            .collect::<Result<_>>()?;
        if values.len() != D + 1 && values.len() != 2 * D + 1 {
            return Err(Error::invalid(format!(
                "{}: {} values; a {D}D particle line has {} (x, volume) or {} (x, volume, v)",
                at(),
                values.len(),
                D + 1,
                2 * D + 1
            )));
        }
        if !v.is_empty() && values.len() == D + 1 || v.len() != x.len() && values.len() > D + 1 {
            return Err(Error::invalid(format!(
                "{}: give velocities on every line or on none",
                at()
            )));
        }
        x.push(Vector::<D>::from_column_slice(&values[..D]));
        vol.push(values[D]);
        if values.len() > D + 1 {
            v.push(Vector::<D>::from_column_slice(&values[D + 1..]));
        }
    }
    let v = (!v.is_empty()).then_some(v);
    Ok((x, vol, v))
}

/// The particles of the bodies placed so far, hashed by position, to refuse a body that
/// overlaps another: two bodies' particles closer than half the smaller particle spacing
/// (`volume^(1/D)`) sit in each other's material, which MPM would push apart at once.
#[derive(Default)]
struct Overlaps<const D: usize> {
    cells: std::collections::HashMap<[i64; D], Vec<(usize, Vector<D>, f64)>>,
    /// The bucket size: the largest particle spacing so far (a close pair is at most one bucket
    /// apart in every direction).
    size: f64,
}

impl<const D: usize> Overlaps<D> {
    fn key(&self, x: &Vector<D>) -> [i64; D] {
        std::array::from_fn(|a| (x[a] / self.size).floor() as i64)
    }

    /// Adds body `body`'s particles; refuses them if one lies within half a spacing of an
    /// earlier body's.
    fn add(&mut self, body: usize, x: &[Vector<D>], volume: &[f64]) -> Result<()> {
        let spacing = |v: f64| v.abs().powf(1.0 / D as f64);
        let largest = volume.iter().map(|&v| spacing(v)).fold(0.0, f64::max);
        if largest > self.size {
            // Rehash with buckets as large as the largest spacing.
            self.size = largest;
            let all: Vec<_> = self.cells.drain().flat_map(|(_, v)| v).collect();
            for entry in all {
                let key = self.key(&entry.1);
                self.cells.entry(key).or_default().push(entry);
            }
        }
        for (xp, &vp) in x.iter().zip(volume) {
            let key = self.key(xp);
            for offset in 0..3usize.pow(D as u32) {
                let near: [i64; D] = std::array::from_fn(|a| {
                    key[a] + (offset / 3usize.pow(a as u32) % 3) as i64 - 1
                });
                let Some(entries) = self.cells.get(&near) else {
                    continue;
                };
                for (other, xq, sq) in entries {
                    let distance = (xp - xq).norm();
                    if distance < 0.5 * sq.min(spacing(vp)) {
                        return Err(Error::invalid(format!(
                            "bodies[{body}] overlaps bodies[{other}]: its particle at ({}) is \
                             {distance:.3e} m from one of bodies[{other}], less than half their \
                             spacing; move the bodies apart",
                            xp.iter()
                                .map(|c| format!("{c}"))
                                .collect::<Vec<_>>()
                                .join(", ")
                        )));
                    }
                }
            }
        }
        for (xp, &vp) in x.iter().zip(volume) {
            let key = self.key(xp);
            self.cells
                .entry(key)
                .or_default()
                .push((body, *xp, spacing(vp)));
        }
        Ok(())
    }
}

fn vector<const D: usize>(what: &str, v: &[f64]) -> Result<Vector<D>> {
    if v.len() != D {
        return Err(Error::invalid(format!(
            "{what} has {} components for a {D}D scene",
            v.len()
        )));
    }
    Ok(Vector::<D>::from_column_slice(v))
}

fn context(here: &str) -> impl Fn(Error) -> Error + '_ {
    move |e| Error::new(e.kind, format!("{here}: {}", e.message))
}

/// The scenes that ship with rkmpm, by name, as TOML text (`runner/scenes/*.toml`).
pub const BUNDLED: [(&str, &str); 6] = [
    ("disks", include_str!("../scenes/disks.toml")),
    ("bar", include_str!("../scenes/bar.toml")),
    ("collapse", include_str!("../scenes/collapse.toml")),
    ("taylor", include_str!("../scenes/taylor.toml")),
    ("penetration", include_str!("../scenes/penetration.toml")),
    ("column", include_str!("../scenes/column.toml")),
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_bundled_scene_builds() {
        for (name, text) in BUNDLED {
            let scene = Scene::from_toml(text, name).unwrap();
            assert!(!scene.title.is_empty(), "{name} has a title");
            scene.build().unwrap_or_else(|e| panic!("{name}: {e}"));
            if let Some(other) = scene.comparison() {
                other
                    .build()
                    .unwrap_or_else(|e| panic!("{name}, [compare]: {e}"));
            }
        }
    }

    /// A shape that reaches past the grid is refused, naming the body, the axis and by how
    /// much, unless the body says `clip = true`; the bundled scenes that cut a shape by a
    /// symmetry wall say so.
    #[test]
    fn a_body_past_the_grid_is_refused_unless_clipped() {
        let bar = BUNDLED.iter().find(|(n, _)| *n == "bar").unwrap().1;
        let mut scene = Scene::from_toml(bar, "bar").unwrap();
        let upper = scene.grid.origin[0] + scene.grid.cells[0] as f64 * scene.grid.cell_size;
        let body = &mut scene.bodies[0];
        let boxed = body.boxed.as_mut().expect("the bar is a box");
        boxed.max[0] = upper + 0.25 * scene.grid.cell_size;
        let Err(e) = scene.build() else {
            panic!("a body past the grid was accepted")
        };
        assert!(e.message.contains("bodies[0]"), "{}", e.message);
        assert!(
            e.message.contains("the box reaches") && e.message.contains("on axis 0 (above"),
            "{}",
            e.message
        );
        let by = 0.25 * scene.grid.cell_size;
        assert!(e.message.contains(&format!("{by:.6e}")), "{}", e.message);
        scene.bodies[0].clip = true;
        assert!(scene.build().is_ok(), "clipped to the grid");
    }

    /// The default scene compares the seed's method with the same shape functions without VC:
    /// `[compare]` replaces the options whole and keeps the rest of the scene.
    #[test]
    fn the_comparison_takes_the_compare_options_and_nothing_else() {
        let scene = Scene::from_toml(BUNDLED[0].1, "disks").unwrap();
        assert_eq!(scene.options.shape, ShapeKind::Rk);
        assert_eq!(scene.options.integration, IntegrationKind::Vc);
        let other = scene.comparison().expect("disks has a [compare] table");
        assert_eq!(other.options.shape, ShapeKind::Rk);
        assert_eq!(other.options.rk_support, scene.options.rk_support);
        assert_eq!(other.options.integration, IntegrationKind::MaterialPoint);
        assert!(other.compare.is_none());
        assert_eq!(other.bodies.len(), scene.bodies.len());
        assert_eq!(other.run.end_time, scene.run.end_time);
        let e = Scene::from_toml(
            &format!("{}\n[compare]\nshape = \"quartic\"\n", BUNDLED[3].1),
            "bad.toml",
        )
        .unwrap_err();
        assert!(e.message.contains("quartic"), "{}", e.message);
    }

    /// `options.vc_tolerance` and `vc_max_iterations` set the VC solve's rule (the engine's
    /// default without them); refused without VC and out of range.
    #[test]
    fn the_vc_solve_keys_set_the_rule() {
        let disks = BUNDLED[0].1;
        let rule = |text: &str| match Scene::from_toml(text, "x").and_then(|s| s.build()) {
            Ok(SceneSim::D2(sim)) => Ok(sim.vc_solve()),
            Ok(SceneSim::D3(_)) => unreachable!("disks is 2D"),
            Err(e) => Err(e.message),
        };
        // RK1 + VC1: the automatic rule solves every `RK_INTERVAL` steps.
        let rk_default = rkmpm::VcSolve {
            interval: rkmpm::VcSolve::RK_INTERVAL,
            ..rkmpm::VcSolve::DEFAULT
        };
        assert_eq!(rule(disks), Ok(rk_default));
        // RK2 + VC2 on the disks' grid (40 cells across): the automatic rule, 1e-4 (32 / 40)^3.
        let vc2 = disks
            .replacen("rk_order = 1\n", "rk_order = 2\n", 1)
            .replacen("vc_order = 1\n", "vc_order = 2\n", 1);
        let automatic = rule(&vc2).unwrap().tolerance;
        assert!((automatic - 5.12e-5).abs() < 1e-18, "{automatic}");
        let with =
            |extra: &str| disks.replacen("vc_order = 1\n", &format!("vc_order = 1\n{extra}\n"), 1);
        assert_eq!(
            rule(&with("vc_tolerance = 1e-12\nvc_max_iterations = 50")),
            Ok(rkmpm::VcSolve {
                tolerance: 1e-12,
                max_iterations: 50,
                interval: rkmpm::VcSolve::RK_INTERVAL,
            })
        );
        assert_eq!(
            rule(&with("vc_solve_interval = 1")),
            Ok(rkmpm::VcSolve {
                interval: 1,
                ..rkmpm::VcSolve::DEFAULT
            })
        );
        let e = rule(&with("vc_solve_interval = 0")).unwrap_err();
        assert!(e.contains("interval must be at least one step"), "{e}");
        let e = rule(&with("vc_tolerance = 1.5")).unwrap_err();
        assert!(e.contains("options: the VC solve's tolerance"), "{e}");
        let e = rule(&with("vc_max_iterations = 0")).unwrap_err();
        assert!(e.contains("at least one iteration"), "{e}");
        let refresh = |text: &str| match Scene::from_toml(text, "x").and_then(|s| s.build()) {
            Ok(SceneSim::D2(sim)) => Ok(sim.vc_surface_refresh()),
            Ok(SceneSim::D3(_)) => unreachable!("disks is 2D"),
            Err(e) => Err(e.message),
        };
        assert_eq!(refresh(disks), Ok(rkmpm::DEFAULT_VC_SURFACE_REFRESH));
        assert_eq!(refresh(&with("vc_surface_refresh = 1")), Ok(1));
        let e = refresh(&with("vc_surface_refresh = 0")).unwrap_err();
        assert!(e.contains("at least one step"), "{e}");
        let bar = BUNDLED[1].1.replacen(
            "transfer = \"apic\"\n",
            "transfer = \"apic\"\nvc_tolerance = 1e-6\n",
            1,
        );
        let e = rule(&bar).unwrap_err();
        assert!(e.contains("options.vc_tolerance does nothing here"), "{e}");
    }

    /// `run.threads` gives the simulation (and its comparison) threads of its own; more than
    /// the engine's bound is refused with the bound.
    #[test]
    fn run_threads_go_to_the_simulations() {
        let good = BUNDLED[0].1;
        let with = |extra: &str| good.replace("[run]\n", &format!("[run]\n{extra}\n"));
        let threads = |text: &str| {
            let scene = Scene::from_toml(text, "x").unwrap();
            let own = match scene.build() {
                Ok(SceneSim::D2(sim)) => sim.threads(),
                Ok(SceneSim::D3(sim)) => sim.threads(),
                Err(e) => return Err(e.message),
            };
            match scene.comparison().map(|c| c.build()) {
                Some(Ok(SceneSim::D2(sim))) => assert_eq!(sim.threads(), own),
                Some(Ok(SceneSim::D3(sim))) => assert_eq!(sim.threads(), own),
                Some(Err(e)) => return Err(e.message),
                None => {}
            }
            Ok(own)
        };
        let shared = Sim::<2>::new([0.0, 0.0], [4, 4], 1.0).unwrap().threads();
        assert_eq!(threads(good), Ok(shared));
        assert_eq!(threads(&with("threads = 3")), Ok(3));
        let e = threads(&with("threads = 5000")).unwrap_err();
        assert!(e.contains("run: threads must be at most 4096"), "{e}");
    }

    /// `run.max_steps` bounds the run: a scene whose estimate exceeds it is refused before the
    /// run with the estimate, and the simulation it builds carries the bound.
    #[test]
    fn run_max_steps_refuses_a_run_above_it() {
        let good = BUNDLED[0].1;
        let with = |extra: &str| good.replace("[run]\n", &format!("[run]\n{extra}\n"));
        let scene = Scene::from_toml(good, "disks").unwrap();
        assert_eq!(scene.run.max_steps, 1_000_000_000);
        // The disks' stable step: the estimate the refusal gives.
        let first = match scene.build().unwrap() {
            SceneSim::D2(sim) => {
                assert_eq!(sim.max_steps_per_advance(), 1_000_000_000);
                sim.stable_dt(scene.run.cfl).unwrap()
            }
            SceneSim::D3(_) => unreachable!("disks is 2D"),
        };
        let e = Scene::from_toml(&with("max_steps = 10"), "x")
            .unwrap()
            .build()
            .err()
            .unwrap();
        let estimate = format!("needs about {:.3e} steps", (3.0 / first).ceil());
        assert!(
            e.message.contains(&estimate) && e.message.contains("above run.max_steps = 10"),
            "{} lacks {estimate}",
            e.message
        );
        let e = Scene::from_toml(&with("max_steps = 0"), "x")
            .unwrap()
            .build()
            .err()
            .unwrap();
        assert!(e.message.contains("at least 1"), "{}", e.message);
        // An end time of 1e300 s: refused under the default bound instead of run for ever.
        let text = good.replace("end_time = 3.0", "end_time = 1e300");
        let e = Scene::from_toml(&text, "x").unwrap().build().err().unwrap();
        assert!(
            e.message.contains("above run.max_steps = 1000000000"),
            "{}",
            e.message
        );
        // Raised, the bound lets the scene build and the simulation carries it.
        match Scene::from_toml(&with("max_steps = 123456"), "x")
            .unwrap()
            .build()
            .unwrap()
        {
            SceneSim::D2(sim) => assert_eq!(sim.max_steps_per_advance(), 123_456),
            SceneSim::D3(_) => unreachable!("disks is 2D"),
        }
        // A material no solid matches is refused with its table and its reason.
        let text = good.replace("young = 1000.0", "young = 1e300");
        let e = Scene::from_toml(&text, "x").unwrap().build().err().unwrap();
        assert!(
            e.message.starts_with("materials[0] \"rubber\": ")
                && e.message.contains("exceeds 1e5 m/s"),
            "{}",
            e.message
        );
    }

    /// Misspelt keys, missing keys and values of the wrong type name their line and field.
    #[test]
    fn bad_files_name_the_line_and_the_field() {
        let good = BUNDLED[0].1;
        let cases = [
            (good.replace("density = ", "densty = "), "densty"),
            (
                good.replace("cell_size = 0.025", "cell_size = \"fine\""),
                "cell_size",
            ),
            (
                good.replace("model = \"neo_hookean\"", "model = \"jelly\""),
                "jelly",
            ),
            (good.replace("end_time = 3.0", ""), "end_time"),
        ];
        for (text, field) in cases {
            let e = Scene::from_toml(&text, "bad.toml").unwrap_err();
            assert!(e.message.contains("bad.toml: line "), "{}", e.message);
            assert!(e.message.contains(field), "{}", e.message);
        }
        // A value the engine refuses names the table it came from.
        let text = good.replace("young = 1000.0", "young = -1.0");
        let e = Scene::from_toml(&text, "x").unwrap().build().err().unwrap();
        assert!(
            e.message.starts_with("materials[0] \"rubber\": "),
            "{}",
            e.message
        );
        let text = good.replace("material = \"rubber\"", "material = \"steel\"");
        let e = Scene::from_toml(&text, "x").unwrap().build().err().unwrap();
        assert!(
            e.message.contains("\"steel\" is not among"),
            "{}",
            e.message
        );
    }
}
