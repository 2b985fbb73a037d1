//! The C API: opaque handles, status codes, a thread-local last-error message, caller-owned
//! arrays. Every exported function runs through [`gate::gate`]: it checks its pointers, lengths and
//! values, never lets a panic cross the boundary, and leaves the simulation unchanged on failure.
//! No physics lives here.
//!
//! Vectors are stored dimension-fastest (`x[p * dim + d]`), which is `x(dim, n)` in Fortran.
//! Thread safety: a simulation may be used by one thread at a time; different simulations may be
//! used from different threads at once. The last-error message is per thread.

#![allow(non_camel_case_types)]
#![allow(clippy::missing_safety_doc)] // every function below has a `# Safety` section
#![deny(unsafe_op_in_unsafe_fn)]
#![deny(clippy::undocumented_unsafe_blocks)]

pub mod gate;
pub mod status;

use gate::{check_ptr, checked_len, gate, kind_of, slice, Failure};
use rkmpm::io::vtk::{self, VtkFormat, VtkSeries};
use rkmpm::material::Material;
use rkmpm::options::{Integration, Scheme, Shape, Side, Transfer, Wall};
use rkmpm::particles::Field;
use rkmpm::sim::{BodyForce, Sim};
use rkmpm::Vector;
pub use status::RkmpmStatus;
use std::ffi::{c_char, c_void, CStr};
use RkmpmStatus::*;

/// Version of the binary interface; changes whenever a signature, a struct or an enum value changes.
pub const RKMPM_ABI_VERSION: u32 = 1;

/// The bound on the steps of one `rkmpm_sim_advance` of a new (or loaded) simulation;
/// `rkmpm_sim_set_max_steps_per_advance` changes it.
pub const RKMPM_DEFAULT_MAX_STEPS_PER_ADVANCE: u64 = 1_000_000_000;
const _: () =
    assert!(RKMPM_DEFAULT_MAX_STEPS_PER_ADVANCE == rkmpm::sim::DEFAULT_MAX_STEPS_PER_ADVANCE);

/// The tolerance of VC's solve of order 1 in a new simulation; at order >= 2 a
/// new simulation's tolerance is 1e-4 on grids of up to 32 cells across and `1e-4 (32 / N)^3`
/// on a grid `N` cells across (`rkmpm_sim_vc_solve` reports it; `rkmpm_sim_set_vc_solve`).
pub const RKMPM_DEFAULT_VC_SOLVE_TOLERANCE: f64 = 1e-4;
/// Every how many steps VC finds the surface of the particles anew in a new simulation
/// (`rkmpm_sim_set_vc_surface_refresh`).
pub const RKMPM_DEFAULT_VC_SURFACE_REFRESH: u32 = 4;
const _: () = assert!(RKMPM_DEFAULT_VC_SURFACE_REFRESH == rkmpm::DEFAULT_VC_SURFACE_REFRESH);
/// Every how many steps VC's solve runs in a new simulation (`rkmpm_sim_set_vc_solve_interval`):
/// at every step, but at order 1 `RKMPM_BSPLINE_VC_SOLVE_INTERVAL` with B-splines and
/// `RKMPM_RK_VC_SOLVE_INTERVAL` with RK shape functions on grids up to
/// `RKMPM_BSPLINE_VC_CARRIED_CELLS` and `RKMPM_RK_VC_CARRIED_CELLS` cells along the widest axis,
/// halved with every doubling of the grid beyond.
pub const RKMPM_DEFAULT_VC_SOLVE_INTERVAL: u32 = 1;
const _: () = assert!(RKMPM_DEFAULT_VC_SOLVE_INTERVAL == rkmpm::VcSolve::DEFAULT.interval);
/// Every how many steps VC's solve of order 1 runs in a new simulation with RK shape functions,
/// the steps between taking the last solve's coefficients.
pub const RKMPM_RK_VC_SOLVE_INTERVAL: u32 = 8;
const _: () = assert!(RKMPM_RK_VC_SOLVE_INTERVAL == rkmpm::VcSolve::RK_INTERVAL);
/// As `RKMPM_RK_VC_SOLVE_INTERVAL`, with the quadratic and cubic B-splines.
pub const RKMPM_BSPLINE_VC_SOLVE_INTERVAL: u32 = 2;
const _: () = assert!(RKMPM_BSPLINE_VC_SOLVE_INTERVAL == rkmpm::VcSolve::BSPLINE_INTERVAL);
/// The widest grid (cells along its widest axis) on which a new simulation with RK shape
/// functions solves VC of order 1 every `RKMPM_RK_VC_SOLVE_INTERVAL` steps.
pub const RKMPM_RK_VC_CARRIED_CELLS: u64 = 256;
const _: () = assert!(RKMPM_RK_VC_CARRIED_CELLS as usize == rkmpm::VcSolve::RK_CARRIED_CELLS);
/// As `RKMPM_RK_VC_CARRIED_CELLS`, with the quadratic and cubic B-splines.
pub const RKMPM_BSPLINE_VC_CARRIED_CELLS: u64 = 256;
const _: () =
    assert!(RKMPM_BSPLINE_VC_CARRIED_CELLS as usize == rkmpm::VcSolve::BSPLINE_CARRIED_CELLS);
/// The iteration bound of VC's solve in a new simulation (`rkmpm_sim_set_vc_solve`).
pub const RKMPM_DEFAULT_VC_SOLVE_MAX_ITERATIONS: u64 = 2000;
const _: () = assert!(
    RKMPM_DEFAULT_VC_SOLVE_TOLERANCE == rkmpm::VcSolve::DEFAULT.tolerance
        && RKMPM_DEFAULT_VC_SOLVE_MAX_ITERATIONS == rkmpm::VcSolve::DEFAULT.max_iterations as u64
);

/// Shape function (`rkmpm_sim_set_shape`).
pub type RkmpmShape = u32;
/// Linear hats (standard MPM).
pub const RKMPM_SHAPE_LINEAR: RkmpmShape = 0;
/// Quadratic B-spline (the default).
pub const RKMPM_SHAPE_BSPLINE2: RkmpmShape = 1;
/// Cubic B-spline.
pub const RKMPM_SHAPE_BSPLINE3: RkmpmShape = 2;
/// Reproducing kernel of basis order `rk_order` (1..5) with normalized support `rk_support` (kernel
/// support in cells; about 2 for order 1, 3 for order 2, 3.5 for order 3). Not with APIC for order >= 2.
pub const RKMPM_SHAPE_RK: RkmpmShape = 3;

/// Integration of the weak form (`rkmpm_sim_set_integration`).
pub type RkmpmIntegration = u32;
/// Material-point integration (the default).
pub const RKMPM_INTEGRATION_MP: RkmpmIntegration = 0;
/// Variationally consistent integration of order `vc_order` (1..4): test-function gradients
/// corrected so the divergence equality of that order holds (needs boundary points; without any,
/// the surface of the particles is found afresh at every step, so a body may break apart).
pub const RKMPM_INTEGRATION_VC: RkmpmIntegration = 1;

/// Particle-grid velocity transfer (`rkmpm_sim_set_transfer`).
pub type RkmpmTransfer = u32;
/// PIC/FLIP blend with FLIP weight `flip_ratio` in [0, 1].
pub const RKMPM_TRANSFER_PIC_FLIP: RkmpmTransfer = 0;
/// Affine particle-in-cell (the default).
pub const RKMPM_TRANSFER_APIC: RkmpmTransfer = 1;
/// Moving-least-squares MPM (Hu et al. 2018): APIC with the MLS gradient in the force and the
/// velocity gradient; quadratic or cubic B-spline only, without VC (else the first step fails
/// with `RKMPM_ERR_UNSUPPORTED`).
pub const RKMPM_TRANSFER_MLS: RkmpmTransfer = 2;

/// Update scheme (`rkmpm_sim_set_scheme`).
pub type RkmpmScheme = u32;
/// Update stress last (the default).
pub const RKMPM_SCHEME_USL: RkmpmScheme = 0;
/// Modified USL: a second momentum map before the velocity gradient.
pub const RKMPM_SCHEME_MUSL: RkmpmScheme = 1;

/// How `rkmpm_sim_write_vtk` and `rkmpm_sim_write_vtk_frame` store the arrays
/// (`rkmpm_sim_set_vtk_format`).
pub type RkmpmVtkFormat = u32;
/// Raw little-endian bytes appended after the XML, as ParaView writes them (the default): exact
/// values; 0.4 to 0.6 of the text's size for moving bodies, larger than the text for bodies at
/// rest (the text writes a zero in three characters).
pub const RKMPM_VTK_BINARY: RkmpmVtkFormat = 0;
/// Numbers as text, each the shortest decimal that reads back to the same value.
pub const RKMPM_VTK_ASCII: RkmpmVtkFormat = 1;

/// Condition on a grid face (`rkmpm_sim_set_boundary`).
pub type RkmpmBoundary = u32;
/// No condition (the default).
pub const RKMPM_BOUNDARY_FREE: RkmpmBoundary = 0;
/// No velocity on the face (mirror treatment).
pub const RKMPM_BOUNDARY_FIXED: RkmpmBoundary = 1;
/// No normal velocity on the face (mirror treatment).
pub const RKMPM_BOUNDARY_SLIP: RkmpmBoundary = 2;
/// Unilateral contact with Coulomb friction `friction`.
pub const RKMPM_BOUNDARY_FRICTION: RkmpmBoundary = 3;

