//! The convergence study: the manufactured solution of Wallstedt & Guilkey (2008) in 2D and 3D
//! for every method, over four grid refinements. Writes `docs/convergence/mms.csv`,
//! `docs/convergence/README.md` (table and fitted slopes) and PNG plots (error against h, error
//! against run time).
//!
//! ```text
//! cargo run --release --example convergence            # the full study
//! cargo run --release --example convergence -- --quick # coarser grids, for a look
//! cargo run --release --example convergence -- --placed # only the particles off the Gauss points
//! cargo run --release --example convergence -- --placed --budget 12           # in pieces: a fresh
//! cargo run --release --example convergence -- --placed --budget 12 --resume  # start, then resume
//! ```
//!
//! Each finished run of the off-Gauss study is kept in `docs/convergence/placed_runs.tsv`. With
//! `--budget MINUTES` the study starts no new run once that many minutes have passed and says so;
//! `--resume` keeps the runs already in the file (without it the file starts empty), so a study
//! longer than one sitting runs as several commands, and the tables and plots are written when
//! every run is in.
//!
//! The particles off the Gauss points (quarter points; jittered by ±30 %, three seeds; slip walls,
//! and fixed walls on the low faces with slip walls on the high ones; 2D to 128 cells, 3D to 24)
//! go to `docs/convergence/placed.md`, `placed_l2.png`, `placed3d_l2.png` and the error against
//! run time in `placed_time.png` and `placed3d_time.png`, with the run time to an L2 error of
//! 1e-3 and 1e-4: the cases where VC has something to correct. Run it on one thread
//! (`RAYON_NUM_THREADS=1`) for the run times the work-precision table compares.

use plotters::prelude::*;
use rkmpm::{Integration, Shape, Transfer};
use rkmpm_studies::verification::{
    fitted_slope, run_mms, run_mms_placed, time_to_error, AxisAlignedMms, ColumnRun, MmsRun,
    MmsWalls, Placement, SelfWeightColumn, Surface, TimeToError,
};
use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

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
            name: "B-spline 2 (MLS)",
            shape: Shape::BSpline2,
            integration: mp,
            transfer: Transfer::Mls,
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

const COLORS: [RGBColor; 12] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
    RGBColor(188, 189, 34),
    RGBColor(127, 127, 127),
    RGBColor(0, 0, 128),
    RGBColor(128, 0, 0),
];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let quick = std::env::args().any(|a| a == "--quick");
    let out = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/..")).join("docs/convergence");
    std::fs::create_dir_all(&out)?;
    plotters::style::register_font(
        "sans-serif",
        FontStyle::Normal,
        include_bytes!("../../assets/fonts/DejaVuSans.ttf"),
    )
    .map_err(|_| "font")?;

    let args: Vec<String> = std::env::args().collect();
    let budget = args
        .iter()
        .position(|a| a == "--budget")
        .and_then(|i| args.get(i + 1))
        .map(|m| m.parse::<f64>().map(|m| Duration::from_secs_f64(60.0 * m)))
        .transpose()
        .map_err(|_| "--budget takes a number of minutes")?;
    let mut runs = RunCache::open(
        out.join("placed_runs.tsv"),
        args.iter().any(|a| a == "--resume"),
        budget.map(|b| Instant::now() + b),
    )?;
    if !placed_study(&out, quick, &mut runs)? {
        eprintln!(
            "the budget is spent with {} runs in {}: run again with --resume",
            runs.rows.len(),
            runs.path.display()
        );
        return Ok(());
    }
    if args.iter().any(|a| a == "--placed") {
        return Ok(());
    }
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
    writeln!(
        md,
        "With the particles off the Gauss points (quarter points, jittered): [placed.md](placed.md).\n"
    )?;
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
    column_study(&mut md, &out, quick)?;
    pressure_study(&mut md, &out, quick)?;
    std::fs::write(out.join("README.md"), md)?;
    eprintln!("wrote {}", out.display());
    Ok(())
}

