//! VC integration conserves what the method conserves: the corrected test-function gradients
//! sum to zero over every particle's support, so the internal forces cancel and a free body's
//! linear momentum stays what it was (to round-off), and a problem symmetric about a node plane
//! stays symmetric.

use rkmpm::UniformRng;
use rkmpm::{Integration, Material, Shape, Side, Sim, Transfer, VcSolve, Wall};

type V<const D: usize> = nalgebra::SVector<f64, D>;

/// Every smooth shape with the VC order it goes with, and a transfer that conserves linear
/// momentum (RK2 with PIC: APIC is unstable with it). Linear hats are not here: cell crossing
/// inverts this jittered, sheared block before 1000 steps.
fn methods() -> Vec<(&'static str, Shape, u32, Transfer)> {
    let apic = Transfer::Apic;
    vec![
        ("B-spline 2 + VC1", Shape::BSpline2, 1, apic),
        ("B-spline 3 + VC1", Shape::BSpline3, 1, apic),
        (
            "RK1 + VC1",
            Shape::Rk {
                order: 1,
                support: 2.0,
            },
            1,
            apic,
        ),
        (
            "RK2 + VC2",
            Shape::Rk {
                order: 2,
                support: 3.0,
            },
            2,
            Transfer::PicFlip { flip: 0.0 },
        ),
    ]
}

/// A block of 2 × 2 (× 2) particles per cell, jittered by ±30 % of their spacing, in the middle
/// of a grid with free faces, sheared and squeezed by its initial velocity field.
fn free_block<const D: usize>(shape: Shape, order: u32, transfer: Transfer) -> Sim<D> {
    let cells = 12;
    let h = 1.0 / cells as f64;
    let mut sim = Sim::<D>::new(V::<D>::zeros(), [cells; D], h).unwrap();
    sim.set_shape(shape).unwrap();
    sim.set_transfer(transfer).unwrap();
    sim.set_integration(Integration::Vc { order }).unwrap();
    let mat = sim.add_material(Material::neo_hookean(1000.0, 1e6, 0.3).unwrap());
    let s = h / 2.0;
    let n = 8usize; // 4 cells of particles per side, from 0.3 on
    let mut rng = UniformRng::new(11);
    let (mut x, mut v) = (Vec::new(), Vec::new());
    for k in 0..n.pow(D as u32) {
        let mut r = k;
        let mut p = V::<D>::from_fn(|_, _| {
            let i = r % n;
            r /= n;
            0.34 + (i as f64 + 0.5) * s
        });
        for a in 0..D {
            p[a] += (2.0 * rng.uniform() - 1.0) * 0.3 * s;
        }
        let c = p - V::<D>::from_element(0.5);
        // Shear, squeeze and a drift: v = (0.3 + 0.5 y − 0.3 x, −0.2 + 0.5 x + 0.3 y, ...) m/s.
        v.push(V::<D>::from_fn(|a, _| {
            let next = c[(a + 1) % D];
            [0.3, -0.2, 0.1][a] + 0.5 * next + 0.3 * if a == 0 { -c[0] } else { c[a] }
        }));
        x.push(p);
    }
    let vol = vec![s.powi(D as i32); x.len()];
    sim.add_particles(mat, &x, &vol, Some(&v)).unwrap();
    sim
}

fn momentum<const D: usize>(sim: &Sim<D>) -> (V<D>, f64) {
    let ps = sim.particles();
    let p = (0..ps.len())
        .map(|i| ps.mass()[i] * ps.velocity()[i])
        .sum::<V<D>>();
    let scale = (0..ps.len())
        .map(|i| ps.mass()[i] * ps.velocity()[i].norm())
        .sum::<f64>();
    (p, scale)
}

