//! Boundary points: quadrature points on the material's surface, with an outward area-weighted
//! normal `n a` (length in 2D), optional tractions, and their own deformation gradient. They move
//! with the grid velocity like massless particles and update `n a = J F⁻ᵀ N A` (Nanson).

use crate::error::{check_finite, Error, Result};
use crate::{Matrix, Vector};
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};

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
    /// points, every `Sim::set_vc_surface_refresh` steps), as a closed voxel surface. Each particle stands for its domain,
    /// the cell of side `s = (V⁰_p)^{1/D}` carried by its deformation gradient,
    /// `x_p + F_p [−s/2, s/2]^D`, taken a little larger (`SURFACE_DOMAIN_SCALE`) so that
    /// neighbouring domains that do not quite meet still close. The voxels, aligned with
    /// `origin`, have a side `v` that divides half a grid cell (`cell_size / 2`) and is at most
    /// half the largest domain as taken, `SURFACE_DOMAIN_SCALE · max_p (J_p V⁰_p)^{1/D} / 2`
    /// (so a body of two particles per cell per direction, compressed or stretched by up to a
    /// fifth, keeps two voxels per particle and axis, whose faces merge below, rather than
    /// jumping to three, nine times the points in 3D); those whose centres lie in some domain
    /// and in the box `[origin, upper]` are the body. Every voxel face between the body and an
    /// empty voxel is a surface element: its `2^{D−1}` two-point Gauss points, each with its
    /// share of the area normal `±e_a v^{D−1}`. No face straddles a knot of the shape functions
    /// (nodes and half-cells), so `Σ_b Ψ_I n_b a_b` is the voxel surface's integral exactly for
    /// the B-splines (VC makes the particle sums equal it; a face-centre rule, spaced at a phase
    /// unrelated to the knots, carried a fixed fraction of error that did not shrink with h).
    /// The normals of each piece sum to zero exactly, a body that breaks apart gets its new
    /// faces, and no point drifts away from the material. A body against a wall has its faces
    /// on the wall's plane (the voxels tile the grid's box, which a grid box of whole cells
    /// is). When a half cell holds an even number of voxels, the `2^{D−1}` voxel faces of a
    /// block `2g, 2g + 1` across (per tangential axis, inside one half cell) merge into one
    /// face; on an undeformed lattice of two particles per cell per direction that is one face
    /// per particle face.
    pub fn of_particles(
        (origin, upper): (&Vector<D>, &Vector<D>),
        cell_size: f64,
        positions: &[Vector<D>],
        reference_volumes: &[f64],
        deformation_gradients: &[Matrix<D>],
    ) -> (Vec<Vector<D>>, Vec<Vector<D>>) {
        let root = |x: f64| if D == 2 { x.sqrt() } else { x.cbrt() };
        // A particle's domain: the half side of its cell in reference coordinates and the
        // bounding box of the cell as carried by `F`. The root of a volume repeated from the
        // particle before (a lattice's) is not taken again: `cbrt` is about as costly as the
        // rest of a particle here. Nothing is stored per particle: the domains are taken again
        // where the voxels are marked.
        let domains = |chunk: usize| {
            let range = chunk * PARTICLE_CHUNK..((chunk + 1) * PARTICLE_CHUNK).min(positions.len());
            let (mut last, mut s) = (f64::NAN, f64::NAN);
            range.map(move |p| {
                let (x, f, v0) = (
                    &positions[p],
                    &deformation_gradients[p],
                    reference_volumes[p],
                );
                if v0.to_bits() != last.to_bits() {
                    (last, s) = (v0, root(v0));
                }
                let half = SURFACE_DOMAIN_SCALE * 0.5 * s;
                let extent = Vector::<D>::from_fn(|a, _| {
                    half * (0..D).map(|b| f[(a, b)].abs()).sum::<f64>()
                });
                (p, half, (x - extent, x + extent))
            })
        };
        let chunks = positions.len().div_ceil(PARTICLE_CHUNK);
        // Over all particles: the largest and the summed current volume `|J| V⁰` (the current
        // spacing's root is taken once, of the largest) and the box of all domains.
        let infinite = Vector::<D>::repeat(f64::INFINITY);
        let parts: Vec<(f64, f64, Vector<D>, Vector<D>)> = (0..chunks)
            .into_par_iter()
            .map(|chunk| {
                let (mut largest, mut total, mut lo, mut hi) = (0.0f64, 0.0, infinite, -infinite);
                for (p, _, domain) in domains(chunk) {
                    let volume =
                        crate::determinant(&deformation_gradients[p]).abs() * reference_volumes[p];
                    largest = largest.max(volume);
                    total += volume;
                    lo = lo.inf(&domain.0);
                    hi = hi.sup(&domain.1);
                }
                (largest, total, lo, hi)
            })
            .collect();
        let (largest, total, lower, higher) = parts.iter().fold(
            (0.0f64, 0.0, infinite, -infinite),
            |(largest, total, lo, hi), part| {
                (
                    largest.max(part.0),
                    total + part.1,
                    lo.inf(&part.2),
                    hi.sup(&part.3),
                )
            },
        );
        let target = SURFACE_DOMAIN_SCALE * 0.5 * root(largest);
        if !(target > 0.0 && target.is_finite()) {
            return (Vec::new(), Vec::new());
        }
        // `per_half` voxels per half cell, so that no voxel face straddles a knot of the shape
        // functions (at the nodes and half-way between) and the voxels tile the grid's box.
        let per_half = (0.5 * cell_size / target).ceil().clamp(1.0, 1e6);
        let v = 0.5 * cell_size / per_half;
        // Faces merge by twos only within a half cell.
        let merge = (per_half as u64).is_multiple_of(2);
        // Voxel k spans [origin + k v, origin + (k + 1) v) per axis; its centre is at k + 1/2.
        // Only voxels whose centres lie in the domain `[origin, upper]` count, which also bounds
        // the work for a particle stretched far.
        let last: [i64; D] =
            std::array::from_fn(|a| ((upper[a] - origin[a]) / v - 0.5).floor() as i64);
        // A domain's range of voxels: those whose centres its bounding box holds, cut to the
        // grid's box.
        let range = |(lo, hi): &(Vector<D>, Vector<D>)| -> ([i64; D], [i64; D]) {
            (
                std::array::from_fn(|a| ceil_index((lo[a] - origin[a]) / v - 0.5).max(0)),
                std::array::from_fn(|a| {
                    crate::floor_index((hi[a] - origin[a]) / v - 0.5).min(last[a])
                }),
            )
        };
        // The body's voxels: the centres inside some particle's domain, visited row by row
        // along axis 0 (the reference coordinates of the next centre are one step away).
        let voxels_of = |chunk: usize, visited: &mut Vec<[i64; D]>| {
            for (p, half, domain) in domains(chunk) {
                let (lo, hi) = range(&domain);
                if (0..D).any(|a| lo[a] > hi[a]) {
                    continue;
                }
                let to_reference = deformation_gradients[p]
                    .try_inverse()
                    .unwrap_or_else(Matrix::zeros);
                let step = to_reference.column(0) * v;
                // The rows' first voxels, counted along axes 1.. (no divisions).
                let mut k = lo;
                loop {
                    let centre = Vector::<D>::from_fn(|a, _| origin[a] + (k[a] as f64 + 0.5) * v);
                    let mut xi = to_reference * (centre - positions[p]);
                    let mut j = k;
                    while j[0] <= hi[0] {
                        if xi.iter().all(|c| c.abs() <= half) {
                            visited.push(j);
                        }
                        xi += step;
                        j[0] += 1;
                    }
                    let Some(a) = (1..D).find(|&a| k[a] < hi[a]) else {
                        break;
                    };
                    k[a] += 1;
                    k[1..a].copy_from_slice(&lo[1..a]);
                }
            }
        };
        let mut body = VoxelSet::of(positions.len(), range(&(lower, higher)), voxels_of);
        let mean_volume = total / positions.len().max(1) as f64;
        // Gaps between neighbouring particles that their domains leave (jittered or stretched
        // particles) are holes narrower than a particle; their faces would put surface points
        // inside the body. Fill every enclosed hole that lies within half a particle's mean
        // spacing of the body.
        let reach = (0.5 * root(mean_volume) / v).round().max(1.0) as usize;
        body.fill_narrow_holes(&last, reach);
        // Faces merged by twos per tangential axis (when a half cell holds an even number of
        // voxels): the `2^{D−1}` faces of one side of a block of voxels `2g, 2g + 1` across
        // (per tangential axis) become one face with their area when all are exposed; the
        // member with even tangential indices stands for the group. On a lattice aligned with
        // the voxels that is one face per particle face; the normals still sum to zero. The
        // points keep the faces' fixed order.
        let full = 1usize << (D - 1);
        // A face (centre in voxel units, side `width` voxels along each tangential axis) as its
        // 2^{D−1} two-point Gauss points, each with its share of the area: exact for the
        // polynomial pieces of the shape functions on the face.
        let gauss = 0.5 / 3f64.sqrt();
        let points = |centre: [f64; D], a: usize, sign: i64, width: f64| {
            let area = (width * v).powi(D as i32 - 1) / full as f64;
            (0..full).map(move |corner| {
                let mut t = 0;
                let x = Vector::<D>::from_fn(|b, _| {
                    let mut c = centre[b];
                    if b != a {
                        c += if (corner >> t) & 1 == 0 {
                            -gauss
                        } else {
                            gauss
                        } * width;
                        t += 1;
                    }
                    (origin[b] + c * v).clamp(origin[b], upper[b])
                });
                let mut e = Vector::<D>::zeros();
                e[a] = sign as f64 * area;
                (x, e)
            })
        };
        let found: Vec<(Vector<D>, Vector<D>)> = body
            .exposed_faces(merge)
            .into_par_iter()
            .flat_map_iter(|(k, a, sign, width)| {
                let normal = k[a] as f64 + 0.5 + 0.5 * sign as f64;
                // A group's face is centred on its block's side: `2g + 1` voxels along each
                // tangential axis.
                let centre = std::array::from_fn(|b| match (b == a, width) {
                    (true, _) => normal,
                    (false, 1) => k[b] as f64 + 0.5,
                    (false, _) => k[b] as f64 + 1.0,
                });
                points(centre, a, sign, width as f64)
            })
            .collect();
        found.into_iter().unzip()
    }
}

