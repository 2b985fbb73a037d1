//! The bundled scene files (`runner/scenes/*.toml`) build the same simulations as the scenes written
//! in Rust that the tests and the validation examples use: same grid, options, materials and
//! particles, bit for bit. So a run of a scene file is a run of the validated scene.

use rkmpm::Sim;
use rkmpm_runner::scene::{Scene, SceneSim, BUNDLED};
use rkmpm_studies::scenes::{
    colliding_disks, GranularColumn, Penetration, TaylorBar, VibratingBar,
};

fn scene(name: &str) -> SceneSim {
    let text = BUNDLED.iter().find(|(n, _)| *n == name).unwrap().1;
    Scene::from_toml(text, name).unwrap().build().unwrap()
}

/// Same simulation; positions may differ by `slack` (the Rust penetration scene offsets its
/// lattice from the plate's face, the scene file from the grid's origin: the same points, a
/// rounding apart).
fn same<const D: usize>(name: &str, file: &Sim<D>, rust: &Sim<D>) {
    close(name, file, rust, 0.0);
}

fn close<const D: usize>(name: &str, file: &Sim<D>, rust: &Sim<D>, slack: f64) {
    assert_eq!(file.grid().cells(), rust.grid().cells(), "{name}: cells");
    assert_eq!(
        file.grid().cell_size().to_bits(),
        rust.grid().cell_size().to_bits(),
        "{name}: h"
    );
    assert_eq!(file.grid().origin(), rust.grid().origin(), "{name}: origin");
    assert_eq!(file.options(), rust.options(), "{name}: options");
    assert_eq!(file.materials(), rust.materials(), "{name}: materials");
    assert_eq!(
        file.particle_count(),
        rust.particle_count(),
        "{name}: particle count"
    );
    let (a, b) = (file.particles(), rust.particles());
    if let Some(p) = (0..a.len()).find(|&p| (a.position()[p] - b.position()[p]).norm() > slack) {
        panic!(
            "{name}: particle {p} at {:?} (file) and {:?} (Rust)",
            a.position()[p].as_slice(),
            b.position()[p].as_slice()
        );
    }
    // Everything but the positions (within `slack` above) is the same to the bit.
    assert!(
        a.velocity() == b.velocity()
            && a.deformation_gradient() == b.deformation_gradient()
            && a.reference_volume() == b.reference_volume()
            && a.mass() == b.mass()
            && a.stress() == b.stress()
            && a.pressure() == b.pressure()
            && a.material() == b.material()
            && a.affine() == b.affine()
            && a.history() == b.history(),
        "{name}: particles differ"
    );
}

/// The default scene runs RK1 + VC1 and compares it with the quadratic B-spline (`[compare]`):
/// both are the Rust scene with those options.
#[test]
fn disks() {
    let text = BUNDLED.iter().find(|(n, _)| *n == "disks").unwrap().1;
    let scene = Scene::from_toml(text, "disks").unwrap();
    let SceneSim::D2(file) = scene.build().unwrap() else {
        panic!("2D")
    };
    let mut rust = colliding_disks(40).unwrap();
    rust.set_shape(rkmpm::Shape::Rk {
        order: 1,
        support: 2.0,
    })
    .unwrap();
    rust.set_integration(rkmpm::Integration::Vc { order: 1 })
        .unwrap();
    same("disks", &file, &rust);
    // The comparison: the same shape functions without VC.
    let SceneSim::D2(without) = scene.comparison().unwrap().build().unwrap() else {
        panic!("2D")
    };
    let mut rust = colliding_disks(40).unwrap();
    rust.set_shape(rkmpm::Shape::Rk {
        order: 1,
        support: 2.0,
    })
    .unwrap();
    same("disks [compare]", &without, &rust);
}

#[test]
fn vibrating_bar() {
    let SceneSim::D2(file) = scene("bar") else {
        panic!("2D")
    };
    same("bar", &file, &VibratingBar::default().build::<2>().unwrap());
}

#[test]
fn column_collapse() {
    let SceneSim::D2(file) = scene("collapse") else {
        panic!("2D")
    };
    let column = GranularColumn {
        aspect: 2.0,
        ..Default::default()
    };
    let rust = column.build().unwrap();
    same("collapse", &file, &rust);
}

#[test]
fn taylor_bar() {
    let SceneSim::D3(file) = scene("taylor") else {
        panic!("3D")
    };
    let rust = TaylorBar {
        cells_per_radius: 4,
        ..Default::default()
    }
    .build()
    .unwrap();
    same("taylor", &file, &rust);
}

#[test]
fn penetration() {
    let SceneSim::D2(file) = scene("penetration") else {
        panic!("2D")
    };
    let rust = Penetration {
        impact_speed: 350.0,
        plate_half_width: 60e-3,
        ..Default::default()
    }
    .build::<2>()
    .unwrap();
    // 1e-16 m: a rounding (an ulp) of positions of order 0.1 m.
    close("penetration", &file, &rust, 1e-16);
}

/// Total linear momentum and `Σ m|v|`, its scale.
fn momentum<const D: usize>(sim: &Sim<D>) -> (rkmpm::Vector<D>, f64) {
    let ps = sim.particles();
    let p = (0..ps.len())
        .map(|i| ps.mass()[i] * ps.velocity()[i])
        .sum::<rkmpm::Vector<D>>();
    let scale = (0..ps.len())
        .map(|i| ps.mass()[i] * ps.velocity()[i].norm())
        .sum::<f64>();
    (p, scale)
}

/// The default scene (two disks collide and part, RK1 + VC1): as the disks part, nodes at
/// their edges are reached by particles with `|Ψ_I|` near round-off while a surface point sees
/// them, and their equalities ask for corrections of the inverse size. The conservative solve
/// keeps every particle's corrections summing to zero all the same: momentum moves by 5e-14 of
/// `Σ m|v|` over the 533 steps (a multilevel-preconditioned solve that was tried let it drift
/// by 8e-4 here, which is why the scene is a test). The bound leaves a factor 20.
#[test]
fn vc_conserves_momentum_as_the_default_disks_part() {
    let text = BUNDLED.iter().find(|(name, _)| *name == "disks").unwrap().1;
    let scene = Scene::from_toml(text, "disks").unwrap();
    assert_eq!(
        scene.options.integration,
        rkmpm::options::IntegrationKind::Vc
    );
    let SceneSim::D2(mut sim) = scene.build().unwrap() else {
        panic!("disks is a 2D scene");
    };
    let (p0, scale) = momentum(&sim);
    sim.advance(scene.run.end_time, scene.run.cfl).unwrap();
    let (p1, _) = momentum(&sim);
    let drift = (p1 - p0).norm() / scale;
    eprintln!(
        "disks, RK1 + VC1: momentum drift {drift:.2e} over {} steps",
        sim.steps()
    );
    assert!(drift < 1e-12, "momentum drift {drift:e}");
}
