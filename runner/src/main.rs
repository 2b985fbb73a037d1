//! `rkmpm`: the command-line runner. Runs a scene file (or a bundled scene) end to end with a
//! progress bar, writes VTK frames for ParaView and prints a summary. `rkmpm --help` explains
//! every option.

#![forbid(unsafe_code)]

use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use rkmpm::io::vtk::VtkSeries;
use rkmpm::sim::{Energies, Momenta};
use rkmpm::Sim;
use rkmpm_runner::scene::{Scene, SceneSim, BUNDLED};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

#[derive(Parser)]
#[command(
    name = "rkmpm",
    version,
    about = "Run Material Point Method scenes (RK shape functions, VC integration) and write ParaView output",
    long_about = "Run Material Point Method scenes and write ParaView output.\n\n\
        Without a command, `rkmpm [SCENE] [OPTIONS]` is `rkmpm run [SCENE] [OPTIONS]`, and with \
        no scene it runs the default one (an elastic column settles on jittered particles, with and without VC). A scene is a TOML file (docs/SCENES.md lists every key) or the \
        name of a bundled scene (`rkmpm list`).",
    after_help = "Examples:\n  rkmpm                                  run the default scene into out/\n  \
        rkmpm run runner/scenes/taylor.toml --out runs/taylor\n  rkmpm run collapse --frames 80 --png plastic_strain\n  \
        rkmpm check my_scene.toml               read and build a scene without running it\n  \
        rkmpm list                              the bundled scenes"
)]
#[command(args_conflicts_with_subcommands = true)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// Without a command: the options of `run`.
    #[command(flatten)]
    run: RunArgs,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scene: build it, step it to its end time with adaptive steps, write VTK frames
    /// (<out>/<output>_NNNNN.vtu and <out>/<output>.pvd) and print a summary.
    Run(RunArgs),
    /// Read and build a scene without stepping it, with the overrides `run` takes; print what
    /// it holds and refuse what `run` would refuse.
    Check(RunArgs),
    /// List the bundled scenes.
    List,
    /// Print a bundled scene's TOML, to start a scene file of your own.
    Show {
        /// The name of a bundled scene.
        name: String,
    },
}

