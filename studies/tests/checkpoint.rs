//! Checkpoint and restart: a run stopped, saved, loaded and continued gives the same particle
//! data bit for bit as the uninterrupted run; damaged files are refused; a failed save leaves
//! the previous checkpoint as it was.

use rkmpm::walls::{Side, Wall};
use rkmpm::{ErrorKind, Integration, Material, Shape, Sim, Transfer, Vector};
use rkmpm_studies::scenes::{colliding_disks, GranularColumn, Penetration, TaylorBar};
use std::path::PathBuf;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("rkmpm-checkpoint-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn advance<const D: usize>(sim: &mut Sim<D>, steps: usize) {
    for _ in 0..steps {
        let dt = sim.stable_dt(0.3).unwrap();
        sim.step(dt).unwrap();
    }
}

/// Runs `first + second` steps straight, and `first`, save, load, `second`; compares everything.
fn restart_is_bit_identical<const D: usize>(
    name: &str,
    build: impl Fn() -> Sim<D>,
    first: usize,
    second: usize,
) {
    let mut straight = build();
    advance(&mut straight, first + second);
    let mut before = build();
    advance(&mut before, first);
    let path = scratch(&format!("{name}.rkmpm"));
    before.save(&path).unwrap();
    drop(before);
    let mut after = Sim::<D>::load(&path).unwrap();
    advance(&mut after, second);
    assert_eq!(after.steps(), straight.steps(), "{name}");
    assert_eq!(after.time().to_bits(), straight.time().to_bits(), "{name}");
    assert!(
        after.particles() == straight.particles(),
        "{name}: particle data differ"
    );
    assert!(
        after.boundary_points() == straight.boundary_points(),
        "{name}: boundary points differ"
    );
}

#[test]
fn elastic_disks_apic() {
    restart_is_bit_identical("disks", || colliding_disks(20).unwrap(), 17, 23);
}

/// The MLS transfer is stored (and its affine matrices) like APIC's.
#[test]
fn elastic_disks_mls() {
    let build = || {
        let mut sim = colliding_disks(20).unwrap();
        sim.set_transfer(Transfer::Mls).unwrap();
        sim
    };
    restart_is_bit_identical("disks_mls", build, 17, 23);
}

/// RK2 with VC2 (boundary points from the lattice at the first step), gravity, walls, MUSL.
#[test]
fn rk2_vc2_block_on_walls_musl() {
    let build = || {
        let mut sim = Sim::<2>::new([0.0, 0.0], [12, 12], 0.1).unwrap();
        sim.set_shape(Shape::Rk {
            order: 2,
            support: 3.0,
        })
        .unwrap();
        sim.set_integration(Integration::Vc { order: 2 }).unwrap();
        sim.set_transfer(Transfer::PicFlip { flip: 0.5 }).unwrap();
        sim.set_scheme(rkmpm::Scheme::Musl).unwrap();
        sim.set_wall(1, Side::Low, Wall::Friction(0.3)).unwrap();
        sim.set_wall(0, Side::Low, Wall::Slip).unwrap();
        sim.set_gravity([0.0, -9.81]).unwrap();
        let m = sim.add_material(Material::neo_hookean(1000.0, 1e5, 0.3).unwrap());
        let x: Vec<Vector<2>> = (0..64)
            .map(|k| Vector::<2>::new(0.025 + 0.05 * (k % 8) as f64, 0.025 + 0.05 * (k / 8) as f64))
            .collect();
        sim.add_particles(m, &x, &[0.0025; 64], None).unwrap();
        sim
    };
    restart_is_bit_identical("rk2", build, 9, 11);
}

/// Drucker–Prager history (F_e, plastic strain) on a friction floor, rate-independent and with
/// the μ(I) rheology (stored under its own material tag).
#[test]
fn soil_collapse() {
    let column = GranularColumn {
        cells_across: 4,
        ..Default::default()
    };
    restart_is_bit_identical("soil", || column.build().unwrap(), 150, 150);
    let flowing = GranularColumn {
        rheology: Some(rkmpm::material::InertialRheology::new(0.26, 0.28, 1.25e-3).unwrap()),
        ..column
    };
    restart_is_bit_identical("soil_mu_i", || flowing.build().unwrap(), 150, 150);
}