/// A voxel face: the voxel (the first of a group), the axis of its normal, the side (±1) and its
/// width in voxels along each tangential axis (2 for a group).
type Face<const D: usize> = ([i64; D], usize, i64, u8);

/// The voxels of a body (integer indices): a dense map of the box the particles' voxel ranges
/// span when it holds at most `DENSE_VOXELS_PER_PARTICLE` voxels per particle (linear time,
/// no sorting), otherwise a sorted list (particles far apart, or of very different sizes).
enum VoxelSet<const D: usize> {
    Dense {
        /// The box: `first ..first + dims` per axis, axis 0 fastest in `body`.
        first: [i64; D],
        dims: [usize; D],
        body: Vec<bool>,
    },
    Sparse(Vec<[i64; D]>),
}

/// See [`VoxelSet`]: the dense map is chosen while it costs at most this many voxels per
/// particle (a body holds 2^D to 3^D per particle).
const DENSE_VOXELS_PER_PARTICLE: usize = 64;

impl<const D: usize> VoxelSet<D> {
    /// The voxels `voxels_of(chunk, list)` appends to `list` for each chunk of
    /// `PARTICLE_CHUNK` of the `particles`, all within the box `lo..=hi` of voxel indices (every
    /// particle's range).
    fn of(
        particles: usize,
        (lo, hi): ([i64; D], [i64; D]),
        voxels_of: impl Fn(usize, &mut Vec<[i64; D]>) + Sync,
    ) -> Self {
        // One empty layer around the ranges: every neighbour of a body voxel is in the box.
        let first: [i64; D] = std::array::from_fn(|a| lo[a] - 1);
        let end: [i64; D] = std::array::from_fn(|a| hi[a] + 2);
        let chunks = particles.div_ceil(PARTICLE_CHUNK);
        if particles == 0 || (0..D).any(|a| lo[a] > hi[a]) {
            return VoxelSet::Sparse(Vec::new());
        }
        let dims: [usize; D] = std::array::from_fn(|a| (end[a] - first[a]) as usize);
        let total = dims
            .iter()
            .try_fold(1usize, |t, &d| t.checked_mul(d))
            .filter(|&t| t <= DENSE_VOXELS_PER_PARTICLE * particles);
        match total {
            Some(total) => {
                let marked: Vec<AtomicBool> = (0..total).map(|_| AtomicBool::new(false)).collect();
                (0..chunks)
                    .into_par_iter()
                    .for_each_init(Vec::new, |list, chunk| {
                        list.clear();
                        voxels_of(chunk, list);
                        for k in list.iter() {
                            // Every visited voxel lies in the box. Only ever set: the map does
                            // not depend on the threads' order.
                            if let Some(i) = dense_index(&first, &dims, k) {
                                marked[i].store(true, Ordering::Relaxed);
                            }
                        }
                    });
                let body = marked.into_iter().map(AtomicBool::into_inner).collect();
                VoxelSet::Dense { first, dims, body }
            }
            None => {
                let mut voxels: Vec<[i64; D]> = (0..chunks)
                    .into_par_iter()
                    .flat_map_iter(|chunk| {
                        let mut list = Vec::new();
                        voxels_of(chunk, &mut list);
                        list
                    })
                    .collect();
                voxels.par_sort_unstable();
                voxels.dedup();
                VoxelSet::Sparse(voxels)
            }
        }
    }