/// Over `steps` steps, VC2 over `order2_steps`.
fn conserves_momentum<const D: usize>(steps: usize, order2_steps: usize) {
    let mut failed = Vec::new();
    for (name, shape, order, transfer) in methods() {
        let steps = if order == 2 { order2_steps } else { steps };
        let mut sim = free_block::<D>(shape, order, transfer);
        let (p0, scale) = momentum(&sim);
        let dt = 0.25 * sim.stable_dt(0.3).unwrap();
        let mut ended = None;
        for k in 0..steps {
            if let Err(e) = sim.step(dt) {
                ended = Some(format!("{k}: {e}"));
                break;
            }
        }
        if let Some(e) = ended {
            failed.push(format!("{D}D {name}: {e}"));
            continue;
        }
        let (p1, _) = momentum(&sim);
        let drift = (p1 - p0).norm() / scale;
        eprintln!("{D}D {name}: momentum drift {drift:.2e} over {steps} steps");
        if drift.is_nan() || drift >= 1e-12 {
            failed.push(format!("{D}D {name}: momentum drift {drift:e}"));
        }
    }
    assert!(failed.is_empty(), "{failed:?}");
}

/// Issue target: a free body's linear momentum conserved to 1e-12 relative over 1000 steps,
/// for every shape and VC order.
#[test]
fn vc_conserves_linear_momentum_2d() {
    conserves_momentum::<2>(1000, 1000);
}

/// 3D over 100 steps in the test command, RK2 + VC2 over 25 (about a second a step on this
/// small block, three quarters of it assembling and applying the order-2 operator of `7^3`-node
/// stencils); the full 1000 below.
#[test]
fn vc_conserves_linear_momentum_3d() {
    conserves_momentum::<3>(100, 25);
}

/// The 3D target over its 1000 steps (`cargo test --release --test engine vc_conservation:: -- --ignored`):
/// measured 5.4e-16, 2.2e-13, 2.2e-13 and 6.6e-16 in the order of `methods`; over half an hour
/// on one thread, most of it RK2 + VC2.
#[test]
#[ignore = "long: the 3D momentum target over 1000 steps; the test command runs 100"]
fn vc_conserves_linear_momentum_3d_over_1000_steps() {
    conserves_momentum::<3>(1000, 1000);
}

/// A block dropped straight down onto a floor of the kind `wall`, its particles (jittered)
/// mirror images of each other about the node plane x = 1/2: the largest mirror mismatch of
/// positions (`x_p + x_p' − 1`, `y_p − y_p'`) after the impact, relative to the block's size.
fn mirror_mismatch<const D: usize>(
    shape: Shape,
    order: Option<u32>,
    transfer: Transfer,
    wall: Wall,
    linear_fit: bool,
) -> f64 {
    mirror_mismatch_of_drop::<D>(
        shape,
        order,
        transfer,
        Drop {
            wall,
            linear_fit,
            ..Drop::STUDY
        },
    )
}

/// The grid, the block and the fall of a mirror-symmetric drop.
#[derive(Clone, Copy)]
struct Drop {
    cells: usize,
    /// Particles per side of the mirror plane along x (twice that along the other axes).
    half: usize,
    /// Height of the block's lowest particle row's cell edge above the floor.
    bottom: f64,
    /// Simulated time: the fall and the impact.
    duration: f64,
    /// The floor.
    wall: Wall,
    /// VC of order 1 with the particles' linear fit (`Sim::set_vc_linear_fit`).
    linear_fit: bool,
}

impl Drop {
    /// 16 cells, 12 particles across, the block's base at 0.14: 0.4 s, the fall (0.17 s) and
    /// the impact.
    const STUDY: Drop = Drop {
        cells: 16,
        half: 6,
        bottom: 0.14,
        duration: 0.4,
        wall: Wall::Friction(0.3),
        linear_fit: false,
    };
}

