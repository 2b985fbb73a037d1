//! Fuzzing the C API: random sequences of calls with random (often invalid) arguments, driven by
//! proptest. Every call must return a defined status (never the panic status), a failed call
//! must leave a message and change nothing a caller can observe, and the simulation must stay
//! usable. No call may crash or hang: each runs under a time budget ([`CALL_BUDGET`]); one that
//! returns late fails its case, and one that does not return at all is reported by a watchdog
//! thread, which then ends the test process with a failure instead of letting it hang.
//!
//! A second target feeds `rkmpm_sim_load` damaged checkpoints whose checksum has been made right
//! again, so that the decoder itself (not only the CRC) meets every kind of garbage.
//!
//! A third target is the first with the μ(I) rheology call among the calls, from a
//! Drucker–Prager seed body (its own strategy, so that the first target's stored seeds keep
//! giving the cases they recorded).
//!
//! A fourth target draws durations, time steps, CFL numbers, moduli, densities and velocities
//! from the whole double range (every exponent, either sign, subnormals, NaN, ±inf), as the
//! first draws bad positions, and changes the bound on the steps of an adaptive run: an absurd
//! run must be refused, not started. Every target sets that bound to [`FUZZ_MAX_STEPS`].
//!
//! The test command runs 20 000 + 3 000 + 14 000 sequences and 5 000 checkpoints; the counts of
//! calls, failures and steps are printed with `--nocapture` (figures in `docs/ROBUSTNESS.md`).
//! A longer run: `PROPTEST_CASES=1000000 cargo test --release -p rkmpm-capi -- --nocapture`.

use crate::*;
use proptest::prelude::*;
use std::ffi::CString;
use std::ptr::{null, null_mut};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

/// The time a call may take. The slowest single steps of the targets (3D, VC of order 4 with
/// boundary points) take about a second on a loaded machine, and an adaptive run takes at most
/// [`FUZZ_MAX_STEPS`] of them; thirty seconds leaves room for that and still ends a hang.
const CALL_BUDGET: Duration = Duration::from_secs(30);

/// The bound on the steps of one adaptive run that every target sets: small enough that an
/// accepted run of the slowest steps fits the budget, large enough that runs of ordinary
/// durations go through and meet the bound while stepping.
const FUZZ_MAX_STEPS: u64 = 20;

/// Interesting floating-point values: normal ones and every kind of bad one.
fn real() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -2.0f64..2.0,
        2 => 0.0f64..1e6,
        1 => Just(0.0),
        1 => Just(-1.0),
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(f64::NEG_INFINITY),
        1 => Just(1e308),
        1 => Just(1e-300),
    ]
}

/// Any double: every decade from the subnormals to the overflow with either sign, arbitrary bit
/// patterns (NaN payloads, infinities, subnormals), and the values of [`real`].
fn any_double() -> impl Strategy<Value = f64> {
    prop_oneof![
        2 => real(),
        2 => (any::<bool>(), -330i32..310, 1.0f64..10.0).prop_map(|(negative, e, m)| {
            let v = m * 10f64.powi(e);
            if negative { -v } else { v }
        }),
        1 => any::<f64>(),
    ]
}

#[derive(Debug, Clone)]
enum Call {
    SetShape(u32, u32, f64),
    SetIntegration(u32, u32),
    SetTransfer(u32, f64),
    SetScheme(u32),
    SetGravity([f64; 3]),
    SetBoundary(u32, i32, u32, f64),
    SetContact(u32, f64),
    AddNeoHookean(f64, f64, f64),
    AddDruckerPrager(f64, f64, f64, f64, f64, f64),
    /// Material, enabled flag, Δμ, I0, grain diameter (only in the second target's calls).
    SetRheology(u32, u32, f64, f64, f64),
    AddRigid(f64, [f64; 3]),
    AddParticles {
        material: u32,
        points: Vec<([f64; 3], f64, [f64; 3])>,
        moving: bool,
        null_positions: bool,
    },
    AddBoundaryPoints {
        points: Vec<([f64; 3], [f64; 3])>,
        tractions: bool,
    },
    Step(f64),
    Advance(f64, f64),
    /// `rkmpm_sim_step` with this `dt` as it is (the whole-range target).
    StepBy(f64),
    /// `rkmpm_sim_advance` with this duration and cfl as they are (the whole-range target).
    AdvanceBy(f64, f64),
    SetMaxSteps(u64),
    SetVcSolve(f64, u64),
    SetVcSolveInterval(u32),
    StableDt(f64),
    Read {
        field: u32,
        short: bool,
    },
    WriteVtkNowhere,
}

