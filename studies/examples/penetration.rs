//! A hard projectile against a 12 mm Weldox 460 E plate (Johnson–Cook plasticity and damage,
//! contact): a sweep of impact speeds in plane strain and one 3D run, against the blunt-projectile
//! set-up of Børvik et al. (2002) (ballistic limit 184.5 m/s). Writes
//! `docs/validation/penetration/` (table, PNGs coloured by damage) and VTK frames (with the
//! damage field) in `out/penetration/`.
//!
//! `cargo run --release --example penetration [-- --quick]` (about 3 minutes; `--quick` skips
//! the 3D run). `-- --methods` instead runs the plane-strain sweep with quadratic B-splines and
//! RK1, each with and without VC1, and writes `docs/validation/penetration/methods.md` and a
//! PNG per method at 300 m/s. `-- --refine` runs 300 m/s in plane strain at 8, 16 and 32 cells
//! through the plate with the quadratic B-spline and RK1 + VC1 and writes
//! `docs/validation/penetration/refinement.md` (about 20 minutes). `-- --wide` runs the
//! plane-strain scene with a plate clamped 150 mm from the axis and room below it to dish, and
//! writes `docs/validation/penetration/wide.md` (about 3 minutes). `-- --quarter 6,12` runs the
//! 3D quarter model at 300 m/s with those cells through the plate and writes
//! `docs/validation/penetration/quarter.md` with the speeds over time (12 cells: about 17
//! minutes on two cores). `-- --regularized` runs the crack-band regularized damage
//! (`Penetration::failure_band`) in plane strain and over a sweep of speeds in 3D at 6 cells,
//! against the Recht–Ipson curve through the test's ballistic limit, and writes
//! `docs/validation/penetration/regularized.md` (about 10 minutes). `-- --limit CELLS --clamp MM
//! --speeds v1,v2,..` runs the regularized 3D quarter model with `CELLS` cells through the plate
//! and the plate clamped `MM` mm from the axis at those speeds, fits Recht–Ipson to the
//! perforating runs (the model's ballistic limit) and writes
//! `docs/validation/penetration/limit_{CELLS}cells_{MM}mm.md` (per speed: 6 cells, 40 mm, about
//! a minute; 80 mm, 3–4 minutes; 12 cells, 40 mm, about 25 minutes).