fn mirror_mismatch_of_drop<const D: usize>(
    shape: Shape,
    order: Option<u32>,
    transfer: Transfer,
    drop: Drop,
) -> f64 {
    let cells = drop.cells;
    let h = 1.0 / cells as f64;
    let mut sim = Sim::<D>::new(V::<D>::zeros(), [cells; D], h).unwrap();
    sim.set_shape(shape).unwrap();
    sim.set_transfer(transfer).unwrap();
    if let Some(order) = order {
        sim.set_integration(Integration::Vc { order }).unwrap();
    }
    sim.set_wall(1, Side::Low, drop.wall).unwrap();
    sim.set_vc_linear_fit(drop.linear_fit).unwrap();
    // The exact solve (the default at order 1, not at order 2), selected whatever the default is.
    sim.set_vc_solve(VcSolve::EXACT).unwrap();
    let mut g = V::<D>::zeros();
    g[1] = -9.81;
    sim.set_gravity(g).unwrap();
    let mat = sim.add_material(Material::neo_hookean(1000.0, 1e5, 0.3).unwrap());
    let s = h / 2.0;
    let half = drop.half; // particles per side of the plane
    let n = 2 * half;
    let mut rng = UniformRng::new(3);
    let mut x = Vec::new();
    // Each particle of the half x < 1/2, then its mirror image: ids 2k and 2k + 1.
    for k in 0..half * n.pow(D as u32 - 1) {
        let mut r = k;
        let mut p = V::<D>::from_fn(|a, _| {
            let (count, start) = if a == 0 {
                (half, 0.5 - half as f64 * s)
            } else {
                (n, drop.bottom)
            };
            let i = r % count;
            r /= count;
            start + (i as f64 + 0.5) * s
        });
        if D == 3 {
            p[2] += 0.5 - drop.bottom - 0.5 * n as f64 * s;
        }
        for a in 0..D {
            p[a] += (2.0 * rng.uniform() - 1.0) * 0.3 * s;
        }
        let mut image = p;
        image[0] = 1.0 - p[0];
        x.push(p);
        x.push(image);
    }
    let vol = vec![s.powi(D as i32); x.len()];
    sim.add_particles(mat, &x, &vol, None).unwrap();
    let mismatch = |sim: &Sim<D>| {
        // In id order: each particle beside its image.
        let ps = sim.particles();
        let mut worst = 0.0f64;
        for k in 0..ps.len() / 2 {
            let (a, b) = (ps.position()[2 * k], ps.position()[2 * k + 1]);
            worst = worst.max((a[0] + b[0] - 1.0).abs());
            for c in 1..D {
                worst = worst.max((a[c] - b[c]).abs());
            }
        }
        worst / (n as f64 * s)
    };
    let dt = 0.3 * sim.stable_dt(0.3).unwrap();
    for _ in 0..(drop.duration / dt) as usize {
        sim.step(dt).unwrap();
    }
    mismatch(&sim)
}

/// A drop: name, shape, VC order, transfer, floor, bound of the mismatch, linear fit.
type MirrorCase<'a> = (
    &'a str,
    Shape,
    Option<u32>,
    Transfer,
    (&'a str, Wall),
    f64,
    bool,
);

/// The mirror mismatch of each drop in `D` dimensions, with its run time; the cases over their
/// bound.
fn mirror_failures<const D: usize>(cases: &[MirrorCase]) -> Vec<String> {
    let mut failed = Vec::new();
    for &(name, shape, order, transfer, (floor, wall), bound, linear_fit) in cases {
        let name = match linear_fit {
            true => format!("{name} (linear fit)"),
            false => name.to_string(),
        };
        let start = std::time::Instant::now();
        let mismatch = mirror_mismatch::<D>(shape, order, transfer, wall, linear_fit);
        eprintln!(
            "{D}D {name}, {floor} floor: mirror mismatch {mismatch:.2e} ({:.1} s)",
            start.elapsed().as_secs_f64()
        );
        if mismatch >= bound {
            failed.push(format!("{D}D {name}, {floor}: {mismatch:.1e}"));
        }
    }
    failed
}

const RK1: Shape = Shape::Rk {
    order: 1,
    support: 2.0,
};
const RK2: Shape = Shape::Rk {
    order: 2,
    support: 3.0,
};
const APIC: Transfer = Transfer::Apic;
const PIC: Transfer = Transfer::PicFlip { flip: 0.0 };
const FRICTION: (&str, Wall) = ("friction", Wall::Friction(0.3));
const SLIP: (&str, Wall) = ("slip", Wall::Slip);
const FIXED: (&str, Wall) = ("fixed", Wall::Fixed);

