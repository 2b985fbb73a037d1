//! METHOD.md 6.5, the vibrating bar, against its exact solution: the period and the mean-velocity
//! history, with both schemes and the APIC and MLS transfers, in 2D and 3D.

use rkmpm::{Scheme, Transfer};
use rkmpm_studies::scenes::{run_vibrating_bar, VibratingBar};

fn check_bar<const D: usize>(scheme: Scheme, transfer: Transfer) {
    let bar = VibratingBar::default();
    let mut sim = bar.build::<D>().unwrap();
    sim.set_scheme(scheme).unwrap();
    sim.set_transfer(transfer).unwrap();
    let r = run_vibrating_bar(&bar, &mut sim, 0.2).unwrap();
    let period_error = (r.period - r.exact_period).abs() / r.exact_period;
    eprintln!(
        "{D}D {scheme:?} {transfer:?}: velocity error {:.4}, period error {period_error:.5}",
        r.velocity_error
    );
    assert!(
        period_error < 0.01,
        "{D}D: period {} vs {}",
        r.period,
        r.exact_period
    );
    assert!(
        r.velocity_error < 0.03,
        "{D}D: velocity error {}",
        r.velocity_error
    );
}

/// METHOD.md 6.5 at 32 cells along the bar with the quadratic B-spline: period within 1% and the
/// mean-velocity history within 3% of the exact one over a whole period, with APIC and MLS.
#[test]
fn vibrating_bar_2d_matches_exact_solution() {
    for transfer in [Transfer::Apic, Transfer::Mls] {
        check_bar::<2>(Scheme::Usl, transfer);
        check_bar::<2>(Scheme::Musl, transfer);
    }
}

#[test]
fn vibrating_bar_3d_matches_exact_solution() {
    check_bar::<3>(Scheme::Usl, Transfer::Apic);
    check_bar::<3>(Scheme::Usl, Transfer::Mls);
}