use rkmpm::io::vtk::VtkSeries;
use rkmpm::{Integration, Shape, Sim};
use rkmpm_runner::snapshot::{write_panels, write_symmetry_section};
use rkmpm_studies::scenes::{recht_ipson_fit, Penetration, PenetrationResult};
use std::fmt::Write as _;
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let quick = std::env::args().any(|a| a == "--quick");
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    let out = root.join("docs/validation/penetration");
    std::fs::create_dir_all(&out)?;
    std::fs::create_dir_all(root.join("out/penetration"))?;
    if std::env::args().any(|a| a == "--methods") {
        return sweep(&out);
    }
    if std::env::args().any(|a| a == "--refine") {
        return refine(&out);
    }
    if std::env::args().any(|a| a == "--wide") {
        return wide(&out);
    }
    if std::env::args().any(|a| a == "--regularized") {
        return regularized(&out);
    }
    let args: Vec<String> = std::env::args().collect();
    let value = |flag: &str| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|i| args.get(i + 1).cloned())
    };
    if let Some(cells) = value("--limit") {
        let clamp: f64 = value("--clamp").map_or(Ok(40.0), |v| v.parse())?;
        let speeds = value("--speeds")
            .unwrap_or_else(|| "200,250,300".into())
            .split(',')
            .map(str::parse)
            .collect::<Result<Vec<f64>, _>>()?;
        return limit(&out, cells.parse()?, clamp, &speeds);
    }
    if let Some(i) = args.iter().position(|a| a == "--quarter") {
        let cells = args
            .get(i + 1)
            .ok_or("--quarter needs a list of cell counts")?
            .split(',')
            .map(str::parse)
            .collect::<Result<Vec<usize>, _>>()?;
        return quarter(&out, &cells);
    }
    let mut rows: Vec<(usize, PenetrationResult)> = Vec::new();
    for v in [150.0, 200.0, 250.0, 300.0, 400.0] {
        let scene = Penetration {
            impact_speed: v,
            cells_through_plate: 8,
            plate_half_width: 60e-3,
            ..Default::default()
        };
        let mut series = VtkSeries::new(root.join(format!("out/penetration/plane_{v}")));
        let (r, sim) = scene.run_observed::<2>(12, |s| series.write_frame(s).map(|_| ()))?;
        eprintln!("plane strain {v} m/s: {r:?}");
        if v == 300.0 {
            plane_snapshot(&sim, "plane strain, 300 m/s", &out.join("plane_300.png"))?;
        }
        rows.push((2, r));
    }
    if !quick {
        let scene = Penetration {
            impact_speed: 300.0,
            cells_through_plate: 6,
            plate_half_width: 40e-3,
            ..Default::default()
        };
        let mut series = VtkSeries::new(root.join("out/penetration/quarter_300"));
        let (r, sim) = scene.run_observed::<3>(12, |s| series.write_frame(s).map(|_| ()))?;
        eprintln!("3D 300 m/s: {r:?}");
        quarter_snapshot(&sim, "3D quarter, 300 m/s", &out.join("quarter_300.png"))?;
        rows.push((3, r));
    }
    let mut md =
        String::from("# Projectile penetration (Johnson–Cook plasticity and damage, contact)\n\n");
    writeln!(md, "Regenerate: `cargo run --release --example penetration`. Blunt elastic steel projectile (20 mm wide or across, 80 mm long, ρ = 7850 kg/m³) against a 12 mm Weldox 460 E plate (Johnson–Cook constants as commonly cited from Børvik et al. 2001: A = 490 MPa, B = 807 MPa, n = 0.73, C = 0.0114, m = 0.94, D1…D5 = 0.0705, 1.732, −0.54, −0.015, 0), frictionless multi-field contact, APIC, quadratic B-spline. Plane strain: half model, plate clamped 60 mm from the axis, 8 cells through the plate. 3D: quarter model, plate clamped 40 mm from the axis, 6 cells through the plate. Failed particles (D = 1) carry no deviatoric stress and no tension.\n")?;
    writeln!(md, "Reference: Børvik, Langseth, Hopperstad & Malo (2002), 20 mm blunt projectile of 197 g on 12 mm Weldox 460 E (a 500 mm plate): measured ballistic limit 184.5 m/s, plugging failure.\n")?;
    writeln!(md, "| model | impact speed (m/s) | perforated | plate cut off from the clamp / plate under the projectile (mass) | nose below back face (mm) | residual speed (m/s) | failed plate particles | max damage | particles | steps | end time (µs) | run time (s) |")?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|---|---|---|")?;
    for (dim, r) in &rows {
        writeln!(
            md,
            "| {} | {:.0} | {} | {:.1} | {:.1} | {:.1} | {} | {:.2} | {} | {} | {:.0} | {:.0} |",
            if *dim == 2 {
                "plane strain"
            } else {
                "3D quarter"
            },
            r.impact_speed,
            if r.perforated { "yes" } else { "no" },
            r.separated_mass,
            r.nose_depth * 1e3,
            r.residual_speed,
            r.failed_particles,
            r.max_damage,
            r.particles,
            r.steps,
            r.time * 1e6,
            r.seconds
        )?;
    }
    writeln!(md, "\n{PERFORATED} A negative residual speed is a rebound. Plane strain is a strip projectile, not Børvik's cylinder, so its ballistic limit (between the highest speed that does not perforate and the lowest that does) is not comparable with the test. At 8 cells through the plate the plane-strain strip tears off at its clamp at 250 and 300 m/s (the cut-off mass is the whole strip's, 6.2) rather than shearing out a plug; at 400 m/s, and at 300 m/s with 32 cells ([refinement.md](refinement.md)), a plug of about the projectile's width shears out at its edge. A plate 2.5 times as wide with room to dish ([wide.md](wide.md)) delays the tear but does not prevent it: at 300 and 350 m/s the strip dishes (47 mm at 300 m/s by 400 µs) and then tears at its clamp by 800 µs; 400 m/s shears out a plug first. The same sweep with RK1 and VC: [methods.md](methods.md). How all of it reads against the test: [FINDINGS.md](../FINDINGS.md).\n")?;
    writeln!(md, "![plane strain](plane_300.png)\n")?;
    if !quick {
        writeln!(md, "![3D section](quarter_300.png)")?;
    }
    std::fs::write(out.join("README.md"), md)?;
    Ok(())
}