fn call() -> impl Strategy<Value = Call> {
    let point = (
        prop::array::uniform3(prop_oneof![12 => 0.1f64..0.9, 2 => -0.2f64..1.2, 1 => real()]),
        prop_oneof![4 => 0.0001f64..0.01, 1 => real()],
        prop::array::uniform3(prop_oneof![4 => -1.0f64..1.0, 1 => real()]),
    );
    prop_oneof![
        1 => (0u32..6, 0u32..7, prop_oneof![Just(2.0), Just(3.0), Just(1.0), Just(0.3), real()])
            .prop_map(|(a, b, c)| Call::SetShape(a, b, c)),
        1 => (0u32..3, 0u32..5).prop_map(|(a, b)| Call::SetIntegration(a, b)),
        1 => (0u32..4, real()).prop_map(|(a, b)| Call::SetTransfer(a, b)),
        1 => (0u32..3).prop_map(Call::SetScheme),
        1 => prop::array::uniform3(real()).prop_map(Call::SetGravity),
        1 => (0u32..4, -2i32..3, 0u32..5, real()).prop_map(|(a, s, k, f)| Call::SetBoundary(a, s, k, f)),
        1 => (0u32..3, real()).prop_map(|(e, f)| Call::SetContact(e, f)),
        1 => (real(), real(), prop_oneof![Just(0.3), real()]).prop_map(|(a, b, c)| Call::AddNeoHookean(a, b, c)),
        1 => (real(), real(), Just(0.3), prop_oneof![Just(30.0), real()], real(), prop_oneof![Just(0.0), real()])
            .prop_map(|(a, b, c, d, e, f)| Call::AddDruckerPrager(a, b, c, d, e, f)),
        1 => (real(), prop::array::uniform3(real())).prop_map(|(a, v)| Call::AddRigid(a, v)),
        2 => (prop_oneof![4 => 0u32..2, 1 => 0u32..5], prop::collection::vec(point, 0..12), any::<bool>(), prop::bool::weighted(0.05))
            .prop_map(|(material, points, moving, null_positions)| Call::AddParticles { material, points, moving, null_positions }),
        1 => (prop::collection::vec((prop::array::uniform3(-0.2f64..1.2), prop::array::uniform3(real())), 0..6), any::<bool>())
            .prop_map(|(points, tractions)| Call::AddBoundaryPoints { points, tractions }),
        6 => prop_oneof![3 => 0.0f64..1.2, 1 => real()].prop_map(Call::Step),
        // cfl: usable values and invalid ones, but no tiny positive one (1e-300 is valid and
        // asks for 1e300 steps: a long run, not a hang of the engine).
        1 => (prop_oneof![3 => 0.0f64..5.0, 1 => real()],
              prop_oneof![3 => 0.05f64..1.2, 1 => prop_oneof![Just(0.0), Just(-1.0), Just(f64::NAN), Just(f64::INFINITY), Just(1e308)]])
            .prop_map(|(n, c)| Call::Advance(n, c)),
        1 => real().prop_map(Call::StableDt),
        2 => (0u32..13, any::<bool>()).prop_map(|(field, short)| Call::Read { field, short }),
        1 => Just(Call::WriteVtkNowhere),
    ]
}

/// The calls of [`call`] and, one time in ten, the μ(I) rheology of a Drucker–Prager material
/// (a separate strategy, so that the first target's stored seeds still give their cases).
fn call_with_rheology() -> impl Strategy<Value = Call> {
    let rheology = (
        prop_oneof![4 => 0u32..2, 1 => 0u32..5],
        prop_oneof![6 => Just(1u32), 2 => Just(0u32), 1 => 2u32..4],
        prop_oneof![3 => 0.0f64..0.5, 1 => real()],
        prop_oneof![3 => 0.01f64..1.0, 1 => real()],
        prop_oneof![3 => 1e-4f64..1e-2, 1 => real()],
    )
        .prop_map(|(m, on, dmu, i0, d)| Call::SetRheology(m, on, dmu, i0, d));
    prop_oneof![9 => call(), 1 => rheology]
}