/// Particle quantity (`rkmpm_sim_get_particles`); the comment gives the values per particle.
pub type RkmpmField = u32;
/// dim values: current position.
pub const RKMPM_FIELD_POSITION: RkmpmField = 0;
/// dim values: velocity.
pub const RKMPM_FIELD_VELOCITY: RkmpmField = 1;
/// dim values: position minus reference position.
pub const RKMPM_FIELD_DISPLACEMENT: RkmpmField = 2;
/// dim*dim values: Cauchy stress, row-major.
pub const RKMPM_FIELD_STRESS: RkmpmField = 3;
/// 1 value: pressure -tr(sigma)/3 (plane strain in 2D).
pub const RKMPM_FIELD_PRESSURE: RkmpmField = 4;
/// 1 value: current volume det(F) V0.
pub const RKMPM_FIELD_VOLUME: RkmpmField = 5;
/// 1 value: mass.
pub const RKMPM_FIELD_MASS: RkmpmField = 6;
/// dim values: position at insertion.
pub const RKMPM_FIELD_REFERENCE_POSITION: RkmpmField = 7;
/// dim*dim values: deformation gradient, row-major.
pub const RKMPM_FIELD_DEFORMATION_GRADIENT: RkmpmField = 8;
/// 1 value: equivalent plastic strain (0 for elastic materials).
pub const RKMPM_FIELD_PLASTIC_STRAIN: RkmpmField = 9;
/// 1 value: damage in [0, 1] (Johnson–Cook; 0 for other materials).
pub const RKMPM_FIELD_DAMAGE: RkmpmField = 10;

// The C codes are the discriminants of the option kinds in `options` (and of `Field`), which
// the engine, scene files and checkpoints use; cbindgen needs them as literals, so they are
// checked here when the crate compiles.
const _: () = {
    use rkmpm::options::{
        IntegrationKind as I, ShapeKind as S, TransferKind as T, VtkFormat as V, WallKind as W,
    };
    assert!(RKMPM_SHAPE_LINEAR == S::Linear as u32);
    assert!(RKMPM_SHAPE_BSPLINE2 == S::Bspline2 as u32);
    assert!(RKMPM_SHAPE_BSPLINE3 == S::Bspline3 as u32);
    assert!(RKMPM_SHAPE_RK == S::Rk as u32);
    assert!(RKMPM_INTEGRATION_MP == I::MaterialPoint as u32);
    assert!(RKMPM_INTEGRATION_VC == I::Vc as u32);
    assert!(RKMPM_TRANSFER_PIC_FLIP == T::PicFlip as u32);
    assert!(RKMPM_TRANSFER_APIC == T::Apic as u32);
    assert!(RKMPM_TRANSFER_MLS == T::Mls as u32);
    assert!(RKMPM_SCHEME_USL == Scheme::Usl as u32);
    assert!(RKMPM_SCHEME_MUSL == Scheme::Musl as u32);
    assert!(RKMPM_VTK_BINARY == V::Binary as u32);
    assert!(RKMPM_VTK_ASCII == V::Ascii as u32);
    assert!(RKMPM_BOUNDARY_FREE == W::Free as u32);
    assert!(RKMPM_BOUNDARY_FIXED == W::Fixed as u32);
    assert!(RKMPM_BOUNDARY_SLIP == W::Slip as u32);
    assert!(RKMPM_BOUNDARY_FRICTION == W::Friction as u32);
    assert!(RKMPM_FIELD_POSITION == Field::Position as u32);
    assert!(RKMPM_FIELD_VELOCITY == Field::Velocity as u32);
    assert!(RKMPM_FIELD_DISPLACEMENT == Field::Displacement as u32);
    assert!(RKMPM_FIELD_STRESS == Field::Stress as u32);
    assert!(RKMPM_FIELD_PRESSURE == Field::Pressure as u32);
    assert!(RKMPM_FIELD_VOLUME == Field::Volume as u32);
    assert!(RKMPM_FIELD_MASS == Field::Mass as u32);
    assert!(RKMPM_FIELD_REFERENCE_POSITION == Field::ReferencePosition as u32);
    assert!(RKMPM_FIELD_DEFORMATION_GRADIENT == Field::DeformationGradient as u32);
    assert!(RKMPM_FIELD_PLASTIC_STRAIN == Field::PlasticStrain as u32);
    assert!(RKMPM_FIELD_DAMAGE == Field::Damage as u32);
};

/// Progress of `rkmpm_sim_advance`, called after every one of its steps on the thread that calls
/// it, with `user_data`, the simulation's step count, the time now, the time the run ends at and
/// the step just taken. Return 0 to go on; any other value stops the run after this step with
/// `RKMPM_ERR_CALLBACK` (the steps taken stand). The callback must not call any `rkmpm_sim_*`
/// function on the simulation that is advancing.
pub type RkmpmProgressFn = Option<
    unsafe extern "C" fn(
        user_data: *mut c_void,
        steps: u64,
        time: f64,
        end_time: f64,
        dt: f64,
    ) -> i32,
>;

/// Body force per unit mass, called once per step on the thread that calls `rkmpm_sim_step`, with
/// the time at the start of the step and `count * dim` interleaved arrays, the particles in the
/// order they were added (as `rkmpm_sim_get_particles` gives them, whatever order the engine
/// stores them in). Write the accelerations of every particle into `accelerations` and return 0; any other return value makes the step
/// fail with `RKMPM_ERR_CALLBACK` and leaves the simulation unchanged. The callback must not call
/// any `rkmpm_sim_*` function on the simulation that is stepping.
pub type RkmpmBodyForceFn = Option<
    unsafe extern "C" fn(
        user_data: *mut c_void,
        time: f64,
        count: usize,
        dim: u32,
        reference_positions: *const f64,
        positions: *const f64,
        accelerations: *mut f64,
    ) -> i32,
>;

enum AnySim {
    D2(Sim<2>),
    D3(Sim<3>),
}

/// A simulation. Created by `rkmpm_sim_new`, owned by the caller, released by `rkmpm_sim_free`.
/// One thread at a time may use a simulation; different simulations are independent.
pub struct RkmpmSim {
    sim: AnySim,
    series: Vec<VtkSeries>,
    /// The format of the VTK files written from now on.
    vtk_format: VtkFormat,
    /// The progress callback of `rkmpm_sim_advance` and its user data.
    progress: RkmpmProgressFn,
    progress_data: *mut c_void,
}

macro_rules! with_sim {
    ($handle:expr, $s:ident => $body:expr) => {
        match $handle {
            AnySim::D2($s) => $body,
            AnySim::D3($s) => $body,
        }
    };
}

/// # Safety
/// `sim` must be NULL or a live handle from `rkmpm_sim_new`.
unsafe fn sim_ref<'a>(sim: *const RkmpmSim) -> Result<&'a RkmpmSim, Failure> {
    check_ptr("sim", sim)?;
    // SAFETY: non-NULL and aligned (checked); live by the contract above.
    Ok(unsafe { &*sim })
}

/// # Safety
/// `sim` must be NULL or a live handle from `rkmpm_sim_new`, not used by another thread.
unsafe fn sim_mut<'a>(sim: *mut RkmpmSim) -> Result<&'a mut RkmpmSim, Failure> {
    check_ptr("sim", sim)?;
    // SAFETY: non-NULL and aligned (checked); live and not shared by the contract above.
    Ok(unsafe { &mut *sim })
}

/// # Safety
/// `out` must be NULL or valid for one write of `T`.
unsafe fn write_out<T>(name: &str, out: *mut T, value: T) -> Result<(), Failure> {
    check_ptr(name, out)?;
    // SAFETY: non-NULL and aligned (checked); writable by the contract above.
    unsafe { out.write(value) };
    Ok(())
}

fn vectors<const D: usize>(values: &[f64]) -> Vec<Vector<D>> {
    values
        .chunks_exact(D)
        .map(Vector::<D>::from_column_slice)
        .collect()
}

/// # Safety
/// `path` must be NULL or point to a NUL-terminated string.
unsafe fn c_path<'a>(name: &str, path: *const c_char) -> Result<&'a str, Failure> {
    check_ptr(name, path)?;
    // SAFETY: non-NULL (checked) and NUL-terminated by the contract above.
    unsafe { CStr::from_ptr(path) }.to_str().map_err(|_| {
        Failure::new(
            RKMPM_ERR_INVALID_ARGUMENT,
            format!("{name} is not valid UTF-8"),
        )
    })
}

/// The library version, e.g. `"0.1.0"` (a static string; do not free).
#[no_mangle]
pub extern "C" fn rkmpm_version() -> *const c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr().cast()
}

/// The binary interface version of the library; compare it with `RKMPM_ABI_VERSION` from the
/// header you compiled against.
#[no_mangle]
pub extern "C" fn rkmpm_abi_version() -> u32 {
    RKMPM_ABI_VERSION
}

/// A static description of a status code (`"unknown status"` for a number that is none).
#[no_mangle]
pub extern "C" fn rkmpm_status_str(status: i32) -> *const c_char {
    RkmpmStatus::ALL
        .iter()
        .find(|s| **s as i32 == status)
        .map_or("unknown status\0", |s| s.describe())
        .as_ptr()
        .cast()
}

/// Copies the message of the last failed call on this thread into `buf` (at most `len - 1`
/// bytes and a NUL) and returns the message's full length in bytes, without the NUL (0 when no
/// call on this thread has failed). Messages start with the name of the failed function. `buf`
/// may be NULL when `len` is 0, to ask for the length.
///
/// # Safety
/// `buf` must be valid for `len` bytes of writes when `len > 0`.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_last_error_message(buf: *mut c_char, len: usize) -> usize {
    let message = gate::last_error();
    if len > 0 && !buf.is_null() {
        let n = message.len().min(len - 1);
        // SAFETY: `buf` is non-NULL (checked) and holds `len > n` bytes (this function's
        // `# Safety`); the message is a separate Rust string.
        unsafe {
            std::ptr::copy_nonoverlapping(message.as_ptr(), buf.cast::<u8>(), n);
            *buf.add(n) = 0;
        }
    }
    message.len()
}