#[derive(clap::Args)]
struct RunArgs {
    /// A scene file (.toml) or the name of a bundled scene [default: column].
    scene: Option<String>,
    /// Directory for the VTK frames and the .pvd series (created if missing).
    #[arg(long, default_value = "out")]
    out: PathBuf,
    /// Overrides the scene's run.end_time (seconds of simulated time).
    #[arg(long)]
    end_time: Option<f64>,
    /// Overrides the scene's run.frames (VTK frames over the run; 0 writes none).
    #[arg(long)]
    frames: Option<usize>,
    /// Overrides the scene's run.vtk: the frames' arrays as raw bytes (binary, as ParaView
    /// writes them) or as text (ascii).
    #[arg(long, value_name = "FORMAT", value_parser = ["binary", "ascii"])]
    vtk: Option<String>,
    /// Overrides the scene's run.cfl (fraction of the stable time step, in (0, 1]).
    #[arg(long)]
    cfl: Option<f64>,
    /// Overrides the scene's run.max_steps (the most steps the run may take; default 10^9).
    #[arg(long)]
    max_steps: Option<u64>,
    /// Overrides the scene's run.png: at the end, write <out>/<output>.png, the particles
    /// coloured by this field (velocity, displacement, stress, pressure, volume, mass,
    /// deformation_gradient, plastic_strain, damage, material); `none` writes no picture.
    #[arg(long, value_name = "FIELD")]
    png: Option<String>,
    /// Overrides the scene's run.section: a 3D picture shows the particles about the plane
    /// y = SECTION (m); default the middle of the bodies.
    #[arg(long, value_name = "Y")]
    section: Option<f64>,
    /// Overrides the scene's run.threads: the simulation's worker threads (0 or default: one
    /// per core). Results do not depend on it.
    #[arg(long)]
    threads: Option<usize>,
    /// No progress bar, only the summary.
    #[arg(long, short)]
    quiet: bool,
    /// Also runs each body alone (no output) and splits the energy the summary puts on the
    /// impacts and the scheme into the bodies' own (transfers, time integration, walls) and
    /// their impacts on each other. Scenes of two bodies or more.
    #[arg(long)]
    split_dissipation: bool,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command.unwrap_or(Command::Run(cli.run)) {
        Command::Run(args) => run(args),
        Command::Check(args) => check(&args),
        Command::List => {
            for (name, text) in BUNDLED {
                let title = Scene::from_toml(text, name)
                    .map(|s| s.title)
                    .unwrap_or_default();
                println!("{name:<12} {title}");
            }
            Ok(())
        }
        Command::Show { name } => match BUNDLED.iter().find(|(n, _)| *n == name) {
            Some((_, text)) => {
                print!("{text}");
                Ok(())
            }
            None => Err(format!("no bundled scene {name:?} (rkmpm list)")),
        },
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// A scene from a file path or a bundled name.
fn load(scene: &str) -> Result<Scene, String> {
    if let Some((name, text)) = BUNDLED.iter().find(|(n, _)| *n == scene) {
        return Scene::from_toml(text, &format!("bundled scene {name}")).map_err(|e| e.message);
    }
    if !Path::new(scene).exists() {
        let names: Vec<&str> = BUNDLED.iter().map(|(n, _)| *n).collect();
        return Err(format!(
            "{scene}: no such file, and not a bundled scene ({})",
            names.join(", ")
        ));
    }
    Scene::load(scene).map_err(|e| e.message)
}

fn check(args: &RunArgs) -> Result<(), String> {
    let s = scene_of(args)?;
    let (sim, other) = validate(&s)?;
    match &sim {
        SceneSim::D2(m) => describe(&s, m),
        SceneSim::D3(m) => describe(&s, m),
    }
    if let Some((other, sim)) = &other {
        println!("compared with the [compare] options:");
        match sim {
            SceneSim::D2(m) => describe(other, m),
            SceneSim::D3(m) => describe(other, m),
        }
    }
    println!("ok");
    Ok(())
}

/// What `check` and `run` both do before anything is computed: builds the scene (and its
/// comparison), and refuses what a run would refuse (combinations of options the step does
/// not support, a picture of a field that does not exist).
fn validate(scene: &Scene) -> Result<(SceneSim, Option<(Scene, SceneSim)>), String> {
    if let Some(p) = &scene.run.png {
        if !rkmpm_runner::snapshot::FIELDS.contains(&p.as_str()) {
            return Err(format!(
                "png = {p:?}: choose one of {}",
                rkmpm_runner::snapshot::FIELDS.join(", ")
            ));
        }
    }
    let checked = |s: &Scene, what: &str| -> Result<SceneSim, String> {
        let sim = s.build().map_err(|e| format!("{what}{}", e.message))?;
        match &sim {
            SceneSim::D2(m) => m.check_options(),
            SceneSim::D3(m) => m.check_options(),
        }
        .map_err(|e| format!("{what}{}", e.message))?;
        Ok(sim)
    };
    let sim = checked(scene, "")?;
    // The frames' count and size, and a picture of a field the materials have.
    let carries = |f: rkmpm::particles::Field| match &sim {
        SceneSim::D2(m) => m.carries(f),
        SceneSim::D3(m) => m.carries(f),
    };
    for f in [
        rkmpm::particles::Field::PlasticStrain,
        rkmpm::particles::Field::Damage,
    ] {
        if scene.run.png.as_deref() == Some(f.name()) && !carries(f) {
            return Err(format!(
                "png = {:?}: no material of this scene has {} (every particle's would be 0); \
                 choose another field",
                f.name(),
                f.name().replace('_', " ")
            ));
        }
    }
    match &sim {
        SceneSim::D2(m) => check_output(scene, m),
        SceneSim::D3(m) => check_output(scene, m),
    }?;
    if let Some(y) = scene.run.section {
        match &sim {
            SceneSim::D2(_) => {
                return Err(
                    "run.section (the plane of a 3D picture) is for 3D scenes; a 2D \
                            picture shows every particle"
                        .into(),
                )
            }
            SceneSim::D3(m) => {
                let (lo, hi) = (m.grid().origin()[1], m.grid().upper()[1]);
                if !(lo..=hi).contains(&y) {
                    return Err(format!(
                        "run.section = {y:e}: the plane y = {y:e} m lies outside the grid \
                         (y from {lo:e} to {hi:e} m)"
                    ));
                }
            }
        }
    }
    // The comparison run, if the scene has one, writes no frames: its picture is the point.
    let other = scene
        .comparison()
        .map(|mut other| {
            other.run.frames = 0;
            checked(&other, "[compare]: ").map(|sim| (other, sim))
        })
        .transpose()?;
    match (&sim, &other) {
        (SceneSim::D2(_), Some((_, SceneSim::D3(_))))
        | (SceneSim::D3(_), Some((_, SceneSim::D2(_)))) => {
            Err("[compare] gave a scene of another dimension".into())
        }
        _ => Ok((sim, other)),
    }
}

fn describe<const D: usize>(scene: &Scene, sim: &Sim<D>) {
    let g = sim.grid();
    let o = sim.options();
    println!("scene: {}", scene.title);
    println!(
        "{D}D, grid {} cells of {:e} m, {} particles, {} material{}; {}, {}",
        g.cells()
            .iter()
            .map(|c| c.to_string())
            .collect::<Vec<_>>()
            .join(" x "),
        g.cell_size(),
        sim.particle_count(),
        sim.materials().len(),
        if sim.materials().len() == 1 { "" } else { "s" },
        method(sim),
        match o.scheme {
            rkmpm::Scheme::Usl => "USL",
            rkmpm::Scheme::Musl => "MUSL",
        }
    );
}

/// The scene `args` names (the default one without a name), with the overrides it gives.
fn scene_of(args: &RunArgs) -> Result<Scene, String> {
    let name = args.scene.clone().unwrap_or_else(|| "column".into());
    let mut scene = load(&name)?;
    if let Some(t) = args.end_time {
        scene.run.end_time = t;
    }
    if let Some(f) = args.frames {
        scene.run.frames = f;
    }
    if let Some(c) = args.cfl {
        scene.run.cfl = c;
    }
    if let Some(n) = args.max_steps {
        scene.run.max_steps = n;
    }
    if let Some(f) = &args.vtk {
        scene.run.vtk = match f.as_str() {
            "ascii" => rkmpm::options::VtkFormat::Ascii,
            _ => rkmpm::options::VtkFormat::Binary,
        };
    }
    if let Some(p) = &args.png {
        scene.run.png = (p != "none").then(|| p.clone());
    }
    if args.section.is_some() {
        scene.run.section = args.section;
    }
    if args.threads.is_some() {
        scene.run.threads = args.threads;
    }
    Ok(scene)
}

fn run(args: RunArgs) -> Result<(), String> {
    let scene = scene_of(&args)?;
    let built = validate(&scene)?;
    std::fs::create_dir_all(&args.out)
        .map_err(|e| format!("cannot create {}: {e}", args.out.display()))?;
    match built {
        (SceneSim::D2(mut sim), None) => run_scenes(&scene, &mut sim, None, &args),
        (SceneSim::D3(mut sim), None) => run_scenes(&scene, &mut sim, None, &args),
        (SceneSim::D2(mut sim), Some((c, SceneSim::D2(mut o)))) => {
            run_scenes(&scene, &mut sim, Some((&c, &mut o)), &args)
        }
        (SceneSim::D3(mut sim), Some((c, SceneSim::D3(mut o)))) => {
            run_scenes(&scene, &mut sim, Some((&c, &mut o)), &args)
        }
        _ => unreachable!("validate refuses a comparison of another dimension"),
    }
}

/// Runs the scene, then its comparison if it has one, and writes the picture: one panel, or
/// the two runs side by side on one colour scale.
fn run_scenes<const D: usize>(
    scene: &Scene,
    sim: &mut Sim<D>,
    other: Option<(&Scene, &mut Sim<D>)>,
    args: &RunArgs,
) -> Result<(), String> {
    let picture = |runs: &[(&Sim<D>, String)]| -> Result<(), String> {
        if let Some(field) = &scene.run.png {
            let path = args.out.join(format!("{}.png", scene.run.output));
            rkmpm_runner::snapshot::write_panels(
                runs,
                field,
                &scene.title,
                &path,
                scene.run.section,
            )?;
            println!("picture: {} (coloured by {field})", path.display());
        }
        Ok(())
    };
    if let Err(e) = run_scene(scene, sim, args) {
        // The last good state's picture, then why the run stopped.
        picture(&[(&*sim, method(sim))])?;
        return Err(e);
    }
    if args.split_dissipation {
        split_dissipation(scene, sim)?;
    }
    let other = match other {
        Some((s, o)) => {
            println!("\ncompared with the [compare] options:");
            run_scene(s, o, args)?;
            Some(o)
        }
        None => None,
    };
    let mut runs = vec![(&*sim, method(sim))];
    if let Some(o) = &other {
        runs.push((&**o, method(o)));
    }
    picture(&runs)?;
    Ok(())
}

/// Splits the energy no term of the ledger measures (`other_dissipation`: the transfers, the
/// time integration, impacts) by running each body of the scene alone to the same time with
/// the same options: what the bodies lose alone is the scheme's (and the walls'), the rest is
/// what their impacts on each other took.
fn split_dissipation<const D: usize>(scene: &Scene, sim: &Sim<D>) -> Result<(), String> {
    if scene.bodies.len() < 2 {
        return Err(format!(
            "--split-dissipation: the scene has {} body; the split needs two or more",
            scene.bodies.len()
        ));
    }
    let together = sim
        .energy_balance()
        .map_err(|e| e.message)?
        .other_dissipation;
    let mut alone = 0.0;
    for (b, body) in scene.bodies.iter().enumerate() {
        let mut one = scene.clone();
        one.bodies = vec![body.clone()];
        one.compare = None;
        alone += other_dissipation_alone(&one, sim.time())
            .map_err(|e| format!("--split-dissipation, body {} alone: {e}", b + 1))?;
    }
    println!(
        "                       of which each body alone (transfers, time integration, walls) \
         {alone:.4e}, the bodies' impacts on each other {:.4e}",
        together - alone
    );
    Ok(())
}

/// The energy no term of the ledger measures, of `scene` run from its start to `end`.
fn other_dissipation_alone(scene: &Scene, end: f64) -> Result<f64, String> {
    fn run<const D: usize>(mut sim: Sim<D>, scene: &Scene, end: f64) -> Result<f64, String> {
        sim.set_energy_accounting(true);
        sim.set_max_steps_per_advance(scene.run.max_steps)
            .map_err(|e| e.message)?;
        sim.advance(end, scene.run.cfl)
            .map_err(|e| plain_reason(&e.message))?;
        Ok(sim
            .energy_balance()
            .map_err(|e| e.message)?
            .other_dissipation)
    }
    match scene.build().map_err(|e| e.message)? {
        SceneSim::D2(sim) => run(sim, scene, end),
        SceneSim::D3(sim) => run(sim, scene, end),
    }
}

/// The method of a run in a mechanician's words: shape functions, integration, transfer.
fn method<const D: usize>(sim: &Sim<D>) -> String {
    let o = sim.options();
    let shape = match o.shape {
        rkmpm::Shape::Linear => "linear hats".to_string(),
        rkmpm::Shape::BSpline2 => "quadratic B-spline".to_string(),
        rkmpm::Shape::BSpline3 => "cubic B-spline".to_string(),
        rkmpm::Shape::Rk { order, support } => format!("RK order {order}, support {support}"),
    };
    let integration = match o.integration {
        rkmpm::Integration::MaterialPoint => "material points".to_string(),
        rkmpm::Integration::Vc { order } => format!("VC order {order}"),
    };
    let transfer = match o.transfer {
        rkmpm::Transfer::Apic => "APIC".to_string(),
        rkmpm::Transfer::PicFlip { flip } => format!("PIC/FLIP {flip}"),
        rkmpm::Transfer::Mls => "MLS".to_string(),
    };
    format!("{shape}, {integration}, {transfer}")
}

/// At most this many frames a run (a series ParaView still opens).
const MAX_FRAMES: usize = 10_000;
/// At most this many bytes of frames a run, estimated from the first frame before the run.
const MAX_OUTPUT_BYTES: f64 = 10.0 * (1u64 << 30) as f64;

/// Refuses, before a step is taken, a run whose frames would be more than [`MAX_FRAMES`] or
/// fill more than [`MAX_OUTPUT_BYTES`] (the frames of a run all have the particles' count, and
/// a binary frame its size; a text frame is estimated from the first one).
fn check_output<const D: usize>(scene: &Scene, sim: &Sim<D>) -> Result<(), String> {
    let frames = scene.run.frames;
    if frames > MAX_FRAMES {
        return Err(format!(
            "run.frames = {frames}: at most {MAX_FRAMES} frames a run; choose fewer (run.frames, \
             --frames)"
        ));
    }
    if frames == 0 {
        return Ok(());
    }
    let one = rkmpm::io::vtk::particles_vtu(sim, scene.run.vtk).len() as f64;
    let total = one * (frames + 1) as f64;
    if total > MAX_OUTPUT_BYTES {
        return Err(format!(
            "run.frames = {frames}: {} frames of {:.4} MiB each would write about {:.4} GiB, \
             above the bound of {:.4} GiB; choose at most {} frames (run.frames, --frames)",
            frames + 1,
            one / (1u64 << 20) as f64,
            total / (1u64 << 30) as f64,
            MAX_OUTPUT_BYTES / (1u64 << 30) as f64,
            (MAX_OUTPUT_BYTES / one) as usize - 1
        ));
    }
    Ok(())
}

/// Steps to the end time with adaptive steps, writing the frames at the steps the run takes
/// anyway (frame `k` of `n` at the first step that reaches `k/n` of the end time), so that the
/// number of frames changes nothing of the physics. When a step is refused, the last good
/// state is written as a frame and summarised before the error is returned.
fn run_scene<const D: usize>(
    scene: &Scene,
    sim: &mut Sim<D>,
    args: &RunArgs,
) -> Result<(), String> {
    describe(scene, sim);
    let run = &scene.run;
    let end = run.end_time;
    let mut series = VtkSeries::new(args.out.join(&run.output));
    series.set_format(run.vtk);
    let interactive = !args.quiet && std::io::stderr().is_terminal();
    // The bar counts thousandths of the end time.
    let bar = if interactive {
        let bar = ProgressBar::new(1000);
        bar.set_style(
            ProgressStyle::with_template(
                "{bar:30.cyan/blue} {percent:>3}%  {msg}  [{elapsed_precise} elapsed, {eta_precise} left]",
            )
            .expect("a valid template"),
        );
        bar
    } else {
        ProgressBar::hidden()
    };
    let (p0, e0) = (sim.momenta(), sim.energies());
    // The summary tells where the energy went (one more pass over the particles per step).
    sim.set_energy_accounting(true);
    let n = sim.particle_count() as f64;
    let start = Instant::now();
    let frames = run.frames;
    let mut written: Result<(), String> = Ok(());
    let mut write = |series: &mut VtkSeries, sim: &Sim<D>| {
        if let Err(e) = series.write_frame(sim) {
            written = Err(format!("writing a frame: {}", e.message));
        }
    };
    if frames > 0 {
        write(&mut series, sim);
    }
    // Frame `k`'s time; the last one the end time itself, where the run lands exactly.
    let due = |k: usize| match k == frames {
        true => end,
        false => end * k as f64 / frames as f64,
    };
    let mut next = 1;
    let mut shown = 0;
    // run.max_steps bounds the whole run (one advance), refused up front when the estimate
    // exceeds it.
    sim.set_max_steps_per_advance(run.max_steps)
        .map_err(|e| e.message)?;
    let stepped = sim.advance_observed(end - sim.time(), run.cfl, &mut |sim, progress| {
        let rate = n * sim.steps() as f64 / start.elapsed().as_secs_f64().max(1e-9);
        let done = (1000.0 * progress.time / end) as u64;
        if done > shown {
            shown = done;
            bar.set_message(format!(
                "step {}  t = {:.4e} of {:.4e} s  {:.2e} particle-steps/s",
                progress.steps, progress.time, end, rate
            ));
            bar.set_position(done.min(1000));
        }
        if next <= frames && progress.time >= due(next) {
            // One frame for all the frame times this step reached.
            while next <= frames && progress.time >= due(next) {
                next += 1;
            }
            write(&mut series, sim);
            if !interactive && !args.quiet {
                println!(
                    "frame {:>3}/{frames}  step {:>6}  t = {:.4e} s  {:.2e} particle-steps/s",
                    next - 1,
                    sim.steps(),
                    sim.time(),
                    rate
                );
            }
        }
        true
    });
    bar.finish_and_clear();
    written?;
    if let Err(e) = stepped {
        // The last good state, to look at: a frame (even without frames) and the summary.
        let _ = series.write_frame(sim);
        summary(sim, p0, e0, start.elapsed().as_secs_f64(), &series);
        return Err(format!(
            "the run stopped at step {} at t = {:.3e} s of {:.3e} s: {}; the frame, picture \
             and summary show the state before that step",
            sim.steps(),
            sim.time(),
            end,
            plain_reason(&e.message),
        ));
    }
    summary(sim, p0, e0, start.elapsed().as_secs_f64(), &series);
    Ok(())
}

/// A refused step's reason in plain numbers: the step's own words without where the advance
/// was (the run says that), every decimal number to 4 significant digits.
fn plain_reason(message: &str) -> String {
    let mut reason = message;
    if let Some((r, _)) = reason.split_once(" (advancing from t = ") {
        reason = r;
    }
    if reason.starts_with("step ") {
        if let Some((_, r)) = reason.split_once(") rejected: ") {
            reason = r;
        }
    }
    let reason = reason.trim_end_matches("; the simulation keeps its last good state");
    let mut out = String::new();
    let chars: Vec<char> = reason.chars().collect();
    let mut i = 0;
    while i < chars.len() {
        let starts = chars[i].is_ascii_digit()
            || (chars[i] == '-' && chars.get(i + 1).is_some_and(|c| c.is_ascii_digit()));
        // Not inside a word (`F2`, `x1`).
        let in_word = i > 0 && (chars[i - 1].is_alphanumeric() || chars[i - 1] == '_');
        if !starts || in_word {
            out.push(chars[i]);
            i += 1;
            continue;
        }
        let mut j = i + 1;
        while j < chars.len()
            && (chars[j].is_ascii_digit()
                || chars[j] == '.'
                || chars[j] == 'e'
                || (matches!(chars[j], '-' | '+') && chars[j - 1] == 'e'))
        {
            j += 1;
        }
        let token: String = chars[i..j].iter().collect();
        // A trailing full stop is punctuation.
        let token = token.trim_end_matches('.');
        let end = i + token.chars().count();
        match token.parse::<f64>() {
            Ok(x) if token.contains(['.', 'e']) => out.push_str(&format!("{x:.3e}")),
            _ => out.push_str(token),
        }
        i = end;
    }
    out
}

fn summary<const D: usize>(
    sim: &Sim<D>,
    p0: Momenta<D>,
    e0: Energies,
    wall: f64,
    series: &VtkSeries,
) {
    let ps = sim.particles();
    let (p1, e1) = (sim.momenta(), sim.energies());
    // 2D scenes are plane strain: per metre of thickness.
    let (joules, momentum, angular_momentum) = match D {
        2 => ("J/m", "kg m/s per m", "kg m^2/s per m"),
        _ => ("J", "kg m/s", "kg m^2/s"),
    };
    let fmt = |v: &[f64]| {
        v.iter()
            .map(|c| format!("{c:.4e}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    // The angular momentum about the origin: its z component in 2D, the vector in 3D.
    let angular = |p: &Momenta<D>| {
        if D == 2 {
            format!("{:.4e}", p.angular[2])
        } else {
            format!("({})", fmt(p.angular.as_slice()))
        }
    };
    println!(
        "steps: {}, simulated time: {:.4e} s, wall time: {:.2} s, {:.2e} particle-steps/s",
        sim.steps(),
        sim.time(),
        wall,
        ps.len() as f64 * sim.steps() as f64 / wall.max(1e-9)
    );
    println!(
        "momentum ({momentum}): start ({}), end ({}); angular about the origin \
         ({angular_momentum}) {} -> {}",
        fmt(p0.linear.as_slice()),
        fmt(p1.linear.as_slice()),
        angular(&p0),
        angular(&p1)
    );
    let line = |e: &Energies| {
        format!(
            "kinetic {:.4e} + stored {:.4e} + gravitational {:.4e} = {:.4e}",
            e.kinetic,
            e.stored,
            e.gravitational,
            e.total()
        )
    };
    println!("energy ({joules}) at the start: {}", line(&e0));
    println!("energy ({joules}) at the end:   {}", line(&e1));
    match sim.energy_balance() {
        Ok(b) => {
            // Without plasticity or damage the stress work less the stored energy's change is
            // the time integration's error, not a dissipation of the material's.
            let material = match ps.history().is_empty() {
                true => format!(
                    "stress work less the stored energy {:.4e} (elastic: the time \
                     integration's error)",
                    b.material_dissipation
                ),
                false => format!("plasticity and damage {:.4e}", b.material_dissipation),
            };
            println!(
                "energy change {:.4e} = external work {:.4e} (body force, tractions) - {material}",
                e1.total() - e0.total(),
                b.external_work,
            );
            if b.friction_dissipation != 0.0 || b.contact_dissipation != 0.0 {
                println!(
                    "                     - friction at walls {:.4e} - in contact {:.4e}",
                    b.friction_dissipation, b.contact_dissipation
                );
            }
            println!(
                "                     - impacts and the scheme (transfer, time \
                 integration) {:.4e}",
                b.other_dissipation
            );
        }
        Err(e) => println!(
            "energy change {:.4e} ({})",
            e1.total() - e0.total(),
            e.message
        ),
    }
    let largest = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    if !ps.history().is_empty() {
        let plastic: Vec<f64> = ps.history().iter().map(|s| s.plastic_strain).collect();
        // Damage only where a material has it (Johnson–Cook), not for soil.
        let damages = sim
            .materials()
            .iter()
            .any(|m| matches!(m, rkmpm::material::Material::JohnsonCook(_)));
        if damages {
            let damage: Vec<f64> = ps.history().iter().map(|s| s.damage).collect();
            println!(
                "largest plastic strain {:.3}, largest damage {:.3}, failed particles {}",
                largest(&plastic),
                largest(&damage),
                damage.iter().filter(|&&d| d >= 1.0).count()
            );
        } else {
            println!("largest plastic strain {:.3}", largest(&plastic));
        }
    }
    println!(
        "largest pressure at the end: {:.4e} Pa",
        ps.pressure()
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max)
    );
    if series.frames() > 0 {
        println!(
            "output: {} frames, open {}.pvd in ParaView",
            series.frames(),
            series.prefix().display()
        );
    }
}