/// The calls of [`call`] and, four times in ten, calls whose durations, steps, CFL numbers,
/// moduli, densities and velocities come from the whole double range ([`any_double`]), with the
/// bound on the steps of a run set anywhere up to [`FUZZ_MAX_STEPS`] (and to 0, refused).
fn call_with_any_double() -> impl Strategy<Value = Call> {
    let wide = prop_oneof![
        2 => (any_double(), any_double(), prop_oneof![Just(0.3), any_double()])
            .prop_map(|(a, b, c)| Call::AddNeoHookean(a, b, c)),
        1 => (any_double(), any_double(), Just(0.3), Just(30.0), prop_oneof![Just(0.0), any_double()], Just(0.0))
            .prop_map(|(a, b, c, d, e, f)| Call::AddDruckerPrager(a, b, c, d, e, f)),
        1 => (any_double(), prop::array::uniform3(any_double())).prop_map(|(a, v)| Call::AddRigid(a, v)),
        2 => any_double().prop_map(Call::StepBy),
        4 => (any_double(), prop_oneof![3 => 0.05f64..1.0, 1 => any_double()])
            .prop_map(|(d, c)| Call::AdvanceBy(d, c)),
        1 => prop_oneof![Just(0u64), Just(1), 1..=FUZZ_MAX_STEPS].prop_map(Call::SetMaxSteps),
        1 => (prop_oneof![1e-12f64..1.0, any_double()], 0u64..50)
            .prop_map(|(t, n)| Call::SetVcSolve(t, n)),
        1 => (0u32..6).prop_map(Call::SetVcSolveInterval),
    ];
    prop_oneof![6 => call(), 4 => wide]
}

/// Everything a caller can observe of a simulation.
#[derive(Debug, PartialEq)]
struct Snapshot {
    count: usize,
    boundary: usize,
    time: u64,
    steps: u64,
    fields: Vec<Vec<u64>>,
}

unsafe fn snapshot(sim: *const RkmpmSim) -> Snapshot {
    let mut time = 0.0;
    let mut steps = 0;
    let mut boundary = 0;
    assert_eq!(rkmpm_sim_time(sim, &mut time), RKMPM_OK);
    assert_eq!(rkmpm_sim_step_count(sim, &mut steps), RKMPM_OK);
    assert_eq!(rkmpm_sim_boundary_point_count(sim, &mut boundary), RKMPM_OK);
    let fields = (0..=RKMPM_FIELD_DAMAGE)
        .map(|f| {
            let mut n = 0;
            assert_eq!(rkmpm_sim_field_len(sim, f, &mut n), RKMPM_OK);
            let mut v = vec![0.0; n];
            assert_eq!(rkmpm_sim_get_particles(sim, f, v.as_mut_ptr(), n), RKMPM_OK);
            // Bits, so that NaN compares equal to itself.
            v.into_iter().map(f64::to_bits).collect()
        })
        .collect();
    Snapshot {
        count: rkmpm_sim_particle_count(sim),
        boundary,
        time: time.to_bits(),
        steps,
        fields,
    }
}

fn last_error() -> String {
    let n = unsafe { rkmpm_last_error_message(null_mut(), 0) };
    let mut buf = vec![0i8; n + 1];
    unsafe { rkmpm_last_error_message(buf.as_mut_ptr(), buf.len()) };
    unsafe { std::ffi::CStr::from_ptr(buf.as_ptr()) }
        .to_string_lossy()
        .into_owned()
}

