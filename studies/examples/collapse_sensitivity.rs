//! Sensitivity of the granular column collapse to resolution, wall and material parameters: runs
//! one set of aspect ratios with the choices given and prints run-out and height against the
//! laws of Nguyen, Bui & Fukagawa (2015) as a Markdown table.
//!
//! `cargo run --release --example collapse_sensitivity -- --cells 32 --aspects 3,4 --wall friction --rods 2015`
//!
//! * `--cells N`: cells across the column (default 16).
//! * `--aspects a,b,..`: aspect ratios (default 1,2,3,4).
//! * `--wall slip|friction|fixed`: the wall at x = 0 (friction: μ = tan φ; default slip).
//! * `--rods 2008|2015`: Bui et al. (2008) rods (ρ 2650, E 0.84 MPa, φ 19.8°, default) or the
//!   set used with the later rod experiments (ρ 2040, E 5.84 MPa, φ 21.9°).
//! * `--floor MU`: floor friction coefficient (default tan φ).
//! * `--young E`: Young's modulus (Pa; default that of the rods' set).
//! * `--friction DEG`, `--dilatancy DEG`: friction and dilatancy angles (default those of the
//!   rods' set, dilatancy 0); the floor's μ stays tan of the rods' friction unless `--floor`.
//! * `--method bspline2|bspline2-mls|bspline2-vc|rk1|rk1-vc`: quadratic B-spline (default) or RK1
//!   (ã = 2), with material-point integration or VC of order 1 (the surface found from the
//!   particles at every step); `bspline2-mls` is the quadratic B-spline with the MLS transfer.
//! * `--flip F`: the PIC/FLIP transfer with FLIP fraction `F` instead of APIC (`0` is PIC, whose
//!   velocity smoothing dissipates energy where the velocity jumps, as at the column's impact).
//! * `--rheology d,Δμ,I0`: the μ(I) rate dependence of the friction (grain diameter in m, the
//!   friction gained at large inertial numbers, the reference inertial number); none by default.
//! * `--gate SPEED[,FRICTION]`: lift a rigid gate at `SPEED` m/s instead of releasing the column
//!   at once, meeting the soil with Coulomb friction `FRICTION` (default 0, a smooth gate).
//! * `--thick k1,k2,..`: also the run-out of the part of the deposit thicker than `k` particle
//!   spacings (`thick_front`), per `k`.
//!
//! Ends with the run-out and height exponents fitted over the aspect ratios ≥ 1.5.

use rkmpm::material::InertialRheology;
use rkmpm::walls::Wall;
use rkmpm::{Integration, Shape};
use rkmpm_studies::scenes::{
    log_log_slope, thick_front, Gate, GranularColumn, NGUYEN_BUI_FUKAGAWA,
};

