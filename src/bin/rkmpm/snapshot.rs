//! A PNG picture of the particles, coloured by a chosen field: the first horizontal axis against
//! the last (x–y in 2D, x–z in 3D), each particle a dot, with the field's range in the caption.

use plotters::prelude::*;
use plotters::style::FontStyle;
use rkmpm::particles::Field;
use rkmpm::Sim;
use std::path::Path;

/// The fields a picture can be coloured by, with how a value per particle is made of them.
pub const FIELDS: [&str; 10] = [
    "velocity",
    "displacement",
    "stress",
    "pressure",
    "volume",
    "mass",
    "deformation_gradient",
    "plastic_strain",
    "damage",
    "material",
];

/// One value per particle: the magnitude of vectors, the von Mises stress, `det F`.
fn values<const D: usize>(sim: &Sim<D>, name: &str) -> Result<(Vec<f64>, String), String> {
    if name == "material" {
        let m = &sim.particles().material;
        return Ok((m.iter().map(|&k| k as f64).collect(), "material id".into()));
    }
    let field = Field::ALL
        .iter()
        .copied()
        .find(|f| f.name() == name && *f != Field::Position && *f != Field::ReferencePosition)
        .ok_or_else(|| format!("--png {name}: choose one of {}", FIELDS.join(", ")))?;
    let raw = sim.field(field);
    let per = field.components(D);
    let chunks = raw.chunks(per);
    Ok(match field {
        Field::Velocity | Field::Displacement => (
            chunks
                .map(|v| v.iter().map(|c| c * c).sum::<f64>().sqrt())
                .collect(),
            format!("|{name}|"),
        ),
        Field::Stress => (
            chunks
                .map(|s| {
                    let m = rkmpm::Matrix::<D>::from_row_slice(s);
                    let dev = m - rkmpm::Matrix::<D>::identity() * (m.trace() / D as f64);
                    (1.5 * dev.norm_squared()).sqrt()
                })
                .collect(),
            "von Mises stress (in-plane)".into(),
        ),
        Field::DeformationGradient => (
            chunks
                .map(|f| rkmpm::determinant(&rkmpm::Matrix::<D>::from_row_slice(f)))
                .collect(),
            "det F".into(),
        ),
        _ => (raw, name.replace('_', " ")),
    })
}

/// Blue (low) through green to red (high).
fn colour(t: f64) -> RGBColor {
    let t = t.clamp(0.0, 1.0);
    let stops = [
        (0.0, (48.0, 18.0, 160.0)),
        (0.33, (30.0, 150.0, 200.0)),
        (0.66, (120.0, 200.0, 60.0)),
        (1.0, (220.0, 40.0, 30.0)),
    ];
    let k = stops.iter().position(|s| s.0 >= t).unwrap_or(3).max(1);
    let (t0, a) = stops[k - 1];
    let (t1, b) = stops[k];
    let u = (t - t0) / (t1 - t0);
    RGBColor(
        (a.0 + u * (b.0 - a.0)) as u8,
        (a.1 + u * (b.1 - a.1)) as u8,
        (a.2 + u * (b.2 - a.2)) as u8,
    )
}

/// Writes the pictures of several runs of one scene side by side, each under its label, on one
/// colour scale and the same axes, so that their fields compare at a glance.
pub fn write_panels<const D: usize>(
    runs: &[(&Sim<D>, String)],
    field: &str,
    title: &str,
    path: &Path,
) -> Result<(), String> {
    let mut fields = Vec::with_capacity(runs.len());
    for (sim, _) in runs {
        fields.push(values(*sim, field)?);
    }
    let label = fields.first().map(|f| f.1.clone()).unwrap_or_default();
    let fail = |e: Box<dyn std::error::Error>| format!("writing {}: {e}", path.display());
    plotters::style::register_font(
        "sans-serif",
        FontStyle::Normal,
        include_bytes!("../../../assets/fonts/DejaVuSans.ttf"),
    )
    .map_err(|_| "the bundled font cannot be read".to_string())?;
    let (a, b) = (0, D - 1);
    let cell = runs
        .iter()
        .map(|(s, _)| s.grid().cell_size)
        .fold(0.0, f64::max);
    let range = |axis: usize| {
        let (lo, hi) = runs
            .iter()
            .flat_map(|(s, _)| s.particles().position.iter().map(move |p| p[axis]))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), c| {
                (l.min(c), h.max(c))
            });
        let pad = 0.05 * (hi - lo).max(cell);
        (lo - pad, hi + pad)
    };
    let ((x0, x1), (y0, y1)) = (range(a), range(b));
    let (lo, hi) = fields
        .iter()
        .flat_map(|f| f.0.iter())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &c| {
            (l.min(c), h.max(c))
        });
    let span = if hi > lo { hi - lo } else { 1.0 };
    let panel = if runs.len() > 1 { 800u32 } else { 1000 };
    let width = panel * runs.len().max(1) as u32;
    let head = if runs.len() > 1 { 40.0 } else { 0.0 };
    let height =
        ((panel as f64 - 90.0) * (y1 - y0) / (x1 - x0) + 110.0 + head).clamp(300.0, 1400.0) as u32;
    let root = BitMapBackend::new(path, (width, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| fail(Box::new(e)))?;
    let time = runs.first().map_or(0.0, |(s, _)| s.time());
    let scale = format!("{label} from {lo:.3e} (blue) to {hi:.3e} (red)");
    let (root, caption) = if runs.len() > 1 {
        let area = root
            .titled(
                &format!("{title}, t = {time:.4e} s: {scale}, one scale for both"),
                ("sans-serif", 18),
            )
            .map_err(|e| fail(Box::new(e)))?;
        (area, None)
    } else {
        (root, Some(format!("{title}, t = {time:.4e} s: {scale}")))
    };
    let axes = ["x", "y", "z"];
    let areas = root.split_evenly((1, runs.len().max(1)));
    for ((area, (sim, name)), (v, _)) in areas.iter().zip(runs).zip(&fields) {
        let mut chart = ChartBuilder::on(area)
            .caption(
                caption.clone().unwrap_or_else(|| name.clone()),
                ("sans-serif", 16),
            )
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(55)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|e| fail(Box::new(e)))?;
        chart
            .configure_mesh()
            .x_desc(format!("{} (m)", axes[a]))
            .y_desc(format!("{} (m)", axes[b]))
            .draw()
            .map_err(|e| fail(Box::new(e)))?;
        let dot = ((panel as f64 * sim.grid().cell_size / (x1 - x0)) / 4.0).clamp(1.0, 6.0) as i32;
        let x = &sim.particles().position;
        chart
            .draw_series(
                x.iter().zip(v).map(|(p, &c)| {
                    Circle::new((p[a], p[b]), dot, colour((c - lo) / span).filled())
                }),
            )
            .map_err(|e| fail(Box::new(e)))?;
    }
    root.present().map_err(|e| fail(Box::new(e)))?;
    Ok(())
}
