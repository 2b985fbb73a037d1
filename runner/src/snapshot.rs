//! A PNG picture of the particles, coloured by a chosen field: the first horizontal axis against
//! the last (x–y in 2D, x–z in 3D), each particle a dot, with a colour bar that names the field,
//! its unit and its range. In 3D the picture is a section: the particles of one layer about a
//! plane `y = const`, as a cut through the body shows it (all of them projected onto the x–z
//! plane would draw the body's outline and hide its inside).

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

/// One value per particle, in id order (as `Sim::field` gives them): the magnitude of vectors,
/// the von Mises stress (with the out-of-plane stress of plane strain in 2D), `det F`. Refuses a
/// field no material of the run has (plastic strain, damage) rather than draw zeros.
pub fn values<const D: usize>(sim: &Sim<D>, name: &str) -> Result<(Vec<f64>, String), String> {
    if name == "material" {
        let ps = sim.particles();
        return Ok((
            ps.material().iter().map(|&k| k as f64).collect(),
            "material id".into(),
        ));
    }
    let field = Field::ALL
        .iter()
        .copied()
        .find(|f| f.name() == name && *f != Field::Position && *f != Field::ReferencePosition)
        .ok_or_else(|| format!("--png {name}: choose one of {}", FIELDS.join(", ")))?;
    if !sim.carries(field) {
        return Err(format!(
            "--png {name}: no material of this scene has {} (every particle's is 0); choose \
             another field",
            name.replace('_', " ")
        ));
    }
    let raw = sim.field(field);
    let per = field.components(D);
    let chunks = raw.chunks(per);
    Ok(match field {
        Field::Velocity | Field::Displacement => (
            chunks
                .map(|v| v.iter().map(|c| c * c).sum::<f64>().sqrt())
                .collect(),
            format!(
                "|{name}| ({})",
                if field == Field::Velocity { "m/s" } else { "m" }
            ),
        ),
        Field::Stress => (
            chunks
                .zip(sim.field(Field::Pressure))
                .map(|(s, p)| von_mises::<D>(s, p))
                .collect(),
            "von Mises stress (Pa)".into(),
        ),
        Field::DeformationGradient => (
            chunks
                .map(|f| rkmpm::determinant(&rkmpm::Matrix::<D>::from_row_slice(f)))
                .collect(),
            "det F".into(),
        ),
        _ => {
            let unit = match field {
                Field::Pressure => " (Pa)",
                Field::Volume if D == 2 => " (m²)",
                Field::Volume => " (m³)",
                Field::Mass if D == 2 => " (kg/m)",
                Field::Mass => " (kg)",
                _ => "",
            };
            (raw, format!("{}{unit}", name.replace('_', " ")))
        }
    })
}

/// The von Mises stress `√(3/2 s : s)` of the Cauchy stress `s` (row-major, `D × D`) whose
/// pressure is `p`: in 2D the out-of-plane stress of plane strain, `σzz = −3p − σxx − σyy`,
/// is part of the deviator.
pub fn von_mises<const D: usize>(s: &[f64], p: f64) -> f64 {
    let m = rkmpm::Matrix::<D>::from_row_slice(s);
    let mut full = rkmpm::Matrix::<3>::zeros();
    full.view_mut((0, 0), (D, D)).copy_from(&m);
    if D == 2 {
        full[(2, 2)] = -3.0 * p - m.trace();
    }
    let dev = full - rkmpm::Matrix::<3>::identity() * (full.trace() / 3.0);
    (1.5 * dev.norm_squared()).sqrt()
}

/// The particles one panel draws (every one in 2D, the section's in 3D), in id order: their ids,
/// positions and values.
pub struct Drawn<const D: usize> {
    pub id: Vec<usize>,
    pub position: Vec<rkmpm::Vector<D>>,
    pub value: Vec<f64>,
}

