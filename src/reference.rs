//! The reference step: the method of METHOD.md section 1 written plainly, serial and node by node,
//! with none of the fast step's machinery (no bins, colours, factored stencils, lanes, SIMD or
//! stored stencils), outside the step's module, of which it uses only the found surface and its
//! age. It is the oracle the fast step is tested against (`tests` below,
//! `fast_step_matches_the_reference_step`): both must give the same particle state to round-off.
//!
//! It covers what the fast step does with one velocity field, or one per body under contact
//! (deformable or rigid), and gravity: linear hats, B-splines, RK of order 1 (on the lattice
//! with ã = 2, and off it) and of orders 2 and 3 (signed, with the transfer weights of
//! `edge_lumping` at a body's edge), every transfer (PIC/FLIP, APIC, MLS), both schemes (USL,
//! MUSL), every kind of wall, every material (elastic, neo-Hookean, Drucker–Prager with and
//! without the μ(I) rheology, Johnson–Cook with damage), material-point integration and VC of
//! orders 1 to 3 over the surface found from the particles or over given boundary points (which
//! carry tractions and move with the grid, without contact); the property tests draw the fast
//! step's paths too (vector instructions, factored stencils, particle sorting). The
//! wall conditions are the walls' own (`Walls::fold`, `apply_friction`, `unfold`), the stresses
//! the materials' own, the edge-lumping node weights `EdgeLumping::blend`'s, the contact law
//! `contact::correct_velocities`'s and the found surface `BoundaryPoints::of_particles`'s: the
//! oracle is for the schedule, the data layout and VC's solve, not for those. VC's correction
//! is solved here densely (order 1: a Cholesky factor of the node system with its null space
//! added; order ≥ 2: the pseudo-inverse of the system scaled by its node blocks), where the
//! fast step runs conjugate gradients preconditioned with the node blocks or a V-cycle.

use crate::grid::{EdgeLumping, Grid, GridNodes};
use crate::integration::{
    first_order_correction_bound, VC_EDGE_DAMPING_FLOOR, VC_EDGE_REACH, VC_REGULARISATION,
};
use crate::material::{block, embed3, pressure, Constitutive};
use crate::options::{Shape, Transfer};
use crate::sim::Sim;
use crate::{Matrix, Vector};
use nalgebra::{DMatrix, DVector};
use std::collections::BTreeMap;

/// A particle's stencil: node indices, `Ψ_I(x_p)`, `∇Ψ_I(x_p)` and the transfer weights `Φ_I`
/// (`Ψ`, or for signed shapes the blend of `edge_lumping` with the kernel's Shepard functions
/// `L_I`, which `lumping` holds).
struct Stencil<const D: usize> {
    nodes: Vec<usize>,
    values: Vec<f64>,
    gradients: Vec<Vector<D>>,
    transfer: Vec<f64>,
    lumping: Vec<f64>,
}

fn stencil<const D: usize>(sim: &Sim<D>, x: &Vector<D>) -> Stencil<D> {
    let len = sim.shape.stencil_len();
    let mut s = Stencil {
        nodes: vec![0; len],
        values: vec![0.0; len],
        gradients: vec![Vector::zeros(); len],
        transfer: Vec::new(),
        lumping: vec![0.0; len],
    };
    sim.shape
        .evaluate(&sim.grid, x, &mut s.nodes, &mut s.values, &mut s.gradients);
    if sim.shape.is_signed() {
        sim.shape.lumping_weights(&sim.grid, x, &mut s.lumping);
    }
    s.transfer.clone_from(&s.values);
    s
}

/// Signed shapes: each node's weight `θ_I` from `Σ m Ψ_I` and `Σ m L_I` ([`EdgeLumping::blend`],
/// the masses after the mirror walls folded their ghosts in; a ghost takes its mirror node's), and each particle's transfer weights `(θ_I Ψ_I + (1 − θ_I) L_I) / S_p`, or
/// `L_I` where `S_p ≤ 1/2`.
fn blend_transfer_weights<const D: usize>(
    sim: &Sim<D>,
    stencils: &mut [Stencil<D>],
    body: Option<u32>,
) -> crate::Result<Vec<f64>> {
    let member = |p: usize| body.is_none_or(|b| sim.particles.material[p] == b);
    let mut nodes = GridNodes::<D>::default();
    nodes.ensure(&sim.grid, true, false, false)?;
    for (p, s) in stencils.iter().enumerate().filter(|&(p, _)| member(p)) {
        let m = sim.particles.mass[p];
        for k in 0..s.nodes.len() {
            nodes.touch(s.nodes[k]);
            nodes.mass[s.nodes[k]] += m * s.values[k];
            nodes.lumping.as_mut().unwrap().mass[s.nodes[k]] += m * s.lumping[k];
        }
    }
    sim.options.walls.fold(&sim.grid, &mut nodes, true);
    let mut theta = vec![1.0; sim.grid.node_count()];
    let lumped = &nodes.lumping.as_ref().unwrap().mass;
    for &n in &nodes.active {
        theta[n] = EdgeLumping::blend(nodes.mass[n], lumped[n]);
    }
    sim.options
        .walls
        .unfold_values(&sim.grid, &nodes.active, &mut theta);
    for (_, s) in stencils.iter_mut().enumerate().filter(|&(p, _)| member(p)) {
        blend(s, &theta);
    }
    Ok(theta)
}

/// Sets a stencil's transfer weights from the nodes' `θ`.
fn blend<const D: usize>(s: &mut Stencil<D>, theta: &[f64]) {
    if s.nodes.iter().all(|&n| theta[n] == 1.0) {
        return;
    }
    for k in 0..s.nodes.len() {
        let t = theta[s.nodes[k]];
        s.transfer[k] = t * s.values[k] + (1.0 - t) * s.lumping[k];
    }
    let sum: f64 = s.transfer.iter().sum();
    if sum > 0.5 {
        s.transfer.iter_mut().for_each(|w| *w /= sum);
    } else {
        s.transfer.clone_from(&s.lumping);
    }
}

/// A boundary point's stencil with its transfer weights: VC's test function there.
fn test_stencil<const D: usize>(sim: &Sim<D>, x: &Vector<D>, theta: Option<&[f64]>) -> Stencil<D> {
    let mut s = stencil(sim, x);
    if let Some(theta) = theta {
        blend(&mut s, theta);
    }
    s
}

fn node_position<const D: usize>(grid: &Grid<D>, n: usize) -> Vector<D> {
    grid.node_position(grid.node_multi_index(n))
}

/// Whether the `k`-th node of a stencil is in the particle's support.
fn in_support<const D: usize>(s: &Stencil<D>, k: usize) -> bool {
    crate::shape::in_support(s.values[k], &s.gradients[k])
}

/// What VC's node system is built on: the surface (given or found), the particles of the body
/// (all without contact) with their stencils, a row per node of their supports (a node that only
/// boundary points reach has no particle to correct) and, per row, its connected body (nodes
/// joined by a particle's support), named by one of its rows.
struct VcNodes<'a, const D: usize> {
    surface: crate::BoundaryPoints<D>,
    /// The nodes' `θ` of the transfer weights (signed shapes), which give the test function
    /// at the boundary points.
    theta: Option<&'a [f64]>,
    members: Vec<usize>,
    stencils: Vec<&'a Stencil<D>>,
    row: BTreeMap<usize, usize>,
    body: Vec<usize>,
}

fn vc_nodes<'a, const D: usize>(
    sim: &Sim<D>,
    all_stencils: &'a [Stencil<D>],
    body: Option<u32>,
    theta: Option<&'a [f64]>,
) -> crate::Result<VcNodes<'a, D>> {
    let ps = &sim.particles;
    // The surface of the step: the given boundary points, the one carried from the last step,
    // or found from the particles (each body's under contact).
    let carried = body.is_none() && !sim.surface_plan().find;
    let surface = match (sim.boundary.is_empty(), carried) {
        (false, _) => sim.boundary.clone(),
        (true, true) => sim.surface.clone(),
        (true, false) => crate::step::found_surface(&sim.grid, ps, body)?,
    };
    let members: Vec<usize> = (0..ps.len())
        .filter(|&p| body.is_none_or(|b| ps.material[p] == b))
        .collect();
    let stencils: Vec<&Stencil<D>> = members.iter().map(|&p| &all_stencils[p]).collect();
    let mut row = BTreeMap::new();
    for s in &stencils {
        for k in 0..s.nodes.len() {
            if in_support(s, k) {
                row.insert(s.nodes[k], 0);
            }
        }
    }
    for (k, r) in row.values_mut().enumerate() {
        *r = k;
    }
    let mut parent: Vec<usize> = (0..row.len()).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            i = parent[i];
        }
        i
    }
    for s in &stencils {
        let rows: Vec<usize> = (0..s.nodes.len())
            .filter(|&k| in_support(s, k))
            .map(|k| row[&s.nodes[k]])
            .collect();
        for &i in &rows[1..] {
            let (r0, ri) = (root(&mut parent, rows[0]), root(&mut parent, i));
            parent[ri] = r0;
        }
    }
    let body = (0..row.len()).map(|i| root(&mut parent, i)).collect();
    Ok(VcNodes {
        surface,
        theta,
        members,
        stencils,
        row,
        body,
    })
}

