//! Key figures of the convergence study (`cargo run --release --example convergence`) as tests:
//! fitted slopes over three refinements of the 2D manufactured solution. Run in release mode
//! (`cargo test --release`, as the README's test command does); in debug they take minutes.

use rkmpm::{Integration, Shape, Transfer};
use rkmpm_studies::verification::{
    fitted_slope, run_mms, run_mms_placed, AxisAlignedMms, Errors, MmsWalls, Placement, Surface,
};

/// The errors of the manufactured solution (APIC, found surface, 2 particles per cell per
/// direction) with the particles placed as `placement` says, between `walls`.
fn placed(
    cells: usize,
    placement: Placement,
    walls: MmsWalls,
    shape: Shape,
    integration: Integration,
) -> Errors {
    run_mms_placed::<2>(
        &AxisAlignedMms {
            walls,
            ..AxisAlignedMms::default()
        },
        cells,
        2,
        placement,
        Surface::Found,
        shape,
        integration,
        Transfer::Apic,
        0.015,
        0.3,
    )
    .unwrap()
    .errors
}

fn slopes(
    shape: Shape,
    integration: Integration,
    transfer: Transfer,
    grids: &[usize],
) -> (f64, f64, Vec<f64>) {
    let mms = AxisAlignedMms::default();
    let runs: Vec<_> = grids
        .iter()
        .map(|&c| run_mms::<2>(&mms, c, shape, integration, transfer, 0.015, 0.3).unwrap())
        .collect();
    let h: Vec<f64> = grids.iter().map(|&c| 1.0 / c as f64).collect();
    let l2: Vec<f64> = runs.iter().map(|r| r.errors.l2).collect();
    let en: Vec<f64> = runs.iter().map(|r| r.errors.energy).collect();
    (fitted_slope(&h, &l2), fitted_slope(&h, &en), l2)
}

/// Issue target: RK n = 1 with VC, L2 slope ≥ 1.8 and energy slope ≥ 0.9 (measured 1.89 / 1.89).
#[test]
fn rk1_with_vc_converges_at_second_order() {
    let (l2, energy, _) = slopes(
        Shape::Rk {
            order: 1,
            support: 2.0,
        },
        Integration::Vc { order: 1 },
        Transfer::Apic,
        &[8, 16, 32],
    );
    eprintln!("RK1 + VC1: L2 slope {l2:.2}, energy slope {energy:.2}");
    assert!(l2 >= 1.8, "L2 slope {l2}");
    assert!(energy >= 0.9, "energy slope {energy}");
}

/// RK n = 2 with order-2 VC and PIC: the target is an L2 slope ≥ 2.7 and an energy slope
/// ≥ 1.8; this build measures 2.50 / 2.02 over 8, 16, 24 cells (PIC's per-step smoothing
/// limits it, see docs/convergence). The test guards what is reached — slopes above 2.3 and 1.6,
/// and VC2 beating material-point integration at the finest grid — not the target.
#[test]
fn rk2_with_vc2_converges_faster_than_second_order() {
    let pic = Transfer::PicFlip { flip: 0.0 };
    let rk2 = Shape::Rk {
        order: 2,
        support: 3.0,
    };
    let grids = [8, 16, 24];
    let (l2, energy, vc_errors) = slopes(rk2, Integration::Vc { order: 2 }, pic, &grids);
    eprintln!("RK2 + VC2: L2 slope {l2:.2}, energy slope {energy:.2}");
    assert!(l2 >= 2.3, "L2 slope {l2}");
    assert!(energy >= 1.6, "energy slope {energy}");
    let mms = AxisAlignedMms::default();
    let mp = run_mms::<2>(&mms, 24, rk2, Integration::MaterialPoint, pic, 0.015, 0.3).unwrap();
    assert!(
        vc_errors[2] < mp.errors.l2,
        "VC2 {} vs MP {}",
        vc_errors[2],
        mp.errors.l2
    );
}

/// Standard MPM (linear hats) does not converge on this problem: cell crossing.
#[test]
fn linear_hats_do_not_converge() {
    let (l2, _, _) = slopes(
        Shape::Linear,
        Integration::MaterialPoint,
        Transfer::Apic,
        &[8, 16, 24],
    );
    eprintln!("linear: L2 slope {l2:.2}");
    assert!(l2 < 1.0, "linear hats converged with slope {l2}");
}

