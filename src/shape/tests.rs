//! The checks of METHOD.md section 2 for every grid shape function, in 2D and 3D, at random points
//! and on and next to every face of the grid.

use super::*;
use crate::{Matrix, Vector};

pub(crate) use super::UniformRng as TestRng;

fn grid_for<const D: usize>(shape: &dyn ShapeFunction<D>) -> Grid<D> {
    let mut g = Grid::<D>::new(Vector::<D>::from_element(-0.3), [5; D], 0.25).unwrap();
    g.set_ghost_layers(shape.ghost_layers()).unwrap();
    g
}

/// Points: random interior ones, and points on and just inside each face.
fn sample_points<const D: usize>(grid: &Grid<D>, rng: &mut TestRng) -> Vec<Vector<D>> {
    let lo = grid.origin;
    let hi = grid.upper();
    let mut pts = Vec::new();
    for _ in 0..200 {
        pts.push(Vector::<D>::from_fn(|a, _| {
            lo[a] + rng.uniform() * (hi[a] - lo[a])
        }));
    }
    for a in 0..D {
        for &t in &[0.0, 1e-9, 0.1, 0.5, 0.999, 1.0] {
            let mut p = Vector::<D>::from_fn(|b, _| lo[b] + rng.uniform() * (hi[b] - lo[b]));
            p[a] = lo[a] + t * grid.cell_size;
            pts.push(p);
            p[a] = hi[a] - t * grid.cell_size;
            pts.push(p);
        }
    }
    pts
}

/// `x^e` and its gradient.
fn monomial<const D: usize>(x: &Vector<D>, e: &[u32; D]) -> (f64, Vector<D>) {
    let value = (0..D).map(|a| x[a].powi(e[a] as i32)).product();
    let grad = Vector::<D>::from_fn(|k, _| {
        if e[k] == 0 {
            return 0.0;
        }
        (0..D)
            .map(|a| {
                if a == k {
                    e[a] as f64 * x[a].powi(e[a] as i32 - 1)
                } else {
                    x[a].powi(e[a] as i32)
                }
            })
            .product()
    });
    (value, grad)
}

/// All exponents of degree ≤ n in D variables.
fn exponents<const D: usize>(n: u32) -> Vec<[u32; D]> {
    (0..(n + 1).pow(D as u32))
        .map(|k| {
            let mut e = [0u32; D];
            let mut r = k;
            for ea in e.iter_mut() {
                *ea = r % (n + 1);
                r /= n + 1;
            }
            e
        })
        .filter(|e| e.iter().sum::<u32>() <= n)
        .collect()
}