/// Applies one call; returns its status.
unsafe fn apply(sim: *mut RkmpmSim, dim: usize, c: &Call) -> RkmpmStatus {
    match c {
        Call::SetShape(s, o, a) => rkmpm_sim_set_shape(sim, *s, *o, *a),
        Call::SetIntegration(i, o) => rkmpm_sim_set_integration(sim, *i, *o),
        Call::SetTransfer(t, f) => rkmpm_sim_set_transfer(sim, *t, *f),
        Call::SetScheme(s) => rkmpm_sim_set_scheme(sim, *s),
        Call::SetGravity(g) => rkmpm_sim_set_gravity(sim, g.as_ptr()),
        Call::SetBoundary(a, s, k, f) => rkmpm_sim_set_boundary(sim, *a, *s, *k, *f),
        Call::SetContact(e, f) => rkmpm_sim_set_contact(sim, *e, *f),
        Call::AddNeoHookean(a, b, c) => {
            let mut id = 0;
            rkmpm_sim_add_material_neo_hookean(sim, *a, *b, *c, &mut id)
        }
        Call::AddDruckerPrager(a, b, c, d, e, f) => {
            let mut id = 0;
            rkmpm_sim_add_material_drucker_prager(sim, *a, *b, *c, *d, *e, *f, &mut id)
        }
        Call::SetRheology(m, on, dmu, i0, d) => {
            rkmpm_sim_set_drucker_prager_rheology(sim, *m, *on, *dmu, *i0, *d)
        }
        Call::AddRigid(d, v) => {
            let mut id = 0;
            rkmpm_sim_add_material_rigid(sim, *d, v.as_ptr(), &mut id)
        }
        Call::AddParticles {
            material,
            points,
            moving,
            null_positions,
        } => {
            let x: Vec<f64> = points.iter().flat_map(|p| p.0[..dim].to_vec()).collect();
            let vol: Vec<f64> = points.iter().map(|p| p.1).collect();
            let v: Vec<f64> = points.iter().flat_map(|p| p.2[..dim].to_vec()).collect();
            let xp = if *null_positions { null() } else { x.as_ptr() };
            let vp = if *moving { v.as_ptr() } else { null() };
            rkmpm_sim_add_particles(sim, *material, points.len(), xp, vol.as_ptr(), vp)
        }
        Call::AddBoundaryPoints { points, tractions } => {
            let x: Vec<f64> = points.iter().flat_map(|p| p.0[..dim].to_vec()).collect();
            let n: Vec<f64> = points.iter().flat_map(|p| p.1[..dim].to_vec()).collect();
            let t = if *tractions { n.as_ptr() } else { null() };
            rkmpm_sim_add_boundary_points(sim, points.len(), x.as_ptr(), n.as_ptr(), t)
        }
        Call::Step(f) => {
            let mut dt = 0.0;
            match rkmpm_sim_stable_dt(sim, 0.5, &mut dt) {
                RKMPM_OK => rkmpm_sim_step(sim, dt * f),
                _ => rkmpm_sim_step(sim, 1e-4 * f),
            }
        }
        Call::Advance(n, cfl) => {
            // `n` stable steps' worth of time (or a small span when there is no stable step).
            let mut dt = 0.0;
            let span = match rkmpm_sim_stable_dt(sim, 1.0, &mut dt) {
                RKMPM_OK => dt * n.min(5.0),
                _ => 1e-4 * n,
            };
            let mut steps = 0;
            rkmpm_sim_advance(sim, span, *cfl, &mut steps)
        }
        Call::StepBy(dt) => rkmpm_sim_step(sim, *dt),
        Call::AdvanceBy(duration, cfl) => {
            let mut steps = 0;
            rkmpm_sim_advance(sim, *duration, *cfl, &mut steps)
        }
        Call::SetMaxSteps(n) => rkmpm_sim_set_max_steps_per_advance(sim, *n),
        Call::SetVcSolve(t, n) => rkmpm_sim_set_vc_solve(sim, *t, *n),
        Call::SetVcSolveInterval(k) => rkmpm_sim_set_vc_solve_interval(sim, *k),
        Call::StableDt(cfl) => {
            let mut dt = 0.0;
            rkmpm_sim_stable_dt(sim, *cfl, &mut dt)
        }
        Call::Read { field, short } => {
            let mut n = 0;
            let s = rkmpm_sim_field_len(sim, *field, &mut n);
            if s != RKMPM_OK {
                return s;
            }
            let len = if *short && n > 0 { n - 1 } else { n };
            let mut v = vec![0.0; len];
            rkmpm_sim_get_particles(sim, *field, v.as_mut_ptr(), len)
        }
        Call::WriteVtkNowhere => {
            let p = CString::new("/nonexistent-dir/f.vtu").unwrap();
            rkmpm_sim_write_vtk(sim, p.as_ptr())
        }
    }
}

use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};

/// Calls made, calls that failed, and steps that moved particles, over all cases (reported).
static CALLS: AtomicUsize = AtomicUsize::new(0);
static FAILED: AtomicUsize = AtomicUsize::new(0);
static STEPS_WITH_PARTICLES: AtomicUsize = AtomicUsize::new(0);
static CASES: AtomicUsize = AtomicUsize::new(0);
/// Steps that moved particles after μ(I) was switched on in the same case.
static STEPS_WITH_RHEOLOGY: AtomicUsize = AtomicUsize::new(0);

