//! Throughput benchmark: particle-steps per second of one method on one block of neo-Hookean
//! material, 2D or 3D, at a given particle count. Run by `scripts/bench.sh`; the peers
//! (`bench/warp_mpm.py`, `bench/taichi_mpm.py`) build the same block, grid, material, velocity
//! field and time step (the "benchmark block" below), so the quadratic B-spline APIC line is
//! directly comparable with theirs.
//!
//! ```text
//! cargo run --release --example throughput -- --dim 2 --method bspline2 --particles 65536 --steps 100
//! RAYON_NUM_THREADS=1 cargo run --release --example throughput -- --dim 3 --method rk2 --vc --particles 100000
//! ```
//!
//! Options: `--dim 2|3`, `--method linear|bspline2|bspline3|rk1|rk2`, `--vc` (VC integration of
//! order 1, order 2 for rk2), `--vc-tolerance T` (the VC solve's tolerance, `rkmpm::VcSolve`;
//! default the engine's), `--vc-interval K` (the VC solve every K steps; default the engine's), `--surface-refresh K` (VC finds the surface every K steps,
//! `Sim::set_vc_surface_refresh`; default the engine's, 4), `--particles N` (rounded to m^D
//! with m even), `--steps S` (timed steps, default 50), `--warmup W` (untimed steps first, default 2), `--max-seconds T` (stop
//! timing after the first step that ends past T seconds, at least `--min-steps`, default 5),
//! `--header` (print the CSV header first), `--phases` (time per phase on stderr),
//! `--stored-stencils` (B-spline stencils stored node by node, as before the 1D factors),
//! `--transfer apic|pic|flip|mls`, `--gravity` (−9.81 m/s² along the last axis),
//! `--material neo-hookean|drucker-prager` (Drucker–Prager with a cohesion so high that the
//! block stays elastic, so the return mapping runs and finds nothing), `--padding CELLS` (that
//! many more empty cells on every side), `--memory` (bytes per particle and per node on
//! stderr), `--energy` (the energy accounting on, `Sim::set_energy_accounting`), `--vtk DIR` (after the timed steps, writes the particles as one `.vtu` file into
//! `DIR` in each format, binary and ASCII, three times each, and gives on stderr each format's
//! size and best write time); the defaults are the benchmark block below. A step the
//! engine rejects (an inverted particle, say) ends the timing: the line reports the steps before
//! it (at least `--min-steps`) and the error goes to stderr.
//!
//! The benchmark block (shared with the peers, keep in sync):
//! - m particles per direction (m even, m^D ≈ N), 2 per cell per direction, so the block is
//!   b = m/2 cells wide; g = 4 + m/16 empty cells on every side; n = b + 2g cells per direction,
//!   unit domain [0,1]^D, h = 1/n; particle i along an axis at (g + (i + 1/2)/2) h.
//! - Neo-Hookean, ρ = 1000 kg/m³, E = 1e5 Pa, ν = 0.3; volume (h/2)^D, mass ρ (h/2)^D.
//! - Velocity v_a = v0 (sin(π ξ_{a+1 mod D}) − ξ_a / 2), ξ = (x − 1/2) / (b h / 2) ∈ (−1, 1),
//!   v0 = 0.01 c, c = sqrt((λ + 2μ)/ρ). No gravity, free faces (the block never reaches them).
//! - dt = 0.4 h / (c + 1.5 sqrt(D) v0), fixed.
//! - rkmpm: USL, APIC (PIC for rk2, which APIC does not support), material-point integration
//!   unless `--vc`.
//!
//! Prints one CSV line: engine,dim,method,vc,transfer,particles,cells,threads,steps,dt,seconds,
//! particle_steps_per_s,kinetic_energy (after warm-up + timed steps; a cross-check between the
//! engines), setup_seconds.

use rkmpm::{Integration, Material, Shape, Sim, Transfer, Vector};
use std::process::ExitCode;
use std::time::Instant;

const DENSITY: f64 = 1000.0;
const YOUNG: f64 = 1e5;
const POISSON: f64 = 0.3;
const CFL: f64 = 0.4;

const HEADER: &str = "engine,dim,method,vc,transfer,particles,cells,threads,steps,dt,seconds,\
particle_steps_per_s,kinetic_energy,setup_seconds";

