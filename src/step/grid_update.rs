//! Grid update: `v_I = ((mv)_I + Δt f_I) / m_I` with the wall conditions.

use super::profile::lap;
use super::{StepInputs, Workspace};
use crate::energy::NodeLosses;
use crate::grid::{Grid, GridNodes, SharedSlice};
use crate::integration::BoundaryPoints;
use crate::options::Walls;
use crate::shape::StencilView;
use crate::{Matrix, Vector};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// Phase 4: the node velocities with the wall conditions, nodes at or below `mass_floor`
/// skipped: of the one field (without the force under MLS, which carries it in the momentum,
/// unless `boundary` has tractions), or under contact of each body's field and then the contact
/// correction. Keeps what friction and contact took in `work.node_losses`.
pub(super) fn phase<const D: usize, S: StencilView<D>>(
    inputs: &StepInputs<'_, D, S>,
    mass_floor: f64,
    boundary: &BoundaryPoints<D>,
    work: &mut Workspace<D>,
) {
    let mut clock = std::time::Instant::now();
    work.node_losses = match inputs.options.contact {
        Some(contact) => super::contact::grid_update_per_body(inputs, contact, &mut work.bodies),
        None => {
            let (plan, dt) = (inputs.plan, inputs.dt);
            let no_force = plan.mls_inverse_inertia().is_some() && !boundary.has_tractions();
            let friction = grid_update(
                inputs.grid,
                inputs.walls,
                &mut work.nodes,
                Some(dt),
                mass_floor,
                no_force,
            );
            NodeLosses {
                friction,
                contact: 0.0,
            }
        }
    };
    work.times.grid_update += lap(&mut clock);
}

/// Signed shape functions: the smallest node mass, as a fraction of the largest node mass, that
/// a node's internal force is divided by. Nodes that barely overlap a body have a tiny lumped
/// mass but not a tiny force; without this limit, an RK2 + VC2 column under its own weight at
/// 32 cells lets the velocities above its free surface grow until a boundary point inverts
/// (t ≈ 1.2 s). The body force is kept apart and not limited, so a uniform gravity stays exact.
/// VC: a node that the particles barely reach while a surface point is near it gets the
/// correction its divergence equality asks for, large against its mass; without this limit a
/// quadratic B-spline + VC block with a smooth small-strain velocity field stopped at step 74
/// (2D) or 77 (3D) with an inverted boundary point. The force held back is handed to the whole
/// field as one mass-weighted acceleration (without walls), so momentum is conserved.
const EDGE_MASS_FRACTION: f64 = 1e-2;

/// The node mass the internal force is divided by at least: [`EDGE_MASS_FRACTION`] of the
/// largest node mass.
pub(super) fn edge_mass_floor<const D: usize>(nodes: &GridNodes<D>) -> f64 {
    EDGE_MASS_FRACTION
        * nodes
            .active
            .iter()
            .map(|&n| nodes.mass[n])
            .fold(0.0, f64::max)
}

