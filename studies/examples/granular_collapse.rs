//! Granular column collapse in plane strain against the power laws measured for true 2D columns
//! of aluminium rods (Nguyen, Bui & Fukagawa 2015). Writes `docs/validation/collapse/`: a table
//! (CSV and Markdown), a plot of run-out and final height against the aspect ratio, a PNG of the
//! final heap coloured by plastic strain, and VTK frames of one run in `out/collapse/`.
//!
//! `cargo run --release --example granular_collapse [-- --quick]` (about 4 minutes; `--quick`
//! runs 8 cells across the column instead of 16). The aspect ratios 0.5–4, and 6 and 8
//! to see where the run-out bends to the law's slope.
//!
//! `cargo run --release --example granular_collapse -- --methods` (about 14 minutes) runs the
//! same aspect ratios with the quadratic B-spline and RK1 (ã = 2), each with material-point and
//! first-order VC integration, and writes `methods.md` and `methods.png` there instead: what RK
//! and VC change in a collapse.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::FontStyle;
use rkmpm::io::vtk::VtkSeries;
use rkmpm::{Integration, Shape};
use rkmpm_runner::snapshot::write_panels;
use rkmpm_studies::scenes::{log_log_slope, CollapseResult, GranularColumn, NGUYEN_BUI_FUKAGAWA};
use std::fmt::Write as _;
use std::path::Path;

/// The aspect ratios of the scene's table: 0.5–4 in steps of 0.5 (the exponent over
/// 1.5–4 is fitted through six points, from the law's lower end a = 1.5 on), and 6 and 8
/// beyond it.
const ASPECTS: [f64; 10] = [0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 6.0, 8.0];
/// The aspect ratios of the methods' comparison (0.5–4, in steps of 0.5).
const METHOD_ASPECTS: [f64; 8] = [0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0];
/// The upper end of the aspect ratios the exponents are fitted over (from 1.5).
const FIT_MAX_ASPECT: f64 = 4.0;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let quick = std::env::args().any(|a| a == "--quick");
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    let out = root.join("docs/validation/collapse");
    std::fs::create_dir_all(&out)?;
    std::fs::create_dir_all(root.join("out/collapse"))?;
    plotters::style::register_font(
        "sans-serif",
        FontStyle::Normal,
        include_bytes!("../../assets/fonts/DejaVuSans.ttf"),
    )
    .map_err(|_| "font")?;
    let cells = if quick { 8 } else { 16 };
    if std::env::args().any(|a| a == "--methods") {
        return methods(cells, &out);
    }
    let mut rows: Vec<CollapseResult> = Vec::new();
    for a in ASPECTS {
        let column = GranularColumn {
            aspect: a,
            cells_across: cells,
            ..Default::default()
        };
        let mut series = VtkSeries::new(root.join(format!("out/collapse/a{a}")));
        let (r, sim) = column.run_observed(20, |sim| series.write_frame(sim).map(|_| ()))?;
        eprintln!(
            "a = {a}: run-out {:.3} (law {:?}), height {:.3} (law {:.3}), {} particles, {} steps, {:.1} s",
            r.normalized_runout,
            NGUYEN_BUI_FUKAGAWA.runout(a),
            r.normalized_height,
            NGUYEN_BUI_FUKAGAWA.final_height(a),
            r.particles,
            r.steps,
            r.seconds
        );
        if a == 2.0 {
            snapshot(&sim, &out.join("heap_a2.png"))?;
        }
        rows.push(r);
    }
    write_tables(&rows, cells, &out)?;
    plot(&rows, &out.join("collapse.png"))?;
    Ok(())
}