/// Creates a simulation on a uniform grid: `dim` (2 or 3), `origin` (`dim` values), `cells`
/// (`dim` cell counts), `cell_size` > 0. Writes the new handle to `*out` (NULL on failure).
/// Defaults: quadratic B-spline, material-point integration, APIC, USL, no gravity, free faces.
///
/// # Safety
/// `origin` and `cells` must point to `dim` values; `out` must be valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_new(
    dim: u32,
    origin: *const f64,
    cells: *const usize,
    cell_size: f64,
    out: *mut *mut RkmpmSim,
) -> RkmpmStatus {
    gate("rkmpm_sim_new", || {
        check_ptr("out", out)?;
        // SAFETY: non-NULL and aligned (checked); writable by this function's `# Safety`.
        unsafe { out.write(std::ptr::null_mut()) };
        if dim != 2 && dim != 3 {
            return Err(Failure::new(
                RKMPM_ERR_INVALID_ARGUMENT,
                format!("dim must be 2 or 3, got {dim}"),
            ));
        }
        let d = dim as usize;
        // SAFETY: the array holds the stated number of values (this function's `# Safety`).
        let origin = unsafe { slice("origin", origin, d) }?;
        // SAFETY: the array holds the stated number of values (this function's `# Safety`).
        let cells = unsafe { slice("cells", cells, d) }?;
        let sim = if d == 2 {
            AnySim::D2(Sim::new(
                Vector::<2>::from_column_slice(origin),
                [cells[0], cells[1]],
                cell_size,
            )?)
        } else {
            AnySim::D3(Sim::new(
                Vector::<3>::from_column_slice(origin),
                [cells[0], cells[1], cells[2]],
                cell_size,
            )?)
        };
        let handle = Box::into_raw(Box::new(RkmpmSim {
            sim,
            series: Vec::new(),
            vtk_format: VtkFormat::default(),
            progress: None,
            progress_data: std::ptr::null_mut(),
        }));
        // SAFETY: as above.
        unsafe { out.write(handle) };
        Ok(())
    })
}

/// Saves the whole simulation state to a checkpoint file at `path` (UTF-8): grid, options,
/// materials, particles with their history, boundary points, time and step count, in a versioned
/// format with a CRC-32 checksum. The file is written under a temporary name and renamed, so an
/// existing checkpoint is replaced only by a complete new one. Not saved: the body-force callback
/// and the VTK series (set them again after loading).
///
/// # Safety
/// `sim` must be a live handle; `path` a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_save(sim: *const RkmpmSim, path: *const c_char) -> RkmpmStatus {
    gate("rkmpm_sim_save", || {
        // SAFETY: `sim` is NULL or a live handle (this function's `# Safety`).
        let s = unsafe { sim_ref(sim) }?;
        // SAFETY: the path is NULL or a NUL-terminated string (this function's `# Safety`).
        let path = unsafe { c_path("path", path) }?;
        with_sim!(&s.sim, m => m.save(path))?;
        Ok(())
    })
}

/// Loads a checkpoint written by `rkmpm_sim_save` into a new handle `*out` (NULL on failure).
/// Continuing it gives the same particle data, bit for bit, as the run that was saved. A
/// truncated or damaged file, or one that is not a checkpoint, gives `RKMPM_ERR_CORRUPT_FILE`;
/// a file that cannot be read `RKMPM_ERR_IO`; a newer format `RKMPM_ERR_UNSUPPORTED`.
///
/// # Safety
/// `path` a NUL-terminated string; `out` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_load(
    path: *const c_char,
    out: *mut *mut RkmpmSim,
) -> RkmpmStatus {
    gate("rkmpm_sim_load", || {
        check_ptr("out", out)?;
        // SAFETY: non-NULL and aligned (checked); writable by this function's `# Safety`.
        unsafe { out.write(std::ptr::null_mut()) };
        // SAFETY: the path is NULL or a NUL-terminated string (this function's `# Safety`).
        let path = unsafe { c_path("path", path) }?;
        let bytes = std::fs::read(path).map_err(|e| {
            rkmpm::Error::new(
                rkmpm::ErrorKind::Io,
                format!("reading the checkpoint {path}: {e}"),
            )
        })?;
        let sim = match rkmpm::io::checkpoint::checkpoint_dimension(&bytes)? {
            2 => AnySim::D2(Sim::<2>::from_checkpoint_bytes(&bytes)?),
            _ => AnySim::D3(Sim::<3>::from_checkpoint_bytes(&bytes)?),
        };
        let handle = Box::into_raw(Box::new(RkmpmSim {
            sim,
            series: Vec::new(),
            vtk_format: VtkFormat::default(),
            progress: None,
            progress_data: std::ptr::null_mut(),
        }));
        // SAFETY: as above.
        unsafe { out.write(handle) };
        Ok(())
    })
}

/// Releases a simulation. NULL is a no-op. The handle must not be used afterwards.
///
/// # Safety
/// `sim` must be NULL or a live handle from `rkmpm_sim_new`, freed once.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_free(sim: *mut RkmpmSim) {
    if !sim.is_null() && sim.is_aligned() {
        // SAFETY: a non-NULL `sim` is a handle from `rkmpm_sim_new` or `rkmpm_sim_load` not freed
        // yet (this function's `# Safety`), so it came from `Box::into_raw`.
        let free = || drop(unsafe { Box::from_raw(sim) });
        let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(free));
    }
}

/// Writes the dimension (2 or 3) to `*out_dim`.
///
/// # Safety
/// `sim` must be a live handle; `out_dim` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_dim(sim: *const RkmpmSim, out_dim: *mut u32) -> RkmpmStatus {
    gate("rkmpm_sim_dim", || {
        // SAFETY: `sim` is NULL or a live handle (this function's `# Safety`).
        let s = unsafe { sim_ref(sim) }?;
        let d = match s.sim {
            AnySim::D2(_) => 2,
            AnySim::D3(_) => 3,
        };
        // SAFETY: the out-pointer is NULL or writable (this function's `# Safety`).
        unsafe { write_out("out_dim", out_dim, d) }
    })
}

/// Chooses the shape function (before the first step). `rk_order` and `rk_support` are read
/// only for `RKMPM_SHAPE_RK`; a support whose moment matrix is singular or badly conditioned for
/// the order is refused with `RKMPM_ERR_INVALID_ARGUMENT`.
///
/// # Safety
/// `sim` must be a live handle.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_set_shape(
    sim: *mut RkmpmSim,
    shape: RkmpmShape,
    rk_order: u32,
    rk_support: f64,
) -> RkmpmStatus {
    gate("rkmpm_sim_set_shape", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        let shape = Shape::from_kind(kind_of("shape", shape)?, rk_order, rk_support);
        with_sim!(&mut s.sim, m => m.set_shape(shape))?;
        Ok(())
    })
}

/// Chooses the integration (before the first step); `vc_order` (1..4) is read only for
/// `RKMPM_INTEGRATION_VC`.
///
/// # Safety
/// `sim` must be a live handle.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_set_integration(
    sim: *mut RkmpmSim,
    integration: RkmpmIntegration,
    vc_order: u32,
) -> RkmpmStatus {
    gate("rkmpm_sim_set_integration", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        let integration = Integration::from_kind(kind_of("integration", integration)?, vc_order);
        with_sim!(&mut s.sim, m => m.set_integration(integration))?;
        Ok(())
    })
}

/// Chooses the velocity transfer (before the first step); `flip_ratio` in [0, 1] is read only
/// for `RKMPM_TRANSFER_PIC_FLIP` (0 is PIC). APIC with RK order >= 2, and MLS with a shape
/// function other than the quadratic or cubic B-spline (or RK1 with support 2, which is the
/// cubic) or with VC, are refused by the first step
/// (`RKMPM_ERR_UNSUPPORTED`), since the options may still be set in either order before it.
///
/// # Safety
/// `sim` must be a live handle.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_set_transfer(
    sim: *mut RkmpmSim,
    transfer: RkmpmTransfer,
    flip_ratio: f64,
) -> RkmpmStatus {
    gate("rkmpm_sim_set_transfer", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        let transfer = Transfer::from_kind(kind_of("transfer", transfer)?, flip_ratio);
        with_sim!(&mut s.sim, m => m.set_transfer(transfer))?;
        Ok(())
    })
}

/// Turns contact between bodies on (`enabled` = 1, Coulomb `friction` >= 0) or off (0), before
/// the first step. With contact every material is a body with its own grid velocity field
/// (Bardenhagen et al. 2000): bodies meet without sticking, slide with friction `friction` and
/// separate freely. Works with USL and with material-point or VC integration (VC corrects each
/// deformable body on its own field, over the surface found from its particles), without given
/// boundary points (else the first step returns `RKMPM_ERR_UNSUPPORTED`).
///
/// # Safety
/// `sim` must be a live handle.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_set_contact(
    sim: *mut RkmpmSim,
    enabled: u32,
    friction: f64,
) -> RkmpmStatus {
    gate("rkmpm_sim_set_contact", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        let on = flag("enabled", enabled)?;
        with_sim!(&mut s.sim, m => m.set_contact(on.then_some(friction)))?;
        Ok(())
    })
}