    /// Fills each narrow hole: a set of empty voxels, connected across faces, that no path
    /// through empty voxels joins to the outside, and none of whose voxels is more than `reach`
    /// voxels (along every axis) from the body. Only voxels with indices `0..=last` (the grid's
    /// box) count as empty: those outside are walls, so a gap between a body and a wall it
    /// rests on is a hole, and a body that fills the box has no outside. A sorted list
    /// (particles far apart) is left as it is.
    fn fill_narrow_holes(&mut self, last: &[i64; D], reach: usize) {
        let VoxelSet::Dense {
            first,
            dims,
            body: map,
        } = self
        else {
            return;
        };
        let total = map.len();
        let body: &[bool] = map;
        let filled = |i: usize| body[i];
        let position = |mut i: usize| -> [usize; D] {
            std::array::from_fn(|a| {
                let r = i % dims[a];
                i /= dims[a];
                r
            })
        };
        let strides: [usize; D] = std::array::from_fn(|a| dims[..a].iter().product());
        // Whether some body voxel lies within `reach` of voxel `r` along every axis.
        let near_body = |r: &[usize; D]| {
            let lo: [usize; D] = std::array::from_fn(|a| r[a].saturating_sub(reach));
            let count: [usize; D] =
                std::array::from_fn(|a| (r[a] + reach).min(dims[a] - 1) + 1 - lo[a]);
            (0..count.iter().product::<usize>()).any(|mut j| {
                let mut i = 0;
                for a in 0..D {
                    i += (lo[a] + j % count[a]) * strides[a];
                    j /= count[a];
                }
                filled(i)
            })
        };
        // The map's rows along axis 0: the part of a row in the box, and whether the row lies
        // on the map's outer layer (else only its two ends do).
        let (width, rows) = (dims[0], total / dims[0]);
        let in_row =
            (-first[0]).max(0) as usize..((last[0] - first[0] + 1).max(0) as usize).min(width);
        let row_of = |row: usize| -> (bool, bool) {
            let r = position(row * width);
            let in_box = (1..D).all(|a| (0..=last[a]).contains(&(first[a] + r[a] as i64)));
            let on_edge = (1..D).any(|a| r[a] == 0 || r[a] + 1 == dims[a]);
            (in_box, on_edge)
        };
        // Empty voxels of the box, not yet reached.
        let mut open = vec![false; total];
        for row in 0..rows {
            if row_of(row).0 {
                for k0 in in_row.clone() {
                    open[row * width + k0] = !filled(row * width + k0);
                }
            }
        }
        let mut stack = Vec::new();
        let mut hole = Vec::new();
        // Every open voxel joined to `seed`, into `hole`; they are open no more.
        let mut flood = |seed: usize, open: &mut Vec<bool>, hole: &mut Vec<usize>| {
            hole.clear();
            open[seed] = false;
            stack.push(seed);
            while let Some(i) = stack.pop() {
                hole.push(i);
                for stride in strides {
                    // Only a voxel of the map's outer layer has a neighbour index that leaves
                    // the map or wraps to another row, and that one is on the outer layer too.
                    for n in [i.wrapping_sub(stride), i + stride] {
                        if n < total && open[n] {
                            open[n] = false;
                            stack.push(n);
                        }
                    }
                }
            }
        };
        // The outside: open voxels joined to the map's outer layer.
        for row in 0..rows {
            let ends = [row * width, row * width + width - 1];
            let edge: &mut dyn Iterator<Item = usize> = match row_of(row).1 {
                true => &mut (row * width..(row + 1) * width),
                false => &mut ends.into_iter(),
            };
            for i in edge {
                if open[i] {
                    flood(i, &mut open, &mut hole);
                }
            }
        }
        // The holes left, filled once all are found (each judged against the body as found).
        let mut fill = Vec::new();
        for i in 0..total {
            if open[i] {
                flood(i, &mut open, &mut hole);
                if hole.iter().all(|&j| near_body(&position(j))) {
                    fill.extend_from_slice(&hole);
                }
            }
        }
        for j in fill {
            map[j] = true;
        }
    }

