//! The convergence study: the manufactured solution of Wallstedt & Guilkey (2008) in 2D and 3D
//! for every method, over four grid refinements. Writes `docs/convergence/mms.csv`,
//! `docs/convergence/README.md` (table and fitted slopes) and PNG plots (error against h, error
//! against run time).
//!
//! ```text
//! cargo run --release --example convergence            # the full study (about 10 minutes on 2 cores)
//! cargo run --release --example convergence -- --quick # coarser grids, for a look
//! ```

use plotters::prelude::*;
use rkmpm::verification::{fitted_slope, run_mms, AxisAlignedMms, MmsRun};
use rkmpm::{Integration, Shape, Transfer};
use std::fmt::Write as _;
use std::path::Path;

struct Method {
    name: &'static str,
    shape: Shape,
    integration: Integration,
    transfer: Transfer,
}

fn methods() -> Vec<Method> {
    let apic = Transfer::Apic;
    let pic = Transfer::PicFlip { flip: 0.0 };
    let mp = Integration::MaterialPoint;
    let rk1 = Shape::Rk {
        order: 1,
        support: 2.0,
    };
    let rk2 = Shape::Rk {
        order: 2,
        support: 3.0,
    };
    vec![
        Method {
            name: "linear (standard MPM)",
            shape: Shape::Linear,
            integration: mp,
            transfer: apic,
        },
        Method {
            name: "B-spline 2",
            shape: Shape::BSpline2,
            integration: mp,
            transfer: apic,
        },
        Method {
            name: "B-spline 3",
            shape: Shape::BSpline3,
            integration: mp,
            transfer: apic,
        },
        Method {
            name: "RK1",
            shape: rk1,
            integration: mp,
            transfer: apic,
        },
        Method {
            name: "RK1 + VC1",
            shape: rk1,
            integration: Integration::Vc { order: 1 },
            transfer: apic,
        },
        Method {
            name: "RK2 (PIC)",
            shape: rk2,
            integration: mp,
            transfer: pic,
        },
        Method {
            name: "RK2 + VC2 (PIC)",
            shape: rk2,
            integration: Integration::Vc { order: 2 },
            transfer: pic,
        },
    ]
}

struct Row {
    dim: usize,
    method: &'static str,
    run: Result<MmsRun, String>,
}

const COLORS: [RGBColor; 7] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let quick = std::env::args().any(|a| a == "--quick");
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/convergence");
    std::fs::create_dir_all(&out)?;
    plotters::style::register_font(
        "sans-serif",
        FontStyle::Normal,
        include_bytes!("../../assets/fonts/DejaVuSans.ttf"),
    )
    .map_err(|_| "font")?;

    let mms = AxisAlignedMms::default();
    let t_end = 0.015; // three quarters of the period 2/c, where |u| is largest again
    let cfl = 0.3;
    let grids2: &[usize] = if quick {
        &[8, 16, 24]
    } else {
        &[8, 16, 32, 64]
    };
    let grids3: &[usize] = if quick { &[4, 6, 8] } else { &[4, 8, 12, 16] };
    let grids3_rk2: &[usize] = if quick { &[4, 6, 8] } else { &[4, 6, 8, 10] };
    let mut rows = Vec::new();
    for dim in [2usize, 3] {
        for m in methods() {
            let grids = match (dim, m.shape) {
                (2, _) => grids2,
                (_, Shape::Rk { order: 2, .. }) => grids3_rk2,
                _ => grids3,
            };
            for &cells in grids {
                let run = if dim == 2 {
                    run_mms::<2>(&mms, cells, m.shape, m.integration, m.transfer, t_end, cfl)
                } else {
                    run_mms::<3>(&mms, cells, m.shape, m.integration, m.transfer, t_end, cfl)
                }
                .map_err(|e| e.to_string());
                match &run {
                    Ok(r) => eprintln!(
                        "{dim}D {:<22} {cells:>3} cells: L2 {:.3e}  energy {:.3e}  {:.2} s",
                        m.name, r.errors.l2, r.errors.energy, r.seconds
                    ),
                    Err(e) => eprintln!("{dim}D {:<22} {cells:>3} cells: failed: {e}", m.name),
                }
                rows.push(Row {
                    dim,
                    method: m.name,
                    run,
                });
            }
        }
    }

    // CSV
    let mut csv = String::from("dim,method,cells,h,steps,l2_error,energy_error,seconds,status\n");
    for r in &rows {
        match &r.run {
            Ok(run) => writeln!(
                csv,
                "{},{},{},{:e},{},{:e},{:e},{:.4},ok",
                r.dim,
                r.method,
                run.cells,
                1.0 / run.cells as f64,
                run.steps,
                run.errors.l2,
                run.errors.energy,
                run.seconds
            )?,
            Err(e) => writeln!(
                csv,
                "{},{},,,,,,,\"{}\"",
                r.dim,
                r.method,
                e.replace('"', "'")
            )?,
        }
    }
    std::fs::write(out.join("mms.csv"), csv)?;

    // Markdown: the table and the slopes.
    let mut md = String::new();
    writeln!(
        md,
        "# Convergence study: manufactured solution (Wallstedt & Guilkey 2008)\n"
    )?;
    writeln!(
        md,
        "Generated by `cargo run --release --example convergence`{}; do not edit by hand.\n",
        if quick { " -- --quick" } else { "" }
    )?;
    writeln!(md, "Axis-aligned neo-Hookean solution `u_a = A sin(2πX_a) sin(cπt + aπ)`, E = 1e7 Pa, ν = 0.3, ρ0 = 1000 kg/m³, A = 0.01 m, unit square (cube) with slip walls, 2 particles per cell per direction at the two-point Gauss abscissae, CFL {cfl}, errors at t = {t_end} s (three quarters of a period) over particles: displacement L2 and deformation-gradient (energy-norm) errors relative to the exact fields.\n")?;
    for dim in [2usize, 3] {
        writeln!(md, "## {dim}D\n")?;
        writeln!(
            md,
            "| method | cells | L2 error | energy error | run time (s) |\n|---|---|---|---|---|"
        )?;
        for r in rows.iter().filter(|r| r.dim == dim) {
            match &r.run {
                Ok(run) => writeln!(
                    md,
                    "| {} | {} | {:.3e} | {:.3e} | {:.2} |",
                    r.method, run.cells, run.errors.l2, run.errors.energy, run.seconds
                )?,
                Err(e) => writeln!(md, "| {} | | failed: {e} | | |", r.method)?,
            }
        }
        writeln!(md, "\n| method | L2 slope (all) | L2 slope (last 3) | energy slope (all) | energy slope (last 3) |\n|---|---|---|---|---|")?;
        for m in methods() {
            let ok: Vec<&MmsRun> = rows
                .iter()
                .filter(|r| r.dim == dim && r.method == m.name)
                .filter_map(|r| r.run.as_ref().ok())
                .collect();
            if ok.len() < 2 {
                continue;
            }
            let h: Vec<f64> = ok.iter().map(|r| 1.0 / r.cells as f64).collect();
            let l2: Vec<f64> = ok.iter().map(|r| r.errors.l2).collect();
            let en: Vec<f64> = ok.iter().map(|r| r.errors.energy).collect();
            let k = ok.len().saturating_sub(3);
            writeln!(
                md,
                "| {} | {:.2} | {:.2} | {:.2} | {:.2} |",
                m.name,
                fitted_slope(&h, &l2),
                fitted_slope(&h[k..], &l2[k..]),
                fitted_slope(&h, &en),
                fitted_slope(&h[k..], &en[k..])
            )?;
        }
        writeln!(md, "\n![L2 error against h](mms{dim}d_l2.png) ![energy error against h](mms{dim}d_energy.png) ![error against run time](mms{dim}d_time.png)\n")?;
        for (what, file, x_time) in [
            ("L2 error", "l2", false),
            ("energy error", "energy", false),
            ("L2 error", "time", true),
        ] {
            plot(
                &rows,
                dim,
                what,
                &out.join(format!("mms{dim}d_{file}.png")),
                x_time,
            )?;
        }
    }
    std::fs::write(out.join("README.md"), md)?;
    eprintln!("wrote {}", out.display());
    Ok(())
}

