//! Grid to particle: velocity (PIC/FLIP blend or APIC), position, velocity gradient and `F`.

use super::constitutive_update::ConstitutiveUpdate;
use super::profile::lap;
use super::surface::move_boundary_points;
use super::{Reorder, StepInputs, TransferPlan, Workspace};
use crate::cpu::Lanes;
use crate::error::ErrorKind;
use crate::grid::{DomainBox, Grid, GridNodes, SharedSlice};
use crate::integration::BoundaryPoints;
use crate::material::History;
use crate::options::Scheme;
use crate::particles::Particles;
use crate::shape::StencilView;
use crate::{Matrix, Vector};
use rayon::prelude::*;

/// The new state of one particle, built in registers during the gather and stored in the
/// [`NewState`] arrays. The history of an elastoplastic particle goes to its own slot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParticleUpdate<const D: usize> {
    pub position: Vector<D>,
    pub velocity: Vector<D>,
    pub affine: Matrix<D>,
    pub deformation_gradient: Matrix<D>,
    pub stress: Matrix<D>,
    pub pressure: f64,
}

impl<const D: usize> Default for ParticleUpdate<D> {
    // Inlined into the gather (compiled for AVX2), which fills each new state whole from it.
    #[inline(always)]
    fn default() -> Self {
        ParticleUpdate {
            position: Vector::zeros(),
            velocity: Vector::zeros(),
            affine: Matrix::zeros(),
            deformation_gradient: Matrix::identity(),
            stress: Matrix::zeros(),
            pressure: 0.0,
        }
    }
}

/// Phase 5: the grid's velocities to the particles' new state (`work.new_state`), in block
/// order when the particles have `scattered` (USL); under USL with each particle's constitutive
/// `update` in the same pass, while it is in cache; under MUSL the new momenta are mapped to the
/// grid again (nodes at or below `mass_floor` skipped) and `F` taken from those velocities. The
/// `moving` boundary points move with the grid. Returns the signal speed and whether every
/// particle passed its checks (under USL; under MUSL the constitutive update's phase says).
pub(super) fn phase<const D: usize, S: StencilView<D>>(
    inputs: &StepInputs<'_, D, S>,
    update: &ConstitutiveUpdate<'_, D>,
    moving: Option<&BoundaryPoints<D>>,
    scattered: bool,
    mass_floor: f64,
    work: &mut Workspace<D>,
) -> (f64, bool) {
    let (grid, ps, dt) = (inputs.grid, inputs.particles, inputs.dt);
    let mut clock = std::time::Instant::now();
    let mut admissible = std::mem::take(&mut work.admissible);
    let mut new = std::mem::take(&mut work.new_state);
    let usl = inputs.options.scheme == Scheme::Usl;
    work.reorder = match scattered {
        false => Reorder::No,
        true if usl && !work.reorder_at_commit => Reorder::InGather,
        true => Reorder::AtCommit,
    };
    let source = (work.reorder == Reorder::InGather).then_some(&inputs.bins.order[..]);
    let fields = match inputs.options.contact {
        Some(_) => Fields::PerBody(&work.bodies.nodes, &ps.material),
        None => Fields::One(&work.nodes),
    };
    let from = FromGrid {
        grid,
        particles: ps,
        stencils: inputs.stencils,
        fields,
        rigid: inputs.rigid,
        plan: inputs.plan,
        dt,
    };
    let gathered = grid_to_particle(
        &from,
        usl.then_some(update),
        source,
        &mut new,
        &mut admissible,
    );
    if !usl {
        super::musl::second_map(inputs, mass_floor, &mut work.nodes, &mut new);
    }
    work.boundary_updates.clear();
    if let Some(boundary) = moving {
        let bs = &work.boundary_stencils;
        move_boundary_points(boundary, bs, &work.nodes, dt, &mut work.boundary_updates);
    }
    work.admissible = admissible;
    work.new_state = new;
    work.times.grid_to_particle += lap(&mut clock);
    gathered
}

/// The new particle state of a step, stored as the particles are (one `Vec` per quantity), and
/// swapped with theirs when the step succeeds: the commit moves no data. `affine` is empty
/// unless APIC runs, `history` unless the particles carry history.
#[derive(Debug, Default, Clone)]
pub struct NewState<const D: usize> {
    pub position: Vec<Vector<D>>,
    pub velocity: Vec<Vector<D>>,
    pub affine: Vec<Matrix<D>>,
    pub deformation_gradient: Vec<Matrix<D>>,
    pub stress: Vec<Matrix<D>>,
    pub pressure: Vec<f64>,
    /// Written for history particles only; the commit copies those.
    pub history: Vec<History>,
}