/// Adds a rigid body material: `density` >= 1e-20 kg/m^3 and the prescribed constant
/// `velocity` (`dim` values). Its particles move with that velocity and do not deform; it needs
/// contact (`rkmpm_sim_set_contact`), through which it pushes the other bodies.
///
/// # Safety
/// `sim` must be a live handle; `velocity` must hold `dim` values; `out_id` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_add_material_rigid(
    sim: *mut RkmpmSim,
    density: f64,
    velocity: *const f64,
    out_id: *mut u32,
) -> RkmpmStatus {
    gate("rkmpm_sim_add_material_rigid", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        check_ptr("out_id", out_id)?;
        let d = with_sim!(&s.sim, m => m.grid().cells().len());
        // SAFETY: the array holds the stated number of values (this function's `# Safety`).
        let v = unsafe { slice("velocity", velocity, d) }?;
        let mut v3 = [0.0; 3];
        v3[..d].copy_from_slice(v);
        let material = Material::rigid(density, v3)?;
        let id = with_sim!(&mut s.sim, m => m.add_material(material));
        // SAFETY: the out-pointer is NULL or writable (this function's `# Safety`).
        unsafe { write_out("out_id", out_id, id) }
    })
}

/// Changes the prescribed velocity of the rigid material `material` (`dim` finite values) for
/// the steps that follow, and its particles' velocity with it: a gate lifted and then held, a
/// piston that stops. Fails for an unknown material (`RKMPM_ERR_UNKNOWN_MATERIAL`), one that is
/// not rigid or a non-finite value, and then changes nothing.
///
/// # Safety
/// `sim` must be a live handle; `velocity` must hold `dim` values.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_set_rigid_velocity(
    sim: *mut RkmpmSim,
    material: u32,
    velocity: *const f64,
) -> RkmpmStatus {
    gate("rkmpm_sim_set_rigid_velocity", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        let d = with_sim!(&s.sim, m => m.grid().cells().len());
        // SAFETY: the array holds the stated number of values (this function's `# Safety`).
        let v = unsafe { slice("velocity", velocity, d) }?;
        let mut v3 = [0.0; 3];
        v3[..d].copy_from_slice(v);
        with_sim!(&mut s.sim, m => m.set_rigid_velocity(material, v3))?;
        Ok(())
    })
}

/// Chooses USL or MUSL (before the first step).
///
/// # Safety
/// `sim` must be a live handle.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_set_scheme(
    sim: *mut RkmpmSim,
    scheme: RkmpmScheme,
) -> RkmpmStatus {
    gate("rkmpm_sim_set_scheme", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        let scheme: Scheme = kind_of("scheme", scheme)?;
        with_sim!(&mut s.sim, m => m.set_scheme(scheme))?;
        Ok(())
    })
}

/// Sets gravity, `dim` finite values (may change between steps).
///
/// # Safety
/// `sim` must be a live handle; `g` must point to `dim` values.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_set_gravity(sim: *mut RkmpmSim, g: *const f64) -> RkmpmStatus {
    gate("rkmpm_sim_set_gravity", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        with_sim!(&mut s.sim, m => {
            // SAFETY: `g` holds `dim` values (this function's `# Safety`).
            let g = unsafe { slice("g", g, m.grid().cells().len()) }?;
            m.set_gravity(Vector::from_column_slice(g))?;
        });
        Ok(())
    })
}

/// Sets the condition on the face `side` (-1 low, +1 high) of `axis` (0 .. dim-1);
/// `friction` (>= 0) is read only for `RKMPM_BOUNDARY_FRICTION`. May change between steps.
///
/// # Safety
/// `sim` must be a live handle.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_set_boundary(
    sim: *mut RkmpmSim,
    axis: u32,
    side: i32,
    kind: RkmpmBoundary,
    friction: f64,
) -> RkmpmStatus {
    gate("rkmpm_sim_set_boundary", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        let side = Side::from_sign(side)?;
        let boundary = Wall::from_kind(kind_of("boundary", kind)?, friction);
        with_sim!(&mut s.sim, m => m.set_wall(axis as usize, side, boundary))?;
        Ok(())
    })
}

/// A C body-force callback with its user data.
struct CBodyForce {
    f: unsafe extern "C" fn(*mut c_void, f64, usize, u32, *const f64, *const f64, *mut f64) -> i32,
    user: *mut c_void,
    buffers: [Vec<f64>; 3],
}

// SAFETY: rkmpm calls the callback only from the thread that calls `rkmpm_sim_step` (or
// `rkmpm_sim_advance`), never from its worker threads and never twice at once (`Sim::step`
// evaluates the body force before the rest of the step goes to the pool); the handle moves
// between threads only as the caller moves it, which the C API documents as the caller's
// business. So `user` is used as the caller would use it.
unsafe impl Send for CBodyForce {}

impl<const D: usize> BodyForce<D> for CBodyForce {
    fn accelerations(
        &mut self,
        time: f64,
        reference: &[Vector<D>],
        current: &[Vector<D>],
        out: &mut [Vector<D>],
    ) -> Result<(), String> {
        let [x0, x, a] = &mut self.buffers;
        x0.clear();
        x0.extend(reference.iter().flat_map(|v| v.iter().copied()));
        x.clear();
        x.extend(current.iter().flat_map(|v| v.iter().copied()));
        a.clear();
        a.resize(x.len(), 0.0);
        // SAFETY: the caller promised `f` is callable with arrays of `count * dim` values.
        let rc = unsafe {
            (self.f)(
                self.user,
                time,
                out.len(),
                D as u32,
                x0.as_ptr(),
                x.as_ptr(),
                a.as_mut_ptr(),
            )
        };
        if rc != 0 {
            return Err(format!("the callback returned {rc}"));
        }
        for (o, v) in out.iter_mut().zip(a.chunks_exact(D)) {
            *o = Vector::<D>::from_column_slice(v);
        }
        Ok(())
    }
}

/// Sets the body-force callback and its `user_data` (passed back unchanged); a NULL `f` removes
/// it. See `RkmpmBodyForceFn` for when and how it is called.
///
/// # Safety
/// `sim` must be a live handle; `f` must stay callable and `user_data` valid while set.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_set_body_force(
    sim: *mut RkmpmSim,
    f: RkmpmBodyForceFn,
    user_data: *mut c_void,
) -> RkmpmStatus {
    gate("rkmpm_sim_set_body_force", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        with_sim!(&mut s.sim, m => m.set_body_force(f.map(|f| {
            Box::new(CBodyForce { f, user: user_data, buffers: Default::default() }) as Box<_>
        })));
        Ok(())
    })
}

/// Sets (or, with `f` NULL, removes) the progress callback of `rkmpm_sim_advance`; see
/// `RkmpmProgressFn`. It is not part of a checkpoint.
///
/// # Safety
/// `sim` must be a live handle; `f` must stay callable and `user_data` valid while set.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_set_progress(
    sim: *mut RkmpmSim,
    f: RkmpmProgressFn,
    user_data: *mut c_void,
) -> RkmpmStatus {
    gate("rkmpm_sim_set_progress", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        s.progress = f;
        s.progress_data = user_data;
        Ok(())
    })
}

/// The body of every `rkmpm_sim_add_material_*`: checks, makes the material, writes its id.
///
/// # Safety
/// `sim` must be NULL or a live handle used by this thread only; `out_id` NULL or writable.
unsafe fn add_material(
    function: &str,
    sim: *mut RkmpmSim,
    out_id: *mut u32,
    make: impl FnOnce() -> rkmpm::Result<Material>,
) -> RkmpmStatus {
    gate(function, || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        check_ptr("out_id", out_id)?;
        let material = make()?;
        let id = with_sim!(&mut s.sim, m => m.add_material(material));
        // SAFETY: the out-pointer is NULL or writable (this function's `# Safety`).
        unsafe { write_out("out_id", out_id, id) }
    })
}

/// Adds a small-strain linear elastic material (density > 0, Young's modulus > 0,
/// -1 < Poisson's ratio < 0.5) and writes its id to `*out_id`. Every material is refused, with
/// its reason, outside any physical range (SI units): a density below 1e-20 kg/m^3, or a
/// dilatational wave speed `sqrt((lambda + 2 mu) / density)` above 1e5 m/s (the fastest solid,
/// diamond, is about 1.8e4 m/s), whose stable step no run could get through.
///
/// # Safety
/// `sim` must be a live handle; `out_id` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_add_material_linear_elastic(
    sim: *mut RkmpmSim,
    density: f64,
    young: f64,
    poisson: f64,
    out_id: *mut u32,
) -> RkmpmStatus {
    // SAFETY: `sim` and `out_id` as `add_material` requires (this function's `# Safety`).
    unsafe {
        add_material("rkmpm_sim_add_material_linear_elastic", sim, out_id, || {
            Material::linear_elastic(density, young, poisson)
        })
    }
}

/// Adds a compressible neo-Hookean material (same arguments as the linear elastic one).
///
/// # Safety
/// `sim` must be a live handle; `out_id` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_add_material_neo_hookean(
    sim: *mut RkmpmSim,
    density: f64,
    young: f64,
    poisson: f64,
    out_id: *mut u32,
) -> RkmpmStatus {
    // SAFETY: `sim` and `out_id` as `add_material` requires (this function's `# Safety`).
    unsafe {
        add_material("rkmpm_sim_add_material_neo_hookean", sim, out_id, || {
            Material::neo_hookean(density, young, poisson)
        })
    }
}