/// VC's corrections of `∇Ψ_I(x_p)` per particle and stencil node (`crate::integration`), of
/// order 1 ([`vc_corrections_first_order`]) or higher ([`vc_corrections_higher_order`]).
fn vc_corrections<const D: usize>(
    sim: &Sim<D>,
    all_stencils: &[Stencil<D>],
    body: Option<u32>,
    order: u32,
    theta: Option<&[f64]>,
) -> crate::Result<Vec<Vec<Vector<D>>>> {
    let nodes = vc_nodes(sim, all_stencils, body, theta)?;
    Ok(match order {
        1 => vc_corrections_first_order(sim, all_stencils, &nodes),
        _ => vc_corrections_higher_order(sim, all_stencils, &nodes, order),
    })
}

/// VC of order 1: per particle and stencil node the correction `|Ψ_I| (ζ_I − f_p(x_I))` of
/// `∇Ψ_I(x_p)`, `f_p` the weighted least-squares linear fit of the `ζ_J` over the particle's
/// nodes (weights `|Ψ_J|`; `l_J = [1, (x_J − x_p)/h]`, `G_p = Σ_J |Ψ_J| l_J l_Jᵀ`, its
/// pseudo-inverse), with `ζ` such that `Σ_p V_p ∇̂Ψ_I = Σ_b Ψ_I(x_b) n_b a_b` at every node:
/// `K ζ = B − Σ_p V_p ∇Ψ_I`, `K_IJ = δ_IJ A_I − Σ_p V_p |Ψ_I| |Ψ_J| l_Iᵀ G_p⁺ l_J`,
/// `A_I = Σ_p V_p |Ψ_I|`. The right-hand side loses its least-squares fit by the linear fields
/// over each connected body's nodes (`K`'s null space; weighted by `A_I`, the fast step's
/// oblique projection); the system scaled by `A^{-1/2}` is
/// solved by the pseudo-inverse of its eigenvalues above `VC_NULL_EIGENVALUE` (the solution
/// of least `Σ_I A_I |ζ_I|²`, where the fast step's conjugate gradients, preconditioned with
/// `A_I` and started from zero, converge), then bounded by `VC_MAX_CORRECTION / h`.
fn vc_corrections_first_order<const D: usize>(
    sim: &Sim<D>,
    all_stencils: &[Stencil<D>],
    vc: &VcNodes<'_, D>,
) -> Vec<Vec<Vector<D>>> {
    let ps = &sim.particles;
    let grid = &sim.grid;
    let h = grid.cell_size;
    let VcNodes {
        surface,
        theta,
        members,
        stencils,
        row,
        body,
    } = vc;
    let used = row.len();
    let nodes: Vec<usize> = row.keys().copied().collect();
    let (mut a, mut rhs) = (vec![0.0; used], vec![Vector::<D>::zeros(); used]);
    for (&p, s) in members.iter().zip(stencils) {
        let v = ps.volume(p);
        for k in (0..s.nodes.len()).filter(|&k| in_support(s, k)) {
            let i = row[&s.nodes[k]];
            a[i] += v * s.values[k].abs();
            rhs[i] -= v * s.gradients[k];
        }
    }
    for b in 0..surface.len() {
        let sb = test_stencil(sim, &surface.position[b], *theta);
        for ((&n, &psi), &w) in sb.nodes.iter().zip(&sb.values).zip(&sb.transfer) {
            if let (true, Some(&i)) = (psi != 0.0, row.get(&n)) {
                rhs[i] += w * surface.area_normal[b];
            }
        }
    }
    // The fit is linear where it is chosen and the shape allows it (`Sim::set_vc_linear_fit`),
    // else the mean:
    // `[1, (x − c)/h]` or `[1]` at a node.
    let fitted = match sim.vc.as_ref().is_some_and(|vc| vc.linear_fit) {
        true => D + 1,
        false => 1,
    };
    let linear = |i: usize, c: &Vector<D>| -> DVector<f64> {
        let d = (node_position(grid, nodes[i]) - c) / h;
        DVector::from_iterator(
            fitted,
            std::iter::once(1.0).chain(d.iter().copied()).take(fitted),
        )
    };
    // Per body, the least-squares fit of the right-hand side by the linear fields, removed.
    let mut centroid = BTreeMap::<usize, (f64, Vector<D>)>::new();
    for i in 0..used {
        let e = centroid.entry(body[i]).or_insert((0.0, Vector::zeros()));
        e.0 += 1.0;
        e.1 += node_position(grid, nodes[i]);
    }
    let centre = |i: usize| centroid[&body[i]].1 / centroid[&body[i]].0;
    let mut fit = BTreeMap::<usize, (DMatrix<f64>, DMatrix<f64>)>::new();
    for i in 0..used {
        let l = linear(i, &centre(i));
        let e = fit
            .entry(body[i])
            .or_insert((DMatrix::zeros(fitted, fitted), DMatrix::zeros(fitted, D)));
        let w = if fitted > 1 { a[i] } else { 1.0 };
        e.0 += w * &l * l.transpose();
        e.1 += &l * DMatrix::from_row_slice(1, D, rhs[i].as_slice());
    }
    let coefficients: BTreeMap<usize, DMatrix<f64>> = fit
        .into_iter()
        .map(|(b, (g, t))| {
            let tolerance = 1e-12 * g.norm();
            (b, g.pseudo_inverse(tolerance).expect("an SVD") * t)
        })
        .collect();
    for i in 0..used {
        let w = if fitted > 1 { a[i] } else { 1.0 };
        let c = linear(i, &centre(i)).transpose() * &coefficients[&body[i]];
        rhs[i] -= w * Vector::<D>::from_fn(|k, _| c[k]);
    }
    // Per particle: its support `(row, |Ψ|, l)` and `G_p⁺`.
    type Support = Vec<(usize, f64, DVector<f64>)>;
    let fits: Vec<(Support, DMatrix<f64>)> = members
        .iter()
        .zip(stencils)
        .map(|(&p, s)| {
            let support: Support = (0..s.nodes.len())
                .filter(|&k| in_support(s, k))
                .map(|k| {
                    let i = row[&s.nodes[k]];
                    (i, s.values[k].abs(), linear(i, &ps.position[p]))
                })
                .collect();
            let g = support
                .iter()
                .fold(DMatrix::zeros(fitted, fitted), |g, (_, w, l)| {
                    g + *w * l * l.transpose()
                });
            let tolerance = 1e-10 * g[(0, 0)];
            (support, g.pseudo_inverse(tolerance).expect("an SVD"))
        })
        .collect();
    // K.
    let mut k = DMatrix::<f64>::from_diagonal(&DVector::from_vec(a.clone()));
    for (&p, (support, inverse)) in members.iter().zip(&fits) {
        let v = ps.volume(p);
        for (i, wi, li) in support {
            for (j, wj, lj) in support {
                k[(*i, *j)] -= v * wi * wj * (li.transpose() * inverse * lj)[(0, 0)];
            }
        }
    }
    // Scaled by the preconditioner, `K̃ = P^{-1/2} K P^{-1/2}` (`P = diag(A)`), and solved by
    // the pseudo-inverse of its eigenvalues above `VC_NULL_EIGENVALUE`.
    let scale: Vec<f64> = a
        .iter()
        .map(|&a| if a > 0.0 { 1.0 / a.sqrt() } else { 0.0 })
        .collect();
    let scaled = DMatrix::from_fn(used, used, |i, j| scale[i] * k[(i, j)] * scale[j]);
    let eigen = scaled.symmetric_eigen();
    let largest = eigen.eigenvalues.amax();
    let mut zeta = vec![Vector::<D>::zeros(); used];
    for c in 0..D {
        let b = DVector::from_iterator(used, (0..used).map(|i| scale[i] * rhs[i][c]));
        let mut y = DVector::<f64>::zeros(used);
        for (j, &lambda) in eigen.eigenvalues.iter().enumerate() {
            if lambda > VC_NULL_EIGENVALUE * largest {
                let u = eigen.eigenvectors.column(j);
                y += u * (u.dot(&b) / lambda);
            }
        }
        for i in 0..used {
            zeta[i][c] = scale[i] * y[i];
        }
    }
    let largest = a.iter().fold(0.0, |l: f64, &a| l.max(a));
    for (z, &a) in zeta.iter_mut().zip(&a) {
        let bound = first_order_correction_bound(a, largest);
        if z.norm() * h > bound {
            *z *= bound / (z.norm() * h);
        }
    }
    let mut corrections: Vec<Vec<Vector<D>>> = all_stencils
        .iter()
        .map(|s| vec![Vector::zeros(); s.nodes.len()])
        .collect();
    for ((&p, s), (support, inverse)) in members.iter().zip(stencils).zip(&fits) {
        // The fit's coefficients per direction, `G_p⁺ Σ_J |Ψ_J| l_J ζ_J`.
        let moments = support
            .iter()
            .fold(DMatrix::zeros(fitted, D), |t, (i, w, l)| {
                t + *w * l * DMatrix::from_row_slice(1, D, zeta[*i].as_slice())
            });
        let coefficients = inverse * moments;
        let mut next = support.iter();
        for k in (0..s.nodes.len()).filter(|&k| in_support(s, k)) {
            let (i, w, l) = next.next().expect("the support");
            let f = l.transpose() * &coefficients;
            corrections[p][k] = *w * (zeta[*i] - Vector::<D>::from_fn(|c, _| f[c]));
        }
    }
    corrections
}

