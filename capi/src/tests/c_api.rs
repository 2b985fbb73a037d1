//! The C API called through its exported functions: status codes, the last-error message,
//! buffer handling, and that failed calls change nothing. (The C and Fortran drivers under CTest
//! repeat the misuse cases from C and Fortran.)

use crate::*;
use std::ffi::{c_void, CStr};
use std::ptr::{null, null_mut};

fn last_error() -> String {
    let n = unsafe { rkmpm_last_error_message(null_mut(), 0) };
    let mut buf = vec![0i8; n + 1];
    let m = unsafe { rkmpm_last_error_message(buf.as_mut_ptr(), buf.len()) };
    assert_eq!(m, n);
    unsafe { CStr::from_ptr(buf.as_ptr()) }
        .to_str()
        .unwrap()
        .to_owned()
}

/// A 2D sim with a 4×4 block of particles, one step taken when `stepped`.
fn sim2d(stepped: bool) -> *mut RkmpmSim {
    let mut sim = null_mut();
    let origin = [0.0, 0.0];
    let cells = [10usize, 10];
    unsafe {
        assert_eq!(
            rkmpm_sim_new(2, origin.as_ptr(), cells.as_ptr(), 0.1, &mut sim),
            RKMPM_OK
        );
        let mut id = u32::MAX;
        assert_eq!(
            rkmpm_sim_add_material_neo_hookean(sim, 1000.0, 1e5, 0.3, &mut id),
            RKMPM_OK
        );
        assert_eq!(id, 0);
        let mut x = Vec::new();
        for j in 0..4 {
            for i in 0..4 {
                x.extend([0.4 + 0.05 * i as f64 + 0.025, 0.4 + 0.05 * j as f64 + 0.025]);
            }
        }
        let vol = [0.0025; 16];
        assert_eq!(
            rkmpm_sim_add_particles(sim, 0, 16, x.as_ptr(), vol.as_ptr(), null()),
            RKMPM_OK
        );
        if stepped {
            let mut dt = 0.0;
            assert_eq!(rkmpm_sim_stable_dt(sim, 0.3, &mut dt), RKMPM_OK);
            assert_eq!(rkmpm_sim_step(sim, dt), RKMPM_OK);
        }
    }
    sim
}

fn positions(sim: *const RkmpmSim) -> Vec<f64> {
    field(sim, RKMPM_FIELD_POSITION)
}

/// The values of `f` for every particle, in id order.
fn field(sim: *const RkmpmSim, f: RkmpmField) -> Vec<f64> {
    let mut n = 0;
    unsafe {
        assert_eq!(rkmpm_sim_field_len(sim, f, &mut n), RKMPM_OK);
        let mut out = vec![0.0; n];
        assert_eq!(
            rkmpm_sim_get_particles(sim, f, out.as_mut_ptr(), n),
            RKMPM_OK
        );
        out
    }
}

#[test]
fn version_abi_and_status_strings() {
    let v = unsafe { CStr::from_ptr(rkmpm_version()) }.to_str().unwrap();
    assert_eq!(v, env!("CARGO_PKG_VERSION"));
    assert_eq!(rkmpm_abi_version(), RKMPM_ABI_VERSION);
    let mut seen = std::collections::HashSet::new();
    for s in RkmpmStatus::ALL {
        let text = unsafe { CStr::from_ptr(rkmpm_status_str(s as i32)) }
            .to_str()
            .unwrap();
        assert!(seen.insert(text.to_owned()), "duplicate status text {text}");
    }
    assert_eq!(seen.len(), 16);
    let unknown = unsafe { CStr::from_ptr(rkmpm_status_str(99)) }
        .to_str()
        .unwrap();
    assert_eq!(unknown, "unknown status");
}