/// Issue target: a mirror-symmetric drop stays symmetric with VC, to round-off, 2D: every
/// method on a friction floor, and the linear fit on a slip floor too (the fast variant; every
/// floor for every VC1 method is `vc_keeps_a_dropped_block_mirror_symmetric_on_every_floor`).
///
/// Without VC the mismatch is the round-off of the fall and the impact: 7.1e-15 measured in
/// 2D. VC of order 1 adds nothing measurable (5.9e-15 to 4.9e-14, every floor). The drops solve
/// VC exactly (`VcSolve::EXACT`, the default at order 1); at 1e-4 VC1 keeps the same figures (its
/// node-block preconditioner is mirror symmetric on this grid) and so does RK2 + VC2 on the
/// friction floor (5.5e-13), whose V-cycle's aggregates are mirror symmetric (3.5e-6 when they
/// were pairs counted from one end). RK2 + VC2 keeps 2.5e-14 with the exact solve (8.4e-13 with
/// pairs from one end; 9.3e-11 once VC's equalities took the transfer weights as their test
/// function, until the edge damping had its floor); its bound is the target, 1e-12, the others about 10 times what
/// is measured. Slip and fixed floors: `vc2_mirror_symmetry_on_slip_and_fixed_floors`. The
/// mismatch was 5e-2 when RK2's edge
/// lumping weighted the correction with the transfer weights instead of Ψ.
#[test]
fn vc_keeps_a_dropped_block_mirror_symmetric_2d() {
    let vc1 = Some(1);
    let failed = mirror_failures::<2>(&[
        (
            "B-spline 2",
            Shape::BSpline2,
            None,
            APIC,
            FRICTION,
            1e-13,
            false,
        ),
        (
            "B-spline 2 + VC1",
            Shape::BSpline2,
            vc1,
            APIC,
            FRICTION,
            1e-13,
            false,
        ),
        (
            "B-spline 3 + VC1",
            Shape::BSpline3,
            vc1,
            APIC,
            FRICTION,
            1e-13,
            false,
        ),
        ("RK1 + VC1", RK1, vc1, APIC, FRICTION, 1e-13, false),
        ("RK2", RK2, None, PIC, FRICTION, 1e-13, false),
        ("RK2 + VC2", RK2, Some(2), PIC, FRICTION, 1e-12, false),
        (
            "B-spline 3 + VC1",
            Shape::BSpline3,
            vc1,
            APIC,
            SLIP,
            1e-13,
            true,
        ),
        ("RK1 + VC1", RK1, vc1, APIC, SLIP, 1e-13, true),
    ]);
    assert!(failed.is_empty(), "{failed:?}");
}

/// The same in 3D with VC of order 1: RK1 with the mean fit on a friction floor, with the
/// linear fit on a slip floor (8.3e-15 to 1.1e-14 measured, every floor, both fits). Before the
/// order-1 solve was projected off `K`'s null space, its iterates drifted along the linear
/// fields to 1e10 at nodes the particles barely reach, and the linear fit's drop onto a slip
/// floor ended 3.6e-3 (RK1) and 4.8e-3 (B-spline 3) off symmetry. 3D RK2 + VC2 is left out:
/// its system (`7^3`-node stencils, blocks of `4 × 4`) is above the assembly's size limit on
/// this grid, and the matrix-free solve took more than 20 minutes for the 0.4 s of the drop; a
/// smaller drop is `vc2_3d_mirror_symmetry_of_a_small_drop`.
#[test]
fn vc_keeps_a_dropped_block_mirror_symmetric_3d() {
    let failed = mirror_failures::<3>(&[
        ("RK1 + VC1", RK1, Some(1), APIC, FRICTION, 1e-13, false),
        ("RK1 + VC1", RK1, Some(1), APIC, SLIP, 1e-13, true),
    ]);
    assert!(failed.is_empty(), "{failed:?}");
}

