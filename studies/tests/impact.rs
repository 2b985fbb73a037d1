//! Fast checks of the metal impact scenes (Johnson–Cook). The full studies are
//! `cargo run --release --example taylor_bar`.

use rkmpm_studies::scenes::{TaylorBar, TaylorCase};

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

/// The same bar with RK1 (ã = 2) and first-order VC, whose surface is found from the particles
/// at every step (the rod's faces on the symmetry planes included). Measured at 4 cells:
/// length 21.94 mm (+2.4%), foot radius 6.38 mm (−10.4%); RK1 without VC +1.8% / −9.9%. RK1
/// with ã = 2 is the cubic B-spline, whose wider support rounds the foot more at this coarse
/// grid (`docs/validation/taylor/methods.md` has 6 and 8 cells). Asserted: 3% on the length,
/// 12% on the radius, the rod stopped and yielded.
#[test]
fn coarse_taylor_bar_with_rk_and_vc() {
    use rkmpm::sim::Integration;
    use rkmpm::Shape;
    let r = TaylorBar {
        case: TaylorCase::Bilinear,
        cells_per_radius: 4,
        shape: Shape::Rk {
            order: 1,
            support: 2.0,
        },
        integration: Integration::Vc { order: 1 },
        ..Default::default()
    }
    .run()
    .unwrap();
    eprintln!("{r:?}");
    assert!((r.final_length / r.reference_length - 1.0).abs() < 0.03);
    assert!((r.foot_radius / r.reference_radius - 1.0).abs() < 0.12);
    assert!(r.kinetic_left < 0.01, "still moving: {}", r.kinetic_left);
    assert!(r.max_plastic_strain > 1.0);
}

/// Plane-strain penetration at 6 cells through the plate (1160 particles, a few seconds):
/// measured: 150 m/s stops (rebound −11 m/s, 12 failed plate particles), 350 m/s perforates
/// (residual 172 m/s). At this size both tear the 60 mm strip off its clamp (the plate cut off
/// is 3 times the mass under the projectile: all of it) rather than shear out a plug; the slow
/// projectile still rebounds off the torn strip. Asserted: the slow shot does not perforate and the fast one
/// does with a residual speed between zero and the impact speed, and plate material was cut
/// off from the clamp; damage stays in [0, 1] and some plate particles fail; mass is carried
/// by the particles unchanged.
#[test]
fn plane_strain_penetration_perforates_fast_and_stops_slow() {
    use rkmpm_studies::scenes::Penetration;
    for (v, through) in [(150.0, false), (350.0, true)] {
        let scene = Penetration {
            impact_speed: v,
            cells_through_plate: 6,
            ..Default::default()
        };
        let mass0: f64 = scene.build::<2>().unwrap().particles().mass().iter().sum();
        let (r, sim) = scene.run_observed::<2>(0, |_| Ok(())).unwrap();
        eprintln!("{r:?}");
        assert_eq!(r.perforated, through, "{v} m/s");
        if through {
            assert!(r.residual_speed > 0.0 && r.residual_speed < v);
            assert!(r.separated_mass > 1.0, "{r:?}");
        }
        assert!(r.max_damage <= 1.0 && r.failed_particles > 0);
        let ps = sim.particles();
        assert!(ps.history().iter().all(|s| (0.0..=1.0).contains(&s.damage)));
        assert_eq!(ps.mass().iter().sum::<f64>(), mass0);
    }
}

/// The crack-band regularized damage (`Penetration::failure_band`) on the same coarse plate:
/// with the strains to failure scaled by 0.375 mm / 2 mm the plate fails in a band at the
/// projectile's edge and a plug shears out, instead of the strip tearing off its clamp.
/// Measured at 300 m/s: perforated at 172 µs, residual 222 m/s, plate cut off 1.83 times the
/// mass under the projectile (the plug and its band, a cell wide on each side), 128 failed
/// particles. Asserted: perforated, the plate cut off from the clamp is a plug (between 0.8 and
/// 2.5 times the mass under the projectile; the whole strip would be 3), the residual speed
/// lies between zero and the impact speed, and damage stays in [0, 1].
#[test]
fn regularized_damage_shears_out_a_plug_on_coarse_cells() {
    use rkmpm_studies::scenes::Penetration;
    let scene = Penetration {
        impact_speed: 300.0,
        cells_through_plate: 6,
        failure_band: Some(0.375e-3),
        ..Default::default()
    };
    let (r, sim) = scene.run_observed::<2>(0, |_| Ok(())).unwrap();
    eprintln!("{r:?}");
    assert!(r.perforated, "{r:?}");
    assert!((0.8..2.5).contains(&r.separated_mass), "{r:?}");
    assert!(r.residual_speed > 0.0 && r.residual_speed < 300.0, "{r:?}");
    let ps = sim.particles();
    assert!(ps.history().iter().all(|s| (0.0..=1.0).contains(&s.damage)));
}
