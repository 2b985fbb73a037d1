//! How far round-off carries in the granular column collapse under VC: runs the collapse of
//! aspect ratio 2 with gravity moved by `k` parts in 10^13 (`k` = 0, 1, …), for each interval of
//! VC's solve, and prints how many runs reached rest and the spread of run-out and height as a
//! Markdown table. A rule whose steps amplify round-off gives a spread far above 1e-13, or runs
//! that lose a particle out of the grid.
//!
//! `cargo run --release --example collapse_margin -- --method rk1 --intervals 1,2,4,8 --runs 10`
//!
//! * `--method rk1|bspline2`: RK1 (ã = 2, the default) or the quadratic B-spline, with VC1.
//! * `--intervals a,b,..`: VC's solve every this many steps (default 1,2,4,8), at 1e-4.
//! * `--runs N`: perturbed runs per interval (default 10).
//! * `--cells N`: cells across the column (default 8).

use rkmpm::{Integration, Shape, VcSolve};
use rkmpm_studies::scenes::GranularColumn;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let value = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .map(String::as_str)
    };
    let shape = match value("--method").unwrap_or("rk1") {
        "rk1" => Shape::Rk {
            order: 1,
            support: 2.0,
        },
        "bspline2" => Shape::BSpline2,
        m => return Err(format!("unknown method {m:?} (rk1 or bspline2)").into()),
    };
    let intervals: Vec<u32> = value("--intervals")
        .unwrap_or("1,2,4,8")
        .split(',')
        .map(str::parse)
        .collect::<Result<_, _>>()?;
    let runs: u32 = value("--runs").unwrap_or("10").parse()?;
    let cells: usize = value("--cells").unwrap_or("8").parse()?;
    println!("| interval | at rest | run-out | height | first failure |");
    println!("|---|---|---|---|---|");
    for interval in intervals {
        let (mut runout, mut height) = ((f64::MAX, f64::MIN), (f64::MAX, f64::MIN));
        let (mut rested, mut failure) = (0, String::new());
        for k in 0..runs {
            let result = GranularColumn {
                aspect: 2.0,
                cells_across: cells,
                gravity: 9.81 * (1.0 + f64::from(k) * 1e-13),
                shape,
                integration: Integration::Vc { order: 1 },
                vc_solve: Some(VcSolve {
                    interval,
                    ..VcSolve::DEFAULT
                }),
                ..Default::default()
            }
            .run();
            match result {
                Ok(r) => {
                    rested += 1;
                    runout = (
                        runout.0.min(r.normalized_runout),
                        runout.1.max(r.normalized_runout),
                    );
                    height = (
                        height.0.min(r.normalized_height),
                        height.1.max(r.normalized_height),
                    );
                }
                Err(e) if failure.is_empty() => failure = format!("k = {k}: {e}"),
                Err(_) => {}
            }
        }
        let range = |(a, b): (f64, f64)| match rested {
            0 => "–".to_string(),
            _ => format!("{a:.4}–{b:.4}"),
        };
        println!(
            "| {interval} | {rested} of {runs} | {} | {} | {} |",
            range(runout),
            range(height),
            failure.split(';').next().unwrap_or("")
        );
    }
    Ok(())
}