/// Every VC1 method on every floor with both fits, 2D and 3D (the long variant of the two
/// tests above).
#[test]
#[ignore = "long: every floor and fit; the test command runs the fast variants"]
fn vc_keeps_a_dropped_block_mirror_symmetric_on_every_floor() {
    let vc1 = Some(1);
    let mut cases2 = Vec::new();
    let mut cases3 = Vec::new();
    for floor in [FRICTION, SLIP, FIXED] {
        cases2.push((
            "B-spline 2 + VC1",
            Shape::BSpline2,
            vc1,
            APIC,
            floor,
            1e-13,
            false,
        ));
        for fit in [false, true] {
            for (name, shape) in [("B-spline 3 + VC1", Shape::BSpline3), ("RK1 + VC1", RK1)] {
                cases2.push((name, shape, vc1, APIC, floor, 1e-13, fit));
                cases3.push((name, shape, vc1, APIC, floor, 1e-13, fit));
            }
        }
    }
    let mut failed = mirror_failures::<2>(&cases2);
    failed.extend(mirror_failures::<3>(&cases3));
    assert!(failed.is_empty(), "{failed:?}");
}

/// 2D RK2 with and without VC2 dropped onto a slip or a fixed floor: 2.1e-14 and 1.8e-14 off
/// symmetry with VC2 (about 6 s each), 1.1e-14 and 1.8e-14 without. It was 1.2e-10 and 4.5e-10
/// with VC2 before the edge damping had a floor: at step 155 of the fall the ghost row below
/// the floor enters the lowest particles' support, its reach is tiny, so the edge damping
/// `ε A_I` damped nothing, and its coefficient came out at `2.6·10^11 / h` with round-off that
/// was not mirror symmetric. The damping of such a node is now at least `10^-4` of `ε` times
/// the largest reach (`VC_EDGE_DAMPING_FLOOR`), held in the assembled operator, so that the
/// V-cycle sees it (`docs/convergence/FINDINGS.md`). The bound is the target.
#[test]
fn vc2_mirror_symmetry_on_slip_and_fixed_floors() {
    let failed = mirror_failures::<2>(&[
        ("RK2", RK2, None, PIC, SLIP, 1e-13, false),
        ("RK2", RK2, None, PIC, FIXED, 1e-13, false),
        ("RK2 + VC2", RK2, Some(2), PIC, SLIP, 1e-12, false),
        ("RK2 + VC2", RK2, Some(2), PIC, FIXED, 1e-12, false),
    ]);
    assert!(failed.is_empty(), "{failed:?}");
}

/// 3D RK2 + VC2 on a small drop (8 cells, 8 particles across; its system on the study's
/// 16 cells is above the assembly's size limit and took over 20 minutes matrix-free): the
/// mismatch is 1.3e-15 after 42 steps (1.8e-15 with the solve stopped at 1e-4). It was 3.0e-10
/// when the V-cycle's aggregates were pairs counted from one end, from jumps at steps 30–36 at
/// particles on the block's outer x faces, far from the mirror plane, and 1.3e-9 before the
/// order-2 solve damped the body's edge nodes. Without VC the same drop keeps 2.2e-15, with VC1
/// 2.7e-15. The bound is the target.
#[test]
fn vc2_keeps_a_small_3d_drop_mirror_symmetric() {
    let rk2 = Shape::Rk {
        order: 2,
        support: 3.0,
    };
    let drop = Drop {
        cells: 8,
        half: 4,
        bottom: 0.02,
        duration: 0.042,
        wall: Wall::Friction(0.3),
        linear_fit: false,
    };
    let pic = Transfer::PicFlip { flip: 0.0 };
    let mismatch = mirror_mismatch_of_drop::<3>(rk2, Some(2), pic, drop);
    eprintln!("3D RK2 + VC2, small drop: mirror mismatch {mismatch:.2e}");
    assert!(
        mismatch < 1e-12,
        "3D RK2 + VC2: mirror mismatch {mismatch:e}"
    );
    let without = mirror_mismatch_of_drop::<3>(rk2, None, pic, drop);
    assert!(without < 1e-13, "3D RK2: mirror mismatch {without:e}");
}