/// Adds a Drucker–Prager soil (Hencky elasticity, return mapping with apex, non-associated
/// flow, fitted to Mohr–Coulomb in plane strain): `density`, `young` > 0, `poisson` in (-1, 0.5),
/// `friction_angle` in [0, 90) degrees, `cohesion` >= 0 (Pa, not both zero with the friction),
/// `dilatancy_angle` in [0, friction_angle] degrees. Its particles carry the field
/// `RKMPM_FIELD_PLASTIC_STRAIN`.
///
/// # Safety
/// `sim` must be a live handle; `out_id` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_add_material_drucker_prager(
    sim: *mut RkmpmSim,
    density: f64,
    young: f64,
    poisson: f64,
    friction_angle: f64,
    cohesion: f64,
    dilatancy_angle: f64,
    out_id: *mut u32,
) -> RkmpmStatus {
    // SAFETY: `sim` and `out_id` as `add_material` requires (this function's `# Safety`).
    unsafe {
        add_material("rkmpm_sim_add_material_drucker_prager", sim, out_id, || {
            Material::drucker_prager(
                density,
                young,
                poisson,
                friction_angle,
                cohesion,
                dilatancy_angle,
            )
        })
    }
}

/// Gives the Drucker–Prager material `material` the μ(I) rate dependence of its friction
/// (`enabled` = 1) or takes it away (0); may change between steps. The friction on
/// `sqrt(J2)/p` rises from the static value by `Δμ I/(I_0 + I)` (`Δμ = friction_increase`,
/// `I_0 = reference_inertial_number`), with the inertial number
/// `I = γ̇ grain_diameter / sqrt(p/ρ)` of the plastic shear rate `γ̇`. With `enabled` = 1: `friction_increase` >= 0, `reference_inertial_number` > 0 and
/// `grain_diameter` > 0 (m), all finite. Fails for an unknown material or one that is not
/// Drucker–Prager.
///
/// # Safety
/// `sim` must be a live handle.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_set_drucker_prager_rheology(
    sim: *mut RkmpmSim,
    material: u32,
    enabled: u32,
    friction_increase: f64,
    reference_inertial_number: f64,
    grain_diameter: f64,
) -> RkmpmStatus {
    gate("rkmpm_sim_set_drucker_prager_rheology", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        let on = flag("enabled", enabled)?;
        let rheology = if on {
            Some(rkmpm::material::InertialRheology::new(
                friction_increase,
                reference_inertial_number,
                grain_diameter,
            )?)
        } else {
            None
        };
        with_sim!(&mut s.sim, m => m.set_rheology(material, rheology))?;
        Ok(())
    })
}

/// Johnson–Cook metal for `rkmpm_sim_add_material_johnson_cook` (SI units, temperatures in
/// kelvin). Yield stress `(a + b ε̄^n)(1 + c ln max(ε̇/reference_strain_rate, 1))(1 − T*^m)`,
/// `T* = (T − room_temperature)/(melt_temperature − room_temperature)`; adiabatic heating
/// `ΔT = taylor_quinney σ_y Δε̄ / (density specific_heat)`.
/// With `damage_enabled = 1`, Johnson–Cook damage with `d1 … d5`: at `D = 1` a particle keeps
/// no deviatoric stress and no tension (`RKMPM_FIELD_DAMAGE` reads `D`).
/// With `eos_enabled = 1`, the pressure follows Mie–Grüneisen (`eos_sound_speed` c0, `eos_slope`
/// s, `eos_gamma0` Γ0); with 0, Hencky's `p = −K ln J`.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct RkmpmJohnsonCook {
    pub density: f64,
    pub young: f64,
    pub poisson: f64,
    pub a: f64,
    pub b: f64,
    pub n: f64,
    pub c: f64,
    pub reference_strain_rate: f64,
    pub m: f64,
    pub room_temperature: f64,
    pub melt_temperature: f64,
    pub specific_heat: f64,
    pub taylor_quinney: f64,
    /// 0 or 1.
    pub damage_enabled: u32,
    pub d1: f64,
    pub d2: f64,
    pub d3: f64,
    pub d4: f64,
    pub d5: f64,
    /// 0 or 1.
    pub eos_enabled: u32,
    pub eos_sound_speed: f64,
    pub eos_slope: f64,
    pub eos_gamma0: f64,
}

fn flag(name: &str, value: u32) -> Result<bool, Failure> {
    match value {
        0 => Ok(false),
        1 => Ok(true),
        _ => Err(rkmpm::Error::invalid(format!("{name} must be 0 or 1, got {value}")).into()),
    }
}

/// Adds a Johnson–Cook metal described by `*parameters` (see `RkmpmJohnsonCook`); its particles
/// carry `RKMPM_FIELD_PLASTIC_STRAIN` and `RKMPM_FIELD_DAMAGE`.
///
/// # Safety
/// `sim` must be a live handle; `parameters` valid for a read; `out_id` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_add_material_johnson_cook(
    sim: *mut RkmpmSim,
    parameters: *const RkmpmJohnsonCook,
    out_id: *mut u32,
) -> RkmpmStatus {
    gate("rkmpm_sim_add_material_johnson_cook", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        check_ptr("parameters", parameters)?;
        check_ptr("out_id", out_id)?;
        // SAFETY: non-NULL and aligned (checked); readable by this function's `# Safety`.
        let p = unsafe { *parameters };
        let damage = flag("damage_enabled", p.damage_enabled)?;
        let eos = flag("eos_enabled", p.eos_enabled)?;
        let material = Material::johnson_cook(rkmpm::material::JohnsonCookParameters {
            density: p.density,
            young: p.young,
            poisson: p.poisson,
            a: p.a,
            b: p.b,
            n: p.n,
            c: p.c,
            reference_strain_rate: p.reference_strain_rate,
            m: p.m,
            room_temperature: p.room_temperature,
            melt_temperature: p.melt_temperature,
            specific_heat: p.specific_heat,
            taylor_quinney: p.taylor_quinney,
            damage: damage.then_some([p.d1, p.d2, p.d3, p.d4, p.d5]),
            eos: eos.then_some(rkmpm::material::MieGruneisen {
                sound_speed: p.eos_sound_speed,
                slope: p.eos_slope,
                gamma0: p.eos_gamma0,
            }),
        })?;
        let id = with_sim!(&mut s.sim, m => m.add_material(material));
        // SAFETY: the out-pointer is NULL or writable (this function's `# Safety`).
        unsafe { write_out("out_id", out_id, id) }
    })
}

/// Adds `count` particles of `material`: `positions` (`count * dim`, inside the grid),
/// `volumes` (`count`, > 0), `velocities` (`count * dim`, or NULL for rest). All or nothing.
///
/// # Safety
/// `sim` must be a live handle; the arrays must hold the stated number of values.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_add_particles(
    sim: *mut RkmpmSim,
    material: u32,
    count: usize,
    positions: *const f64,
    volumes: *const f64,
    velocities: *const f64,
) -> RkmpmStatus {
    gate("rkmpm_sim_add_particles", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        // SAFETY: the arrays hold `count` particles' values (this function's `# Safety`).
        with_sim!(&mut s.sim, m => unsafe {
            add_particles(m, material, count, positions, volumes, velocities)
        })
    })
}

/// # Safety
/// `positions` (and `velocities`, when not NULL) must hold `count · D` values and `volumes`
/// `count` values.
unsafe fn add_particles<const D: usize>(
    m: &mut Sim<D>,
    material: u32,
    count: usize,
    positions: *const f64,
    volumes: *const f64,
    velocities: *const f64,
) -> Result<(), Failure> {
    let n = checked_len("count", count, D)?;
    // SAFETY: the array holds the stated number of values (this function's `# Safety`).
    let x = vectors::<D>(unsafe { slice("positions", positions, n) }?);
    // SAFETY: the array holds the stated number of values (this function's `# Safety`).
    let vol = unsafe { slice("volumes", volumes, count) }?;
    let v = if velocities.is_null() {
        None
    } else {
        // SAFETY: the array holds the stated number of values (this function's `# Safety`).
        Some(vectors::<D>(unsafe { slice("velocities", velocities, n) }?))
    };
    m.add_particles(material, &x, vol, v.as_deref())?;
    Ok(())
}

/// Adds `count` boundary points: `positions` (`count * dim`, on the material's surface, inside the
/// grid), `area_normals` (`count * dim`, outward normal times area; length in 2D; non-zero) and
/// `tractions` (`count * dim`, force per current area, or NULL for none). They move with the grid,
/// update their normals by Nanson's formula, carry the tractions and close VC integration's
/// divergence equality. All or nothing. Without any, VC finds the surface of the particles at
/// every step.
///
/// # Safety
/// `sim` must be a live handle; the arrays must hold the stated number of values.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_add_boundary_points(
    sim: *mut RkmpmSim,
    count: usize,
    positions: *const f64,
    area_normals: *const f64,
    tractions: *const f64,
) -> RkmpmStatus {
    gate("rkmpm_sim_add_boundary_points", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        // SAFETY: the arrays hold `count` points' values (this function's `# Safety`).
        with_sim!(&mut s.sim, m => unsafe {
            add_boundary_points(m, count, positions, area_normals, tractions)
        })
    })
}

/// # Safety
/// `positions`, `area_normals` (and `tractions`, when not NULL) must hold `count · D` values.
unsafe fn add_boundary_points<const D: usize>(
    m: &mut Sim<D>,
    count: usize,
    positions: *const f64,
    area_normals: *const f64,
    tractions: *const f64,
) -> Result<(), Failure> {
    let n = checked_len("count", count, D)?;
    // SAFETY: the array holds the stated number of values (this function's `# Safety`).
    let x = vectors::<D>(unsafe { slice("positions", positions, n) }?);
    // SAFETY: the array holds the stated number of values (this function's `# Safety`).
    let na = vectors::<D>(unsafe { slice("area_normals", area_normals, n) }?);
    let t = if tractions.is_null() {
        None
    } else {
        // SAFETY: the array holds the stated number of values (this function's `# Safety`).
        Some(vectors::<D>(unsafe { slice("tractions", tractions, n) }?))
    };
    m.add_boundary_points(&x, &na, t.as_deref())?;
    Ok(())
}