/// One aspect ratio's normalized results for the exponents: aspect ratio, run-out, height, and
/// the run-out of the part thicker than each `--thick` value.
type Row = (f64, f64, f64, Vec<f64>);

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let value = |flag: &str| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|i| args.get(i + 1).cloned())
    };
    let cells: usize = value("--cells").map_or(Ok(16), |v| v.parse())?;
    let aspects: Vec<f64> = value("--aspects")
        .unwrap_or_else(|| "1,2,3,4".into())
        .split(',')
        .map(str::parse)
        .collect::<Result<_, _>>()?;
    let rods = value("--rods").unwrap_or_else(|| "2008".into());
    let mut base = GranularColumn {
        cells_across: cells,
        ..Default::default()
    };
    match rods.as_str() {
        "2008" => {}
        "2015" => {
            base.density = 2040.0;
            base.young = 5.84e6;
            base.friction_degrees = 21.9;
        }
        other => return Err(format!("--rods 2008|2015, got {other}").into()),
    }
    base.young = value("--young").map_or(Ok(base.young), |v| v.parse())?;
    let mu = base.friction_degrees.to_radians().tan();
    base.floor_friction = value("--floor").map_or(Ok(mu), |v| v.parse())?;
    base.friction_degrees = value("--friction").map_or(Ok(base.friction_degrees), |v| v.parse())?;
    base.dilatancy_degrees = value("--dilatancy").map_or(Ok(0.0), |v| v.parse())?;
    let wall = value("--wall").unwrap_or_else(|| "slip".into());
    base.wall = match wall.as_str() {
        "slip" => Wall::Slip,
        "friction" => Wall::Friction(mu),
        "fixed" => Wall::Fixed,
        other => return Err(format!("--wall slip|friction|fixed, got {other}").into()),
    };
    let method = value("--method").unwrap_or_else(|| "bspline2".into());
    let rk1 = Shape::Rk {
        order: 1,
        support: 2.0,
    };
    (base.shape, base.integration) = match method.as_str() {
        "bspline2" => (Shape::BSpline2, Integration::MaterialPoint),
        "bspline2-vc" => (Shape::BSpline2, Integration::Vc { order: 1 }),
        "rk1" => (rk1, Integration::MaterialPoint),
        "rk1-vc" => (rk1, Integration::Vc { order: 1 }),
        "bspline2-mls" => {
            base.transfer = rkmpm::Transfer::Mls;
            (Shape::BSpline2, Integration::MaterialPoint)
        }
        other => {
            return Err(format!(
                "--method bspline2|bspline2-mls|bspline2-vc|rk1|rk1-vc, got {other}"
            )
            .into())
        }
    };
    if let Some(f) = value("--flip") {
        let flip: f64 = f.parse()?;
        base.transfer = rkmpm::Transfer::PicFlip { flip };
    }
    if let Some(r) = value("--rheology") {
        let v: Vec<f64> = r.split(',').map(str::parse).collect::<Result<_, _>>()?;
        if v.len() != 3 {
            return Err("--rheology d,Δμ,I0".into());
        }
        base.rheology = Some(InertialRheology::new(v[1], v[2], v[0])?);
    }
    if let Some(g) = value("--gate") {
        let v: Vec<f64> = g.split(',').map(str::parse).collect::<Result<_, _>>()?;
        base.gate = match v[..] {
            [speed] => Some(Gate {
                speed,
                friction: 0.0,
            }),
            [speed, friction] => Some(Gate { speed, friction }),
            _ => return Err("--gate SPEED[,FRICTION]".into()),
        };
    }
    println!(
        "cells {cells}, wall {wall}, rods {rods}, E {:.3e}, φ {}°, ψ {}°, floor μ {:.3}, method {method}, transfer {:?}, rheology {:?}, gate {:?}\n",
        base.young, base.friction_degrees, base.dilatancy_degrees, base.floor_friction, base.transfer, base.rheology, base.gate
    );
    let thick: Vec<f64> = value("--thick").map_or(Ok(Vec::new()), |v| {
        v.split(',').map(str::parse).collect::<Result<_, _>>()
    })?;
    let thick_heads: String = thick
        .iter()
        .map(|k| format!(" run-out thicker than {k} q | ratio |"))
        .collect();
    println!(
        "| a | run-out | law | ratio | height | law | ratio |{thick_heads} KE end | steps | s |"
    );
    println!(
        "|---|---|---|---|---|---|---|{}---|---|---|",
        "---|---|".repeat(thick.len())
    );
    let mut rows: Vec<Row> = Vec::new();
    for a in aspects {
        let column = GranularColumn { aspect: a, ..base };
        let (r, sim) = column.run_observed(0, |_| Ok(()))?;
        let law = NGUYEN_BUI_FUKAGAWA.runout(a);
        let h_law = NGUYEN_BUI_FUKAGAWA.final_height(a);
        let ratio = |x: f64| law.map_or("–".into(), |l| format!("{:.3}", x / l));
        let q = sim.grid().cell_size() / 2.0;
        // The soil's particles only (a gate is material 1).
        let ps = sim.particles();
        let soil: Vec<_> = (0..ps.len())
            .filter(|&p| ps.material()[p] == 0)
            .map(|p| ps.position()[p])
            .collect();
        let thick_runouts: Vec<f64> = thick
            .iter()
            .map(|k| (thick_front(&soil, q, k * q) - column.width) / column.width)
            .collect();
        let thick_cells: String = thick_runouts
            .iter()
            .map(|t| format!(" {t:.3} | {} |", ratio(*t)))
            .collect();
        println!(
            "| {a} | {:.3} | {} | {} | {:.3} | {h_law:.3} | {:.3} |{thick_cells} {:.1e} | {} | {:.0} |",
            r.normalized_runout,
            law.map_or("–".into(), |l| format!("{l:.3}")),
            ratio(r.normalized_runout),
            r.normalized_height,
            r.normalized_height / h_law,
            r.final_kinetic,
            r.steps,
            r.seconds
        );
        rows.push((a, r.normalized_runout, r.normalized_height, thick_runouts));
    }
    let tall: Vec<_> = rows.iter().filter(|r| r.0 >= 1.5).collect();
    if tall.len() >= 2 {
        let fit = |f: &dyn Fn(&Row) -> f64| {
            log_log_slope(&tall.iter().map(|r| (r.0, f(r))).collect::<Vec<_>>())
        };
        print!(
            "\nExponents over a ≥ 1.5 (laws 0.73, 1/3): run-out {:.3}, height {:.3}",
            fit(&|r| r.1),
            fit(&|r| r.2)
        );
        for (i, k) in thick.iter().enumerate() {
            print!(", run-out thicker than {k} q {:.3}", fit(&|r| r.3[i]));
        }
        println!();
    }
    Ok(())
}
