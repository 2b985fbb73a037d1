//! Grid update: `v_I = ((mv)_I + Δt f_I) / m_I` with the wall conditions.

use crate::boundary::Walls;
use crate::grid::{Grid, GridNodes};
use crate::Vector;

/// Updates the velocities of the active nodes.
///
/// With `dt = Some(Δt)`: folds mass, momentum and force of mirrored walls, sets
/// `velocity_old = (mv)/m` and `velocity = ((mv) + Δt f)/m`, applies friction walls and sets the
/// ghost velocities. With `None` (the second map of MUSL): folds momentum only and sets
/// `velocity = (mv)/m`. Nodes with mass at or below `mass_floor` get zero velocity; nothing is
/// divided by a negligible mass.
pub fn grid_update<const D: usize>(
    grid: &Grid<D>,
    walls: &Walls<D>,
    nodes: &mut GridNodes<D>,
    dt: Option<f64>,
    mass_floor: f64,
) {
    walls.fold(grid, nodes, dt.is_some());
    for &n in &nodes.active {
        let m = nodes.mass[n];
        if m <= mass_floor {
            nodes.velocity[n] = Vector::zeros();
            nodes.velocity_old[n] = Vector::zeros();
            continue;
        }
        let p = nodes.momentum[n];
        match dt {
            Some(dt) => {
                nodes.velocity_old[n] = p / m;
                nodes.velocity[n] = (p + dt * nodes.force[n]) / m;
            }
            None => nodes.velocity[n] = p / m,
        }
    }
    walls.apply_friction(grid, nodes);
    walls.unfold(grid, nodes);
}
