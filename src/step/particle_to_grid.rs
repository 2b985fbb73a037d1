//! Particle to grid: `m_I = Σ m_p Ψ_Ip`, `(mv)_I = Σ m_p Ψ_Ip (v_p + C_p (x_I − x_p))`,
//! `f_I = −Σ V_p σ_p ∇Ψ_Ip + Σ m_p Ψ_Ip b_p`.
//!
//! For a signed shape function (RK of order ≥ 2) the stencils give the transfer weights of
//! [`super::edge_lumping`] (`Ψ` inside a body); the force takes the gradients `∇Ψ` and VC's
//! correction is weighted with `Ψ`, as VC computed it.

use super::profile::lap;
use super::{StepInputs, Workspace};
use crate::grid::Bins;
use crate::grid::{scatter_add, NodeScatter};
use crate::grid::{Grid, GridNodes};
use crate::integration::{BoundaryPoints, VcCorrection};
use crate::options::Shape;
use crate::particles::Particles;
use crate::shape::{ScatterInput, StencilNode, StencilView, Stencils, SupportNodes};
use crate::{Matrix, Vector};

/// Phase 3: the particles' mass, momentum and force to the grid: to the one field, with VC's
/// torque removed and the tractions of `boundary` added, or under contact to each body's own
/// field. Returns the mass at or below which the grid update gives a node no velocity: for
/// signed shape functions and linear hats a fraction of the largest particle mass (their node
/// masses may be tiny where the force or the velocity gradient is not); for the smooth
/// nonnegative ones (B-splines, RK1) only empty nodes, so that no node's momentum or force is
/// dropped and a free body's momentum is kept to round-off (with the floor a cubic B-spline
/// block drifted by 1e-10 of M·v in 1000 steps).
pub(super) fn phase<const D: usize, S: StencilView<D>>(
    inputs: &StepInputs<'_, D, S>,
    vc: Option<&VcCorrection<D>>,
    boundary: &BoundaryPoints<D>,
    work: &mut Workspace<D>,
) -> f64 {
    let (grid, ps, plan) = (inputs.grid, inputs.particles, inputs.plan);
    let mut clock = std::time::Instant::now();
    let forces = Forces {
        gravity: inputs.options.gravity,
        body: inputs.body_acceleration,
        vc,
        mls: plan
            .mls_inverse_inertia()
            .map(|inverse_inertia| (inputs.dt, inverse_inertia)),
    };
    let floored = inputs.shape.is_signed() || matches!(inputs.options.shape, Shape::Linear);
    let mass_floor_fraction = if floored { 1e-10 } else { 0.0 };
    if inputs.options.contact.is_some() {
        let floor = super::contact::particle_to_grid_per_body(
            inputs,
            forces,
            mass_floor_fraction,
            &mut work.bodies,
        );
        work.times.particle_to_grid += lap(&mut clock);
        return floor;
    }
    let (v, c) = (&ps.velocity[..], &ps.affine[..]);
    let velocity = move |p: usize| v[p];
    let affine_map = plan.apic.then_some(move |p: usize| c[p]);
    let largest_mass = particle_to_grid(
        &ToGrid::of(inputs),
        velocity,
        affine_map,
        Some(forces),
        None,
        &mut work.nodes,
    );
    if let (Some(vc), Some(stored)) = (vc, inputs.stored) {
        let (walls, all) = (inputs.walls, |_| true);
        let found = vc.bodies();
        let tensor = inputs.stencils.tensor_factors();
        super::vc_torque::remove_vc_torque(
            grid,
            walls,
            SupportNodes { stored, tensor },
            ps.len(),
            all,
            found,
            &mut work.nodes,
        );
    }
    if boundary.has_tractions() {
        super::surface::apply_tractions(boundary, &work.boundary_stencils, &mut work.nodes);
    }
    work.times.particle_to_grid += lap(&mut clock);
    mass_floor_fraction * largest_mass
}

/// What the first map accumulates besides momentum: mass and forces.
#[derive(Clone, Copy)]
pub struct Forces<'a, const D: usize> {
    pub gravity: Vector<D>,
    /// Per-particle body accelerations from the callback, if any.
    pub body: Option<&'a [Vector<D>]>,
    /// Gradient corrections of VC integration (internal force only), if on.
    pub vc: Option<&'a VcCorrection<D>>,
    /// MLS (`Some((Δt, 1/D))`, see [`crate::options::Transfer::Mls`]): `Δt f` goes into the
    /// momentum, the internal force through the affine term `m C − (Δt/D) V σ` and the body force
    /// through `m (v + Δt b)`; nothing is added to `force`.
    pub mls: Option<(f64, f64)>,
}

