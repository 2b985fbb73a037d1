//! The Taylor bar with RK and VC, and what they change: Simo's
//! bilinear copper bar at the given resolutions with the quadratic B-spline, RK1 (cubic B-spline
//! kernel, ã = 2) and RK1 with first-order VC, all APIC. Writes
//! `docs/validation/taylor/methods.md`.
//!
//! `cargo run --release --example taylor_methods [-- --cells 4,6]`

use rkmpm::sim::Integration;
use rkmpm::Shape;
use rkmpm_studies::scenes::{TaylorBar, TaylorCase};
use std::fmt::Write as _;
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let cells: Vec<usize> = args
        .iter()
        .position(|a| a == "--cells")
        .and_then(|i| args.get(i + 1))
        .map_or("4,6", String::as_str)
        .split(',')
        .map(str::parse)
        .collect::<Result<_, _>>()?;
    let rk1 = Shape::Rk {
        order: 1,
        support: 2.0,
    };
    let methods = [
        (
            "quadratic B-spline",
            Shape::BSpline2,
            Integration::MaterialPoint,
        ),
        ("RK1 (ã = 2)", rk1, Integration::MaterialPoint),
        ("RK1 (ã = 2) + VC1", rk1, Integration::Vc { order: 1 }),
    ];
    let mut md = String::from("# Taylor bar: shape functions and integration\n\n");
    writeln!(md, "Regenerate: `cargo run --release --example taylor_methods -- --cells {}`. Simo's bilinear bar (see [README.md](README.md)): reference final length 21.42 mm, foot radius 7.12 mm; targets 3% and 5%. APIC, CFL 0.3, 2 particles per cell per direction.\n", cells.iter().map(ToString::to_string).collect::<Vec<_>>().join(","))?;
    writeln!(md, "| method | cells per radius | final length (mm) | error | foot radius (mm) | error | max ε̄ | KE left | steps | run time (s) |")?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|---|")?;
    for &c in &cells {
        for (name, shape, integration) in methods {
            let bar = TaylorBar {
                case: TaylorCase::Bilinear,
                cells_per_radius: c,
                shape,
                integration,
                ..Default::default()
            };
            let row = match bar.run() {
                Ok(r) => format!(
                    "| {name} | {c} | {:.2} | {:+.1}% | {:.2} | {:+.1}% | {:.2} | {:.1e} | {} | {:.0} |",
                    r.final_length * 1e3,
                    100.0 * (r.final_length / r.reference_length - 1.0),
                    r.foot_radius * 1e3,
                    100.0 * (r.foot_radius / r.reference_radius - 1.0),
                    r.max_plastic_strain,
                    r.kinetic_left,
                    r.steps,
                    r.seconds
                ),
                Err(e) => format!("| {name} | {c} | stopped: {e} | | | | | | | |"),
            };
            eprintln!("{row}");
            writeln!(md, "{row}")?;
        }
    }
    let out = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
        .join("docs/validation/taylor/methods.md");
    std::fs::write(&out, md)?;
    eprintln!("wrote {}", out.display());
    Ok(())
}
