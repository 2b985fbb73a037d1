//! Tests of the step: conservation in the transfers, the vibrating bar against its exact
//! solution, wall conditions, and the guards that keep the last good state.

use crate::error::ErrorKind;
use crate::material::{History, Material};
use crate::options::{FastPaths, Scheme, Shape, Side, Transfer, Wall};
use crate::particles::{Field, Particles};
use crate::sim::Sim;
use crate::{Matrix, Vector};

/// Young's modulus of the test block.
const YOUNG: f64 = 1e5;

/// A block of `n^D` particles, 2 per cell, with a spin and a shear in its velocity.
fn block<const D: usize>(shape: Shape, transfer: Transfer) -> Sim<D> {
    block_moving::<D>(shape, transfer, true)
}

/// The block of [`block`], moving (spin and shear) or at rest.
fn block_moving<const D: usize>(shape: Shape, transfer: Transfer, moving: bool) -> Sim<D> {
    let rubber = Material::neo_hookean(1000.0, YOUNG, 0.3).unwrap();
    block_of::<D>(shape, transfer, rubber, moving)
}

/// The block of [`block_moving`], of `material`.
fn block_of<const D: usize>(
    shape: Shape,
    transfer: Transfer,
    material: Material,
    moving: bool,
) -> Sim<D> {
    let mut sim = Sim::<D>::new(Vector::<D>::zeros(), [12; D], 0.1).unwrap();
    sim.set_shape(shape).unwrap();
    sim.set_transfer(transfer).unwrap();
    let m = sim.add_material(material);
    let mut x = Vec::new();
    let n = 8usize;
    for k in 0..n.pow(D as u32) {
        let mut p = Vector::<D>::zeros();
        let mut r = k;
        for a in 0..D {
            // Slightly irregular spacing so that no particle sits on a node or a cell centre.
            p[a] = 0.3125 + 0.05 * (r % n) as f64 + 0.003 * ((k * 7 + a * 3) % 5) as f64;
            r /= n;
        }
        x.push(p);
    }
    let v: Vec<Vector<D>> = x
        .iter()
        .map(|p| {
            let c = p - Vector::<D>::from_element(0.5);
            let mut v = Vector::<D>::from_element(0.1);
            v[0] += -0.6 * c[1];
            v[1] += 0.75 * c[0];
            if moving {
                v
            } else {
                Vector::zeros()
            }
        })
        .collect();
    let vol = vec![0.05f64.powi(D as i32); x.len()];
    sim.add_particles(m, &x, &vol, Some(&v)).unwrap();
    sim
}

/// A column of rubber 16 cells tall in a grid 160 cells tall along axis 1 (two cells across the
/// other axes), spinning: 40 rows of blocks, so particle to grid runs by rows
/// (`Bins::tasks`).
fn tall_column<const D: usize>(transfer: Transfer) -> Sim<D> {
    let mut dims = [8; D];
    dims[1] = 160;
    let mut sim = Sim::<D>::new(Vector::<D>::zeros(), dims, 0.1).unwrap();
    sim.set_transfer(transfer).unwrap();
    let m = sim.add_material(Material::neo_hookean(1000.0, YOUNG, 0.3).unwrap());
    let (across, along) = (4usize, 300usize);
    let mut x = Vec::new();
    for k in 0..across.pow(D as u32 - 1) * along {
        let (mut r, mut p) = (k, Vector::<D>::zeros());
        for a in 0..D {
            let n = if a == 1 { along } else { across };
            p[a] = 0.3125 + 0.05 * (r % n) as f64 + 0.003 * ((k * 7 + a * 3) % 5) as f64;
            r /= n;
        }
        x.push(p);
    }
    let centre = 0.4;
    let v: Vec<Vector<D>> = x
        .iter()
        .map(|p| {
            let mut v = Vector::<D>::from_element(0.1);
            v[0] += -0.01 * (p[1] - 7.8);
            v[1] += 0.75 * (p[0] - centre);
            v
        })
        .collect();
    let vol = vec![0.05f64.powi(D as i32); x.len()];
    sim.add_particles(m, &x, &vol, Some(&v)).unwrap();
    sim
}

fn angular_momentum_2d(sim: &Sim<2>) -> f64 {
    let ps = &sim.particles;
    let mut l = 0.0;
    for p in 0..ps.len() {
        let (x, v) = (ps.position[p], ps.velocity[p]);
        l += ps.mass[p] * (x[0] * v[1] - x[1] * v[0]);
        if !ps.affine.is_empty() {
            // APIC carries angular momentum in C_p too: m_p D_p (C_p - C_pᵀ) part; with
            // D_p = d I that is m_p d (C_10 - C_01).
            let d = sim.shape.apic_inertia(sim.grid.cell_size).unwrap_or(0.0);
            let c = ps.affine[p];
            l += ps.mass[p] * d * (c[(1, 0)] - c[(0, 1)]);
        }
    }
    l
}

/// Linear momentum is conserved by a step with free walls and no external force, for every
/// shape function and transfer: internal forces sum to zero because Σ_I ∇Ψ_I = 0, and PIC,
/// FLIP and APIC all return Σ_I m_I v_I to the particles because Σ_I Ψ_I = 1.
#[test]
fn step_conserves_mass_and_linear_momentum() {
    for shape in [Shape::Linear, Shape::BSpline2, Shape::BSpline3] {
        for transfer in [
            Transfer::PicFlip { flip: 0.0 },
            Transfer::PicFlip { flip: 0.95 },
            Transfer::Apic,
        ] {
            for scheme in [Scheme::Usl, Scheme::Musl] {
                let mut sim = block::<2>(shape, transfer);
                sim.set_scheme(scheme).unwrap();
                let p0 = sim.particles.momentum();
                let m0: f64 = sim.particles.mass.iter().sum();
                let dt = sim.stable_dt(0.3).unwrap();
                for _ in 0..10 {
                    sim.step(dt)
                        .unwrap_or_else(|e| panic!("{shape:?} {transfer:?} {scheme:?}: {e}"));
                }
                let p1 = sim.particles.momentum();
                // Sums of ~500 terms of size |p0|: round-off ~1e-14 relative; the 1e-10 mass
                // floor drops no node here (every active node has far more mass).
                assert!(
                    (p1 - p0).norm() < 1e-12 * p0.norm(),
                    "{shape:?} {transfer:?} {scheme:?}: momentum {p0} -> {p1}"
                );
                let m1: f64 = sim.particles.mass.iter().sum();
                assert_eq!(m0, m1);
                // The nodes keep the last step's sums until the next step clears them (while
                // it bins): Σ_I m_I = Σ_p m_p (partition of unity; round-off of ~100 terms).
                let nodes = &sim.work.nodes;
                let node_mass: f64 = nodes.active.iter().map(|&n| nodes.mass[n]).sum();
                assert!((node_mass - m1).abs() < 1e-13 * m1, "{node_mass} {m1}");
                sim.work.clear_grid();
                assert!(sim.work.nodes.is_clear(), "grid not cleared");
                // No APIC matrices unless APIC runs.
                let apic = matches!(transfer, Transfer::Apic);
                assert_eq!(
                    sim.particles.affine.len(),
                    if apic { sim.particles.len() } else { 0 }
                );
            }
        }
    }
}

/// APIC also conserves angular momentum (Jiang et al. 2015); a full step adds the torque of the
/// internal forces, which is zero for a symmetric stress. PIC loses it.
#[test]
fn apic_conserves_angular_momentum_pic_does_not() {
    let mut apic = block::<2>(Shape::BSpline2, Transfer::Apic);
    let mut pic = block::<2>(Shape::BSpline2, Transfer::PicFlip { flip: 0.0 });
    let (l0a, l0p) = (angular_momentum_2d(&apic), angular_momentum_2d(&pic));
    let dt = apic.stable_dt(0.3).unwrap();
    for _ in 0..20 {
        apic.step(dt).unwrap();
        pic.step(dt).unwrap();
    }
    let (l1a, l1p) = (angular_momentum_2d(&apic), angular_momentum_2d(&pic));
    assert!(
        (l1a - l0a).abs() < 1e-10 * l0a.abs(),
        "APIC: {l0a} -> {l1a}"
    );
    assert!(
        (l1p - l0p).abs() > 1e-3 * l0p.abs(),
        "PIC kept angular momentum: {l0p} -> {l1p}"
    );
}

/// MLS (Hu et al. 2018) conserves linear and angular momentum like APIC: its internal force is
/// `−V σ M⁻¹ Ψ_I (x_I − x_p)`, which sums to zero over the nodes (`Σ Ψ_I (x_I − x_p) = 0`) and
/// has zero torque for a symmetric stress; the round trip keeps `m D C` as APIC does.
#[test]
fn mls_conserves_linear_and_angular_momentum() {
    for shape in [Shape::BSpline2, Shape::BSpline3] {
        for scheme in [Scheme::Usl, Scheme::Musl] {
            let mut sim = block::<2>(shape, Transfer::Mls);
            sim.set_scheme(scheme).unwrap();
            let (p0, l0) = (sim.particles.momentum(), angular_momentum_2d(&sim));
            let dt = sim.stable_dt(0.3).unwrap();
            for _ in 0..20 {
                sim.step(dt).unwrap();
            }
            let (p1, l1) = (sim.particles.momentum(), angular_momentum_2d(&sim));
            // The bounds of the APIC tests above: sums of ~500 terms, round-off ~1e-14 relative.
            assert!(
                (p1 - p0).norm() < 1e-12 * p0.norm(),
                "{shape:?} {scheme:?}: momentum {p0} -> {p1}"
            );
            assert!(
                (l1 - l0).abs() < 1e-10 * l0.abs(),
                "{shape:?} {scheme:?}: angular momentum {l0} -> {l1}"
            );
            assert_eq!(sim.particles.affine.len(), sim.particles.len());
        }
    }
}