    /// Position of voxel `k` in the dense map, if it lies in its box.
    fn index(&self, k: &[i64; D]) -> Option<usize> {
        match self {
            VoxelSet::Dense { first, dims, .. } => dense_index(first, dims, k),
            VoxelSet::Sparse(_) => None,
        }
    }

    fn contains(&self, k: &[i64; D]) -> bool {
        match self {
            VoxelSet::Dense { body, .. } => self.index(k).is_some_and(|i| body[i]),
            VoxelSet::Sparse(list) => list.binary_search(k).is_ok(),
        }
    }

    /// Whether voxel `k` is in the body and its neighbour `k + sign e_a` is not: a face of the
    /// surface.
    fn exposed(&self, k: &[i64; D], a: usize, sign: i64) -> bool {
        match self {
            // A body voxel's neighbours lie in the map (the empty layer around it).
            VoxelSet::Dense { dims, body, .. } => self.index(k).is_some_and(|i| {
                let stride: usize = dims[..a].iter().product();
                body[i] && !body[if sign < 0 { i - stride } else { i + stride }]
            }),
            VoxelSet::Sparse(_) => {
                let mut n = *k;
                n[a] += sign;
                self.contains(k) && !self.contains(&n)
            }
        }
    }

    /// The faces between the body and empty voxels, in a fixed order (storage order for the
    /// map, sorted order for the list). With `merge`, the `2^{D−1}` faces of one side of a block
    /// of voxels `2g, 2g + 1` across (per tangential axis) that are all exposed are one face of
    /// width 2, listed where its first member (even tangential indices) is; the other members
    /// are left out.
    fn exposed_faces(&self, merge: bool) -> Vec<Face<D>> {
        // An exposed face's width, or none for a merged group's member other than its first:
        // `member(t)` is whether the group's member offset by `t` from its first (bit per
        // tangential axis) is exposed, `own` that offset for the face's voxel.
        let face_width = |k: &[i64; D], a: usize, member: &dyn Fn(usize, usize) -> bool| {
            if !merge {
                return Some(1);
            }
            let own = (0..D)
                .filter(|&b| b != a)
                .enumerate()
                .fold(0, |m, (t, b)| m | ((k[b].rem_euclid(2) as usize) << t));
            match (0..1 << (D - 1)).all(|t| member(own, t)) {
                false => Some(1),
                true => (own == 0).then_some(2),
            }
        };
        let faces_of = |k: [i64; D], out: &mut Vec<Face<D>>| {
            for a in 0..D {
                for sign in [-1i64, 1] {
                    let mut n = k;
                    n[a] += sign;
                    if !self.contains(&n) {
                        let member = |own: usize, t: usize| {
                            let mut m = k;
                            for (bit, b) in (0..D).filter(|&b| b != a).enumerate() {
                                m[b] += ((t >> bit) & 1) as i64 - ((own >> bit) & 1) as i64;
                            }
                            self.exposed(&m, a, sign)
                        };
                        if let Some(w) = face_width(&k, a, &member) {
                            out.push((k, a, sign, w));
                        }
                    }
                }
            }
        };
        let chunks: Vec<Vec<Face<D>>> = match self {
            VoxelSet::Sparse(list) => list
                .par_chunks(1024)
                .map(|chunk| {
                    let mut out = Vec::new();
                    for &k in chunk {
                        faces_of(k, &mut out);
                    }
                    out
                })
                .collect(),
            // Rows along axis 0; a voxel's neighbours are `±stride` away in the map (the empty
            // layer around the box keeps them inside it).
            VoxelSet::Dense { first, dims, body } => body
                .par_chunks(dims[0])
                .enumerate()
                .map(|(row, cells)| {
                    let mut out = Vec::new();
                    let base = row * dims[0];
                    let mut k = [0i64; D];
                    let mut r = row;
                    for a in 1..D {
                        k[a] = first[a] + (r % dims[a]) as i64;
                        r /= dims[a];
                    }
                    // A row with a body voxel lies inside the empty outer layer, so its
                    // neighbouring rows (axes 1 and 2) lie in the map; a voxel whose six
                    // neighbours are all in the body is passed over with no index arithmetic.
                    if !cells.contains(&true) {
                        return out;
                    }
                    let width = dims[0];
                    let strides: [usize; D] = std::array::from_fn(|a| dims[..a].iter().product());
                    let beside: [&[bool]; 4] = std::array::from_fn(|t| {
                        let a = 1 + t / 2;
                        match (a < D, t % 2) {
                            (false, _) => cells,
                            (true, 0) => &body[base - strides[a]..][..width],
                            (true, _) => &body[base + strides[a]..][..width],
                        }
                    });
                    // Whether each voxel and its neighbours are all in the body, without branches.
                    let [b0, b1, b2, b3] = beside.map(|row| &row[..width]);
                    let (before, after) = (&cells[..width - 2], &cells[2..]);
                    for k0 in 1..width - 1 {
                        let inner =
                            before[k0 - 1] & after[k0 - 1] & b0[k0] & b1[k0] & b2[k0] & b3[k0];
                        if !cells[k0] || inner {
                            continue;
                        }
                        k[0] = first[0] + k0 as i64;
                        let i = base + k0;
                        for (a, &stride) in strides.iter().enumerate() {
                            for sign in [-1i64, 1] {
                                let beyond =
                                    |i: usize| if sign < 0 { i - stride } else { i + stride };
                                if body[beyond(i)] {
                                    continue;
                                }
                                // A body voxel is off the map's outer layer, so are its
                                // neighbours' indices, and a member in the body has its
                                // neighbour beyond the face in the map.
                                let member = |own: usize, t: usize| {
                                    let mut m = i;
                                    for (bit, b) in (0..D).filter(|&b| b != a).enumerate() {
                                        m = m + ((t >> bit) & 1) * strides[b]
                                            - ((own >> bit) & 1) * strides[b];
                                    }
                                    body[m] && !body[beyond(m)]
                                };
                                if let Some(w) = face_width(&k, a, &member) {
                                    out.push((k, a, sign, w));
                                }
                            }
                        }
                    }
                    out
                })
                .collect(),
        };
        chunks.concat()
    }
}