/// What a picture of `sim` coloured by `field` draws within `cut`, and the field's label.
pub fn drawn<const D: usize>(
    sim: &Sim<D>,
    field: &str,
    cut: &Section,
) -> Result<(Drawn<D>, String), String> {
    let (v, label) = values(sim, field)?;
    // Positions in id order, as the values.
    let ps = sim.particles();
    let x = ps.position();
    let id: Vec<usize> = (0..x.len()).filter(|&p| cut.holds(&x[p])).collect();
    if id.is_empty() && !x.is_empty() {
        let (lo, hi) = extremes(&x.iter().map(|p| p[1]).collect::<Vec<_>>());
        return Err(format!(
            "the picture's section y = {:e} m holds no particle (within {:.3e} m); the bodies \
             span y from {lo:e} to {hi:e} m: choose a section there (run.section, --section)",
            cut.at, cut.half_width
        ));
    }
    Ok((
        Drawn {
            position: id.iter().map(|&p| x[p]).collect(),
            value: id.iter().map(|&p| v[p]).collect(),
            id,
        },
        label,
    ))
}

/// How much a drawn field oscillates from particle to particle: `√(Σ (v_p − v̄_p)²) / √(Σ v_p²)`
/// over the drawn particles, `v̄_p` the mean of the values within `radius` of `x_p` (itself
/// included). A smooth field reads near 0 (a linear one exactly 0 where the neighbourhood is
/// symmetric), particle-to-particle noise of the field's own size near 1: the pressure
/// oscillation that material-point integration shows and VC removes. 0 for a field that is 0
/// everywhere.
pub fn roughness<const D: usize>(drawn: &Drawn<D>, radius: f64) -> f64 {
    use std::collections::HashMap;
    let cell = |x: &rkmpm::Vector<D>| -> [i64; 3] {
        let mut c = [0; 3];
        for k in 0..D {
            c[k] = (x[k] / radius).floor() as i64;
        }
        c
    };
    let mut bins: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    for (i, x) in drawn.position.iter().enumerate() {
        bins.entry(cell(x)).or_default().push(i);
    }
    let (mut deviation, mut size) = (0.0, 0.0);
    for (i, x) in drawn.position.iter().enumerate() {
        let c = cell(x);
        let (mut sum, mut count) = (0.0, 0usize);
        let reach = |k: usize| if k < D { -1..=1 } else { 0..=0 };
        for a in reach(0) {
            for b in reach(1) {
                for e in reach(2) {
                    let Some(near) = bins.get(&[c[0] + a, c[1] + b, c[2] + e]) else {
                        continue;
                    };
                    for &j in near {
                        if (drawn.position[j] - x).norm() <= radius {
                            sum += drawn.value[j];
                            count += 1;
                        }
                    }
                }
            }
        }
        let v = drawn.value[i];
        deviation += (v - sum / count as f64).powi(2);
        size += v * v;
    }
    match size > 0.0 {
        true => (deviation / size).sqrt(),
        false => 0.0,
    }
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

/// The section a 3D picture shows: the plane `y = at` and the particles within half a particle
/// spacing of it (the spacing `∛(mean volume)` of all runs' particles; a 2D picture shows every
/// particle), one layer of an
/// undeformed lattice (two where the plane falls half-way between layers). `at` defaults to the
/// middle of the particles' extent along y.
pub struct Section {
    pub at: f64,
    pub half_width: f64,
}

impl Section {
    pub fn of<const D: usize>(runs: &[&Sim<D>], at: Option<f64>) -> Self {
        let (mut lo, mut hi, mut volume, mut count) = (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0);
        for sim in runs {
            let ps = sim.particles();
            for p in 0..ps.len() {
                lo = lo.min(ps.position()[p][1]);
                hi = hi.max(ps.position()[p][1]);
                volume += ps.reference_volume()[p]
                    * rkmpm::determinant(&ps.deformation_gradient()[p]).abs();
                count += 1;
            }
        }
        let mean = volume / count.max(1) as f64;
        let spacing = if D == 2 { mean.sqrt() } else { mean.cbrt() };
        Section {
            at: at.unwrap_or(0.5 * (lo + hi)),
            half_width: 0.5 * spacing * (1.0 + 1e-9),
        }
    }

    /// Whether a particle at `x` is drawn.
    pub fn holds<const D: usize>(&self, x: &rkmpm::Vector<D>) -> bool {
        D == 2 || (x[1] - self.at).abs() <= self.half_width
    }
}

/// Writes one 3D run's picture as the section through its first layer of particles along y:
/// next to a symmetry plane y = 0, the profile of a half or quarter model.
pub fn write_symmetry_section(
    sim: &Sim<3>,
    field: &str,
    title: &str,
    path: &Path,
) -> Result<(), String> {
    let first = sim
        .field(Field::Position)
        .chunks(3)
        .map(|x| x[1])
        .fold(f64::INFINITY, f64::min);
    write_panels(&[(sim, title.to_string())], field, title, path, Some(first))
}

/// Writes the pictures of several runs of one scene side by side, each under its label, on one
/// colour scale and the same axes, so that their fields compare at a glance. In 3D only the
/// particles of the section `y = section` are drawn ([`Section`]; the middle of the bodies by
/// default), and the colour scale is theirs.
pub fn write_panels<const D: usize>(
    runs: &[(&Sim<D>, String)],
    field: &str,
    title: &str,
    path: &Path,
    section: Option<f64>,
) -> Result<(), String> {
    let sims: Vec<&Sim<D>> = runs.iter().map(|(s, _)| *s).collect();
    let cut = Section::of(&sims, section);
    // Per run: the particles drawn, their positions and values.
    let mut panels = Vec::with_capacity(runs.len());
    for (sim, _) in runs {
        panels.push(drawn(*sim, field, &cut)?);
    }
    // Each panel's roughness, over the particles within 1.5 particle spacings.
    let rough: Vec<f64> = panels
        .iter()
        .map(|(d, _)| roughness(d, 3.0 * cut.half_width))
        .collect();
    let mut fields = Vec::with_capacity(panels.len());
    let mut shown = Vec::with_capacity(panels.len());
    for (d, label) in panels {
        fields.push((d.value, label));
        shown.push(d.position);
    }
    let label = fields.first().map(|f| f.1.clone()).unwrap_or_default();
    let fail = |e: Box<dyn std::error::Error>| format!("writing {}: {e}", path.display());
    plotters::style::register_font(
        "sans-serif",
        FontStyle::Normal,
        include_bytes!("../../assets/fonts/DejaVuSans.ttf"),
    )
    .map_err(|_| "the bundled font cannot be read".to_string())?;
    let (a, b) = (0, D - 1);
    let cell = runs
        .iter()
        .map(|(s, _)| s.grid().cell_size())
        .fold(0.0, f64::max);
    let range = |axis: usize| {
        let (lo, hi) = runs
            .iter()
            .flat_map(|(s, _)| s.field(Field::Position).into_iter().skip(axis).step_by(D))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), c| {
                (l.min(c), h.max(c))
            });
        let pad = 0.05 * (hi - lo).max(cell);
        (lo - pad, hi + pad)
    };
    let ((x0, x1), (y0, y1)) = (range(a), range(b));
    let all: Vec<f64> = fields.iter().flat_map(|f| f.0.iter().copied()).collect();
    let scale = ColourScale::of(&all, field == "material");
    let panel = if runs.len() > 1 { 800u32 } else { 1000 };
    let width = panel * runs.len().max(1) as u32;
    let head = if runs.len() > 1 { 40.0 } else { 0.0 };
    let bar = 70;
    let height = ((panel as f64 - 90.0) * (y1 - y0) / (x1 - x0) + 110.0 + head).clamp(300.0, 1400.0)
        as u32
        + bar;
    let root = BitMapBackend::new(path, (width, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| fail(Box::new(e)))?;
    let (root, bar_area) = root.split_vertically(height - bar);
    let both = if runs.len() > 1 { " of both runs" } else { "" };
    draw_colour_bar(&bar_area, &scale, &format!("{label}{both}")).map_err(fail)?;
    let time = runs.first().map_or(0.0, |(s, _)| s.time());
    let (root, caption) = if runs.len() > 1 {
        let area = root
            .titled(
                &format!("{title}, t = {time:.4e} s: {label}, one colour scale"),
                ("sans-serif", 18),
            )
            .map_err(|e| fail(Box::new(e)))?;
        (area, None)
    } else {
        (root, Some(format!("{title}, t = {time:.4e} s")))
    };
    let section_note = if D == 3 {
        format!(", section y = {:.4} m (±{:.2e} m)", cut.at, cut.half_width)
    } else {
        String::new()
    };
    let axes = ["x", "y", "z"];
    let areas = root.split_evenly((1, runs.len().max(1)));
    let panels = areas.iter().zip(runs).zip(&fields).zip(&shown).zip(&rough);
    for ((((area, (sim, name)), (v, _)), x), &r) in panels {
        // The roughness where it says something (not of material ids).
        let rough = match field {
            "material" => String::new(),
            _ => format!(", roughness {r:.3}"),
        };
        let mut chart = ChartBuilder::on(area)
            .caption(
                caption.clone().map_or_else(
                    || {
                        let (l, h) = extremes(v);
                        format!("{name}: {l:.3e} to {h:.3e}{rough}{section_note}")
                    },
                    |c| format!("{c}{rough}{section_note}"),
                ),
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
        let dot =
            ((panel as f64 * sim.grid().cell_size() / (x1 - x0)) / 4.0).clamp(1.0, 6.0) as i32;
        chart
            .draw_series(
                x.iter().zip(v).map(|(p, &c)| {
                    Circle::new((p[a], p[b]), dot, colour(scale.position(c)).filled())
                }),
            )
            .map_err(|e| fail(Box::new(e)))?;
    }
    root.present().map_err(|e| fail(Box::new(e)))?;
    Ok(())
}

/// The smallest and largest of `v`.
fn extremes(v: &[f64]) -> (f64, f64) {
    v.iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &c| {
            (l.min(c), h.max(c))
        })
}