/// Under MLS the velocity gradient is the affine matrix: for an affine velocity field
/// `v = A x + c` (and no stress yet) one step gives every particle, at the edge of the body too,
/// `v = A x + c`, `C = A` and `F = I + Δt A` to round-off (the nodes' velocities are
/// `A x_I + c` exactly, and `M⁻¹ Σ Ψ_I v_I (x_I − x_p)ᵀ` reproduces a linear field).
#[test]
fn mls_velocity_gradient_is_exact_for_an_affine_field() {
    fn check<const D: usize>(shape: Shape) {
        let mut sim = block::<D>(shape, Transfer::Mls);
        let a = Matrix::<D>::from_fn(|i, j| 0.3 * (i as f64 + 1.0) - 0.2 * j as f64);
        let c = Vector::<D>::from_element(0.05);
        let x = sim.particles.position.clone();
        let ps = &mut sim.particles;
        for ((v, c_p), x) in ps.velocity.iter_mut().zip(&mut ps.affine).zip(&x) {
            *v = a * x + c;
            *c_p = a;
        }
        let dt = 1e-3;
        sim.step(dt).unwrap();
        let ps = &sim.particles;
        let f = Matrix::<D>::identity() + dt * a;
        // Round-off of sums of O(1) terms; a first-order error would be O(h) = 0.1 here.
        let tol = 1e-12;
        for (p, &id) in ps.id.iter().enumerate() {
            // The field at the particle's position at the start of the step (its stencil's);
            // `x` is in id order (no step had sorted the particles).
            let x = &x[id as usize];
            let v = a * x + c;
            assert!((ps.velocity[p] - v).norm() < tol, "{shape:?} v at {p}");
            assert!(
                (ps.position[p] - (x + dt * v)).norm() < tol,
                "{shape:?} x at {p}"
            );
            assert!((ps.affine[p] - a).norm() < tol, "{shape:?} C at {p}");
            assert!(
                (ps.deformation_gradient[p] - f).norm() < tol,
                "{shape:?} F at {p}"
            );
        }
    }
    check::<2>(Shape::BSpline2);
    check::<2>(Shape::BSpline3);
    check::<3>(Shape::BSpline2);
}

/// MLS needs a constant APIC inertia (quadratic or cubic B-spline) and no VC; otherwise the
/// first step is refused and nothing changes.
#[test]
fn mls_is_refused_without_a_quadratic_or_cubic_bspline_or_with_vc() {
    // RK1 with a support other than 2 (with 2 it is the cubic B-spline, which MLS takes).
    let rk1 = Shape::Rk {
        order: 1,
        support: 2.5,
    };
    for (shape, vc) in [
        (Shape::Linear, false),
        (rk1, false),
        (Shape::BSpline2, true),
    ] {
        let mut sim = block::<2>(shape, Transfer::Mls);
        if vc {
            sim.set_integration(crate::sim::Integration::Vc { order: 1 })
                .unwrap();
        }
        let before = sim.particles.clone();
        let e = sim.step(1e-4).unwrap_err();
        assert_eq!(e.kind, ErrorKind::Unsupported, "{shape:?} vc {vc}: {e}");
        assert!(e.message.contains("MLS"), "{e}");
        assert_eq!(sim.particles, before);
        assert_eq!(sim.steps(), 0);
    }
}

/// A block resting on a slip floor under gravity keeps its tangential momentum exactly while it
/// bounces; on a friction floor it decelerates at μ g, as Coulomb's law says.
#[test]
fn slip_and_friction_floors() {
    let run = |floor: Wall| {
        let mut sim = Sim::<2>::new([0.0, 0.0], [40, 10], 0.05).unwrap();
        sim.set_wall(1, Side::Low, floor).unwrap();
        sim.set_gravity([0.0, -10.0]).unwrap();
        let m = sim.add_material(Material::neo_hookean(1000.0, 1e6, 0.3).unwrap());
        let mut x = Vec::new();
        for j in 0..8 {
            for i in 0..16 {
                x.push(Vector::<2>::new(
                    0.2 + 0.025 * (i as f64 + 0.5),
                    0.025 * (j as f64 + 0.5),
                ));
            }
        }
        let v = vec![Vector::<2>::new(1.0, 0.0); x.len()];
        sim.add_particles(m, &x, &vec![0.025 * 0.025; x.len()], Some(&v))
            .unwrap();
        let dt = sim.stable_dt(0.3).unwrap();
        let steps = (0.05 / dt).ceil() as usize;
        for _ in 0..steps {
            sim.step(dt).unwrap();
        }
        let mass: f64 = sim.particles.mass.iter().sum();
        (sim.particles.momentum()[0] / mass, sim.time())
    };
    let (v_slip, _) = run(Wall::Slip);
    assert!(
        (v_slip - 1.0).abs() < 1e-12,
        "slip floor changed tangential velocity: {v_slip}"
    );
    let mu = 0.4;
    let (v_fric, t) = run(Wall::Friction(mu));
    let expected = 1.0 - mu * 10.0 * t;
    eprintln!("friction: v = {v_fric}, Coulomb {expected}");
    assert!(
        (v_fric - expected).abs() < 0.1 * (1.0 - expected),
        "v = {v_fric}, Coulomb {expected}"
    );
}

/// A fixed floor stops a falling block: after it settles, the mean velocity is near zero and no
/// particle went below the floor.
#[test]
fn fixed_floor_holds_a_block() {
    let mut sim = Sim::<2>::new([0.0, 0.0], [10, 10], 0.1).unwrap();
    sim.set_wall(1, Side::Low, Wall::Fixed).unwrap();
    sim.set_gravity([0.0, -10.0]).unwrap();
    let m = sim.add_material(Material::neo_hookean(100.0, 1e5, 0.3).unwrap());
    let mut x = Vec::new();
    for j in 0..8 {
        for i in 0..8 {
            x.push(Vector::<2>::new(
                0.3 + 0.05 * (i as f64 + 0.5),
                0.05 * (j as f64 + 0.5),
            ));
        }
    }
    sim.add_particles(m, &x, &vec![0.0025; x.len()], None)
        .unwrap();
    let dt = sim.stable_dt(0.3).unwrap();
    while sim.time() < 0.5 {
        sim.step(dt).unwrap();
    }
    let ps = &sim.particles;
    assert!(ps.position.iter().all(|x| x[1] >= 0.0));
    // Free fall for 0.5 s would give 5 m/s; resting on the floor gives elastic oscillation
    // of order g·(period) ≈ 10 · 0.01 m/s.
    let mass: f64 = ps.mass.iter().sum();
    let v = ps.momentum() / mass;
    assert!(v.norm() < 0.05, "mean velocity {v}");
}

/// A rejected step changes nothing: the particle data stay bit for bit, time and step count too.
#[test]
fn rejected_steps_keep_the_last_good_state() {
    let mut sim = block::<2>(Shape::BSpline2, Transfer::Apic);
    let dt = sim.stable_dt(0.3).unwrap();
    sim.step(dt).unwrap();
    let before = sim.particles.clone();
    let (t, n) = (sim.time(), sim.steps());

    // dt far above the critical step.
    let e = sim.step(100.0 * dt).unwrap_err();
    assert_eq!(e.kind, ErrorKind::UnstableTimeStep);
    assert_eq!(sim.particles, before);

    // A body force that fails, and one that returns NaN.
    sim.set_body_force(Some(Box::new(
        |_t: f64, _x0: &[Vector<2>], _x: &[Vector<2>], _a: &mut [Vector<2>]| Err("no".to_string()),
    )));
    assert_eq!(sim.step(dt).unwrap_err().kind, ErrorKind::Callback);
    sim.set_body_force(Some(Box::new(
        |_t: f64, _x0: &[Vector<2>], _x: &[Vector<2>], a: &mut [Vector<2>]| {
            a[3] = Vector::<2>::new(f64::NAN, 0.0);
            Ok(())
        },
    )));
    assert_eq!(sim.step(dt).unwrap_err().kind, ErrorKind::Callback);

    // A body force that tears the block apart with huge accelerations: non-finite stress.
    sim.set_body_force(Some(Box::new(
        |_t: f64, _x0: &[Vector<2>], x: &[Vector<2>], a: &mut [Vector<2>]| {
            for (a, x) in a.iter_mut().zip(x) {
                *a = Vector::<2>::new(if x[0] < 0.5 { -1e308 } else { 1e308 }, 0.0);
            }
            Ok(())
        },
    )));
    let e = sim.step(dt).unwrap_err();
    assert_eq!(e.kind, ErrorKind::NonFinite, "{e}");
    assert!(
        e.message.contains("particle") && e.message.contains("step 2"),
        "{e}"
    );

    // A body force that pushes everything out of the grid within one step.
    sim.set_body_force(Some(Box::new(
        |_t: f64, _x0: &[Vector<2>], _x: &[Vector<2>], a: &mut [Vector<2>]| {
            a.iter_mut().for_each(|a| *a = Vector::<2>::new(1e12, 0.0));
            Ok(())
        },
    )));
    assert_eq!(sim.step(dt).unwrap_err().kind, ErrorKind::OutsideGrid);

    assert_eq!(sim.particles, before);
    assert_eq!((sim.time(), sim.steps()), (t, n));
    // And the simulation still steps afterwards, from a cleared grid: as one that never saw
    // the rejected steps.
    sim.set_body_force(None);
    sim.step(dt).unwrap();
    let mut fresh = block::<2>(Shape::BSpline2, Transfer::Apic);
    fresh.step(dt).unwrap();
    fresh.step(dt).unwrap();
    assert_eq!(sim.particles, fresh.particles);
}

/// A rejected step keeps the found surface VC carries between refreshes, and the coefficients
/// it carries between solves, as they were, whether the step would have carried them or found
/// them anew; stepping on goes as a run that never saw it. The steps between solves take no
/// iteration.
#[test]
fn rejected_steps_keep_the_carried_surface_and_coefficients() {
    let vc_block = || {
        let mut sim = block::<2>(Shape::BSpline2, Transfer::Apic);
        sim.set_vc1_every(3);
        sim.set_vc_surface_refresh(2).unwrap();
        sim
    };
    let carried = |sim: &Sim<2>| sim.vc.as_ref().unwrap().carried().clone();
    let mut sim = vc_block();
    let dt = sim.stable_dt(0.3).unwrap();
    let out_of_grid = || -> Box<dyn crate::BodyForce<2>> {
        Box::new(
            |_t: f64, _x0: &[Vector<2>], _x: &[Vector<2>], a: &mut [Vector<2>]| {
                a.iter_mut().for_each(|a| *a = Vector::<2>::new(1e12, 0.0));
                Ok(())
            },
        )
    };
    let mut fresh = vc_block();
    for step in 1..=5 {
        // Step 2 carries the surface of step 1, step 3 finds it anew; steps 1 and 4 solve, the
        // others take the coefficients of the last solve.
        let before = (
            sim.particles.clone(),
            sim.vc_surface().clone(),
            carried(&sim),
        );
        sim.set_body_force(Some(out_of_grid()));
        assert_eq!(sim.step(dt).unwrap_err().kind, ErrorKind::OutsideGrid);
        assert_eq!((&sim.particles, sim.vc_surface()), (&before.0, &before.1));
        assert_eq!(carried(&sim), before.2, "step {step}");
        sim.set_body_force(None);
        sim.step(dt).unwrap();
        fresh.step(dt).unwrap();
        assert_eq!(sim.particles, fresh.particles, "step {step}");
        assert_eq!(sim.vc_surface(), fresh.vc_surface(), "step {step}");
        assert_eq!(carried(&sim), carried(&fresh), "step {step}");
        let solved = step % 3 == 1;
        assert_eq!(
            carried(&sim).age,
            if solved { 0 } else { (step as u32 - 1) % 3 }
        );
        assert_eq!(
            sim.vc.as_ref().unwrap().iterations() > 0,
            solved,
            "step {step}"
        );
    }
}