/// Updates the velocities of the active nodes.
///
/// With `dt = Some(Δt)`: folds mass, momentum and force of mirrored walls, sets
/// `velocity_old = (mv)/m` and `velocity = ((mv) + Δt f)/m`, applies friction walls and sets the
/// ghost velocities. With `None` (the second map of MUSL): folds momentum only and sets
/// `velocity = (mv)/m`. Nodes with mass at or below `mass_floor` get zero velocity; nothing is
/// divided by a negligible mass. Returns the kinetic energy the friction walls took from the
/// nodes ([`Walls::apply_friction`]).
///
/// `no_force`: nothing was mapped to `force` (MLS without tractions, whose forces ride on the
/// momentum). Without a body force kept apart, the velocity is then
/// `(mv)/m + 0` (the same bits as the whole expression with zero forces: adding `+0` turns a
/// `−0` into `+0`, as adding the zero forces does) and `velocity_old`, which only FLIP reads,
/// is left at zero: two divisions less per node.
pub fn grid_update<const D: usize>(
    grid: &Grid<D>,
    walls: &Walls<D>,
    nodes: &mut GridNodes<D>,
    dt: Option<f64>,
    mass_floor: f64,
    no_force: bool,
) -> f64 {
    walls.fold(grid, nodes, dt.is_some());
    // Signed shape functions: nodes at the edge of a body have a tiny mass but not a tiny
    // force; their acceleration is taken against at least a fraction of the largest node mass
    // (see [`EDGE_MASS_FRACTION`]). The limit is on exactly when the body force is kept apart.
    let force_mass_floor = match (!nodes.body_force.is_empty(), dt) {
        (true, Some(_)) => edge_mass_floor(nodes),
        _ => 0.0,
    };
    // Every active node on its own, in parallel (the list holds each node once).
    let GridNodes {
        mass,
        momentum,
        force,
        velocity_old,
        velocity,
        body_force,
        active,
        ..
    } = nodes;
    let (mass, momentum) = (SharedSlice::new(mass), SharedSlice::new(momentum));
    let (velocity_old, velocity) = (SharedSlice::new(velocity_old), SharedSlice::new(velocity));
    let (force, body_force) = (&*force, &*body_force);
    let momentum_only = no_force && body_force.is_empty();
    active.par_iter().for_each(|&n| {
        // SAFETY: `active` lists each node once, so every node is written by one task only.
        let (m, p) = unsafe { (mass.at(n), momentum.at(n)) };
        // Body force apart from the internal force (the mass floor limits only the internal
        // part, so that a uniform gravity stays exact).
        let body = match dt {
            Some(_) if !body_force.is_empty() => body_force[n],
            _ => Vector::<D>::zeros(),
        };
        // SAFETY: as above.
        let (v_old, v) = unsafe { (velocity_old.at(n), velocity.at(n)) };
        if *m <= mass_floor {
            *v = Vector::zeros();
            *v_old = Vector::zeros();
            return;
        }
        match dt {
            Some(_) if momentum_only => *v = *p / *m + Vector::zeros(),
            Some(dt) => {
                *v_old = *p / *m;
                *v = (*p + dt * body) / *m + dt * force[n] / m.max(force_mass_floor);
            }
            None => *v = *p / *m,
        }
    });
    // The force the edge-mass floor held back, and the momentum and forces of the nodes at or
    // below the mass floor (which get no velocity), handed to the whole field as one rigid-body
    // acceleration (see [`rigid_acceleration`]), so that the field's momentum and angular
    // momentum still change by Σ f Δt and Σ x × f Δt; with walls, which take momentum anyway and
    // must not be pushed through, they are dropped. Sums in node order: the same bits with any
    // number of threads.
    if let (Some(dt), true) = (dt, force_mass_floor > 0.0 && !walls.any_wall()) {
        let mut held = Vec::new();
        for &n in &nodes.active {
            let m = nodes.mass[n];
            let h = if m > mass_floor {
                if m >= force_mass_floor {
                    continue;
                }
                nodes.force[n] * (1.0 - m / force_mass_floor)
            } else {
                let body = match nodes.body_force.is_empty() {
                    true => Vector::zeros(),
                    false => nodes.body_force[n],
                };
                nodes.force[n] + nodes.momentum[n] / dt + body
            };
            if h != Vector::<D>::zeros() {
                held.push((grid.node_position(grid.node_multi_index(n)), h));
            }
        }
        let receivers: Vec<(Vector<D>, f64)> = nodes
            .active
            .iter()
            .filter(|&&n| nodes.mass[n] > mass_floor)
            .map(|&n| (grid.node_position(grid.node_multi_index(n)), nodes.mass[n]))
            .collect();
        if let Some((centre, linear, angular)) = rigid_acceleration(&receivers, &held) {
            let GridNodes {
                mass,
                velocity,
                active,
                ..
            } = nodes;
            let velocity = SharedSlice::new(velocity);
            active.par_iter().for_each(|&n| {
                if mass[n] > mass_floor {
                    let r = grid.node_position(grid.node_multi_index(n)) - centre;
                    // SAFETY: `active` lists each node once.
                    unsafe { *velocity.at(n) += dt * (linear + angular * r) };
                }
            });
        }
    }
    let friction = walls.apply_friction(grid, nodes);
    walls.unfold(grid, nodes);
    friction
}