/// Writes to `*out_count` the number of boundary points VC integrated over in the last step: the
/// given ones, or without any those found on the surface of the particles at the start of that
/// step (0 before the first step).
///
/// # Safety
/// `sim` must be a live handle; `out_count` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_boundary_point_count(
    sim: *const RkmpmSim,
    out_count: *mut usize,
) -> RkmpmStatus {
    gate("rkmpm_sim_boundary_point_count", || {
        // SAFETY: `sim` is NULL or a live handle (this function's `# Safety`).
        let s = unsafe { sim_ref(sim) }?;
        let count = with_sim!(&s.sim, m => m.vc_surface().len());
        // SAFETY: the out-pointer is NULL or writable (this function's `# Safety`).
        unsafe { write_out("out_count", out_count, count) }
    })
}

/// Writes `cfl · h / max_p(c_p + |v_p|)` to `*out_dt`; `cfl` in (0, 1] (0.2 to 0.5 is usual).
/// With no particles there is no wave speed: `RKMPM_ERR_INVALID_STATE`.
///
/// # Safety
/// `sim` must be a live handle; `out_dt` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_stable_dt(
    sim: *const RkmpmSim,
    cfl: f64,
    out_dt: *mut f64,
) -> RkmpmStatus {
    gate("rkmpm_sim_stable_dt", || {
        // SAFETY: `sim` is NULL or a live handle (this function's `# Safety`).
        let s = unsafe { sim_ref(sim) }?;
        check_ptr("out_dt", out_dt)?;
        let dt = with_sim!(&s.sim, m => m.stable_dt(cfl))?;
        // SAFETY: the out-pointer is NULL or writable (this function's `# Safety`).
        unsafe { write_out("out_dt", out_dt, dt) }
    })
}

/// Advances by `dt`. On failure (`dt` above the critical step, a callback failure, a non-finite
/// value, an inverted particle, a particle leaving the grid) the simulation keeps its last good
/// state and the message names the particle and the step.
///
/// # Safety
/// `sim` must be a live handle.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_step(sim: *mut RkmpmSim, dt: f64) -> RkmpmStatus {
    gate("rkmpm_sim_step", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        with_sim!(&mut s.sim, m => m.step(dt))?;
        Ok(())
    })
}

/// Advances by `duration` (> 0) with adaptive steps: before every step the stable step is
/// recomputed from the current state and `cfl` (in `(0, 1]`) times it is taken, shortened at
/// the end so that the run ends at `time + duration` exactly. Writes the number of steps taken
/// to `*out_steps` when `out_steps` is not NULL (also on failure).
///
/// Each step is all or nothing: on failure the simulation keeps the state after the last good
/// step (earlier steps of this call stay taken) and the message says how many steps were taken
/// and where it stopped. Invalid `duration` or `cfl` change nothing.
///
/// The steps of one call are bounded (`rkmpm_sim_set_max_steps_per_advance`, default
/// `RKMPM_DEFAULT_MAX_STEPS_PER_ADVANCE`, 10^9): a run whose estimate `duration /
/// stable_dt(cfl)` exceeds the bound is refused before its first step with
/// `RKMPM_ERR_INVALID_ARGUMENT` and a message giving the estimate (nothing changes); a run whose
/// stable step shrinks on the way stops with the same status once it has taken the bound's
/// number of steps (they stay taken). To stop a run earlier by its own measure (wall time, a
/// cancel request), a host returns non-zero from the progress callback (`rkmpm_sim_set_progress`).
///
/// # Safety
/// `sim` must be a live handle; `out_steps` NULL or valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_advance(
    sim: *mut RkmpmSim,
    duration: f64,
    cfl: f64,
    out_steps: *mut u64,
) -> RkmpmStatus {
    gate("rkmpm_sim_advance", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        if !out_steps.is_null() {
            check_ptr("out_steps", out_steps)?;
        }
        let before = with_sim!(&s.sim, m => m.steps());
        let (progress, user) = (s.progress, s.progress_data);
        let observe = |p: rkmpm::sim::Progress| match progress {
            // SAFETY: the caller promised the callback stays callable with its user data.
            Some(f) => unsafe { f(user, p.steps, p.time, p.end, p.dt) == 0 },
            None => true,
        };
        let result =
            with_sim!(&mut s.sim, m => m.advance_observed(duration, cfl, &mut |_, p| observe(p)));
        if !out_steps.is_null() {
            // SAFETY: checked non-NULL and aligned; the caller promises it is writable.
            unsafe { out_steps.write(with_sim!(&s.sim, m => m.steps()) - before) };
        }
        result?;
        Ok(())
    })
}

/// Bounds the steps one `rkmpm_sim_advance` may take: `max_steps` >= 1 (default
/// `RKMPM_DEFAULT_MAX_STEPS_PER_ADVANCE`, 10^9; `UINT64_MAX` for no practical bound). Raise it
/// for a run meant to be that long. May change between steps; not part of a checkpoint (a loaded
/// simulation has the default).
///
/// # Safety
/// `sim` must be a live handle.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_set_max_steps_per_advance(
    sim: *mut RkmpmSim,
    max_steps: u64,
) -> RkmpmStatus {
    gate("rkmpm_sim_set_max_steps_per_advance", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        with_sim!(&mut s.sim, m => m.set_max_steps_per_advance(max_steps))?;
        Ok(())
    })
}

/// Writes the bound on the steps of one `rkmpm_sim_advance` to `*out_max_steps`.
///
/// # Safety
/// `sim` must be a live handle; `out_max_steps` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_max_steps_per_advance(
    sim: *const RkmpmSim,
    out_max_steps: *mut u64,
) -> RkmpmStatus {
    gate("rkmpm_sim_max_steps_per_advance", || {
        // SAFETY: `sim` is NULL or a live handle (this function's `# Safety`).
        let s = unsafe { sim_ref(sim) }?;
        let max = with_sim!(&s.sim, m => m.max_steps_per_advance());
        // SAFETY: the out-pointer is NULL or writable (this function's `# Safety`).
        unsafe { write_out("out_max_steps", out_max_steps, max) }
    })
}

/// Sets the stopping rule of VC's conservative solve (`RKMPM_INTEGRATION_VC`): conjugate
/// gradients stop when the preconditioned residual has fallen to `tolerance` (in (0, 1]) of the
/// right-hand side's, or after `max_iterations` (>= 1). Without it a simulation takes the
/// automatic rule for its VC order and grid: at order 1 `RKMPM_DEFAULT_VC_SOLVE_TOLERANCE`
/// (1e-4: the convergence study's errors within 0.2 % of the exact solve's) and
/// `RKMPM_DEFAULT_VC_SOLVE_MAX_ITERATIONS` (2000); at order >= 2 1e-4 on grids of up to 32 cells
/// across, falling as `(32 / N)^3` on a grid `N` cells across, which keeps the study's errors
/// within 1 % of the exact solve's at a quarter to a half of its iterations
/// (`rkmpm_sim_vc_solve` reports the rule in force). 1e-12 is the exact solve, the divergence
/// equalities to round-off; loose rules break mirror symmetry (docs/convergence/FINDINGS.md). Linear and angular momentum are conserved whatever
/// the rule. May change between steps; part of a checkpoint. A refused rule changes nothing.
///
/// # Safety
/// `sim` must be a live handle.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_set_vc_solve(
    sim: *mut RkmpmSim,
    tolerance: f64,
    max_iterations: u64,
) -> RkmpmStatus {
    gate("rkmpm_sim_set_vc_solve", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        with_sim!(&mut s.sim, m => m.set_vc_solve(rkmpm::VcSolve {
            tolerance,
            max_iterations: usize::try_from(max_iterations).unwrap_or(usize::MAX),
            ..m.vc_solve()
        }))?;
        Ok(())
    })
}

/// Sets every how many steps VC's conservative solve runs (`RKMPM_INTEGRATION_VC`): every
/// `steps` >= 1 steps, the steps between taking the last solve's coefficients, carried by grid
/// node (the next solve starts from them); 1 solves at every step. Order 1 only, without
/// contact: VC of order >= 2 and the bodies' corrections under contact solve at every step.
/// Between solves the coefficients go on along the line through the last two solves and, on
/// grids wider than 64 cells across, take sweeps on the step's own system (two with B-splines,
/// one with RK shape functions). Without
/// it a simulation solves at every step (`RKMPM_DEFAULT_VC_SOLVE_INTERVAL`), but at order 1
/// every `RKMPM_BSPLINE_VC_SOLVE_INTERVAL` (2) steps with B-splines and
/// `RKMPM_RK_VC_SOLVE_INTERVAL` (8) with RK shape functions on grids up to
/// `RKMPM_BSPLINE_VC_CARRIED_CELLS` (256) and `RKMPM_RK_VC_CARRIED_CELLS` (256) cells across,
/// halved with every doubling of the grid beyond, the convergence study's errors within 1 % of
/// a solve at every step (docs/convergence/FINDINGS.md). Linear and
/// angular momentum are conserved whatever the interval. Keeps the tolerance and the
/// iteration bound in force (`rkmpm_sim_set_vc_solve`). May change between steps; part of a
/// checkpoint, with the carried coefficients. A refused value changes nothing.
///
/// # Safety
/// `sim` must be a live handle.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_set_vc_solve_interval(
    sim: *mut RkmpmSim,
    steps: u32,
) -> RkmpmStatus {
    gate("rkmpm_sim_set_vc_solve_interval", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        with_sim!(&mut s.sim, m => m.set_vc_solve(rkmpm::VcSolve {
            interval: steps,
            ..m.vc_solve()
        }))?;
        Ok(())
    })
}