/// Issue target: column under its own weight, σ_yy error of RK + VC at least ten times smaller
/// than standard MPM's. At 16 cells over the height: linear hats 2.0e-1 (cell crossing),
/// RK1 + VC1 1.1e-2; at 32 cells linear hats invert a particle and stop.
#[test]
fn column_under_self_weight_rk_vc_beats_standard_mpm_tenfold() {
    use rkmpm_studies::verification::SelfWeightColumn;
    let col = SelfWeightColumn::default();
    let pic = Transfer::PicFlip { flip: 0.0 };
    let linear = col
        .run(16, Shape::Linear, Integration::MaterialPoint, pic)
        .unwrap();
    let rk_vc = col
        .run(
            16,
            Shape::Rk {
                order: 1,
                support: 2.0,
            },
            Integration::Vc { order: 1 },
            pic,
        )
        .unwrap();
    eprintln!(
        "column: linear {:.3e}, RK1 + VC1 {:.3e}",
        linear.stress_error, rk_vc.stress_error
    );
    assert!(rk_vc.stress_error * 10.0 <= linear.stress_error);
    assert!(rk_vc.stress_error < 0.02);
}

/// The column with the surface VC finds from the particles instead of the lattice's faces:
/// found at every step and found every fourth step, carried by the grid between (the default,
/// `Sim::set_vc_surface_refresh`). RK1 + VC1 at 16 cells: σ_yy error 6.516e-3 and 6.514e-3
/// (lattice faces 7.0e-3); RK2 + VC2 1.111e-2 and 1.082e-2 (refreshes of 2 and 8: 1.124e-2 and
/// 1.070e-2), within 3 % of each other, under the 2e-2 of the tests above.
#[test]
fn column_with_a_carried_surface_keeps_its_error() {
    use rkmpm_studies::verification::SelfWeightColumn;
    let rk = |order| Shape::Rk {
        order,
        support: order as f64 + 1.0,
    };
    for (order, spread) in [(1, 0.01), (2, 0.05)] {
        let error = |refresh| {
            let column = SelfWeightColumn {
                found_surface: Some(refresh),
                ..SelfWeightColumn::default()
            };
            let run = column
                .run(
                    16,
                    rk(order),
                    Integration::Vc { order },
                    Transfer::PicFlip { flip: 0.0 },
                )
                .unwrap();
            run.stress_error
        };
        let (every, carried) = (error(1), error(4));
        eprintln!("column RK{order} + VC{order}, found surface: every step {every:.3e}, every fourth {carried:.3e}");
        assert!(every < 0.02 && carried < 0.02);
        assert!(
            (carried / every - 1.0).abs() < spread,
            "{every:e} / {carried:e}"
        );
    }
}

/// RK2 with a free surface: the lumped mass `Σ m_p Ψ_I` of the nodes above the column is
/// negative or tiny, and before the edge-node lumping the step diverged there. With it, RK2 + VC2
/// runs the column to the end; with VC's equalities taking the transfer weights `Φ` as their test
/// function (those that weigh the body force), its σ_yy error at 16 cells is 6.7e-3 (3.76e-2 with
/// `Ψ` there: a load of the order of `ρ g h` on the top rows; RK2 without VC 5.69e-2). The bound
/// is the 2e-2 that RK1 + VC1 is held to (7.0e-3 measured).
#[test]
fn column_with_free_surface_runs_with_rk2_vc2() {
    use rkmpm_studies::verification::SelfWeightColumn;
    let run = SelfWeightColumn::default()
        .run(
            16,
            Shape::Rk {
                order: 2,
                support: 3.0,
            },
            Integration::Vc { order: 2 },
            Transfer::PicFlip { flip: 0.0 },
        )
        .unwrap();
    eprintln!(
        "column RK2 + VC2, 16 cells: σ_yy error {:.3e}",
        run.stress_error
    );
    assert!(run.stress_error < 0.02);
}