impl<const D: usize> NewState<D> {
    /// Sizes the arrays for `ps` (no work when the count did not change).
    pub fn prepare(&mut self, ps: &Particles<D>, apic: bool) {
        let n = ps.len();
        self.position.resize(n, Vector::zeros());
        self.velocity.resize(n, Vector::zeros());
        self.affine
            .resize(if apic { n } else { 0 }, Matrix::zeros());
        self.deformation_gradient.resize(n, Matrix::identity());
        self.stress.resize(n, Matrix::zeros());
        self.pressure.resize(n, 0.0);
        self.history.resize(ps.history.len(), History::default());
    }

    /// Particle `p`'s new state.
    pub fn get(&self, p: usize) -> ParticleUpdate<D> {
        ParticleUpdate {
            position: self.position[p],
            velocity: self.velocity[p],
            affine: self.affine.get(p).copied().unwrap_or_else(Matrix::zeros),
            deformation_gradient: self.deformation_gradient[p],
            stress: self.stress[p],
            pressure: self.pressure[p],
        }
    }

    /// Bytes allocated.
    pub fn bytes(&self) -> usize {
        use crate::step::profile_bytes as b;
        b(&self.position)
            + b(&self.velocity)
            + b(&self.affine)
            + b(&self.deformation_gradient)
            + b(&self.stress)
            + b(&self.pressure)
            + b(&self.history)
    }

    /// Write access for the parallel per-particle passes.
    pub fn writer(&mut self) -> NewStateWriter<'_, D> {
        NewStateWriter {
            position: SharedSlice::new(&mut self.position),
            velocity: SharedSlice::new(&mut self.velocity),
            affine: SharedSlice::new(&mut self.affine),
            deformation_gradient: SharedSlice::new(&mut self.deformation_gradient),
            stress: SharedSlice::new(&mut self.stress),
            pressure: SharedSlice::new(&mut self.pressure),
            history: SharedSlice::new(&mut self.history),
        }
    }
}

/// Writes particles' new states from several threads; each particle is written by one task.
pub struct NewStateWriter<'a, const D: usize> {
    position: SharedSlice<'a, Vector<D>>,
    velocity: SharedSlice<'a, Vector<D>>,
    affine: SharedSlice<'a, Matrix<D>>,
    deformation_gradient: SharedSlice<'a, Matrix<D>>,
    stress: SharedSlice<'a, Matrix<D>>,
    pressure: SharedSlice<'a, f64>,
    history: SharedSlice<'a, History>,
}

impl<const D: usize> NewStateWriter<'_, D> {
    /// Stores particle `p`'s new state (the affine matrix only when APIC keeps it).
    ///
    /// # Safety
    /// No other thread accesses particle `p`'s new state meanwhile.
    #[inline(always)]
    pub unsafe fn store(&self, p: usize, u: &ParticleUpdate<D>) {
        // SAFETY: the caller keeps this function's `# Safety` contract: particle `p`'s slots
        // are this task's alone.
        unsafe {
            *self.position.at(p) = u.position;
            *self.velocity.at(p) = u.velocity;
            if !self.affine.is_empty() {
                *self.affine.at(p) = u.affine;
            }
            *self.deformation_gradient.at(p) = u.deformation_gradient;
            *self.stress.at(p) = u.stress;
            *self.pressure.at(p) = u.pressure;
        }
    }

    /// Asks for the cache lines of particles `p .. p + n`'s new state, for writing
    /// ([`Lanes::prefetch_for_write`]); nothing past the end.
    #[inline(always)]
    pub fn prefetch_for_write(&self, lanes: Lanes, p: usize, n: usize) {
        #[inline(always)]
        fn lines<T>(lanes: Lanes, s: &SharedSlice<'_, T>, p: usize, n: usize) {
            if p + n <= s.len() {
                lanes.prefetch_for_write(s.as_ptr_at(p), n);
            }
        }
        lines(lanes, &self.position, p, n);
        lines(lanes, &self.velocity, p, n);
        lines(lanes, &self.affine, p, n);
        lines(lanes, &self.deformation_gradient, p, n);
        lines(lanes, &self.stress, p, n);
        lines(lanes, &self.pressure, p, n);
    }

    /// Particle `p`'s new state as stored.
    ///
    /// # Safety
    /// No other thread writes particle `p`'s new state meanwhile.
    #[inline(always)]
    pub unsafe fn get(&self, p: usize) -> ParticleUpdate<D> {
        // SAFETY: the caller keeps this function's `# Safety` contract: particle `p`'s slots
        // are this task's alone.
        unsafe {
            ParticleUpdate {
                position: *self.position.at(p),
                velocity: *self.velocity.at(p),
                affine: if self.affine.is_empty() {
                    Matrix::zeros()
                } else {
                    *self.affine.at(p)
                },
                deformation_gradient: *self.deformation_gradient.at(p),
                stress: *self.stress.at(p),
                pressure: *self.pressure.at(p),
            }
        }
    }

    /// Particle `p`'s history slot, when the particles carry history.
    ///
    /// # Safety
    /// No other thread accesses particle `p`'s new state meanwhile.
    #[allow(clippy::mut_from_ref)]
    #[inline(always)]
    pub unsafe fn history(&self, p: usize) -> Option<&mut History> {
        // SAFETY: the caller keeps this function's `# Safety` contract: particle `p`'s slots
        // are this task's alone.
        unsafe { (!self.history.is_empty()).then(|| self.history.at(p)) }
    }
}