/// Position of voxel `k` in a dense map of the box `first ..first + dims` (axis 0 fastest), if
/// it lies in the box.
#[inline]
fn dense_index<const D: usize>(first: &[i64; D], dims: &[usize; D], k: &[i64; D]) -> Option<usize> {
    let mut i = 0;
    for a in (0..D).rev() {
        let r = k[a] - first[a];
        if r < 0 || r >= dims[a] as i64 {
            return None;
        }
        i = i * dims[a] + r as usize;
    }
    Some(i)
}

/// `⌈x⌉` as an integer (saturating; 0 for NaN), as `x.ceil() as i64` gives it, without the
/// library call that `ceil` is on the baseline target.
#[inline]
fn ceil_index(x: f64) -> i64 {
    let t = x as i64;
    t.saturating_add(((t as f64) < x) as i64)
}

/// Particles per task of the surface's per-particle passes.
const PARTICLE_CHUNK: usize = 4096;

/// How much larger than its domain a particle is taken when the surface is found
/// ([`BoundaryPoints::of_particles`]): on an undeformed lattice any scale in (1/2, 3/2) gives
/// the same voxels; 1.2 closes gaps of a fifth of a spacing between deformed domains.
const SURFACE_DOMAIN_SCALE: f64 = 1.2;

#[cfg(test)]
mod tests {
    use super::*;