/// The RK2 + VC2 column (16 cells) at t = 1.9646 s, saved just before the step where the
/// conservative correction's conjugate-gradient solve breaks down near the free surface (the
/// system is badly conditioned there). The solve used to return its last iterate, whose residual
/// was 190 times the right-hand side's, with coefficients up to 8e9 / h: a particle inside the
/// body jumped from rest to 2.75 m/s. It now restarts from its best iterate and returns the
/// iterate of smallest residual (2.9e-2 m/s after this step; 7.5e-3 since VC's equalities take
/// the transfer weights as their test function, from 8.7e-3 before it). The bound is the fastest the
/// column moves in the whole run: its top follows the static solution at
/// `ρ g H² / (2 M T_ramp)` = 1.86e-2 m/s (M = 1.35e5 Pa the constrained modulus, 2 s of ramp),
/// and the oscillation the ramp starts doubles that, 3.7e-2 m/s (measured 3.77e-2).
#[test]
fn vc2_solve_survives_a_breakdown_near_the_free_surface() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/column_rk2_vc2_step1350.ckpt"
    );
    let mut sim = rkmpm::Sim::<2>::from_checkpoint_bytes(&std::fs::read(path).unwrap()).unwrap();
    let fastest = |sim: &rkmpm::Sim<2>| {
        let ps = sim.particles();
        ps.velocity().iter().map(|v| v.norm()).fold(0.0, f64::max)
    };
    let before = fastest(&sim);
    // The step of the original run, to the bit.
    let dt = f64::from_bits(0x3f57d353c2f2795c);
    sim.step(dt).unwrap();
    let after = fastest(&sim);
    eprintln!("largest speed {before:.3e} -> {after:.3e} m/s");
    assert!(before < 1e-2, "{before}");
    assert!(after < 3.8e-2, "{after}");
}

/// Issue target: pressure oscillation amplitude with VC at least five times smaller than without.
/// Nearly incompressible column (ν = 0.49), particles jittered by ±30% of their spacing, 16 cells:
/// RK1 1.24e-1, RK1 + VC1 1.83e-2 (6.8×).
#[test]
fn vc_cuts_the_pressure_oscillation_fivefold() {
    use rkmpm_studies::verification::SelfWeightColumn;
    let col = SelfWeightColumn {
        poisson: 0.49,
        jitter: 0.3,
        ..Default::default()
    };
    let pic = Transfer::PicFlip { flip: 0.0 };
    let rk1 = Shape::Rk {
        order: 1,
        support: 2.0,
    };
    let mp = col.run(16, rk1, Integration::MaterialPoint, pic).unwrap();
    let vc = col.run(16, rk1, Integration::Vc { order: 1 }, pic).unwrap();
    eprintln!(
        "pressure error: RK1 {:.3e}, RK1 + VC1 {:.3e}",
        mp.pressure_error, vc.pressure_error
    );
    assert!(vc.pressure_error * 5.0 <= mp.pressure_error);
}

/// The exact pressure of the column solves the uniaxial-strain neo-Hookean equations: at the top
/// it is zero, at the bottom it lies between the vertical stress and the incompressible limit.
#[test]
fn column_exact_pressure_is_consistent() {
    use rkmpm_studies::verification::SelfWeightColumn;
    let col = SelfWeightColumn {
        poisson: 0.49,
        ..Default::default()
    };
    assert!(col.exact_pressure(col.height).abs() < 1e-9);
    let p0 = col.exact_pressure(0.0);
    let weight = col.density * col.gravity * col.height;
    // Lateral stress ≈ ν/(1−ν) of the vertical one in the small-strain limit: p ≈ 0.99 ρgH.
    assert!(p0 > 0.95 * weight && p0 < weight, "{p0} vs {weight}");
}

/// The quadratic B-spline with MLS (Hu et al. 2018) converges on the manufactured solution, but
/// at about first order where APIC with the true gradient reaches second: the MLS gradient
/// `M⁻¹ Ψ_I (x_I − x_p)` is exact for linear fields only, while the quadratic B-spline's own
/// gradient also differentiates quadratics exactly (`Σ x_I² Ψ_I = x² + h²/4`). Measured L2 errors
/// at 8, 16, 32 cells: APIC 4.71e-2, 4.99e-3, 2.40e-3 (slope 2.15); MLS 1.49e-2, 1.14e-2,
/// 4.11e-3 (slope 0.93), 1.7× APIC's at 32 cells (at 64 and 128 cells 2.4× and 3.0×). The test
/// guards those figures with margins: MLS slope above 0.8, APIC's above 2, MLS within 2× APIC
/// at 32 cells.
#[test]
fn bspline2_with_mls_converges_at_first_order() {
    let grids = [8, 16, 32];
    let (apic, _, apic_errors) = slopes(
        Shape::BSpline2,
        Integration::MaterialPoint,
        Transfer::Apic,
        &grids,
    );
    let (mls, _, mls_errors) = slopes(
        Shape::BSpline2,
        Integration::MaterialPoint,
        Transfer::Mls,
        &grids,
    );
    eprintln!(
        "quadratic B-spline L2 slope: APIC {apic:.2}, MLS {mls:.2}; errors APIC {apic_errors:?}, \
         MLS {mls_errors:?}"
    );
    assert!(apic >= 2.0, "APIC L2 slope {apic}");
    assert!(mls >= 0.8, "MLS L2 slope {mls}");
    assert!(
        mls_errors[2] < 2.0 * apic_errors[2],
        "MLS {} vs APIC {} at 32 cells",
        mls_errors[2],
        apic_errors[2]
    );
}

