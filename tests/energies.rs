//! The energies and momenta a simulation reports (`Sim::energies`, `Sim::momenta`): the
//! particles' own sums, and the exact energy the time integration takes from a body in free fall.

use rkmpm::{Material, Sim, Transfer};

type V<const D: usize> = nalgebra::SVector<f64, D>;

/// A block of `m^D` particles, 2 per cell per direction, with the velocity field `velocity`.
fn block<const D: usize>(m: usize, velocity: impl Fn(&V<D>) -> V<D>) -> Sim<D> {
    let mut sim = Sim::<D>::new([0.0; D], [16; D], 1.0 / 16.0).unwrap();
    let mat = sim.add_material(Material::neo_hookean(1000.0, 1e5, 0.3).unwrap());
    let s = 0.5 / 16.0;
    let x: Vec<V<D>> = (0..m.pow(D as u32))
        .map(|k| V::<D>::from_fn(|a, _| 0.25 + s * (0.5 + ((k / m.pow(a as u32)) % m) as f64)))
        .collect();
    let v: Vec<V<D>> = x.iter().map(&velocity).collect();
    sim.add_particles(mat, &x, &vec![s.powi(D as i32); x.len()], Some(&v))
        .unwrap();
    sim
}

/// Kinetic, stored and gravitational energy, linear and angular momentum: the sums over the
/// particles, written out here, after a few steps of a spinning, stretching block under
/// gravity (2D and 3D).
fn sums_of_the_particles<const D: usize>() {
    let mut sim = block::<D>(6, |x| {
        let mut v = V::<D>::zeros();
        v[0] = -(x[1] - 0.4) + 0.3 * (x[0] - 0.4);
        v[1] = x[0] - 0.4;
        v
    });
    // Without gravity the potential is +0 (a summary prints 0, not −0).
    assert_eq!(sim.energies().gravitational.to_bits(), 0.0f64.to_bits());
    let mut g = V::<D>::zeros();
    g[D - 1] = -9.81;
    sim.set_gravity(g).unwrap();
    let dt = sim.stable_dt(0.3).unwrap();
    for _ in 0..5 {
        sim.step(dt).unwrap();
    }
    let (e, p) = (sim.energies(), sim.momenta());
    let ps = sim.particles();
    let embed = |v: &V<D>| nalgebra::Vector3::from_fn(|k, _| if k < D { v[k] } else { 0.0 });
    let (mut kinetic, mut potential) = (0.0, 0.0);
    let (mut linear, mut angular) = (V::<D>::zeros(), nalgebra::Vector3::zeros());
    for q in 0..ps.len() {
        let (m, x, v) = (ps.mass[q], ps.position[q], ps.velocity[q]);
        kinetic += 0.5 * m * v.norm_squared();
        potential -= m * g.dot(&x);
        linear += m * v;
        angular += m * embed(&x).cross(&embed(&v));
    }
    let close = |a: f64, b: f64, scale: f64| (a - b).abs() <= 1e-13 * scale;
    assert!(
        close(e.kinetic, kinetic, kinetic),
        "{} {kinetic}",
        e.kinetic
    );
    assert!(close(e.gravitational, potential, potential.abs()));
    assert_eq!(e.stored, sim.strain_energy());
    assert!(e.stored > 0.0, "the block is strained");
    assert_eq!(e.total(), e.kinetic + e.stored + e.gravitational);
    for k in 0..D {
        assert!(close(p.linear[k], linear[k], linear.norm()));
    }
    for k in 0..3 {
        assert!(close(p.angular[k], angular[k], angular.norm()), "{k}");
    }
    assert!(angular.norm() > 0.0);
    if D == 2 {
        assert_eq!((p.angular[0], p.angular[1]), (0.0, 0.0));
    }
}

#[test]
fn energies_and_momenta_are_the_sums_of_the_particles() {
    sums_of_the_particles::<2>();
    sums_of_the_particles::<3>();
}

/// A block in free fall (no walls, no stress): every step moves the particles by `v_{n+1} Δt`
/// with `v_{n+1} = v_n + g Δt` (symplectic Euler), so kinetic plus gravitational energy falls
/// by exactly `½ M g² Δt²` a step, what the time integration takes. APIC and PIC alike
/// reproduce the uniform velocity on the grid, and the block stays unstrained.
fn free_fall<const D: usize>(transfer: Transfer) {
    let mut sim = block::<D>(4, |_| V::<D>::from_element(0.05));
    sim.set_transfer(transfer).unwrap();
    let mut g = V::<D>::zeros();
    g[D - 1] = -9.81;
    sim.set_gravity(g).unwrap();
    let dt = 1e-3;
    let e0 = sim.energies();
    let steps = 20;
    for _ in 0..steps {
        sim.step(dt).unwrap();
    }
    let e = sim.energies();
    let mass: f64 = sim.particles().mass.iter().sum();
    let expected = -(steps as f64) * 0.5 * mass * g.norm_squared() * dt * dt;
    let change = e.total() - e0.total();
    assert!(
        (change - expected).abs() <= 1e-9 * expected.abs(),
        "{D}D: energy change {change:e}, symplectic Euler's {expected:e}"
    );
    assert!(e.stored.abs() <= 1e-12 * e.kinetic, "stored {:e}", e.stored);
}

#[test]
fn a_block_in_free_fall_loses_what_symplectic_euler_takes() {
    free_fall::<2>(Transfer::Apic);
    free_fall::<3>(Transfer::Apic);
    free_fall::<2>(Transfer::PicFlip { flip: 0.0 });
}
