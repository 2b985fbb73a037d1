//! Fast checks of the metal impact scenes (Johnson–Cook). The full studies are
//! `cargo run --release --example taylor_bar`.

use rkmpm::scenes::{TaylorBar, TaylorCase};

/// Taylor bar (Simo's bilinear copper, 227 m/s, 80 µs) at 4 cells across the radius, 4212
/// particles in one quarter. Measured: final length 21.72 mm against 21.42 mm (+1.4%), foot
/// radius 6.63 mm against 7.12 mm (−6.8%); at 6 cells +0.4% and −4.0%. Asserted: the 3%
/// on the length, and 8% on the radius at this coarse grid (the 5% target holds from 6 cells, in
/// `docs/validation/taylor`); the rod has stopped (kinetic energy below 1% of the initial) and
/// has flowed plastically.
#[test]
fn coarse_taylor_bar_matches_the_reference_shape() {
    let r = TaylorBar {
        case: TaylorCase::Bilinear,
        cells_per_radius: 4,
        ..Default::default()
    }
    .run()
    .unwrap();
    eprintln!("{r:?}");
    assert!(
        (r.final_length / r.reference_length - 1.0).abs() < 0.03,
        "length {} against {}",
        r.final_length,
        r.reference_length
    );
    assert!(
        (r.foot_radius / r.reference_radius - 1.0).abs() < 0.08,
        "radius {} against {}",
        r.foot_radius,
        r.reference_radius
    );
    assert!(r.kinetic_left < 0.01, "still moving: {}", r.kinetic_left);
    assert!(r.max_plastic_strain > 1.0);
}