/// Partition of unity, reproduction of every monomial of degree ≤ the shape's order and of its
/// gradient (so `Σ∇Ψ = 0` and `Σ x_I ⊗ ∇Ψ_I = I` among them), non-negativity for B-splines, and
/// gradients against central differences. `tol` is the round-off allowed for O(1) sums.
fn check_consistency<const D: usize>(shape: Shape, check_fd: bool, tol: f64) {
    let f = shape.build::<D>().unwrap();
    let grid = grid_for(f.as_ref());
    let mut rng = TestRng::new(7);
    let n = f.stencil_len();
    let order = f.reproduction_order();
    let (mut nodes, mut w, mut g) = (vec![0; n], vec![0.0; n], vec![Vector::<D>::zeros(); n]);
    for x in sample_points(&grid, &mut rng) {
        f.evaluate(&grid, &x, &mut nodes, &mut w, &mut g);
        for e in exponents::<D>(order) {
            let mut sum = 0.0;
            let mut grad = Vector::<D>::zeros();
            for s in 0..n {
                let xi = grid.node_position(grid.node_multi_index(nodes[s]));
                let (m, _) = monomial(&xi, &e);
                sum += w[s] * m;
                grad += g[s] * m;
            }
            let (exact, exact_grad) = monomial(&x, &e);
            assert!(
                (sum - exact).abs() < tol,
                "{shape:?} at {x}: Σ Ψ x^{e:?} = {sum}, exact {exact}"
            );
            // Gradients carry a factor 1/h = 4.
            assert!(
                (grad - exact_grad).norm() < 4.0 * tol,
                "{shape:?} at {x}: Σ ∇Ψ x^{e:?} = {grad}, exact {exact_grad}"
            );
        }
        if matches!(shape, Shape::Linear | Shape::BSpline2 | Shape::BSpline3) {
            assert!(w.iter().all(|&v| v >= 0.0), "{shape:?}: negative value");
        }
        if check_fd {
            // Central differences, step 1e-6 h: truncation O(1e-12), round-off O(1e-10)/h.
            let eps = 1e-6 * grid.cell_size;
            let (mut np, mut wp, mut gp) =
                (vec![0; n], vec![0.0; n], vec![Vector::<D>::zeros(); n]);
            let (mut nm, mut wm, mut gm) =
                (vec![0; n], vec![0.0; n], vec![Vector::<D>::zeros(); n]);
            for a in 0..D {
                let mut e = Vector::<D>::zeros();
                e[a] = eps;
                f.evaluate(&grid, &(x + e), &mut np, &mut wp, &mut gp);
                f.evaluate(&grid, &(x - e), &mut nm, &mut wm, &mut gm);
                for s in 0..n {
                    if w[s] == 0.0 && g[s] == Vector::<D>::zeros() {
                        continue;
                    }
                    let value_at = |nn: &[usize], ww: &[f64]| {
                        nn.iter()
                            .zip(ww)
                            .find(|(&k, &v)| k == nodes[s] && v != 0.0)
                            .map_or(0.0, |(_, &v)| v)
                    };
                    let fd = (value_at(&np, &wp) - value_at(&nm, &wm)) / (2.0 * eps);
                    assert!(
                        (fd - g[s][a]).abs() < 1e-6 / grid.cell_size,
                        "{shape:?} at {x}: d/dx{a} FD {fd} vs {}",
                        g[s][a]
                    );
                }
            }
        }
    }
}

#[test]
fn linear_hats_partition_reproduce_and_gradients_2d_3d() {
    // Linear hats have kinks at nodes: finite differences only where they are smooth, which the
    // random points almost surely are, but the face points sit on nodes; skip FD for them.
    check_consistency::<2>(Shape::Linear, false, 1e-13);
    check_consistency::<3>(Shape::Linear, false, 1e-13);
}

#[test]
fn quadratic_bspline_partition_reproduce_and_gradients_2d_3d() {
    check_consistency::<2>(Shape::BSpline2, true, 1e-13);
    check_consistency::<3>(Shape::BSpline2, true, 1e-13);
}

#[test]
fn cubic_bspline_partition_reproduce_and_gradients_2d_3d() {
    check_consistency::<2>(Shape::BSpline3, true, 1e-13);
    check_consistency::<3>(Shape::BSpline3, true, 1e-13);
}

#[test]
fn bspline_apic_inertia_matches_its_definition() {
    for shape in [Shape::BSpline2, Shape::BSpline3] {
        let f = shape.build::<2>().unwrap();
        let grid = grid_for(f.as_ref());
        let d = f.apic_inertia(grid.cell_size).unwrap();
        let n = f.stencil_len();
        let (mut nodes, mut w, mut g) = (vec![0; n], vec![0.0; n], vec![Vector::<2>::zeros(); n]);
        let mut rng = TestRng::new(3);
        for x in sample_points(&grid, &mut rng) {
            f.evaluate(&grid, &x, &mut nodes, &mut w, &mut g);
            let mut m = Matrix::<2>::zeros();
            for s in 0..n {
                let r = grid.node_position(grid.node_multi_index(nodes[s])) - x;
                m += w[s] * r * r.transpose();
            }
            assert!(
                (m - d * Matrix::<2>::identity()).norm() < 1e-14,
                "{shape:?}: {m}"
            );
        }
    }
}

/// RK of orders 1 to 3 in 2D and 3D reproduce every monomial of their order, with exact
/// gradients, anywhere in the grid and on its faces. The moment matrix is solved with condition
/// numbers up to ~1e5 here, so round-off is allowed to 1e-10.
#[test]
fn rk_reproduces_its_order_2d() {
    for (order, support) in [(1, 1.6), (1, 2.0), (2, 2.5), (2, 3.0), (3, 3.5)] {
        check_consistency::<2>(Shape::Rk { order, support }, true, 1e-10);
    }
}