/// Eigenvalues of the scaled order-n system below this fraction of the largest are its null
/// space. Over the property test's order-2 systems (84 to 357 unknowns) the null eigenvalues
/// (one per body, or three: the constant and the linear polynomials) lie below 1e-14 of the
/// largest, and the next smallest above 4e-8 (linear polynomials that nodes corrected to order 1
/// only just break), so any bound in between picks the same null space.
const VC_NULL_EIGENVALUE: f64 = 1e-12;

/// VC of order `n ≥ 2`: per particle and stencil node the correction
/// `|Ψ_I| (ζ_I·Q_I(x_p) − μ_p)`, `Q_I` the monomials of degree ≤ n − 1 in `(x − x_I)/h`,
/// `μ_p = Σ_J |Ψ_J| ζ_J·Q_J(x_p) / Σ_J |Ψ_J|`, so that for every node and every `Q`
/// `Σ_p V_p (∇̂Ψ_I Q + Ψ_I ∇Q) = Σ_b Ψ_I Q n_b a_b`:
///
/// ```text
/// K ζ = r,  K_(Iα)(Jβ) = δ_IJ A_I,αβ − Σ_p V_p |Ψ_I| |Ψ_J| Q_Iα Q_Jβ / W_p,
/// A_I = Σ_p V_p |Ψ_I| Q_I Q_Iᵀ,  r_Iα = Σ_b Φ_I Q_Iα n_b a_b − Σ_p V_p (∇Ψ_I Q_Iα + Φ_I ∇Q_Iα).
/// ```
///
/// (`Φ` the transfer weights, the test function: `Ψ` but at a signed shape's body edge.)
///
/// A node whose `A_I` is nearly singular (smallest to largest eigenvalue at most
/// `VC_MIN_RELATIVE_EIGENVALUE`) keeps its constant unknown only. The right-hand side loses,
/// per body, its least-squares fit by the node coefficients of the polynomials of degree < n
/// (`K`'s null space for a body without such nodes), re-expanded about each node, before those
/// nodes' higher rows are dropped. The system is scaled by the Cholesky factors of the blocks
/// `A_I` (the fast step's preconditioner), damped at the edge nodes as the fast step damps it
/// (`K + ε E A`, `VC_REGULARISATION`: `ε` on their scaled diagonal, scaled up to the floor
/// `VC_EDGE_DAMPING_FLOOR`) and solved by the
/// pseudo-inverse of its eigenvalues above `VC_NULL_EIGENVALUE`: where the fast step's conjugate
/// gradients, started from zero, converge.
fn vc_corrections_higher_order<const D: usize>(
    sim: &Sim<D>,
    all_stencils: &[Stencil<D>],
    vc: &VcNodes<'_, D>,
    order: u32,
) -> Vec<Vec<Vector<D>>> {
    let ps = &sim.particles;
    let grid = &sim.grid;
    let h = grid.cell_size;
    let VcNodes {
        surface,
        theta,
        members,
        stencils,
        row,
        body,
    } = vc;
    let basis = crate::shape::Monomials::<D>::up_to(order - 1);
    let m = basis.len();
    let used = row.len();
    let nodes: Vec<usize> = row.keys().copied().collect();
    // `Q_I(x)` and `∂Q_I/∂x_k` (per length).
    let q_at = |i: usize, x: &Vector<D>| -> (Vec<f64>, Vec<Vec<f64>>) {
        let z = (x - node_position(grid, nodes[i])) / h;
        let mut q = vec![0.0; m];
        basis.values(&z, &mut q);
        let dq = (0..D)
            .map(|k| {
                let mut d = vec![0.0; m];
                basis.derivatives(&z, k, &mut d);
                d.iter().map(|d| d / h).collect()
            })
            .collect();
        (q, dq)
    };
    let mut a = vec![DMatrix::<f64>::zeros(m, m); used];
    // r[i][(α, k)]: the equality of monomial α along direction k.
    let mut r = vec![DMatrix::<f64>::zeros(m, D); used];
    for (&p, s) in members.iter().zip(stencils) {
        let v = ps.volume(p);
        for k in (0..s.nodes.len()).filter(|&k| in_support(s, k)) {
            let i = row[&s.nodes[k]];
            let (q, dq) = q_at(i, &ps.position[p]);
            for al in 0..m {
                for be in 0..m {
                    a[i][(al, be)] += v * s.values[k].abs() * q[al] * q[be];
                }
                for c in 0..D {
                    r[i][(al, c)] -= v * (s.gradients[k][c] * q[al] + s.transfer[k] * dq[c][al]);
                }
            }
        }
    }
    for b in 0..surface.len() {
        let sb = test_stencil(sim, &surface.position[b], *theta);
        for ((&n, &psi), &w) in sb.nodes.iter().zip(&sb.values).zip(&sb.transfer) {
            if let (true, Some(&i)) = (psi != 0.0, row.get(&n)) {
                let (q, _) = q_at(i, &surface.position[b]);
                for al in 0..m {
                    for c in 0..D {
                        r[i][(al, c)] += w * q[al] * surface.area_normal[b][c];
                    }
                }
            }
        }
    }
    // Per body, the node coefficients `N_I` of the polynomials of degree < n about the body's
    // node centroid `x_c`: column f holds `((x − x_c)/h)^f` re-expanded in `(x − x_I)/h`.
    let exps = basis.exponents();
    let mut centroid = BTreeMap::<usize, (f64, Vector<D>)>::new();
    for i in 0..used {
        let e = centroid.entry(body[i]).or_insert((0.0, Vector::zeros()));
        e.0 += 1.0;
        e.1 += node_position(grid, nodes[i]);
    }
    let binomial = |n: u32, k: u32| (0..k).fold(1.0, |c, i| c * (n - i) as f64 / (i + 1) as f64);
    let null_at = |i: usize| {
        let (count, sum) = centroid[&body[i]];
        let d = (node_position(grid, nodes[i]) - sum / count) / h;
        DMatrix::<f64>::from_fn(m, m, |e, f| {
            let (ee, ff) = (exps[e], exps[f]);
            match (0..D).all(|a| ee[a] <= ff[a]) {
                true => (0..D)
                    .map(|a| binomial(ff[a], ee[a]) * d[a].powi((ff[a] - ee[a]) as i32))
                    .product(),
                false => 0.0,
            }
        })
    };
    let mut fit = BTreeMap::<usize, (DMatrix<f64>, DMatrix<f64>)>::new();
    for i in 0..used {
        let n = null_at(i);
        let e = fit
            .entry(body[i])
            .or_insert((DMatrix::zeros(m, m), DMatrix::zeros(m, D)));
        e.0 += n.transpose() * &n;
        e.1 += n.transpose() * &r[i];
    }
    let coefficients: BTreeMap<usize, DMatrix<f64>> = fit
        .into_iter()
        .map(|(b, (g, t))| (b, g.cholesky().expect("the Gram matrix").solve(&t)))
        .collect();
    for i in 0..used {
        r[i] -= null_at(i) * &coefficients[&body[i]];
    }
    // The unknowns: `m` per node, one for a node whose moment matrix is nearly singular.
    let reduced: Vec<bool> = a
        .iter()
        .map(|a| {
            let eig = a.clone().symmetric_eigenvalues();
            eig.min() <= crate::integration::VC_MIN_RELATIVE_EIGENVALUE * eig.max()
        })
        .collect();
    let width: Vec<usize> = reduced.iter().map(|&r| if r { 1 } else { m }).collect();
    let first: Vec<usize> = width
        .iter()
        .scan(0, |next, &w| {
            let f = *next;
            *next += w;
            Some(f)
        })
        .collect();
    let unknowns = first.last().map_or(0, |f| f + width[used - 1]);
    let mut k = DMatrix::<f64>::zeros(unknowns, unknowns);
    let mut factor = DMatrix::<f64>::zeros(unknowns, unknowns);
    for i in 0..used {
        let (f, w) = (first[i], width[i]);
        let block = a[i].view((0, 0), (w, w)).clone_owned();
        k.view_mut((f, f), (w, w)).copy_from(&block);
        let l = block.cholesky().expect("a node block").l();
        factor.view_mut((f, f), (w, w)).copy_from(&l);
    }
    for (&p, s) in members.iter().zip(stencils) {
        let v = ps.volume(p);
        let mut entries = Vec::new();
        let mut weight = 0.0;
        for k in (0..s.nodes.len()).filter(|&k| in_support(s, k)) {
            let i = row[&s.nodes[k]];
            let (q, _) = q_at(i, &ps.position[p]);
            let w = s.values[k].abs();
            weight += w;
            entries.extend((0..width[i]).map(|al| (first[i] + al, w * q[al])));
        }
        for &(u, eu) in &entries {
            for &(t, et) in &entries {
                k[(u, t)] -= v * eu * et / weight;
            }
        }
    }
    let inverse = factor
        .try_inverse()
        .expect("the node blocks' Cholesky factors");
    let mut scaled = &inverse * &k * inverse.transpose();
    // The edge nodes' damping `ε A_I`, scaled up to its floor: `ε` times that scale on their
    // unknowns once scaled.
    let reach = a.iter().map(|a| a[(0, 0)]).fold(0.0, f64::max);
    for i in 0..used {
        if reduced[i] || a[i][(0, 0)] < VC_EDGE_REACH * reach {
            let floor = match a[i][(0, 0)] > 0.0 {
                true => (VC_EDGE_DAMPING_FLOOR * reach / a[i][(0, 0)]).max(1.0),
                false => 1.0,
            };
            for al in 0..width[i] {
                scaled[(first[i] + al, first[i] + al)] += VC_REGULARISATION * floor;
            }
        }
    }
    let eigen = scaled.symmetric_eigen();
    let largest = eigen.eigenvalues.amax();
    let mut zeta = vec![DMatrix::<f64>::zeros(m, D); used];
    for c in 0..D {
        let mut b = DVector::<f64>::zeros(unknowns);
        for i in 0..used {
            for al in 0..width[i] {
                b[first[i] + al] = r[i][(al, c)];
            }
        }
        let b = &inverse * b;
        let mut y = DVector::<f64>::zeros(unknowns);
        for (j, &lambda) in eigen.eigenvalues.iter().enumerate() {
            if lambda > VC_NULL_EIGENVALUE * largest {
                let u = eigen.eigenvectors.column(j);
                y += u * (u.dot(&b) / lambda);
            }
        }
        let x = inverse.transpose() * y;
        for i in 0..used {
            for al in 0..width[i] {
                zeta[i][(al, c)] = x[first[i] + al];
            }
        }
    }
    let mut corrections: Vec<Vec<Vector<D>>> = all_stencils
        .iter()
        .map(|s| vec![Vector::zeros(); s.nodes.len()])
        .collect();
    for (&p, s) in members.iter().zip(stencils) {
        let support: Vec<usize> = (0..s.nodes.len()).filter(|&k| in_support(s, k)).collect();
        // `ζ_I·Q_I(x_p)` per support node.
        let value: Vec<Vector<D>> = support
            .iter()
            .map(|&k| {
                let i = row[&s.nodes[k]];
                let (q, _) = q_at(i, &ps.position[p]);
                Vector::<D>::from_fn(|c, _| (0..m).map(|al| zeta[i][(al, c)] * q[al]).sum())
            })
            .collect();
        let weight: f64 = support.iter().map(|&k| s.values[k].abs()).sum();
        let mu = support
            .iter()
            .zip(&value)
            .map(|(&k, g)| s.values[k].abs() * g)
            .sum::<Vector<D>>()
            / weight;
        for (&k, g) in support.iter().zip(&value) {
            corrections[p][k] = s.values[k].abs() * (g - mu);
        }
    }
    corrections
}