/// A free block's relative drift of total angular momentum (the affine part included) over
/// `steps` steps, after the first (which gives the affine matrices: they start at zero).
fn angular_drift<const D: usize>(
    shape: Shape,
    order: u32,
    transfer: Transfer,
    linear_fit: bool,
    steps: usize,
) -> f64 {
    let mut sim = free_block::<D>(shape, order, transfer);
    sim.set_vc_linear_fit(linear_fit).unwrap();
    // A quarter of the stable step, as for linear momentum: VC2 lets this sheared block's
    // energy grow after about 0.4 s (2D), past the 1000 steps.
    let dt = 0.25 * sim.stable_dt(0.3).unwrap();
    sim.step(dt).unwrap();
    let (start, energy) = (sim.momenta().angular, sim.energies().total());
    for _ in 0..steps {
        if let Err(e) = sim.step(dt) {
            eprintln!("{e}");
            return f64::NAN;
        }
    }
    let end = sim.energies().total();
    eprintln!("  total energy {energy:.4e} -> {end:.4e}");
    (sim.momenta().angular - start).norm() / start.norm()
}

/// Every smooth shape under APIC with VC of the `orders` given (RK2 + VC2 runs with PIC,
/// which does not conserve angular momentum: its linear momentum is checked above). Linear
/// hats are not here: cell crossing inverts this sheared block (see `methods`).
fn apic_methods(orders: &[u32]) -> Vec<(String, Shape, u32)> {
    let rk1 = Shape::Rk {
        order: 1,
        support: 2.0,
    };
    let shapes = [
        ("B-spline 2", Shape::BSpline2),
        ("B-spline 3", Shape::BSpline3),
        ("RK1", rk1),
    ];
    let mut methods = Vec::new();
    for &order in orders {
        for (name, shape) in shapes {
            methods.push((format!("{name} + VC{order}"), shape, order));
        }
    }
    methods
}

/// Issue target: with VC and a transfer that conserves angular momentum (APIC), a free body's
/// total angular momentum stays what it was to round-off: the internal forces lose the rigid
/// rotation that carries their torque, per body (`src/step/vc_torque.rs`). Before, the
/// correction's first moment let a symmetric stress turn the block: 8.4e-5 to 1.1e-4 of its
/// angular momentum over these 1000 steps in 2D with VC1. Without VC, APIC keeps it to 2e-14
/// (`apic_and_mls_conserve_angular_momentum_with_the_affine_part`).
fn conserves_angular_momentum<const D: usize>(steps: usize, orders: &[u32]) -> Vec<String> {
    let mut failed = Vec::new();
    for (name, shape, order) in apic_methods(orders) {
        let drift = angular_drift::<D>(shape, order, Transfer::Apic, false, steps);
        eprintln!("{D}D {name}, {steps} steps: angular momentum drift {drift:.2e}");
        if drift.is_nan() || drift > 1e-12 {
            failed.push(format!("{D}D {name}: {drift:.1e}"));
        }
    }
    failed
}

/// Measured VC1 1.8e-14 (B-spline 2), 1.6e-13 (B-spline 3), 1.7e-13 (RK1); VC2 1.8e-14,
/// 1.7e-13, 1.7e-13. VC2 leaked linear momentum at a few steps (drift 5.8e-5 and 2.5e-6 with
/// the cubic B-spline and RK1) until its solve damped the body's edge nodes
/// (`VC_REGULARISATION` in `src/integration/mod.rs`).
#[test]
fn vc_conserves_angular_momentum_2d() {
    let failed = conserves_angular_momentum::<2>(1000, &[1, 2]);
    assert!(failed.is_empty(), "{failed:?}");
}

/// Measured over 200 steps: VC1 3.7e-15, 4.7e-14, 4.8e-14; VC2 3.0e-15, 4.1e-13, 1.2e-13
/// (B-spline 2, B-spline 3, RK1). The test command runs VC2 over 50 steps (a tenth of a second
/// a step); the 200 are the ignored test below.
#[test]
fn vc_conserves_angular_momentum_3d() {
    let mut failed = conserves_angular_momentum::<3>(200, &[1]);
    failed.extend(conserves_angular_momentum::<3>(50, &[2]));
    assert!(failed.is_empty(), "{failed:?}");
}