/// The call a fuzzing thread is in: when it started, and the case it belongs to.
struct Running {
    started: Instant,
    dim: u32,
    calls: Arc<[Call]>,
    index: usize,
}

type Slot = Arc<Mutex<Option<Running>>>;

/// The slots of every fuzzing thread, watched by one thread that ends the process (with a
/// report on stderr and a failing exit status) when a call has run past [`CALL_BUDGET`]: such a
/// call may never return, and the test must fail rather than hang.
fn watchdog() -> &'static Mutex<Vec<Slot>> {
    static SLOTS: OnceLock<Mutex<Vec<Slot>>> = OnceLock::new();
    SLOTS.get_or_init(|| {
        std::thread::spawn(|| loop {
            std::thread::sleep(Duration::from_millis(200));
            for slot in watchdog().lock().unwrap().iter() {
                let running = slot.lock().unwrap();
                if let Some(r) = running
                    .as_ref()
                    .filter(|r| r.started.elapsed() > CALL_BUDGET)
                {
                    use std::io::Write;
                    // Written past the test harness's capture, which a process exit would lose.
                    let _ = writeln!(
                        std::io::stderr(),
                        "fuzz: a call has not returned after {:.0} s (budget {} s): dim {}, \
                         call {} of {:?}",
                        r.started.elapsed().as_secs_f64(),
                        CALL_BUDGET.as_secs(),
                        r.dim,
                        r.index,
                        r.calls
                    );
                    std::process::exit(101);
                }
            }
        });
        Mutex::new(Vec::new())
    })
}

thread_local! {
    /// This thread's slot, registered with the watchdog on first use.
    static SLOT: Slot = {
        let slot = Slot::default();
        watchdog().lock().unwrap().push(slot.clone());
        slot
    };
}

/// The body a seeded case starts from (material 0 with eight particles).
#[derive(Debug, Clone, Copy)]
enum SeedBody {
    NeoHookean,
    DruckerPrager,
}

thread_local! {
    /// The one-thread pool this fuzzing thread's simulations step on. On rayon's global pool, a
    /// worker waiting inside one target's step takes up the other targets' queued steps (work
    /// stealing), so a call's time would include theirs and a long but legal call of one target
    /// could push another's past [`CALL_BUDGET`]. The same bits for any thread count are tested
    /// elsewhere; here one thread a target keeps the time a call takes its own.
    static POOL: rayon::ThreadPool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .thread_name(|_| "fuzz-step".into())
        .build()
        .expect("a fuzzing thread pool");
}

/// Runs one case: a new simulation in `dim` dimensions (with a seed body when `seeded`), then
/// `calls`, checking after each call what the file's documentation promises, on this thread's
/// [`POOL`].
fn run_sequence(
    dim: u32,
    seeded: bool,
    seed: SeedBody,
    calls: &[Call],
    max_steps: u64,
) -> Result<(), TestCaseError> {
    POOL.with(|pool| pool.install(|| run_sequence_here(dim, seeded, seed, calls, max_steps)))
}

