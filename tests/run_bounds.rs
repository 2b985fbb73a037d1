//! Nothing a caller passes can hang the host: materials outside any physical range
//! are refused when they are made, each with its reason, and an adaptive run above the bound on
//! its steps is refused before its first step (or stopped at the bound when its stable step
//! shrinks on the way), keeping the last good state.

use rkmpm::material::{JohnsonCook, MieGruneisen, MAX_WAVE_SPEED, MIN_DENSITY};
use rkmpm::sim::DEFAULT_MAX_STEPS_PER_ADVANCE;
use rkmpm::{ErrorKind, Material, Sim, Vector};

/// A 2×2 block of resting particles of a neo-Hookean material with wave speed about 3.7 m/s,
/// no gravity: its stable step stays the same over a run.
fn resting_block() -> Sim<2> {
    let mut sim = Sim::<2>::new([0.0, 0.0], [10, 10], 0.1).unwrap();
    let m = sim.add_material(Material::neo_hookean(1000.0, 1e4, 0.3).unwrap());
    let x: Vec<Vector<2>> = (0..4)
        .map(|k| Vector::<2>::new(0.475 + 0.05 * (k % 2) as f64, 0.475 + 0.05 * (k / 2) as f64))
        .collect();
    sim.add_particles(m, &x, &[0.0025; 4], None).unwrap();
    sim
}

/// The time, the step count and every particle's position, velocity and F, as bits.
fn state(sim: &Sim<2>) -> (u64, u64, Vec<u64>) {
    let ps = sim.particles();
    let mut bits = Vec::new();
    for p in 0..ps.len() {
        bits.extend(ps.position()[p].iter().map(|v| v.to_bits()));
        bits.extend(ps.velocity()[p].iter().map(|v| v.to_bits()));
        bits.extend(ps.deformation_gradient()[p].iter().map(|v| v.to_bits()));
    }
    (sim.time().to_bits(), sim.steps(), bits)
}

#[test]
fn a_run_above_the_bound_is_refused_with_its_estimate_and_changes_nothing() {
    let mut sim = resting_block();
    assert_eq!(sim.max_steps_per_advance(), DEFAULT_MAX_STEPS_PER_ADVANCE);
    assert_eq!(DEFAULT_MAX_STEPS_PER_ADVANCE, 1_000_000_000);
    let dt = sim.stable_dt(0.3).unwrap();
    sim.set_max_steps_per_advance(10).unwrap();
    let before = state(&sim);
    // 24.5 stable steps: 23 whole ones and the last 1.5 in two, 25 in all.
    let e = sim.advance(24.5 * dt, 0.3).unwrap_err();
    assert_eq!(e.kind, ErrorKind::InvalidArgument);
    assert!(
        e.message.contains("needs about 2.500e1 steps")
            && e.message
                .contains("above the bound of 10 steps per advance"),
        "{}",
        e.message
    );
    assert_eq!(state(&sim), before, "a refused run changed the simulation");
    // Raised, the bound lets the same run through, with the estimated number of steps.
    sim.set_max_steps_per_advance(25).unwrap();
    assert_eq!(sim.advance(24.5 * dt, 0.3).unwrap(), 25);
    assert_eq!(sim.time(), 24.5 * dt);
    assert_eq!(sim.steps(), 25);
    // A bound of 0 would refuse every run: refused itself, the bound kept.
    let e = sim.set_max_steps_per_advance(0).unwrap_err();
    assert_eq!(e.kind, ErrorKind::InvalidArgument);
    assert_eq!(sim.max_steps_per_advance(), 25);
}

#[test]
fn a_duration_of_1e300_is_refused_under_the_default_bound() {
    let mut sim = resting_block();
    let before = state(&sim);
    let dt = sim.stable_dt(0.3).unwrap();
    let e = sim.advance(1e300, 0.3).unwrap_err();
    assert_eq!(e.kind, ErrorKind::InvalidArgument);
    let estimate = format!("needs about {:.3e} steps", (1e300 / dt).ceil());
    assert!(
        e.message.contains(&estimate) && e.message.contains("1000000000 steps per advance"),
        "{} lacks {estimate}",
        e.message
    );
    assert_eq!(state(&sim), before);
    // A tiny cfl asks for as many steps: the same refusal.
    let e = sim.advance(1.0, 1e-300).unwrap_err();
    assert!(e.message.contains("above the bound"), "{}", e.message);
    assert_eq!(state(&sim), before);
}