/// The methods compared by `--methods`.
fn method_list() -> [(&'static str, Shape, Integration); 4] {
    let rk1 = Shape::Rk {
        order: 1,
        support: 2.0,
    };
    let (mp, vc) = (Integration::MaterialPoint, Integration::Vc { order: 1 });
    [
        ("quadratic B-spline", Shape::BSpline2, mp),
        ("quadratic B-spline + VC1", Shape::BSpline2, vc),
        ("RK1 (ã = 2)", rk1, mp),
        ("RK1 (ã = 2) + VC1", rk1, vc),
    ]
}

/// Every method at every aspect ratio: `methods.md` (table, fitted exponents) and `methods.png`.
fn methods(cells: usize, out: &Path) -> Result<(), Box<dyn std::error::Error>> {
    let law = NGUYEN_BUI_FUKAGAWA;
    let mut md = String::from("# Granular column collapse: shape functions and integration\n\n");
    writeln!(md, "Regenerate: `cargo run --release --example granular_collapse -- --methods{}`. The scene of [README.md](README.md) ({cells} cells across the column, APIC, CFL 0.3) with each method; VC finds the surface of the particles at every step. Ratios are to the laws of Nguyen, Bui & Fukagawa (2015); exponents are fitted over a ≥ 1.5 (laws: run-out 0.73, height 1/3). Targets: values within 20%, exponents within 15%.\n", if cells == 8 { " --quick" } else { "" })?;
    writeln!(md, "| method | a | run-out (L∞−L0)/L0 | ratio | height H∞/L0 | ratio | KE/(m g H0) at end | largest f/E | steps | run time (s) |")?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|---|")?;
    let mut all: Vec<(&str, Vec<CollapseResult>)> = Vec::new();
    let mut exponents = String::new();
    for (name, shape, integration) in method_list() {
        let mut rows = Vec::new();
        for a in METHOD_ASPECTS {
            let column = GranularColumn {
                aspect: a,
                cells_across: cells,
                shape,
                integration,
                ..Default::default()
            };
            let r = column.run()?;
            eprintln!(
                "{name}, a = {a}: run-out {:.3}, height {:.3}, {:.1} s",
                r.normalized_runout, r.normalized_height, r.seconds
            );
            let ratio = law
                .runout(a)
                .map_or("–".into(), |l| format!("{:.3}", r.normalized_runout / l));
            writeln!(
                md,
                "| {name} | {a} | {:.3} | {ratio} | {:.3} | {:.3} | {:.1e} | {:.1e} | {} | {:.0} |",
                r.normalized_runout,
                r.normalized_height,
                r.normalized_height / law.final_height(a),
                r.final_kinetic,
                r.worst_yield,
                r.steps,
                r.seconds
            )?;
            rows.push(r);
        }
        let (run_exp, h_exp) = exponents_of(&rows, 1.5, FIT_MAX_ASPECT);
        writeln!(
            exponents,
            "| {name} | {run_exp:.3} | {:.2} | {h_exp:.3} | {:.2} |",
            run_exp / 0.73,
            h_exp * 3.0
        )?;
        all.push((name, rows));
    }
    writeln!(
        md,
        "\n| method | run-out exponent | ratio to 0.73 | height exponent | ratio to 1/3 |"
    )?;
    writeln!(md, "|---|---|---|---|---|")?;
    md.push_str(&exponents);
    writeln!(md, "\n![run-out and height by method](methods.png)")?;
    std::fs::write(out.join("methods.md"), md)?;
    plot_methods(&all, &out.join("methods.png"))
}

/// Fitted exponents of run-out and final height over the aspect ratios in `[lo, hi]`.
fn exponents_of(rows: &[CollapseResult], lo: f64, hi: f64) -> (f64, f64) {
    let tall = rows.iter().filter(|r| (lo..=hi).contains(&r.aspect));
    let run: Vec<(f64, f64)> = tall
        .clone()
        .map(|r| (r.aspect, r.normalized_runout))
        .collect();
    let height: Vec<(f64, f64)> = tall.map(|r| (r.aspect, r.normalized_height)).collect();
    (log_log_slope(&run), log_log_slope(&height))
}

/// The log-log axes of run-out and height against the aspect ratio.
type LawChart<'a, 'b> =
    ChartContext<'b, BitMapBackend<'a>, Cartesian2d<LogCoord<f64>, LogCoord<f64>>>;

/// A log-log chart of run-out and height against the aspect ratio on a white `root`.
fn law_chart<'a, 'b>(
    root: &'b DrawingArea<BitMapBackend<'a>, Shift>,
    caption: &str,
    y_desc: &str,
    max_aspect: f64,
) -> Result<LawChart<'a, 'b>, Box<dyn std::error::Error>> {
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(root)
        .caption(caption, ("sans-serif", 22))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(
            (0.4f64..max_aspect * 1.25).log_scale(),
            (0.2f64..30.0).log_scale(),
        )?;
    chart
        .configure_mesh()
        .x_desc("aspect ratio a = H0/L0")
        .y_desc(y_desc)
        .draw()?;
    Ok(chart)
}

/// The measured laws of run-out and height as curves over a = 0.65 … `1.25 max_aspect`.
fn law_curves(max_aspect: f64) -> [Vec<(f64, f64)>; 2] {
    let law = NGUYEN_BUI_FUKAGAWA;
    let grid: Vec<f64> = (0..=60)
        .map(|k| 0.65 * (1.25 * max_aspect / 0.65).powf(k as f64 / 60.0))
        .collect();
    [
        grid.iter().map(|&a| (a, law.runout(a).unwrap())).collect(),
        grid.iter().map(|&a| (a, law.final_height(a))).collect(),
    ]
}

/// Run-out and height of every method against the laws.
fn plot_methods(
    all: &[(&str, Vec<CollapseResult>)],
    path: &Path,
) -> Result<(), Box<dyn std::error::Error>> {
    let root = BitMapBackend::new(path, (900, 650)).into_drawing_area();
    let mut chart = law_chart(
        &root,
        "Column collapse by method (lines: measured laws)",
        "(L∞ − L0)/L0 (circles) and H∞/L0 (triangles)",
        FIT_MAX_ASPECT,
    )?;
    let [runout_law, height_law] = law_curves(FIT_MAX_ASPECT);
    chart.draw_series(LineSeries::new(runout_law, BLACK.stroke_width(2)))?;
    chart.draw_series(LineSeries::new(height_law, BLACK.stroke_width(2)))?;
    let colours = [BLUE, CYAN, RED, MAGENTA];
    for ((name, rows), colour) in all.iter().zip(colours) {
        chart
            .draw_series(LineSeries::new(
                rows.iter().map(|r| (r.aspect, r.normalized_runout)),
                colour.stroke_width(1),
            ))?
            .label(*name)
            .legend(move |(x, y)| Circle::new((x + 10, y), 5, colour.filled()));
        chart.draw_series(
            rows.iter()
                .map(|r| Circle::new((r.aspect, r.normalized_runout), 5, colour.filled())),
        )?;
        chart.draw_series(LineSeries::new(
            rows.iter().map(|r| (r.aspect, r.normalized_height)),
            colour.stroke_width(1),
        ))?;
        chart
            .draw_series(rows.iter().map(|r| {
                TriangleMarker::new((r.aspect, r.normalized_height), 6, colour.filled())
            }))?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

fn write_tables(
    rows: &[CollapseResult],
    cells: usize,
    out: &Path,
) -> Result<(), Box<dyn std::error::Error>> {
    let law = NGUYEN_BUI_FUKAGAWA;
    let mut csv = String::from(
        "aspect,runout,runout_law,height,height_law,final_kinetic,worst_yield,particles,steps,seconds\n",
    );
    let mut md = String::new();
    writeln!(
        md,
        "# Granular column collapse (plane strain) against measured power laws\n"
    )?;
    writeln!(md, "Regenerate: `cargo run --release --example granular_collapse` (this table: {cells} cells across the column).\n")?;
    writeln!(md, "Drucker–Prager (φ = 19.8°, ψ = 0, c = 0, E = 0.84 MPa, ν = 0.3, ρ = 2650 kg/m³), column L0 = 0.1 m wide against a slip wall, floor with Coulomb friction μ = tan φ, quadratic B-spline, APIC, CFL 0.3, run for 8 sqrt(H0/g). Run-out: the front of the contiguous deposit (a gap wider than four particle spacings ends it); height: the highest particle. Laws: Nguyen, Bui & Fukagawa (2015), true 2D aluminium-rod columns: (L∞ − L0)/L0 = 3.25 a^0.96 (0.65 ≤ a ≤ 1.5), 3.80 a^0.73 (a ≥ 1.5); H∞/L0 = a / (1.42 a^(2/3)) (a ≥ 0.65), H∞ = H0 below.\n")?;
    writeln!(md, "| a = H0/L0 | run-out (L∞−L0)/L0 | law | ratio | height H∞/L0 | law | ratio | KE/(m g H0) at end | particles | steps | run time (s) |")?;
    writeln!(md, "|---|---|---|---|---|---|---|---|---|---|---|")?;
    for r in rows {
        let a = r.aspect;
        let rl = law.runout(a);
        let hl = law.final_height(a);
        writeln!(
            csv,
            "{a},{},{},{},{hl},{:e},{:e},{},{},{:.2}",
            r.normalized_runout,
            rl.map_or(String::from(""), |v| v.to_string()),
            r.normalized_height,
            r.final_kinetic,
            r.worst_yield,
            r.particles,
            r.steps,
            r.seconds
        )?;
        writeln!(
            md,
            "| {a} | {:.3} | {} | {} | {:.3} | {hl:.3} | {:.3} | {:.1e} | {} | {} | {:.1} |",
            r.normalized_runout,
            rl.map_or("–".into(), |v| format!("{v:.3}")),
            rl.map_or("–".into(), |v| format!("{:.3}", r.normalized_runout / v)),
            r.normalized_height,
            r.normalized_height / hl,
            r.final_kinetic,
            r.particles,
            r.steps,
            r.seconds
        )?;
    }
    let (run_exp, h_exp) = exponents_of(rows, 1.5, FIT_MAX_ASPECT);
    writeln!(md, "\nFitted exponents over 1.5 ≤ a ≤ {FIT_MAX_ASPECT} (the fitted range): run-out {run_exp:.3} (law 0.73, ratio {:.2}); final height H∞/L0 {h_exp:.3} (law 1/3, ratio {:.2}).", run_exp / 0.73, h_exp / (1.0 / 3.0))?;
    let (run_exp, h_exp) = exponents_of(rows, 3.0, f64::INFINITY);
    writeln!(md, "\nOver a ≥ 3 (to a = {}): run-out {run_exp:.3} (ratio {:.2}); final height {h_exp:.3} (ratio {:.2}).", ASPECTS[ASPECTS.len() - 1], run_exp / 0.73, h_exp / (1.0 / 3.0))?;
    writeln!(md, "\nThe yield function after the return mapping never exceeds round-off: largest f/E at the end over all runs {:.1e}.", rows.iter().map(|r| r.worst_yield).fold(f64::NEG_INFINITY, f64::max))?;
    writeln!(
        md,
        "\n![run-out and height](collapse.png)\n\n![heap at a = 2, plastic strain](heap_a2.png)"
    )?;
    std::fs::write(out.join("collapse.csv"), csv)?;
    std::fs::write(out.join("README.md"), md)?;
    Ok(())
}

fn plot(rows: &[CollapseResult], path: &Path) -> Result<(), Box<dyn std::error::Error>> {
    let root = BitMapBackend::new(path, (900, 650)).into_drawing_area();
    let mut chart = law_chart(
        &root,
        "Column collapse: rkmpm against Nguyen, Bui & Fukagawa (2015)",
        "(L∞ − L0)/L0 and H∞/L0",
        ASPECTS[ASPECTS.len() - 1],
    )?;
    let [runout_law, height_law] = law_curves(ASPECTS[ASPECTS.len() - 1]);
    chart
        .draw_series(LineSeries::new(runout_law, BLUE.stroke_width(2)))?
        .label("run-out, measured law")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE.stroke_width(2)));
    chart
        .draw_series(LineSeries::new(height_law, RED.stroke_width(2)))?
        .label("final height, measured law")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
    chart
        .draw_series(
            rows.iter()
                .map(|r| Circle::new((r.aspect, r.normalized_runout), 6, BLUE.filled())),
        )?
        .label("run-out, rkmpm")
        .legend(|(x, y)| Circle::new((x + 10, y), 5, BLUE.filled()));
    chart
        .draw_series(
            rows.iter()
                .map(|r| TriangleMarker::new((r.aspect, r.normalized_height), 7, RED.filled())),
        )?
        .label("final height, rkmpm")
        .legend(|(x, y)| TriangleMarker::new((x + 10, y), 6, RED.filled()));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

/// The final heap, particles coloured by equivalent plastic strain, with the colour bar of the
/// runner's pictures.
fn snapshot(sim: &rkmpm::Sim<2>, path: &Path) -> Result<(), Box<dyn std::error::Error>> {
    let title = "Final heap, a = 2";
    write_panels(
        &[(sim, title.to_string())],
        "plastic_strain",
        title,
        path,
        None,
    )?;
    Ok(())
}
