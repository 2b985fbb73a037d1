//! A column under its own weight settling on a floor with VC: the energy over the hold.
//!
//! `cargo run --release --example settling -- [--cells 8] [--hold 3] [--block 4] [--only RK2]`
//!
//! `--block n`: a block `n` cells wide standing free on the floor instead of the column between
//! slip walls (its σ_yy error is against the column's solution, so only its motion counts).
//!
//! Gravity ramps up over 2 s and is then held. Under PIC with an elastic material the total
//! energy (kinetic + stored + gravitational) can only fall during the hold; this prints, per
//! method and VC variant, the kinetic energy at the start and end of the hold, the largest rise
//! of the total energy over any stretch of the hold, and the σ_yy error.

use rkmpm::options::{Integration, Shape, Transfer};
use rkmpm_studies::verification::{window_maxima, SelfWeightColumn};

fn main() -> rkmpm::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let value = |name: &str, default: f64| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .and_then(|v| v.parse().ok())
            .unwrap_or(default)
    };
    let cells = value("--cells", 8.0) as usize;
    let hold = value("--hold", 3.0);
    let only = args
        .iter()
        .position(|a| a == "--only")
        .and_then(|i| args.get(i + 1).cloned());
    let block = args
        .iter()
        .position(|a| a == "--block")
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok());
    let column = SelfWeightColumn {
        hold,
        free_block: block,
        ..SelfWeightColumn::default()
    };
    let methods = [
        ("B-spline 2 + VC1", Shape::BSpline2, 1),
        (
            "RK1 + VC1",
            Shape::Rk {
                order: 1,
                support: 2.0,
            },
            1,
        ),
        (
            "RK2 + VC2",
            Shape::Rk {
                order: 2,
                support: 3.0,
            },
            2,
        ),
    ];
    println!(
        "| method | fit | KE at hold start | KE at end | largest KE in last second | \
         largest rise of total energy in hold | σ_yy error | s | largest KE per half second |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for (name, shape, order) in methods {
        if only.as_deref().is_some_and(|o| !name.contains(o)) {
            continue;
        }
        for linear_fit in [false, true] {
            if linear_fit && (order != 1 || !shape.vc_linear_fit()) {
                continue;
            }
            let mut trace = Vec::new();
            let run = column.run_observed(
                cells,
                shape,
                Integration::Vc { order },
                Transfer::PicFlip { flip: 0.0 },
                |sim| sim.set_vc_linear_fit(linear_fit),
                |sim| {
                    let e = sim.energies();
                    trace.push((sim.time(), e.kinetic, e.total()));
                },
            );
            let fit = if linear_fit { "linear" } else { "mean" };
            let run = match run {
                Ok(run) => run,
                Err(e) => {
                    let last = trace.last().map_or(0.0, |t| t.0);
                    println!("| {name} | {fit} | stopped at t = {last:.3} s: {e} |");
                    continue;
                }
            };
            // The hold, from 0.05 s after the ramp (the step that ends the ramp changes the
            // gravity that the gravitational energy is taken with).
            let held: Vec<_> = trace.iter().filter(|t| t.0 >= column.ramp + 0.05).collect();
            if args.iter().any(|a| a == "--trace") {
                let every = (held.len() / 12).max(1);
                for t in held.iter().step_by(every) {
                    eprintln!("  t = {:.3} s: kinetic {:.4e}, total {:.6e}", t.0, t.1, t.2);
                }
            }
            let end = column.ramp + column.hold;
            let last_second = held
                .iter()
                .filter(|t| t.0 >= end - 1.0)
                .map(|t| t.1)
                .fold(0.0, f64::max);
            // The largest rise of the total energy: max over t2 > t1 of E(t2) − E(t1).
            let (mut lowest, mut rise) = (f64::INFINITY, 0.0f64);
            for t in &held {
                lowest = lowest.min(t.2);
                rise = rise.max(t.2 - lowest);
            }
            if args.iter().any(|a| a == "--profile") {
                for (y0, syy, _) in &run.profile {
                    let exact = -column.density * column.gravity * (column.height - y0);
                    eprintln!("  Y = {y0:.4}: σ_yy {syy:.4e}, exact {exact:.4e}");
                }
            }
            let kinetic: Vec<(f64, f64)> = held.iter().map(|t| (t.0, t.1)).collect();
            let windows: Vec<String> = window_maxima(&kinetic, column.ramp, 0.5)
                .iter()
                .map(|k| format!("{k:.3e}"))
                .collect();
            println!(
                "| {name} | {fit} | {:.3e} | {:.3e} | {:.3e} | {:.3e} | {:.3e} | {:.0} | {} |",
                held.first().map_or(0.0, |t| t.1),
                held.last().map_or(0.0, |t| t.1),
                last_second,
                rise,
                run.stress_error,
                run.seconds,
                windows.join(" ")
            );
        }
    }
    Ok(())
}