fn plot(
    rows: &[Row],
    dim: usize,
    what: &str,
    path: &Path,
    x_time: bool,
) -> Result<(), Box<dyn std::error::Error>> {
    let series: Vec<(&str, Vec<(f64, f64)>)> = methods()
        .iter()
        .map(|m| {
            let pts = rows
                .iter()
                .filter(|r| r.dim == dim && r.method == m.name)
                .filter_map(|r| r.run.as_ref().ok())
                .map(|r| {
                    let x = if x_time {
                        r.seconds.max(1e-4)
                    } else {
                        1.0 / r.cells as f64
                    };
                    let y = if what == "energy error" {
                        r.errors.energy
                    } else {
                        r.errors.l2
                    };
                    (x, y)
                })
                .collect();
            (m.name, pts)
        })
        .collect();
    let all: Vec<(f64, f64)> = series.iter().flat_map(|s| s.1.iter().copied()).collect();
    if all.is_empty() {
        return Ok(());
    }
    let (xmin, xmax) = all
        .iter()
        .fold((f64::MAX, f64::MIN), |a, p| (a.0.min(p.0), a.1.max(p.0)));
    let (ymin, ymax) = all
        .iter()
        .fold((f64::MAX, f64::MIN), |a, p| (a.0.min(p.1), a.1.max(p.1)));
    let root = BitMapBackend::new(path, (900, 650)).into_drawing_area();
    root.fill(&WHITE)?;
    let xlabel = if x_time {
        "run time (s)"
    } else {
        "cell size h"
    };
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "{dim}D manufactured solution: {what} against {}",
                if x_time { "run time" } else { "h" }
            ),
            ("sans-serif", 22),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(
            (xmin * 0.8..xmax * 1.25).log_scale(),
            (ymin * 0.5..ymax * 2.0).log_scale(),
        )?;
    chart
        .configure_mesh()
        .x_desc(xlabel)
        .y_desc(what)
        .x_label_formatter(&|v| format!("{v:.2e}"))
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .draw()?;
    for (i, (name, pts)) in series.iter().enumerate() {
        let c = COLORS[i % COLORS.len()];
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))?
            .label(*name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        chart.draw_series(pts.iter().map(|&p| Circle::new(p, 4, c.filled())))?;
    }
    if !x_time {
        // Reference slopes 1, 2 and 3 through the coarsest point of the first series.
        if let Some(&(x0, y0)) = series[0].1.first() {
            for (k, style) in [
                (1.0, BLACK.mix(0.3)),
                (2.0, BLACK.mix(0.5)),
                (3.0, BLACK.mix(0.7)),
            ] {
                let pts = [(x0, y0), (xmin, y0 * (xmin / x0).powf(k))];
                chart
                    .draw_series(LineSeries::new(pts, style.stroke_width(1)))?
                    .label(format!("slope {k}"))
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
            }
        }
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}
