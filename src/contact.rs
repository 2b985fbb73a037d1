//! Contact between bodies: the multi-velocity-field grid contact of Bardenhagen, Brackbill &
//! Sulsky (2000) with Coulomb friction, and rigid bodies with a prescribed velocity.
//!
//! With contact on, every material is a body with its own grid velocity field: particles map to
//! (and read from) the nodes of their own body only, so bodies interpenetrate nowhere on the grid
//! by themselves. Where two bodies share a node after the grid update, their velocities are
//! compared with the centre-of-mass velocity `v_cm = Σ m_b v_b / Σ m_b`. A body that moves
//! toward the other along the contact normal (`(v_b − v_cm)·n_b > 0`) loses that normal
//! part, and its tangential part relative to `v_cm` is reduced by `μ` times the normal part
//! (stick when that exceeds it). Separating bodies are left alone: contact is unilateral.
//!
//! * Normal: from `g_b = Σ_p m_p ∇Ψ_I(x_p)` over the particles of body `b`, which is minus the
//!   spatial gradient of its mass field at the node and so points out of the body. With two
//!   bodies at a node, `n_a = (g_a − g_b)/|g_a − g_b|` (out of `a`, into `b`) and `n_b = −n_a`;
//!   the corrections of the two bodies are then equal and opposite, so momentum is conserved
//!   exactly. With more bodies at a node each uses its own `g_b/|g_b|`.
//! * Rigid bodies move with their prescribed velocity and do not deform; at a shared node their
//!   velocity replaces `v_cm` (infinite mass), so they push the others and are not pushed back.
//!   The normal there is the rigid body's own, `−g_r/|g_r|` into it: its surface is exact, while
//!   the difference of the two gradients tilts at the corner of a deformable body beside it, and
//!   a rigid plate sliding past that corner then drags it along even without friction.

use crate::grid::GridNodes;
use crate::Vector;

pub use crate::options::Contact;

/// Applies the contact correction to the updated velocities of the per-body node fields, at
/// every node that more than one body touched. `rigid[b]` is the prescribed velocity of body `b`
/// if it is rigid.
pub fn correct_velocities<const D: usize>(
    contact: &Contact,
    bodies: &mut [GridNodes<D>],
    rigid: &[Option<Vector<D>>],
    shared: &[usize],
) {
    let mu = contact.friction;
    let mut here: Vec<usize> = Vec::with_capacity(bodies.len());
    for &n in shared {
        here.clear();
        here.extend(
            (0..bodies.len()).filter(|&b| bodies[b].is_touched(n) && bodies[b].mass[n] > 0.0),
        );
        if here.len() < 2 {
            continue;
        }
        // A rigid body here sets the velocity (infinite mass) and the normal.
        let rigid_body = here.iter().copied().find(|&b| rigid[b].is_some());
        let v_cm = match rigid_body.and_then(|r| rigid[r]) {
            Some(v) => v,
            None => {
                let (mut p, mut m) = (Vector::<D>::zeros(), 0.0);
                for &b in &here {
                    p += bodies[b].mass[n] * bodies[b].velocity[n];
                    m += bodies[b].mass[n];
                }
                p / m
            }
        };
        // A rigid body's surface is exact (it never deforms), so its own mass gradient gives
        // the normal: into it, `−g_r/|g_r|`, for every body it touches here.
        let rigid_normal = rigid_body
            .map(|r| -bodies[r].mass_gradient[n])
            .and_then(|g| (g.norm() > 0.0).then(|| g / g.norm()));
        let pair_normal = (here.len() == 2).then(|| {
            let (a, b) = (here[0], here[1]);
            let d = bodies[a].mass_gradient[n] - bodies[b].mass_gradient[n];
            (d.norm() > 0.0).then(|| d / d.norm())
        });
        for (k, &b) in here.iter().enumerate() {
            if rigid[b].is_some() {
                continue;
            }
            let normal = match (rigid_normal, pair_normal) {
                (Some(into_rigid), _) => into_rigid,
                (None, Some(Some(n_a))) => {
                    if k == 0 {
                        n_a
                    } else {
                        -n_a
                    }
                }
                (None, _) => {
                    let g = bodies[b].mass_gradient[n];
                    if g.norm() == 0.0 {
                        continue;
                    }
                    g / g.norm()
                }
            };
            let v = bodies[b].velocity[n];
            let relative = v - v_cm;
            let approach = relative.dot(&normal);
            if approach <= 0.0 {
                continue;
            }
            let tangential = relative - approach * normal;
            let slip = tangential.norm();
            bodies[b].velocity[n] = if slip <= mu * approach {
                v_cm
            } else {
                v - approach * normal - (mu * approach / slip) * tangential
            };
        }
    }
}
