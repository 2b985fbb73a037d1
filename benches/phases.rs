//! Per-phase micro-benchmarks of the explicit step (criterion), so that a slowdown shows which
//! phase moved: shape functions (B-spline factors, RK moment solves), binning, particle to grid,
//! grid update, grid to particle and the VC correction, in 2D and 3D, on the throughput
//! benchmark's block (`studies/examples/throughput.rs`) after one step.
//!
//! ```text
//! cargo bench --features internals --bench phases          # all (about 2 minutes)
//! cargo bench --features internals --bench phases -- p2g   # a subset (names contain the phase)
//! ```
//!
//! One thread unless `RAYON_NUM_THREADS` says otherwise. Each figure is the time of the phase
//! for all particles of the block; divide by the particle count for ns per particle.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use rkmpm::grid::{Grid, GridNodes};
use rkmpm::integration::{BoundaryPoints, VcCorrection, VcInputs};
use rkmpm::shape::{BSpline, BSplineOrder, ShapeFunction, StencilView, Stencils, TensorStencils};
use rkmpm::step::{grid_to_particle, grid_update, particle_to_grid, Bins, Fields, Forces};
use rkmpm::step::{FromGrid, NewState, NoFinish, ToGrid, TransferPlan};
use rkmpm::walls::Walls;
use rkmpm::{Material, Particles, Shape, Sim, Vector};
use std::time::Duration;

/// The throughput block with `m^D` particles (2 per cell per direction), stepped once.
fn block<const D: usize>(m: usize, shape: Shape) -> Sim<D> {
    let (b, g) = (m / 2, 4 + m / 16);
    let n = b + 2 * g;
    let h = 1.0 / n as f64;
    let mut sim = Sim::<D>::new(Vector::<D>::zeros(), [n; D], h).unwrap();
    sim.set_shape(shape).unwrap();
    let mat = sim.add_material(Material::neo_hookean(1000.0, 1e5, 0.3).unwrap());
    let total = m.pow(D as u32);
    let (mut x, mut v) = (Vec::with_capacity(total), Vec::with_capacity(total));
    let half = b as f64 * h / 2.0;
    for lin in 0..total {
        let mut p = Vector::<D>::zeros();
        let mut r = lin;
        for a in 0..D {
            p[a] = (g as f64 + ((r % m) as f64 + 0.5) / 2.0) * h;
            r /= m;
        }
        let xi = p.map(|c| (c - 0.5) / half);
        x.push(p);
        v.push(Vector::<D>::from_fn(|a, _| {
            0.1 * ((std::f64::consts::PI * xi[(a + 1) % D]).sin() - 0.5 * xi[a])
        }));
    }
    sim.add_particles(mat, &x, &vec![(h / 2.0).powi(D as i32); total], Some(&v))
        .unwrap();
    let dt = sim.stable_dt(0.3).unwrap();
    sim.step(dt).unwrap();
    sim
}

/// Resets the nodes, then maps the particles to the grid with `stencils` (as a step does).
fn p2g<const D: usize, S: StencilView<D>>(
    grid: &Grid<D>,
    ps: &Particles<D>,
    bins: &Bins<D>,
    stencils: &S,
    forces: Forces<D>,
    nodes: &mut GridNodes<D>,
) {
    nodes.reset();
    let to = ToGrid {
        grid,
        particles: ps,
        bins,
        stencils,
        shape: None,
    };
    particle_to_grid(
        &to,
        |p| ps.velocity()[p],
        Some(|p: usize| ps.affine()[p]),
        Some(forces),
        None,
        nodes,
    );
}