/// Writes every how many steps VC's solve runs (`rkmpm_sim_set_vc_solve_interval`: the interval
/// given, or the automatic rule's) to `*out_steps`.
///
/// # Safety
/// `sim` must be a live handle; `out_steps` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_vc_solve_interval(
    sim: *const RkmpmSim,
    out_steps: *mut u32,
) -> RkmpmStatus {
    gate("rkmpm_sim_vc_solve_interval", || {
        // SAFETY: `sim` is NULL or a live handle (this function's `# Safety`).
        let s = unsafe { sim_ref(sim) }?;
        let steps = with_sim!(&s.sim, m => m.vc_solve().interval);
        // SAFETY: the out-pointer is NULL or writable (this function's `# Safety`).
        unsafe { write_out("out_steps", out_steps, steps) }
    })
}

/// Sets every how many steps VC finds the surface of the particles anew (VC without given
/// boundary points, without contact): every `steps` >= 1 steps, the grid carrying the surface
/// between like given boundary points; 1 finds it at every step. Default
/// `RKMPM_DEFAULT_VC_SURFACE_REFRESH` (4: a quarter of the cost of finding it at every step,
/// errors within a few per cent either way, docs/convergence/FINDINGS.md). May change between
/// steps; part of a checkpoint, with the carried surface. A refused value changes nothing.
///
/// # Safety
/// `sim` must be a live handle.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_set_vc_surface_refresh(
    sim: *mut RkmpmSim,
    steps: u32,
) -> RkmpmStatus {
    gate("rkmpm_sim_set_vc_surface_refresh", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        with_sim!(&mut s.sim, m => m.set_vc_surface_refresh(steps))?;
        Ok(())
    })
}

/// Writes every how many steps VC finds the surface anew (`rkmpm_sim_set_vc_surface_refresh`)
/// to `*out_steps`.
///
/// # Safety
/// `sim` must be a live handle; `out_steps` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_vc_surface_refresh(
    sim: *const RkmpmSim,
    out_steps: *mut u32,
) -> RkmpmStatus {
    gate("rkmpm_sim_vc_surface_refresh", || {
        // SAFETY: `sim` is NULL or a live handle (this function's `# Safety`).
        let s = unsafe { sim_ref(sim) }?;
        let steps = with_sim!(&s.sim, m => m.vc_surface_refresh());
        // SAFETY: the out-pointer is NULL or writable (this function's `# Safety`).
        unsafe { write_out("out_steps", out_steps, steps) }
    })
}

/// The most worker threads `rkmpm_sim_set_threads` starts for one simulation.
pub const RKMPM_MAX_THREADS: u32 = 4096;
const _: () = assert!(RKMPM_MAX_THREADS as usize == rkmpm::MAX_THREADS);

/// Gives the simulation its own `threads` worker threads (0: one per core the process may use),
/// on which its steps run whatever other simulations or the host's threads do. Until this is
/// called a simulation runs on the library's process-wide pool (`RAYON_NUM_THREADS` threads,
/// or one per core), shared by every simulation. Results are the same to the last bit for any
/// count. Two simulations may step at once on two host threads, each on its own threads. May
/// change between steps; not part of a checkpoint (a loaded simulation takes the shared
/// pool). Refuses more than `RKMPM_MAX_THREADS` (`RKMPM_ERR_INVALID_ARGUMENT`); threads the
/// system cannot start give `RKMPM_ERR_OUT_OF_MEMORY`; a refused call changes nothing.
///
/// # Safety
/// `sim` must be a live handle.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_set_threads(sim: *mut RkmpmSim, threads: u32) -> RkmpmStatus {
    gate("rkmpm_sim_set_threads", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        with_sim!(&mut s.sim, m => m.set_threads(threads as usize))?;
        Ok(())
    })
}

/// Writes the number of worker threads the simulation's steps run on (`rkmpm_sim_set_threads`,
/// or the size of the shared pool) to `*out_threads`.
///
/// # Safety
/// `sim` must be a live handle; `out_threads` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_threads(
    sim: *const RkmpmSim,
    out_threads: *mut u32,
) -> RkmpmStatus {
    gate("rkmpm_sim_threads", || {
        // SAFETY: `sim` is NULL or a live handle (this function's `# Safety`).
        let s = unsafe { sim_ref(sim) }?;
        let threads = with_sim!(&s.sim, m => m.threads());
        // SAFETY: the out-pointer is NULL or writable (this function's `# Safety`).
        unsafe { write_out("out_threads", out_threads, threads as u32) }
    })
}

/// Writes the stopping rule of VC's solve in force (`rkmpm_sim_set_vc_solve`: the one given, or the
/// automatic rule for the simulation's VC order and grid) to `*out_tolerance` and
/// `*out_max_iterations`; neither is written unless both pointers are valid.
///
/// # Safety
/// `sim` must be a live handle; `out_tolerance` and `out_max_iterations` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_vc_solve(
    sim: *const RkmpmSim,
    out_tolerance: *mut f64,
    out_max_iterations: *mut u64,
) -> RkmpmStatus {
    gate("rkmpm_sim_vc_solve", || {
        // SAFETY: `sim` is NULL or a live handle (this function's `# Safety`).
        let s = unsafe { sim_ref(sim) }?;
        check_ptr("out_tolerance", out_tolerance)?;
        check_ptr("out_max_iterations", out_max_iterations)?;
        let solve = with_sim!(&s.sim, m => m.vc_solve());
        // SAFETY: both out-pointers are checked non-NULL and aligned, and writable by this
        // function's `# Safety`.
        unsafe {
            write_out("out_tolerance", out_tolerance, solve.tolerance)?;
            write_out(
                "out_max_iterations",
                out_max_iterations,
                solve.max_iterations as u64,
            )
        }
    })
}

/// The energies of the particles at one instant (per unit thickness in 2D), from
/// `rkmpm_sim_energies`. Their sum changes over a run by what it dissipated (plastic work and
/// damage, friction and impacts at walls, contact, the transfer's and the time integration's
/// numerical dissipation) and by the work of a body-force callback; none of these is included.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RkmpmEnergies {
    /// `1/2 sum m_p |v_p|^2`.
    pub kinetic: f64,
    /// `sum V0_p W(F_p)`: the stored (elastic) energy of every material.
    pub stored: f64,
    /// `-sum m_p g.x_p`: the potential of the gravity set now, zero at the coordinates' origin.
    pub gravitational: f64,
}

/// The particles' momenta at one instant (per unit thickness in 2D), from `rkmpm_sim_momenta`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RkmpmMomenta {
    /// `sum m_p v_p` (the third component 0 in 2D).
    pub linear: [f64; 3],
    /// `sum m_p x_p x v_p` about the origin (in 2D only the third component is not 0), plus,
    /// under APIC and MLS with a B-spline or RK1 with support 2, the angular momentum the
    /// particles' affine velocities carry (Jiang et al. 2015), `sum m_p d eps : C_p` with
    /// `d = h^2/4` (quadratic) or `h^2/3` (cubic, and RK1 with support 2, which is the cubic):
    /// the total the transfers conserve.
    pub angular: [f64; 3],
}

/// Where a run's energy went since the accounting started (`rkmpm_sim_set_energy_accounting`;
/// per unit thickness in 2D), from `rkmpm_sim_energy_balance`. The balance
/// `kinetic + stored + gravitational = start + external_work - material_dissipation -
/// friction_dissipation - contact_dissipation - other_dissipation` holds by the definition of
/// `other_dissipation`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RkmpmEnergyBalance {
    /// The energies now, as `rkmpm_sim_energies` gives them.
    pub kinetic: f64,
    pub stored: f64,
    pub gravitational: f64,
    /// The total energy when the accounting started, plus what the caller gave since
    /// (particles added, a rigid body's velocity or gravity changed).
    pub start: f64,
    /// The work of the body-force callback and of the boundary points' tractions.
    pub external_work: f64,
    /// The work of the stresses, `sum V0 (P^n + P^{n+1})/2 : (F^{n+1} - F^n)` over the steps.
    pub stress_work: f64,
    /// The stress work less the change of the stored energy: what plasticity and damage
    /// dissipated (for an elastic material, the trapezoidal rule's error, O(dt^2) over a run).
    pub material_dissipation: f64,
    /// The friction walls' work on the slip, `sum m_I (v_I - v_I*).v_I*` over the nodes they
    /// changed (`v*` the velocity they leave) and the steps.
    pub friction_dissipation: f64,
    /// The same sum for the contact correction at the nodes bodies share: the contact
    /// friction's work on the slip (0 to round-off without friction), less the work of a rigid
    /// body pushing a deformable one.
    pub contact_dissipation: f64,
    /// The rest: the normal loss of impacts (on walls and between bodies), and the scheme's
    /// numerical dissipation (the transfer's and the time integration's).
    pub other_dissipation: f64,
}

/// Writes the kinetic, stored and gravitational energies of the particles to `*out`.
///
/// # Safety
/// `sim` must be a live handle; `out` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_energies(
    sim: *const RkmpmSim,
    out: *mut RkmpmEnergies,
) -> RkmpmStatus {
    gate("rkmpm_sim_energies", || {
        // SAFETY: `sim` is NULL or a live handle (this function's `# Safety`).
        let s = unsafe { sim_ref(sim) }?;
        check_ptr("out", out)?;
        let e = with_sim!(&s.sim, m => m.energies());
        let value = RkmpmEnergies {
            kinetic: e.kinetic,
            stored: e.stored,
            gravitational: e.gravitational,
        };
        // SAFETY: the out-pointer is NULL or writable (this function's `# Safety`).
        unsafe { write_out("out", out, value) }
    })
}

