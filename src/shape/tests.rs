//! The checks of METHOD.md section 2 for every grid shape function, in 2D and 3D, at random points
//! and on and next to every face of the grid.

use super::*;
use crate::{Matrix, Vector};

/// A small deterministic generator for test points (xorshift64*).
pub(crate) struct TestRng(u64);
impl TestRng {
    pub(crate) fn new(seed: u64) -> Self {
        TestRng(seed.wrapping_mul(0x9E3779B97F4A7C15) | 1)
    }
    /// Uniform in [0, 1).
    pub(crate) fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545F4914F6CDD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
}

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

fn check_consistency<const D: usize>(shape: Shape, check_fd: bool) {
    let f = shape.build::<D>().unwrap();
    let grid = grid_for(f.as_ref());
    let mut rng = TestRng::new(7);
    let n = f.stencil_len();
    let (mut nodes, mut w, mut g) = (vec![0; n], vec![0.0; n], vec![Vector::<D>::zeros(); n]);
    for x in sample_points(&grid, &mut rng) {
        f.evaluate(&grid, &x, &mut nodes, &mut w, &mut g);
        let mut sum = 0.0;
        let mut first = Vector::<D>::zeros();
        let mut grad_sum = Vector::<D>::zeros();
        let mut grad_first = Matrix::<D>::zeros();
        for s in 0..n {
            let xi = grid.node_position(grid.node_multi_index(nodes[s]));
            sum += w[s];
            first += w[s] * xi;
            grad_sum += g[s];
            grad_first += xi * g[s].transpose();
            assert!(w[s] >= 0.0, "{shape:?}: negative value");
        }
        // Round-off: a few ulps of O(1) sums over at most 64 terms.
        assert!((sum - 1.0).abs() < 1e-13, "{shape:?} at {x}: ΣΨ = {sum}");
        assert!(
            (first - x).norm() < 1e-13,
            "{shape:?} at {x}: ΣΨx_I − x = {}",
            first - x
        );
        assert!(
            grad_sum.norm() < 1e-12,
            "{shape:?} at {x}: Σ∇Ψ = {grad_sum}"
        );
        assert!(
            (grad_first - Matrix::<D>::identity()).norm() < 1e-12,
            "{shape:?} at {x}: Σ x_I ⊗ ∇Ψ = {grad_first}"
        );
        if check_fd {
            // Central differences, step 1e-6 h: truncation O(1e-12) and round-off O(1e-10)/h.
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
                    let value_at = |nn: &[usize], ww: &[f64]| {
                        nn.iter()
                            .zip(ww)
                            .find(|(&k, _)| k == nodes[s])
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
    check_consistency::<2>(Shape::Linear, false);
    check_consistency::<3>(Shape::Linear, false);
}

#[test]
fn quadratic_bspline_partition_reproduce_and_gradients_2d_3d() {
    check_consistency::<2>(Shape::BSpline2, true);
    check_consistency::<3>(Shape::BSpline2, true);
}

#[test]
fn cubic_bspline_partition_reproduce_and_gradients_2d_3d() {
    check_consistency::<2>(Shape::BSpline3, true);
    check_consistency::<3>(Shape::BSpline3, true);
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

#[test]
fn rk_is_refused_until_it_lands() {
    let e = Shape::Rk {
        order: 1,
        support: 2.0,
    }
    .build::<2>()
    .err()
    .unwrap();
    assert_eq!(e.kind, crate::ErrorKind::Unsupported);
}
