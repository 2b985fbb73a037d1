//! Boundary points: quadrature points on the material's surface, with an outward area-weighted
//! normal `n a` (length in 2D), optional tractions, and their own deformation gradient. They move
//! with the grid velocity like massless particles and update `n a = J F⁻ᵀ N A` (Nanson).

use crate::error::{check_finite, Error, Result};
use crate::{Matrix, Vector};
use rayon::prelude::*;
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

    /// The surface of the particles as they are now, found afresh (VC without given boundary
    /// points, at every step), as a closed voxel surface. Each particle stands for its domain,
    /// the cell of side `s = (V⁰_p)^{1/D}` carried by its deformation gradient,
    /// `x_p + F_p [−s/2, s/2]^D`, taken a little larger (`SURFACE_DOMAIN_SCALE`) so that
    /// neighbouring domains that do not quite meet still close. The voxels of side
    /// `v = max_p (J_p V⁰_p)^{1/D} / 2` (aligned with `origin`) whose centres lie in some domain
    /// and in the box `[origin, upper]` are the body; every voxel face between the body and an empty voxel is a point at the face
    /// centre with the area normal `±e_a v^{D−1}`. The normals of each piece sum to zero
    /// exactly, a body that breaks apart gets its new faces, and no point drifts away from the
    /// material. On an undeformed lattice whose sites are voxel centres this is the surface of
    /// [`BoundaryPoints::from_lattice`], split in `2^{D−1}` points per face.
    pub fn of_particles(
        (origin, upper): (&Vector<D>, &Vector<D>),
        positions: &[Vector<D>],
        reference_volumes: &[f64],
        deformation_gradients: &[Matrix<D>],
    ) -> (Vec<Vector<D>>, Vec<Vector<D>>) {
        let n = positions.len();
        let spacing = |p: usize| reference_volumes[p].powf(1.0 / D as f64);
        let v = 0.5
            * (0..n)
                .map(|p| {
                    spacing(p) * crate::determinant(&deformation_gradients[p]).powf(1.0 / D as f64)
                })
                .fold(0.0, f64::max);
        if !(v > 0.0 && v.is_finite()) {
            return (Vec::new(), Vec::new());
        }
        // Voxel k spans [origin + k v, origin + (k + 1) v) per axis; its centre is at k + 1/2.
        // Only voxels whose centres lie in the domain `[origin, upper]` count, which also bounds
        // the work for a particle stretched far.
        let last: [i64; D] =
            std::array::from_fn(|a| ((upper[a] - origin[a]) / v - 0.5).floor() as i64);
        let mut voxels: Vec<[i64; D]> = (0..n)
            .into_par_iter()
            .flat_map_iter(|p| {
                let (x, f) = (positions[p], deformation_gradients[p]);
                let half = SURFACE_DOMAIN_SCALE * 0.5 * spacing(p);
                let to_reference = f.try_inverse().unwrap_or_else(Matrix::zeros);
                // The domain's bounding box, then the voxel centres inside the domain.
                let extent: [f64; D] =
                    std::array::from_fn(|a| half * (0..D).map(|b| f[(a, b)].abs()).sum::<f64>());
                let lo: [i64; D] = std::array::from_fn(|a| {
                    (((x[a] - extent[a] - origin[a]) / v - 0.5).ceil() as i64).max(0)
                });
                let count: [usize; D] = std::array::from_fn(|a| {
                    let hi = ((x[a] + extent[a] - origin[a]) / v - 0.5).floor() as i64;
                    (hi.min(last[a]) - lo[a] + 1).max(0) as usize
                });
                let total: usize = count.iter().product();
                (0..total).filter_map(move |i| {
                    let mut r = i;
                    let k: [i64; D] = std::array::from_fn(|a| {
                        let k = lo[a] + (r % count[a]) as i64;
                        r /= count[a];
                        k
                    });
                    let centre = Vector::<D>::from_fn(|a, _| origin[a] + (k[a] as f64 + 0.5) * v);
                    let xi = to_reference * (centre - x);
                    xi.iter().all(|c| c.abs() <= half).then_some(k)
                })
            })
            .collect();
        voxels.par_sort_unstable();
        voxels.dedup();
        let faces: Vec<Vec<(Vector<D>, Vector<D>)>> = voxels
            .par_iter()
            .map(|k| {
                let mut out = Vec::new();
                for a in 0..D {
                    for sign in [-1i64, 1] {
                        let mut n = *k;
                        n[a] += sign;
                        if voxels.binary_search(&n).is_err() {
                            let centre = Vector::<D>::from_fn(|b, _| {
                                let c = k[b] as f64
                                    + 0.5
                                    + if b == a { 0.5 * sign as f64 } else { 0.0 };
                                origin[b] + c * v
                            });
                            let mut e = Vector::<D>::zeros();
                            e[a] = sign as f64 * v.powi(D as i32 - 1);
                            out.push((centre, e));
                        }
                    }
                }
                out
            })
            .collect();
        faces.into_iter().flatten().unzip()
    }
}