/// The values the colours run between. A field with a long tail (a few particles far beyond
/// the rest: the pressure spikes of material-point integration) is drawn between its 1st and
/// 99th percentiles, so that the body shows, and values beyond take the end colours; the bar
/// says so and gives the extremes. A field whose positive values span at least two decades and
/// whose median sits nearer the middle of the bar on a log scale than on the linear one (plastic
/// strain: most of a collapsed heap near 1, shear bands up to 23) is drawn on a log scale from
/// the 1st percentile of its positive values to its largest, smaller values at the low end; the
/// bar says so.
struct ColourScale {
    lo: f64,
    hi: f64,
    extremes: (f64, f64),
    clipped: bool,
    log: bool,
}

impl ColourScale {
    fn of(values: &[f64], discrete: bool) -> Self {
        let extremes = extremes(values);
        let mut sorted: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
        sorted.sort_by(f64::total_cmp);
        let at = |q: f64| sorted[((sorted.len() - 1) as f64 * q).round() as usize];
        let (lo, hi, clipped) = if sorted.len() < 100 || discrete {
            (extremes.0, extremes.1, false)
        } else {
            let (p1, p99) = (at(0.01), at(0.99));
            // A tail counts as long when the extremes span twice what the percentiles do.
            let long = (extremes.1 - extremes.0) > 2.0 * (p99 - p1) && p99 > p1;
            if long {
                (p1, p99, true)
            } else {
                (extremes.0, extremes.1, false)
            }
        };
        let hi = if hi > lo { hi } else { lo + 1.0 };
        let linear = ColourScale {
            lo,
            hi,
            extremes,
            clipped,
            log: false,
        };
        if sorted.len() < 100 || discrete {
            return linear;
        }
        // A signed field (pressure) keeps the linear scale: a log one would hide one sign.
        let positive = &sorted[sorted.partition_point(|&v| v <= 0.0)..];
        if positive.is_empty() || extremes.0 < 0.0 {
            return linear;
        }
        let low = positive[((positive.len() - 1) as f64 * 0.01).round() as usize];
        if extremes.1 < 100.0 * low {
            return linear;
        }
        let log = ColourScale {
            lo: low,
            hi: extremes.1,
            extremes,
            clipped: false,
            log: true,
        };
        // The scale on which the body (its median) sits nearer the middle of the bar.
        let median = at(0.5);
        let off_centre = |s: &ColourScale| (s.position(median) - 0.5).abs();
        if off_centre(&log) < off_centre(&linear) {
            log
        } else {
            linear
        }
    }