struct Args {
    dim: usize,
    method: String,
    vc: bool,
    vc_tolerance: Option<f64>,
    vc_interval: Option<u32>,
    surface_refresh: Option<u32>,
    particles: usize,
    steps: usize,
    warmup: usize,
    max_seconds: Option<f64>,
    min_steps: usize,
    header: bool,
    phases: bool,
    stored: bool,
    transfer: Option<String>,
    gravity: bool,
    material: String,
    padding: usize,
    memory: bool,
    shuffle: bool,
    energy: bool,
    sort: bool,
    vtk: Option<std::path::PathBuf>,
}

fn parse() -> Result<Args, String> {
    let mut a = Args {
        dim: 2,
        method: "bspline2".into(),
        vc: false,
        vc_tolerance: None,
        vc_interval: None,
        surface_refresh: None,
        particles: 65536,
        steps: 50,
        warmup: 2,
        max_seconds: None,
        min_steps: 5,
        header: false,
        phases: false,
        stored: false,
        transfer: None,
        gravity: false,
        material: "neo-hookean".into(),
        padding: 0,
        memory: false,
        shuffle: false,
        energy: false,
        sort: true,
        vtk: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let mut val = || it.next().ok_or_else(|| format!("{k} needs a value"));
        match k.as_str() {
            "--dim" => a.dim = val()?.parse().map_err(|e| format!("--dim: {e}"))?,
            "--method" => a.method = val()?,
            "--vc" => a.vc = true,
            "--surface-refresh" => {
                a.surface_refresh = Some(
                    val()?
                        .parse()
                        .map_err(|e| format!("--surface-refresh: {e}"))?,
                )
            }
            "--vc-tolerance" => {
                a.vc_tolerance = Some(val()?.parse().map_err(|e| format!("--vc-tolerance: {e}"))?)
            }
            "--vc-interval" => {
                a.vc_interval = Some(val()?.parse().map_err(|e| format!("--vc-interval: {e}"))?)
            }
            "--particles" => {
                a.particles = val()?.parse().map_err(|e| format!("--particles: {e}"))?
            }
            "--steps" => a.steps = val()?.parse().map_err(|e| format!("--steps: {e}"))?,
            "--warmup" => a.warmup = val()?.parse().map_err(|e| format!("--warmup: {e}"))?,
            "--max-seconds" => {
                a.max_seconds = Some(val()?.parse().map_err(|e| format!("--max-seconds: {e}"))?)
            }
            "--min-steps" => {
                a.min_steps = val()?.parse().map_err(|e| format!("--min-steps: {e}"))?
            }
            "--header" => a.header = true,
            "--phases" => a.phases = true,
            "--stored-stencils" => a.stored = true,
            "--transfer" => a.transfer = Some(val()?),
            "--gravity" => a.gravity = true,
            "--energy" => a.energy = true,
            "--memory" => a.memory = true,
            "--shuffle" => a.shuffle = true,
            "--no-sort" => a.sort = false,
            "--vtk" => a.vtk = Some(val()?.into()),
            "--material" => a.material = val()?,
            "--padding" => a.padding = val()?.parse().map_err(|e| format!("--padding: {e}"))?,
            "-h" | "--help" => {
                return Err(
                    "usage: throughput [--dim 2|3] [--method linear|bspline2|bspline3|rk1|rk2] \
                     [--vc] [--vc-tolerance T] [--vc-interval K] [--surface-refresh K] [--particles N] [--steps S] [--warmup W] [--max-seconds T] \
                     [--min-steps K] [--header] [--phases] [--stored-stencils] \
                     [--transfer apic|pic|flip|mls] [--gravity] [--material neo-hookean|drucker-prager] \
                     [--padding CELLS] [--memory] [--shuffle] [--no-sort] [--energy] [--vtk DIR]"
                        .into(),
                )
            }
            _ => return Err(format!("unknown option {k} (see --help)")),
        }
    }
    if a.dim != 2 && a.dim != 3 {
        return Err(format!("--dim must be 2 or 3, got {}", a.dim));
    }
    Ok(a)
}

/// Particles per direction: m^D ≈ N, m even, at least 4.
fn per_direction(n: usize, dim: usize) -> usize {
    let m = (n as f64).powf(1.0 / dim as f64).round() as usize;
    m.max(4).div_ceil(2) * 2
}