/// How much larger than its domain a particle is taken when the surface is found
/// ([`BoundaryPoints::of_particles`]): on an undeformed lattice any scale in (1/2, 3/2) gives
/// the same voxels; 1.2 closes gaps of a fifth of a spacing between deformed domains.
const SURFACE_DOMAIN_SCALE: f64 = 1.2;

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

    fn block_2d(nx: usize, ny: usize, s: f64, at: Vector<2>) -> Vec<Vector<2>> {
        (0..nx * ny)
            .map(|k| {
                at + Vector::<2>::new(((k % nx) as f64 + 0.5) * s, ((k / nx) as f64 + 0.5) * s)
            })
            .collect()
    }

    /// `Σ x·(n a) / D`: the volume a closed surface encloses (divergence theorem).
    fn enclosed<const D: usize>(x: &[Vector<D>], na: &[Vector<D>]) -> f64 {
        x.iter().zip(na).map(|(x, n)| x.dot(n)).sum::<f64>() / D as f64
    }

    /// On an undeformed lattice the surface found from the particles is the lattice surface of
    /// [`BoundaryPoints::from_lattice`]: the same area, on the same faces, closed.
    #[test]
    fn surface_of_an_undeformed_box_is_its_lattice_surface() {
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
        let vol = vec![s * s * s; x.len()];
        let f = vec![Matrix::<3>::identity(); x.len()];
        let (pts, normals) = BoundaryPoints::of_particles(
            (&Vector::zeros(), &Vector::from_element(1.0)),
            &x,
            &vol,
            &f,
        );
        let (lattice, _) = BoundaryPoints::from_lattice(&x, &vol);
        assert_eq!(pts.len(), 4 * lattice.len());
        let sum: Vector<3> = normals.iter().sum();
        assert!(sum.norm() < 1e-15);
        let area: f64 = normals.iter().map(|n| n.norm()).sum();
        assert!((area - 2.0 * (0.5 * 0.4 + 0.4 * 0.3 + 0.5 * 0.3)).abs() < 1e-12);
        assert!((enclosed(&pts, &normals) - 0.5 * 0.4 * 0.3).abs() < 1e-14);
        for p in &pts {
            let on =
                (0..3).any(|a| p[a].abs() < 1e-12 || (p[a] - [0.5, 0.4, 0.3][a]).abs() < 1e-12);
            assert!(on, "{p}");
        }
    }

    /// A body that breaks apart gets the faces of the crack: two blocks three spacings apart
    /// have two closed surfaces; a gap of a tenth of a spacing (domains that do not quite meet)
    /// is closed over.
    #[test]
    fn a_broken_body_gets_the_faces_of_the_crack() {
        let s = 0.05;
        let surface = |gap: f64| {
            let mut x = block_2d(4, 3, s, Vector::<2>::new(0.2, 0.2));
            x.extend(block_2d(4, 3, s, Vector::<2>::new(0.2, 0.35 + gap)));
            let vol = vec![s * s; x.len()];
            let f = vec![Matrix::<2>::identity(); x.len()];
            BoundaryPoints::of_particles(
                (&Vector::zeros(), &Vector::from_element(1.0)),
                &x,
                &vol,
                &f,
            )
        };
        let (x, na) = surface(0.15);
        let area: f64 = na.iter().map(|n| n.norm()).sum();
        assert!((area - 2.0 * 2.0 * (0.2 + 0.15)).abs() < 1e-12, "{area}");
        assert!(na.iter().sum::<Vector<2>>().norm() < 1e-16);
        // The lower block's top and the upper block's bottom are surface now.
        let top = x
            .iter()
            .zip(&na)
            .filter(|(x, n)| (x[1] - 0.35).abs() < 1e-12 && n[1] > 0.0);
        assert_eq!(top.count(), 8);
        let (_, na) = surface(0.1 * s);
        let area: f64 = na.iter().map(|n| n.norm()).sum();
        assert!(area < 2.0 * (0.2 + 0.3) + 4.0 * s, "{area}");
    }

    /// A sheared and stretched lattice carrying its deformation gradient: the surface is closed,
    /// has no holes inside (its enclosed volume is the body's within the staircase of one voxel
    /// layer), and lies within a voxel of the body's edge.
    #[test]
    fn surface_of_a_sheared_block_is_closed_and_tight() {
        let s = 0.02;
        let f = Matrix::<2>::new(1.3, 0.9, 0.0, 0.8);
        let reference = block_2d(20, 10, s, Vector::zeros());
        let shift = Vector::<2>::new(0.3, 0.3);
        let x: Vec<Vector<2>> = reference.iter().map(|xr| shift + f * xr).collect();
        let vol = vec![s * s; x.len()];
        let (pts, na) = BoundaryPoints::of_particles(
            (&Vector::zeros(), &Vector::from_element(2.0)),
            &x,
            &vol,
            &vec![f; x.len()],
        );
        assert!(na.iter().sum::<Vector<2>>().norm() < 1e-15);
        let j = f.determinant();
        let volume = j * 0.4 * 0.2;
        // Voxels of half the current spacing (J s²)^(1/2).
        let v = 0.5 * s * j.sqrt();
        let perimeter = 2.0
            * ((f * Vector::<2>::new(0.4, 0.0)).norm() + (f * Vector::<2>::new(0.0, 0.2)).norm());
        let v_enclosed = enclosed(&pts, &na);
        assert!(
            (v_enclosed - volume).abs() < perimeter * v,
            "{v_enclosed} vs {volume}"
        );
        // Every point within a voxel of the parallelogram's edge.
        let fi = f.try_inverse().unwrap();
        for p in &pts {
            let xi = fi * (p - shift);
            let inside = xi[0] > 0.0 && xi[0] < 0.4 && xi[1] > 0.0 && xi[1] < 0.2;
            let depth = [xi[0], 0.4 - xi[0], xi[1], 0.2 - xi[1]]
                .into_iter()
                .map(f64::abs)
                .fold(f64::INFINITY, f64::min);
            assert!(!inside || depth < 2.0 * v, "{p}: {depth}");
            assert!(inside || depth < 2.0 * v, "{p}: {depth}");
        }
    }
}