/// [`run_sequence`] on the calling thread.
fn run_sequence_here(
    dim: u32,
    seeded: bool,
    seed: SeedBody,
    calls: &[Call],
    max_steps: u64,
) -> Result<(), TestCaseError> {
    let case: Arc<[Call]> = calls.into();
    unsafe {
        let mut sim = null_mut();
        let origin = [0.0; 3];
        let cells = [6usize; 3];
        prop_assert_eq!(
            rkmpm_sim_new(dim, origin.as_ptr(), cells.as_ptr(), 1.0 / 6.0, &mut sim),
            RKMPM_OK
        );
        CASES.fetch_add(1, Relaxed);
        if seeded {
            // Most cases start from a valid body, so that the calls after it meet particles.
            let mut id = 0;
            let status = match seed {
                SeedBody::NeoHookean => {
                    rkmpm_sim_add_material_neo_hookean(sim, 1000.0, 1e4, 0.3, &mut id)
                }
                // Soil that yields under its own weight, so that steps reach the return mapping.
                SeedBody::DruckerPrager => rkmpm_sim_add_material_drucker_prager(
                    sim, 2000.0, 1e4, 0.3, 20.0, 0.0, 0.0, &mut id,
                ),
            };
            prop_assert_eq!(status, RKMPM_OK);
            let d = dim as usize;
            let x: Vec<f64> = (0..8)
                .flat_map(|k| (0..d).map(move |a| 0.4 + 0.1 * ((k >> a) & 1) as f64))
                .collect();
            prop_assert_eq!(
                rkmpm_sim_add_particles(sim, 0, 8, x.as_ptr(), [1e-3; 8].as_ptr(), null()),
                RKMPM_OK
            );
        }
        prop_assert_eq!(
            rkmpm_sim_set_max_steps_per_advance(sim, max_steps),
            RKMPM_OK
        );
        let mut rheology_on = false;
        for (index, c) in calls.iter().enumerate() {
            let before = snapshot(sim);
            if let Some(trace) = std::env::var_os("RKMPM_FUZZ_TRACE") {
                // The call about to run, for a run that hangs or aborts.
                let _ = std::fs::write(
                    trace,
                    format!("dim {dim}, {} calls: {calls:?}\nnow: {c:?}\n", calls.len()),
                );
            }
            let started = Instant::now();
            SLOT.with(|slot| {
                *slot.lock().unwrap() = Some(Running {
                    started,
                    dim,
                    calls: case.clone(),
                    index,
                })
            });
            let status = apply(sim, dim as usize, c);
            let took = started.elapsed();
            SLOT.with(|slot| *slot.lock().unwrap() = None);
            prop_assert!(
                took <= CALL_BUDGET,
                "{:?} took {:.1} s, beyond the budget of {} s",
                c,
                took.as_secs_f64(),
                CALL_BUDGET.as_secs()
            );
            if took.as_secs_f64() > 0.5 {
                eprintln!(
                    "slow call ({:.1} s, dim {dim}, {:?}): {c:?}",
                    took.as_secs_f64(),
                    status
                );
            }
            CALLS.fetch_add(1, Relaxed);
            if status != RKMPM_OK {
                FAILED.fetch_add(1, Relaxed);
            } else if matches!(c, Call::Step(_) | Call::StepBy(_)) && before.count > 0 {
                STEPS_WITH_PARTICLES.fetch_add(1, Relaxed);
                if rheology_on {
                    STEPS_WITH_RHEOLOGY.fetch_add(1, Relaxed);
                }
            } else if matches!(c, Call::SetRheology(_, 1, ..)) {
                rheology_on = true;
            }
            prop_assert!(
                status != RKMPM_ERR_PANIC,
                "{:?} panicked: {}",
                c,
                last_error()
            );
            // An adaptive run that fails part-way keeps its good steps (documented), so only
            // its first step must leave nothing behind.
            let partial = matches!(c, Call::Advance(..) | Call::AdvanceBy(..))
                && snapshot(sim).steps != before.steps;
            if status != RKMPM_OK {
                prop_assert!(!last_error().is_empty(), "{:?}: no message", c);
            }
            if status != RKMPM_OK && !partial {
                let after = snapshot(sim);
                prop_assert!(
                    before == after,
                    "{:?} failed with {:?} but changed the simulation",
                    c,
                    status
                );
            }
        }
        rkmpm_sim_free(sim);
        if CASES.load(Relaxed).is_multiple_of(64) {
            eprintln!(
                "fuzz: {} cases, {} calls, {} failed with a status, {} steps moved particles \
                 ({} with μ(I) on)",
                CASES.load(Relaxed),
                CALLS.load(Relaxed),
                FAILED.load(Relaxed),
                STEPS_WITH_PARTICLES.load(Relaxed),
                STEPS_WITH_RHEOLOGY.load(Relaxed)
            );
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 20_000, max_shrink_iters: 2000, ..ProptestConfig::default() })]

    #[test]
    fn random_call_sequences_never_break_the_api(
        dim in 2u32..4,
        seeded in prop::bool::weighted(0.7),
        calls in prop::collection::vec(call(), 1..40),
    ) {
        run_sequence(dim, seeded, SeedBody::NeoHookean, &calls, FUZZ_MAX_STEPS)?;
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 3_000, max_shrink_iters: 2000, ..ProptestConfig::default() })]

    /// The same with the μ(I) rheology call among the calls, from a Drucker–Prager seed body.
    #[test]
    fn random_call_sequences_with_the_rheology_never_break_the_api(
        dim in 2u32..4,
        seeded in prop::bool::weighted(0.8),
        calls in prop::collection::vec(call_with_rheology(), 1..40),
    ) {
        run_sequence(dim, seeded, SeedBody::DruckerPrager, &calls, FUZZ_MAX_STEPS)?;
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 14_000, max_shrink_iters: 2000, ..ProptestConfig::default() })]

    /// Durations, steps, CFL numbers, moduli, densities and velocities from the whole double
    /// range, with the bound on a run's steps set to [`FUZZ_MAX_STEPS`] (and changed by the
    /// calls): every call returns within the budget.
    #[test]
    fn random_call_sequences_with_any_double_never_hang(
        dim in 2u32..4,
        seeded in prop::bool::weighted(0.8),
        calls in prop::collection::vec(call_with_any_double(), 1..80),
    ) {
        run_sequence(dim, seeded, SeedBody::NeoHookean, &calls, FUZZ_MAX_STEPS)?;
    }
}

