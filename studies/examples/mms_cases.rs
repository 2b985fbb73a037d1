//! The manufactured solution of the convergence study for one method, with the particles placed
//! off the Gauss points and VC's surface given or found: the cases that show whether VC helps
//! where the study's own arrangement would hide it.
//!
//! ```text
//! cargo run --release --example mms_cases -- PLACEMENT METHOD GRIDS [--found-surface] [--3d]
//!                                                    [--mixed-walls]
//!   PLACEMENT  gauss | uniform (the quarter points) | jitter:SEED (±30 % of the spacing)
//!   METHOD     b2 | b3 | b2vc | b3vc | rk1vc | rk2 | rk2vc (RK2 with PIC, the rest APIC)
//!   GRIDS      cells per side, comma-separated (16,32,64)
//!   --mixed-walls  fixed walls on the low faces, slip walls on the high ones (slip everywhere
//!                  without it)
//!   --vc-tolerance T, --vc-iterations N, --vc-interval K  the VC solve's rule (default the
//!                                       engine's automatic rule, `rkmpm::VcSolve::automatic`; with
//!                                       one option, the exact solve's values of the others:
//!                                       1e-12, 2000, every step)
//! ```
//!
//! Prints the relative L2 and energy-norm errors and the run time per grid, and the L2 slope.

use rkmpm::{Integration, Shape, Transfer};
use rkmpm_studies::verification::{
    fitted_slope, run_mms_placed, AxisAlignedMms, MmsWalls, Placement, Surface,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: mms_cases PLACEMENT METHOD GRIDS [--found-surface] [--3d] [--mixed-walls]";
    let [placement, method, grids] = [0, 1, 2].map(|i| args.get(i).cloned().unwrap_or_default());
    let placement = match placement.as_str() {
        "gauss" => Placement::Gauss,
        "uniform" => Placement::Uniform,
        p => match p.strip_prefix("jitter:").map(str::parse) {
            Some(Ok(seed)) => Placement::Jittered {
                fraction: 0.3,
                seed,
            },
            _ => return Err(format!("unknown placement {p:?}; {usage}").into()),
        },
    };
    let rk1 = Shape::Rk {
        order: 1,
        support: 2.0,
    };
    let rk2 = Shape::Rk {
        order: 2,
        support: 3.0,
    };
    let (apic, pic) = (Transfer::Apic, Transfer::PicFlip { flip: 0.0 });
    let (mp, vc1, vc2) = (
        Integration::MaterialPoint,
        Integration::Vc { order: 1 },
        Integration::Vc { order: 2 },
    );
    let (shape, integration, transfer) = match method.as_str() {
        "b2" => (Shape::BSpline2, mp, apic),
        "b3" => (Shape::BSpline3, mp, apic),
        "b2vc" => (Shape::BSpline2, vc1, apic),
        "b3vc" => (Shape::BSpline3, vc1, apic),
        "rk1vc" => (rk1, vc1, apic),
        "rk2" => (rk2, mp, pic),
        "rk2vc" => (rk2, vc2, pic),
        m => return Err(format!("unknown method {m:?}; {usage}").into()),
    };
    let grids: Vec<usize> = grids
        .split(',')
        .map(str::parse)
        .collect::<Result<_, _>>()
        .map_err(|_| usage)?;
    let surface = if args.iter().any(|a| a == "--found-surface") {
        Surface::Found
    } else {
        Surface::Exact
    };
    let three = args.iter().any(|a| a == "--3d");
    let walls = if args.iter().any(|a| a == "--mixed-walls") {
        MmsWalls::FixedLowSlipHigh
    } else {
        MmsWalls::Slip
    };
    let number = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .map(|v| {
                v.parse::<f64>()
                    .map_err(|_| format!("{name} takes a number"))
            })
            .transpose()
    };
    // Without either option the engine's automatic rule; with one, the exact solve's value of
    // the other.
    let exact = rkmpm::VcSolve::EXACT;
    let (tolerance, iterations) = (number("--vc-tolerance")?, number("--vc-iterations")?);
    let interval = number("--vc-interval")?;
    let vc_solve = (tolerance.is_some() || iterations.is_some() || interval.is_some()).then(|| {
        rkmpm::VcSolve {
            tolerance: tolerance.unwrap_or(exact.tolerance),
            max_iterations: iterations.map_or(exact.max_iterations, |n| n as usize),
            interval: interval.map_or(exact.interval, |n| n as u32),
        }
    });
    let mms = AxisAlignedMms {
        walls,
        vc_solve,
        ..AxisAlignedMms::default()
    };
    let mut l2 = Vec::new();
    for &cells in &grids {
        let case = (cells, placement, surface, shape, integration, transfer);
        let run = if three {
            run::<3>(&mms, case)?
        } else {
            run::<2>(&mms, case)?
        };
        println!(
            "{method} {cells:>4} cells: L2 {:.3e}  energy {:.3e}  ({:.1} s)",
            run.errors.l2, run.errors.energy, run.seconds
        );
        l2.push(run.errors.l2);
    }
    if grids.len() >= 2 {
        let h: Vec<f64> = grids.iter().map(|&c| 1.0 / c as f64).collect();
        println!("L2 slope {:.2}", fitted_slope(&h, &l2));
    }
    Ok(())
}

type Case = (usize, Placement, Surface, Shape, Integration, Transfer);

fn run<const D: usize>(
    mms: &AxisAlignedMms,
    (cells, placement, surface, shape, integration, transfer): Case,
) -> rkmpm::Result<rkmpm_studies::verification::MmsRun> {
    run_mms_placed::<D>(
        mms,
        cells,
        2,
        placement,
        surface,
        shape,
        integration,
        transfer,
        0.015,
        0.3,
    )
}