/// Solving every second step, a solve starts from the carried coefficients and runs to the
/// tolerance: fewer iterations than the first solve, from zero, takes; and none between solves.
#[test]
fn solves_from_carried_coefficients_take_fewer_iterations() {
    let mut sim = block::<2>(Shape::BSpline2, Transfer::Apic);
    sim.set_vc1_every(2);
    let dt = sim.stable_dt(0.3).unwrap();
    let mut iterations = Vec::new();
    for _ in 0..12 {
        sim.step(dt).unwrap();
        iterations.push(sim.vc.as_ref().unwrap().iterations());
    }
    let first = iterations[0];
    for (step, &n) in iterations.iter().enumerate().skip(1) {
        match step % 2 {
            0 => assert!(n >= 1 && n < first, "step {step}: {n} against {first}"),
            _ => assert_eq!(n, 0, "step {step}"),
        }
    }
}

/// Spacing of [`block_by_columns`]: two particles per cell of the 32 × 32 unit grid.
const BY_COLUMNS_SPACING: f64 = 1.0 / 64.0;

/// A 32 × 32 block of particles in the middle of the unit square, listed column by column
/// (across the rows of grid blocks, so the first step finds them scattered and sorts them).
fn block_by_columns() -> Vec<Vector<2>> {
    let q = BY_COLUMNS_SPACING;
    (0..32)
        .flat_map(|i| {
            (0..32).map(move |j| {
                Vector::<2>::new(0.25 + (i as f64 + 0.5) * q, 0.25 + (j as f64 + 0.5) * q)
            })
        })
        .collect()
}

/// A step that sorts the particles as it gathers (`Reorder::InGather`) and is rejected names
/// the first particle that failed by its id, as the same step without sorting does, and keeps
/// the last good state. Particles added column by column (so the first step sorts), one of them
/// (id 52) thrown out of the grid, taking its neighbours along; the one named sits in another
/// slot of the sorted new state than its id.
#[test]
fn a_rejected_sorting_step_names_the_particle_by_id() {
    let (x, q) = (block_by_columns(), BY_COLUMNS_SPACING);
    let named = |sort: bool| {
        let mut sim = Sim::<2>::new([0.0, 0.0], [32, 32], 1.0 / 32.0).unwrap();
        sim.set_fast_paths(FastPaths {
            particle_sorting: sort,
            ..FastPaths::default()
        });
        let m = sim.add_material(Material::neo_hookean(1000.0, YOUNG, 0.3).unwrap());
        sim.add_particles(m, &x, &vec![q * q; x.len()], None)
            .unwrap();
        // The time step of the block at rest, carried as if a step had found it: the
        // stability check would refuse the throw before the gather otherwise.
        let dt = sim.stable_dt(0.3).unwrap();
        sim.work.signal_speed = Some(sim.signal_speed());
        sim.particles.velocity[52] = Vector::<2>::new(1e9, 0.0);
        let before = sim.particles.clone();
        let e = sim.step(dt).unwrap_err();
        assert_eq!(e.kind, ErrorKind::OutsideGrid, "{e}");
        assert_eq!(sim.particles, before);
        let after = e.message.split("particle ").nth(1).unwrap();
        let id: usize = after.split(' ').next().unwrap().parse().unwrap();
        (id, sim.work.reorder, sim.work.bins.order.clone())
    };
    let ((sorted, reorder, order), (unsorted, _, _)) = (named(true), named(false));
    assert_eq!(reorder, super::Reorder::InGather);
    assert_eq!(sorted, unsorted);
    let slot = order.iter().position(|&p| p as usize == sorted).unwrap();
    assert_ne!(slot, sorted, "particle {sorted} keeps its slot");
}

/// A body force that squeezes the body along x so hard that one step maps every particle
/// through itself (`F_xx = 1 − Δt² K < 0`): the step is refused as inverted.
#[test]
fn inverted_particles_are_refused() {
    let mut sim = block::<2>(Shape::BSpline2, Transfer::Apic);
    let before = sim.particles.clone();
    let dt = sim.stable_dt(0.3).unwrap();
    let k = 3.0 / (dt * dt);
    sim.set_body_force(Some(Box::new(
        move |_t: f64, _x0: &[Vector<2>], x: &[Vector<2>], a: &mut [Vector<2>]| {
            for (a, x) in a.iter_mut().zip(x) {
                *a = Vector::<2>::new(-k * (x[0] - 0.5), 0.0);
            }
            Ok(())
        },
    )));
    let e = sim.step(dt).unwrap_err();
    assert_eq!(e.kind, ErrorKind::InvertedParticle, "{e}");
    assert_eq!(sim.particles, before);
}

#[test]
fn options_are_fixed_after_the_first_step() {
    let mut sim = block::<3>(Shape::BSpline3, Transfer::Apic);
    let dt = sim.stable_dt(0.3).unwrap();
    sim.step(dt).unwrap();
    for e in [
        sim.set_shape(Shape::Linear).unwrap_err(),
        sim.set_transfer(Transfer::Apic).unwrap_err(),
        sim.set_scheme(Scheme::Musl).unwrap_err(),
    ] {
        assert_eq!(e.kind, ErrorKind::InvalidState);
    }
    // Gravity and walls may change between steps.
    sim.set_gravity([0.0, 0.0, -9.81]).unwrap();
    sim.set_wall(2, Side::Low, Wall::Slip).unwrap();
    sim.step(dt).unwrap();
}

#[test]
fn add_particles_is_all_or_nothing() {
    let mut sim = Sim::<2>::new([0.0, 0.0], [4, 4], 0.25).unwrap();
    let m = sim.add_material(Material::linear_elastic(1.0, 1.0, 0.2).unwrap());
    let good = Vector::<2>::new(0.5, 0.5);
    let cases: [(u32, Vec<Vector<2>>, Vec<f64>, ErrorKind); 4] = [
        (7, vec![good], vec![0.1], ErrorKind::UnknownMaterial),
        (
            m,
            vec![good, Vector::<2>::new(1.5, 0.5)],
            vec![0.1, 0.1],
            ErrorKind::OutsideGrid,
        ),
        (
            m,
            vec![good, Vector::<2>::new(f64::NAN, 0.5)],
            vec![0.1, 0.1],
            ErrorKind::InvalidArgument,
        ),
        (
            m,
            vec![good, good],
            vec![0.1, 0.0],
            ErrorKind::InvalidArgument,
        ),
    ];
    for (mat, x, vol, kind) in cases {
        assert_eq!(
            sim.add_particles(mat, &x, &vol, None).unwrap_err().kind,
            kind
        );
        assert_eq!(sim.particles.len(), 0);
    }
    sim.add_particles(m, &[good], &[0.1], None).unwrap();
    assert_eq!(sim.particles.len(), 1);
    assert_eq!(sim.particles.mass[0], 0.1);
    assert_eq!(
        sim.particles.deformation_gradient[0],
        Matrix::<2>::identity()
    );
}

/// RK shape functions run through the unchanged step: order 1 (ã = 2, the cubic B-spline, and
/// ã = 1.6, a genuinely different function) conserves momentum with APIC and PIC; APIC with order
/// 2 is refused before anything moves.
///
/// Order ≥ 2 is not exercised in a full step here: its shape functions take negative values, so the
/// lumped node mass `Σ m_p Ψ_I` can be negative at the edge of a body, and the grid update has no
/// answer for that yet (the RK/VC issue decides it).
#[test]
fn rk_shape_functions_slot_into_the_step() {
    for (support, transfer) in [
        (2.0, Transfer::Apic),
        (1.6, Transfer::Apic),
        (1.6, Transfer::PicFlip { flip: 0.0 }),
    ] {
        let mut sim = block::<2>(Shape::Rk { order: 1, support }, transfer);
        let p0 = sim.particles.momentum();
        let dt = sim.stable_dt(0.3).unwrap();
        for _ in 0..10 {
            sim.step(dt).unwrap();
        }
        let p1 = sim.particles.momentum();
        assert!(
            (p1 - p0).norm() < 1e-12 * p0.norm(),
            "RK ã = {support}: {p0} -> {p1}"
        );
    }
    let mut sim = block::<2>(
        Shape::Rk {
            order: 2,
            support: 3.0,
        },
        Transfer::Apic,
    );
    let dt = sim.stable_dt(0.3).unwrap();
    assert_eq!(sim.step(dt).unwrap_err().kind, ErrorKind::Unsupported);
    assert_eq!(sim.steps(), 0);
}

/// With VC and no boundary points, every step finds the surface of the particles afresh: none
/// are added to the given boundary points, the surface of an undeformed 4×4 block is its
/// perimeter (voxels of half a spacing, merged: one face per particle face, two Gauss points
/// each), closed, and a rejected
/// step keeps the particles, so the next step finds the same surface.
#[test]
fn vc_finds_the_surface_of_the_particles_at_every_step() {
    let mut sim = Sim::<2>::new([0.0, 0.0], [10, 10], 0.1).unwrap();
    sim.set_integration(crate::sim::Integration::Vc { order: 1 })
        .unwrap();
    let m = sim.add_material(Material::linear_elastic(1.0, 1.0, 0.2).unwrap());
    let x: Vec<Vector<2>> = (0..16)
        .map(|k| Vector::<2>::new(0.425 + 0.05 * (k % 4) as f64, 0.425 + 0.05 * (k / 4) as f64))
        .collect();
    sim.add_particles(m, &x, &[0.0025; 16], None).unwrap();
    sim.set_body_force(Some(Box::new(
        |_t: f64, _x0: &[Vector<2>], _x: &[Vector<2>], _a: &mut [Vector<2>]| Err("no".to_string()),
    )));
    let dt = sim.stable_dt(0.3).unwrap();
    assert_eq!(sim.step(dt).unwrap_err().kind, ErrorKind::Callback);
    assert!(sim.boundary_points().is_empty());
    sim.set_body_force(None);
    sim.step(dt).unwrap();
    assert!(sim.boundary_points().is_empty());
    let s = sim.vc_surface();
    // One face per particle face of the 4 × 4 block (its faces fall on even voxels), two Gauss
    // points each.
    assert_eq!(s.len(), 32);
    let sum: Vector<2> = s.area_normal.iter().sum();
    assert!(sum.norm() < 1e-16, "{sum}");
    let area: f64 = s.area_normal.iter().map(|n| n.norm()).sum();
    assert!((area - 0.8).abs() < 1e-14, "{area}");
    // Every point lies on the block's edge.
    for p in &s.position {
        let on = (0..2).any(|a| (p[a] - 0.4).abs() < 1e-12 || (p[a] - 0.6).abs() < 1e-12);
        assert!(on, "{p}");
    }
}