fn run<const D: usize>(a: &Args) -> Result<(), String> {
    let e = |x: rkmpm::Error| x.to_string();
    let setup = Instant::now();
    let (shape, transfer, vc_order) = match a.method.as_str() {
        "linear" => (Shape::Linear, Transfer::Apic, 1),
        "bspline2" => (Shape::BSpline2, Transfer::Apic, 1),
        "bspline3" => (Shape::BSpline3, Transfer::Apic, 1),
        "rk1" => (
            Shape::Rk {
                order: 1,
                support: 2.0,
            },
            Transfer::Apic,
            1,
        ),
        "rk2" => (
            Shape::Rk {
                order: 2,
                support: 3.0,
            },
            Transfer::PicFlip { flip: 0.0 },
            2,
        ),
        m => return Err(format!("unknown method {m}")),
    };
    let transfer = match a.transfer.as_deref() {
        None => transfer,
        Some("apic") => Transfer::Apic,
        Some("pic") => Transfer::PicFlip { flip: 0.0 },
        Some("flip") => Transfer::PicFlip { flip: 0.99 },
        Some("mls") => Transfer::Mls,
        Some(t) => return Err(format!("unknown transfer {t}")),
    };
    let m = per_direction(a.particles, D);
    let b = m / 2;
    let g = 4 + m / 16 + a.padding;
    let n = b + 2 * g;
    let h = 1.0 / n as f64;
    let mu = YOUNG / (2.0 * (1.0 + POISSON));
    let lambda = YOUNG * POISSON / ((1.0 + POISSON) * (1.0 - 2.0 * POISSON));
    let c = ((lambda + 2.0 * mu) / DENSITY).sqrt();
    let v0 = 0.01 * c;
    let dt = CFL * h / (c + 1.5 * (D as f64).sqrt() * v0);

    let mut sim = Sim::<D>::new(Vector::<D>::zeros(), [n; D], h).map_err(e)?;
    sim.set_shape(shape).map_err(e)?;
    sim.set_transfer(transfer).map_err(e)?;
    if a.vc {
        sim.set_integration(Integration::Vc { order: vc_order })
            .map_err(e)?;
        if let Some(steps) = a.surface_refresh {
            sim.set_vc_surface_refresh(steps).map_err(e)?;
        }
        if a.vc_tolerance.is_some() || a.vc_interval.is_some() {
            let automatic = sim.vc_solve();
            let solve = rkmpm::VcSolve {
                tolerance: a.vc_tolerance.unwrap_or(automatic.tolerance),
                interval: a.vc_interval.unwrap_or(automatic.interval),
                ..automatic
            };
            sim.set_vc_solve(solve).map_err(e)?;
        }
    }
    let material = match a.material.as_str() {
        "neo-hookean" => Material::neo_hookean(DENSITY, YOUNG, POISSON),
        // Drucker–Prager with a cohesion so high that the block stays elastic: the return
        // mapping runs (and finds nothing to return).
        "drucker-prager" => Material::drucker_prager(DENSITY, YOUNG, POISSON, 30.0, 1e12, 0.0),
        m => return Err(format!("unknown material {m}")),
    }
    .map_err(e)?;
    let mat = sim.add_material(material);
    sim.set_energy_accounting(a.energy);
    if a.gravity {
        let mut g = Vector::<D>::zeros();
        g[D - 1] = -9.81;
        sim.set_gravity(g).map_err(e)?;
    }
    let total = m.pow(D as u32);
    let mut x = Vec::with_capacity(total);
    let mut v = Vec::with_capacity(total);
    let half = b as f64 * h / 2.0;
    for lin in 0..total {
        // x fastest, then y, then z (the peers use the same order).
        let mut p = Vector::<D>::zeros();
        let mut r = lin;
        for a in 0..D {
            let i = r % m;
            r /= m;
            p[a] = (g as f64 + (i as f64 + 0.5) / 2.0) * h;
        }
        let xi = p.map(|c| (c - 0.5) / half);
        let mut vel = Vector::<D>::zeros();
        for a in 0..D {
            vel[a] = v0 * ((std::f64::consts::PI * xi[(a + 1) % D]).sin() - 0.5 * xi[a]);
        }
        x.push(p);
        v.push(vel);
    }
    if a.shuffle {
        // Fisher–Yates with a fixed xorshift sequence: the same order in every run.
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        for i in (1..total).rev() {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let j = (state % (i as u64 + 1)) as usize;
            x.swap(i, j);
            v.swap(i, j);
        }
    }
    let vol = vec![(h / 2.0).powi(D as i32); total];
    sim.add_particles(mat, &x, &vol, Some(&v)).map_err(e)?;
    sim.set_fast_paths(rkmpm::options::FastPaths {
        factored_stencils: !a.stored,
        particle_sorting: a.sort,
        ..Default::default()
    });
    drop((x, v, vol));
    for _ in 0..a.warmup {
        sim.step(dt).map_err(e)?;
    }
    let setup_seconds = setup.elapsed().as_secs_f64();
    let before = sim.phase_times();

    let start = Instant::now();
    let mut steps = 0;
    let mut seconds = 0.0;
    while steps < a.steps {
        if let Err(err) = sim.step(dt) {
            // A rejected step (e.g. an inverted particle) ends the measurement: report the steps
            // taken before it, if there are enough of them, and say so on stderr.
            if steps < a.min_steps.max(1) {
                return Err(err.to_string());
            }
            eprintln!("throughput: stopped after {steps} timed steps: {err}");
            break;
        }
        steps += 1;
        seconds = start.elapsed().as_secs_f64();
        if let Some(t) = a.max_seconds {
            if steps >= a.min_steps && seconds > t {
                break;
            }
        }
    }

    if a.phases {
        // Time per phase of the timed steps, in ns per particle-step and as a share.
        let after = sim.phase_times();
        let work = (total * steps) as f64;
        let (b, t) = (before.phases(), after.phases());
        let sum: f64 = t.iter().zip(&b).map(|(t, b)| t.1 - b.1).sum();
        for ((name, t), (_, b)) in t.iter().zip(&b) {
            eprintln!(
                "phase {name:>12}: {:8.2} ns/particle-step {:5.1} %",
                (t - b) * 1e9 / work,
                100.0 * (t - b) / sum
            );
        }
    }
    if a.memory {
        let m = sim.memory();
        eprintln!(
            "memory: particles {:.0} B + step workspace {:.0} B = {:.0} B per particle; grid {:.0} B \
             per stored node ({} nodes, {:.1} MB; {} active, {:.0} B per active node); total {:.2} GB",
            m.particles as f64 / m.particle_count as f64,
            m.particle_workspace as f64 / m.particle_count as f64,
            m.bytes_per_particle(),
            m.bytes_per_node(),
            m.node_count,
            m.grid as f64 / 1e6,
            m.active_nodes,
            m.grid as f64 / m.active_nodes.max(1) as f64,
            (m.particles + m.particle_workspace + m.grid) as f64 / 1e9
        );
    }
    if let Some(dir) = &a.vtk {
        use rkmpm::io::vtk::{write_particles, VtkFormat};
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        for (format, name) in [(VtkFormat::Binary, "binary"), (VtkFormat::Ascii, "ascii")] {
            let path = dir.join(format!("throughput_{name}.vtu"));
            let mut best = f64::INFINITY;
            for _ in 0..3 {
                let start = Instant::now();
                write_particles(&sim, &path, format).map_err(|e| e.message)?;
                best = best.min(start.elapsed().as_secs_f64());
            }
            let bytes = std::fs::metadata(&path).map_err(|e| e.to_string())?.len();
            eprintln!(
                "vtk {name}: {:.1} MB ({:.1} B per particle), written in {best:.3} s (best of 3)",
                bytes as f64 / 1e6,
                bytes as f64 / total as f64
            );
        }
    }
    let ps = sim.particles();
    let ke: f64 = ps
        .mass()
        .iter()
        .zip(ps.velocity())
        .map(|(m, v)| 0.5 * m * v.norm_squared())
        .sum();
    let transfer_name = match transfer {
        Transfer::Apic => "apic",
        Transfer::Mls => "mls",
        Transfer::PicFlip { .. } => "pic",
    };
    if a.header {
        println!("{HEADER}");
    }
    println!(
        "rkmpm,{D},{},{},{transfer_name},{total},{n},{},{steps},{dt:.6e},{seconds:.6},{:.6e},{ke:.12e},{setup_seconds:.3}",
        a.method,
        if a.vc { "vc" } else { "mp" },
        rayon::current_num_threads(),
        (total * steps) as f64 / seconds,
    );
    Ok(())
}

fn main() -> ExitCode {
    let result = parse().and_then(|a| match a.dim {
        2 => run::<2>(&a),
        _ => run::<3>(&a),
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("throughput: {e}");
            ExitCode::FAILURE
        }
    }
}