/// What one map to the grid maps.
struct Map<'a, const D: usize> {
    /// The particles' velocities and APIC matrices: their own, or the new ones in MUSL's second
    /// map (no matrices: none mapped).
    velocity: &'a [Vector<D>],
    affine: &'a [Matrix<D>],
    /// `(Δt, body accelerations)` (gravity added here): also map mass and forces.
    forces: Option<(f64, &'a [Vector<D>])>,
    /// VC's corrections of the gradients in the internal force, per particle and stencil node.
    vc: Option<&'a [Vec<Vector<D>>]>,
    /// Under contact, the body (material) whose particles map.
    body: Option<u32>,
}

/// Maps `m_p Ψ (v_p + C_p (x_I − x_p))` (and, with forces, `m_p Ψ` and the forces) of every
/// particle (of the body) to `nodes`. The body force goes to `nodes.body_force` when the nodes
/// keep it apart.
fn map_to_grid<const D: usize>(
    sim: &Sim<D>,
    stencils: &[Stencil<D>],
    map: &Map<'_, D>,
    nodes: &mut GridNodes<D>,
) {
    let Map {
        velocity,
        affine,
        forces,
        vc,
        body,
    } = *map;
    let keep_body_force = !nodes.body_force.is_empty();
    let with_gradient = !nodes.mass_gradient.is_empty();
    let ps = &sim.particles;
    let mls = matches!(sim.options.transfer, Transfer::Mls);
    let inverse_inertia = sim.shape.apic_inertia(sim.grid.cell_size).map(|d| 1.0 / d);
    for (p, s) in stencils.iter().enumerate() {
        if body.is_some_and(|b| ps.material[p] != b) {
            continue;
        }
        let m = ps.mass[p];
        let volume = ps.volume(p);
        let mut mv = m * velocity[p];
        let mut mc = (!affine.is_empty()).then(|| m * affine[p]);
        let mut internal = forces.map(|_| -volume * ps.stress[p]);
        let mut body = forces.map(|(_, a)| sim.options.gravity + a[p]);
        if let (true, Some((dt, _)), Some(b)) = (mls, forces, body) {
            // MLS: the forces ride on the momentum (METHOD.md section 1).
            mv += (dt * m) * b;
            mc = mc.map(|mc| mc + (dt * inverse_inertia.unwrap()) * internal.unwrap());
            (internal, body) = (None, None);
        }
        for (k, ((&n, &w), g)) in s
            .nodes
            .iter()
            .zip(&s.transfer)
            .zip(&s.gradients)
            .enumerate()
        {
            if w == 0.0 && *g == Vector::<D>::zeros() {
                continue;
            }
            nodes.touch(n);
            let offset = node_position(&sim.grid, n) - ps.position[p];
            let momentum = match mc {
                Some(mc) => mv + mc * offset,
                None => mv,
            };
            nodes.momentum[n] += w * momentum;
            if forces.is_some() {
                nodes.mass[n] += m * w;
                if with_gradient {
                    nodes.mass_gradient[n] += m * g;
                }
            }
            if let Some(vs) = internal {
                let correction = vc.map_or(Vector::zeros(), |vc| vc[p][k]);
                nodes.force[n] += vs * (g + correction);
            }
            match body {
                Some(b) if keep_body_force => nodes.body_force[n] += (m * w) * b,
                Some(b) => nodes.force[n] += (m * w) * b,
                None => {}
            }
        }
    }
}

/// Grid update: `v_I = ((mv)_I + Δt f_I) / m_I` (or `(mv)_I / m_I` for MUSL's second map, `dt =
/// None`) with the wall conditions; nodes at or below `mass_floor` get no velocity. When the
/// body force is kept apart (VC), the internal force is divided by at least 1 % of the largest
/// node mass, and without walls the force so held back is handed to the whole field.
fn update_grid<const D: usize>(
    sim: &Sim<D>,
    nodes: &mut GridNodes<D>,
    dt: Option<f64>,
    mass_floor: f64,
) {
    let walls = &sim.options.walls;
    walls.fold(&sim.grid, nodes, dt.is_some());
    let apart = !nodes.body_force.is_empty() && dt.is_some();
    let largest = nodes
        .active
        .iter()
        .map(|&n| nodes.mass[n])
        .fold(0.0, f64::max);
    let force_floor = if apart { 1e-2 * largest } else { 0.0 };
    let mut held = Vec::<(Vector<D>, Vector<D>)>::new();
    let position = |n: usize| node_position(&sim.grid, n);
    for k in 0..nodes.active.len() {
        let n = nodes.active[k];
        let m = nodes.mass[n];
        let body = match apart {
            true => nodes.body_force[n],
            false => Vector::zeros(),
        };
        if m <= mass_floor {
            if let Some(dt) = dt {
                held.push((position(n), nodes.force[n] + body + nodes.momentum[n] / dt));
            }
            nodes.velocity[n] = Vector::zeros();
            nodes.velocity_old[n] = Vector::zeros();
            continue;
        }
        if m < force_floor {
            held.push((position(n), nodes.force[n] * (1.0 - m / force_floor)));
        }
        match dt {
            Some(dt) => {
                nodes.velocity_old[n] = nodes.momentum[n] / m;
                nodes.velocity[n] =
                    (nodes.momentum[n] + dt * body) / m + dt * nodes.force[n] / m.max(force_floor);
            }
            None => nodes.velocity[n] = nodes.momentum[n] / m,
        }
    }
    if let (Some(dt), true) = (dt, apart && !walls.any_wall()) {
        // The rigid-body velocity field `Σ_j c_j g_j` (the translations and the rotations about
        // the receivers' mass centre) that does the held forces' work on every rigid mode:
        // `Σ_I m_I g_j(x_I)·δv_I = Δt Σ_f g_j(x_f)·f`, so that momentum and angular momentum
        // change by the held forces' sum and moment.
        let receivers: Vec<usize> = (nodes.active.iter().copied())
            .filter(|&n| nodes.mass[n] > mass_floor)
            .collect();
        let total: f64 = receivers.iter().map(|&n| nodes.mass[n]).sum();
        let centre = receivers
            .iter()
            .map(|&n| nodes.mass[n] * position(n))
            .sum::<Vector<D>>()
            / total;
        let modes = |x: &Vector<D>| -> Vec<Vector<D>> {
            let mut g: Vec<Vector<D>> = (0..D)
                .map(|k| Vector::<D>::from_fn(|i, _| if i == k { 1.0 } else { 0.0 }))
                .collect();
            g.extend(rotations(x, &centre));
            g
        };
        let count = modes(&Vector::zeros()).len();
        let mut gram = DMatrix::<f64>::zeros(count, count);
        for &n in &receivers {
            let g = modes(&position(n));
            for i in 0..count {
                for j in 0..count {
                    gram[(i, j)] += nodes.mass[n] * g[i].dot(&g[j]);
                }
            }
        }
        let work = DVector::from_iterator(
            count,
            (0..count).map(|i| held.iter().map(|(x, f)| modes(x)[i].dot(f)).sum::<f64>()),
        );
        if !receivers.is_empty() && !held.is_empty() {
            let tolerance = 1e-12 * gram.norm();
            let c = gram.pseudo_inverse(tolerance).expect("an SVD") * work;
            for &n in &receivers {
                let g = modes(&position(n));
                nodes.velocity[n] += dt * (0..count).map(|i| c[i] * g[i]).sum::<Vector<D>>();
            }
        }
    }
    walls.apply_friction(&sim.grid, nodes);
    walls.unfold(&sim.grid, nodes);
}