/// Results do not depend on the thread count: the same particle data bit for bit with 1 and with
/// 2 worker threads of the simulation's own pool (`Sim::set_threads`; P2G runs by colours of rows of grid blocks or of blocks; the other phases
/// are per particle or per node), for B-splines with APIC and MLS and for RK with VC, and by rows
/// in a tall column, in 2D and 3D.
#[test]
fn results_do_not_depend_on_the_thread_count() {
    /// The particles after `steps` steps under gravity on `threads` worker threads, and the
    /// number of colours particle to grid ran by.
    fn steps_on<const D: usize>(
        threads: usize,
        steps: usize,
        make: impl FnOnce() -> Sim<D> + Send,
    ) -> (Particles<D>, usize) {
        let mut sim = make();
        sim.set_threads(threads).unwrap();
        assert_eq!(sim.threads(), threads);
        sim.set_gravity(Vector::<D>::from_element(-9.81)).unwrap();
        let dt = sim.stable_dt(0.3).unwrap();
        for _ in 0..steps {
            sim.step(dt).unwrap();
        }
        (sim.particles.clone(), sim.work.bins.tasks.len())
    }
    fn run<const D: usize>(
        threads: usize,
        shape: Shape,
        transfer: Transfer,
        vc: bool,
    ) -> Particles<D> {
        let make = || {
            let mut sim = block::<D>(shape, transfer);
            if vc {
                sim.set_integration(crate::sim::Integration::Vc { order: 1 })
                    .unwrap();
            }
            sim
        };
        steps_on(threads, 15, make).0
    }
    let rk1 = Shape::Rk {
        order: 1,
        support: 2.0,
    };
    // Particle to grid by rows of blocks (a tall column) as well as by blocks (the block).
    fn run_tall<const D: usize>(threads: usize) -> Particles<D> {
        let (particles, colours) = steps_on(threads, 10, || tall_column::<D>(Transfer::Mls));
        assert_eq!(colours, 1 << (D - 1), "not by rows");
        particles
    }
    assert_eq!(run_tall::<2>(1), run_tall::<2>(2), "2D by rows");
    assert_eq!(run_tall::<3>(1), run_tall::<3>(2), "3D by rows");
    for (shape, transfer, vc) in [
        (Shape::BSpline2, Transfer::Apic, false),
        (Shape::BSpline2, Transfer::Mls, false),
        (rk1, Transfer::Apic, true),
    ] {
        let (one, two) = (
            run::<2>(1, shape, transfer, vc),
            run::<2>(2, shape, transfer, vc),
        );
        assert_eq!(one, two, "{shape:?} {transfer:?}");
        let (one, two) = (
            run::<3>(1, shape, transfer, vc),
            run::<3>(2, shape, transfer, vc),
        );
        assert_eq!(one, two, "{shape:?} {transfer:?}");
    }
}

/// Two simulations, each on its own worker threads (`Sim::set_threads`: 3 and 2), stepped at
/// once from two host threads, give the particle data each gives stepped alone on one thread,
/// bit for bit: a 2D block with RK1 + VC1 and a 3D block with the quadratic B-spline.
#[test]
fn simulations_on_their_own_threads_step_at_once() {
    fn run<const D: usize>(threads: usize, shape: Shape, vc: bool) -> Particles<D> {
        let mut sim = block::<D>(shape, Transfer::Apic);
        if vc {
            sim.set_integration(crate::sim::Integration::Vc { order: 1 })
                .unwrap();
        }
        sim.set_threads(threads).unwrap();
        assert_eq!(sim.threads(), threads);
        sim.set_gravity(Vector::<D>::from_element(-9.81)).unwrap();
        let dt = sim.stable_dt(0.3).unwrap();
        for _ in 0..10 {
            sim.step(dt).unwrap();
        }
        sim.particles.clone()
    }
    let rk1 = Shape::Rk {
        order: 1,
        support: 2.0,
    };
    let alone = (run::<2>(1, rk1, true), run::<3>(1, Shape::BSpline2, false));
    let at_once = std::thread::scope(|s| {
        let a = s.spawn(|| run::<2>(3, rk1, true));
        let b = s.spawn(|| run::<3>(2, Shape::BSpline2, false));
        (a.join().unwrap(), b.join().unwrap())
    });
    assert!(
        alone.0 == at_once.0,
        "2D RK1 + VC1 on 3 threads beside a 3D run"
    );
    assert!(
        alone.1 == at_once.1,
        "3D B-spline on 2 threads beside a 2D run"
    );
}

/// `Sim::set_threads` takes 0 for one thread per core, refuses more than `MAX_THREADS` with the
/// count it had kept, and can change the count between steps.
#[test]
fn thread_counts_are_checked() {
    let mut sim = block::<2>(Shape::BSpline2, Transfer::Apic);
    assert_eq!(sim.threads(), rayon::current_num_threads());
    sim.set_threads(0).unwrap();
    let cores = std::thread::available_parallelism().unwrap().get();
    assert_eq!(sim.threads(), cores);
    let e = sim.set_threads(crate::MAX_THREADS + 1).unwrap_err();
    assert_eq!(e.kind, crate::ErrorKind::InvalidArgument);
    assert!(e.message.contains("at most 4096"), "{}", e.message);
    assert_eq!(sim.threads(), cores);
    let dt = sim.stable_dt(0.3).unwrap();
    sim.step(dt).unwrap();
    sim.set_threads(2).unwrap();
    sim.step(dt).unwrap();
    assert_eq!(sim.threads(), 2);
}

/// Results do not depend on the instruction set: the particle loops compiled for AVX2 and FMA
/// (`Lanes::wide`) give the same particle data bit for bit as the baseline code, for B-splines
/// with APIC, MLS and PIC/FLIP (the factored scatter and gather, the 3D gather in AVX2
/// registers, the shape factors, the constitutive update), elastic and with Drucker–Prager, in
/// 2D and 3D. On a processor without AVX2 both runs
/// take the baseline and the test says so.
#[test]
fn results_do_not_depend_on_the_instruction_set() {
    fn run<const D: usize>(
        baseline: bool,
        shape: Shape,
        transfer: Transfer,
        plastic: bool,
    ) -> Particles<D> {
        // A soil weak enough that the spinning block yields.
        let material = if plastic {
            Material::drucker_prager(1000.0, YOUNG, 0.3, 30.0, 1.0, 0.0).unwrap()
        } else {
            Material::neo_hookean(1000.0, YOUNG, 0.3).unwrap()
        };
        let mut sim = block_of::<D>(shape, transfer, material, true);
        sim.set_fast_paths(FastPaths {
            vector_instructions: !baseline,
            ..FastPaths::default()
        });
        sim.set_gravity(Vector::<D>::from_element(-9.81)).unwrap();
        let dt = sim.stable_dt(0.3).unwrap();
        for _ in 0..15 {
            sim.step(dt).unwrap();
        }
        if plastic {
            let yielded = sim
                .particles
                .history
                .iter()
                .filter(|s| s.plastic_strain > 0.0);
            assert!(yielded.count() > 0, "the soil block did not yield");
        }
        sim.particles.clone()
    }
    if !crate::cpu::Lanes::detect().avx2() {
        eprintln!("no AVX2 and FMA here: both runs take the baseline code");
    }
    let flip = Transfer::PicFlip { flip: 0.95 };
    for (shape, transfer, plastic) in [
        (Shape::BSpline2, Transfer::Apic, false),
        (Shape::BSpline2, Transfer::Mls, false),
        (Shape::BSpline2, Transfer::Apic, true),
        // The gather with the old velocities and the gradient sums (`avx2::gather_3d`,
        // `avx2::gather_2d`), and the 2D gather's rows of two and four nodes.
        (Shape::BSpline2, flip, false),
        (Shape::Linear, flip, false),
        (Shape::Linear, Transfer::Apic, false),
        (Shape::BSpline3, flip, false),
        (Shape::BSpline3, Transfer::Mls, false),
    ] {
        let (base, wide) = (
            run::<2>(true, shape, transfer, plastic),
            run::<2>(false, shape, transfer, plastic),
        );
        assert_eq!(base, wide, "2D {shape:?} {transfer:?} plastic {plastic}");
        if shape == Shape::BSpline2 {
            let (base, wide) = (
                run::<3>(true, shape, transfer, plastic),
                run::<3>(false, shape, transfer, plastic),
            );
            assert_eq!(base, wide, "3D {transfer:?} plastic {plastic}");
        }
    }
}

