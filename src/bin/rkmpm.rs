//! `rkmpm`: runs a built-in scene end to end, writes VTK frames, prints a summary.
//!
//! ```text
//! rkmpm [disks|bar2d|bar3d] [--out DIR]
//! ```

use rkmpm::io::vtk::VtkSeries;
use rkmpm::scenes::{colliding_disks, run_vibrating_bar, VibratingBar};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

const HELP: &str = "\
rkmpm: run a built-in MPM scene and write ParaView output

USAGE: rkmpm [SCENE] [--out DIR]

SCENES:
  disks   two neo-Hookean disks collide (Sulsky et al. 1994), 2D  [default]
  bar2d   axial vibrating bar against its exact solution, 2D
  bar3d   the same bar in 3D

OPTIONS:
  --out DIR   directory for the VTK frames and the .pvd series (default: out)
  -h, --help  this text
";

fn main() -> ExitCode {
    let mut scene = "disks".to_string();
    let mut out = PathBuf::from("out");
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "-h" | "--help" => {
                print!("{HELP}");
                return ExitCode::SUCCESS;
            }
            "--out" => match args.next() {
                Some(d) => out = PathBuf::from(d),
                None => {
                    eprintln!("--out needs a directory\n\n{HELP}");
                    return ExitCode::from(2);
                }
            },
            s if !s.starts_with('-') => scene = s.to_string(),
            other => {
                eprintln!("unknown option {other}\n\n{HELP}");
                return ExitCode::from(2);
            }
        }
    }
    if let Err(e) = std::fs::create_dir_all(&out) {
        eprintln!("cannot create {}: {e}", out.display());
        return ExitCode::FAILURE;
    }
    let result = match scene.as_str() {
        "disks" => disks(&out),
        "bar2d" => bar::<2>(&out),
        "bar3d" => bar::<3>(&out),
        other => Err(format!("unknown scene {other}\n\n{HELP}")),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn disks(out: &std::path::Path) -> Result<(), String> {
    let mut sim = colliding_disks(40).map_err(|e| e.to_string())?;
    let mut series = VtkSeries::new(out.join("disks"));
    let (p0, e0) = (sim.particles().momentum(), sim.particles().kinetic_energy());
    println!(
        "scene: two colliding neo-Hookean disks, {} particles, grid 40 x 40, quadratic B-spline, APIC, USL",
        sim.particles().len()
    );
    let t_end = 3.0;
    let frame_every = 0.1;
    let start = Instant::now();
    let mut next_frame = 0.0;
    let mut min_total: f64 = f64::INFINITY;
    while sim.time() < t_end - 1e-12 {
        if sim.time() >= next_frame - 1e-12 {
            series.write_frame(&sim).map_err(|e| e.to_string())?;
            next_frame += frame_every;
        }
        let dt = sim
            .stable_dt(0.3)
            .map_err(|e| e.to_string())?
            .min(t_end - sim.time());
        sim.step(dt).map_err(|e| e.to_string())?;
        min_total = min_total.min(sim.particles().kinetic_energy() + sim.strain_energy());
    }
    series.write_frame(&sim).map_err(|e| e.to_string())?;
    let wall = start.elapsed().as_secs_f64();
    let ps = sim.particles();
    let p1 = ps.momentum();
    let e1 = ps.kinetic_energy() + sim.strain_energy();
    let pmax = ps
        .pressure
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    println!(
        "steps: {}, simulated time: {:.3} s, wall time: {:.2} s, {:.2e} particle-steps/s",
        sim.steps(),
        sim.time(),
        wall,
        (ps.len() as f64 * sim.steps() as f64) / wall
    );
    println!(
        "momentum: start ({:.6e}, {:.6e}), end ({:.6e}, {:.6e})",
        p0[0], p0[1], p1[0], p1[1]
    );
    println!("energy (kinetic + strain): start {e0:.6e} J/m, end {e1:.6e} J/m, lowest {min_total:.6e} J/m ({:.1}% kept)",
        100.0 * e1 / e0);
    println!("largest pressure at the end: {pmax:.4e} Pa");
    println!(
        "output: {} frames, open {}.pvd in ParaView",
        series.frames(),
        series.prefix().display()
    );
    Ok(())
}

fn bar<const D: usize>(out: &std::path::Path) -> Result<(), String> {
    let bar = VibratingBar::default();
    let mut sim = bar.build::<D>().map_err(|e| e.to_string())?;
    println!(
        "scene: axial vibrating bar in {D}D, {} particles, {} cells along the bar",
        sim.particles().len(),
        bar.cells_along
    );
    let start = Instant::now();
    let r = run_vibrating_bar(&bar, &mut sim, 0.2).map_err(|e| e.to_string())?;
    let mut series = VtkSeries::new(out.join(format!("bar{D}d")));
    series.write_frame(&sim).map_err(|e| e.to_string())?;
    println!(
        "steps: {}, wall time {:.2} s",
        r.steps,
        start.elapsed().as_secs_f64()
    );
    println!(
        "period: {:.6} s (exact {:.6} s, error {:.3}%)",
        r.period,
        r.exact_period,
        100.0 * (r.period - r.exact_period).abs() / r.exact_period
    );
    println!(
        "mean-velocity history: largest error {:.3}% of the amplitude",
        100.0 * r.velocity_error
    );
    println!("output: {}.pvd", series.prefix().display());
    Ok(())
}