/// A checkpoint with something of everything: two materials with history (Drucker–Prager and
/// Johnson–Cook is not needed: the history layout is shared), boundary points with tractions,
/// walls, gravity and a few steps taken.
fn rich_checkpoint() -> Vec<u8> {
    use rkmpm::walls::{Side, Wall};
    use rkmpm::{Material, Sim, Vector};
    let mut sim = Sim::<2>::new([0.0, 0.0], [8, 8], 0.125).unwrap();
    sim.set_wall(1, Side::Low, Wall::Friction(0.3)).unwrap();
    sim.set_gravity([0.0, -9.81]).unwrap();
    let soil =
        sim.add_material(Material::drucker_prager(1800.0, 1e6, 0.3, 30.0, 0.0, 0.0).unwrap());
    let x: Vec<Vector<2>> = (0..16)
        .map(|k| {
            Vector::<2>::new(
                0.3 + 0.0625 * (k % 4) as f64,
                0.03 + 0.0625 * (k / 4) as f64,
            )
        })
        .collect();
    sim.add_particles(soil, &x, &[0.0625 * 0.0625; 16], None)
        .unwrap();
    let top: Vec<Vector<2>> = (0..4)
        .map(|k| Vector::<2>::new(0.3 + 0.0625 * k as f64, 0.28))
        .collect();
    let n = vec![Vector::<2>::new(0.0, 0.0625); 4];
    let t = vec![Vector::<2>::new(0.0, -100.0); 4];
    sim.add_boundary_points(&top, &n, Some(&t)).unwrap();
    for _ in 0..3 {
        let dt = sim.stable_dt(0.3).unwrap();
        sim.step(dt).unwrap();
    }
    sim.checkpoint_bytes()
}

/// One way of damaging a payload: overwrite bytes, flip bits, cut or insert a run.
#[derive(Debug, Clone)]
enum Damage {
    Overwrite(usize, Vec<u8>),
    Flip(usize, u8),
    Cut(usize, usize),
    Insert(usize, Vec<u8>),
    /// A stored length or count (u64) made huge or off by a little.
    Word(usize, u64),
}

fn damage() -> impl Strategy<Value = Damage> {
    prop_oneof![
        (any::<usize>(), prop::collection::vec(any::<u8>(), 1..16))
            .prop_map(|(k, b)| Damage::Overwrite(k, b)),
        (any::<usize>(), 0u8..8).prop_map(|(k, b)| Damage::Flip(k, b)),
        (any::<usize>(), 1usize..64).prop_map(|(k, n)| Damage::Cut(k, n)),
        (any::<usize>(), prop::collection::vec(any::<u8>(), 1..64))
            .prop_map(|(k, b)| Damage::Insert(k, b)),
        (
            any::<usize>(),
            prop_oneof![
                Just(u64::MAX),
                Just(1u64 << 40),
                0u64..64,
                Just(0x7ff8_0000_0000_0000)
            ]
        )
            .prop_map(|(k, w)| Damage::Word(k, w)),
    ]
}

/// Re-frames `payload` as a checkpoint with a correct length and checksum.
fn reframe(original: &[u8], payload: &[u8]) -> Vec<u8> {
    let mut out = original[..16].to_vec();
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(payload);
    out.extend_from_slice(&crc32fast::hash(payload).to_le_bytes());
    out
}