#[test]
fn rk_reproduces_its_order_3d() {
    for (order, support) in [(1, 2.0), (2, 3.0), (3, 3.5)] {
        check_consistency::<3>(Shape::Rk { order, support }, false, 1e-10);
    }
    check_consistency::<3>(
        Shape::Rk {
            order: 2,
            support: 2.5,
        },
        true,
        1e-10,
    );
}

/// METHOD.md section 2: with n = 1 and ã = 2 on a full grid, RK (computed as RK, with its
/// moment matrix) is the cubic B-spline, which is why `Shape::Rk { order: 1, support: 2.0 }`
/// builds the B-spline ([`super::LatticeRk1`]).
#[test]
fn rk_order_one_support_two_is_the_cubic_bspline() {
    let rk: Box<dyn ShapeFunction<2>> =
        Box::new(super::ReproducingKernel::<2>::new(1, 2.0).unwrap());
    let bs = Shape::BSpline3.build::<2>().unwrap();
    let mut grid = grid_for(rk.as_ref());
    grid.set_ghost_layers(rk.ghost_layers().max(bs.ghost_layers()))
        .unwrap();
    let mut rng = TestRng::new(11);
    let (nr, nb) = (rk.stencil_len(), bs.stencil_len());
    for x in sample_points(&grid, &mut rng) {
        let (mut n1, mut w1, mut g1) = (vec![0; nr], vec![0.0; nr], vec![Vector::<2>::zeros(); nr]);
        let (mut n2, mut w2, mut g2) = (vec![0; nb], vec![0.0; nb], vec![Vector::<2>::zeros(); nb]);
        rk.evaluate(&grid, &x, &mut n1, &mut w1, &mut g1);
        bs.evaluate(&grid, &x, &mut n2, &mut w2, &mut g2);
        for s in 0..nb {
            let k = n1
                .iter()
                .zip(&w1)
                .position(|(&n, &w)| n == n2[s] && w != 0.0);
            match k {
                Some(k) => {
                    assert!(
                        (w1[k] - w2[s]).abs() < 1e-13,
                        "at {x}: {} vs {}",
                        w1[k],
                        w2[s]
                    );
                    assert!(
                        (g1[k] - g2[s]).norm() < 1e-12,
                        "at {x}: {} vs {}",
                        g1[k],
                        g2[s]
                    );
                }
                None => assert!(w2[s].abs() < 1e-15 && g2[s].norm() < 1e-13),
            }
        }
    }
}

/// A support too small for the order makes the moment matrix singular: refused with a message.
#[test]
fn rk_refuses_singular_supports() {
    // Measured worst condition numbers over a cell: order 1: ∞ at ã = 1, 51 at 1.25, 12 at 2;
    // order 2: ∞ at 1.25, 2.5e3 at 1.5, 1.5e2 at 3; order 3: ∞ at 2, 1.1e3 at 2.5.
    for (order, support) in [(1, 1.0), (2, 1.25), (3, 2.0)] {
        let e = Shape::Rk { order, support }
            .build::<2>()
            .err()
            .expect("accepted a singular support");
        assert_eq!(e.kind, crate::ErrorKind::InvalidArgument);
        assert!(e.message.contains("condition number"), "{}", e.message);
    }
    for (order, support) in [(0, 2.0), (6, 4.0), (1, f64::NAN), (1, 0.2), (1, 100.0)] {
        assert!(Shape::Rk { order, support }.build::<3>().is_err());
    }
}

/// What a stencil visit calls: slot, node, `x_I − x_p`.
type Visitor<'a, const D: usize> = dyn FnMut(usize, StencilNode<D>, Vector<D>) + 'a;