/// A chunk of particles finished at once (`ConstitutiveUpdate::finish_chunk`, the stresses as
/// vector lanes) gives each particle the same bits as finishing it alone: stress, pressure,
/// position (against a wall) and signal speed, in 2D and 3D, for full and partial chunks, with a
/// particle outside the grid (inadmissible, `None`). A chunk with an inverted particle, two
/// materials or a plastic one is left to `finish` (false, nothing changed).
#[test]
fn a_chunk_finished_at_once_gives_the_same_bits_as_one_by_one() {
    use super::grid_to_particle::{Chunk, Finish, ParticleUpdate, CHUNK};
    fn check<const D: usize>() {
        let mut sim = Sim::<D>::new(Vector::<D>::zeros(), [10; D], 0.1).unwrap();
        sim.set_wall(0, Side::Low, Wall::Slip).unwrap();
        let rubber = sim.add_material(Material::neo_hookean(1000.0, 1e6, 0.3).unwrap());
        let soil =
            sim.add_material(Material::drucker_prager(1000.0, 1e6, 0.3, 30.0, 0.0, 0.0).unwrap());
        let n = 2 * CHUNK;
        let x: Vec<Vector<D>> = (0..n)
            .map(|k| Vector::<D>::from_element(0.2 + 0.02 * k as f64))
            .collect();
        sim.add_particles(rubber, &x, &vec![1e-3; n], None).unwrap();
        let ps = sim.particles.clone();
        let finish = super::ConstitutiveUpdate {
            domain: sim.grid.domain(),
            particles: &ps,
            materials: &sim.materials,
            walls: &sim.options.walls,
            any_wall: sim.options.walls.any_wall(),
            dt: 1e-4,
        };
        let mut x = 0.37_f64;
        let mut next = || {
            x = (x * 9301.0 + 0.49297).fract();
            x - 0.5
        };
        let updates: Vec<ParticleUpdate<D>> = (0..n)
            .map(|k| {
                let mut u = ParticleUpdate::<D> {
                    deformation_gradient: Matrix::<D>::identity()
                        + 0.4 * Matrix::<D>::from_fn(|_, _| next()),
                    velocity: Vector::<D>::from_fn(|_, _| next()),
                    ..Default::default()
                };
                // Particle 3 pushed through the wall at x = 0, particle 5 out of the grid.
                u.position = Vector::<D>::from_element(0.5 + 0.3 * next());
                if k == 3 {
                    u.position[0] = -0.01;
                }
                if k == 5 {
                    u.position[1] = 7.0;
                }
                u
            })
            .collect();
        for len in [CHUNK, 7] {
            let mut alone = updates[..len].to_vec();
            let expected: Vec<Option<f64>> = alone
                .iter_mut()
                .enumerate()
                .map(|(p, u)| finish.finish(p, u, &mut History::default()))
                .collect();
            assert!(expected[5].is_none() && expected[0].is_some());
            assert_eq!(alone[3].position[0], 0.0);
            let mut together = updates[..len].to_vec();
            let mut speeds = vec![Some(-1.0); len];
            let chunk = Chunk {
                first: 0,
                len,
                source: None,
            };
            assert!(finish.finish_chunk(chunk, &mut together, &mut speeds));
            assert_eq!(speeds, expected, "{D}D, {len} particles");
            for (a, b) in alone.iter().zip(&together) {
                assert_eq!(a.stress, b.stress);
                assert_eq!(a.pressure.to_bits(), b.pressure.to_bits());
                assert_eq!(a.position, b.position);
            }
        }
        // Left to `finish`: an inverted particle; two materials; a plastic material.
        let mut inverted = updates[..CHUNK].to_vec();
        inverted[2].deformation_gradient[(0, 0)] = -1.0;
        inverted[2].deformation_gradient[(1, 1)] = 1.0;
        let mut speeds = vec![None; CHUNK];
        let before = inverted.clone();
        let [first, second] = [0, CHUNK].map(|first| Chunk {
            first,
            len: CHUNK,
            source: None,
        });
        assert!(!finish.finish_chunk(first, &mut inverted, &mut speeds));
        assert_eq!(inverted, before);
        let mut mixed = ps.clone();
        mixed.material[CHUNK + 1] = soil;
        let finish_mixed = super::ConstitutiveUpdate {
            particles: &mixed,
            ..finish
        };
        let mut chunk = updates[CHUNK..].to_vec();
        assert!(!finish_mixed.finish_chunk(second, &mut chunk, &mut speeds));
        mixed.material.fill(soil);
        let finish_soil = super::ConstitutiveUpdate {
            particles: &mixed,
            ..finish
        };
        assert!(!finish_soil.finish_chunk(second, &mut chunk, &mut speeds));
    }
    check::<2>();
    check::<3>();
}

/// RK of order 2 takes negative values, so the lumped mass `Σ m_p Ψ_I` of nodes at the edge of a
/// body is negative or tiny there; those nodes transfer with the nonnegative Shepard lumping
/// instead (`edge_lumping`). Every particle's transfer weights sum to one, no node mass is
/// negative, free fall stays exact and the spinning block keeps its momentum to round-off.
#[test]
fn rk2_lumping_at_the_edge_of_a_body() {
    use crate::shape::Stencils;
    let rk2 = Shape::Rk {
        order: 2,
        support: 3.0,
    };
    assert!(rk2.build::<2>().unwrap().is_signed());
    for support in [1.6, 2.0] {
        let rk1 = Shape::Rk { order: 1, support };
        assert!(!rk1.build::<2>().unwrap().is_signed(), "RK1 ã = {support}");
    }
    let pic = Transfer::PicFlip { flip: 0.0 };

    // Negative Σ m_p Ψ_I at the edge, positive Σ m_p L_I everywhere; the transfer weights of
    // the step sum to one at every particle and give no node a negative mass.
    let mut sim = block::<2>(rk2, pic);
    let dt = sim.stable_dt(0.3).unwrap();
    sim.step(dt).unwrap();
    let mut shape_only = Stencils::<2>::default();
    let shape = rk2.build::<2>().unwrap();
    shape_only.compute(shape.as_ref(), &sim.grid, &sim.particles.position);
    let st = &sim.work.stencils;
    let mut mass = std::collections::HashMap::<usize, [f64; 3]>::new();
    let mut blended = 0;
    for p in 0..sim.particles.len() {
        let (ns, ws, _) = shape_only.of(p);
        let phi = &st.transfer[p * st.len..(p + 1) * st.len];
        let ls = shape_only
            .lumping_of(p)
            .expect("signed shape has lumping weights");
        assert!((ls.iter().sum::<f64>() - 1.0).abs() < 1e-14);
        assert!((phi.iter().sum::<f64>() - 1.0).abs() < 1e-14);
        blended += usize::from(phi != ws);
        for s in 0..ns.len() {
            let e = mass.entry(ns[s]).or_default();
            e[0] += sim.particles.mass[p] * ws[s];
            e[1] += sim.particles.mass[p] * ls[s];
            e[2] += sim.particles.mass[p] * phi[s];
        }
    }
    let lowest = |k: usize| mass.values().map(|m| m[k]).fold(f64::INFINITY, f64::min);
    assert!(
        lowest(0) < 0.0,
        "expected negative Σ m Ψ, lowest {}",
        lowest(0)
    );
    assert!(
        lowest(1) >= 0.0 && lowest(2) >= 0.0,
        "{} {}",
        lowest(1),
        lowest(2)
    );
    // The 4 × 4-cell block has no node more than two cells from its edge: every particle sees
    // a blended node.
    assert_eq!(blended, sim.particles.len());

    // Free fall from rest: v = g t, F = I and no stress for every particle, to round-off.
    let mut sim = block_moving::<2>(rk2, pic, false);
    sim.set_gravity([0.0, -9.81]).unwrap();
    let dt = sim.stable_dt(0.3).unwrap();
    for _ in 0..20 {
        sim.step(dt).unwrap();
    }
    let g = Vector::<2>::new(0.0, -9.81 * sim.time());
    let ps = &sim.particles;
    for p in 0..ps.len() {
        // |v| ≈ 0.1 m/s after 20 steps; round-off of the sums is 1e-16 relative per step.
        assert!((ps.velocity[p] - g).norm() < 1e-14, "{}", ps.velocity[p]);
        assert!((ps.deformation_gradient[p] - Matrix::<2>::identity()).norm() < 1e-12);
    }

    // Momentum of the spinning block under PIC, over 100 steps: round-off (each step's sums
    // are exact to about 1e-16 relative).
    let mut sim = block::<2>(rk2, pic);
    let p0 = sim.particles.momentum();
    for _ in 0..100 {
        sim.step(dt).unwrap();
    }
    let drift = (sim.particles.momentum() - p0).norm() / p0.norm();
    eprintln!("RK2 spinning block: relative momentum drift over 100 steps {drift:e}");
    assert!(drift < 1e-13, "momentum drift {drift:e}");
}

/// B-spline stencils stored as 1D factors, with their factored (row by row) scatter and gather,
/// give the particle data of the stencils stored node by node to round-off: after 8 steps the
/// kinematic fields agree to 1e-12 of their largest value (measured: below 1e-14) and the stresses
/// to 1e-14 E (measured 2e-16 E), for APIC, FLIP and MLS (MLS with USL and MUSL: the stored
/// path folds the force node by node, the factored one row by row), 2D and 3D; and with VC
/// (of order 1 and 2 on the B-splines, APIC and MUSL with FLIP), where the factored map adds
/// VC's part of the internal force after the rest, at order 1 from the factors (no stencil
/// listed), at order 2 from the stored lists.
#[test]
fn factored_and_stored_stencils_agree_to_round_off() {
    fn run<const D: usize>(
        shape: Shape,
        (transfer, musl): (Transfer, bool),
        vc: Option<u32>,
        stored: bool,
    ) -> Particles<D> {
        let mut sim = block::<D>(shape, transfer);
        if musl {
            sim.set_scheme(Scheme::Musl).unwrap();
        }
        if let Some(order) = vc {
            sim.set_integration(crate::sim::Integration::Vc { order })
                .unwrap();
        }
        sim.set_gravity(Vector::<D>::from_element(-9.81)).unwrap();
        sim.set_fast_paths(FastPaths {
            factored_stencils: !stored,
            ..FastPaths::default()
        });
        let dt = sim.stable_dt(0.3).unwrap();
        for _ in 0..8 {
            sim.step(dt).unwrap();
        }
        // On the factors, only VC of order 2 lists the stencils (order 1 reads the factors).
        if !stored {
            assert_eq!(
                sim.work.stencils.len > 0,
                vc == Some(2),
                "{shape:?} VC {vc:?}"
            );
        }
        sim.particles.clone()
    }
    fn close<const D: usize>(a: &Particles<D>, b: &Particles<D>, what: &str) {
        let fields: [(&str, Vec<f64>, Vec<f64>); 6] = [
            ("position", flat(&a.position), flat(&b.position)),
            ("velocity", flat(&a.velocity), flat(&b.velocity)),
            (
                "F",
                flat(&a.deformation_gradient),
                flat(&b.deformation_gradient),
            ),
            ("stress", flat(&a.stress), flat(&b.stress)),
            ("affine", flat(&a.affine), flat(&b.affine)),
            ("pressure", a.pressure.clone(), b.pressure.clone()),
        ];
        for (name, x, y) in fields {
            assert_eq!(x.len(), y.len());
            let scale = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let diff = x
                .iter()
                .zip(&y)
                .fold(0.0f64, |m, (u, v)| m.max((u - v).abs()));
            // Stresses are the modulus times F − I: round-off in F (~1e-16) shows up as
            // ~1e-16 E in them (measured 1.9e-11 Pa with E = 1e5 Pa).
            let tolerance = match name {
                "stress" | "pressure" => 1e-14 * YOUNG,
                _ => 1e-12 * scale,
            };
            assert!(diff <= tolerance, "{what} {name}: {diff:e} of {scale:e}");
        }
    }
    fn flat<T: AsRef<[f64]>>(v: &[T]) -> Vec<f64> {
        v.iter().flat_map(|x| x.as_ref().to_vec()).collect()
    }
    for shape in [Shape::Linear, Shape::BSpline2, Shape::BSpline3] {
        for (transfer, musl) in [
            (Transfer::Apic, false),
            (Transfer::PicFlip { flip: 0.95 }, true),
            (Transfer::Mls, false),
            (Transfer::Mls, true),
        ] {
            if transfer == Transfer::Mls && shape == Shape::Linear {
                continue; // refused (tested above)
            }
            let what = format!("{shape:?} {transfer:?} musl {musl}");
            let scheme = (transfer, musl);
            close(
                &run::<2>(shape, scheme, None, false),
                &run::<2>(shape, scheme, None, true),
                &format!("{what} 2D"),
            );
            close(
                &run::<3>(shape, scheme, None, false),
                &run::<3>(shape, scheme, None, true),
                &format!("{what} 3D"),
            );
        }
    }
    for (shape, order, scheme) in [
        (Shape::BSpline2, 1, (Transfer::Apic, false)),
        (Shape::BSpline2, 1, (Transfer::PicFlip { flip: 0.95 }, true)),
        (Shape::BSpline3, 2, (Transfer::Apic, false)),
    ] {
        let what = format!("{shape:?} VC{order} {scheme:?}");
        close(
            &run::<2>(shape, scheme, Some(order), false),
            &run::<2>(shape, scheme, Some(order), true),
            &format!("{what} 2D"),
        );
        close(
            &run::<3>(shape, scheme, Some(order), false),
            &run::<3>(shape, scheme, Some(order), true),
            &format!("{what} 3D"),
        );
    }
}