/// VC2 over the 200 steps of the target (`cargo test --release --test engine
/// vc_conservation:: -- --ignored`).
#[test]
#[ignore = "long: 3D VC2 over 200 steps; the test command runs 50"]
fn vc2_conserves_angular_momentum_3d_over_200_steps() {
    let failed = conserves_angular_momentum::<3>(200, &[2]);
    assert!(failed.is_empty(), "{failed:?}");
}

/// The linear fit (`Sim::set_vc_linear_fit`) makes each particle's correction torque-free on
/// its own, for the shapes that allow it (`Shape::vc_linear_fit`): angular momentum to
/// round-off as well. Measured 1.7e-14 (2D) and 2.5e-14 (3D) over 100 steps of a quarter of
/// the stable time step.
#[test]
fn vc_with_the_linear_fit_conserves_angular_momentum() {
    let rk1 = Shape::Rk {
        order: 1,
        support: 2.0,
    };
    let mut failed = Vec::new();
    for (name, shape) in [("B-spline 3 + VC1", Shape::BSpline3), ("RK1 + VC1", rk1)] {
        assert!(shape.vc_linear_fit(), "{name}");
        let (d2, d3) = (
            angular_drift::<2>(shape, 1, Transfer::Apic, true, 100),
            angular_drift::<3>(shape, 1, Transfer::Apic, true, 100),
        );
        eprintln!("{name}: 2D {d2:.2e}, 3D {d3:.2e}");
        if d2.max(d3) > 1e-12 {
            failed.push(format!("{name}: 2D {d2:.1e}, 3D {d3:.1e}"));
        }
    }
    assert!(failed.is_empty(), "{failed:?}");
}

/// The linear fit on two bodies that approach and collide (one node field, RK1 + VC1, APIC, the
/// default scene's disks on a coarser grid): the total energy never rises above its start. Where
/// the two bodies' supports first meet, nodes that each body barely reaches join them into one
/// body of `K`'s null space, and the right-hand side's part along each body's own linear fields
/// (the surface and the particles disagreeing on their divergence theorem) was left in along a
/// near-null direction: the solve amplified it, and the disks gained energy from 2.54 to
/// 16.5 J/m (40 × 40 cells) and inverted a particle. Nodes reached below 1 % of the largest
/// reach join no body now (`WEAK_REACH`). Measured here: the largest total energy over the 2 s
/// is its start, 2.600 J/m, and it ends at 1.835 J/m (179 steps); before, step 52 (t = 0.50 s,
/// as the supports met) inverted a particle.
#[test]
fn vc_with_the_linear_fit_loses_energy_as_colliding_disks_meet() {
    let cells = 20;
    let h = 1.0 / cells as f64;
    let mut sim = Sim::<2>::new(V::<2>::zeros(), [cells, cells], h).unwrap();
    sim.set_shape(Shape::Rk {
        order: 1,
        support: 2.0,
    })
    .unwrap();
    sim.set_transfer(Transfer::Apic).unwrap();
    sim.set_integration(Integration::Vc { order: 1 }).unwrap();
    sim.set_vc_linear_fit(true).unwrap();
    let rubber = sim.add_material(Material::neo_hookean(1000.0, 1000.0, 0.3).unwrap());
    let s = h / 2.0;
    for (centre, velocity) in [(0.25, 0.1), (0.75, -0.1)] {
        let (mut x, mut vol) = (Vec::new(), Vec::new());
        for i in 0..2 * cells {
            for j in 0..2 * cells {
                let p = V::<2>::new((i as f64 + 0.5) * s, (j as f64 + 0.5) * s);
                if (p - V::<2>::new(centre, centre)).norm() <= 0.2 {
                    x.push(p);
                    vol.push(s * s);
                }
            }
        }
        let v = vec![V::<2>::new(velocity, velocity); x.len()];
        sim.add_particles(rubber, &x, &vol, Some(&v)).unwrap();
    }
    let start = sim.energies().total();
    let mut highest = start;
    while sim.time() < 2.0 {
        let dt = sim.stable_dt(0.3).unwrap();
        sim.step(dt).unwrap();
        highest = highest.max(sim.energies().total());
    }
    let end = sim.energies().total();
    eprintln!(
        "energy {start:.4e} -> {end:.4e}, highest {highest:.4e} ({} steps)",
        sim.steps()
    );
    // Round-off of the sums only (the stored energy starts at zero).
    assert!(highest <= start * (1.0 + 1e-9), "{highest:e} > {start:e}");
    assert!(end < start);
}

