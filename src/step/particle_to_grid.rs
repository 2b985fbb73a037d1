//! Particle to grid: `m_I = Σ m_p Ψ_Ip`, `(mv)_I = Σ m_p Ψ_Ip (v_p + C_p (x_I − x_p))`,
//! `f_I = −Σ V_p σ_p ∇Ψ_Ip + Σ m_p Ψ_Ip b_p`.
//!
//! For a signed shape function (RK of order ≥ 2) the same sums with the nonnegative lumping
//! weights `L_I` are kept as shifts `Σ m_p (L_Ip − Ψ_Ip)(1, v_p, b_p)`, which the grid update
//! blends in at nodes that barely overlap a body.

use crate::grid::{Grid, GridNodes};
use crate::integration::VcCorrection;
use crate::particles::Particles;
use crate::shape::Stencils;
use crate::{Matrix, Vector};

/// What the first map accumulates besides momentum: mass and forces.
#[derive(Clone, Copy)]
pub struct Forces<'a, const D: usize> {
    pub gravity: Vector<D>,
    /// Per-particle body accelerations from the callback, if any.
    pub body: Option<&'a [Vector<D>]>,
    /// Gradient corrections of VC integration (internal force only), if on.
    pub vc: Option<&'a VcCorrection<D>>,
}

/// Scatters particle quantities to the nodes of their stencils and marks those nodes active.
///
/// * `velocity(p)` and `affine(p)` give the velocity and, under APIC, `C_p` to map (the
///   particle's own, or the updated ones in the second map of MUSL).
/// * `forces`: `Some(..)` also accumulates mass and force; `None` maps momentum only.
///
/// * `body`: with contact, only the particles of this material map (to its own field).
///
/// Serial in particle order, so the sums do not depend on the thread count.
#[allow(clippy::too_many_arguments)]
pub fn particle_to_grid<const D: usize>(
    grid: &Grid<D>,
    ps: &Particles<D>,
    stencils: &Stencils<D>,
    velocity: &(dyn Fn(usize) -> Vector<D> + Sync),
    affine: Option<&(dyn Fn(usize) -> Matrix<D> + Sync)>,
    forces: Option<Forces<D>>,
    body: Option<u32>,
    nodes: &mut GridNodes<D>,
) {
    let with_gradient = !nodes.mass_gradient.is_empty() && forces.is_some();
    for p in 0..ps.len() {
        if body.is_some_and(|b| ps.material[p] != b) {
            continue;
        }
        let (ns, ws, gs) = stencils.of(p);
        let lumping = stencils.lumping_of(p);
        let m = ps.mass[p];
        let v = velocity(p);
        let c = affine.map(|a| a(p));
        let xp = ps.position[p];
        let vc = forces.and_then(|f| f.vc);
        let force = forces.map(|f| {
            let b = match f.body {
                Some(b) => f.gravity + b[p],
                None => f.gravity,
            };
            (-ps.volume(p) * ps.stress[p], b)
        });
        for s in 0..ns.len() {
            let (n, w) = (ns[s], ws[s]);
            let shift = lumping.map_or(0.0, |l| l[s] - w);
            if w == 0.0 && shift == 0.0 && gs[s] == Vector::<D>::zeros() {
                continue;
            }
            nodes.touch(n);
            let mut mv = v;
            if let Some(c) = c {
                mv += c * (grid.node_position(grid.node_multi_index(n)) - xp);
            }
            nodes.momentum[n] += (m * w) * mv;
            if let Some(l) = nodes.lumping.as_mut() {
                l.momentum[n] += (m * shift) * mv;
                if let Some((_, b)) = force {
                    l.mass[n] += m * shift;
                    l.body_force[n] += (m * shift) * b;
                }
            }
            if let Some((vs, b)) = force {
                let grad = match vc {
                    Some(vc) => gs[s] + vc.gradient_correction(grid, nodes, n, &xp),
                    None => gs[s],
                };
                nodes.mass[n] += m * w;
                if with_gradient {
                    nodes.mass_gradient[n] += m * gs[s];
                }
                nodes.force[n] += vs * grad;
                if nodes.body_force.is_empty() {
                    nodes.force[n] += (m * w) * b;
                } else {
                    nodes.body_force[n] += (m * w) * b;
                }
            }
        }
    }
}