/// Every particle is in one task of particle to grid, the tasks of one colour write disjoint
/// nodes, and of two tasks that write one node the later (in colour order) waits for the earlier
/// (`Bins::waits_of`); a task waits only for earlier ones.
fn check_tasks(
    bins: &crate::step::Bins<2>,
    stencils: &crate::shape::Stencils<2>,
    nodes: usize,
    particles: usize,
) {
    use crate::shape::StencilView;
    let mut seen = vec![0; particles];
    // The tasks (numbered colour by colour) that write each node.
    let mut writers = vec![Vec::<u32>::new(); nodes];
    let mut k = 0u32;
    for colour in &bins.tasks {
        let mut owner = vec![usize::MAX; nodes];
        for (t, range) in colour.iter().enumerate() {
            for &p in &bins.order[range.clone()] {
                seen[p as usize] += 1;
                stencils.for_each(p as usize, |_, s| {
                    if s.value != 0.0 || s.gradient != Vector::<2>::zeros() {
                        assert!(owner[s.node] == usize::MAX || owner[s.node] == t);
                        owner[s.node] = t;
                        if writers[s.node].last() != Some(&k) {
                            writers[s.node].push(k);
                        }
                    }
                });
            }
            k += 1;
        }
    }
    assert!(seen.iter().all(|&c| c == 1));
    let mut needed = vec![std::collections::BTreeSet::<u32>::new(); k as usize];
    for w in &writers {
        for (i, &later) in w.iter().enumerate() {
            needed[later as usize].extend(&w[..i]);
        }
    }
    for (t, needed) in needed.iter().enumerate() {
        let waits: std::collections::BTreeSet<u32> = bins.waits_of(t).iter().copied().collect();
        // Neighbouring blocks whose particles happen not to share a node may be waited for
        // too; a task that shares a node must be.
        assert!(
            needed.is_subset(&waits),
            "task {t}: {needed:?} not in {waits:?}"
        );
        assert!(
            waits.iter().all(|&w| (w as usize) < t),
            "task {t} waits for a later one"
        );
    }
}

/// The counting sort of the bins in chunks (over 2^17 particles per chunk, one per thread) gives
/// the stable order by block: the particles of a block in index order, the blocks ascending.
#[test]
fn bins_sorted_in_chunks_are_the_stable_order() {
    use crate::grid::{Bins, BlockLayout};
    let grid = crate::grid::Grid::<2>::new(Vector::<2>::zeros(), [600, 40], 0.1).unwrap();
    let layout = BlockLayout::new(3, &grid);
    let mut rng = crate::shape::UniformRng::new(11);
    let n = 400_000;
    // Runs of one block (as sorted particles have) and single strays.
    let mut keys = Vec::with_capacity(n);
    while keys.len() < n {
        let key = (rng.uniform() * 50.0) as u32; // of the 55 blocks
        let run = if rng.uniform() < 0.5 {
            1
        } else {
            1 + (rng.uniform() * 300.0) as usize
        };
        keys.extend(std::iter::repeat_n(key, run.min(n - keys.len())));
    }
    let mut bins = Bins::<2>::default();
    bins.compute_from_keys(&layout, &keys);
    let mut expected: Vec<u32> = (0..n as u32).collect();
    expected.sort_by_key(|&p| keys[p as usize]);
    assert_eq!(bins.order, expected);
}

/// The bins hold every particle once, in index order within a block; blocks of one colour are
/// two blocks apart along some axis, so the stencils of their particles never share a node.
#[test]
fn bins_cover_every_particle_and_colours_write_disjoint_nodes() {
    use crate::grid::{Bins, BlockLayout};
    use crate::shape::TensorStencils;
    use crate::shape::{BSpline, BSplineOrder, ShapeFunction, StencilView, Stencils};
    let mut rng = crate::shape::UniformRng::new(5);
    for shape in [
        Shape::Linear,
        Shape::BSpline3,
        Shape::Rk {
            order: 2,
            support: 3.0,
        },
    ] {
        let f: Box<dyn ShapeFunction<2>> = shape.build().unwrap();
        // Wide enough for two blocks along axis 0 (128 nodes each), so all four colours occur.
        let mut grid = crate::grid::Grid::<2>::new(Vector::<2>::zeros(), [300, 23], 0.1).unwrap();
        grid.set_ghost_layers(f.ghost_layers()).unwrap();
        let x: Vec<Vector<2>> = (0..8000)
            .map(|_| Vector::<2>::new(30.0 * rng.uniform(), 2.3 * rng.uniform()))
            .collect();
        let mut bins = Bins::<2>::default();
        crate::shape::bin_particles(&mut bins, f.as_ref(), &grid, &x);
        let mut seen = vec![0; x.len()];
        for (_, range) in &bins.occupied {
            let ps = &bins.order[range.clone()];
            assert!(ps.windows(2).all(|w| w[0] < w[1]));
            ps.iter().for_each(|&p| seen[p as usize] += 1);
        }
        assert!(seen.iter().all(|&c| c == 1), "{shape:?}");
        let mut stencils = Stencils::<2>::default();
        stencils.compute(f.as_ref(), &grid, &x);
        let mut blocks_seen = 0;
        for colour in &bins.colours {
            let mut owner = vec![u32::MAX; grid.node_count()];
            for &b in colour {
                blocks_seen += 1;
                for &p in &bins.order[bins.occupied[b as usize].1.clone()] {
                    stencils.for_each(p as usize, |_, s| {
                        if s.value != 0.0 || s.gradient != Vector::<2>::zeros() {
                            assert!(owner[s.node] == u32::MAX || owner[s.node] == b, "{shape:?}");
                            owner[s.node] = b;
                        }
                    });
                }
            }
        }
        assert_eq!(blocks_seen, bins.occupied.len());
        assert!(bins.colours.iter().filter(|c| !c.is_empty()).count() == 4);
        // The tasks of particle to grid: blocks here (six rows of blocks, fewer than
        // `MIN_ROWS`).
        assert_eq!(bins.tasks.len(), 4);
        check_tasks(&bins, &stencils, grid.node_count(), x.len());
        // A grid 40 to 80 rows of blocks tall: rows (two colours).
        let mut tall = crate::grid::Grid::<2>::new(Vector::<2>::zeros(), [300, 320], 0.1).unwrap();
        tall.set_ghost_layers(f.ghost_layers()).unwrap();
        let y: Vec<Vector<2>> = (0..8000)
            .map(|_| Vector::<2>::new(30.0 * rng.uniform(), 32.0 * rng.uniform()))
            .collect();
        let mut tall_bins = Bins::<2>::default();
        crate::shape::bin_particles(&mut tall_bins, f.as_ref(), &tall, &y);
        assert_eq!(tall_bins.tasks.len(), 2, "{shape:?}");
        let mut tall_stencils = Stencils::<2>::default();
        tall_stencils.compute(f.as_ref(), &tall, &y);
        check_tasks(&tall_bins, &tall_stencils, tall.node_count(), y.len());
        // The B-spline stencils find the same blocks with their factors (the step's bins).
        let keyed = |keys: &[u32], width: usize| {
            let mut b = Bins::<2>::default();
            b.compute_from_keys(&BlockLayout::new(width, &grid), keys);
            (b.order, b.occupied, b.colours, b.node_blocks)
        };
        let from_factors = match shape {
            Shape::Linear => {
                let mut t = TensorStencils::<2, 2>::default();
                t.compute(&BSpline::new(BSplineOrder::Linear), &grid, &x);
                Some(keyed(t.block_keys(), 2))
            }
            Shape::BSpline3 => {
                let mut t = TensorStencils::<2, 4>::default();
                t.compute(&BSpline::new(BSplineOrder::Cubic), &grid, &x);
                Some(keyed(t.block_keys(), 4))
            }
            _ => None,
        };
        if let Some(from_factors) = from_factors {
            let from_shape = (bins.order, bins.occupied, bins.colours, bins.node_blocks);
            assert_eq!(from_factors, from_shape, "{shape:?}");
        }
    }
}