impl<const D: usize> ParticleUpdate<D> {
    /// Whether the new state is admissible, given `j = det F`: the same answer as
    /// [`ParticleUpdate::check`], from one sum instead of a test per value (a sum that is finite
    /// has no NaN or infinite term; when the sum is not finite, the full check decides).
    #[inline(always)]
    pub fn is_admissible(&self, domain: &DomainBox<D>, j: f64) -> bool {
        let sum = self.position.sum()
            + self.velocity.sum()
            + self.deformation_gradient.sum()
            + self.stress.sum()
            + self.affine.sum()
            + self.pressure;
        if sum.is_finite() && j > 0.0 && domain.contains(&self.position) {
            true
        } else {
            self.check(domain).is_ok()
        }
    }

    /// Whether the new state is admissible; if not, the kind of failure and what was wrong.
    #[cold]
    #[inline(never)]
    pub fn check(&self, domain: &DomainBox<D>) -> Result<(), (ErrorKind, String)> {
        let finite = self.position.iter().all(|c| c.is_finite())
            && self.velocity.iter().all(|c| c.is_finite())
            && self.deformation_gradient.iter().all(|c| c.is_finite())
            && self.stress.iter().all(|c| c.is_finite())
            && self.affine.iter().all(|c| c.is_finite())
            && self.pressure.is_finite();
        if !finite {
            return Err((ErrorKind::NonFinite, "has a non-finite value".into()));
        }
        let j = crate::determinant(&self.deformation_gradient);
        if j <= 0.0 {
            return Err((
                ErrorKind::InvertedParticle,
                format!("is inverted (det F = {j:e})"),
            ));
        }
        if !domain.contains(&self.position) {
            return Err((
                ErrorKind::OutsideGrid,
                format!("would leave the grid (x = {:?})", self.position.as_slice()),
            ));
        }
        Ok(())
    }
}

/// `L_p = Σ_I v_I ⊗ ∇Ψ_I(x_p)` with the current node velocities.
#[inline]
pub fn velocity_gradient<const D: usize>(
    stencils: &impl StencilView<D>,
    nodes: &GridNodes<D>,
    p: usize,
) -> Matrix<D> {
    let mut l = Matrix::<D>::zeros();
    stencils.for_each(p, |_, s| {
        l += nodes.velocity[s.node] * s.gradient.transpose()
    });
    l
}

/// The MLS velocity gradient `L_p = D⁻¹ Σ_I Ψ_I(x_p) v_I ⊗ (x_I − x_p)` with the current node
/// velocities (`inverse_inertia = D⁻¹`); exact for a linear velocity field.
#[inline]
pub fn mls_velocity_gradient<const D: usize>(
    stencils: &impl StencilView<D>,
    grid: &Grid<D>,
    nodes: &GridNodes<D>,
    p: usize,
    xp: &Vector<D>,
    inverse_inertia: f64,
) -> Matrix<D> {
    stencils
        .gather(grid, p, xp, &nodes.velocity, None, true, false)
        .affine
        * inverse_inertia
}