/// 300 m/s in plane strain at 8, 16 and 32 cells through the plate, to 150 µs: where the plate
/// fails (at the projectile's edge: a plug; at the clamp: the strip tears off).
fn refine(out: &Path) -> Result<(), Box<dyn std::error::Error>> {
    let [bspline2, _, _, rk1_vc] = methods();
    let methods = [bspline2, rk1_vc];
    let mut md = String::from(
        "# Projectile penetration: refinement through the plate (plane strain, 300 m/s)\n\n",
    );
    writeln!(md, "Regenerate: `cargo run --release --example penetration -- --refine` (about 20 minutes). The plane-strain scene of [README.md](README.md) at 300 m/s, run to 150 µs, with 8, 16 and 32 cells through the 12 mm plate (cells of 1.5, 0.75 and 0.375 mm). Børvik's plugging shear band is a fraction of a millimetre wide.\n")?;
    writeln!(md, "| method | cells through the plate | perforated | plate cut off from the clamp / plate under the projectile (mass) | nose below back face (mm) | residual speed (m/s) | failed plate particles | particles | steps | run time (s) |")?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|---|")?;
    for (name, tag, shape, integration) in methods {
        for cells in [8, 16, 32] {
            let scene = Penetration {
                impact_speed: 300.0,
                cells_through_plate: cells,
                plate_half_width: 60e-3,
                duration: 150e-6,
                shape,
                integration,
                ..Default::default()
            };
            let (r, sim) = scene.run_observed::<2>(0, |_| Ok(()))?;
            eprintln!("{name} {cells} cells: {r:?}");
            if cells == 32 {
                plane_snapshot(
                    &sim,
                    &format!("{name}, 32 cells, 300 m/s, 150 µs"),
                    &out.join(format!("refine_{tag}_32.png")),
                )?;
            }
            writeln!(md, "| {name} | {cells} | {}", outcome_cells(&r))?;
        }
    }
    writeln!(md, "\n{PERFORATED}\n")?;
    for (name, tag, _, _) in methods {
        writeln!(md, "![{name}, 32 cells](refine_{tag}_32.png)\n")?;
    }
    std::fs::write(out.join("refinement.md"), md)?;
    Ok(())
}