/// The elastic column compressed under its own weight: vertical stress against the exact
/// `−ρ0 g (H − Y)`, table and a profile plot at the finest grid.
fn column_study(
    md: &mut String,
    out: &Path,
    quick: bool,
) -> Result<(), Box<dyn std::error::Error>> {
    let col = SelfWeightColumn::default();
    let pic = Transfer::PicFlip { flip: 0.0 };
    let grids: &[usize] = if quick { &[8, 16] } else { &[8, 16, 32] };
    let rk1 = Shape::Rk {
        order: 1,
        support: 2.0,
    };
    let rk2 = Shape::Rk {
        order: 2,
        support: 3.0,
    };
    let cases: [(&str, Shape, Integration); 7] = [
        (
            "linear (standard MPM)",
            Shape::Linear,
            Integration::MaterialPoint,
        ),
        ("B-spline 2", Shape::BSpline2, Integration::MaterialPoint),
        ("B-spline 3", Shape::BSpline3, Integration::MaterialPoint),
        ("RK1", rk1, Integration::MaterialPoint),
        ("RK1 + VC1", rk1, Integration::Vc { order: 1 }),
        ("RK2", rk2, Integration::MaterialPoint),
        ("RK2 + VC2", rk2, Integration::Vc { order: 2 }),
    ];
    writeln!(
        md,
        "## Elastic column under its own weight (cell crossing)\n"
    )?;
    writeln!(md, "Neo-Hookean column (E = 1e5 Pa, ν = 0.3, ρ0 = 1000 kg/m³, H = 1 m) between slip walls on a fixed floor, gravity ramped to 10 m/s² over 2 s and held 1 s, PIC; the bottom is compressed by about 10%, so particles cross cells. Error: `sqrt(Σ (σ_yy − σ_exact)² V0 / Σ σ_exact² V0)` with `σ_exact = −ρ0 g (H − Y)` at each particle's reference height.\n")?;
    writeln!(
        md,
        "| method | cells over the height | σ_yy error | run time (s) |\n|---|---|---|---|"
    )?;
    let mut finest: Vec<(&str, ColumnRun)> = Vec::new();
    for (name, shape, integration) in cases {
        for &cells in grids {
            match col.run(cells, shape, integration, pic) {
                Ok(r) => {
                    eprintln!(
                        "column {name:<22} {cells:>3} cells: σ_yy error {:.3e}  {:.2} s",
                        r.stress_error, r.seconds
                    );
                    writeln!(
                        md,
                        "| {name} | {cells} | {:.3e} | {:.2} |",
                        r.stress_error, r.seconds
                    )?;
                    if cells == *grids.last().unwrap()
                        || (cells == grids[grids.len() - 2] && name.starts_with("linear"))
                    {
                        finest.push((name, r));
                    }
                }
                Err(e) => {
                    eprintln!("column {name:<22} {cells:>3} cells: failed: {e}");
                    writeln!(
                        md,
                        "| {name} | {cells} | failed: {} | |",
                        e.to_string().replace('|', "/")
                    )?;
                }
            }
        }
    }
    writeln!(md, "\nRK2 is left out: with a free surface its lumped node masses `Σ m_p Ψ_I` turn negative at the top (see FINDINGS.md).\n")?;
    writeln!(
        md,
        "![vertical stress along the column](column_profile.png)\n"
    )?;

    let path = out.join("column_profile.png");
    let root = BitMapBackend::new(&path, (900, 650)).into_drawing_area();
    root.fill(&WHITE)?;
    let smin = -col.density * col.gravity * col.height;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Column under its own weight: σ_yy along the height",
            ("sans-serif", 22),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..col.height, (1.3 * smin)..(0.3 * -smin))?;
    chart
        .configure_mesh()
        .x_desc("reference height Y (m)")
        .y_desc("σ_yy (Pa)")
        .draw()?;
    chart
        .draw_series(LineSeries::new(
            [(0.0, smin), (col.height, 0.0)],
            BLACK.stroke_width(2),
        ))?
        .label("exact −ρ0 g (H − Y)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(2)));
    for (i, (name, r)) in finest.iter().enumerate() {
        let c = COLORS[i % COLORS.len()];
        chart
            .draw_series(
                r.profile
                    .iter()
                    .map(|&(y, s, _)| Circle::new((y, s), 3, c.filled())),
            )?
            .label(format!("{name} ({} cells)", r.cells))
            .legend(move |(x, y)| Circle::new((x + 10, y), 4, c.filled()));
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
    let series: Vec<Series> = series
        .into_iter()
        .enumerate()
        .map(|(i, (name, pts))| (name.to_string(), COLORS[i % COLORS.len()], pts))
        .collect();
    let caption = format!(
        "{dim}D manufactured solution: {what} against {}",
        if x_time { "run time" } else { "h" }
    );
    let xlabel = if x_time {
        "run time (s)"
    } else {
        "cell size h"
    };
    draw_loglog(&series, &caption, xlabel, what, path, !x_time)
}

/// A named line of points in a log-log plot, with its colour.
type Series = (String, RGBColor, Vec<(f64, f64)>);

/// Draws `series` on log-log axes into `path`, with reference slopes 1, 2 and 3 through the
/// coarsest point of the first series when `slopes` is set (error against `h`: the legend in the
/// lower right); without them (error against run time) the legend goes to the upper right,
/// where the long runs of large errors would be.
fn draw_loglog(
    series: &[Series],
    caption: &str,
    xlabel: &str,
    ylabel: &str,
    path: &Path,
    slopes: bool,
) -> Result<(), Box<dyn std::error::Error>> {
    let all: Vec<(f64, f64)> = series.iter().flat_map(|s| s.2.iter().copied()).collect();
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
    let mut chart = ChartBuilder::on(&root)
        .caption(caption, ("sans-serif", 22))
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
        .y_desc(ylabel)
        .x_label_formatter(&|v| format!("{v:.2e}"))
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .draw()?;
    for (name, c, pts) in series {
        let c = *c;
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))?
            .label(name.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        chart.draw_series(pts.iter().map(|&p| Circle::new(p, 4, c.filled())))?;
    }
    if slopes {
        // Reference slopes 1, 2 and 3 through the coarsest point of the first series.
        if let Some(&(x0, y0)) = series[0].2.first() {
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
        .position(match slopes {
            true => SeriesLabelPosition::LowerRight,
            false => SeriesLabelPosition::UpperRight,
        })
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

/// One finished run of the off-Gauss study.
#[derive(Debug, Clone, Copy)]
struct Measured {
    l2: f64,
    energy: f64,
    seconds: f64,
}

/// The off-Gauss study's finished runs, kept in a file so that the study can run in pieces.
struct RunCache {
    path: PathBuf,
    /// The runs by [`RunCache::key`].
    rows: HashMap<String, Measured>,
    /// No new run starts after this.
    deadline: Option<Instant>,
}

impl RunCache {
    fn open(
        path: PathBuf,
        resume: bool,
        deadline: Option<Instant>,
    ) -> Result<Self, Box<dyn std::error::Error>> {
        let mut rows = HashMap::new();
        if resume && path.exists() {
            for line in std::fs::read_to_string(&path)?.lines().skip(1) {
                let f: Vec<&str> = line.split('\t').collect();
                let bad = || format!("{}: bad line {line:?}", path.display());
                if f.len() != 8 {
                    return Err(bad().into());
                }
                let num = |i: usize| f[i].parse::<f64>().map_err(|_| bad());
                let run = Measured {
                    l2: num(5)?,
                    energy: num(6)?,
                    seconds: num(7)?,
                };
                rows.insert(f[..5].join("\t"), run);
            }
        } else {
            std::fs::write(
                &path,
                "dim\tparticles\tmethod\tcells\tseed\tl2_error\tenergy_error\tseconds\n",
            )?;
        }
        Ok(Self {
            path,
            rows,
            deadline,
        })
    }

    fn key(dim: usize, particles: &str, method: &str, cells: usize, seed: usize) -> String {
        format!("{dim}\t{particles}\t{method}\t{cells}\t{seed}")
    }

    /// The run under `key`: from the file, or run now and added to it; `None` once the budget
    /// is spent.
    fn get(
        &mut self,
        key: String,
        run: impl FnOnce() -> rkmpm::Result<MmsRun>,
    ) -> Result<Option<Measured>, Box<dyn std::error::Error>> {
        if let Some(&row) = self.rows.get(&key) {
            return Ok(Some(row));
        }
        if self.deadline.is_some_and(|d| Instant::now() >= d) {
            return Ok(None);
        }
        let r = run()?;
        let row = Measured {
            l2: r.errors.l2,
            energy: r.errors.energy,
            seconds: r.seconds,
        };
        let mut file = std::fs::OpenOptions::new().append(true).open(&self.path)?;
        use std::io::Write as _;
        writeln!(
            file,
            "{key}\t{:e}\t{:e}\t{:.3}",
            row.l2, row.energy, row.seconds
        )?;
        self.rows.insert(key, row);
        Ok(Some(row))
    }
}

/// The manufactured solution with the particles off the Gauss points, at the quarter points
/// and jittered by ±30 % of their spacing (seeds 1, 2, 3), for the quadratic and cubic B-splines
/// with material-point integration and RK1 + VC1 with the surface found from the particles (what a
/// user who gives no boundary points gets), between slip walls and between fixed (low) and slip
/// (high) walls: 2D to 128 cells, 3D to 24. Writes `placed.md`
/// (tables, band over the seeds, slopes, run time to an error), `placed_l2.png`,
/// `placed3d_l2.png`, `placed_time.png` and `placed3d_time.png`.
///
/// `false` when the budget ran out before every run was in.
fn placed_study(
    out: &Path,
    quick: bool,
    runs: &mut RunCache,
) -> Result<bool, Box<dyn std::error::Error>> {
    let mut md = String::from("# Convergence off the Gauss points (manufactured solution)\n\n");
    writeln!(
        md,
        "Generated by `cargo run --release --example convergence -- --placed`{}; do not edit by \
         hand. The study's problem (see `README.md` here: slip walls on every face), 2 particles \
         per cell per direction at the quarter points of each cell, or moved from there by a \
         uniform random amount of up to ±30 % of their spacing per direction (seeds 1, 2, 3: the \
         band is the smallest and largest error over them). \"Fixed + slip walls\": fixed walls \
         on the low faces and slip walls on the high ones, the solution's components multiplied \
         by `sin(π X_b / 2)` along the other axes (`MmsWalls::FixedLowSlipHigh`). APIC; RK1 + \
         VC1 with the surface found from the particles. Run times on {} thread(s).\n",
        if quick { " --quick" } else { "" },
        rayon::current_num_threads()
    )?;
    // 3D RK1 + VC1 takes about 25 s at 16 cells and 130 s at 24 on one thread, 16 times
    // as long per doubling of the cells (8 times the particles, twice the steps), so the 3D
    // part stops at 24 cells (32 would take about 7 minutes a run).
    let (grids2, grids3): (&[usize], &[usize]) = if quick {
        (&[8, 16, 32], &[4, 6, 8])
    } else {
        (&[8, 16, 32, 64, 128], &[8, 12, 16, 24])
    };
    let path = out.join("placed.md");
    let write =
        |md: &str| std::fs::write(&path, md).map_err(|e| format!("{}: {e}", path.display()));
    if !placed_dimension::<2>(&mut md, out, grids2, runs)? {
        return Ok(false);
    }
    write(&md)?;
    if !placed_dimension::<3>(&mut md, out, grids3, runs)? {
        return Ok(false);
    }
    write(&md)?;
    Ok(true)
}

/// One dimension of [`placed_study`]: its table, slopes and plot; `false` when the budget ran
/// out first (every run that fits is still made, and nothing is drawn).
fn placed_dimension<const D: usize>(
    md: &mut String,
    out: &Path,
    grids: &[usize],
    runs: &mut RunCache,
) -> Result<bool, Box<dyn std::error::Error>> {
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
        (
            "cubic B-spline",
            Shape::BSpline3,
            Integration::MaterialPoint,
        ),
        ("RK1 + VC1", rk1, Integration::Vc { order: 1 }),
    ];
    let jitter = |seed| Placement::Jittered {
        fraction: 0.3,
        seed,
    };
    let (slip, mixed) = (MmsWalls::Slip, MmsWalls::FixedLowSlipHigh);
    let placements = [
        ("quarter points", vec![Placement::Uniform], slip),
        (
            "jittered ±30 %",
            vec![jitter(1), jitter(2), jitter(3)],
            slip,
        ),
        (
            "quarter points, fixed + slip walls",
            vec![Placement::Uniform],
            mixed,
        ),
        (
            "jittered ±30 % (seed 1), fixed + slip walls",
            vec![jitter(1)],
            mixed,
        ),
    ];
    writeln!(
        md,
        "## {D}D\n\n| particles | method | cells | L2 error | energy error | run time (s), each |\n|---|---|---|---|---|---|"
    )?;
    let mut slopes = String::from(
        "\n| particles | method | fitted L2 slope over the last three grids, each seed |\n|---|---|---|\n",
    );
    let mut series: Vec<Series> = Vec::new();
    // Error against run time, per placement and method: each seed's `(L2, seconds)` by grid.
    let mut work: Vec<Work> = Vec::new();
    let mut timed: Vec<Series> = Vec::new();
    let mut complete = true;
    for (k, (pname, list, walls)) in placements.iter().enumerate() {
        let mms = AxisAlignedMms {
            walls: *walls,
            ..AxisAlignedMms::default()
        };
        for (j, &(mname, shape, integration)) in methods.iter().enumerate() {
            let colour = COLORS[(methods.len() * k + j) % COLORS.len()];
            let mut l2 = vec![Vec::new(); list.len()];
            let mut runs_of = vec![Vec::new(); list.len()];
            for &cells in grids {
                let mut errors = Vec::new();
                for (s, &placement) in list.iter().enumerate() {
                    let key = RunCache::key(D, pname, mname, cells, s + 1);
                    let Some(run) = runs.get(key, || {
                        run_mms_placed::<D>(
                            &mms,
                            cells,
                            2,
                            placement,
                            Surface::Found,
                            shape,
                            integration,
                            Transfer::Apic,
                            0.015,
                            0.3,
                        )
                    })?
                    else {
                        complete = false;
                        continue;
                    };
                    eprintln!(
                        "{D}D {pname}, {mname}, {cells} cells, #{s}: L2 {:.3e}  energy {:.3e}  {:.1} s",
                        run.l2, run.energy, run.seconds
                    );
                    l2[s].push(run.l2);
                    runs_of[s].push((run.l2, run.seconds));
                    errors.push(run);
                }
                if !complete {
                    continue;
                }
                let band = |f: &dyn Fn(&Measured) -> f64| {
                    let (lo, hi) = errors
                        .iter()
                        .map(f)
                        .fold((f64::MAX, f64::MIN), |a, e| (a.0.min(e), a.1.max(e)));
                    if lo == hi {
                        format!("{lo:.3e}")
                    } else {
                        format!("{lo:.3e} – {hi:.3e}")
                    }
                };
                let seconds: Vec<String> =
                    errors.iter().map(|r| format!("{:.1}", r.seconds)).collect();
                writeln!(
                    md,
                    "| {pname} | {mname} | {cells} | {} | {} | {} |",
                    band(&|r| r.l2),
                    band(&|r| r.energy),
                    seconds.join(", ")
                )?;
            }
            if !complete {
                continue;
            }
            let h: Vec<f64> = grids.iter().map(|&c| 1.0 / c as f64).collect();
            let last = h.len().saturating_sub(3);
            let fitted: Vec<String> = l2
                .iter()
                .map(|e| format!("{:.2}", fitted_slope(&h[last..], &e[last..])))
                .collect();
            writeln!(slopes, "| {pname} | {mname} | {} |", fitted.join(", "))?;
            for (s, e) in l2.iter().enumerate() {
                let name = match list.len() {
                    1 => format!("{mname}, {pname}"),
                    _ => format!("{mname}, {pname}, seed {}", s + 1),
                };
                series.push((
                    name.clone(),
                    colour,
                    h.iter().copied().zip(e.iter().copied()).collect(),
                ));
                if *walls == slip {
                    let points = runs_of[s].iter().map(|&(e, t)| (t.max(1e-3), e)).collect();
                    timed.push((name, colour, points));
                }
            }
            work.push((pname, mname, runs_of));
        }
    }
    if !complete {
        return Ok(false);
    }
    md.push_str(&slopes);
    let png = if D == 2 {
        "placed_l2.png".to_string()
    } else {
        format!("placed{D}d_l2.png")
    };
    writeln!(md, "\n![{D}D: L2 error against h]({png})")?;
    draw_loglog(
        &series,
        &format!("{D}D manufactured solution off the Gauss points: L2 error against h"),
        "cell size h",
        "L2 error",
        &out.join(png),
        true,
    )?;
    work_precision(md, &work)?;
    let time_png = if D == 2 {
        "placed_time.png".to_string()
    } else {
        format!("placed{D}d_time.png")
    };
    writeln!(
        md,
        "\n![{D}D: L2 error against run time, slip walls]({time_png})\n"
    )?;
    draw_loglog(
        &timed,
        &format!("{D}D off the Gauss points, slip walls: L2 error against run time"),
        "run time (s)",
        "L2 error",
        &out.join(time_png),
        false,
    )?;
    Ok(true)
}

/// One placement and method of the off-Gauss study: their names and each seed's `(L2 error,
/// seconds)` by grid.
type Work<'a> = (&'a str, &'a str, Vec<Vec<(f64, f64)>>);

/// The errors the work-precision table asks each method to reach.
const WORK_TARGETS: [f64; 2] = [1e-3, 1e-4];

/// The run time to each of [`WORK_TARGETS`] per placement and method (every seed), and its
/// ratio to the fastest B-spline's for the same particles (the slowest seed of each).
fn work_precision(md: &mut String, work: &[Work]) -> Result<(), Box<dyn std::error::Error>> {
    let seconds = |t: f64| match t {
        t if t >= 100.0 => format!("{t:.0}"),
        t if t >= 10.0 => format!("{t:.1}"),
        t if t >= 1.0 => format!("{t:.2}"),
        t => format!("{t:.3}"),
    };
    let cell = |r: &TimeToError| match *r {
        TimeToError::Between(t) => seconds(t),
        TimeToError::AtMost(t) => format!("≤ {}", seconds(t)),
        TimeToError::Never(e) => format!("never ({e:.2e})"),
    };
    // The slowest seed's time, `None` when a seed never reaches the error.
    let worst = |runs: &[Vec<(f64, f64)>], target: f64| -> Option<f64> {
        runs.iter()
            .map(|r| match time_to_error(r, target) {
                TimeToError::Between(t) | TimeToError::AtMost(t) => Some(t),
                TimeToError::Never(_) => None,
            })
            .try_fold(0.0f64, |a, t| t.map(|t| a.max(t)))
    };
    writeln!(
        md,
        "\nWork-precision: the run time to an L2 error of 1e-3 and 1e-4 (log-log interpolation \
         between the two grids around it, each seed; \"≤\": already on the coarsest grid; \
         \"never\": no grid gets there, with the smallest error), and its ratio to the fastest \
         B-spline's for the same particles (slowest seed of each).\n\n\
         | particles | method | to 1e-3 (s) | to 1e-4 (s) | ratio to the best B-spline, 1e-3 | 1e-4 |\n\
         |---|---|---|---|---|---|"
    )?;
    for &(pname, mname, ref runs) in work {
        let mut cols = Vec::new();
        for target in WORK_TARGETS {
            let each: Vec<String> = runs
                .iter()
                .map(|r| cell(&time_to_error(r, target)))
                .collect();
            cols.push(each.join(", "));
        }
        for target in WORK_TARGETS {
            let best = work
                .iter()
                .filter(|w| w.0 == pname && w.1.contains("B-spline"))
                .filter_map(|w| worst(&w.2, target))
                .fold(None, |a: Option<f64>, t| Some(a.map_or(t, |a| a.min(t))));
            cols.push(match (worst(runs, target), best) {
                (Some(t), Some(b)) => format!("{:.2}", t / b),
                (Some(_), None) => "no B-spline gets there".to_string(),
                (None, _) => "—".to_string(),
            });
        }
        writeln!(md, "| {pname} | {mname} | {} |", cols.join(" | "))?;
    }
    Ok(())
}

/// The nearly incompressible column (ν = 0.49) with jittered particles: pressure against the exact
/// pressure, with and without VC, table and a profile plot.
fn pressure_study(
    md: &mut String,
    out: &Path,
    quick: bool,
) -> Result<(), Box<dyn std::error::Error>> {
    let col = SelfWeightColumn {
        poisson: 0.49,
        jitter: 0.3,
        ..Default::default()
    };
    let pic = Transfer::PicFlip { flip: 0.0 };
    let grids: &[usize] = if quick { &[16] } else { &[16, 32] };
    let rk1 = Shape::Rk {
        order: 1,
        support: 2.0,
    };
    let cases: [(&str, Shape, Integration); 6] = [
        (
            "linear (standard MPM)",
            Shape::Linear,
            Integration::MaterialPoint,
        ),
        ("B-spline 2", Shape::BSpline2, Integration::MaterialPoint),
        (
            "B-spline 2 + VC1",
            Shape::BSpline2,
            Integration::Vc { order: 1 },
        ),
        ("RK1", rk1, Integration::MaterialPoint),
        ("RK1 + VC1", rk1, Integration::Vc { order: 1 }),
        ("RK1 + VC2", rk1, Integration::Vc { order: 2 }),
    ];
    writeln!(
        md,
        "## Nearly incompressible column: pressure oscillation\n"
    )?;
    writeln!(md, "The column above with ν = 0.49 and particles jittered by up to ±30% of their spacing (boundary points on the lattice faces). Error: `sqrt(Σ (p − p_exact)² V0 / Σ p_exact² V0)` with the exact pressure of the uniaxial-strain neo-Hookean column at each particle's reference height (`SelfWeightColumn::exact_pressure`); it is the amplitude of the pressure oscillation.\n")?;
    writeln!(md, "| method | cells over the height | pressure error | σ_yy error | run time (s) |\n|---|---|---|---|---|")?;
    let mut profiles: Vec<(&str, ColumnRun)> = Vec::new();
    for (name, shape, integration) in cases {
        for &cells in grids {
            match col.run(cells, shape, integration, pic) {
                Ok(r) => {
                    eprintln!(
                        "pressure {name:<22} {cells:>3} cells: p error {:.3e}  {:.2} s",
                        r.pressure_error, r.seconds
                    );
                    writeln!(
                        md,
                        "| {name} | {cells} | {:.3e} | {:.3e} | {:.2} |",
                        r.pressure_error, r.stress_error, r.seconds
                    )?;
                    if cells == grids[0] && name.starts_with("RK1") && !name.ends_with("VC2") {
                        profiles.push((name, r));
                    }
                }
                Err(e) => writeln!(
                    md,
                    "| {name} | {cells} | failed: {} | | |",
                    e.to_string().replace('|', "/")
                )?,
            }
        }
    }
    writeln!(md, "\n![pressure along the column](pressure_profile.png)\n")?;
    let path = out.join("pressure_profile.png");
    let root = BitMapBackend::new(&path, (900, 650)).into_drawing_area();
    root.fill(&WHITE)?;
    let pmax = col.exact_pressure(0.0);
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "ν = 0.49, jittered particles, {} cells: pressure along the height",
                grids[0]
            ),
            ("sans-serif", 22),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..col.height, (-0.3 * pmax)..(1.4 * pmax))?;
    chart
        .configure_mesh()
        .x_desc("reference height Y (m)")
        .y_desc("pressure (Pa)")
        .draw()?;
    let exact: Vec<(f64, f64)> = (0..=100)
        .map(|i| {
            let y = col.height * i as f64 / 100.0;
            (y, col.exact_pressure(y))
        })
        .collect();
    chart
        .draw_series(LineSeries::new(exact, BLACK.stroke_width(2)))?
        .label("exact")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(2)));
    for (i, (name, r)) in profiles.iter().enumerate() {
        let c = COLORS[(i + 3) % COLORS.len()];
        chart
            .draw_series(LineSeries::new(
                r.profile.iter().map(|&(y, _, p)| (y, p)),
                c.stroke_width(1),
            ))?
            .label(*name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        chart.draw_series(
            r.profile
                .iter()
                .map(|&(y, _, p)| Circle::new((y, p), 3, c.filled())),
        )?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}