static LOADED: AtomicUsize = AtomicUsize::new(0);
static REFUSED: AtomicUsize = AtomicUsize::new(0);

proptest! {
    #![proptest_config(ProptestConfig { cases: 5_000, max_shrink_iters: 2000, ..ProptestConfig::default() })]

    /// Damaged checkpoints with a valid frame: `rkmpm_sim_load` refuses them with a status and a
    /// message, or gives a simulation that can be stepped and read without a crash; never a
    /// panic, never an abort.
    #[test]
    fn damaged_checkpoints_are_refused_or_load_cleanly(damages in prop::collection::vec(damage(), 1..4)) {
        thread_local!(static GOOD: Vec<u8> = rich_checkpoint());
        let good = GOOD.with(|g| g.clone());
        let mut payload = good[24..good.len() - 4].to_vec();
        for d in &damages {
            let n = payload.len().max(1);
            match d {
                Damage::Overwrite(k, b) => for (i, x) in b.iter().enumerate() {
                    if let Some(p) = payload.get_mut((k % n) + i) { *p = *x; }
                },
                Damage::Flip(k, b) => if let Some(p) = payload.get_mut(k % n) { *p ^= 1 << b },
                Damage::Cut(k, m) => { let a = k % n; let e = (a + m).min(payload.len()); payload.drain(a.min(e)..e); }
                Damage::Insert(k, b) => { let a = (k % n).min(payload.len()); payload.splice(a..a, b.iter().copied()); }
                Damage::Word(k, w) => {
                    // Stored words are 8-byte aligned in the payload.
                    let a = (k % n) / 8 * 8;
                    if a + 8 <= payload.len() { payload[a..a + 8].copy_from_slice(&w.to_le_bytes()); }
                }
            }
        }
        let bytes = reframe(&good, &payload);
        let dir = std::env::temp_dir().join(format!("rkmpm-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(format!("{:?}.rkmpm", std::thread::current().id()).replace(['(', ')'], ""));
        std::fs::write(&path, &bytes).unwrap();
        let c_path = CString::new(path.to_str().unwrap()).unwrap();
        let mut sim = null_mut();
        let status = unsafe { rkmpm_sim_load(c_path.as_ptr(), &mut sim) };
        prop_assert!(status != RKMPM_ERR_PANIC, "load panicked: {}", last_error());
        if status == RKMPM_OK {
            LOADED.fetch_add(1, Relaxed);
            unsafe {
                let _ = snapshot(sim);
                for _ in 0..3 {
                    let mut dt = 0.0;
                    let s = rkmpm_sim_stable_dt(sim, 0.3, &mut dt);
                    prop_assert!(s != RKMPM_ERR_PANIC, "stable_dt panicked: {}", last_error());
                    if s != RKMPM_OK { break; }
                    let s = rkmpm_sim_step(sim, dt);
                    prop_assert!(s != RKMPM_ERR_PANIC, "step panicked: {}", last_error());
                }
                rkmpm_sim_free(sim);
            }
        } else {
            REFUSED.fetch_add(1, Relaxed);
            prop_assert!(sim.is_null(), "a refused load gave a handle");
            prop_assert!(!last_error().is_empty());
        }
        let done = LOADED.load(Relaxed) + REFUSED.load(Relaxed);
        if done.is_multiple_of(1000) {
            eprintln!("checkpoint fuzz: {done} damaged files, {} loaded, {} refused", LOADED.load(Relaxed), REFUSED.load(Relaxed));
        }
    }
}

/// A sequence the fuzzing found: a VC step rejected after its solve (gravity of 1e6), then
/// contact (whose bodies solve their own corrections) and the linear shape (a grid of fewer
/// nodes), then a step. The rejected step's solve must not be committed by the next step.
#[test]
fn a_rejected_vc_solve_is_not_committed_by_a_later_step() {
    let calls = vec![
        Call::SetGravity([0.0, 0.0, 976236.8652031254]),
        Call::SetIntegration(1, 1),
        Call::Step(0.3769729261234349),
        Call::SetContact(1, 0.0),
        Call::SetShape(0, 0, 2.0),
        Call::StepBy(0.0001),
    ];
    run_sequence(3, true, SeedBody::NeoHookean, &calls, FUZZ_MAX_STEPS).unwrap();
}