#[test]
fn every_error_status_is_reachable_and_changes_nothing() {
    unsafe {
        // 1: NULL pointers.
        assert_eq!(
            rkmpm_sim_new(2, null(), null(), 0.1, null_mut()),
            RKMPM_ERR_NULL_POINTER
        );
        assert!(last_error().contains("out is NULL"), "{}", last_error());
        assert_eq!(rkmpm_sim_step(null_mut(), 0.1), RKMPM_ERR_NULL_POINTER);
        let mut out = null_mut();
        assert_eq!(
            rkmpm_sim_new(2, null(), [1usize, 1].as_ptr(), 0.1, &mut out),
            RKMPM_ERR_NULL_POINTER
        );
        assert!(out.is_null());

        // 2: invalid arguments.
        let origin = [0.0; 3];
        let cells = [4usize; 3];
        assert_eq!(
            rkmpm_sim_new(4, origin.as_ptr(), cells.as_ptr(), 0.1, &mut out),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert_eq!(
            rkmpm_sim_new(3, origin.as_ptr(), cells.as_ptr(), -0.1, &mut out),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert_eq!(
            rkmpm_sim_new(3, origin.as_ptr(), [4usize, 0, 4].as_ptr(), 0.1, &mut out),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert!(out.is_null());

        let sim = sim2d(false);
        let x0 = positions(sim);
        assert_eq!(
            rkmpm_sim_set_gravity(sim, [f64::NAN, 0.0].as_ptr()),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert_eq!(
            rkmpm_sim_set_shape(sim, 77, 0, 0.0),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert_eq!(
            rkmpm_sim_set_integration(sim, 9, 0),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert_eq!(
            rkmpm_sim_set_transfer(sim, RKMPM_TRANSFER_PIC_FLIP, 1.5),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert_eq!(rkmpm_sim_set_scheme(sim, 2), RKMPM_ERR_INVALID_ARGUMENT);
        assert_eq!(
            rkmpm_sim_set_boundary(sim, 0, 0, RKMPM_BOUNDARY_FIXED, 0.0),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert_eq!(
            rkmpm_sim_set_boundary(sim, 2, 1, RKMPM_BOUNDARY_FIXED, 0.0),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert_eq!(
            rkmpm_sim_set_boundary(sim, 0, 1, 9, 0.0),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert_eq!(
            rkmpm_sim_set_boundary(sim, 0, 1, RKMPM_BOUNDARY_FRICTION, -1.0),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        let mut id = 0;
        assert_eq!(
            rkmpm_sim_add_material_linear_elastic(sim, 1.0, 1.0, 0.5, &mut id),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert!(last_error().contains("poisson"), "{}", last_error());
        let mut dt = 0.0;
        assert_eq!(
            rkmpm_sim_stable_dt(sim, 0.0, &mut dt),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert_eq!(
            rkmpm_sim_step(sim, f64::INFINITY),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        let mut n = 0;
        assert_eq!(
            rkmpm_sim_field_len(sim, 77, &mut n),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        let bad = [0.5, 0.5, 0.5, f64::NAN];
        assert_eq!(
            rkmpm_sim_add_particles(sim, 0, 2, bad.as_ptr(), [1e-3, 1e-3].as_ptr(), null()),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert_eq!(
            rkmpm_sim_add_particles(sim, 0, usize::MAX, bad.as_ptr(), bad.as_ptr(), null()),
            RKMPM_ERR_INVALID_ARGUMENT
        );

        // 3: a short buffer writes nothing and says how much is needed.
        let mut buf = vec![-7.0; 10];
        assert_eq!(
            rkmpm_sim_get_particles(sim, RKMPM_FIELD_STRESS, buf.as_mut_ptr(), 10),
            RKMPM_ERR_BUFFER_TOO_SMALL
        );
        assert!(buf.iter().all(|&v| v == -7.0));
        assert!(last_error().contains("needs 64"), "{}", last_error());

        // 5: unknown material; 6: outside the grid. Nothing added.
        let x = [0.5, 0.5, 0.6, 0.6];
        let vol = [1e-3, 1e-3];
        assert_eq!(
            rkmpm_sim_add_particles(sim, 3, 2, x.as_ptr(), vol.as_ptr(), null()),
            RKMPM_ERR_UNKNOWN_MATERIAL
        );
        let outside = [0.5, 0.5, 1.6, 0.6];
        assert_eq!(
            rkmpm_sim_add_particles(sim, 0, 2, outside.as_ptr(), vol.as_ptr(), null()),
            RKMPM_ERR_OUTSIDE_GRID
        );
        assert_eq!(rkmpm_sim_particle_count(sim), 16);

        // A support too small for the RK order.
        assert_eq!(
            rkmpm_sim_set_shape(sim, RKMPM_SHAPE_RK, 2, 1.25),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert!(
            last_error().contains("condition number"),
            "{}",
            last_error()
        );
        assert_eq!(
            rkmpm_sim_set_integration(sim, RKMPM_INTEGRATION_VC, 0),
            RKMPM_ERR_INVALID_ARGUMENT
        );

        // 7: dt far above the stable limit.
        assert_eq!(rkmpm_sim_stable_dt(sim, 1.0, &mut dt), RKMPM_OK);
        assert_eq!(rkmpm_sim_step(sim, 10.0 * dt), RKMPM_ERR_UNSTABLE_TIME_STEP);

        // 10: the callback fails; 8: it drives the step to non-finite values;
        // 9: it squeezes particles through themselves.
        extern "C" fn failing(
            _: *mut c_void,
            _: f64,
            _: usize,
            _: u32,
            _: *const f64,
            _: *const f64,
            _: *mut f64,
        ) -> i32 {
            1
        }
        extern "C" fn tearing(
            _: *mut c_void,
            _: f64,
            n: usize,
            d: u32,
            _: *const f64,
            x: *const f64,
            a: *mut f64,
        ) -> i32 {
            for p in 0..n {
                unsafe {
                    let xp = *x.add(p * d as usize);
                    *a.add(p * d as usize) = if xp < 0.5 { -1e308 } else { 1e308 };
                    *a.add(p * d as usize + 1) = 0.0;
                }
            }
            0
        }
        extern "C" fn squeezing(
            user: *mut c_void,
            _: f64,
            n: usize,
            d: u32,
            _: *const f64,
            x: *const f64,
            a: *mut f64,
        ) -> i32 {
            let k = unsafe { *(user as *const f64) };
            for p in 0..n {
                unsafe {
                    *a.add(p * d as usize) = -k * (*x.add(p * d as usize) - 0.5);
                    *a.add(p * d as usize + 1) = 0.0;
                }
            }
            0
        }
        let step_dt = 0.3 * dt;
        assert_eq!(
            rkmpm_sim_set_body_force(sim, Some(failing), null_mut()),
            RKMPM_OK
        );
        assert_eq!(rkmpm_sim_step(sim, step_dt), RKMPM_ERR_CALLBACK);
        assert!(last_error().contains("returned 1"), "{}", last_error());
        assert_eq!(
            rkmpm_sim_set_body_force(sim, Some(tearing), null_mut()),
            RKMPM_OK
        );
        assert_eq!(rkmpm_sim_step(sim, step_dt), RKMPM_ERR_NON_FINITE);
        let mut k = 3.0 / (step_dt * step_dt);
        assert_eq!(
            rkmpm_sim_set_body_force(sim, Some(squeezing), (&mut k as *mut f64).cast()),
            RKMPM_OK
        );
        assert_eq!(rkmpm_sim_step(sim, step_dt), RKMPM_ERR_INVERTED_PARTICLE);
        assert!(last_error().contains("inverted"), "{}", last_error());
        assert_eq!(rkmpm_sim_set_body_force(sim, None, null_mut()), RKMPM_OK);

        // 11: a file that cannot be written.
        let path = c"/nonexistent-dir/x.vtu";
        assert_eq!(rkmpm_sim_write_vtk(sim, path.as_ptr()), RKMPM_ERR_IO);
        // Energies and momenta: the sums over the particles' masses and velocities.
        let (mass, v) = (
            field(sim, RKMPM_FIELD_MASS),
            field(sim, RKMPM_FIELD_VELOCITY),
        );
        let mut e = RkmpmEnergies::default();
        assert_eq!(rkmpm_sim_energies(sim, &mut e), RKMPM_OK);
        let kinetic: f64 = (0..mass.len())
            .map(|p| 0.5 * mass[p] * (v[2 * p].powi(2) + v[2 * p + 1].powi(2)))
            .sum();
        assert!(
            (e.kinetic - kinetic).abs() <= 1e-13 * kinetic,
            "{e:?} {kinetic}"
        );
        let mut momenta = RkmpmMomenta::default();
        assert_eq!(rkmpm_sim_momenta(sim, &mut momenta), RKMPM_OK);
        let px: f64 = (0..mass.len()).map(|p| mass[p] * v[2 * p]).sum();
        assert!((momenta.linear[0] - px).abs() <= 1e-13 * px.abs().max(kinetic.sqrt()));
        assert_eq!(momenta.linear[2], 0.0);
        assert_eq!(rkmpm_sim_energies(sim, null_mut()), RKMPM_ERR_NULL_POINTER);
        // The energy balance: refused while the accounting is off, and a bad flag leaves it
        // off.
        let mut balance = RkmpmEnergyBalance::default();
        assert_eq!(
            rkmpm_sim_energy_balance(sim, &mut balance),
            RKMPM_ERR_INVALID_STATE
        );
        assert!(
            last_error().contains("accounting is off"),
            "{}",
            last_error()
        );
        assert_eq!(
            rkmpm_sim_set_energy_accounting(sim, 2),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert_eq!(
            rkmpm_sim_energy_balance(sim, &mut balance),
            RKMPM_ERR_INVALID_STATE
        );
        // On, on another block: three steps of free fall, whose ledger closes.
        let other = sim2d(false);
        let g = [0.0, -9.81];
        assert_eq!(rkmpm_sim_set_gravity(other, g.as_ptr()), RKMPM_OK);
        assert_eq!(rkmpm_sim_set_energy_accounting(other, 1), RKMPM_OK);
        let mut start = RkmpmEnergies::default();
        assert_eq!(rkmpm_sim_energies(other, &mut start), RKMPM_OK);
        assert_eq!(rkmpm_sim_energy_balance(other, &mut balance), RKMPM_OK);
        assert_eq!(
            (
                balance.start,
                balance.stress_work,
                balance.other_dissipation
            ),
            (start.kinetic + start.stored + start.gravitational, 0.0, 0.0)
        );
        for _ in 0..3 {
            assert_eq!(rkmpm_sim_step(other, step_dt), RKMPM_OK);
        }
        assert_eq!(rkmpm_sim_energy_balance(other, &mut balance), RKMPM_OK);
        let mut now = RkmpmEnergies::default();
        assert_eq!(rkmpm_sim_energies(other, &mut now), RKMPM_OK);
        assert_eq!(
            (balance.kinetic, balance.stored, balance.gravitational),
            (now.kinetic, now.stored, now.gravitational)
        );
        // Free fall: symplectic Euler takes `½ M g² Δt²` a step (M = 16 × 2.5 kg).
        let expected = 3.0 * 0.5 * 40.0 * 9.81f64.powi(2) * step_dt * step_dt;
        assert!(
            (balance.other_dissipation - expected).abs() <= 1e-9 * expected,
            "{balance:?}, expected {expected:e}"
        );
        let closed = balance.start + balance.external_work
            - balance.material_dissipation
            - balance.other_dissipation;
        let total = now.kinetic + now.stored + now.gravitational;
        assert!(
            (closed - total).abs() <= 1e-12 * balance.start.abs(),
            "{balance:?}"
        );
        assert_eq!(rkmpm_sim_set_energy_accounting(other, 0), RKMPM_OK);
        rkmpm_sim_free(other);
        assert_eq!(
            rkmpm_sim_momenta(null(), &mut momenta),
            RKMPM_ERR_NULL_POINTER
        );
        // The VTK format: binary by default, ASCII on request, an unknown one refused.
        let file =
            std::env::temp_dir().join(format!("rkmpm-capi-format-{}.vtu", std::process::id()));
        let c_file = std::ffi::CString::new(file.to_str().unwrap()).unwrap();
        let appended = |sim| {
            assert_eq!(rkmpm_sim_write_vtk(sim, c_file.as_ptr()), RKMPM_OK);
            let bytes = std::fs::read(&file).unwrap();
            bytes
                .windows(29)
                .any(|w| w == b"<AppendedData encoding=\"raw\">")
        };
        assert!(appended(sim));
        assert_eq!(rkmpm_sim_set_vtk_format(sim, 7), RKMPM_ERR_INVALID_ARGUMENT);
        assert!(last_error().contains("format = 7"), "{}", last_error());
        assert!(appended(sim));
        assert_eq!(rkmpm_sim_set_vtk_format(sim, RKMPM_VTK_ASCII), RKMPM_OK);
        assert!(!appended(sim));
        assert!(std::str::from_utf8(&std::fs::read(&file).unwrap()).is_ok());
        assert_eq!(rkmpm_sim_set_vtk_format(sim, RKMPM_VTK_BINARY), RKMPM_OK);
        assert!(appended(sim));
        std::fs::remove_file(&file).unwrap();

        // Nothing above changed the particles, the time or the step count.
        assert_eq!(positions(sim), x0);
        let (mut t, mut steps) = (-1.0, 99);
        assert_eq!(rkmpm_sim_time(sim, &mut t), RKMPM_OK);
        assert_eq!(rkmpm_sim_step_count(sim, &mut steps), RKMPM_OK);
        assert_eq!((t, steps), (0.0, 0));

        // 12: a combination that cannot run (APIC with RK order 2), refused at the step.
        let other = sim2d(false);
        assert_eq!(rkmpm_sim_set_shape(other, RKMPM_SHAPE_RK, 2, 3.0), RKMPM_OK);
        assert_eq!(rkmpm_sim_step(other, step_dt), RKMPM_ERR_UNSUPPORTED);
        assert_eq!(
            rkmpm_sim_set_transfer(other, RKMPM_TRANSFER_PIC_FLIP, 0.0),
            RKMPM_OK
        );
        assert_eq!(rkmpm_sim_step(other, step_dt), RKMPM_OK);
        rkmpm_sim_free(other);

        // Boundary points: lengths, NULL tractions, outside the grid; VC then steps.
        let other = sim2d(false);
        let bx = [0.4, 0.5, 0.6, 0.5];
        let bn = [-0.2, 0.0, 0.2, 0.0];
        assert_eq!(
            rkmpm_sim_add_boundary_points(other, 2, bx.as_ptr(), null(), null()),
            RKMPM_ERR_NULL_POINTER
        );
        assert_eq!(
            rkmpm_sim_add_boundary_points(
                other,
                2,
                [0.4, 0.5, 1.6, 0.5].as_ptr(),
                bn.as_ptr(),
                null()
            ),
            RKMPM_ERR_OUTSIDE_GRID
        );
        assert_eq!(
            rkmpm_sim_add_boundary_points(other, 2, bx.as_ptr(), [0.0; 4].as_ptr(), null()),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        let mut nb = 9;
        assert_eq!(rkmpm_sim_boundary_point_count(other, &mut nb), RKMPM_OK);
        assert_eq!(nb, 0);
        assert_eq!(
            rkmpm_sim_set_integration(other, RKMPM_INTEGRATION_VC, 1),
            RKMPM_OK
        );
        assert_eq!(rkmpm_sim_step(other, step_dt), RKMPM_OK);
        assert_eq!(rkmpm_sim_boundary_point_count(other, &mut nb), RKMPM_OK);
        assert_eq!(
            nb, 32,
            "surface of a 4×4 block, one face per particle face, two Gauss points each"
        );
        rkmpm_sim_free(other);

        // 4: options after the first step.
        assert_eq!(rkmpm_sim_step(sim, step_dt), RKMPM_OK);
        assert_eq!(
            rkmpm_sim_set_shape(sim, RKMPM_SHAPE_LINEAR, 0, 0.0),
            RKMPM_ERR_INVALID_STATE
        );
        assert!(
            last_error().contains("before the first step"),
            "{}",
            last_error()
        );
        rkmpm_sim_free(sim);
        rkmpm_sim_free(null_mut());
    }
}

#[test]
fn last_error_message_truncates_with_a_nul_and_reports_the_full_length() {
    unsafe {
        assert_eq!(rkmpm_sim_step(null_mut(), 0.1), RKMPM_ERR_NULL_POINTER);
        let full = last_error();
        assert_eq!(full, "rkmpm_sim_step: sim is NULL");
        let mut small = [1i8; 5];
        let n = rkmpm_last_error_message(small.as_mut_ptr(), small.len());
        assert_eq!(n, full.len());
        assert_eq!(CStr::from_ptr(small.as_ptr()).to_str().unwrap(), &full[..4]);
    }
}

#[test]
fn fields_have_their_documented_layout() {
    let sim = sim2d(true);
    unsafe {
        let mut dim = 0;
        assert_eq!(rkmpm_sim_dim(sim, &mut dim), RKMPM_OK);
        assert_eq!(dim, 2);
        for (field, per) in [
            (RKMPM_FIELD_POSITION, 2),
            (RKMPM_FIELD_VELOCITY, 2),
            (RKMPM_FIELD_DISPLACEMENT, 2),
            (RKMPM_FIELD_STRESS, 4),
            (RKMPM_FIELD_PRESSURE, 1),
            (RKMPM_FIELD_VOLUME, 1),
            (RKMPM_FIELD_MASS, 1),
            (RKMPM_FIELD_REFERENCE_POSITION, 2),
            (RKMPM_FIELD_DEFORMATION_GRADIENT, 4),
            (RKMPM_FIELD_PLASTIC_STRAIN, 1),
        ] {
            let mut n = 0;
            assert_eq!(rkmpm_sim_field_len(sim, field, &mut n), RKMPM_OK);
            assert_eq!(n, 16 * per);
        }
        let mut mass = vec![0.0; 16];
        assert_eq!(
            rkmpm_sim_get_particles(sim, RKMPM_FIELD_MASS, mass.as_mut_ptr(), 16),
            RKMPM_OK
        );
        assert!(mass.iter().all(|&m| (m - 2.5).abs() < 1e-12));
        let mut s = vec![0.0; 64];
        assert_eq!(
            rkmpm_sim_get_particles(sim, RKMPM_FIELD_STRESS, s.as_mut_ptr(), 64),
            RKMPM_OK
        );
        for p in 0..16 {
            assert_eq!(s[4 * p + 1], s[4 * p + 2], "stress is symmetric");
        }
        rkmpm_sim_free(sim);
    }
}

/// Drucker–Prager through the C API: bad parameters get status and message and add nothing; a
/// block of soil dropped on a friction floor yields, and its plastic strain is readable.
#[test]
fn drucker_prager_soil_through_the_c_api() {
    let mut sim = null_mut();
    let (origin, cells) = ([0.0, 0.0], [24usize, 10]);
    unsafe {
        assert_eq!(
            rkmpm_sim_new(2, origin.as_ptr(), cells.as_ptr(), 0.1, &mut sim),
            RKMPM_OK
        );
        let mut id = u32::MAX;
        for (phi, c, psi, what) in [
            (30.0, 0.0, 31.0, "dilatancy_angle"),
            (95.0, 0.0, 0.0, "friction_angle"),
            (30.0, -1.0, 0.0, "cohesion"),
            (f64::NAN, 0.0, 0.0, "friction_angle"),
        ] {
            assert_eq!(
                rkmpm_sim_add_material_drucker_prager(sim, 2650.0, 1e6, 0.3, phi, c, psi, &mut id),
                RKMPM_ERR_INVALID_ARGUMENT
            );
            assert!(last_error().contains(what), "{}", last_error());
            assert_eq!(id, u32::MAX);
        }
        assert_eq!(
            rkmpm_sim_add_material_drucker_prager(sim, 2650.0, 1e6, 0.3, 20.0, 0.0, 0.0, &mut id),
            RKMPM_OK
        );
        assert_eq!(id, 0);
        assert_eq!(
            rkmpm_sim_set_boundary(sim, 1, -1, RKMPM_BOUNDARY_FRICTION, 0.4),
            RKMPM_OK
        );
        let g = [0.0, -9.81];
        assert_eq!(rkmpm_sim_set_gravity(sim, g.as_ptr()), RKMPM_OK);
        let mut x = Vec::new();
        for j in 0..8 {
            for i in 0..8 {
                x.extend([1.0 + 0.05 * i as f64 + 0.025, 0.05 * j as f64 + 0.025]);
            }
        }
        let vol = [0.0025; 64];
        assert_eq!(
            rkmpm_sim_add_particles(sim, 0, 64, x.as_ptr(), vol.as_ptr(), null()),
            RKMPM_OK
        );
        let mut dt = 0.0;
        assert_eq!(rkmpm_sim_stable_dt(sim, 0.3, &mut dt), RKMPM_OK);
        for _ in 0..400 {
            assert_eq!(rkmpm_sim_step(sim, dt), RKMPM_OK, "{}", last_error());
        }
        let mut eps = vec![-1.0; 64];
        assert_eq!(
            rkmpm_sim_get_particles(sim, RKMPM_FIELD_PLASTIC_STRAIN, eps.as_mut_ptr(), 64),
            RKMPM_OK
        );
        // The unconfined block slumps: its corners flow plastically, and nothing is negative.
        assert!(eps.iter().all(|&e| e >= 0.0));
        assert!(eps.iter().any(|&e| e > 1e-3), "no plastic flow: {eps:?}");
        rkmpm_sim_free(sim);
    }
}

/// The μ(I) rheology from C: the slumping block of the test above flows less with it (the
/// friction only rises with the shear rate); turned on and off again before stepping it leaves
/// the run bit for bit as without; an elastic material or an unknown id is refused.
#[test]
fn drucker_prager_rheology_through_the_c_api() {
    // Total plastic strain of the block after 300 steps: `switch` 0 none, 1 on, 2 on then off.
    let slump = |switch: u32| unsafe {
        let mut sim = null_mut();
        let (origin, cells) = ([0.0, 0.0], [24usize, 10]);
        assert_eq!(
            rkmpm_sim_new(2, origin.as_ptr(), cells.as_ptr(), 0.1, &mut sim),
            RKMPM_OK
        );
        let (mut soil, mut rubber) = (u32::MAX, u32::MAX);
        assert_eq!(
            rkmpm_sim_add_material_drucker_prager(sim, 2650.0, 1e6, 0.3, 20.0, 0.0, 0.0, &mut soil),
            RKMPM_OK
        );
        assert_eq!(
            rkmpm_sim_add_material_neo_hookean(sim, 1000.0, 1e5, 0.3, &mut rubber),
            RKMPM_OK
        );
        for (material, status, what) in [
            (rubber, RKMPM_ERR_INVALID_ARGUMENT, "not Drucker"),
            (7, RKMPM_ERR_INVALID_ARGUMENT, "does not exist"),
        ] {
            assert_eq!(
                rkmpm_sim_set_drucker_prager_rheology(sim, material, 1, 0.5, 0.28, 1e-2),
                status
            );
            assert!(last_error().contains(what), "{}", last_error());
        }
        if switch > 0 {
            assert_eq!(
                rkmpm_sim_set_drucker_prager_rheology(sim, soil, 1, 0.5, 0.28, 1e-2),
                RKMPM_OK
            );
        }
        if switch > 1 {
            assert_eq!(
                rkmpm_sim_set_drucker_prager_rheology(sim, soil, 0, f64::NAN, 0.0, 0.0),
                RKMPM_OK
            );
        }
        assert_eq!(
            rkmpm_sim_set_boundary(sim, 1, -1, RKMPM_BOUNDARY_FRICTION, 0.4),
            RKMPM_OK
        );
        let g = [0.0, -9.81];
        assert_eq!(rkmpm_sim_set_gravity(sim, g.as_ptr()), RKMPM_OK);
        let x: Vec<f64> = (0..64)
            .flat_map(|k| [1.025 + 0.05 * (k % 8) as f64, 0.025 + 0.05 * (k / 8) as f64])
            .collect();
        let vol = [0.0025; 64];
        assert_eq!(
            rkmpm_sim_add_particles(sim, soil, 64, x.as_ptr(), vol.as_ptr(), null()),
            RKMPM_OK
        );
        let mut dt = 0.0;
        assert_eq!(rkmpm_sim_stable_dt(sim, 0.3, &mut dt), RKMPM_OK);
        for _ in 0..300 {
            assert_eq!(rkmpm_sim_step(sim, dt), RKMPM_OK, "{}", last_error());
        }
        let mut eps = vec![-1.0; 64];
        assert_eq!(
            rkmpm_sim_get_particles(sim, RKMPM_FIELD_PLASTIC_STRAIN, eps.as_mut_ptr(), 64),
            RKMPM_OK
        );
        rkmpm_sim_free(sim);
        eps.iter().sum::<f64>()
    };
    let (none, on, off) = (slump(0), slump(1), slump(2));
    eprintln!("total plastic strain: without μ(I) {none}, with {on}");
    assert_eq!(off.to_bits(), none.to_bits());
    assert!(
        on > 0.0 && on < 0.95 * none,
        "μ(I) did not slow the flow: {on} against {none}"
    );
}

/// Johnson–Cook through the C API: a bad flag and a NULL struct are refused; a copper block hit
/// against a slip floor at 300 m/s flows plastically, heats up and accumulates damage in [0, 1].
#[test]
fn johnson_cook_metal_through_the_c_api() {
    let mut sim = null_mut();
    let (origin, cells) = ([0.0, 0.0], [24usize, 12]);
    let mut jc = RkmpmJohnsonCook {
        density: 8960.0,
        young: 124e9,
        poisson: 0.34,
        a: 90e6,
        b: 292e6,
        n: 0.31,
        c: 0.025,
        reference_strain_rate: 1.0,
        m: 1.09,
        room_temperature: 298.0,
        melt_temperature: 1356.0,
        specific_heat: 383.0,
        taylor_quinney: 0.9,
        damage_enabled: 2,
        d1: 0.54,
        d2: 4.89,
        d3: -3.03,
        d4: 0.014,
        d5: 1.12,
        eos_enabled: 1,
        eos_sound_speed: 3940.0,
        eos_slope: 1.49,
        eos_gamma0: 1.96,
    };
    unsafe {
        assert_eq!(
            rkmpm_sim_new(2, origin.as_ptr(), cells.as_ptr(), 1e-3, &mut sim),
            RKMPM_OK
        );
        let mut id = u32::MAX;
        assert_eq!(
            rkmpm_sim_add_material_johnson_cook(sim, null(), &mut id),
            RKMPM_ERR_NULL_POINTER
        );
        assert_eq!(
            rkmpm_sim_add_material_johnson_cook(sim, &jc, &mut id),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert!(last_error().contains("damage_enabled"), "{}", last_error());
        assert_eq!(id, u32::MAX);
        jc.damage_enabled = 1;
        assert_eq!(
            rkmpm_sim_add_material_johnson_cook(sim, &jc, &mut id),
            RKMPM_OK
        );
        assert_eq!(
            rkmpm_sim_set_boundary(sim, 1, -1, RKMPM_BOUNDARY_SLIP, 0.0),
            RKMPM_OK
        );
        let (mut x, mut v) = (Vec::new(), Vec::new());
        for j in 0..16 {
            for i in 0..8 {
                x.extend([
                    10e-3 + 0.5e-3 * i as f64 + 0.25e-3,
                    0.5e-3 * j as f64 + 0.25e-3,
                ]);
                v.extend([0.0, -300.0]);
            }
        }
        let vol = [0.25e-6; 128];
        assert_eq!(
            rkmpm_sim_add_particles(sim, 0, 128, x.as_ptr(), vol.as_ptr(), v.as_ptr()),
            RKMPM_OK
        );
        for _ in 0..300 {
            let mut dt = 0.0;
            assert_eq!(rkmpm_sim_stable_dt(sim, 0.3, &mut dt), RKMPM_OK);
            assert_eq!(rkmpm_sim_step(sim, dt), RKMPM_OK, "{}", last_error());
        }
        let (mut eps, mut damage) = (vec![-1.0; 128], vec![-1.0; 128]);
        assert_eq!(
            rkmpm_sim_get_particles(sim, RKMPM_FIELD_PLASTIC_STRAIN, eps.as_mut_ptr(), 128),
            RKMPM_OK
        );
        assert_eq!(
            rkmpm_sim_get_particles(sim, RKMPM_FIELD_DAMAGE, damage.as_mut_ptr(), 128),
            RKMPM_OK
        );
        assert!(eps.iter().any(|&e| e > 0.05), "no plastic flow");
        assert!(damage.iter().all(|&d| (0.0..=1.0).contains(&d)));
        assert!(damage.iter().any(|&d| d > 0.0), "no damage");
        rkmpm_sim_free(sim);
    }
}

/// Contact and rigid bodies through the C API: bad flags, friction and pointers are refused; a
/// rigid body without contact is refused at the first step; with contact a block falls onto a
/// fixed rigid slab and stays above it.
#[test]
fn contact_and_rigid_bodies_through_the_c_api() {
    let mut sim = null_mut();
    let (origin, cells) = ([0.0, 0.0], [10usize, 20]);
    unsafe {
        assert_eq!(
            rkmpm_sim_new(2, origin.as_ptr(), cells.as_ptr(), 0.05, &mut sim),
            RKMPM_OK
        );
        assert_eq!(
            rkmpm_sim_set_contact(sim, 2, 0.1),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert_eq!(
            rkmpm_sim_set_contact(sim, 1, -0.1),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert!(last_error().contains("friction"), "{}", last_error());
        let mut id = u32::MAX;
        assert_eq!(
            rkmpm_sim_add_material_rigid(sim, 7800.0, null(), &mut id),
            RKMPM_ERR_NULL_POINTER
        );
        let still = [0.0, 0.0];
        assert_eq!(
            rkmpm_sim_add_material_rigid(sim, -1.0, still.as_ptr(), &mut id),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert_eq!(
            rkmpm_sim_add_material_rigid(sim, 7800.0, still.as_ptr(), &mut id),
            RKMPM_OK
        );
        assert_eq!(id, 0);
        let mut soft = u32::MAX;
        assert_eq!(
            rkmpm_sim_add_material_neo_hookean(sim, 1000.0, 1e5, 0.3, &mut soft),
            RKMPM_OK
        );
        let q = 0.025;
        let (mut slab, mut block) = (Vec::new(), Vec::new());
        for j in 0..4 {
            for i in 0..16 {
                slab.extend([0.05 + (i as f64 + 0.5) * q, 0.2 + (j as f64 + 0.5) * q]);
            }
        }
        for j in 0..8 {
            for i in 0..8 {
                block.extend([0.15 + (i as f64 + 0.5) * q, 0.5 + (j as f64 + 0.5) * q]);
            }
        }
        let vol = [q * q; 64];
        assert_eq!(
            rkmpm_sim_add_particles(sim, 0, 64, slab.as_ptr(), vol.as_ptr(), null()),
            RKMPM_OK
        );
        assert_eq!(
            rkmpm_sim_add_particles(sim, soft, 64, block.as_ptr(), vol.as_ptr(), null()),
            RKMPM_OK
        );
        let g = [0.0, -9.81];
        assert_eq!(rkmpm_sim_set_gravity(sim, g.as_ptr()), RKMPM_OK);
        let mut dt = 0.0;
        assert_eq!(rkmpm_sim_stable_dt(sim, 0.3, &mut dt), RKMPM_OK);
        assert_eq!(rkmpm_sim_step(sim, dt), RKMPM_ERR_UNSUPPORTED);
        assert!(last_error().contains("contact"), "{}", last_error());
        assert_eq!(rkmpm_sim_set_contact(sim, 1, 0.3), RKMPM_OK);
        for _ in 0..600 {
            assert_eq!(rkmpm_sim_stable_dt(sim, 0.3, &mut dt), RKMPM_OK);
            assert_eq!(rkmpm_sim_step(sim, dt), RKMPM_OK, "{}", last_error());
        }
        let mut x = vec![0.0; 256];
        assert_eq!(
            rkmpm_sim_get_particles(sim, RKMPM_FIELD_POSITION, x.as_mut_ptr(), 256),
            RKMPM_OK
        );
        assert_eq!(&x[..128], &slab[..], "the rigid slab moved");
        let lowest = (64..128).map(|p| x[2 * p + 1]).fold(1.0, f64::min);
        assert!(lowest > 0.3, "the block sank into the slab: {lowest}");
        // Slide the slab sideways for one step, then hold it: it moves by exactly v dt.
        let slide = [0.5, 0.0];
        assert_eq!(
            rkmpm_sim_set_rigid_velocity(sim, 0, slide.as_ptr()),
            RKMPM_OK
        );
        assert_eq!(rkmpm_sim_step(sim, dt), RKMPM_OK, "{}", last_error());
        assert_eq!(
            rkmpm_sim_set_rigid_velocity(sim, 0, still.as_ptr()),
            RKMPM_OK
        );
        assert_eq!(rkmpm_sim_step(sim, dt), RKMPM_OK, "{}", last_error());
        let mut moved = vec![0.0; 256];
        assert_eq!(
            rkmpm_sim_get_particles(sim, RKMPM_FIELD_POSITION, moved.as_mut_ptr(), 256),
            RKMPM_OK
        );
        for k in 0..128 {
            let expected = slab[k] + if k % 2 == 0 { 0.5 * dt } else { 0.0 };
            assert!(
                (moved[k] - expected).abs() < 1e-15,
                "slab coordinate {k}: {} against {expected}",
                moved[k]
            );
        }
        assert_eq!(
            rkmpm_sim_set_rigid_velocity(sim, soft, slide.as_ptr()),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert!(last_error().contains("not rigid"), "{}", last_error());
        rkmpm_sim_free(sim);
    }
}

/// Checkpoints through the C API: save, load into a new handle and continue gives the same
/// positions bit for bit as continuing the original; a damaged file gives
/// `RKMPM_ERR_CORRUPT_FILE` and no handle; bad pointers are refused.
#[test]
fn checkpoint_through_the_c_api() {
    let dir = std::env::temp_dir().join(format!("rkmpm-c-checkpoint-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = std::ffi::CString::new(dir.join("a.rkmpm").to_str().unwrap()).unwrap();
    let sim = sim2d(true);
    unsafe {
        assert_eq!(rkmpm_sim_save(sim, path.as_ptr()), RKMPM_OK);
        assert_eq!(
            rkmpm_sim_save(null(), path.as_ptr()),
            RKMPM_ERR_NULL_POINTER
        );
        assert_eq!(rkmpm_sim_save(sim, null()), RKMPM_ERR_NULL_POINTER);
        let mut copy = null_mut();
        assert_eq!(rkmpm_sim_load(path.as_ptr(), &mut copy), RKMPM_OK);
        for s in [sim, copy] {
            let mut dt = 0.0;
            assert_eq!(rkmpm_sim_stable_dt(s, 0.3, &mut dt), RKMPM_OK);
            assert_eq!(rkmpm_sim_step(s, dt), RKMPM_OK);
        }
        let (a, b) = (positions(sim), positions(copy));
        assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
        rkmpm_sim_free(copy);
        // Damage one byte in the middle.
        let file = dir.join("a.rkmpm");
        let mut bytes = std::fs::read(&file).unwrap();
        let k = bytes.len() / 2;
        bytes[k] ^= 1;
        std::fs::write(&file, &bytes).unwrap();
        let mut none = std::ptr::dangling_mut::<RkmpmSim>();
        assert_eq!(
            rkmpm_sim_load(path.as_ptr(), &mut none),
            RKMPM_ERR_CORRUPT_FILE
        );
        assert!(none.is_null());
        assert!(last_error().contains("checksum"), "{}", last_error());
        assert_eq!(
            rkmpm_sim_load(path.as_ptr(), null_mut()),
            RKMPM_ERR_NULL_POINTER
        );
        let missing = std::ffi::CString::new(dir.join("none.rkmpm").to_str().unwrap()).unwrap();
        assert_eq!(rkmpm_sim_load(missing.as_ptr(), &mut none), RKMPM_ERR_IO);
        // The message names the file it could not read.
        let message = last_error();
        assert!(
            message.contains("reading the checkpoint") && message.contains("none.rkmpm"),
            "{message}"
        );
        rkmpm_sim_free(sim);
    }
}

/// A simulation's own threads: 0 for one per core, a refused count that changes nothing, two
/// simulations with their own counts stepped at once from two host threads with the bits of one
/// stepped alone, and a checkpoint that does not keep the count.
#[test]
fn threads_through_the_c_api() {
    let dir = std::env::temp_dir().join(format!("rkmpm-c-threads-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = std::ffi::CString::new(dir.join("a.rkmpm").to_str().unwrap()).unwrap();
    unsafe {
        let threads = |s: *const RkmpmSim| {
            let mut n = 0u32;
            assert_eq!(rkmpm_sim_threads(s, &mut n), RKMPM_OK);
            n
        };
        let sim = sim2d(false);
        assert_eq!(threads(sim), rayon::current_num_threads() as u32);
        assert_eq!(rkmpm_sim_set_threads(sim, 0), RKMPM_OK);
        let cores = std::thread::available_parallelism().unwrap().get() as u32;
        assert_eq!(threads(sim), cores);
        assert_eq!(
            rkmpm_sim_set_threads(sim, RKMPM_MAX_THREADS + 1),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        let message = last_error();
        assert!(message.starts_with("rkmpm_sim_set_threads: "), "{message}");
        assert_eq!(threads(sim), cores);
        assert_eq!(rkmpm_sim_threads(sim, null_mut()), RKMPM_ERR_NULL_POINTER);
        assert_eq!(rkmpm_sim_set_threads(sim, 3), RKMPM_OK);
        assert_eq!(rkmpm_sim_save(sim, path.as_ptr()), RKMPM_OK);
        let mut copy = null_mut();
        assert_eq!(rkmpm_sim_load(path.as_ptr(), &mut copy), RKMPM_OK);
        assert_eq!(threads(copy), rayon::current_num_threads() as u32);
        rkmpm_sim_free(copy);
        rkmpm_sim_free(sim);
    }
    // The positions after ten steps of a simulation on `n` threads of its own.
    fn positions(n: u32) -> Vec<f64> {
        unsafe {
            let sim = sim2d(false);
            assert_eq!(rkmpm_sim_set_threads(sim, n), RKMPM_OK);
            assert_eq!(rkmpm_sim_set_gravity(sim, [0.0, -9.81].as_ptr()), RKMPM_OK);
            let mut dt = 0.0;
            assert_eq!(rkmpm_sim_stable_dt(sim, 0.3, &mut dt), RKMPM_OK);
            for _ in 0..10 {
                assert_eq!(rkmpm_sim_step(sim, dt), RKMPM_OK);
            }
            let mut out = vec![0.0; 2 * rkmpm_sim_particle_count(sim)];
            assert_eq!(
                rkmpm_sim_get_particles(sim, RKMPM_FIELD_POSITION, out.as_mut_ptr(), out.len()),
                RKMPM_OK
            );
            rkmpm_sim_free(sim);
            out
        }
    }
    let alone = positions(1);
    let (a, b) = std::thread::scope(|s| {
        let a = s.spawn(|| positions(2));
        let b = s.spawn(|| positions(3));
        (a.join().unwrap(), b.join().unwrap())
    });
    assert!(
        alone == a && alone == b,
        "the thread count changed the positions"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// The found surface's refresh interval: the default, a refused zero that changes nothing, and
/// a checkpoint that keeps it.
#[test]
fn vc_surface_refresh_through_the_c_api() {
    let dir = std::env::temp_dir().join(format!("rkmpm-c-surface-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = std::ffi::CString::new(dir.join("a.rkmpm").to_str().unwrap()).unwrap();
    let sim = sim2d(false);
    unsafe {
        let refresh = |s: *const RkmpmSim| {
            let mut steps = 0u32;
            assert_eq!(rkmpm_sim_vc_surface_refresh(s, &mut steps), RKMPM_OK);
            steps
        };
        assert_eq!(refresh(sim), RKMPM_DEFAULT_VC_SURFACE_REFRESH);
        assert_eq!(
            rkmpm_sim_set_vc_surface_refresh(sim, 0),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        let message = last_error();
        assert!(
            message.starts_with("rkmpm_sim_set_vc_surface_refresh: "),
            "{message}"
        );
        assert_eq!(refresh(sim), 4);
        assert_eq!(
            rkmpm_sim_vc_surface_refresh(sim, null_mut()),
            RKMPM_ERR_NULL_POINTER
        );
        assert_eq!(rkmpm_sim_set_vc_surface_refresh(sim, 7), RKMPM_OK);
        assert_eq!(rkmpm_sim_save(sim, path.as_ptr()), RKMPM_OK);
        let mut copy = null_mut();
        assert_eq!(rkmpm_sim_load(path.as_ptr(), &mut copy), RKMPM_OK);
        assert_eq!(refresh(copy), 7);
        rkmpm_sim_free(copy);
        rkmpm_sim_free(sim);
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The VC solve's stopping rule: the default, a refused rule that changes nothing, and a
/// checkpoint that keeps the rule.
#[test]
fn vc_solve_rule_through_the_c_api() {
    let dir = std::env::temp_dir().join(format!("rkmpm-c-vc-solve-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = std::ffi::CString::new(dir.join("a.rkmpm").to_str().unwrap()).unwrap();
    let sim = sim2d(false);
    unsafe {
        let rule = |s: *const RkmpmSim| {
            let (mut tolerance, mut iterations) = (0.0, 0u64);
            assert_eq!(
                rkmpm_sim_vc_solve(s, &mut tolerance, &mut iterations),
                RKMPM_OK
            );
            (tolerance, iterations)
        };
        assert_eq!(
            rule(sim),
            (
                RKMPM_DEFAULT_VC_SOLVE_TOLERANCE,
                RKMPM_DEFAULT_VC_SOLVE_MAX_ITERATIONS
            )
        );
        assert_eq!(rule(sim), (1e-4, 2000));
        for (tolerance, iterations) in [(0.0, 5), (f64::NAN, 5), (2.0, 5), (1e-6, 0)] {
            assert_eq!(
                rkmpm_sim_set_vc_solve(sim, tolerance, iterations),
                RKMPM_ERR_INVALID_ARGUMENT
            );
            let message = last_error();
            assert!(message.starts_with("rkmpm_sim_set_vc_solve: "), "{message}");
        }
        assert_eq!(rule(sim), (1e-4, 2000));
        let interval = |s: *const RkmpmSim| {
            let mut steps = 0u32;
            assert_eq!(rkmpm_sim_vc_solve_interval(s, &mut steps), RKMPM_OK);
            steps
        };
        // The automatic rule of the default shape, the quadratic B-spline, at order 1.
        assert_eq!(interval(sim), RKMPM_BSPLINE_VC_SOLVE_INTERVAL);
        assert_eq!(
            rkmpm_sim_set_vc_solve_interval(sim, 0),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        let message = last_error();
        assert!(
            message.starts_with("rkmpm_sim_set_vc_solve_interval: ")
                && message.contains("interval must be at least one step"),
            "{message}"
        );
        assert_eq!(
            rkmpm_sim_vc_solve_interval(sim, null_mut()),
            RKMPM_ERR_NULL_POINTER
        );
        assert_eq!(interval(sim), RKMPM_BSPLINE_VC_SOLVE_INTERVAL);
        // The tolerance and the interval are set apart, each keeping the other.
        assert_eq!(rkmpm_sim_set_vc_solve_interval(sim, 3), RKMPM_OK);
        assert_eq!(rkmpm_sim_set_vc_solve(sim, 1e-6, 50), RKMPM_OK);
        assert_eq!(interval(sim), 3);
        assert_eq!(rkmpm_sim_save(sim, path.as_ptr()), RKMPM_OK);
        let mut copy = null_mut();
        assert_eq!(rkmpm_sim_load(path.as_ptr(), &mut copy), RKMPM_OK);
        assert_eq!(rule(copy), (1e-6, 50));
        assert_eq!(interval(copy), 3);
        rkmpm_sim_free(copy);
        rkmpm_sim_free(sim);
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Separate simulations on separate threads at once give the same results as one after another.
#[test]
fn separate_simulations_run_on_separate_threads() {
    struct Handle(*mut RkmpmSim);
    unsafe impl Send for Handle {}
    let run = |h: Handle| unsafe {
        let mut dt = 0.0;
        assert_eq!(rkmpm_sim_stable_dt(h.0, 0.3, &mut dt), RKMPM_OK);
        for _ in 0..20 {
            assert_eq!(rkmpm_sim_step(h.0, dt), RKMPM_OK);
        }
        let x = positions(h.0);
        rkmpm_sim_free(h.0);
        x
    };
    let serial = run(Handle(sim2d(false)));
    let handles: Vec<_> = (0..4)
        .map(|_| {
            let h = Handle(sim2d(false));
            std::thread::spawn(move || run(h))
        })
        .collect();
    for h in handles {
        assert_eq!(h.join().unwrap(), serial);
    }
}

/// The engine sorts its particle storage by grid block; the C API never shows that order. A
/// block added column by column (across the blocks' rows, so the first step sorts it) comes back
/// from `rkmpm_sim_get_particles` in the order it was added: after a few small steps every
/// particle is within a hair of where it was added, and its reference position is exactly it.
#[test]
fn particles_come_back_in_the_order_they_were_added() {
    let mut sim = null_mut();
    let h = 1.0 / 32.0;
    let q = h / 2.0;
    let x: Vec<f64> = (0..32)
        .flat_map(|i| {
            (0..32).flat_map(move |j| [0.25 + (i as f64 + 0.5) * q, 0.25 + (j as f64 + 0.5) * q])
        })
        .collect();
    let n = x.len() / 2;
    unsafe {
        assert_eq!(
            rkmpm_sim_new(2, [0.0, 0.0].as_ptr(), [32usize, 32].as_ptr(), h, &mut sim),
            RKMPM_OK
        );
        let mut id = 0;
        assert_eq!(
            rkmpm_sim_add_material_neo_hookean(sim, 1000.0, 1e5, 0.3, &mut id),
            RKMPM_OK
        );
        let v: Vec<f64> = (0..n).flat_map(|_| [0.1, -0.05]).collect();
        assert_eq!(
            rkmpm_sim_add_particles(sim, id, n, x.as_ptr(), vec![q * q; n].as_ptr(), v.as_ptr()),
            RKMPM_OK
        );
        let mut dt = 0.0;
        assert_eq!(rkmpm_sim_stable_dt(sim, 0.3, &mut dt), RKMPM_OK);
        for _ in 0..5 {
            assert_eq!(rkmpm_sim_step(sim, dt), RKMPM_OK);
        }
        let mut reference = vec![0.0; 2 * n];
        assert_eq!(
            rkmpm_sim_get_particles(
                sim,
                RKMPM_FIELD_REFERENCE_POSITION,
                reference.as_mut_ptr(),
                reference.len()
            ),
            RKMPM_OK
        );
        assert_eq!(reference, x);
        // Five steps at 0.1 m/s move a particle by 5 dt |v| (about 1e-4 m here), far less than
        // the spacing q between neighbours.
        let now = positions(sim);
        let moved = now
            .iter()
            .zip(&x)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(moved < 0.1 * q, "moved {moved:e}, spacing {q:e}");
        rkmpm_sim_free(sim);
    }
}

/// A material with E = 1e300 Pa would have `rkmpm_sim_advance` set out on 1e147 steps. Such a
/// material is refused with its reason, and a run above the bound on the
/// steps of one advance is refused before its first step with the estimate in the message;
/// both leave the simulation as it was.
#[test]
fn absurd_materials_and_runs_are_refused_through_the_c_api() {
    unsafe {
        let sim = sim2d(false);
        let mut id = 77u32;
        assert_eq!(
            rkmpm_sim_add_material_neo_hookean(sim, 1000.0, 1e300, 0.3, &mut id),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        let message = last_error();
        assert!(
            message.starts_with("rkmpm_sim_add_material_neo_hookean: ")
                && message.contains("wave speed")
                && message.contains("exceeds 1e5 m/s"),
            "{message}"
        );
        assert_eq!(id, 77, "a refused material wrote an id");
        // The next material still gets id 1: the refused one used up none.
        assert_eq!(
            rkmpm_sim_add_material_linear_elastic(sim, 1000.0, 1e5, 0.3, &mut id),
            RKMPM_OK
        );
        assert_eq!(id, 1);
        assert_eq!(
            rkmpm_sim_add_material_rigid(sim, 1e-300, [0.0; 2].as_ptr(), &mut id),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert!(
            last_error().contains("below 1e-20 kg/m³"),
            "{}",
            last_error()
        );

        let mut bound = 0u64;
        assert_eq!(rkmpm_sim_max_steps_per_advance(sim, &mut bound), RKMPM_OK);
        assert_eq!(bound, RKMPM_DEFAULT_MAX_STEPS_PER_ADVANCE);
        assert_eq!(bound, 1_000_000_000);

        let before = positions(sim);
        let mut steps = 77u64;
        assert_eq!(
            rkmpm_sim_advance(sim, 1e300, 0.3, &mut steps),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        let message = last_error();
        assert!(
            message.starts_with("rkmpm_sim_advance: ")
                && message.contains("above the bound of 1000000000 steps per advance"),
            "{message}"
        );
        assert_eq!(steps, 0);
        let mut dt = 0.0;
        assert_eq!(rkmpm_sim_stable_dt(sim, 0.3, &mut dt), RKMPM_OK);
        // The estimate in the message is duration / stable step, to its 4 printed digits.
        let estimate = format!("{:.3e}", (1e300 / dt).ceil());
        assert!(message.contains(&estimate), "{message} lacks {estimate}");

        // A bound of 10 steps refuses a run of about 25 and lets it through once raised.
        assert_eq!(
            rkmpm_sim_set_max_steps_per_advance(sim, 0),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert!(last_error().contains("at least 1"), "{}", last_error());
        assert_eq!(rkmpm_sim_set_max_steps_per_advance(sim, 10), RKMPM_OK);
        assert_eq!(
            rkmpm_sim_advance(sim, 24.5 * dt, 0.3, &mut steps),
            RKMPM_ERR_INVALID_ARGUMENT
        );
        assert!(
            last_error().contains("needs about 2.500e1 steps"),
            "{}",
            last_error()
        );
        let mut time = -1.0;
        let mut count = 77u64;
        assert_eq!(rkmpm_sim_time(sim, &mut time), RKMPM_OK);
        assert_eq!(rkmpm_sim_step_count(sim, &mut count), RKMPM_OK);
        assert_eq!((time, count, steps), (0.0, 0, 0));
        assert_eq!(positions(sim), before);
        assert_eq!(rkmpm_sim_set_max_steps_per_advance(sim, 100), RKMPM_OK);
        assert_eq!(rkmpm_sim_advance(sim, 24.5 * dt, 0.3, &mut steps), RKMPM_OK);
        assert_eq!(steps, 25);
        rkmpm_sim_free(sim);
    }
}