/// A block falling under strong gravity: its speed, and with it the signal speed `c + |v|`,
/// grows from 1 m/s to 51 m/s over the run, so the run needs about 26 times the steps its first
/// stable step gives. The estimate (20 steps) passes a bound of 100; the bound stops the run
/// at its 100th step, which stays taken.
#[test]
fn the_bound_holds_while_the_stable_step_shrinks() {
    // c = sqrt(E / ρ) = 1 m/s with ν = 0.
    let setup = || {
        let mut sim = Sim::<2>::new([0.0, 0.0], [8, 400], 0.1).unwrap();
        sim.set_gravity([0.0, -50.0]).unwrap();
        let m = sim.add_material(Material::neo_hookean(1000.0, 1000.0, 0.0).unwrap());
        let x: Vec<Vector<2>> = (0..4)
            .map(|k| Vector::<2>::new(0.375 + 0.05 * (k % 2) as f64, 35.0 + 0.05 * (k / 2) as f64))
            .collect();
        sim.add_particles(m, &x, &[0.0025; 4], None).unwrap();
        sim
    };
    let mut sim = setup();
    let first = sim.stable_dt(0.5).unwrap();
    assert!((first - 0.05).abs() < 1e-12, "stable step {first}");
    sim.set_max_steps_per_advance(100).unwrap();
    let e = sim.advance(1.0, 0.5).unwrap_err();
    assert_eq!(e.kind, ErrorKind::InvalidArgument);
    assert!(
        e.message.contains("took the bound of 100 steps") && e.message.contains("(kept)"),
        "{}",
        e.message
    );
    assert_eq!(sim.steps(), 100);
    assert!(sim.time() > 0.0 && sim.time() < 1.0, "t = {}", sim.time());
    // The 100 steps kept are those of a run that was never refused.
    let mut free = setup();
    let mut observe = |_: &Sim<2>, p: rkmpm::sim::Progress| p.steps < 100;
    let _ = free.advance_observed(1.0, 0.5, &mut observe);
    assert_eq!(state(&free), state(&sim));
    // Raised, the bound lets the rest through: about 26 × 20 steps in all.
    sim.set_max_steps_per_advance(1000).unwrap();
    let rest = sim.advance(1.0 - sim.time(), 0.5).unwrap();
    let total = 100 + rest;
    assert!((480..=560).contains(&total), "{total} steps");
}

#[test]
fn materials_outside_any_physical_range_are_refused_with_their_reason() {
    let refused = |m: rkmpm::Result<Material>, reason: &str| {
        let e = m.unwrap_err();
        assert_eq!(e.kind, ErrorKind::InvalidArgument);
        assert!(e.message.contains(reason), "{} lacks {reason:?}", e.message);
    };
    let too_fast = "exceeds 1e5 m/s";
    // E = 1e300 Pa: a wave speed of 3.7e148 m/s.
    refused(Material::neo_hookean(1000.0, 1e300, 0.3), too_fast);
    refused(Material::linear_elastic(1000.0, 1e300, 0.3), too_fast);
    refused(
        Material::drucker_prager(1000.0, 1e300, 0.3, 30.0, 0.0, 0.0),
        too_fast,
    );
    let mut jc = rkmpm::material::ofhc_copper();
    jc.young = 1e300;
    refused(Material::johnson_cook(jc), too_fast);
    // The Mie–Grüneisen bulk modulus ρ0 c0² sets the wave speed when it is the stiffer one.
    let mut jc = rkmpm::material::ofhc_copper();
    jc.eos = Some(MieGruneisen {
        sound_speed: 2e5,
        slope: 1.49,
        gamma0: 1.96,
    });
    refused(Material::johnson_cook(jc), too_fast);
    // Just above and below the bound: c² = E / ρ with ν = 0.
    let c = 0.999 * MAX_WAVE_SPEED;
    assert!(Material::neo_hookean(1.0, c * c, 0.0).is_ok());
    let c = 1.001 * MAX_WAVE_SPEED;
    refused(Material::neo_hookean(1.0, c * c, 0.0), too_fast);
    // Densities that no material has, even with a modulus that keeps the wave speed at 1 m/s.
    let too_light = "below 1e-20 kg/m³";
    refused(Material::neo_hookean(1e-300, 1e-300, 0.0), too_light);
    refused(
        Material::linear_elastic(0.5 * MIN_DENSITY, 0.5 * MIN_DENSITY, 0.0),
        too_light,
    );
    refused(Material::rigid(1e-300, [0.0; 3]), too_light);
    assert!(Material::rigid(MIN_DENSITY, [0.0; 3]).is_ok());
    assert!(Material::neo_hookean(MIN_DENSITY, MIN_DENSITY, 0.0).is_ok());
    // A modulus whose shear modulus E / 2 underflows to 0: no wave speed, no stable step.
    refused(
        Material::neo_hookean(1.0, 5e-324, 0.0),
        "not finite and positive",
    );
    // The real materials of the scenes and studies stay well inside: steel, copper, diamond.
    assert!(Material::linear_elastic(7850.0, 204e9, 0.3).is_ok());
    assert!(JohnsonCook::new(rkmpm::material::ofhc_copper()).is_ok());
    assert!(Material::linear_elastic(3510.0, 1050e9, 0.1).is_ok());
}