/// Every stencil node with a nonzero value or gradient lies in the box of
/// `ShapeFunction::stencil_origin` and `stencil_width` (the coloured particle-to-grid map writes
/// only there), and the 1D factors of B-splines (and of RK1 with ã = 2) give the stored values
/// bit for bit, read as factors or filled into the lists (`Stencils::fill_from_factors`), the
/// nodes in support and the nonzero values too (`TensorFactors::for_each_in_support`,
/// `for_each_value`).
fn check_stencil_box<const D: usize>(shape: Shape) {
    let f = shape.build::<D>().unwrap();
    let grid = grid_for::<D>(f.as_ref());
    let mut rng = TestRng::new(17);
    let len = f.stencil_len();
    let (mut n, mut w, mut g) = (
        vec![0; len],
        vec![0.0; len],
        vec![Vector::<D>::zeros(); len],
    );
    let pts = sample_points(&grid, &mut rng);
    for x in &pts {
        f.evaluate(&grid, x, &mut n, &mut w, &mut g);
        let origin = f.stencil_origin(&grid.to_cell_units(x));
        for s in 0..len {
            if w[s] == 0.0 && g[s] == Vector::<D>::zeros() {
                continue;
            }
            let i = grid.node_multi_index(n[s]);
            for a in 0..D {
                let k = i[a] - origin[a];
                assert!(
                    (0..f.stencil_width() as i64).contains(&k),
                    "{shape:?}: node {i:?} outside the stencil box at {origin:?} (x = {x:?})"
                );
            }
        }
    }
    // Every shape that is a B-spline on the lattice (RK1 with ã = 2 too).
    let Some(order) = f.tensor_order() else {
        return;
    };
    let mut stored = Stencils::<D>::default();
    stored.compute(f.as_ref(), &grid, &pts);
    let check = |view: &dyn Fn(usize, &mut Visitor<D>)| {
        for (p, xp) in pts.iter().enumerate() {
            let (ns, ws, gs) = stored.of(p);
            let mut count = 0;
            view(p, &mut |s, node, offset| {
                assert_eq!(
                    (node.node, node.value, node.gradient),
                    (ns[s], ws[s], gs[s])
                );
                assert_eq!(offset, stored.offset(&grid, p, s, ns[s], xp));
                count += 1;
            });
            assert_eq!(count, len);
        }
    };
    macro_rules! tensor {
        ($w:literal) => {{
            let mut t = TensorStencils::<D, $w>::default();
            t.compute(&BSpline::new(order), &grid, &pts);
            // The lists filled from the factors are the evaluated ones, bit for bit.
            let mut filled = Stencils::<D>::default();
            filled.fill_from_factors(&t);
            let bits = |s: &Stencils<D>| {
                let g: Vec<u64> = s
                    .gradients
                    .iter()
                    .flat_map(|g| g.map(f64::to_bits).iter().copied().collect::<Vec<_>>())
                    .collect();
                (
                    s.len,
                    s.nodes.clone(),
                    s.values.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                    g,
                )
            };
            assert_eq!(bits(&filled), bits(&stored), "{shape:?}");
            let t = t.local();
            // The nodes in support as VC's passes read them from the factors
            // (`TensorFactors::for_each_in_support`): the stored ones in slot order, bit for
            // bit, without the nodes that leave the support (on nodes and cell centres).
            let factors = t.tensor_factors().unwrap();
            let key = |n: usize, w: f64, g: Vector<D>| (n, w.to_bits(), g.map(f64::to_bits));
            for p in 0..pts.len() {
                let (ns, ws, gs) = stored.of(p);
                let listed: Vec<_> = (0..len)
                    .filter(|&s| in_support(ws[s], &gs[s]))
                    .map(|s| key(ns[s], ws[s], gs[s]))
                    .collect();
                let mut factored = Vec::new();
                factors.for_each_in_support(p, |s| factored.push(key(s.node, s.value, s.gradient)));
                assert_eq!(factored, listed, "{shape:?}");
                // The nonzero values alone (`TensorFactors::for_each_value`).
                let nonzero: Vec<_> = (0..len)
                    .filter(|&s| ws[s] != 0.0)
                    .map(|s| (ns[s], ws[s].to_bits()))
                    .collect();
                let mut values = Vec::new();
                factors.for_each_value(p, |n, w| values.push((n, w.to_bits())));
                assert_eq!(values, nonzero, "{shape:?}");
            }
            check(&|p, f| {
                t.for_each(p, |s, node| {
                    f(s, node, t.offset(&grid, p, s, node.node, &pts[p]))
                })
            });
        }};
    }
    match order {
        BSplineOrder::Linear => tensor!(2),
        BSplineOrder::Quadratic => tensor!(3),
        BSplineOrder::Cubic => tensor!(4),
    }
}

#[test]
fn stencils_lie_in_their_box_and_factors_give_the_stored_bits() {
    let rk1 = Shape::Rk {
        order: 1,
        support: 2.0,
    };
    let rk2 = Shape::Rk {
        order: 2,
        support: 3.0,
    };
    for shape in [Shape::Linear, Shape::BSpline2, Shape::BSpline3, rk1, rk2] {
        check_stencil_box::<2>(shape);
        check_stencil_box::<3>(shape);
    }
}