/// Johnson–Cook (heating, rate) in 3D and Johnson–Cook damage with contact in plane strain.
#[test]
fn metals_with_damage_and_contact() {
    let bar = TaylorBar {
        cells_per_radius: 2,
        ..Default::default()
    };
    restart_is_bit_identical("taylor", || bar.build().unwrap(), 40, 40);
    let shot = Penetration {
        cells_through_plate: 3,
        impact_speed: 400.0,
        ..Default::default()
    };
    restart_is_bit_identical("penetration", || shot.build::<2>().unwrap(), 300, 300);
}

#[test]
fn damaged_files_are_refused() {
    let mut sim = colliding_disks(10).unwrap();
    advance(&mut sim, 3);
    let good = sim.checkpoint_bytes();
    assert!(Sim::<2>::from_checkpoint_bytes(&good).is_ok());
    // One flipped bit anywhere in the payload: the checksum catches it.
    for k in [30, good.len() / 2, good.len() - 5] {
        let mut bad = good.clone();
        bad[k] ^= 0x10;
        let e = Sim::<2>::from_checkpoint_bytes(&bad).err().unwrap();
        assert_eq!(e.kind, ErrorKind::CorruptFile, "byte {k}: {e}");
    }
    // Truncated anywhere.
    for n in [0, 7, 27, 100, good.len() - 1] {
        let e = Sim::<2>::from_checkpoint_bytes(&good[..n]).err().unwrap();
        assert_eq!(e.kind, ErrorKind::CorruptFile, "{n} bytes: {e}");
    }
    let mut other = good.clone();
    other[0] = b'X';
    assert!(Sim::<2>::from_checkpoint_bytes(&other)
        .err()
        .unwrap()
        .message
        .contains("magic"));
    let mut newer = good.clone();
    newer[8] = 99;
    assert_eq!(
        Sim::<2>::from_checkpoint_bytes(&newer).err().unwrap().kind,
        ErrorKind::Unsupported
    );
    let e = Sim::<3>::from_checkpoint_bytes(&good).err().unwrap();
    assert_eq!(e.kind, ErrorKind::InvalidArgument);
    assert!(e.message.contains("2D"), "{e}");
    let e = Sim::<2>::load(scratch("missing.rkmpm")).err().unwrap();
    assert_eq!(e.kind, ErrorKind::Io);
    assert!(
        e.message.contains("reading") && e.message.contains("missing.rkmpm"),
        "{e}"
    );
}

/// A save that cannot complete leaves the previous checkpoint untouched and no partial file.
#[test]
fn failed_save_keeps_the_previous_checkpoint() {
    let mut sim = colliding_disks(10).unwrap();
    let path = scratch("kept.rkmpm");
    sim.save(&path).unwrap();
    let first = std::fs::read(&path).unwrap();
    advance(&mut sim, 2);
    // The temporary name is taken by a directory, so the new file cannot be written.
    let tmp = PathBuf::from(format!("{}.tmp", path.display()));
    std::fs::create_dir_all(&tmp).unwrap();
    assert_eq!(sim.save(&path).unwrap_err().kind, ErrorKind::Io);
    assert_eq!(std::fs::read(&path).unwrap(), first);
    std::fs::remove_dir(&tmp).unwrap();
    sim.save(&path).unwrap();
    assert_eq!(Sim::<2>::load(&path).unwrap().steps(), 2);
    let e = sim.save(scratch("no/such/dir/x.rkmpm")).unwrap_err();
    assert_eq!(e.kind, ErrorKind::Io);
    // The message names the file, not only the operating system's "No such file or directory".
    assert!(e.message.contains("no/such/dir/x.rkmpm"), "{e}");
}
