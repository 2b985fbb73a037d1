//! Boundary points: quadrature points on the material's surface, with an outward area-weighted
//! normal `n a` (length in 2D), optional tractions, and their own deformation gradient. They move
//! with the grid velocity like massless particles and update `n a = J F⁻ᵀ N A` (Nanson).

use crate::error::{check_finite, Error, Result};
use crate::{Matrix, Vector};
use std::collections::HashMap;

/// Surface quadrature points of all bodies, structure of arrays.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct BoundaryPoints<const D: usize> {
    pub position: Vec<Vector<D>>,
    /// Area-weighted outward normal at insertion, `N A`.
    pub reference_area_normal: Vec<Vector<D>>,
    /// Current area-weighted outward normal, `n a = J F⁻ᵀ N A`.
    pub area_normal: Vec<Vector<D>>,
    pub deformation_gradient: Vec<Matrix<D>>,
    /// Traction (force per current area) at each point; empty when no point carries one.
    pub traction: Vec<Vector<D>>,
}

impl<const D: usize> BoundaryPoints<D> {
    pub fn len(&self) -> usize {
        self.position.len()
    }

    pub fn is_empty(&self) -> bool {
        self.position.is_empty()
    }

    /// Whether any point carries a traction.
    pub fn has_tractions(&self) -> bool {
        !self.traction.is_empty()
    }

    /// Appends points. `area_normals` are outward normals times area (length in 2D), non-zero;
    /// `tractions` (force per area) may be `None`. All or nothing.
    pub fn add(
        &mut self,
        positions: &[Vector<D>],
        area_normals: &[Vector<D>],
        tractions: Option<&[Vector<D>]>,
    ) -> Result<()> {
        let n = positions.len();
        if area_normals.len() != n || tractions.is_some_and(|t| t.len() != n) {
            return Err(Error::invalid(
                "boundary positions, area normals and tractions differ in length",
            ));
        }
        for b in 0..n {
            for a in 0..D {
                check_finite("boundary point position", positions[b][a])?;
                check_finite("boundary point area normal", area_normals[b][a])?;
                if let Some(t) = tractions {
                    check_finite("boundary point traction", t[b][a])?;
                }
            }
            if area_normals[b].norm() == 0.0 {
                return Err(Error::invalid(format!(
                    "boundary point {b} has a zero area normal"
                )));
            }
        }
        let before = self.len();
        if tractions.is_some() && self.traction.is_empty() {
            self.traction.resize(before, Vector::zeros());
        }
        self.position.extend_from_slice(positions);
        self.reference_area_normal.extend_from_slice(area_normals);
        self.area_normal.extend_from_slice(area_normals);
        self.deformation_gradient
            .extend(std::iter::repeat_n(Matrix::<D>::identity(), n));
        match tractions {
            Some(t) => self.traction.extend_from_slice(t),
            None if !self.traction.is_empty() => self
                .traction
                .extend(std::iter::repeat_n(Vector::zeros(), n)),
            None => {}
        }
        Ok(())
    }

    /// Boundary points of bodies whose particles sit on a lattice of spacing `V_p^{1/D}`: every
    /// particle face with no neighbour across it gets a point at the face centre, with normal
    /// `± e_a` times the face area `s^{D−1}`. Neighbours are looked for within a quarter spacing
    /// of the lattice site.
    pub fn from_lattice(
        positions: &[Vector<D>],
        volumes: &[f64],
    ) -> (Vec<Vector<D>>, Vec<Vector<D>>) {
        let spacing: Vec<f64> = volumes.iter().map(|v| v.powf(1.0 / D as f64)).collect();
        // Bins as large as the largest spacing: a neighbour within a quarter spacing of a site
        // is then in the site's bin or next to it, however different the particle sizes are
        // (binning by the smallest spacing made the search span grow as the ratio of the
        // spacings, without bound: found by fuzzing).
        let bin = spacing.iter().copied().fold(0.0, f64::max);
        let key =
            |x: &Vector<D>| -> [i64; D] { std::array::from_fn(|a| (x[a] / bin).floor() as i64) };
        let mut bins: HashMap<[i64; D], Vec<usize>> = HashMap::new();
        for (p, x) in positions.iter().enumerate() {
            bins.entry(key(x)).or_default().push(p);
        }
        let occupied = |site: &Vector<D>, tol: f64| -> bool {
            let c = key(site);
            debug_assert!(tol <= bin);
            let reach = 1i64;
            let mut k = [0i64; D];
            let span = (2 * reach + 1) as usize;
            for i in 0..span.pow(D as u32) {
                let mut r = i;
                for a in 0..D {
                    k[a] = c[a] + (r % span) as i64 - reach;
                    r /= span;
                }
                if let Some(list) = bins.get(&k) {
                    if list.iter().any(|&q| (positions[q] - site).norm() < tol) {
                        return true;
                    }
                }
            }
            false
        };
        let (mut x_out, mut n_out) = (Vec::new(), Vec::new());
        for (p, x) in positions.iter().enumerate() {
            let s = spacing[p];
            for a in 0..D {
                for sign in [-1.0, 1.0] {
                    let mut e = Vector::<D>::zeros();
                    e[a] = sign;
                    if !occupied(&(x + s * e), 0.25 * s) {
                        x_out.push(x + 0.5 * s * e);
                        n_out.push(e * s.powi(D as i32 - 1));
                    }
                }
            }
        }
        (x_out, n_out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lattice surface of a box: the normals of a closed surface sum to zero, and the total
    /// area is the box's surface area.
    #[test]
    fn lattice_surface_of_a_box() {
        let s = 0.1;
        let mut x = Vec::new();
        for k in 0..3 {
            for j in 0..4 {
                for i in 0..5 {
                    x.push(Vector::<3>::new(
                        (i as f64 + 0.5) * s,
                        (j as f64 + 0.5) * s,
                        (k as f64 + 0.5) * s,
                    ));
                }
            }
        }
        let (pts, normals) = BoundaryPoints::from_lattice(&x, &vec![s * s * s; x.len()]);
        assert_eq!(pts.len(), 2 * (5 * 4 + 4 * 3 + 5 * 3));
        let sum: Vector<3> = normals.iter().sum();
        assert!(sum.norm() < 1e-15);
        let area: f64 = normals.iter().map(|n| n.norm()).sum();
        assert!((area - 2.0 * (0.5 * 0.4 + 0.4 * 0.3 + 0.5 * 0.3)).abs() < 1e-12);
        // Every point lies on the box surface.
        for p in &pts {
            let on =
                (0..3).any(|a| p[a].abs() < 1e-12 || (p[a] - [0.5, 0.4, 0.3][a]).abs() < 1e-12);
            assert!(on, "{p}");
        }
    }
}