/// The particles as a map to the grid reads them.
#[derive(Clone, Copy)]
pub struct ToGrid<'a, const D: usize, S> {
    pub grid: &'a Grid<D>,
    pub particles: &'a Particles<D>,
    /// The particles binned by grid block (the map's schedule).
    pub bins: &'a Bins<D>,
    pub stencils: &'a S,
    /// The stored stencils, whose values `Ψ` weigh VC's correction where the transfer weights
    /// differ from them (signed shape functions).
    pub shape: Option<&'a Stencils<D>>,
}

impl<'a, const D: usize, S> ToGrid<'a, D, S> {
    /// The step's particles, bins and stencils.
    pub(super) fn of(inputs: &StepInputs<'a, D, S>) -> Self {
        ToGrid {
            grid: inputs.grid,
            particles: inputs.particles,
            bins: inputs.bins,
            stencils: inputs.stencils,
            shape: inputs.stored,
        }
    }
}

/// Scatters particle quantities to the nodes of their stencils and marks those nodes active.
///
/// * `velocity(p)` and `affine(p)` give the velocity and, under APIC, `C_p` to map (the
///   particle's own, or the updated ones in the second map of MUSL).
/// * `forces`: `Some(..)` also accumulates mass and force; `None` maps momentum only.
/// * `body`: with contact, only the particles of this material map (to its own field).
///
/// Runs in parallel by colours of rows of grid blocks, or of blocks ([`Bins::tasks`]), a task
/// starting once its neighbours of earlier colours have ended ([`Bins::run_tasks`]): every
/// node's sum is taken in the same order with any number of threads.
///
/// Returns the largest mass of the particles (of all of them, whichever `body` maps), which the
/// grid update's mass floor needs: taken here, where each particle's mass is read anyway, it
/// saves a separate pass over the masses (a serial chain of `max`).
pub fn particle_to_grid<const D: usize, S, A>(
    to: &ToGrid<'_, D, S>,
    velocity: impl Fn(usize) -> Vector<D> + Sync + Copy,
    affine: Option<A>,
    forces: Option<Forces<D>>,
    body: Option<u32>,
    nodes: &mut GridNodes<D>,
) -> f64
where
    S: StencilView<D>,
    A: Fn(usize) -> Matrix<D> + Sync + Copy,
{
    let ToGrid {
        grid,
        particles: ps,
        bins,
        stencils,
        shape,
    } = *to;
    let vc = forces.and_then(|f| f.vc);
    let out = NodeScatter::new(nodes);
    let with_gradient = !out.mass_gradient.is_null() && forces.is_some();
    let keep_body_force = !out.body_force.is_null();
    let with_mass = forces.is_some();
    let mls = forces.and_then(|f| f.mls);
    // No body-force sums when there is no gravity and no body-force callback (nor under MLS,
    // which adds the body force to the momentum).
    let with_body_force = mls.is_none()
        && forces.is_some_and(|f| f.body.is_some() || f.gravity != Vector::<D>::zeros());
    // The particle arrays as slices, the stencils as their `Local` view, and the closure by
    // value (`move`, copied into each task below): the compiler then keeps them in registers
    // instead of reloading them after every store to the nodes, which it cannot prove leaves
    // them alone.
    let (material, mass, position, stress) = (
        &ps.material[..],
        &ps.mass[..],
        &ps.position[..],
        &ps.stress[..],
    );
    let (deformation_gradient, reference_volume) =
        (&ps.deformation_gradient[..], &ps.reference_volume[..]);
    // VC's correction at the nodes of each support, from the factors where there are some.
    let support = shape.map(|stored| SupportNodes {
        stored,
        tensor: stencils.tensor_factors(),
    });
    let stencils = stencils.local();
    let lanes = stencils.lanes();
    let scatter = crate::cpu::inlined(
        #[inline(always)]
        move |p: usize| {
            if body.is_some_and(|b| material[p] != b) {
                return;
            }
            let m = mass[p];
            let v = velocity(p);
            let c = affine.as_ref().map(|a| a(p));
            let xp = position[p];
            let mut force = forces.map(|f| {
                let b = match f.body {
                    Some(b) => f.gravity + b[p],
                    None => f.gravity,
                };
                let volume = crate::determinant(&deformation_gradient[p]) * reference_volume[p];
                (-volume * stress[p], b)
            });
            // Momentum of the particle and its affine part, `m v + m C (x_I − x_p)`.
            let mut mv = m * v;
            let mut mc = c.map(|c| m * c);
            if let (Some((dt, inverse_inertia)), Some((vs, b))) = (mls, force) {
                // MLS: `Δt f_I = Ψ_I (Δt m b + (Δt/D) (−V σ)(x_I − x_p))`, on the momentum.
                mv += (dt * m) * b;
                mc = mc.map(|mc| mc + (dt * inverse_inertia) * vs);
                force = None;
            }
            let psi = shape
                .filter(|s| !s.transfer.is_empty())
                .map(|s| &s.values[p * s.len..(p + 1) * s.len]);
            let node_sums = |s: usize, node: StencilNode<D>, offset: Vector<D>| {
                let StencilNode {
                    node: n,
                    value: w,
                    gradient: g,
                } = node;
                if w == 0.0 && g == Vector::<D>::zeros() {
                    return;
                }
                // SAFETY: tasks that share nodes never run at once (`Bins::run_tasks`).
                unsafe {
                    out.touch(n);
                    let mut momentum = mv;
                    if let Some(mc) = mc {
                        momentum += mc * offset;
                    }
                    scatter_add(out.momentum, n, w * momentum);
                    if with_mass {
                        scatter_add(out.mass, n, m * w);
                        if with_gradient {
                            scatter_add(out.mass_gradient, n, m * g);
                        }
                    }
                    if let Some((vs, b)) = force {
                        let grad = match vc {
                            Some(vc) if w != 0.0 || g != Vector::<D>::zeros() => {
                                let psi = psi.map_or(w, |psi| psi[s]);
                                g + vc.gradient_correction_at(grid, out.slot[n], n, p, &xp, psi)
                            }
                            _ => g,
                        };
                        scatter_add(out.force, n, vs * grad);
                        if !with_body_force {
                            // Nothing to add.
                        } else if keep_body_force {
                            scatter_add(out.body_force, n, (m * w) * b);
                        } else {
                            scatter_add(out.force, n, (m * w) * b);
                        }
                    }
                }
            };
            // A factored scatter when the stencils have one (B-spline factors), then VC's
            // correction of the internal force from the stored stencils.
            let input = ScatterInput {
                position: xp,
                mass: m,
                momentum: mv,
                affine: mc,
                with_mass,
                force,
                with_body_force,
                keep_body_force,
                with_gradient,
                mean_fit: vc.and_then(|vc| vc.mean_fit_coefficients()),
            };
            // SAFETY: as above.
            if unsafe { stencils.scatter(p, &input, &out) } {
                // VC's correction, unless the scatter took it (the mean fit on the factors).
                if let (Some(vc), Some((vs, _)), Some(support)) = (vc, force, &support) {
                    if vc.mean_fit_coefficients().is_none() {
                        // SAFETY: as above (the same stencil's nodes).
                        unsafe { scatter_vc_correction(grid, vc, support, p, &xp, vs, &out) };
                    }
                }
                return;
            }
            stencils.for_each_with_offset(grid, p, c.is_some().then_some(&xp), node_sums);
        },
    );
    let largest_mass = bins.run_tasks(
        || 0.0f64,
        |range| {
            lanes.wide(
                #[inline(always)]
                || {
                    // A copy in this task (see above), not a reference to the shared one.
                    #[allow(clippy::redundant_locals)]
                    let scatter = scatter;
                    let mut largest = 0.0f64;
                    for &p in &bins.order[range] {
                        scatter(p as usize);
                        largest = largest.max(mass[p as usize]);
                    }
                    largest
                },
            )
        },
        f64::max,
    );
    bins.collect_active(grid, nodes);
    largest_mass
}

/// VC's part of particle `p`'s internal force, `f_I += −V_p σ_p (∇̂Ψ_I − ∇Ψ_I)` (`vs` is
/// `−V_p σ_p`), at the nodes of its stored stencil where `Ψ_I(x_p) ≠ 0`, for a map whose
/// factored scatter added the rest.
///
/// # Safety
/// As [`StencilView::scatter`]: no other thread writes these nodes meanwhile.
#[inline(always)]
unsafe fn scatter_vc_correction<const D: usize>(
    grid: &Grid<D>,
    vc: &VcCorrection<D>,
    support: &SupportNodes<D>,
    p: usize,
    xp: &Vector<D>,
    vs: Matrix<D>,
    out: &NodeScatter<D>,
) {
    support.for_each_value(p, |n, w| {
        let correction = vc.gradient_correction_at(grid, out.slot[n], n, p, xp, w);
        // SAFETY: the caller's.
        unsafe { scatter_add(out.force, n, vs * correction) };
    });
}
