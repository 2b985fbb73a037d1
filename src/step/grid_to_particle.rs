//! Grid to particle: velocity (PIC/FLIP blend or APIC), position, velocity gradient and `F`.

use super::TransferPlan;
use crate::error::ErrorKind;
use crate::grid::{Grid, GridNodes};
use crate::material::PlasticState;
use crate::particles::Particles;
use crate::shape::StencilView;
use crate::{Matrix, Vector};
use rayon::prelude::*;

/// The new state of one particle, built during a step and committed when the step succeeds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParticleUpdate<const D: usize> {
    pub position: Vector<D>,
    pub velocity: Vector<D>,
    pub affine: Matrix<D>,
    pub deformation_gradient: Matrix<D>,
    pub stress: Matrix<D>,
    pub pressure: f64,
    /// New history of an elastoplastic particle (untouched for elastic ones).
    pub plastic: PlasticState,
}

impl<const D: usize> Default for ParticleUpdate<D> {
    fn default() -> Self {
        ParticleUpdate {
            position: Vector::zeros(),
            velocity: Vector::zeros(),
            affine: Matrix::zeros(),
            deformation_gradient: Matrix::identity(),
            stress: Matrix::zeros(),
            pressure: 0.0,
            plastic: PlasticState::default(),
        }
    }
}

impl<const D: usize> ParticleUpdate<D> {
    /// Whether the new state is admissible; if not, the kind of failure and what was wrong.
    pub fn check(&self, grid: &Grid<D>) -> Result<(), (ErrorKind, String)> {
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
        if !grid.contains(&self.position) {
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

/// Completes particle `p`'s new state and says whether it is admissible.
pub type Finish<'a, const D: usize> = dyn Fn(usize, &mut ParticleUpdate<D>) -> bool + Sync + 'a;

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

/// Gathers the new velocity, affine matrix and position of every particle, and under USL its new
/// deformation gradient `(I + Δt L) F` (under MUSL that waits for the second map). Particles of
/// a rigid material (`rigid[material]` is its velocity) move with it and keep their `F`.
///
/// `finish(p, u)`, when given, completes particle `p`'s new state while it is in cache (the
/// constitutive update and the checks under USL) and says whether it is admissible; `admissible`
/// receives that (true for every particle without `finish`).
#[allow(clippy::too_many_arguments)]
pub fn grid_to_particle<const D: usize>(
    grid: &Grid<D>,
    ps: &Particles<D>,
    stencils: &impl StencilView<D>,
    fields: Fields<'_, D>,
    rigid: &[Option<Vector<D>>],
    plan: TransferPlan,
    dt: f64,
    finish: Option<&Finish<'_, D>>,
    updates: &mut Vec<ParticleUpdate<D>>,
    admissible: &mut Vec<bool>,
) {
    updates.resize(ps.len(), ParticleUpdate::default());
    let flip = plan.flip > 0.0;
    let update_deformation = finish.is_some();
    let apic_inertia = plan.inverse_inertia.is_some();
    let gather = |p: usize, u: &mut ParticleUpdate<D>| {
        let xp = ps.position[p];
        if let Some(v) = rigid.get(ps.material[p] as usize).copied().flatten() {
            u.position = xp + dt * v;
            u.velocity = v;
            u.affine = Matrix::zeros();
            u.deformation_gradient = ps.deformation_gradient[p];
            return;
        }
        let nodes = fields.of(p);
        let g = stencils.gather(
            grid,
            p,
            &xp,
            &nodes.velocity,
            flip.then_some(&nodes.velocity_old[..]),
            apic_inertia,
        );
        let (v_pic, dv, b, l) = (g.velocity, g.velocity_change, g.affine, g.gradient);
        u.position = xp + dt * v_pic;
        u.velocity = if flip {
            (1.0 - plan.flip) * v_pic + plan.flip * (ps.velocity[p] + dv)
        } else {
            v_pic
        };
        if plan.apic {
            u.affine = match plan.inverse_inertia {
                Some(inv) => b * inv,
                None => l,
            };
        }
        if update_deformation {
            u.deformation_gradient =
                (Matrix::<D>::identity() + dt * l) * ps.deformation_gradient[p];
        }
    };
    updates
        .par_iter_mut()
        .enumerate()
        .map(|(p, u)| {
            gather(p, u);
            finish.is_none_or(|f| f(p, u))
        })
        .collect_into_vec(admissible);
}