/// What completes a particle's new state while it is in registers (the constitutive update and
/// the checks under USL), and says whether it is admissible; `history` is the particle's new
/// history slot, or scratch for particles without one.
pub trait Finish<const D: usize>: Sync {
    /// `None` when the new state is not admissible; otherwise the particle's signal speed
    /// `c + |v|` in it, of which the next step's stability check takes the maximum.
    fn finish(&self, p: usize, u: &mut ParticleUpdate<D>, history: &mut History) -> Option<f64>;

    /// [`Finish::finish`] for the particles of a chunk of grid to particle (at most 8, `us[k]`
    /// the new state of particle `chunk.particle(k)`) at once, when the chunk allows it (all of
    /// one elastic material, say): fills `speeds` with what `finish` would return for each and
    /// returns true. Returns false, having changed nothing, when the chunk has to be finished
    /// particle by particle. Each particle's result is the same bits as `finish` gives it.
    #[inline(always)]
    fn finish_chunk(
        &self,
        _chunk: Chunk<'_>,
        _us: &mut [ParticleUpdate<D>],
        _speeds: &mut [Option<f64>],
    ) -> bool {
        false
    }
}

/// Particles per chunk of grid to particle: the gathers of a chunk, then its constitutive
/// updates and stores. Each loop is short, so the processor overlaps consecutive particles' long
/// dependency chains (gather → F → det F → ln → stress) instead of waiting on each in turn.
pub(crate) const CHUNK: usize = 8;

/// Chunks ahead whose new state grid to particle asks the cache for (32 particles): far enough
/// for the lines to arrive before the stores, near enough to stay in the cache.
const AHEAD: usize = 4;

/// The particles of a chunk of grid to particle: slots `first..first + len`, each holding
/// particle `source[slot]`, or the particle of the slot's index without `source`.
#[derive(Clone, Copy)]
pub struct Chunk<'a> {
    pub first: usize,
    pub len: usize,
    pub source: Option<&'a [u32]>,
}

impl Chunk<'_> {
    /// The particle of the chunk's slot `k`.
    #[inline(always)]
    pub fn particle(&self, k: usize) -> usize {
        match self.source {
            Some(s) => s[self.first + k] as usize,
            None => self.first + k,
        }
    }

    /// Whether `f` holds for the particle of every slot of the chunk.
    #[inline(always)]
    pub fn all(&self, f: impl Fn(usize) -> bool) -> bool {
        match self.source {
            Some(s) => s[self.first..self.first + self.len]
                .iter()
                .all(|&p| f(p as usize)),
            None => (self.first..self.first + self.len).all(f),
        }
    }
}

/// The type of a missing `finish` of [`grid_to_particle`] (`None::<&NoFinish>`).
#[cfg_attr(not(feature = "internals"), allow(dead_code))] // for the benchmarks
pub struct NoFinish;

impl<const D: usize> Finish<D> for NoFinish {
    fn finish(&self, _: usize, _: &mut ParticleUpdate<D>, _: &mut History) -> Option<f64> {
        Some(0.0)
    }
}

/// The grid fields particles read: one for all, or one per body under contact.
#[derive(Clone, Copy)]
pub enum Fields<'a, const D: usize> {
    One(&'a GridNodes<D>),
    /// Per-body fields and each particle's body (its material).
    PerBody(&'a [GridNodes<D>], &'a [u32]),
}

impl<'a, const D: usize> Fields<'a, D> {
    /// The field particle `p` reads.
    #[inline]
    pub fn of(&self, p: usize) -> &'a GridNodes<D> {
        match *self {
            Fields::One(n) => n,
            Fields::PerBody(b, material) => &b[material[p] as usize],
        }
    }
}

/// What grid to particle reads: the particles, their stencils, the grid fields after the grid
/// update, each material's rigid velocity (`None` for a deformable one), the transfer and `Δt`.
#[derive(Clone, Copy)]
pub struct FromGrid<'a, const D: usize, S> {
    pub grid: &'a Grid<D>,
    pub particles: &'a Particles<D>,
    pub stencils: &'a S,
    pub fields: Fields<'a, D>,
    pub rigid: &'a [Option<Vector<D>>],
    pub plan: TransferPlan,
    pub dt: f64,
}

