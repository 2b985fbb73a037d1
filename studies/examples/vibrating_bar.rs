//! The axial vibrating bar through the Rust API, with the same set-up as
//! `examples/c/vibrating_bar.c` and `examples/fortran/vibrating_bar.f90`; CTest compares the
//! three outputs to 1e-12.
//!
//! ```text
//! cargo run --release --example vibrating_bar -- <2|3> <output file>
//! ```

use rkmpm::{Field, Sim};
use rkmpm_studies::scenes::{run_vibrating_bar, VibratingBar};
use std::io::Write;
use std::process::ExitCode;

fn run<const D: usize>(path: &str) -> Result<(), String> {
    let bar = VibratingBar::default();
    let mut sim: Sim<D> = bar.build().map_err(|e| e.to_string())?;
    let r = run_vibrating_bar(&bar, &mut sim, 0.2).map_err(|e| e.to_string())?;
    let period_error = (r.period - r.exact_period).abs() / r.exact_period;
    println!(
        "{D}D bar: {} steps, velocity error {:.4}%, period error {:.4}%",
        r.steps,
        100.0 * r.velocity_error,
        100.0 * period_error
    );
    let mut out = std::io::BufWriter::new(std::fs::File::create(path).map_err(|e| e.to_string())?);
    // In id order, as the C and Fortran drivers read them (`Sim::field`); the engine's own
    // storage is sorted by grid block.
    let (x, v) = (sim.field(Field::Position), sim.field(Field::Velocity));
    for (x, v) in x.chunks_exact(D).zip(v.chunks_exact(D)) {
        let values: Vec<String> = x.iter().chain(v).map(|v| format!("{v:.16e}")).collect();
        writeln!(out, "{}", values.join(" ")).map_err(|e| e.to_string())?;
    }
    if period_error > 0.01 || r.velocity_error > 0.03 {
        return Err("bar outside its tolerances (period 1%, velocity 3%)".into());
    }
    Ok(())
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let result = match (args.get(1).map(String::as_str), args.get(2)) {
        (Some("2"), Some(path)) => run::<2>(path),
        (Some("3"), Some(path)) => run::<3>(path),
        _ => Err("usage: vibrating_bar <2|3> <output file>".into()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{e}");
            ExitCode::FAILURE
        }
    }
}