    /// Particles on a lattice of spacing 0.1 filling the box [0, 0.5] × [0, 0.4] × [0, 0.3].
    fn box_5_4_3() -> Vec<Vector<3>> {
        (0..60)
            .map(|k| {
                Vector::<3>::new(
                    (k % 5) as f64 + 0.5,
                    (k / 5 % 4) as f64 + 0.5,
                    (k / 20) as f64 + 0.5,
                ) * 0.1
            })
            .collect()
    }

    /// The lattice surface of a box: the normals of a closed surface sum to zero, and the total
    /// area is the box's surface area.
    #[test]
    fn lattice_surface_of_a_box() {
        let (s, x) = (0.1, box_5_4_3());
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

    /// [`BoundaryPoints::of_particles`] in the unit box, on a grid of cells `2 s` wide (two
    /// particles of spacing `s` per cell per direction).
    fn in_unit_box<const D: usize>(
        s: f64,
        x: &[Vector<D>],
        volumes: &[f64],
        deformation_gradients: &[Matrix<D>],
    ) -> (Vec<Vector<D>>, Vec<Vector<D>>) {
        let (origin, upper) = (Vector::zeros(), Vector::from_element(1.0));
        BoundaryPoints::of_particles(
            (&origin, &upper),
            2.0 * s,
            x,
            volumes,
            deformation_gradients,
        )
    }

    /// `Σ x·(n a) / D`: the volume a closed surface encloses (divergence theorem).
    fn enclosed<const D: usize>(x: &[Vector<D>], na: &[Vector<D>]) -> f64 {
        x.iter().zip(na).map(|(x, n)| x.dot(n)).sum::<f64>() / D as f64
    }

    /// On an undeformed lattice of two particles per cell per direction the surface found from
    /// the particles is the lattice surface of [`BoundaryPoints::from_lattice`] with each face
    /// centre replaced by the face's four Gauss points (the four voxel faces of each particle
    /// face merged into one): four times the points, the same closed surface, the same moments
    /// `Σ n a` and `Σ x ⊗ n a`, every point on the box's faces.
    #[test]
    fn surface_of_an_undeformed_box_is_its_lattice_surface() {
        let (s, x) = (0.1, box_5_4_3());
        let vol = vec![s * s * s; x.len()];
        let f = vec![Matrix::<3>::identity(); x.len()];
        let (pts, normals) = in_unit_box(s, &x, &vol, &f);
        let (lattice, lattice_normals) = BoundaryPoints::from_lattice(&x, &vol);
        assert_eq!(pts.len(), 4 * lattice.len());
        let moment = |x: &[Vector<3>], n: &[Vector<3>]| {
            x.iter()
                .zip(n)
                .map(|(x, n)| x * n.transpose())
                .sum::<Matrix<3>>()
        };
        let difference = moment(&pts, &normals) - moment(&lattice, &lattice_normals);
        assert!(difference.norm() < 1e-14, "{difference}");
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

    /// A body compressed by a tenth keeps voxels of a quarter cell (two per particle and axis,
    /// faces merged where they fall within a half cell): 480 points, at most twice the
    /// undeformed box's 376, where voxels taken from its spacing alone would be a sixth of a
    /// cell, unmerged: about 2 700 (its area over `v²`, four points each). The surface stays
    /// closed and encloses the compressed box to within one voxel layer.
    #[test]
    fn a_compressed_body_keeps_its_voxels() {
        let (s, x) = (0.1, box_5_4_3());
        let squeezed: Vec<Vector<3>> = x.iter().map(|x| 0.9 * x).collect();
        let vol = vec![s * s * s; x.len()];
        let f = vec![0.9 * Matrix::<3>::identity(); x.len()];
        let (pts, normals) = in_unit_box(s, &squeezed, &vol, &f);
        let (lattice, _) = BoundaryPoints::from_lattice(&x, &vol);
        assert!(pts.len() <= 2 * 4 * lattice.len(), "{} points", pts.len());
        assert!(normals.iter().sum::<Vector<3>>().norm() < 1e-15);
        // Each side within one voxel (a quarter cell, 0.05) of the compressed box's.
        let (v, sides) = (0.05, [0.45, 0.36, 0.27]);
        let (lo, hi) = (
            sides.iter().map(|a| a - v).product::<f64>(),
            sides.iter().map(|a| a + v).product::<f64>(),
        );
        let volume = enclosed(&pts, &normals);
        assert!(volume > lo && volume < hi, "{volume} outside ({lo}, {hi})");
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
            in_unit_box(s, &x, &vol, &f)
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
        // Four particles across: one merged face per particle face, two Gauss points each.
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
            2.0 * s,
            &x,
            &vol,
            &vec![f; x.len()],
        );
        assert!(na.iter().sum::<Vector<2>>().norm() < 1e-15);
        let j = f.determinant();
        let volume = j * 0.4 * 0.2;
        // Voxels of at most half the current spacing (J s²)^(1/2).
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

    /// Particles jittered by ±30 % of their spacing leave gaps between their domains: holes
    /// inside the body, whose faces would be surface points in the material. The domains of the
    /// study's jittered particles (`Placement::Jittered`) just cover the box undeformed; squeezed
    /// by 1 % along one axis (as the manufactured solution does in its first steps) they leave
    /// holes. The body still fills the grid's box: its surface lies on the box's faces, closed,
    /// enclosing the box, in 2D and 3D.
    fn jittered_body_fills_the_box<const D: usize>(cells: usize, seed: u64) {
        let s = 0.5 / cells as f64;
        // Two particles per cell and direction at the quarter points, each moved by up to 30 %
        // of their spacing `s` along every axis.
        let n = 2 * cells;
        let mut rng = crate::shape::UniformRng::new(seed);
        let x: Vec<Vector<D>> = (0..n.pow(D as u32))
            .map(|k| {
                let mut r = k;
                let mut site = Vector::<D>::from_fn(|_, _| {
                    let i = r % n;
                    r /= n;
                    (i as f64 + 0.5) * s
                });
                for a in 0..D {
                    site[a] += (2.0 * rng.uniform() - 1.0) * 0.3 * s;
                }
                site
            })
            .collect();
        let (pts, na) = in_unit_box(
            s,
            &x,
            &vec![s.powi(D as i32); x.len()],
            &vec![
                Matrix::<D>::from_fn(|a, b| match (a, b) {
                    (0, 0) => 1.01,
                    (1, 1) => 0.99,
                    (a, b) => (a == b) as u8 as f64,
                });
                x.len()
            ],
        );
        // Sums over the points, each term rounded: a tolerance of 1e-14 per point.
        let round_off = 1e-14 * pts.len() as f64;
        assert!(na.iter().sum::<Vector<D>>().norm() < round_off);
        let area: f64 = na.iter().map(|n| n.norm()).sum();
        assert!((area - 2.0 * D as f64).abs() < round_off, "{area}");
        assert!((enclosed(&pts, &na) - 1.0).abs() < round_off);
        for p in &pts {
            assert!(
                (0..D).any(|a| p[a].abs() < 1e-12 || (p[a] - 1.0).abs() < 1e-12),
                "{p}"
            );
        }
    }

    #[test]
    fn gaps_between_jittered_particles_are_not_surface() {
        jittered_body_fills_the_box::<2>(16, 1);
        jittered_body_fills_the_box::<3>(6, 1);
    }

    /// A cavity two particles wide is the body's own surface and is kept; the gap one missing
    /// particle leaves is within half a spacing of the material everywhere and is filled.
    #[test]
    fn a_cavity_is_kept_and_a_missing_particle_is_filled() {
        let s = 0.05;
        let x: Vec<Vector<2>> = block_2d(12, 12, s, Vector::<2>::new(0.2, 0.2))
            .into_iter()
            .enumerate()
            .filter(|(k, _)| {
                let (i, j) = (k % 12, k / 12);
                let cavity = (6..8).contains(&i) && (6..8).contains(&j);
                !cavity && (i, j) != (2, 2)
            })
            .map(|(_, x)| x)
            .collect();
        let (pts, na) = in_unit_box(
            s,
            &x,
            &vec![s * s; x.len()],
            &vec![Matrix::<2>::identity(); x.len()],
        );
        assert!(na.iter().sum::<Vector<2>>().norm() < 1e-15);
        let area: f64 = na.iter().map(|n| n.norm()).sum();
        assert!(
            (area - (4.0 * 12.0 + 4.0 * 2.0) * s).abs() < 1e-12,
            "{area}"
        );
        assert!((enclosed(&pts, &na) - (144.0 - 4.0) * s * s).abs() < 1e-12);
    }

    /// The dense voxel map (particles close together) and the sorted list (a particle far away
    /// makes the box too large for the map) find the same surface, in another order.
    /// The voxel ranges' rounding up gives what `ceil` gives, at the edges of `i64` too.
    #[test]
    fn ceil_index_is_the_library_ceiling() {
        let big = i64::MAX as f64;
        for x in [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.5,
            -2.5,
            1e-300,
            -1e-300,
            4503599627370495.5,
            -4503599627370495.5,
            1e18,
            -1e18,
            big,
            -big,
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ] {
            assert_eq!(ceil_index(x), x.ceil() as i64, "{x}");
            assert_eq!(crate::floor_index(x), x.floor() as i64, "{x}");
        }
    }

    #[test]
    fn dense_and_sparse_voxel_sets_find_the_same_surface() {
        let s = 0.02;
        let f = Matrix::<2>::new(1.1, 0.4, -0.2, 0.9);
        let mut x: Vec<Vector<2>> = block_2d(12, 7, s, Vector::zeros())
            .iter()
            .enumerate()
            .map(|(k, xr)| {
                let jitter = 0.1 * s * ((k * 7919 % 13) as f64 / 13.0 - 0.5);
                Vector::<2>::new(0.5, 0.5) + f * xr + Vector::<2>::new(jitter, -jitter)
            })
            .collect();
        let domain = (&Vector::<2>::zeros(), &Vector::<2>::from_element(1e4));
        let surface = |x: &[Vector<2>]| {
            let (p, n) = BoundaryPoints::of_particles(
                domain,
                2.0 * s,
                x,
                &vec![s * s; x.len()],
                &vec![f; x.len()],
            );
            let mut faces: Vec<[f64; 4]> = p
                .iter()
                .zip(&n)
                .map(|(p, n)| [p[0], p[1], n[0], n[1]])
                .collect();
            faces.sort_by(|a, b| a.partial_cmp(b).unwrap());
            faces
        };
        let dense = surface(&x);
        x.push(Vector::<2>::new(5e3, 5e3));
        let sparse: Vec<[f64; 4]> = surface(&x).into_iter().filter(|p| p[0] < 10.0).collect();
        assert!(!dense.is_empty());
        assert_eq!(dense, sparse);
    }
}