/// Issue target: on particles jittered by ±30 % of their spacing, RK1 + VC1 (found surface)
/// converges at L2 slope ≥ 1.5 while the cubic B-spline with material-point integration does not
/// converge in energy, between slip walls and between fixed (low) and slip (high) walls.
/// `mms_cases -- jitter:1 METHOD 8,16,32 [--mixed-walls]`, measured:
///
/// | walls | RK1 + VC1 L2 | its energy error | cubic B-spline energy error |
/// |---|---|---|---|
/// | slip | 7.08e-2, 1.22e-2, 4.48e-3 (slope 1.99) | 6.92e-2, 2.69e-2, 1.73e-2 | 1.03e-1, 7.85e-2, 8.51e-2 |
/// | fixed + slip | 9.22e-2, 1.83e-2, 4.96e-3 (slope 2.11) | 7.99e-2, 3.46e-2, 1.72e-2 | 1.03e-1, 7.58e-2, 7.95e-2 |
///
/// The B-spline's energy error grows from 16 cells on (at 64 and 128 cells its L2 error stalls
/// near 6e-3, see docs/convergence/FINDINGS.md). The energy bound (4×) leaves 20 % of the
/// smaller measured ratio (4.6× with the mixed walls, 4.9× with slip walls).
#[test]
fn rk1_vc1_converges_on_jittered_particles_where_the_bspline_does_not() {
    let jitter = Placement::Jittered {
        fraction: 0.3,
        seed: 1,
    };
    let rk1 = Shape::Rk {
        order: 1,
        support: 2.0,
    };
    let grids = [8, 16, 32];
    for walls in [MmsWalls::Slip, MmsWalls::FixedLowSlipHigh] {
        let run = |cells, shape, integration| placed(cells, jitter, walls, shape, integration);
        let vc: Vec<_> = grids
            .iter()
            .map(|&c| run(c, rk1, Integration::Vc { order: 1 }))
            .collect();
        let bspline: Vec<_> = grids
            .iter()
            .map(|&c| run(c, Shape::BSpline3, Integration::MaterialPoint))
            .collect();
        let h: Vec<f64> = grids.iter().map(|&c| 1.0 / c as f64).collect();
        let l2: Vec<f64> = vc.iter().map(|e| e.l2).collect();
        let slope = fitted_slope(&h, &l2);
        eprintln!(
            "jittered, {walls:?}: RK1 + VC1 L2 {l2:?} (slope {slope:.2}), energy {:?}; cubic B-spline energy {:?}",
            vc.iter().map(|e| e.energy).collect::<Vec<_>>(),
            bspline.iter().map(|e| e.energy).collect::<Vec<_>>()
        );
        assert!(slope >= 1.5, "{walls:?}: RK1 + VC1 L2 slope {slope}");
        assert!(
            bspline[2].energy >= bspline[1].energy,
            "{walls:?}: cubic B-spline energy error fell: {} -> {}",
            bspline[1].energy,
            bspline[2].energy
        );
        assert!(
            4.0 * vc[2].energy <= bspline[2].energy,
            "{walls:?}: RK1 + VC1 energy {} against the B-spline's {}",
            vc[2].energy,
            bspline[2].energy
        );
    }
}