/// The plane-strain scene with a plate 2.5 times as wide (clamped 150 mm from the axis) and
/// room below it (20 plate thicknesses), to 400 and 800 µs: does the strip still tear at its
/// clamp when it has room to dish?
fn wide(out: &Path) -> Result<(), Box<dyn std::error::Error>> {
    let mut md = String::from(
        "# Projectile penetration: a wider plane-strain plate (quadratic B-spline)

",
    );
    writeln!(md, "Regenerate: `cargo run --release --example penetration -- --wide` (about 3 minutes). The plane-strain scene of [README.md](README.md) (8 cells through the plate), with the plate clamped 150 mm from the axis instead of 60 mm and 240 mm (20 plate thicknesses) of room below it instead of 48 mm.
")?;
    writeln!(md, "| impact speed (m/s) | end time (µs) | perforated | plate cut off from the clamp / plate under the projectile (mass) | nose below back face (mm) | residual speed (m/s) | failed plate particles | particles | steps | run time (s) |")?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|---|")?;
    for (v, duration) in [
        (200.0, 400e-6),
        (300.0, 400e-6),
        (400.0, 400e-6),
        (300.0, 800e-6),
        (350.0, 800e-6),
    ] {
        let scene = Penetration {
            impact_speed: v,
            cells_through_plate: 8,
            plate_half_width: 150e-3,
            space_below: 20.0,
            duration,
            ..Default::default()
        };
        let (r, sim) = scene.run_observed::<2>(0, |_| Ok(()))?;
        eprintln!("wide plate {v} m/s, {:.0} µs: {r:?}", duration * 1e6);
        if v == 300.0 {
            let us = (duration * 1e6).round();
            plane_snapshot(
                &sim,
                &format!("plate clamped at 150 mm, 300 m/s, {us} µs"),
                &out.join(format!("wide_300_{us}.png")),
            )?;
        }
        writeln!(md, "| {v:.0} | {:.0} | {}", r.time * 1e6, outcome_cells(&r))?;
    }
    writeln!(
        md,
        "\n{PERFORATED} Here the strip's half width over the projectile's is 15.\n"
    )?;
    writeln!(md, "![300 m/s, 400 µs](wide_300_400.png)\n")?;
    writeln!(md, "![300 m/s, 800 µs](wide_300_800.png)")?;
    std::fs::write(out.join("wide.md"), md)?;
    Ok(())
}

/// The failure band of `--regularized` (m): the cell size at which the plane-strain plug first
/// formed with the constants as they are (refinement.md).
const FAILURE_BAND: f64 = 0.375e-3;

/// The crack-band regularized damage: plane strain at 300 m/s on 8 and 16 cells against the
/// unregularized 32 cells, and the 3D quarter model at 6 cells over a sweep of speeds against
/// the Recht–Ipson curve through the test's ballistic limit.
fn regularized(out: &Path) -> Result<(), Box<dyn std::error::Error>> {
    let mut md = String::from("# Projectile penetration: crack-band regularized damage\n\n");
    writeln!(md, "Regenerate: `cargo run --release --example penetration -- --regularized` (about 6 minutes). The scenes of [README.md](README.md) with the plate's strains to failure scaled by `w / h` on cells `h` coarser than a failure band `w = {:.3} mm` (`JohnsonCookParameters::regularized`, `Penetration::failure_band`): a band one cell wide then dissipates about the work of a band `w` wide. `w` is the cell size at which the plane-strain plug first formed with the constants as they are ([refinement.md](refinement.md)); it was fixed before the 3D runs and not fitted to the test.\n", FAILURE_BAND * 1e3)?;
    writeln!(md, "## Plane strain, 300 m/s, to 150 µs\n")?;
    writeln!(md, "| cells through the plate | strain-to-failure scale | perforated | plate cut off from the clamp / plate under the projectile (mass) | nose below back face (mm) | speed at 150 µs (m/s) | failed plate particles | particles | steps | run time (s) |")?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|---|")?;
    for cells in [8, 16] {
        let scene = Penetration {
            impact_speed: 300.0,
            cells_through_plate: cells,
            plate_half_width: 60e-3,
            duration: 150e-6,
            failure_band: Some(FAILURE_BAND),
            ..Default::default()
        };
        let (r, _) = scene.run_observed::<2>(0, |_| Ok(()))?;
        eprintln!("regularized plane strain, {cells} cells: {r:?}");
        writeln!(
            md,
            "| {cells} | {:.3} | {}",
            strain_scale(&scene),
            outcome_cells(&r)
        )?;
    }
    let quarter_scene = |v| Penetration {
        impact_speed: v,
        cells_through_plate: 6,
        plate_half_width: 40e-3,
        failure_band: Some(FAILURE_BAND),
        ..Default::default()
    };
    writeln!(md, "\nAt 32 cells the scale is 1: the unregularized run of [refinement.md](refinement.md) (plug, 183.7 m/s at 150 µs).\n")?;
    writeln!(
        md,
        "## 3D quarter model, 6 cells through the plate (scale {:.4}), to 300 µs\n",
        strain_scale(&quarter_scene(300.0))
    )?;
    let reference = Penetration::default();
    let projectile_mass = 7850.0
        * std::f64::consts::PI
        * reference.projectile_radius.powi(2)
        * reference.projectile_length;
    let plug_mass = 7850.0
        * std::f64::consts::PI
        * reference.projectile_radius.powi(2)
        * reference.plate_thickness;
    let a = projectile_mass / (projectile_mass + plug_mass);
    writeln!(md, "Recht–Ipson (1963): `v_r = a (v_i² − v_bl²)^½` for `v_i > v_bl`, with the test's ballistic limit `v_bl = {BALLISTIC_LIMIT} m/s` (Børvik et al. 2002) and `a = m_p / (m_p + m_plug) = {a:.3}` (projectile {:.0} g, a plug of the projectile's diameter through the plate {:.1} g). The residual speed is the projectile's mean speed at the end of the run (300 µs, or when the plug nears the bottom of the grid).\n", projectile_mass * 1e3, plug_mass * 1e3)?;
    writeln!(md, "| impact speed (m/s) | Recht–Ipson residual (m/s) | perforated | plate cut off from the clamp / plate under the projectile (mass) | nose below back face (mm) | residual speed (m/s) | failed plate particles | particles | steps | run time (s) |")?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|---|")?;
    let mut last = None;
    for v in [150.0, 200.0, 250.0, 300.0, 400.0] {
        let (r, sim) = quarter_scene(v).run_observed::<3>(0, |_| Ok(()))?;
        eprintln!("regularized 3D, {v} m/s: {r:?}");
        let recht_ipson = a * (v * v - BALLISTIC_LIMIT * BALLISTIC_LIMIT).max(0.0).sqrt();
        writeln!(md, "| {v:.0} | {recht_ipson:.0} | {}", outcome_cells(&r))?;
        if v == 300.0 {
            last = Some(sim);
        }
    }
    if let Some(sim) = last {
        quarter_snapshot(
            &sim,
            "3D quarter, 6 cells, regularized, 300 m/s",
            &out.join("regularized_300.png"),
        )?;
    }
    writeln!(md, "\n{PERFORATED}\n")?;
    writeln!(md, "![3D, regularized, 300 m/s](regularized_300.png)")?;
    std::fs::write(out.join("regularized.md"), md)?;
    Ok(())
}

/// The regularized 3D quarter model with `cells` cells through the plate, clamped `clamp_mm` from
/// the axis, at each of `speeds`, and the Recht–Ipson curve fitted to the perforating runs.
fn limit(
    out: &Path,
    cells: usize,
    clamp_mm: f64,
    speeds: &[f64],
) -> Result<(), Box<dyn std::error::Error>> {
    let scene = |v| Penetration {
        impact_speed: v,
        cells_through_plate: cells,
        plate_half_width: clamp_mm * 1e-3,
        failure_band: Some(FAILURE_BAND),
        ..Default::default()
    };
    let list = |xs: &[f64]| {
        xs.iter()
            .map(|x| format!("{x}"))
            .collect::<Vec<_>>()
            .join(",")
    };
    let path = out.join(format!("limit_{cells}cells_{clamp_mm}mm.md"));
    let mut md = format!("# Projectile penetration: the regularized 3D model's ballistic limit ({cells} cells, clamped at {clamp_mm} mm)\n\n");
    writeln!(md, "Regenerate: `cargo run --release --example penetration -- --limit {cells} --clamp {clamp_mm} --speeds {}`. The 3D quarter model of [regularized.md](regularized.md) (damage regularized with the failure band w = {:.3} mm; strain-to-failure scale {:.4}) with {cells} cells through the 12 mm plate and the plate clamped {clamp_mm} mm from the axis, to 300 µs.\n", list(speeds), FAILURE_BAND * 1e3, strain_scale(&scene(300.0)))?;
    writeln!(md, "| impact speed (m/s) | perforated | plate cut off from the clamp / plate under the projectile (mass) | nose below back face (mm) | residual speed (m/s) | failed plate particles | particles | steps | run time (s) |")?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|")?;
    let mut perforating = Vec::new();
    for &v in speeds {
        let (r, _) = scene(v).run_observed::<3>(0, |_| Ok(()))?;
        eprintln!("limit {cells} cells, {clamp_mm} mm, {v} m/s: {r:?}");
        writeln!(md, "| {v:.0} | {}", outcome_cells(&r))?;
        std::fs::write(&path, &md)?;
        if r.perforated {
            perforating.push((v, r.residual_speed));
        }
    }
    let r = Penetration::default().projectile_radius * 1e3;
    writeln!(
        md,
        "\n{PERFORATED} Here the plate's quarter over the projectile's is {:.0}.\n",
        clamp_mm * clamp_mm / (std::f64::consts::FRAC_PI_4 * r * r)
    )?;
    match recht_ipson_fit(&perforating) {
        Some((a, v_bl)) => writeln!(md, "Recht–Ipson `v_r = a (v_i² − v_bl²)^½` fitted (least squares in `v_r²` against `v_i²`) to the {} perforating runs: a = {a:.3}, **ballistic limit v_bl = {v_bl:.0} m/s** ({:+.0}% against the test's {BALLISTIC_LIMIT} m/s).", perforating.len(), (v_bl / BALLISTIC_LIMIT - 1.0) * 100.0)?,
        None => writeln!(md, "Fewer than two runs perforated: no Recht–Ipson fit.")?,
    }
    std::fs::write(&path, md)?;
    Ok(())
}

/// The factor on the plate's strains to failure in `scene` (`JohnsonCookParameters::regularized`
/// for its cell size).
fn strain_scale(scene: &Penetration) -> f64 {
    let band = scene.failure_band.unwrap_or(f64::INFINITY);
    (band * scene.cells_through_plate as f64 / scene.plate_thickness).min(1.0)
}

/// Børvik et al. (2002): the measured ballistic limit of the blunt projectile (m/s).
const BALLISTIC_LIMIT: f64 = 184.5;

/// The 3D quarter model at 300 m/s with `cells` cells through the plate: does a plug shear out
/// once the band at the projectile's edge is resolved?
fn quarter(out: &Path, cells: &[usize]) -> Result<(), Box<dyn std::error::Error>> {
    let mut md =
        String::from("# Projectile penetration: refinement of the 3D quarter model (300 m/s)\n\n");
    writeln!(md, "Regenerate: `cargo run --release --example penetration -- --quarter {}`. The 3D quarter model of [README.md](README.md) (plate clamped 40 mm from the axis, quadratic B-spline, APIC) at 300 m/s with more cells through the 12 mm plate.\n", cells.iter().map(|c| c.to_string()).collect::<Vec<_>>().join(","))?;
    writeln!(md, "| cells through the plate | end time (µs) | perforated | plate cut off from the clamp / plate under the projectile (mass) | nose below back face (mm) | residual speed (m/s) | failed plate particles | particles | steps | run time (s) |")?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|---|")?;
    let mut histories = Vec::new();
    for &n in cells {
        let scene = Penetration {
            impact_speed: 300.0,
            cells_through_plate: n,
            plate_half_width: 40e-3,
            ..Default::default()
        };
        let mut history = Vec::new();
        let (r, sim) = scene.run_observed::<3>(20, |s| {
            let row = motion(s, scene.projectile_radius);
            eprintln!("  {n} cells: {row:?}");
            history.push(row);
            Ok(())
        })?;
        eprintln!("3D {n} cells: {r:?}");
        quarter_snapshot(
            &sim,
            &format!("3D quarter, {n} cells, 300 m/s"),
            &out.join(format!("quarter_300_{n}.png")),
        )?;
        writeln!(md, "| {n} | {:.0} | {}", r.time * 1e6, outcome_cells(&r))?;
        histories.push((n, history));
    }
    writeln!(md, "\n{PERFORATED}\n")?;
    writeln!(md, "Over time: the mean downward speed of the projectile and of the plate under it (within its radius, reference configuration) and the failed plate particles.\n")?;
    for (n, history) in histories {
        writeln!(md, "| {n} cells: time (µs) | projectile (m/s) | plate under it (m/s) | failed plate particles |")?;
        writeln!(md, "|---|---|---|---|")?;
        for (t, vp, vu, failed) in history {
            writeln!(md, "| {:.0} | {vp:.1} | {vu:.1} | {failed} |", t * 1e6)?;
        }
        writeln!(md)?;
    }
    for &n in cells {
        writeln!(md, "![{n} cells](quarter_300_{n}.png)\n")?;
    }
    std::fs::write(out.join("quarter.md"), md)?;
    Ok(())
}

/// Time, mean downward speed of the projectile and of the plate within `radius` of the shot
/// line (reference configuration), and the failed plate particles.
fn motion<const D: usize>(sim: &Sim<D>, radius: f64) -> (f64, f64, f64, usize) {
    let ps = sim.particles();
    let (mut projectile, mut under, mut failed) = ([0.0; 2], [0.0; 2], 0);
    for p in 0..ps.len() {
        let sum = if ps.material()[p] == 1 {
            &mut projectile
        } else {
            failed += usize::from(ps.history()[p].damage >= 1.0);
            if ps.reference_position()[p].rows(0, D - 1).norm() >= radius {
                continue;
            }
            &mut under
        };
        sum[0] -= ps.mass()[p] * ps.velocity()[p][D - 1];
        sum[1] += ps.mass()[p];
    }
    (
        sim.time(),
        projectile[0] / projectile[1],
        under[0] / under[1],
        failed,
    )
}

/// The columns the refinement and wide-plate tables share, from "perforated" to "run time",
/// with the row's closing bar.
fn outcome_cells(r: &PenetrationResult) -> String {
    format!(
        "{} | {:.2} | {:.1} | {:.1} | {} | {} | {} | {:.0} |",
        if r.perforated { "yes" } else { "no" },
        r.separated_mass,
        r.nose_depth * 1e3,
        r.residual_speed,
        r.failed_particles,
        r.particles,
        r.steps,
        r.seconds
    )
}

/// How the tables read perforation and the separated plate.
const PERFORATED: &str = "Perforated: no plate material joined to the clamped edge through intact material (damage below 1) lies in the projectile's path below its nose, and the projectile still moves onward. Cut off: the mass of plate material no longer joined to the clamp over the mass of the plate under the projectile (within its radius, reference configuration): about 1 (plus a shear band) for a plug, the half width over the radius (6 in plane strain here, 20 in the 3D quarter model) when the plate tore off at its clamp, 0 when nothing separated.";

/// The shape functions and integrations compared: name, file tag, shape, integration.
type Method = (&'static str, &'static str, Shape, Integration);

fn methods() -> [Method; 4] {
    let rk1 = Shape::Rk {
        order: 1,
        support: 2.0,
    };
    let vc1 = Integration::Vc { order: 1 };
    let mp = Integration::MaterialPoint;
    [
        ("quadratic B-spline", "bspline2", Shape::BSpline2, mp),
        (
            "quadratic B-spline + VC1",
            "bspline2-vc",
            Shape::BSpline2,
            vc1,
        ),
        ("RK1 (ã = 2)", "rk1", rk1, mp),
        ("RK1 (ã = 2) + VC1", "rk1-vc", rk1, vc1),
    ]
}

/// The plane-strain sweep with each shape function, with and without VC.
fn sweep(out: &Path) -> Result<(), Box<dyn std::error::Error>> {
    let methods = methods();
    let mut md = String::from(
        "# Projectile penetration: shape functions and integration (plane strain)\n\n",
    );
    writeln!(md, "Regenerate: `cargo run --release --example penetration -- --methods`. The plane-strain scene of [README.md](README.md) (8 cells through the plate, APIC, CFL 0.3, frictionless contact) with each method. Under VC each body (plate, projectile) is corrected on its own grid field over the surface found from its own particles at every step, so the plate's surface follows the crater and the plug as they open.\n")?;
    writeln!(md, "| method | impact speed (m/s) | perforated | plate cut off from the clamp / plate under the projectile (mass) | nose below back face (mm) | residual speed (m/s) | failed plate particles | max damage | steps | run time (s) |")?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|---|")?;
    for (name, tag, shape, integration) in methods {
        for v in [150.0, 200.0, 250.0, 300.0, 400.0] {
            let scene = Penetration {
                impact_speed: v,
                cells_through_plate: 8,
                plate_half_width: 60e-3,
                shape,
                integration,
                ..Default::default()
            };
            let row = match scene.run_observed::<2>(0, |_| Ok(())) {
                Ok((r, sim)) => {
                    eprintln!("{name} {v} m/s: {r:?}");
                    if v == 300.0 {
                        plane_snapshot(
                            &sim,
                            &format!("{name}, 300 m/s"),
                            &out.join(format!("methods_{tag}_300.png")),
                        )?;
                    }
                    format!(
                        "| {name} | {v:.0} | {} | {:.1} | {:.1} | {:.1} | {} | {:.2} | {} | {:.0} |",
                        if r.perforated { "yes" } else { "no" },
                        r.separated_mass,
                        r.nose_depth * 1e3,
                        r.residual_speed,
                        r.failed_particles,
                        r.max_damage,
                        r.steps,
                        r.seconds
                    )
                }
                Err(e) => {
                    eprintln!("{name} {v} m/s failed: {e}");
                    format!("| {name} | {v:.0} | stopped: {e} | | | | | | | |")
                }
            };
            writeln!(md, "{row}")?;
        }
    }
    writeln!(md, "\n{PERFORATED}\n")?;
    for (name, tag, _, _) in methods {
        writeln!(md, "![{name}](methods_{tag}_300.png)\n")?;
    }
    std::fs::write(out.join("methods.md"), md)?;
    Ok(())
}

/// A plane-strain run's particles coloured by damage, with the colour bar of the runner's
/// pictures.
fn plane_snapshot(
    sim: &Sim<2>,
    title: &str,
    path: &Path,
) -> Result<(), Box<dyn std::error::Error>> {
    write_panels(&[(sim, title.to_string())], "damage", title, path, None)?;
    Ok(())
}

/// A 3D quarter model coloured by damage: the section through its first layer of particles
/// along y, next to the symmetry plane y = 0.
fn quarter_snapshot(
    sim: &Sim<3>,
    title: &str,
    path: &Path,
) -> Result<(), Box<dyn std::error::Error>> {
    write_symmetry_section(sim, "damage", title, path)?;
    Ok(())
}