fn phases<const D: usize>(c: &mut Criterion, m: usize) {
    let dim = format!("{D}d");
    let rk1 = Shape::Rk {
        order: 1,
        support: 2.0,
    };
    let rk2 = Shape::Rk {
        order: 2,
        support: 3.0,
    };
    let sim = block::<D>(m, Shape::BSpline2);
    let (grid, ps) = (sim.grid().clone(), sim.particles());
    let dt = sim.stable_dt(0.3).unwrap();
    let mut g = c.benchmark_group(format!("{dim} ({} particles)", ps.len()));
    g.sample_size(10)
        .measurement_time(Duration::from_secs(2))
        .warm_up_time(Duration::from_millis(500));

    // Shape functions.
    let quadratic = BSpline::new(BSplineOrder::Quadratic);
    let mut factors = TensorStencils::<D, 3>::default();
    // Computed once here too, so that a filtered run (`... --bench phases -- g2p`) that skips
    // the shape and bins benchmarks still maps real stencils.
    factors.compute(&quadratic, &grid, ps.position());
    g.bench_function(BenchmarkId::new("shape", "bspline2 factors"), |b| {
        b.iter(|| factors.compute(&quadratic, &grid, ps.position()))
    });
    for (name, shape) in [("rk1", rk1), ("rk2", rk2)] {
        let f: Box<dyn ShapeFunction<D>> = shape.build().unwrap();
        let mut grid = grid.clone();
        grid.set_ghost_layers(f.ghost_layers()).unwrap();
        let mut stored = Stencils::<D>::default();
        g.bench_function(
            BenchmarkId::new("shape", format!("{name} moment solves")),
            |b| b.iter(|| stored.compute(f.as_ref(), &grid, ps.position())),
        );
    }

    // Binning, then the transfers with the quadratic B-spline.
    let mut bins = Bins::<D>::default();
    rkmpm::shape::bin_particles(&mut bins, &quadratic, &grid, ps.position());
    g.bench_function("bins", |b| {
        b.iter(|| rkmpm::shape::bin_particles(&mut bins, &quadratic, &grid, ps.position()))
    });
    let mut nodes = GridNodes::<D>::default();
    nodes.ensure(&grid, false, false, false).unwrap();
    let forces = Forces {
        gravity: Vector::zeros(),
        body: None,
        vc: None,
        mls: None,
    };
    g.bench_function(BenchmarkId::new("p2g", "bspline2 apic"), |b| {
        b.iter(|| p2g(&grid, &ps, &bins, &factors.local(), forces, &mut nodes))
    });
    // MLS: the force on the affine momentum, mass and momentum only.
    let inverse_inertia = 4.0 / (grid.cell_size() * grid.cell_size());
    let mls_forces = Forces {
        mls: Some((dt, inverse_inertia)),
        ..forces
    };
    g.bench_function(BenchmarkId::new("p2g", "bspline2 mls"), |b| {
        b.iter(|| p2g(&grid, &ps, &bins, &factors.local(), mls_forces, &mut nodes))
    });
    let walls = Walls::<D>::default();
    g.bench_function("grid_update", |b| {
        b.iter(|| grid_update(&grid, &walls, &mut nodes, Some(dt), 0.0, false))
    });
    // The node velocities the gathers read (also when the benchmarks above are filtered out).
    p2g(&grid, &ps, &bins, &factors.local(), forces, &mut nodes);
    grid_update(&grid, &walls, &mut nodes, Some(dt), 0.0, false);
    let (mut new, mut admissible) = (NewState::<D>::default(), Vec::new());
    for (name, mls) in [("bspline2 apic", false), ("bspline2 mls", true)] {
        let plan = TransferPlan {
            flip: 0.0,
            apic: true,
            inverse_inertia: Some(inverse_inertia),
            mls,
        };
        g.bench_function(BenchmarkId::new("g2p", name), |b| {
            b.iter(|| {
                let from = FromGrid {
                    grid: &grid,
                    particles: &ps,
                    stencils: &factors.local(),
                    fields: Fields::One(&nodes),
                    rigid: &[None],
                    plan,
                    dt,
                };
                grid_to_particle(&from, None::<&NoFinish>, None, &mut new, &mut admissible)
            })
        });
    }

    // VC correction (order 1) with the quadratic B-spline, stencils stored node by node.
    let mut stored = Stencils::<D>::default();
    stored.compute(&quadratic, &grid, ps.position());
    let volumes: Vec<f64> = (0..ps.len()).map(|p| ps.volume(p)).collect();
    let (bx, bn) = BoundaryPoints::from_lattice(ps.position(), ps.reference_volume());
    let mut boundary = BoundaryPoints::<D>::default();
    boundary.add(&bx, &bn, None).unwrap();
    let mut boundary_stencils = Stencils::<D>::default();
    boundary_stencils.compute(&quadratic, &grid, &boundary.position);
    let mut vc = VcCorrection::<D>::new(1).unwrap();
    g.bench_function(BenchmarkId::new("vc", "bspline2 order 1"), |b| {
        b.iter(|| {
            nodes.reset();
            let inputs = VcInputs {
                grid: &grid,
                bins: &bins,
                positions: ps.position(),
                volumes: &volumes,
                stencils: &stored,
                tensor: None,
                boundary: &boundary,
                boundary_stencils: &boundary_stencils,
                body: None,
            };
            vc.compute(inputs, &mut nodes)
        })
    });
    // Particle to grid with stored stencils, for the ratio against the factors.
    g.bench_function(BenchmarkId::new("p2g", "bspline2 apic stored"), |b| {
        b.iter(|| p2g(&grid, &ps, &bins, &stored, forces, &mut nodes))
    });
    g.finish();
}

fn all(c: &mut Criterion) {
    phases::<2>(c, 256);
    phases::<3>(c, 32);
}

criterion_group!(benches, all);
criterion_main!(benches);