/// Conservation does not rest on the solve: the corrected gradients sum to zero over each
/// particle's nodes for any coefficients, and the torque is removed per body after the solve.
/// With the loosest rule (a residual of 1e-2 of the right-hand side's, at most two
/// iterations, a solve every eighth step and the coefficients carried between) the free block keeps its linear momentum (every method) and, under APIC, its
/// angular momentum to round-off, as the exact solve does: measured over 300 steps, linear
/// 3.5e-16 to 4.6e-14, angular 6.1e-15 to 5.2e-14 (VC1 and VC2; VC2 solves at every step).
#[test]
fn a_loose_vc_solve_still_conserves_momentum() {
    let loose = VcSolve {
        tolerance: 1e-2,
        max_iterations: 2,
        interval: 8,
    };
    let mut cases: Vec<(String, Shape, u32, Transfer)> = methods()
        .into_iter()
        .map(|(name, shape, order, transfer)| (name.to_string(), shape, order, transfer))
        .collect();
    for (name, shape, order) in apic_methods(&[2]) {
        cases.push((name, shape, order, Transfer::Apic));
    }
    let mut failed = Vec::new();
    for (name, shape, order, transfer) in cases {
        let mut sim = free_block::<2>(shape, order, transfer);
        sim.set_vc_solve(loose).unwrap();
        let dt = 0.25 * sim.stable_dt(0.3).unwrap();
        sim.step(dt).unwrap();
        let ((p0, scale), l0) = (momentum(&sim), sim.momenta().angular);
        for _ in 0..300 {
            sim.step(dt).unwrap();
        }
        let linear = (momentum(&sim).0 - p0).norm() / scale;
        let angular = (sim.momenta().angular - l0).norm() / l0.norm();
        eprintln!("{name}: linear drift {linear:.2e}, angular {angular:.2e}");
        if linear.is_nan() || linear > 1e-12 {
            failed.push(format!("{name}: linear {linear:e}"));
        }
        if transfer == Transfer::Apic && (angular.is_nan() || angular > 1e-12) {
            failed.push(format!("{name}: angular {angular:e}"));
        }
    }
    assert!(failed.is_empty(), "{failed:?}");
}

/// The rule is checked: a tolerance outside (0, 1], zero iterations or an interval of zero steps
/// is refused with an invalid-argument error, and the rule in force stays.
#[test]
fn the_vc_solve_rule_is_checked() {
    let mut sim = free_block::<2>(Shape::BSpline2, 1, Transfer::Apic);
    // The automatic rule of the quadratic B-spline at order 1.
    let automatic = VcSolve {
        interval: VcSolve::BSPLINE_INTERVAL,
        ..VcSolve::default()
    };
    assert_eq!(sim.vc_solve(), automatic);
    let rule = VcSolve {
        tolerance: 1e-4,
        max_iterations: 7,
        interval: 3,
    };
    sim.set_vc_solve(rule).unwrap();
    for (tolerance, max_iterations, interval) in [
        (0.0, 10, 1),
        (f64::NAN, 10, 1),
        (2.0, 10, 1),
        (1e-6, 0, 1),
        (1e-6, 10, 0),
    ] {
        let e = sim
            .set_vc_solve(VcSolve {
                tolerance,
                max_iterations,
                interval,
            })
            .unwrap_err();
        assert_eq!(e.kind, rkmpm::ErrorKind::InvalidArgument, "{e}");
        assert_eq!(sim.vc_solve(), rule);
    }
}