/// Switches the energy accounting on (`on` = 1: from the energies now, with nothing dissipated
/// yet; switching it on again starts it afresh) or off (`on` = 0). While it is on, every step
/// adds its stress work and external work to a ledger (one more pass over the particles per
/// step) that `rkmpm_sim_energy_balance` reads and checkpoints keep.
///
/// # Safety
/// `sim` must be a live handle.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_set_energy_accounting(
    sim: *mut RkmpmSim,
    on: u32,
) -> RkmpmStatus {
    gate("rkmpm_sim_set_energy_accounting", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        let on = flag("on", on)?;
        with_sim!(&mut s.sim, m => m.set_energy_accounting(on));
        Ok(())
    })
}

/// Writes where the energy went since the accounting started to `*out`
/// (`RkmpmEnergyBalance`). Fails with `RKMPM_ERR_INVALID_STATE` when the accounting is off.
///
/// # Safety
/// `sim` must be a live handle; `out` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_energy_balance(
    sim: *const RkmpmSim,
    out: *mut RkmpmEnergyBalance,
) -> RkmpmStatus {
    gate("rkmpm_sim_energy_balance", || {
        // SAFETY: `sim` is NULL or a live handle (this function's `# Safety`).
        let s = unsafe { sim_ref(sim) }?;
        check_ptr("out", out)?;
        let b = with_sim!(&s.sim, m => m.energy_balance())?;
        let value = RkmpmEnergyBalance {
            kinetic: b.now.kinetic,
            stored: b.now.stored,
            gravitational: b.now.gravitational,
            start: b.start,
            external_work: b.external_work,
            stress_work: b.stress_work,
            material_dissipation: b.material_dissipation,
            friction_dissipation: b.friction_dissipation,
            contact_dissipation: b.contact_dissipation,
            other_dissipation: b.other_dissipation,
        };
        // SAFETY: the out-pointer is NULL or writable (this function's `# Safety`).
        unsafe { write_out("out", out, value) }
    })
}

/// Writes the particles' total linear and angular momentum to `*out`.
///
/// # Safety
/// `sim` must be a live handle; `out` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_momenta(
    sim: *const RkmpmSim,
    out: *mut RkmpmMomenta,
) -> RkmpmStatus {
    gate("rkmpm_sim_momenta", || {
        // SAFETY: `sim` is NULL or a live handle (this function's `# Safety`).
        let s = unsafe { sim_ref(sim) }?;
        check_ptr("out", out)?;
        let mut value = RkmpmMomenta::default();
        with_sim!(&s.sim, m => {
            let p = m.momenta();
            value.linear[..p.linear.len()].copy_from_slice(p.linear.as_slice());
            value.angular.copy_from_slice(p.angular.as_slice());
        });
        // SAFETY: the out-pointer is NULL or writable (this function's `# Safety`).
        unsafe { write_out("out", out, value) }
    })
}

/// Writes the simulated time to `*out_time`.
///
/// # Safety
/// `sim` must be a live handle; `out_time` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_time(sim: *const RkmpmSim, out_time: *mut f64) -> RkmpmStatus {
    gate("rkmpm_sim_time", || {
        // SAFETY: `sim` is NULL or a live handle (this function's `# Safety`).
        let s = unsafe { sim_ref(sim) }?;
        let time = with_sim!(&s.sim, m => m.time());
        // SAFETY: the out-pointer is NULL or writable (this function's `# Safety`).
        unsafe { write_out("out_time", out_time, time) }
    })
}

/// Writes the number of steps taken to `*out_steps`.
///
/// # Safety
/// `sim` must be a live handle; `out_steps` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_step_count(
    sim: *const RkmpmSim,
    out_steps: *mut u64,
) -> RkmpmStatus {
    gate("rkmpm_sim_step_count", || {
        // SAFETY: `sim` is NULL or a live handle (this function's `# Safety`).
        let s = unsafe { sim_ref(sim) }?;
        let steps = with_sim!(&s.sim, m => m.steps());
        // SAFETY: the out-pointer is NULL or writable (this function's `# Safety`).
        unsafe { write_out("out_steps", out_steps, steps) }
    })
}

/// The number of particles (0 for NULL).
///
/// # Safety
/// `sim` must be NULL or a live handle.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_particle_count(sim: *const RkmpmSim) -> usize {
    if sim.is_null() || !sim.is_aligned() {
        return 0;
    }
    // SAFETY: non-NULL and aligned (checked); a live handle by this function's `# Safety`.
    with_sim!(unsafe { &(*sim).sim }, m => m.particle_count())
}

fn field_from(field: RkmpmField) -> Result<Field, Failure> {
    kind_of("field", field)
}

/// Writes to `*out_len` how many values `rkmpm_sim_get_particles` writes for `field`.
///
/// # Safety
/// `sim` must be a live handle; `out_len` valid for a write.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_field_len(
    sim: *const RkmpmSim,
    field: RkmpmField,
    out_len: *mut usize,
) -> RkmpmStatus {
    gate("rkmpm_sim_field_len", || {
        // SAFETY: `sim` is NULL or a live handle (this function's `# Safety`).
        let s = unsafe { sim_ref(sim) }?;
        let f = field_from(field)?;
        let n = with_sim!(&s.sim, m => f.components(m.grid().cells().len()) * m.particle_count());
        // SAFETY: the out-pointer is NULL or writable (this function's `# Safety`).
        unsafe { write_out("out_len", out_len, n) }
    })
}

/// Copies `field` of every particle into `out` (particle-major, see `RkmpmField`), the particles in
/// the order they were added: particle `i` of the `k`-th call to `rkmpm_sim_add_particles` after
/// those of the earlier calls. (The engine keeps its own storage sorted by grid block for
/// speed; that order is never visible through the C API.) `len` is the
/// capacity of `out` in values; when it is smaller than needed, returns
/// `RKMPM_ERR_BUFFER_TOO_SMALL` and writes nothing.
///
/// # Safety
/// `sim` must be a live handle; `out` valid for `len` writes.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_get_particles(
    sim: *const RkmpmSim,
    field: RkmpmField,
    out: *mut f64,
    len: usize,
) -> RkmpmStatus {
    gate("rkmpm_sim_get_particles", || {
        // SAFETY: `sim` is NULL or a live handle (this function's `# Safety`).
        let s = unsafe { sim_ref(sim) }?;
        let f = field_from(field)?;
        with_sim!(&s.sim, m => {
            let need = f.components(m.grid().cells().len()) * m.particle_count();
            if len < need {
                return Err(Failure::new(
                    RKMPM_ERR_BUFFER_TOO_SMALL,
                    format!("field {} needs {need} values, the buffer holds {len}", f.name()),
                ));
            }
            if need > 0 {
                check_ptr("out", out)?;
                // SAFETY: non-NULL (checked); `out` holds `len >= need` values (checked above,
                // and this function's `# Safety`).
                let out = unsafe { std::slice::from_raw_parts_mut(out, need) };
                m.write_field(f, out);
            }
        });
        Ok(())
    })
}

/// Writes the particles and their fields to one VTK `.vtu` file at `path` (UTF-8).
///
/// # Safety
/// `sim` must be a live handle; `path` a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_write_vtk(
    sim: *const RkmpmSim,
    path: *const c_char,
) -> RkmpmStatus {
    gate("rkmpm_sim_write_vtk", || {
        // SAFETY: `sim` is NULL or a live handle (this function's `# Safety`).
        let s = unsafe { sim_ref(sim) }?;
        // SAFETY: the path is NULL or a NUL-terminated string (this function's `# Safety`).
        let path = unsafe { c_path("path", path) }?;
        with_sim!(&s.sim, m => vtk::write_particles(m, path, s.vtk_format))?;
        Ok(())
    })
}

/// Sets how the VTK files written from now on store their arrays: `RKMPM_VTK_BINARY` (the
/// default) or `RKMPM_VTK_ASCII`. A time series may mix both; ParaView and meshio read either.
///
/// # Safety
/// `sim` must be a live handle.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_set_vtk_format(
    sim: *mut RkmpmSim,
    format: RkmpmVtkFormat,
) -> RkmpmStatus {
    gate("rkmpm_sim_set_vtk_format", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        s.vtk_format = kind_of("format", format)?;
        Ok(())
    })
}

/// Writes the next frame of the time series `prefix`: `<prefix>_NNNNN.vtu`, and rewrites
/// `<prefix>.pvd` (open it in ParaView) listing every frame this simulation wrote under `prefix`.
///
/// # Safety
/// `sim` must be a live handle; `prefix` a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn rkmpm_sim_write_vtk_frame(
    sim: *mut RkmpmSim,
    prefix: *const c_char,
) -> RkmpmStatus {
    gate("rkmpm_sim_write_vtk_frame", || {
        // SAFETY: `sim` is NULL or a live handle used by this thread only (this function's `# Safety`).
        let s = unsafe { sim_mut(sim) }?;
        // SAFETY: the path is NULL or a NUL-terminated string (this function's `# Safety`).
        let prefix = unsafe { c_path("prefix", prefix) }?;
        if prefix.is_empty() || prefix.ends_with('/') {
            return Err(Failure::new(
                RKMPM_ERR_INVALID_ARGUMENT,
                format!("prefix \"{prefix}\" names no file (frames are <prefix>_00000.vtu)"),
            ));
        }
        let k = match s
            .series
            .iter()
            .position(|v| v.prefix() == std::path::Path::new(prefix))
        {
            Some(k) => k,
            None => {
                s.series.push(VtkSeries::new(prefix));
                s.series.len() - 1
            }
        };
        let series = &mut s.series[k];
        series.set_format(s.vtk_format);
        with_sim!(&s.sim, m => series.write_frame(m))?;
        Ok(())
    })
}

#[cfg(test)]
mod tests;