/// A 3D scene of 10 million particles must fit in 16 GiB: with the quadratic B-spline
/// and APIC, particles and the step's per-particle storage stay under 1000 B per particle (885
/// measured with the sort's spare buffers at 10^6), which leaves 6 GiB of 16 for the grid;
/// 10^7 particles ran at 8.9 GB peak RSS (`BENCHMARKS.md`).
#[test]
fn memory_per_particle_allows_ten_million_particles_in_16_gib() {
    let mut sim = block::<3>(Shape::BSpline2, Transfer::Apic);
    let dt = sim.stable_dt(0.3).unwrap();
    sim.step(dt).unwrap();
    // As after a sort by block (the block here is in block order already): the spare buffers
    // count too.
    let reversed: Vec<u32> = (0..sim.particles.len() as u32).rev().collect();
    sim.particles.permute(&reversed, &mut sim.work.spare);
    let m = sim.memory();
    assert_eq!(m.particle_count, 512);
    assert!(m.bytes_per_particle() < 1000.0, "{m:?}");
    assert!(m.active_nodes > 0 && m.active_nodes < m.node_count, "{m:?}");
    assert!(m.bytes_per_node() < 200.0, "{m:?}");
}

/// A body against the domain's edge under VC: the faces of its lattice lie on the edge, but the
/// spacing `V^(1/3)` comes out a hair larger than the lattice's (rounding), which put the
/// generated boundary points just outside and refused the first step (found with the Taylor bar,
/// whose quarter rod sits on two symmetry planes). Points of the surface found outside the
/// domain go onto the edge.
#[test]
fn vc_body_against_the_domain_edge_steps() {
    let h: f64 = 3.2e-3 / 4.0;
    let q = h / 2.0;
    let spacing = (q * q * q).powf(1.0 / 3.0);
    // The case is real: the face of the first particle falls outside the domain by rounding.
    assert!(
        0.5 * q - 0.5 * spacing < 0.0,
        "spacing {spacing:e} against {q:e}"
    );
    let mut sim = Sim::<3>::new(Vector::<3>::zeros(), [6; 3], h).unwrap();
    sim.set_shape(Shape::Rk {
        order: 1,
        support: 2.0,
    })
    .unwrap();
    sim.set_integration(crate::sim::Integration::Vc { order: 1 })
        .unwrap();
    for axis in 0..3 {
        sim.set_wall(axis, Side::Low, Wall::Slip).unwrap();
    }
    let m = sim.add_material(Material::neo_hookean(8930.0, 117e9, 0.35).unwrap());
    let n = 4;
    let x: Vec<Vector<3>> = (0..n * n * n)
        .map(|k| {
            Vector::<3>::new(
                ((k % n) as f64 + 0.5) * q,
                ((k / n % n) as f64 + 0.5) * q,
                ((k / (n * n)) as f64 + 0.5) * q,
            )
        })
        .collect();
    sim.add_particles(m, &x, &vec![q * q * q; x.len()], None)
        .unwrap();
    let dt = sim.stable_dt(0.3).unwrap();
    sim.step(dt).unwrap();
    let b = sim.vc_surface();
    assert!(!b.is_empty());
    assert!(b.position.iter().all(|p| sim.grid().contains(p)));
    // The faces on the three planes x, y, z = 0 are on the edge exactly (the four voxel faces
    // of a particle face merged into one face, its four Gauss points).
    let on_edge = b
        .position
        .iter()
        .filter(|p| p.iter().any(|&c| c == 0.0))
        .count();
    assert_eq!(on_edge, 4 * 3 * n * n);
}

/// The steps store the particles in the order of their grid blocks once they are scattered over
/// them (here from the start: added column by column, across the blocks' rows). That changes the
/// order of the node sums, so the results agree with unsorted storage to round-off, and nothing
/// the API hands out changes order: `Sim::field` and the body-force callback's arrays are in id
/// order (the callback below checks its reference positions against the added ones and pushes
/// the two halves of the block apart by them, so a slip in the map back would show at once).
#[test]
fn sorting_the_particles_changes_only_round_off() {
    let (added, q) = (block_by_columns(), BY_COLUMNS_SPACING);
    let run = |sort: bool| {
        let mut sim = Sim::<2>::new([0.0, 0.0], [32, 32], 1.0 / 32.0).unwrap();
        sim.set_fast_paths(FastPaths {
            particle_sorting: sort,
            ..FastPaths::default()
        });
        let m = sim.add_material(Material::neo_hookean(1000.0, YOUNG, 0.3).unwrap());
        let v: Vec<Vector<2>> = added
            .iter()
            .map(|x| Vector::<2>::new(-(x[1] - 0.5), x[0] - 0.5))
            .collect();
        sim.add_particles(m, &added, &vec![q * q; added.len()], Some(&v))
            .unwrap();
        let expected = added.clone();
        sim.set_body_force(Some(Box::new(
            move |_t: f64, x0: &[Vector<2>], _x: &[Vector<2>], a: &mut [Vector<2>]| {
                if x0 != &expected[..] {
                    return Err("reference positions out of id order".into());
                }
                for (a, x0) in a.iter_mut().zip(x0) {
                    *a = Vector::<2>::new(if x0[0] < 0.5 { -5.0 } else { 5.0 }, 0.0);
                }
                Ok(())
            },
        )));
        let dt = sim.stable_dt(0.3).unwrap();
        for _ in 0..20 {
            sim.step(dt).unwrap();
        }
        sim
    };
    let (sorted, unsorted) = (run(true), run(false));
    assert!(unsorted.particles.in_id_order());
    assert!(
        !sorted.particles.in_id_order(),
        "the particles were not sorted"
    );
    assert!(!sorted.work.bins.is_scattered(crate::cpu::Lanes::baseline()));
    // Round-off of sums of a few dozen O(1) terms per node, over 20 steps.
    for field in [Field::Position, Field::Velocity, Field::Stress] {
        let (a, b) = (sorted.field(field), unsorted.field(field));
        let scale = b.iter().fold(0.0f64, |s, x| s.max(x.abs()));
        let worst = a
            .iter()
            .zip(&b)
            .fold(0.0f64, |s, (x, y)| s.max((x - y).abs()));
        eprintln!("{field:?}: sorted against unsorted {worst:e} of {scale:e}");
        assert!(worst <= 1e-12 * scale, "{field:?}: {worst:e} of {scale:e}");
    }
}

/// Under USL grid to particle writes the new state in block order and the commit permutes only
/// what a step carries unchanged (`Reorder::InGather`); that is the same, bit for bit, as
/// permuting everything at the commit: every particle array (ids, materials, history of the
/// plastic half included) after steps that sorted. Particles added column by column, so the first
/// step sorts; a rotating block of an elastic and a Drucker–Prager half under gravity (the soil
/// yields, so its history moves with it).
#[test]
fn sorting_in_grid_to_particle_is_sorting_at_the_commit() {
    let (added, q) = (block_by_columns(), BY_COLUMNS_SPACING);
    let run = |at_commit: bool| {
        let mut sim = Sim::<2>::new([0.0, 0.0], [32, 32], 1.0 / 32.0).unwrap();
        sim.work.reorder_at_commit = at_commit;
        let solid = sim.add_material(Material::neo_hookean(1000.0, YOUNG, 0.3).unwrap());
        let soil =
            sim.add_material(Material::drucker_prager(2000.0, YOUNG, 0.3, 30.0, 0.0, 0.0).unwrap());
        sim.set_gravity(Vector::<2>::new(0.0, -9.81)).unwrap();
        for (m, left) in [(solid, true), (soil, false)] {
            let x: Vec<Vector<2>> = added
                .iter()
                .copied()
                .filter(|x| (x[0] < 0.5) == left)
                .collect();
            let v: Vec<Vector<2>> = x
                .iter()
                .map(|x| Vector::<2>::new(-(x[1] - 0.5), x[0] - 0.5))
                .collect();
            sim.add_particles(m, &x, &vec![q * q; x.len()], Some(&v))
                .unwrap();
        }
        let dt = sim.stable_dt(0.3).unwrap();
        let mut in_gather = 0;
        for _ in 0..20 {
            sim.step(dt).unwrap();
            in_gather += usize::from(sim.work.reorder == super::Reorder::InGather);
        }
        (sim, in_gather)
    };
    let ((gathered, in_gather), (committed, none)) = (run(false), run(true));
    assert!(
        in_gather >= 1 && none == 0,
        "{in_gather} sorts in grid to particle"
    );
    assert!(
        !gathered.particles.in_id_order(),
        "the particles were not sorted"
    );
    let yielded = gathered
        .particles
        .history
        .iter()
        .filter(|s| s.plastic_strain > 0.0);
    assert!(yielded.count() > 0, "the soil did not yield");
    assert_eq!(gathered.particles, committed.particles);
}

/// A step computes `max_p (c_p + |v_p|)` of the new state while it has it in registers, and the
/// next step's stability check (and `stable_dt`) use that instead of reading every particle
/// again. It is the same number, bit for bit, as taking it afresh from the committed particles:
/// under USL and MUSL, for neo-Hookean, Drucker–Prager and Johnson–Cook (with its
/// Mie–Grüneisen EOS) materials and a rigid body under contact. Adding particles drops it.
#[test]
fn the_signal_speed_a_step_carries_is_the_one_taken_afresh() {
    fn check<const D: usize>(material: Material, scheme: Scheme, rigid: bool) {
        let mut sim = block::<D>(Shape::BSpline2, Transfer::Apic);
        sim.set_scheme(scheme).unwrap();
        // The block's own material is replaced by `material` (index 1).
        let m = sim.add_material(material);
        sim.particles.material.iter_mut().for_each(|k| *k = m);
        let n = sim.particles.len();
        sim.particles.history.resize(n, History::default());
        if rigid {
            sim.set_contact(Some(0.2)).unwrap();
            let slab = sim.add_material(Material::rigid(7800.0, [0.0; 3]).unwrap());
            let x: Vec<Vector<D>> = (0..20)
                .map(|i| {
                    let mut x = Vector::<D>::from_element(0.5);
                    x[0] = 0.2 + 0.03 * i as f64;
                    x[D - 1] = 0.25;
                    x
                })
                .collect();
            sim.add_particles(slab, &x, &[0.05f64.powi(D as i32); 20], None)
                .unwrap();
        }
        sim.set_gravity(Vector::<D>::from_element(-9.81)).unwrap();
        assert_eq!(sim.work.signal_speed, None);
        let dt = 0.5 * sim.stable_dt(0.3).unwrap();
        for _ in 0..5 {
            sim.step(dt).unwrap();
            let fresh = sim.signal_speed();
            assert!(fresh > 0.0);
            assert_eq!(
                sim.work.signal_speed.map(f64::to_bits),
                Some(fresh.to_bits()),
                "{scheme:?} rigid {rigid}"
            );
        }
        let x = [sim.particles.position[0]];
        sim.add_particles(m, &x, &[1e-4], None).unwrap();
        assert_eq!(sim.work.signal_speed, None);
    }
    let soil = || Material::drucker_prager(2000.0, 1e6, 0.3, 30.0, 0.0, 0.0).unwrap();
    let metal = || {
        Material::johnson_cook(crate::material::JohnsonCookParameters {
            density: 1000.0,
            young: 1e5,
            ..crate::material::ofhc_copper()
        })
        .unwrap()
    };
    let rubber = || Material::neo_hookean(1000.0, YOUNG, 0.3).unwrap();
    for scheme in [Scheme::Usl, Scheme::Musl] {
        check::<2>(rubber(), scheme, false);
        check::<3>(rubber(), scheme, false);
        check::<2>(soil(), scheme, false);
        check::<2>(metal(), scheme, false);
    }
    check::<2>(rubber(), Scheme::Usl, true);
    check::<3>(soil(), Scheme::Usl, true);
}

