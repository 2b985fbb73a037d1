//! The walls: boundary conditions of the grid on the faces of the domain (not to be confused
//! with boundary points, the surface quadrature points of `crate::integration`).
//!
//! * `Fixed` and `Slip` walls use the **mirror treatment** (METHOD.md section 7): the ghost layers
//!   beyond the face hold the mirror image of the body. A ghost node's mass folds onto its mirror
//!   node; its momentum and force fold on with the sign of the wall condition (every component
//!   reversed for a fixed wall, the normal component reversed for a slip wall); the node on the face
//!   keeps only the free components. After the grid update the ghost velocities are the mirror
//!   images again. Overwriting ghost velocities instead would make every smooth shape function first
//!   order next to a wall.
//! * `Friction` is a unilateral Coulomb contact applied to the nodes on and beyond the face: a node
//!   moving into the wall loses its normal velocity and its tangential speed drops by `μ |v_n|`
//!   (sticking when that exceeds it); a node moving away is free.
//! * `Free` does nothing; the ghost layers act as ordinary nodes.

use crate::error::{check_finite, Error, Result};
use crate::grid::{DomainBox, Grid, GridNodes};
use crate::Vector;

pub use crate::options::{Side, Wall, WallKind, Walls};

impl Side {
    pub fn from_sign(side: i32) -> Result<Side> {
        match side {
            -1 => Ok(Side::Low),
            1 => Ok(Side::High),
            _ => Err(Error::invalid(format!(
                "side must be -1 (low) or +1 (high), got {side}"
            ))),
        }
    }
}

impl Wall {
    /// Fails for a negative or non-finite friction coefficient.
    pub fn validate(&self) -> Result<()> {
        if let Wall::Friction(mu) = *self {
            check_finite("friction", mu)?;
            if mu < 0.0 {
                return Err(Error::invalid(format!("friction must be >= 0, got {mu}")));
            }
        }
        Ok(())
    }

    /// Whether this wall uses the mirror treatment.
    fn mirrors(&self) -> bool {
        matches!(self, Wall::Fixed | Wall::Slip)
    }

    /// Mirror sign of velocity component `c` for a wall normal to `axis`.
    fn sign(&self, axis: usize, c: usize) -> f64 {
        match self {
            Wall::Fixed => -1.0,
            Wall::Slip if c == axis => -1.0,
            _ => 1.0,
        }
    }

    fn reflect<const D: usize>(&self, axis: usize, v: &Vector<D>) -> Vector<D> {
        Vector::<D>::from_fn(|c, _| self.sign(axis, c) * v[c])
    }
}

/// How far node `i` lies beyond face (`axis`, `side`): 0 on the face, > 0 in the ghost layers.
#[inline]
fn depth<const D: usize>(grid: &Grid<D>, i: &[i64; D], axis: usize, side: Side) -> i64 {
    match side {
        Side::Low => -i[axis],
        Side::High => i[axis] - grid.cells[axis] as i64,
    }
}

#[inline]
fn mirror<const D: usize>(
    grid: &Grid<D>,
    mut i: [i64; D],
    axis: usize,
    side: Side,
    d: i64,
) -> [i64; D] {
    i[axis] = match side {
        Side::Low => d,
        Side::High => grid.cells[axis] as i64 - d,
    };
    i
}

impl<const D: usize> Walls<D> {
    /// Fails when a mirrored wall has fewer cells along its axis than the ghost layers it folds.
    pub fn check_fits(&self, grid: &Grid<D>) -> Result<()> {
        for a in 0..D {
            if self.faces[a].iter().any(|b| b.mirrors()) && grid.cells[a] < grid.ghost_layers() {
                return Err(Error::invalid(format!(
                    "a fixed or slip wall on axis {a} needs at least {} cells along it, the grid has {}",
                    grid.ghost_layers(),
                    grid.cells[a]
                )));
            }
        }
        Ok(())
    }