/// Gathers the new velocity, affine matrix and position of every particle, and under USL its new
/// deformation gradient `(I + Δt L) F` (under MUSL that waits for the second map). Particles of
/// a rigid material (`rigid[material]` is its velocity) move with it and keep their `F`.
///
/// `source`, when given, reorders the particles as it goes: slot `k` of the new state (and of
/// `admissible`) is particle `source[k]` (a permutation). The step stores its particles in the
/// order of their grid blocks this way: the new state comes out sorted, and only the quantities
/// a step does not change are permuted afterwards ([`Particles::permute_carried`]).
///
/// `finish(p, u, history)`, when given, completes particle `p`'s new state while it is in
/// registers (the constitutive update and the checks under USL; `history` is its new history
/// slot, or scratch for particles without one) and says whether it is admissible; `admissible`
/// receives that (true for every particle without `finish`). The new states go to `new`.
/// Returns the largest signal speed `finish` gave (0 without `finish`) and whether every new
/// state is admissible (so that the checks scan `admissible` only when one is not).
pub fn grid_to_particle<const D: usize, F, S>(
    from: &FromGrid<'_, D, S>,
    finish: Option<&F>,
    source: Option<&[u32]>,
    new: &mut NewState<D>,
    admissible: &mut Vec<bool>,
) -> (f64, bool)
where
    F: Finish<D>,
    S: StencilView<D>,
{
    if let Some(source) = source {
        assert_eq!(
            source.len(),
            from.particles.len(),
            "a permutation of the particles"
        );
    }
    // One compiled pass per case: MLS takes no gradient sum. (One per `source` too made no
    // measurable difference; BENCHMARKS.md.)
    if from.plan.mls {
        gather_all::<true, D, F, S>(from, finish, source, new, admissible)
    } else {
        gather_all::<false, D, F, S>(from, finish, source, new, admissible)
    }
}