/// Issue target: VC never worse than the same shape without VC by more than 10 %. Particles at
/// the quarter points of each cell (not the Gauss points), found surface: RK1 + VC1 against the
/// cubic B-spline (which RK1 with ã = 2 equals). Measured with `mms_cases -- uniform METHOD
/// 16,32,64,128 [--mixed-walls]`: slip walls, RK1 + VC1 1.064e-2, 3.653e-3, 9.499e-4, 2.392e-4;
/// cubic B-spline 1.09e-2, 3.67e-3, 9.51e-4, 2.41e-4. Fixed (low) and slip (high) walls, 16 to
/// 64 cells: RK1 + VC1 1.723e-2, 5.004e-3, 1.260e-3; cubic B-spline 1.735e-2, 4.999e-3,
/// 1.258e-3. Here 16 and 32 cells.
#[test]
fn rk1_vc1_is_no_worse_than_the_bspline_off_the_gauss_points() {
    let rk1 = Shape::Rk {
        order: 1,
        support: 2.0,
    };
    for walls in [MmsWalls::Slip, MmsWalls::FixedLowSlipHigh] {
        let run = |cells, shape, integration| {
            placed(cells, Placement::Uniform, walls, shape, integration).l2
        };
        for cells in [16, 32] {
            let vc = run(cells, rk1, Integration::Vc { order: 1 });
            let bspline = run(cells, Shape::BSpline3, Integration::MaterialPoint);
            eprintln!(
                "quarter points, {walls:?}, {cells} cells: RK1 + VC1 {vc:.4e}, cubic B-spline {bspline:.4e}"
            );
            assert!(
                vc <= 1.1 * bspline,
                "{walls:?}, {cells} cells: {vc} against {bspline}"
            );
        }
    }
}

/// The kinetic energy of a body settling under gravity on a fixed floor, as the largest value in
/// each half second of a 3 s hold (PIC, 8 cells over the height): the column between slip walls
/// and a free block 4 cells wide. An elastic body in equilibrium oscillates about it, so the
/// kinetic energy itself rises and falls within a period; what must not rise is its envelope.
fn settling_envelope(shape: Shape, order: u32, free_block: Option<usize>) -> Vec<f64> {
    use rkmpm_studies::verification::{window_maxima, SelfWeightColumn};
    let column = SelfWeightColumn {
        hold: 3.0,
        free_block,
        ..Default::default()
    };
    let mut kinetic = Vec::new();
    column
        .run_observed(
            8,
            shape,
            Integration::Vc { order },
            Transfer::PicFlip { flip: 0.0 },
            |_| Ok(()),
            |sim| kinetic.push((sim.time(), sim.energies().kinetic)),
        )
        .unwrap();
    // Full windows only: the last sample at t = 5 s opens a window of its own.
    let mut windows = window_maxima(&kinetic, column.ramp, 0.5);
    windows.truncate(6);
    windows
}

/// Issue target: a body settling under gravity keeps a kinetic energy that decays, never grows,
/// over a 3 s hold, with VC1 and VC2. Measured envelopes (J/m, first and last half-second maxima,
/// column; block): B-spline 2 + VC1 9.9e-3 → 6.4e-7; 5.9e-2 → 5.8e-7; RK1 + VC1 2.8e-2 → 1.4e-7;
/// 5.3e-2 → 4.1e-8; RK2 + VC2 5.5e-3 → 4.8e-3; 7.1e-2 → 6.4e-4, every step of the six down (the
/// example `cargo run --release --example settling -- --cells 8 [--block 4]` prints them from
/// 0.05 s later). Asserted: each half second's largest kinetic energy at most the one
/// before (a rise is an amplifying step: the explicit step's own error is far below the
/// 1e-3 relative margin, which only absorbs a flat envelope's round-off), and VC1's at the end
/// 1e-3 of its first (PIC damps it by 4 to 6 decades); RK2 + VC2 damps slowly (its stiffness
/// against the column's top mode is small, `docs/convergence/FINDINGS.md`), so it must only fall.
#[test]
fn settling_under_gravity_never_gains_kinetic_energy() {
    let rk = |order, support| Shape::Rk { order, support };
    let cases = [
        ("B-spline 2 + VC1", Shape::BSpline2, 1, 1e-3),
        ("RK1 + VC1", rk(1, 2.0), 1, 1e-3),
        ("RK2 + VC2", rk(2, 3.0), 2, 1.0),
    ];
    for (name, shape, order, fall) in cases {
        for block in [None, Some(4)] {
            let e = settling_envelope(shape, order, block);
            eprintln!("{name}, block {block:?}: {e:?}");
            assert_eq!(e.len(), 6, "{name}");
            for w in e.windows(2) {
                assert!(
                    w[1] <= w[0] * (1.0 + 1e-3),
                    "{name}, block {block:?}: {e:?}"
                );
            }
            assert!(e[5] <= fall * e[0], "{name}, block {block:?}: {e:?}");
        }
    }
}