/// The rigid rotations `g_j(x)` about `centre`: `e_b (x − c)_a − e_a (x − c)_b`, `a < b`.
fn rotations<const D: usize>(x: &Vector<D>, centre: &Vector<D>) -> Vec<Vector<D>> {
    let r = x - centre;
    let mut g = Vec::new();
    for a in 0..D {
        for b in a + 1..D {
            let mut v = Vector::<D>::zeros();
            v[a] = -r[b];
            v[b] = r[a];
            g.push(v);
        }
    }
    g
}

/// VC's internal forces lose, per connected body of nodes (nodes joined by a particle's
/// support) that no wall acts on, the rigid rotation `m_I Σ_j c_j g_j(x_I)` about the body's
/// node mass centre whose moments `Σ_I g_j(x_I)·f_I` are the forces' own: then they exert no
/// torque.
fn remove_vc_torque<const D: usize>(
    sim: &Sim<D>,
    stencils: &[Stencil<D>],
    body: Option<u32>,
    nodes: &mut GridNodes<D>,
) {
    let ps = &sim.particles;
    let mut label: BTreeMap<usize, usize> = BTreeMap::new();
    let of_particle: Vec<Vec<usize>> = (0..ps.len())
        .map(|p| match body.is_some_and(|b| ps.material[p] != b) {
            true => Vec::new(),
            false => (stencils[p].nodes.iter().enumerate())
                .filter(|&(k, _)| {
                    stencils[p].values[k] != 0.0 || stencils[p].gradients[k] != Vector::<D>::zeros()
                })
                .map(|(_, &n)| n)
                .collect(),
        })
        .collect();
    // Labels spread along the particles' supports until no label changes.
    for ns in &of_particle {
        for &n in ns {
            let next = label.len();
            label.entry(n).or_insert(next);
        }
    }
    let mut changed = true;
    while changed {
        changed = false;
        for ns in &of_particle {
            let least = ns.iter().map(|n| label[n]).min();
            for n in ns {
                if Some(label[n]) != least {
                    label.insert(*n, least.unwrap());
                    changed = true;
                }
            }
        }
    }
    let mut members: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for (&n, &l) in &label {
        members.entry(l).or_default().push(n);
    }
    let position = |n: usize| node_position(&sim.grid, n);
    // With walls, the forces as the grid update applies them: a node below 1 % of the largest
    // node mass keeps `m / m_floor` of its force, the rest is dropped.
    let largest = (nodes.active.iter())
        .map(|&n| nodes.mass[n])
        .fold(0.0, f64::max);
    let floor = match sim.options.walls.any_wall() {
        true => 1e-2 * largest,
        false => 0.0,
    };
    let applied = |m: f64| if m < floor { m / floor } else { 1.0 };
    let walls = &sim.options.walls;
    for ns in members.values() {
        let total: f64 = ns.iter().map(|&n| nodes.mass[n]).sum();
        // Bodies that a wall acts on keep their torque.
        let walled = ns
            .iter()
            .any(|&n| walls.acts_on(&sim.grid, &sim.grid.node_multi_index(n)));
        if total <= 0.0 || walled {
            continue;
        }
        let centre = ns
            .iter()
            .map(|&n| nodes.mass[n] * position(n))
            .sum::<Vector<D>>()
            / total;
        let count = rotations(&centre, &centre).len();
        let mut gram = DMatrix::<f64>::zeros(count, count);
        let mut moments = DVector::<f64>::zeros(count);
        for &n in ns {
            let g = rotations(&position(n), &centre);
            for i in 0..count {
                moments[i] += g[i].dot(&(applied(nodes.mass[n]) * nodes.force[n]));
                for j in 0..count {
                    gram[(i, j)] += nodes.mass[n] * g[i].dot(&g[j]);
                }
            }
        }
        let tolerance = 1e-12 * gram.norm();
        let c = gram.pseudo_inverse(tolerance).expect("an SVD") * moments;
        for &n in ns {
            let g = rotations(&position(n), &centre);
            nodes.force[n] -= nodes.mass[n] * (0..count).map(|i| c[i] * g[i]).sum::<Vector<D>>();
        }
    }
}

/// `Σ_I Ψ_I v_I`, `Σ_I Ψ_I (v_I − v_old_I)`, `Σ_I Ψ_I v_I (x_I − x_p)ᵀ` and `Σ_I v_I ⊗ ∇Ψ_I`.
fn gather<const D: usize>(
    grid: &Grid<D>,
    s: &Stencil<D>,
    x: &Vector<D>,
    nodes: &GridNodes<D>,
) -> (Vector<D>, Vector<D>, Matrix<D>, Matrix<D>) {
    let (mut v, mut dv, mut b, mut l) = (
        Vector::<D>::zeros(),
        Vector::<D>::zeros(),
        Matrix::<D>::zeros(),
        Matrix::<D>::zeros(),
    );
    for ((&n, &w), g) in s.nodes.iter().zip(&s.transfer).zip(&s.gradients) {
        let vi = nodes.velocity[n];
        v += w * vi;
        dv += w * (vi - nodes.velocity_old[n]);
        b += (w * vi) * (node_position(grid, n) - x).transpose();
        l += vi * g.transpose();
    }
    (v, dv, b, l)
}