/// [`grid_to_particle`] with `MLS = plan.mls`.
fn gather_all<const MLS: bool, const D: usize, F, S>(
    from: &FromGrid<'_, D, S>,
    finish: Option<&F>,
    source: Option<&[u32]>,
    new: &mut NewState<D>,
    admissible: &mut Vec<bool>,
) -> (f64, bool)
where
    F: Finish<D>,
    S: StencilView<D>,
{
    let FromGrid {
        grid,
        particles: ps,
        stencils,
        fields,
        rigid,
        plan,
        dt,
    } = *from;
    new.prepare(ps, plan.apic);
    let flip = plan.flip > 0.0;
    let update_deformation = finish.is_some();
    let apic_inertia = plan.inverse_inertia.is_some();
    // Slices and plain values captured by value, as in particle to grid, so that the compiler
    // keeps them in registers.
    let stencils = stencils.local();
    let lanes = stencils.lanes();
    let (position, material, velocity, deformation_gradient) = (
        &ps.position[..],
        &ps.material[..],
        &ps.velocity[..],
        &ps.deformation_gradient[..],
    );
    let one_field = match fields {
        Fields::One(n) => Some((&n.velocity[..], &n.velocity_old[..])),
        Fields::PerBody(..) => None,
    };
    let any_rigid = rigid.iter().any(Option::is_some);
    // Each particle's whole new state, built in registers: the stress and pressure stay zero
    // for `finish` to fill, and `F` stays the identity when no `finish` updates it (MUSL).
    let gather = crate::cpu::inlined(
        #[inline(always)]
        move |p: usize| -> ParticleUpdate<D> {
            let xp = position[p];
            let rigid_velocity = match any_rigid {
                true => rigid.get(material[p] as usize).copied().flatten(),
                false => None,
            };
            if let Some(v) = rigid_velocity {
                return ParticleUpdate {
                    position: xp + dt * v,
                    velocity: v,
                    deformation_gradient: deformation_gradient[p],
                    ..ParticleUpdate::default()
                };
            }
            let (v, v_old) = one_field.unwrap_or_else(|| {
                let nodes = fields.of(p);
                (&nodes.velocity, &nodes.velocity_old)
            });
            let g = stencils.gather(grid, p, &xp, v, flip.then_some(v_old), apic_inertia, !MLS);
            let (v_pic, dv) = (g.velocity, g.velocity_change);
            // `C_p = B_p / D` when the inertia is constant; under MLS it is the velocity gradient.
            let affine = plan.inverse_inertia.map(|inv| g.affine * inv);
            let l = match affine {
                Some(c) if MLS => c,
                _ => g.gradient,
            };
            ParticleUpdate {
                position: xp + dt * v_pic,
                velocity: if flip {
                    (1.0 - plan.flip) * v_pic + plan.flip * (velocity[p] + dv)
                } else {
                    v_pic
                },
                affine: if plan.apic {
                    affine.unwrap_or(l)
                } else {
                    Matrix::zeros()
                },
                deformation_gradient: if update_deformation {
                    (Matrix::<D>::identity() + dt * l) * deformation_gradient[p]
                } else {
                    Matrix::identity()
                },
                ..ParticleUpdate::default()
            }
        },
    );
    let writer = new.writer();
    admissible.clear();
    admissible.resize(ps.len(), false);
    admissible
        .par_chunks_mut(CHUNK)
        .enumerate()
        .map_init(History::default, |scratch, (c, ok)| {
            lanes.wide(
                #[inline(always)]
                || {
                    let first = c * CHUNK;
                    let n = ok.len();
                    // The lines this task writes a few chunks on (`AHEAD`).
                    writer.prefetch_for_write(lanes, first + AHEAD * CHUNK, CHUNK);
                    let chunk = Chunk {
                        first,
                        len: n,
                        source,
                    };
                    // Not initialised first: each slot is written whole by its gather.
                    let mut slots = [std::mem::MaybeUninit::<ParticleUpdate<D>>::uninit(); CHUNK];
                    for (k, u) in slots[..n].iter_mut().enumerate() {
                        u.write(gather(chunk.particle(k)));
                    }
                    // SAFETY: the first `n` slots were written just above.
                    let updates = unsafe {
                        std::slice::from_raw_parts_mut(
                            slots.as_mut_ptr().cast::<ParticleUpdate<D>>(),
                            n,
                        )
                    };
                    let (mut speed, mut all_admissible) = (0.0f64, true);
                    let mut speeds = [None; CHUNK];
                    let whole =
                        finish.is_some_and(|f| f.finish_chunk(chunk, updates, &mut speeds[..n]));
                    for (k, (u, ok)) in updates.iter_mut().zip(ok.iter_mut()).enumerate() {
                        let slot = first + k;
                        let finished = match finish {
                            _ if whole => speeds[k],
                            Some(f) => f.finish(
                                chunk.particle(k),
                                u,
                                // SAFETY: each slot belongs to one chunk, and so to one task.
                                unsafe { writer.history(slot) }.unwrap_or(scratch),
                            ),
                            None => Some(0.0),
                        };
                        *ok = finished.is_some();
                        all_admissible &= *ok;
                        speed = speed.max(finished.unwrap_or(0.0));
                        // SAFETY: as for the history above.
                        unsafe { writer.store(slot, u) };
                    }
                    (speed, all_admissible)
                },
            )
        })
        .reduce(|| (0.0, true), |a, b| (a.0.max(b.0), a.1 && b.1))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The new state written from several threads through [`NewStateWriter`], each particle by
    /// one thread (the threads take particles `k, k + 3, ...`), then read back through it: every
    /// quantity, the affine matrix and the history slot included, holds what its one writer
    /// stored. Run under Miri by `scripts/test-miri.sh`, where two threads reaching one
    /// particle's slots would be a data race.
    #[test]
    fn new_states_written_from_several_threads() {
        let n = 30;
        let update = |p: usize| ParticleUpdate::<2> {
            position: Vector::<2>::new(p as f64, 1.0),
            velocity: Vector::<2>::new(2.0, p as f64),
            affine: Matrix::from_element(p as f64),
            deformation_gradient: Matrix::identity() * (1.0 + p as f64),
            stress: Matrix::from_element(-(p as f64)),
            pressure: 0.5 * p as f64,
        };
        let mut state = NewState::<2> {
            position: vec![Vector::zeros(); n],
            velocity: vec![Vector::zeros(); n],
            affine: vec![Matrix::zeros(); n],
            deformation_gradient: vec![Matrix::zeros(); n],
            stress: vec![Matrix::zeros(); n],
            pressure: vec![0.0; n],
            history: vec![History::default(); n],
        };
        {
            let writer = state.writer();
            std::thread::scope(|scope| {
                for k in 0..3 {
                    let writer = &writer;
                    scope.spawn(move || {
                        for p in (k..n).step_by(3) {
                            // SAFETY: thread `k` alone handles the particles `k + 3j`.
                            unsafe {
                                writer.store(p, &update(p));
                                if let Some(h) = writer.history(p) {
                                    h.plastic_strain = p as f64;
                                }
                                assert_eq!(writer.get(p), update(p));
                            }
                        }
                    });
                }
            });
        }
        for p in 0..n {
            assert_eq!(state.get(p), update(p), "particle {p}");
            assert_eq!(state.history[p].plastic_strain, p as f64);
        }
    }
}