    fn mirrored_faces(&self) -> impl Iterator<Item = (usize, Side, Wall)> + '_ {
        (0..D).flat_map(move |a| {
            [Side::Low, Side::High]
                .into_iter()
                .map(move |s| (a, s, self.faces[a][s as usize]))
                .filter(|(_, _, b)| b.mirrors())
        })
    }

    /// Folds ghost-layer momentum (and, when `with_mass_and_force`, mass and force) onto the
    /// mirror nodes, and removes the constrained components on the face nodes.
    pub fn fold(&self, grid: &Grid<D>, nodes: &mut GridNodes<D>, with_mass_and_force: bool) {
        for (axis, side, wall) in self.mirrored_faces() {
            // The list grows when a mirror node is touched for the first time; the new entries lie
            // inside the domain along `axis` and need no folding for it.
            for k in 0..nodes.active.len() {
                let n = nodes.active[k];
                let i = grid.node_multi_index(n);
                let d = depth(grid, &i, axis, side);
                if d > 0 {
                    let m = grid.node_index(mirror(grid, i, axis, side, d));
                    nodes.touch(m);
                    let p = wall.reflect(axis, &nodes.momentum[n]);
                    nodes.momentum[m] += p;
                    nodes.momentum[n] = Vector::zeros();
                    if with_mass_and_force {
                        nodes.mass[m] += nodes.mass[n];
                        let f = wall.reflect(axis, &nodes.force[n]);
                        nodes.force[m] += f;
                        nodes.mass[n] = 0.0;
                        nodes.force[n] = Vector::zeros();
                        if !nodes.body_force.is_empty() {
                            let b = wall.reflect(axis, &nodes.body_force[n]);
                            nodes.body_force[m] += b;
                            nodes.body_force[n] = Vector::zeros();
                        }
                    }
                    if let Some(l) = nodes.lumping.as_mut().filter(|_| with_mass_and_force) {
                        l.mass[m] += l.mass[n];
                        l.mass[n] = 0.0;
                    }
                } else if d == 0 {
                    for c in 0..D {
                        if wall.sign(axis, c) < 0.0 {
                            nodes.momentum[n][c] = 0.0;
                            nodes.force[n][c] = 0.0;
                            if !nodes.body_force.is_empty() {
                                nodes.body_force[n][c] = 0.0;
                            }
                        }
                    }
                }
            }
        }
    }

    /// Sets ghost-layer velocities to the mirror images of their mirror nodes (reverse order of
    /// `fold`, so that corner ghosts end up with the image of an image).
    pub fn unfold(&self, grid: &Grid<D>, nodes: &mut GridNodes<D>) {
        let faces: Vec<_> = self.mirrored_faces().collect();
        for &(axis, side, wall) in faces.iter().rev() {
            for k in 0..nodes.active.len() {
                let n = nodes.active[k];
                let i = grid.node_multi_index(n);
                let d = depth(grid, &i, axis, side);
                if d > 0 {
                    let m = grid.node_index(mirror(grid, i, axis, side, d));
                    nodes.velocity[n] = wall.reflect(axis, &nodes.velocity[m]);
                    nodes.velocity_old[n] = wall.reflect(axis, &nodes.velocity_old[m]);
                }
            }
        }
    }

    /// Sets each ghost-layer node's value in `values` to its mirror node's (a scalar per node,
    /// in the order of [`Walls::unfold`]), for the nodes in `active`.
    pub fn unfold_values(&self, grid: &Grid<D>, active: &[usize], values: &mut [f64]) {
        let faces: Vec<_> = self.mirrored_faces().collect();
        for &(axis, side, _) in faces.iter().rev() {
            for &n in active {
                let i = grid.node_multi_index(n);
                let d = depth(grid, &i, axis, side);
                if d > 0 {
                    values[n] = values[grid.node_index(mirror(grid, i, axis, side, d))];
                }
            }
        }
    }

    /// Moves a point that the step put just beyond a wall (fixed, slip or friction) back onto
    /// its face: the grid velocity has no normal component into the wall on the face, but a
    /// point near it also feels the nodes above, and round-off or that blend may carry it a
    /// hair past the face. Free faces leave points alone (leaving the grid is then an error).
    pub fn clamp_to_walls(&self, domain: &DomainBox<D>, x: &mut Vector<D>) {
        for axis in 0..D {
            for side in [Side::Low, Side::High] {
                if self.faces[axis][side as usize] == Wall::Free {
                    continue;
                }
                let c = &mut x[axis];
                match side {
                    Side::Low => *c = c.max(domain.lower[axis]),
                    Side::High => *c = c.min(domain.upper[axis]),
                }
            }
        }
    }

    /// Whether a wall acts on node `i`: it lies on a wall's face or beyond it.
    pub fn acts_on(&self, grid: &Grid<D>, i: &[i64; D]) -> bool {
        (0..D).any(|a| {
            [Side::Low, Side::High]
                .into_iter()
                .any(|s| self.faces[a][s as usize] != Wall::Free && depth(grid, i, a, s) >= 0)
        })
    }

    /// Whether any face is a wall.
    pub fn any_wall(&self) -> bool {
        self.faces.iter().flatten().any(|b| *b != Wall::Free)
    }

    /// Applies the friction walls to the updated node velocities.
    ///
    /// Returns the work of the friction on the slip it leaves, `Σ m_I (v_I − v_I*)·v_I*` over
    /// the nodes whose velocity it changed (in node order): the impulse against the velocity
    /// after it, whose normal part is zero, so the wall's constraint (an impact's normal loss,
    /// as at a mirror wall) is not counted as friction.
    pub fn apply_friction(&self, grid: &Grid<D>, nodes: &mut GridNodes<D>) -> f64 {
        let mut taken = 0.0;
        for axis in 0..D {
            for side in [Side::Low, Side::High] {
                let Wall::Friction(mu) = self.faces[axis][side as usize] else {
                    continue;
                };
                let outward = if side == Side::Low { -1.0 } else { 1.0 };
                for k in 0..nodes.active.len() {
                    let n = nodes.active[k];
                    if depth(grid, &grid.node_multi_index(n), axis, side) < 0 {
                        continue;
                    }
                    let v = &mut nodes.velocity[n];
                    let vn = outward * v[axis];
                    if vn <= 0.0 {
                        continue;
                    }
                    v[axis] = 0.0;
                    let tangential = *v;
                    let vt = v.norm();
                    if vt <= mu * vn {
                        *v = Vector::zeros();
                    } else {
                        *v *= 1.0 - mu * vn / vt;
                    }
                    taken += nodes.mass[n] * (tangential - *v).dot(v);
                }
            }
        }
        taken
    }
}