/// One step of `sim` by the reference method; the particles get the new state. Fails (with the
/// particles unchanged) when a new state is not finite, inverted or outside the grid.
pub(crate) fn reference_step<const D: usize>(sim: &mut Sim<D>, dt: f64) -> crate::Result<()> {
    assert!(
        sim.boundary.is_empty() || sim.options.contact.is_none(),
        "given boundary points are for one body"
    );
    assert!(
        sim.particles.in_id_order(),
        "the reference step keeps particles in id order"
    );
    // The found surface of this step when it is found anew (then kept, and moved on when carried).
    let plan = sim.surface_plan();
    let own = sim.vc.is_some() && sim.boundary.is_empty() && sim.options.contact.is_none();
    let found_surface = match own && plan.find {
        true => Some(crate::step::found_surface(&sim.grid, &sim.particles, None)?),
        false => None,
    };
    let mut acceleration = vec![Vector::<D>::zeros(); sim.particles.len()];
    if let Some(bf) = sim.body_force.as_mut() {
        let ps = &sim.particles;
        bf.accelerations(
            sim.time,
            &ps.reference_position,
            &ps.position,
            &mut acceleration,
        )
        .map_err(|m| crate::Error::new(crate::ErrorKind::Callback, m))?;
    }
    let ps = &sim.particles;
    let grid = &sim.grid;
    let mut stencils: Vec<Stencil<D>> = ps.position.iter().map(|x| stencil(sim, x)).collect();
    let signed = sim.shape.is_signed();
    // One node field, or under contact one per body (material), each with its own transfer
    // weights, VC correction, maps and grid update; a rigid body's nodes take its velocity.
    let contact = sim.options.contact;
    let bodies: Vec<Option<u32>> = match contact {
        Some(_) => (0..sim.materials.len() as u32).map(Some).collect(),
        None => vec![None],
    };
    let rigid: Vec<Option<Vector<D>>> = sim.materials.iter().map(|m| m.rigid_velocity()).collect();
    let largest_mass = ps.mass.iter().copied().fold(0.0, f64::max);
    let floored = signed || matches!(sim.options.shape, Shape::Linear);
    let mass_floor = if floored { 1e-10 * largest_mass } else { 0.0 };
    let mut fields = Vec::new();
    for &body in &bodies {
        let theta = match signed {
            true => Some(blend_transfer_weights(sim, &mut stencils, body)?),
            false => None,
        };
        let mut nodes = GridNodes::<D>::default();
        nodes.ensure(grid, false, contact.is_some(), signed || sim.vc.is_some())?;
        let rigid_velocity = body.and_then(|b| rigid[b as usize]);
        // VC's corrections, particle to grid, grid update.
        let vc = match &sim.vc {
            Some(vc) if rigid_velocity.is_none() => Some(vc_corrections(
                sim,
                &stencils,
                body,
                vc.order,
                theta.as_deref(),
            )?),
            _ => None,
        };
        let map = Map {
            velocity: &ps.velocity,
            affine: &ps.affine,
            forces: Some((dt, &acceleration)),
            vc: vc.as_deref(),
            body,
        };
        map_to_grid(sim, &stencils, &map, &mut nodes);
        if vc.is_some() {
            remove_vc_torque(sim, &stencils, body, &mut nodes);
        }
        // The given boundary points' tractions: `t_b |n_b a_b|` on the nodes by `Ψ_I(x_b)`.
        if sim.boundary.has_tractions() {
            for b in 0..sim.boundary.len() {
                let force = sim.boundary.traction[b] * sim.boundary.area_normal[b].norm();
                let sb = stencil(sim, &sim.boundary.position[b]);
                for (&n, &w) in sb.nodes.iter().zip(&sb.values).filter(|(_, &w)| w != 0.0) {
                    nodes.touch(n);
                    nodes.force[n] += w * force;
                }
            }
        }
        update_grid(sim, &mut nodes, Some(dt), mass_floor);
        if let Some(v) = rigid_velocity {
            for k in 0..nodes.active.len() {
                let n = nodes.active[k];
                (nodes.velocity[n], nodes.velocity_old[n]) = (v, v);
            }
        }
        fields.push(nodes);
    }
    if let Some(contact) = contact {
        let shared: Vec<usize> = (0..grid.node_count())
            .filter(|&n| fields.iter().filter(|f| f.is_touched(n)).count() > 1)
            .collect();
        crate::contact::correct_velocities(&contact, &mut fields, &rigid, &shared);
    }
    let field_of = |p: usize| match contact {
        Some(_) => &fields[ps.material[p] as usize],
        None => &fields[0],
    };

    // Grid to particle.
    let (flip, apic, mls) = match sim.options.transfer {
        Transfer::PicFlip { flip } => (flip, false, false),
        Transfer::Apic => (0.0, true, false),
        Transfer::Mls => (0.0, true, true),
    };
    let inverse_inertia = sim.shape.apic_inertia(grid.cell_size).map(|d| 1.0 / d);
    let n = ps.len();
    let (mut x, mut v, mut c, mut l) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    for (p, s) in stencils.iter().enumerate() {
        if let Some(v_rigid) = rigid[ps.material[p] as usize] {
            // A rigid body's particles move with it and keep their `F`.
            x.push(ps.position[p] + dt * v_rigid);
            v.push(v_rigid);
            c.push(Matrix::zeros());
            l.push(Matrix::zeros());
            continue;
        }
        let (v_pic, dv, b, gradient) = gather(grid, s, &ps.position[p], field_of(p));
        x.push(ps.position[p] + dt * v_pic);
        v.push(match flip > 0.0 {
            true => (1.0 - flip) * v_pic + flip * (ps.velocity[p] + dv),
            false => v_pic,
        });
        let affine = inverse_inertia.map(|inv| b * inv);
        let lp = match (mls, affine) {
            (true, Some(c)) => c,
            _ => gradient,
        };
        c.push(if apic {
            affine.unwrap_or(lp)
        } else {
            Matrix::zeros()
        });
        l.push(lp);
    }
    if sim.options.scheme == crate::options::Scheme::Musl {
        // The new momenta to the grid again; the velocity gradient from those velocities (one
        // field: contact runs under USL only).
        let nodes = &mut fields[0];
        for &k in &nodes.active {
            nodes.momentum[k] = Vector::zeros();
        }
        let new_affine = if apic { c.clone() } else { Vec::new() };
        let map = Map {
            velocity: &v,
            affine: &new_affine,
            forces: None,
            vc: None,
            body: None,
        };
        map_to_grid(sim, &stencils, &map, nodes);
        update_grid(sim, nodes, None, mass_floor);
        for (p, s) in stencils.iter().enumerate() {
            let (_, _, b, gradient) = gather(grid, s, &ps.position[p], nodes);
            l[p] = match (mls, inverse_inertia) {
                (true, Some(inv)) => b * inv,
                _ => gradient,
            };
        }
    }

    // Given boundary points (with VC or tractions) move with the grid like massless particles,
    // and so does a found surface the next step takes again (`Sim::set_vc_surface_refresh`).
    let domain = grid.domain();
    let mut boundary = sim.boundary.clone();
    if sim.vc.is_some() || boundary.has_tractions() {
        move_with_grid(sim, &fields[0], dt, false, &mut boundary)?;
    }
    let mut surface = match found_surface {
        Some(found) => found,
        None => sim.surface.clone(),
    };
    // A carried surface stays inside the grid's box; one that cannot be carried is found anew
    // by the next step (`checks::settle_carried_surface`).
    let mut carried = plan.carry;
    if plan.carry {
        let mut moved = surface.clone();
        carried = move_with_grid(sim, &fields[0], dt, true, &mut moved).is_ok();
        if carried {
            surface = moved;
        }
    }

    // Constitutive update and checks.
    let mut new = ps.clone();
    for p in 0..n {
        let f = (Matrix::<D>::identity() + dt * l[p]) * ps.deformation_gradient[p];
        let j = crate::determinant(&f);
        let material = &sim.materials[ps.material[p] as usize];
        let mut position = x[p];
        if j.is_nan() || j <= 0.0 {
            return Err(crate::Error::new(
                crate::ErrorKind::InvertedParticle,
                format!("particle {} inverted", ps.id[p]),
            ));
        }
        let (stress, pressure_p) = if material.is_elastic() {
            material.elastic_stress_and_wave_speed(&f, j).0
        } else {
            let df = embed3(&f) * embed3(&ps.deformation_gradient[p]).try_inverse().unwrap();
            let (state, s3) = material.plastic_update(&ps.history[p], &df, j, dt);
            new.history[p] = state;
            (block(&s3), pressure(&s3))
        };
        if sim.options.walls.any_wall() {
            sim.options.walls.clamp_to_walls(&domain, &mut position);
        }
        if !domain.contains(&position) || !stress.iter().all(|s| s.is_finite()) {
            return Err(crate::Error::new(
                crate::ErrorKind::OutsideGrid,
                format!("particle {} outside or not finite", ps.id[p]),
            ));
        }
        new.position[p] = position;
        new.velocity[p] = v[p];
        new.deformation_gradient[p] = f;
        new.stress[p] = stress;
        new.pressure[p] = pressure_p;
        if apic {
            new.affine[p] = c[p];
        }
    }
    sim.particles = new;
    sim.boundary = boundary;
    sim.surface = surface;
    sim.surface_age = crate::step::surface_age_after(sim.surface_age, plan, carried);
    sim.time += dt;
    sim.steps += 1;
    Ok(())
}