/// Four positions as vector lanes (`BSpline::factors_4`) give the bits of one at a time
/// (`BSpline::factors_into`): first node, values and derivatives, for every order in 2D and 3D,
/// at random points, on nodes and cell centres, on and next to the faces (including the negative
/// coordinates of the grid's origin) and up to 2^30 cells away; a coordinate that is not finite
/// or 2^30 cells or more out is refused with nothing written.
#[test]
fn bspline_factors_as_lanes_give_the_bits_of_one_at_a_time() {
    fn check<const D: usize, const W: usize>(order: BSplineOrder) {
        let lanes = crate::cpu::Lanes::detect();
        if !lanes.avx2() {
            eprintln!("no AVX2 here: the lanes are not taken");
            return;
        }
        let shape = BSpline::new(order);
        let grid = grid_for::<D>(&shape);
        let mut rng = TestRng::new(11);
        let mut points = sample_points(&grid, &mut rng);
        // Far from the origin on both sides, inside the lanes' 2^30 cells (the first nodes
        // convert through 32-bit integers, negative ones included).
        for cells in [-1073741000.3, -536870912.7, 536870911.6, 1073741000.2] {
            for _ in 0..4 {
                points.push(Vector::<D>::from_fn(|a, _| {
                    grid.origin[a] + (cells + a as f64 * 0.25) * grid.cell_size
                }));
            }
        }
        // Nodes, cell centres and the points a rounding away from them.
        for k in 0..8 {
            let t = 0.5 * k as f64;
            for e in [0.0, 1e-12, -1e-12] {
                points.push(Vector::<D>::from_fn(|a, _| {
                    grid.origin[a] + (t + e + a as f64 * 0.5) * grid.cell_size
                }));
            }
        }
        for x in points.chunks_exact(4) {
            let mut first = [[0i32; D]; 4];
            let mut values = [[[0.0; W]; D]; 4];
            let mut derivatives = [[[0.0; W]; D]; 4];
            // SAFETY: the processor has AVX2.
            let taken = unsafe {
                lanes.wide(|| {
                    shape.factors_4(&grid, x, &mut first, &mut values, Some(&mut derivatives))
                })
            };
            assert!(taken);
            for (q, xq) in x.iter().enumerate() {
                let (mut f, mut w, mut dw) = ([0i64; D], [[0.0; W]; D], [[0.0; W]; D]);
                shape.factors_into(&grid, xq, &mut f, &mut w, Some(&mut dw));
                assert_eq!(first[q].map(i64::from), f, "{order:?} first node at {xq:?}");
                let bits = |v: &[[f64; W]; D]| v.map(|r| r.map(f64::to_bits));
                assert_eq!(bits(&values[q]), bits(&w), "{order:?} values at {xq:?}");
                assert_eq!(
                    bits(&derivatives[q]),
                    bits(&dw),
                    "{order:?} derivatives at {xq:?}"
                );
            }
        }
        // Not finite, or 2^30 cells or more from the origin: left to the scalar code.
        let far = (1u64 << 30) as f64 * grid.cell_size;
        for bad in [f64::NAN, f64::INFINITY, 1e300, grid.origin[D - 1] - far] {
            let mut x = [Vector::<D>::from_element(0.1); 4];
            x[2][D - 1] = bad;
            let mut first = [[7i32; D]; 4];
            let mut values = [[[7.0; W]; D]; 4];
            // SAFETY: as above.
            let taken =
                unsafe { lanes.wide(|| shape.factors_4(&grid, &x, &mut first, &mut values, None)) };
            assert!(!taken, "{order:?} took {bad}");
            assert_eq!((first, values), ([[7i32; D]; 4], [[[7.0; W]; D]; 4]));
        }
    }
    check::<2, 2>(BSplineOrder::Linear);
    check::<2, 3>(BSplineOrder::Quadratic);
    check::<2, 4>(BSplineOrder::Cubic);
    check::<3, 2>(BSplineOrder::Linear);
    check::<3, 3>(BSplineOrder::Quadratic);
    check::<3, 4>(BSplineOrder::Cubic);
}