/// The rigid-body acceleration `a + A (x − x_c)` of the `receivers` (position, mass) whose
/// force and moment about the origin are those of the `held` forces (position, force):
/// `Σ m a = Σ f`, and `A` antisymmetric with `Σ m (r ⊗ A r − A r ⊗ r) = Σ (r_f ⊗ f − f ⊗ r_f)`
/// about the receivers' mass centre `x_c`, that is `A J + J A = Σ (f ⊗ r_f − r_f ⊗ f)`,
/// `J = Σ m r rᵀ` (in 3D `A = [α]×` with `(tr J − J) α` the torque). Returns `(x_c, a, A)`,
/// `A` zero where `J` cannot carry it (receivers on one line), None without mass or force.
pub(super) fn rigid_acceleration<const D: usize>(
    receivers: &[(Vector<D>, f64)],
    held: &[(Vector<D>, Vector<D>)],
) -> Option<(Vector<D>, Vector<D>, Matrix<D>)> {
    let total: f64 = receivers.iter().map(|(_, m)| m).sum();
    if total <= 0.0 || held.is_empty() {
        return None;
    }
    let centre = receivers.iter().map(|(x, m)| x * *m).sum::<Vector<D>>() / total;
    let force: Vector<D> = held.iter().map(|(_, f)| f).sum();
    let (mut second, mut torque) = (Matrix::<D>::zeros(), Matrix::<D>::zeros());
    for (x, m) in receivers {
        let r = x - centre;
        second += *m * r * r.transpose();
    }
    for (x, f) in held {
        let r = x - centre;
        torque += f * r.transpose() - r * f.transpose();
    }
    // The antisymmetric unit matrices E_ab (a < b), and the map A ↦ A J + J A on them.
    let pairs: Vec<(usize, usize)> = (0..D)
        .flat_map(|a| (a + 1..D).map(move |b| (a, b)))
        .collect();
    let unit = |(a, b): (usize, usize)| {
        let mut e = Matrix::<D>::zeros();
        e[(b, a)] = 1.0;
        e[(a, b)] = -1.0;
        e
    };
    let map = DMatrix::from_fn(pairs.len(), pairs.len(), |i, j| {
        let e = unit(pairs[j]);
        let image = e * second + second * e;
        image[(pairs[i].1, pairs[i].0)]
    });
    let target = DVector::from_iterator(pairs.len(), pairs.iter().map(|&(a, b)| torque[(b, a)]));
    let coefficients = map
        .lu()
        .solve(&target)
        .filter(|c| c.iter().all(|c| c.is_finite()));
    let angular = match coefficients {
        Some(c) => pairs.iter().zip(c.iter()).map(|(&p, &c)| unit(p) * c).sum(),
        None => Matrix::zeros(),
    };
    Some((centre, force / total, angular))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::walls::Wall;

    /// With nothing mapped to `force`, the momentum-only update (`no_force`) gives the node
    /// velocities of the whole update bit for bit, signed zeros and a slip wall included.
    #[test]
    fn the_momentum_only_update_gives_the_bits_of_the_whole_one() {
        let grid = Grid::<2>::new(Vector::<2>::zeros(), [6, 6], 0.5).unwrap();
        let mut nodes = GridNodes::<2>::default();
        nodes.ensure(&grid, false, false, false).unwrap();
        let mut walls = Walls::<2>::default();
        walls.faces[0][0] = Wall::Slip;
        for n in 0..grid.node_count() {
            let k = n as f64;
            nodes.mass[n] = if n % 7 == 3 {
                0.0
            } else {
                0.1 + 0.37 * (k * 0.71).sin().abs()
            };
            nodes.momentum[n] = match n % 5 {
                0 => Vector::<2>::new(-0.0, 0.0),
                1 => Vector::<2>::new(0.0, -0.0),
                _ => Vector::<2>::new((k * 1.3).cos(), -(k * 0.9).sin() / 3.0),
            };
            nodes.collect_touched(n);
        }
        let dt = 1e-3;
        let (mut whole, mut momentum_only) = (nodes.clone(), nodes);
        grid_update(&grid, &walls, &mut whole, Some(dt), 1e-12, false);
        grid_update(&grid, &walls, &mut momentum_only, Some(dt), 1e-12, true);
        let bits = |v: &[Vector<2>]| -> Vec<[u64; 2]> {
            v.iter().map(|v| [v[0].to_bits(), v[1].to_bits()]).collect()
        };
        assert_eq!(bits(&whole.velocity), bits(&momentum_only.velocity));
        assert!(whole.velocity.iter().any(|v| v[0] != 0.0));
    }
}