/// Moves boundary points with the grid like massless particles: `F_b` with the velocity
/// gradient there, `n a` by Nanson's formula `J F⁻ᵀ N A`; they must stay finite, uninverted and
/// inside the grid (clamped into the grid's box when `inside`, then onto walls).
fn move_with_grid<const D: usize>(
    sim: &Sim<D>,
    nodes: &GridNodes<D>,
    dt: f64,
    inside: bool,
    points: &mut crate::BoundaryPoints<D>,
) -> crate::Result<()> {
    let (grid, domain) = (&sim.grid, sim.grid.domain());
    for b in 0..points.len() {
        let sb = stencil(sim, &points.position[b]);
        let (v_b, _, _, l_b) = gather(grid, &sb, &points.position[b], nodes);
        let f = (Matrix::<D>::identity() + dt * l_b) * points.deformation_gradient[b];
        let j = crate::determinant(&f);
        let area_normal = match f.try_inverse() {
            Some(fi) => j * fi.transpose() * points.reference_area_normal[b],
            None => Vector::from_element(f64::NAN),
        };
        let mut position = points.position[b] + dt * v_b;
        if inside {
            for a in 0..D {
                if position[a].is_finite() {
                    position[a] = position[a].max(domain.lower[a]).min(domain.upper[a]);
                }
            }
        }
        sim.options.walls.clamp_to_walls(&domain, &mut position);
        let finite = position
            .iter()
            .chain(area_normal.iter())
            .all(|c| c.is_finite());
        if !finite || j <= 0.0 || !domain.contains(&position) {
            return Err(crate::Error::new(
                crate::ErrorKind::InvertedParticle,
                format!("boundary point {b} is not admissible"),
            ));
        }
        points.position[b] = position;
        points.deformation_gradient[b] = f;
        points.area_normal[b] = area_normal;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::options::{Integration, Scheme, Side, Wall};
    use crate::shape::UniformRng;
    use crate::{Field, Material};
    use proptest::prelude::*;

    /// One random scene: the choices and the seed of its particles.
    #[derive(Debug, Clone)]
    struct Case {
        seed: u64,
        shape: usize,
        transfer: usize,
        flip: f64,
        musl: bool,
        walls: [usize; 6],
        material: usize,
        body_force: bool,
        /// VC's order, 0 for material-point integration; up to 3 in 2D; in 3D order 2 on the
        /// small scene only (on the 8-cell scene its dense reference solve has 1,400 to 5,300
        /// unknowns: seconds to minutes a step) and order 3 not at all.
        vc: u32,
        /// In 3D, the scene on 6 cells instead of 8.
        small: bool,
        /// 0: one body; 1: two deformable bodies in contact; 2: a deformable and a rigid one.
        contact: usize,
        /// The fast step's paths: vector instructions, factored stencils, particle sorting.
        fast_paths: (bool, bool, bool),
        /// Without contact, 0: no boundary points (VC finds the surface); 1: the block's faces
        /// given as boundary points; 2: those with tractions.
        boundary: usize,
    }

    fn cases() -> impl Strategy<Value = Case> {
        (
            any::<u64>(),
            0..7usize,
            0..3usize,
            0.0..1.0f64,
            any::<bool>(),
            prop::array::uniform6(0..4usize),
            0..5usize,
            any::<bool>(),
            (0..4u32, 0..3usize),
            0..3usize,
            (any::<bool>(), any::<bool>(), any::<bool>()),
        )
            .prop_map(
                |(
                    seed,
                    shape,
                    transfer,
                    flip,
                    musl,
                    walls,
                    material,
                    body_force,
                    (vc, contact),
                    boundary,
                    fast_paths,
                )| Case {
                    seed,
                    shape,
                    transfer,
                    flip,
                    musl,
                    walls,
                    material,
                    body_force,
                    vc,
                    contact,
                    boundary,
                    fast_paths,
                    small: false,
                },
            )
    }

    /// A block of jittered particles against the low faces, moving randomly under gravity,
    /// with the options of `case`.
    fn scene<const D: usize>(case: &Case) -> Sim<D> {
        let cells = match (D, case.small) {
            (2, _) => 12,
            (_, true) => 6,
            _ => 8,
        };
        let h = 1.0 / cells as f64;
        let mut sim = Sim::<D>::new(Vector::<D>::zeros(), [cells; D], h).unwrap();
        let shape = [
            Shape::Linear,
            Shape::BSpline2,
            Shape::BSpline3,
            Shape::Rk {
                order: 1,
                support: 2.0,
            },
            Shape::Rk {
                order: 2,
                support: 3.0,
            },
            // RK1 off the lattice (ã = 2.5: node by node, not the cubic B-spline).
            Shape::Rk {
                order: 1,
                support: 2.5,
            },
            // RK3 in 2D; in 3D RK2 (RK3's 512-node stencils run on the small scene only, below).
            Shape::Rk {
                order: if D == 2 { 3 } else { 2 },
                support: if D == 2 { 4.0 } else { 3.0 },
            },
            // RK3 in 2D and 3D (not drawn at random: `fast_step_matches_the_reference_step_rk3`).
            Shape::Rk {
                order: 3,
                support: 4.0,
            },
        ][case.shape];
        sim.set_shape(shape).unwrap();
        sim.set_fast_paths(crate::options::FastPaths {
            vector_instructions: case.fast_paths.0,
            factored_stencils: case.fast_paths.1,
            particle_sorting: case.fast_paths.2,
        });
        // APIC and MLS do not take RK of order 2 or more (signed).
        let signed = matches!(shape, Shape::Rk { order: 2.., .. });
        let transfer = match case.transfer {
            _ if signed => Transfer::PicFlip { flip: case.flip },
            0 => Transfer::PicFlip { flip: case.flip },
            2 if matches!(shape, Shape::BSpline2 | Shape::BSpline3) && case.vc == 0 => {
                Transfer::Mls
            }
            _ => Transfer::Apic,
        };
        sim.set_transfer(transfer).unwrap();
        if case.vc > 0 {
            // In 3D order 1 on the 8-cell scene, at most 2 on the small one (VC3's dense
            // reference solve has thousands of unknowns).
            let order = match D {
                2 => case.vc,
                _ if case.small => case.vc.min(2),
                _ => 1,
            };
            sim.set_integration(Integration::Vc { order }).unwrap();
            // The reference solves densely, to round-off: the fast step solves exactly too.
            sim.set_vc_solve(crate::VcSolve::EXACT).unwrap();
        }
        // Contact runs under USL only.
        let scheme = if case.musl && case.contact == 0 {
            Scheme::Musl
        } else {
            Scheme::Usl
        };
        if case.contact > 0 {
            sim.set_contact(Some(0.3)).unwrap();
        }
        sim.set_scheme(scheme).unwrap();
        for a in 0..D {
            for (k, side) in [Side::Low, Side::High].into_iter().enumerate() {
                let wall = [Wall::Free, Wall::Fixed, Wall::Slip, Wall::Friction(0.3)]
                    [case.walls[2 * a + k]];
                sim.set_wall(a, side, wall).unwrap();
            }
        }
        let mut g = Vector::<D>::zeros();
        g[1] = -9.81;
        sim.set_gravity(g).unwrap();
        if case.body_force {
            // A field that varies with time, the reference and the current position.
            sim.set_body_force(Some(Box::new(
                |t: f64, x0: &[Vector<D>], x: &[Vector<D>], out: &mut [Vector<D>]| {
                    for ((a, x0), x) in out.iter_mut().zip(x0).zip(x) {
                        *a = Vector::<D>::from_fn(|i, _| {
                            (3.0 * x0[i] + t).sin() * 20.0 + 10.0 * x[(i + 1) % D]
                        });
                    }
                    Ok(())
                },
            )));
        }
        let material = match case.material {
            0 => Material::linear_elastic(1000.0, 1e5, 0.3),
            1 => Material::neo_hookean(1000.0, 1e5, 0.3),
            // A soft Johnson–Cook metal that yields, heats and accumulates damage here (far from
            // failure, whose stress drop a round-off could trigger in one step and not the other).
            3 => Material::johnson_cook(crate::material::JohnsonCookParameters {
                density: 1000.0,
                young: 1e5,
                poisson: 0.3,
                a: 50.0,
                b: 100.0,
                n: 0.3,
                c: 0.01,
                reference_strain_rate: 1.0,
                m: 1.0,
                room_temperature: 293.0,
                melt_temperature: 1000.0,
                specific_heat: 0.5,
                taylor_quinney: 0.9,
                damage: Some([0.5, 0.5, -1.5, 0.01, 0.5]),
                eos: None,
            }),
            // 2: Drucker–Prager; 4: with the μ(I) rheology (below).
            _ => Material::drucker_prager(1000.0, 1e5, 0.3, 30.0, 50.0, 0.0),
        };
        let id = sim.add_material(material.unwrap());
        if case.material == 4 {
            let rheology = crate::material::InertialRheology::new(0.26, 0.28, 1e-3).unwrap();
            sim.set_rheology(id, Some(rheology)).unwrap();
        }
        // Under contact the particles beyond the middle of the block along x are a second body.
        let second = match case.contact {
            0 => id,
            1 => sim.add_material(Material::neo_hookean(800.0, 5e4, 0.25).unwrap()),
            _ => sim.add_material(Material::rigid(2000.0, [0.3, -0.2, 0.1]).unwrap()),
        };
        // Two particles per cell over the lower half of the grid, jittered by ±20 % of their
        // spacing, on the low faces' first cells.
        let q = h / 2.0;
        let per_axis = cells;
        let mut rng = UniformRng::new(case.seed);
        let (mut x, mut v, mut body, mut sites) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for k in 0..per_axis.pow(D as u32) {
            body.push(if k % per_axis < per_axis / 2 {
                id
            } else {
                second
            });
            let mut xp = Vector::<D>::zeros();
            let mut rest = k;
            for a in 0..D {
                let i = rest % per_axis;
                rest /= per_axis;
                xp[a] = (i as f64 + 0.5) * q;
            }
            sites.push(xp);
            for a in 0..D {
                xp[a] += 0.4 * q * (rng.uniform() - 0.5);
            }
            x.push(xp);
            v.push(Vector::<D>::from_fn(|_, _| rng.uniform() - 0.5));
        }
        for material in [id, second] {
            let of = |values: &[Vector<D>]| -> Vec<Vector<D>> {
                (0..values.len())
                    .filter(|&p| body[p] == material)
                    .map(|p| values[p])
                    .collect()
            };
            let (x, v) = (of(&x), of(&v));
            let volumes = vec![q.powi(D as i32); x.len()];
            sim.add_particles(material, &x, &volumes, Some(&v)).unwrap();
            if second == id {
                break;
            }
        }
        if case.boundary > 0 && case.contact == 0 {
            // The faces of the lattice the particles were jittered from, and on them a
            // traction that varies from point to point.
            let volumes = vec![q.powi(D as i32); sites.len()];
            let (mut bx, bn) = crate::BoundaryPoints::from_lattice(&sites, &volumes);
            // The faces on the low walls lie at 0 up to the round-off of `V^{1/3}`.
            bx.iter_mut().for_each(|x| x.apply(|c| *c = c.max(0.0)));
            let traction: Vec<Vector<D>> = bx
                .iter()
                .map(|x| Vector::<D>::from_fn(|i, _| 2e3 * (5.0 * x[(i + 1) % D]).cos()))
                .collect();
            let tractions = (case.boundary == 2).then_some(&traction[..]);
            sim.add_boundary_points(&bx, &bn, tractions).unwrap();
        }
        sim
    }

    /// The fast step against the reference step over four steps of one scene: positions,
    /// velocities, `F` and stresses agree to round-off. The sums run in other orders (by blocks
    /// and rows, factored per axis), so they agree to a few ulps of each quantity's scale per
    /// step, which four steps and the stiff material's stresses amplify: the largest difference
    /// over these cases is 7e-13 of the field's largest value (stresses), and the bound is
    /// 1e-11 (with VC1 9e-13, with VC2 1.8e-12: its conjugate gradients stop at 1e-12 of
    /// the right-hand side; with VC3 4.1e-13). With VC2 and VC3 the bound is 3e-10: once VC's
    /// torque is removed per body, RK2 + VC2 beside a wall differs by up to 3.1e-11 in the
    /// cases seen (the removal spreads the round-off of the body's total torque, a sum over
    /// nodes the particles barely reach with large forces, over all its nodes); ten times that,
    /// still ten times below what scaling VC's corrections by `1 + 1e-7` gives. Dropping the friction walls' friction
    /// differs by 3e-3; scaling APIC's `B` by `1 + 1e-7` differs by 1e-10, VC's corrections by
    /// `1 + 1e-7` by 3e-9.
    fn same_steps<const D: usize>(case: &Case) -> std::result::Result<(), TestCaseError> {
        let (mut fast, mut reference) = (scene::<D>(case), scene::<D>(case));
        for _ in 0..4 {
            let dt = fast.stable_dt(0.4).unwrap();
            let (a, b) = (fast.step(dt), reference_step(&mut reference, dt));
            prop_assert_eq!(a.is_ok(), b.is_ok(), "{:?} / {:?}", a, b);
            if a.is_err() {
                return Ok(());
            }
        }
        let bound = if case.vc >= 2 { 3e-10 } else { 1e-11 };
        for field in [
            Field::Position,
            Field::Velocity,
            Field::DeformationGradient,
            Field::Stress,
        ] {
            let (a, b) = (fast.field(field), reference.field(field));
            let scale = a.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(1e-300);
            let worst = a
                .iter()
                .zip(&b)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            prop_assert!(
                worst <= bound * scale,
                "{:?}: differs by {:e} of {:e}",
                field,
                worst,
                scale
            );
        }
        Ok(())
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]
        #[test]
        fn fast_step_matches_the_reference_step_2d(case in cases()) {
            same_steps::<2>(&case)?;
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]
        #[test]
        fn fast_step_matches_the_reference_step_3d(case in cases()) {
            same_steps::<3>(&case)?;
        }
    }

    /// The found surface carried between refreshes ([`Sim::set_vc_surface_refresh`]): with a
    /// refresh every second step over five steps (found at steps 1, 3 and 5, carried into 2 and
    /// 4) and with the default's four (found at 1 and 5), the fast step and the reference agree
    /// on the particles (`same_steps`'s bound) and on the surface, which after step 5 is the one
    /// found at its start carried once. With a refresh at every step the surface after a step
    /// is the one found from the particles before it, bit for bit.
    #[test]
    fn fast_step_matches_the_reference_step_with_a_carried_surface() {
        let case = Case {
            seed: 5,
            shape: 1,
            transfer: 0,
            flip: 0.0,
            musl: false,
            walls: [1, 0, 3, 0, 0, 0],
            material: 0,
            body_force: true,
            vc: 1,
            contact: 0,
            boundary: 0,
            fast_paths: (true, true, true),
            small: false,
        };
        for refresh in [1, 2, 4] {
            let (mut fast, mut reference) = (scene::<2>(&case), scene::<2>(&case));
            for sim in [&mut fast, &mut reference] {
                sim.set_vc_surface_refresh(refresh).unwrap();
            }
            for step in 1..=5 {
                let before = fast.particles.clone();
                let dt = fast.stable_dt(0.4).unwrap();
                fast.step(dt).unwrap();
                reference_step(&mut reference, dt).unwrap();
                let (a, b) = (fast.vc_surface(), reference.vc_surface());
                assert_eq!(a.len(), b.len(), "refresh {refresh}, step {step}");
                assert!(!a.is_empty());
                let scale = a.position.iter().map(|x| x.norm()).fold(0.0, f64::max);
                for (x, y) in a
                    .position
                    .iter()
                    .zip(&b.position)
                    .chain(a.area_normal.iter().zip(&b.area_normal))
                {
                    assert!(
                        (x - y).norm() <= 1e-12 * scale,
                        "refresh {refresh}, step {step}"
                    );
                }
                if refresh == 1 {
                    let found = crate::step::found_surface(&fast.grid, &before, None).unwrap();
                    assert_eq!(fast.vc_surface(), &found, "step {step}");
                }
            }
            let worst = fast
                .field(Field::Stress)
                .iter()
                .zip(reference.field(Field::Stress))
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            let scale = fast
                .field(Field::Stress)
                .iter()
                .fold(0.0f64, |m, x| m.max(x.abs()));
            assert!(
                worst <= 1e-11 * scale,
                "refresh {refresh}: {worst:e} of {scale:e}"
            );
        }
    }

    /// RK of order 3 against the reference step: in 2D with VC of order 3 (not drawn at random:
    /// its dense reference solve has 6 test polynomials a node), over given boundary points with
    /// tractions beside fixed, friction and slip walls and over the surface found between free
    /// ones; in 3D (the 6-cell scene) with material-point integration and with VC of order 1.
    /// Each scene's four steps must all be taken. Measured largest differences, relative to each
    /// field's largest value: 6.8e-14 (2D, VC3, stresses), 0 (3D without VC), 2.7e-14 (3D,
    /// VC1, stresses). The four scenes take 15 s, 12 of them the 3D reference with VC1.
    #[test]
    fn fast_step_matches_the_reference_step_rk3() {
        let case = |shape, vc, boundary, walls, small| Case {
            seed: 7,
            shape,
            transfer: 0,
            flip: 0.3,
            musl: false,
            walls,
            material: 1,
            body_force: true,
            vc,
            contact: 0,
            boundary,
            fast_paths: (true, true, true),
            small,
        };
        let take_four = |case: &Case, d: usize| {
            if d == 2 {
                let mut sim = scene::<2>(case);
                for _ in 0..4 {
                    let dt = sim.stable_dt(0.4).unwrap();
                    sim.step(dt).unwrap();
                }
                same_steps::<2>(case).unwrap();
            } else {
                let mut sim = scene::<3>(case);
                for _ in 0..4 {
                    let dt = sim.stable_dt(0.4).unwrap();
                    sim.step(dt).unwrap();
                }
                same_steps::<3>(case).unwrap();
            }
        };
        take_four(&case(7, 3, 2, [1, 0, 3, 2, 0, 0], false), 2);
        take_four(&case(7, 3, 0, [0; 6], false), 2);
        take_four(&case(7, 0, 0, [1, 0, 3, 0, 2, 0], true), 3);
        take_four(&case(7, 1, 1, [1, 0, 3, 0, 2, 0], true), 3);
    }

    /// 3D VC of order 2 against the reference step, on the 6-cell scene (its dense reference
    /// solve has a few hundred nodes of 4 test polynomials): RK of order 2 with the block's
    /// faces as boundary points on fixed, friction and slip floors, and the quadratic B-spline
    /// with the surface found from the particles between free faces. Each scene's four steps
    /// must all be taken (a step refused by both would pass `same_steps` unchecked). Measured
    /// largest differences, relative to each field's largest value: 1.6e-14 (RK2, stresses)
    /// and 4.3e-13 (quadratic B-spline, stresses), within `same_steps`'s 1e-11.
    #[test]
    fn fast_step_matches_the_reference_step_3d_with_vc2() {
        for (shape, boundary, walls) in [(4, 1, [1, 0, 3, 0, 2, 0]), (1, 0, [0; 6])] {
            let case = Case {
                seed: 11,
                shape,
                transfer: 0,
                flip: 0.0,
                musl: false,
                walls,
                material: 1,
                body_force: false,
                vc: 2,
                contact: 0,
                boundary,
                fast_paths: (true, true, true),
                small: true,
            };
            let mut sim = scene::<3>(&case);
            for _ in 0..4 {
                let dt = sim.stable_dt(0.4).unwrap();
                sim.step(dt).unwrap();
            }
            same_steps::<3>(&case).unwrap();
        }
    }
}