    /// Where `v` falls on the colour bar, from 0 to 1.
    fn position(&self, v: f64) -> f64 {
        let t = if self.log {
            (v.max(self.lo).ln() - self.lo.ln()) / (self.hi.ln() - self.lo.ln())
        } else {
            (v - self.lo) / (self.hi - self.lo)
        };
        t.clamp(0.0, 1.0)
    }
}

/// A horizontal colour bar under the panels: the gradient with its end and middle values, and
/// the field's name and unit (and, when clipped to percentiles, the extremes).
fn draw_colour_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    scale: &ColourScale,
    label: &str,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let (w, _) = area.dim_in_pixel();
    let (x0, x1) = (w as i32 / 5, 4 * w as i32 / 5);
    let (y0, y1) = (8, 28);
    let steps = 200;
    for i in 0..steps {
        let a = x0 + (x1 - x0) * i / steps;
        let b = x0 + (x1 - x0) * (i + 1) / steps;
        let t = (i as f64 + 0.5) / steps as f64;
        area.draw(&Rectangle::new([(a, y0), (b, y1)], colour(t).filled()))?;
    }
    area.draw(&Rectangle::new([(x0, y0), (x1, y1)], BLACK.stroke_width(1)))?;
    let font = ("sans-serif", 14).into_font();
    let mid = if scale.log {
        (scale.lo * scale.hi).sqrt()
    } else {
        0.5 * (scale.lo + scale.hi)
    };
    for (x, v) in [(x0, scale.lo), ((x0 + x1) / 2, mid), (x1, scale.hi)] {
        area.draw(&Text::new(
            format!("{v:.3e}"),
            (x - 30, y1 + 4),
            font.clone(),
        ))?;
    }
    let text = if scale.clipped {
        format!(
            "{label}: 1st to 99th percentile, beyond drawn at the ends (all from {:.3e} to {:.3e})",
            scale.extremes.0, scale.extremes.1
        )
    } else if scale.log {
        format!(
            "{label}: log scale, from the 1st percentile of the positive values (all from {:.3e})",
            scale.extremes.0
        )
    } else {
        label.to_string()
    };
    area.draw(&Text::new(text, (x0, y1 + 22), font))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::{ColourScale, Section};
    use rkmpm::{Material, Sim, Vector};

    /// A 3D section holds one layer of a lattice about its plane (two where the plane falls
    /// half-way between layers, as the default middle does for an even count), a 2D picture
    /// every particle.
    #[test]
    fn a_section_holds_the_layers_at_its_plane() {
        let mut sim = Sim::<3>::new([0.0; 3], [8; 3], 0.125).unwrap();
        let m = sim.add_material(Material::neo_hookean(1000.0, 1e5, 0.3).unwrap());
        let s = 0.0625;
        let x: Vec<Vector<3>> = (0..64)
            .map(|k| {
                Vector::<3>::new(
                    0.25 + s * (0.5 + (k % 4) as f64),
                    0.25 + s * (0.5 + (k / 4 % 4) as f64),
                    0.25 + s * (0.5 + (k / 16) as f64),
                )
            })
            .collect();
        sim.add_particles(m, &x, &[s * s * s; 64], None).unwrap();
        let count = |c: &Section| x.iter().filter(|p| c.holds(p)).count();
        let middle = Section::of(&[&sim], None);
        assert!((middle.at - 0.375).abs() < 1e-12 && (middle.half_width - 0.5 * s).abs() < 1e-9);
        assert_eq!(count(&middle), 32);
        let first = Section::of(&[&sim], Some(0.25 + 0.5 * s));
        assert_eq!(count(&first), 16);
        assert!(x.iter().filter(|p| first.holds(p)).all(|p| p[1] < 0.25 + s));
        assert_eq!(count(&Section::of(&[&sim], Some(0.9))), 0);
        let flat = Section {
            at: 0.0,
            half_width: 0.0,
        };
        assert!(flat.holds(&rkmpm::Vector::<2>::new(0.3, 0.7)));
    }

    /// A constant field has no roughness, a linear one none where the neighbourhood is
    /// symmetric and little over a whole lattice, a checkerboard of the field's own size about
    /// 1.
    #[test]
    fn roughness_tells_noise_from_smooth_fields() {
        let x: Vec<Vector<2>> = (0..400)
            .map(|k| Vector::<2>::new((k % 20) as f64, (k / 20) as f64))
            .collect();
        let panel = |value: Vec<f64>| super::Drawn {
            id: (0..400).collect(),
            position: x.clone(),
            value,
        };
        assert_eq!(super::roughness(&panel(vec![2.0; 400]), 1.5), 0.0);
        let linear = panel(x.iter().map(|p| 100.0 + p[0] + 2.0 * p[1]).collect());
        let r = super::roughness(&linear, 1.5);
        assert!(r > 0.0 && r < 0.01, "{r}");
        let checker = panel(
            (0..400)
                .map(|k| [1.0, -1.0][(k % 20 + k / 20) % 2])
                .collect(),
        );
        let r = super::roughness(&checker, 1.5);
        assert!(r > 0.8 && r <= 1.0, "{r}");
    }

    /// A body near zero with a few spikes is drawn between its percentiles; a field without a
    /// tail, and material ids, between their extremes.
    #[test]
    fn long_tails_are_clipped_to_percentiles_and_said_so() {
        let mut v: Vec<f64> = (0..1000).map(|i| i as f64 / 1000.0).collect();
        v[7] = 50.0;
        v[8] = -20.0;
        let s = ColourScale::of(&v, false);
        assert!(s.clipped);
        assert_eq!(s.extremes, (-20.0, 50.0));
        assert!(
            (s.lo - 0.01).abs() < 2e-3 && (s.hi - 0.99).abs() < 2e-3,
            "{} {}",
            s.lo,
            s.hi
        );
        let plain: Vec<f64> = (0..1000).map(|i| i as f64).collect();
        let s = ColourScale::of(&plain, false);
        assert!(!s.clipped);
        assert_eq!((s.lo, s.hi), (0.0, 999.0));
        let s = ColourScale::of(&v, true);
        assert!(!s.clipped);
        assert_eq!((s.lo, s.hi), (-20.0, 50.0));
        // A constant field still gets a scale of nonzero width.
        let s = ColourScale::of(&[3.0; 200], false);
        assert_eq!((s.lo, s.hi), (3.0, 4.0));
        assert!(!s.log && !ColourScale::of(&plain, false).log);
    }

    /// A positive field whose body sits at the bottom of a range of decades (plastic strain of a
    /// collapse: zeros, most near 1, a band up to 23) takes a log scale from its positive 1st
    /// percentile; the clipped field above, whose body fills its range, does not.
    #[test]
    fn skewed_positive_fields_take_a_log_scale() {
        let mut v: Vec<f64> = (0..1000).map(|i| 1e-3 * 1.01f64.powi(i % 500)).collect();
        v[0] = 0.0;
        v.extend((0..40).map(|i| 5.0 + 0.45 * i as f64));
        let s = ColourScale::of(&v, false);
        assert!(s.log && !s.clipped);
        assert_eq!(s.hi, 5.0 + 0.45 * 39.0);
        assert!(s.lo > 0.0 && s.lo < 2e-3, "{}", s.lo);
        assert_eq!(s.position(0.0), 0.0);
        assert_eq!(s.position(s.hi), 1.0);
        let mid = s.position((s.lo * s.hi).sqrt());
        assert!((mid - 0.5).abs() < 1e-12, "{mid}");
        // A heap's plastic strain: from 2e-3 to 1.5 for half the body, to 3 for most of the
        // rest, a band up to 23. Its median sits at 6 % of the linear bar and near the middle
        // of the log one.
        let heap: Vec<f64> = (0..1000)
            .map(|i| match i {
                0..500 => 2e-3 * 750f64.powf(i as f64 / 500.0),
                500..950 => 1.5 + 1.5 * (i - 500) as f64 / 450.0,
                _ => 3.0 + 20.0 * (i - 950) as f64 / 49.0,
            })
            .collect();
        let s = ColourScale::of(&heap, false);
        assert!(
            s.log && (s.position(1.5) - 0.5).abs() < 0.25,
            "{}",
            s.position(1.5)
        );
        // Values spanning less than two decades stay linear.
        let narrow: Vec<f64> = (0..1000)
            .map(|i| 1.0 + (i % 10) as f64 * 0.01 + if i < 20 { 50.0 } else { 0.0 })
            .collect();
        assert!(!ColourScale::of(&narrow, false).log);
    }
}
