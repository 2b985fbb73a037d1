//! Taylor bar impact in 3D against published results: Simo's bilinear copper bar (a
//! code-to-code reference) at several resolutions and the OFHC copper experiment of Johnson &
//! Cook (1983) with Johnson–Cook plasticity and a Mie–Grüneisen equation of state. Writes
//! `docs/validation/taylor/` (table and a PNG of each final rod, coloured by plastic strain) and
//! VTK frames in `out/taylor/`.
//!
//! `cargo run --release --example taylor_bar [-- --quick]` (about 10 minutes on 2 cores; `--quick`
//! runs 4 cells across the radius only).

use rkmpm::io::vtk::VtkSeries;
use rkmpm_runner::snapshot::write_symmetry_section;
use rkmpm_studies::scenes::{TaylorBar, TaylorCase, TaylorResult};
use std::fmt::Write as _;
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let quick = std::env::args().any(|a| a == "--quick");
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    let out = root.join("docs/validation/taylor");
    std::fs::create_dir_all(&out)?;
    std::fs::create_dir_all(root.join("out/taylor"))?;
    let runs: Vec<(TaylorCase, usize)> = if quick {
        vec![(TaylorCase::Bilinear, 4), (TaylorCase::OfhcCopper, 4)]
    } else {
        vec![
            (TaylorCase::Bilinear, 4),
            (TaylorCase::Bilinear, 6),
            (TaylorCase::Bilinear, 8),
            (TaylorCase::OfhcCopper, 4),
            (TaylorCase::OfhcCopper, 6),
        ]
    };
    let mut rows: Vec<(TaylorCase, usize, TaylorResult)> = Vec::new();
    for (case, cells) in runs {
        let bar = TaylorBar {
            case,
            cells_per_radius: cells,
            ..Default::default()
        };
        let name = format!("{case:?}_{cells}").to_lowercase();
        let mut series = VtkSeries::new(root.join(format!("out/taylor/{name}")));
        let (r, sim) = bar.run_observed(16, |sim| series.write_frame(sim).map(|_| ()))?;
        eprintln!(
            "{case:?}, {cells} cells per radius: length {:.2} mm ({:+.1}%), foot radius {:.2} mm ({:+.1}%), {} particles, {} steps, {:.0} s",
            r.final_length * 1e3,
            100.0 * (r.final_length / r.reference_length - 1.0),
            r.foot_radius * 1e3,
            100.0 * (r.foot_radius / r.reference_radius - 1.0),
            r.particles,
            r.steps,
            r.seconds
        );
        snapshot(
            &sim,
            &format!("{case:?}, {cells} cells per radius"),
            &out.join(format!("{name}.png")),
        )?;
        rows.push((case, cells, r));
    }
    let mut md = String::from("# Taylor bar impact (3D) against published results\n\n");
    writeln!(md, "Regenerate: `cargo run --release --example taylor_bar`. One quarter of the rod between symmetry (slip) walls, rigid frictionless wall (slip face) at z = 0, quadratic B-spline, APIC, CFL 0.3, 2 particles per cell per direction. Lengths: highest particle plus half a particle spacing; foot radius: the particle of the bottom layer farthest from the axis plus half a spacing.\n")?;
    writeln!(md, "- **Bilinear** (code-to-code): L0 = 32.4 mm, R0 = 3.2 mm, 227 m/s, ρ = 8930 kg/m³, E = 117 GPa, ν = 0.35, σ_y = 400 MPa + 100 MPa ε̄ (Johnson–Cook with n = 1, C = 0, no heating), 80 µs. Reference: final length 21.42 mm, foot radius 7.12 mm (Simo 1992; Zienkiewicz et al. 1998 give 7.11 mm, Foulk et al. 2021 7.22 mm).")?;
    writeln!(md, "- **OfhcCopper** (experiment): L0 = 25.4 mm, D0 = 7.62 mm, 190 m/s, Johnson–Cook OFHC copper (A = 90 MPa, B = 292 MPa, n = 0.31, C = 0.025, m = 1.09, χ = 0.9) with Mie–Grüneisen (c0 = 3940 m/s, s = 1.49, Γ0 = 1.96), 100 µs. Reference: Johnson & Cook (1983) as compiled by Banerjee (Uintah validation data, after Zerilli & Armstrong 1987): final length 16.21 mm, foot diameter 13.56 mm.\n")?;
    writeln!(md, "Targets: length within 3%, radius within 5%.\n")?;
    writeln!(md, "| case | cells per radius | particles (quarter) | final length (mm) | reference | error | foot radius (mm) | reference | error | max ε̄ | KE left | steps | run time (s) |")?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|---|---|---|---|")?;
    for (case, cells, r) in &rows {
        writeln!(
            md,
            "| {case:?} | {cells} | {} | {:.2} | {:.2} | {:+.1}% | {:.2} | {:.2} | {:+.1}% | {:.2} | {:.1e} | {} | {:.0} |",
            r.particles,
            r.final_length * 1e3,
            r.reference_length * 1e3,
            100.0 * (r.final_length / r.reference_length - 1.0),
            r.foot_radius * 1e3,
            r.reference_radius * 1e3,
            100.0 * (r.foot_radius / r.reference_radius - 1.0),
            r.max_plastic_strain,
            r.kinetic_left,
            r.steps,
            r.seconds
        )?;
    }
    for (case, cells, _) in &rows {
        let name = format!("{case:?}_{cells}").to_lowercase();
        writeln!(md, "\n![{case:?}, {cells} cells per radius]({name}.png)")?;
    }
    std::fs::write(out.join("README.md"), md)?;
    Ok(())
}

/// The final rod coloured by plastic strain, with the colour bar of the runner's pictures: the
/// section through its first layer of particles along y, next to the symmetry plane y = 0 (the
/// rod's profile).
fn snapshot(
    sim: &rkmpm::Sim<3>,
    title: &str,
    path: &Path,
) -> Result<(), Box<dyn std::error::Error>> {
    write_symmetry_section(sim, "plastic_strain", title, path)?;
    Ok(())
}