/// Linear hats (and signed shapes): nodes whose mass is at most 1e-10 of the heaviest
/// particle's get no velocity (the grid update's mass floor, from the largest mass particle to
/// grid returns): a particle 10^-13 as heavy as the block's, alone away from it, stops; one
/// 10^-6 as heavy keeps its velocity. Smooth nonnegative shapes (B-splines) floor only empty
/// nodes, so that no momentum is dropped: there even the 10^-13 particle keeps its velocity.
/// With one field and with contact (a field per body, each mapping only its own particles; the
/// floor is still from the heaviest of all).
#[test]
fn nodes_lighter_than_the_mass_floor_get_no_velocity() {
    fn light_particle_velocity(shape: Shape, ratio: f64, contact: bool) -> Vector<2> {
        let mut sim = block_moving::<2>(shape, Transfer::PicFlip { flip: 0.0 }, false);
        if contact {
            sim.set_contact(Some(0.0)).unwrap();
        }
        let dust =
            sim.add_material(Material::neo_hookean(1000.0 * ratio, YOUNG * ratio, 0.3).unwrap());
        let v = Vector::<2>::new(0.3, -0.2);
        sim.add_particles(
            dust,
            &[Vector::<2>::new(1.02, 0.98)],
            &[0.05f64.powi(2)],
            Some(&[v]),
        )
        .unwrap();
        sim.step(1e-4).unwrap();
        let ps = &sim.particles;
        let p = ps.material.iter().position(|&m| m == dust).unwrap();
        ps.velocity[p]
    }
    let v = Vector::<2>::new(0.3, -0.2);
    for contact in [false, true] {
        assert_eq!(
            light_particle_velocity(Shape::Linear, 1e-13, contact),
            Vector::<2>::zeros()
        );
        for (shape, ratio) in [
            (Shape::Linear, 1e-6),
            (Shape::BSpline2, 1e-6),
            (Shape::BSpline2, 1e-13),
        ] {
            let kept = light_particle_velocity(shape, ratio, contact);
            assert!(
                (kept - v).norm() < 1e-12,
                "{shape:?} {ratio:e} contact {contact}: {kept:?}"
            );
        }
    }
}

/// The body force is called on the thread that steps (the C API promises it), also now that the
/// rest of the step runs on rayon's threads: from the test's own thread and from a thread of a
/// pool of two that steps the simulation there; the step's result is the same either way.
#[test]
fn the_body_force_is_called_on_the_thread_that_steps() {
    fn step_on_this_thread() -> (Vec<std::thread::ThreadId>, Particles<2>) {
        let mut sim = block::<2>(Shape::BSpline2, Transfer::Apic);
        let dt = sim.stable_dt(0.3).unwrap();
        let seen = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let record = seen.clone();
        sim.set_body_force(Some(Box::new(
            move |_t: f64, _x0: &[Vector<2>], _x: &[Vector<2>], a: &mut [Vector<2>]| {
                record.lock().unwrap().push(std::thread::current().id());
                a.iter_mut().for_each(|a| *a = Vector::<2>::new(0.0, -9.81));
                Ok(())
            },
        )));
        for _ in 0..3 {
            sim.step(dt).unwrap();
        }
        let seen = seen.lock().unwrap().clone();
        (seen, sim.particles.clone())
    }
    let here = std::thread::current().id();
    let (seen, alone) = step_on_this_thread();
    assert_eq!(seen, vec![here; 3]);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    let (seen, in_pool) = pool.install(|| {
        let (seen, ps) = step_on_this_thread();
        assert_eq!(seen, vec![std::thread::current().id(); 3]);
        (seen, ps)
    });
    assert_ne!(seen[0], here);
    assert_eq!(in_pool, alone);
}

/// The active list collected in parallel (nothing listed yet) is the serial one: the written
/// nodes (marked touched, or with mass) of the touched node blocks, block by block in ascending
/// order, each with its slot; nodes outside those blocks are not listed. The serial way is
/// taken when a node is listed already: listing the parallel list's first node first must give
/// the same list. In 2D and 3D, with blocks cut by the grid's edge.
#[test]
fn active_nodes_collected_in_parallel_are_the_serial_list() {
    fn check<const D: usize>(dims: [usize; D]) {
        use crate::grid::Bins;
        use crate::grid::{Grid, GridNodes, NodeScatter};
        use crate::shape::ShapeFunction;
        let mut rng = crate::shape::UniformRng::new(11);
        let f: Box<dyn ShapeFunction<D>> = Shape::BSpline2.build().unwrap();
        let mut grid = Grid::<D>::new(Vector::<D>::zeros(), dims, 0.1).unwrap();
        grid.set_ghost_layers(f.ghost_layers()).unwrap();
        // Particles in part of the grid only, so that some node blocks are untouched.
        let x: Vec<Vector<D>> = (0..3000)
            .map(|_| Vector::<D>::from_fn(|a, _| 0.06 * dims[a] as f64 * rng.uniform()))
            .collect();
        let mut bins = Bins::<D>::default();
        crate::shape::bin_particles(&mut bins, f.as_ref(), &grid, &x);
        let mut nodes = GridNodes::<D>::default();
        nodes.ensure(&grid, false, false, false).unwrap();
        // Every third node touched, every fifth given mass, everywhere in the grid.
        {
            let out = NodeScatter::new(&mut nodes);
            for n in (0..grid.node_count()).step_by(3) {
                // SAFETY: one thread.
                unsafe { out.touch(n) };
            }
        }
        for n in (0..grid.node_count()).step_by(5) {
            nodes.mass[n] = 1.0;
        }
        let mut parallel = nodes.clone();
        bins.collect_active(&grid, &mut parallel);
        let listed = &parallel.active;
        assert!(listed.len() > 100, "{}", listed.len());
        for (k, &n) in listed.iter().enumerate() {
            assert!(n % 3 == 0 || n % 5 == 0, "node {n} is not written");
            assert!(parallel.is_touched(n));
            assert_eq!(parallel.slot(n), k);
        }
        let mut serial = nodes.clone();
        serial.touch(listed[0]);
        bins.collect_active(&grid, &mut serial);
        assert_eq!(&serial.active, listed);
        // Written nodes outside the touched blocks stay off the list.
        let unlisted = (0..grid.node_count())
            .filter(|&n| (n % 3 == 0 || n % 5 == 0) && !listed.contains(&n))
            .count();
        assert!(unlisted > 0);
    }
    check::<2>([300, 40]);
    check::<3>([40, 30, 20]);
}

/// RK2 + VC2 at a free surface: the divergence equalities take the transfer weights `Φ` as the
/// test function (`crate::integration`), the weights that also carry the body force and the
/// mass, so a column in its exact static stress state is in equilibrium node by node, the nodes
/// above its top (where `Φ ≠ Ψ`) included. A column 8 cells tall between slip walls on a fixed
/// floor, 2 × 2 particles per cell, given `σ_yy = −ρ g (H − y)` (and `σ_xx = ν/(1 − ν) σ_yy`)
/// and stepped once from rest under gravity: the particles' velocities are what the nodes'
/// force imbalance gave them. Measured: largest `|v_p|` 6.2e-3 of `g Δt`, against 8.8e-2 with
/// `Ψ` as the test function; what is left is the equalities that the edge nodes meet only
/// approximately (damped, or of order 1). The bound sits between the two, 3 times above the
/// measured value.
#[test]
fn rk2_vc2_column_in_its_exact_stress_state_stays_at_rest() {
    let (cells, height, rho, g, nu) = (8usize, 1.0, 1000.0, 10.0, 0.3);
    let h = height / cells as f64;
    // As wide as the slip walls' mirrors need.
    let width = 4usize;
    let mut sim = Sim::<2>::new(Vector::<2>::zeros(), [width, cells + 2], h).unwrap();
    sim.set_shape(Shape::Rk {
        order: 2,
        support: 3.0,
    })
    .unwrap();
    sim.set_transfer(Transfer::PicFlip { flip: 0.0 }).unwrap();
    sim.set_integration(crate::options::Integration::Vc { order: 2 })
        .unwrap();
    sim.set_vc_solve(crate::VcSolve::EXACT).unwrap();
    sim.set_wall(0, Side::Low, Wall::Slip).unwrap();
    sim.set_wall(0, Side::High, Wall::Slip).unwrap();
    sim.set_wall(1, Side::Low, Wall::Fixed).unwrap();
    sim.set_gravity([0.0, -g]).unwrap();
    let m = sim.add_material(Material::neo_hookean(rho, YOUNG, nu).unwrap());
    let q = h / 2.0;
    let across = 2 * width;
    let x: Vec<Vector<2>> = (0..2 * cells * across)
        .map(|k| {
            let (i, j) = (k % across, k / across);
            Vector::<2>::new((i as f64 + 0.5) * q, (j as f64 + 0.5) * q)
        })
        .collect();
    let vol = vec![q * q; x.len()];
    sim.add_particles(m, &x, &vol, None).unwrap();
    let (bx, bn) = crate::BoundaryPoints::<2>::from_lattice(&x, &vol);
    sim.add_boundary_points(&bx, &bn, None).unwrap();
    for (p, xp) in x.iter().enumerate() {
        let s = -rho * g * (height - xp[1]);
        sim.particles.stress[p] = Matrix::<2>::new(nu / (1.0 - nu) * s, 0.0, 0.0, s);
    }
    let dt = sim.stable_dt(0.3).unwrap();
    sim.step(dt).unwrap();
    let fastest = sim
        .particles
        .velocity
        .iter()
        .map(|v| v.norm())
        .fold(0.0, f64::max);
    eprintln!(
        "largest speed after one step: {:.3e} of g dt",
        fastest / (g * dt)
    );
    assert!(fastest < 2e-2 * g * dt, "{:e} of g dt", fastest / (g * dt));
}
