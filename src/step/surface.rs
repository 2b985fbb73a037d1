//! The surface of the bodies in a step: the tractions of the boundary points on the grid, their
//! motion with the grid (like massless particles, with Nanson's formula for `n a`) and their
//! checks, and the surface VC finds from the particles when no boundary points are given.

use crate::error::Result;
use crate::grid::{DomainBox, Grid, GridNodes};
use crate::integration::BoundaryPoints;
use crate::options::Walls;
use crate::particles::Particles;
use crate::shape::Stencils;
use crate::{Matrix, Vector};
use rayon::prelude::*;

/// The new state of one boundary point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoundaryUpdate<const D: usize> {
    pub position: Vector<D>,
    pub deformation_gradient: Matrix<D>,
    pub area_normal: Vector<D>,
}

/// The surface of the particles as they are now ([`BoundaryPoints::of_particles`]): of all of
/// them, or under contact of those of material `body` only.
pub(crate) fn found_surface<const D: usize>(
    grid: &Grid<D>,
    ps: &Particles<D>,
    body: Option<u32>,
) -> Result<BoundaryPoints<D>> {
    let box_ = (&grid.origin, &grid.upper());
    let (x, na) = match body {
        None => BoundaryPoints::of_particles(
            box_,
            grid.cell_size,
            &ps.position,
            &ps.reference_volume,
            &ps.deformation_gradient,
        ),
        Some(body) => {
            let members: Vec<usize> = (0..ps.len()).filter(|&p| ps.material[p] == body).collect();
            BoundaryPoints::of_particles(
                box_,
                grid.cell_size,
                &gather(&ps.position, &members),
                &gather(&ps.reference_volume, &members),
                &gather(&ps.deformation_gradient, &members),
            )
        }
    };
    let mut surface = BoundaryPoints::default();
    surface.add(&x, &na, None)?;
    Ok(surface)
}

/// `values[p]` for each `p` of `members`.
fn gather<T: Copy>(values: &[T], members: &[usize]) -> Vec<T> {
    members.iter().map(|&p| values[p]).collect()
}

/// Adds the traction forces `Σ_b Ψ_I(x_b) t_b |n a|_b` of the boundary points.
pub(super) fn apply_tractions<const D: usize>(
    boundary: &BoundaryPoints<D>,
    stencils: &Stencils<D>,
    nodes: &mut GridNodes<D>,
) {
    for b in 0..boundary.len() {
        let force = boundary.traction[b] * boundary.area_normal[b].norm();
        let (ns, ws, _) = stencils.of(b);
        for (&n, &w) in ns.iter().zip(ws) {
            if w != 0.0 {
                nodes.touch(n);
                nodes.force[n] += w * force;
            }
        }
    }
}

/// The new state of the boundary points after the grid update: each moves with the velocity
/// the grid interpolates at it, `F_b` with the grid's velocity gradient, and `n a` by Nanson's
/// formula `J F⁻ᵀ N A` (NaN where `F` is singular, which the checks reject).
pub(super) fn move_boundary_points<const D: usize>(
    boundary: &BoundaryPoints<D>,
    bs: &Stencils<D>,
    nodes: &GridNodes<D>,
    dt: f64,
    updates: &mut Vec<BoundaryUpdate<D>>,
) {
    let moved = (0..boundary.len()).into_par_iter().map(|b| {
        // The velocity and its gradient in one pass over the point's stencil.
        let (ns, ws, gs) = bs.of(b);
        let mut v = Vector::<D>::zeros();
        let mut l = Matrix::<D>::zeros();
        for ((&n, &w), g) in ns.iter().zip(ws).zip(gs) {
            let vn = nodes.velocity[n];
            v += w * vn;
            l += vn * g.transpose();
        }
        let f = (Matrix::<D>::identity() + dt * l) * boundary.deformation_gradient[b];
        let j = crate::determinant(&f);
        let area_normal = f
            .try_inverse()
            .map_or(Vector::from_element(f64::NAN), |fi| {
                j * fi.transpose() * boundary.reference_area_normal[b]
            });
        BoundaryUpdate {
            position: boundary.position[b] + dt * v,
            deformation_gradient: f,
            area_normal,
        }
    });
    updates.par_extend(moved);
}

/// Keeps the moved boundary points on a wall on it (round-off may not push them out), then
/// returns the first one that is not admissible and why: a non-finite value, an inverted `F`,
/// or a position outside the grid.
pub(super) fn settle_boundary_points<const D: usize>(
    walls: &Walls<D>,
    domain: &DomainBox<D>,
    updates: &mut [BoundaryUpdate<D>],
) -> Option<(usize, &'static str)> {
    for u in updates.iter_mut() {
        walls.clamp_to_walls(domain, &mut u.position);
    }
    updates.iter().enumerate().find_map(|(b, u)| {
        let what = if !u
            .position
            .iter()
            .chain(u.area_normal.iter())
            .all(|c| c.is_finite())
        {
            "has a non-finite value"
        } else if crate::determinant(&u.deformation_gradient) <= 0.0 {
            "is inverted"
        } else if !domain.contains(&u.position) {
            "would leave the grid"
        } else {
            return None;
        };
        Some((b, what))
    })
}
