//! The command-line runner, as a user runs it: a bundled scene end to end, a scene file with a
//! misspelt key, the help and the bundled-scene listing.

use std::process::Command;

fn rkmpm(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_rkmpm"))
        .args(args)
        .output()
        .expect("the runner starts");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn scratch(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("rkmpm-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// The vibrating bar scene runs one period: 40 frames plus the first, a .pvd naming all of
/// them, and a summary; momentum and energy are printed.
#[test]
fn runs_a_bundled_scene_to_its_end() {
    let out = scratch("bar");
    let (ok, stdout, stderr) = rkmpm(&["run", "bar", "--quiet", "--out", out.to_str().unwrap()]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("simulated time: 4.0000e-1 s"), "{stdout}");
    assert!(
        stdout.contains("momentum (kg m/s per m): start")
            && stdout.contains("angular about the origin (kg m^2/s per m)"),
        "{stdout}"
    );
    // The energies at the start and the end, and their change, which is the difference of the
    // printed totals (to the printed digits).
    let total = |prefix: &str| -> f64 {
        let line = stdout
            .lines()
            .find(|l| l.starts_with(prefix))
            .expect(prefix);
        assert!(
            line.contains("kinetic") && line.contains("gravitational"),
            "{line}"
        );
        line.rsplit("= ").next().unwrap().trim().parse().unwrap()
    };
    let (start, end) = (
        total("energy (J/m) at the start:"),
        total("energy (J/m) at the end:"),
    );
    // The change, then where it went: external work less the stress work's excess over the
    // stored energy less the rest (the bar is elastic: that excess is the time integration's
    // error, and the rest is the scheme's).
    let number_after = |label: &str| -> f64 {
        let at = stdout.find(label).expect(label) + label.len();
        let rest = stdout[at..].trim_start();
        rest.split([' ', '\n']).next().unwrap().parse().unwrap()
    };
    let change = number_after("energy change ");
    let external = number_after("external work ");
    let material = number_after("stress work less the stored energy ");
    let other = number_after("(transfer, time integration) ");
    assert!(
        (change - (end - start)).abs() <= 1e-4 * start.abs(),
        "{stdout}"
    );
    assert!(
        (change - (external - material - other)).abs() <= 1e-4 * start.abs(),
        "{stdout}"
    );
    assert_eq!(external, 0.0, "{stdout}");
    assert!(material.abs() <= 1e-3 * other.abs(), "{stdout}");
    assert!(change <= 0.0 && end > 0.0, "{stdout}");
    assert!(stdout.contains("41 frames"), "{stdout}");
    let pvd = std::fs::read_to_string(out.join("bar.pvd")).unwrap();
    assert_eq!(pvd.matches("<DataSet").count(), 41);
    for k in 0..41 {
        assert!(out.join(format!("bar_{k:05}.vtu")).exists(), "frame {k}");
    }
    // The bundled bar draws its final particles coloured by velocity: a real PNG.
    let png = std::fs::read(out.join("bar.png")).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    let width = u32::from_be_bytes(png[16..20].try_into().unwrap());
    assert_eq!(width, 1000);
    assert!(
        stdout.contains("picture: ") && stdout.contains("coloured by velocity"),
        "{stdout}"
    );
    std::fs::remove_dir_all(out).unwrap();
}

/// The default scene runs twice, RK + VC and then its `[compare]` options (the same RK shape
/// functions without VC), and draws the two side by side: a PNG two panels wide, both
/// summaries printed.
#[test]
fn the_default_scene_draws_both_runs_side_by_side() {
    let out = scratch("compare");
    let (ok, stdout, stderr) = rkmpm(&[
        "--end-time",
        "0.05",
        "--frames",
        "0",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("1 material; RK order 1, support 2, VC order 1, PIC/FLIP 0, USL"),
        "{stdout}"
    );
    assert!(
        stdout.contains("compared with the [compare] options"),
        "{stdout}"
    );
    assert!(
        stdout.contains("1 material; RK order 1, support 2, material points, PIC/FLIP 0, USL"),
        "{stdout}"
    );
    assert_eq!(stdout.matches("scene: ").count(), 2, "{stdout}");
    assert_eq!(
        stdout.matches("simulated time: 5.0000e-2 s").count(),
        2,
        "{stdout}"
    );
    let png = std::fs::read(out.join("column.png")).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    let width = u32::from_be_bytes(png[16..20].try_into().unwrap());
    assert_eq!(width, 1600, "two panels of 800 pixels");
    assert!(
        !out.join("column.pvd").exists(),
        "--frames 0 writes no series"
    );
    std::fs::remove_dir_all(out).unwrap();
}

/// Overrides: `--end-time`, `--frames 0` (no output) and a scene file by path.
#[test]
fn runs_a_scene_file_with_overrides() {
    let out = scratch("file");
    std::fs::create_dir_all(&out).unwrap();
    let (ok, toml, _) = rkmpm(&["show", "disks"]);
    assert!(ok);
    let file = out.join("my_disks.toml");
    std::fs::write(
        &file,
        toml.replace("output = \"disks\"", "output = \"mine\""),
    )
    .unwrap();
    let (ok, stdout, stderr) = rkmpm(&[
        file.to_str().unwrap(),
        "--end-time",
        "0.1",
        "--frames",
        "2",
        "--png",
        "none",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("simulated time: 1.0000e-1 s"), "{stdout}");
    assert!(out.join("mine.pvd").exists() && out.join("mine_00002.vtu").exists());
    assert!(!out.join("mine.png").exists(), "--png none draws nothing");
    let (ok, _, stderr) = rkmpm(&[
        "run",
        "disks",
        "--png",
        "colour",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!ok && stderr.contains("choose one of"), "{stderr}");
    std::fs::remove_dir_all(out).unwrap();
}

/// A misspelt key fails with the file, the line and the field; nothing runs.
#[test]
fn a_bad_scene_file_names_the_line_and_the_field() {
    let out = scratch("bad");
    std::fs::create_dir_all(&out).unwrap();
    let (_, toml, _) = rkmpm(&["show", "disks"]);
    let file = out.join("bad.toml");
    std::fs::write(&file, toml.replace("poisson = 0.3", "poison = 0.3")).unwrap();
    let (ok, stdout, stderr) = rkmpm(&[
        "run",
        file.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!ok);
    let line = toml.lines().position(|l| l.starts_with("poisson")).unwrap() + 1;
    assert!(
        stderr.contains(&format!(
            "bad.toml: line {line}, column 1 (`poison = 0.3`): unknown field `poison`"
        )),
        "{stderr}"
    );
    assert!(stdout.is_empty() || !stdout.contains("steps:"));
    assert!(!out.join("disks.pvd").exists());
    let (ok, _, stderr) = rkmpm(&["run", "no-such-scene"]);
    assert!(!ok && stderr.contains("not a bundled scene"), "{stderr}");
    std::fs::remove_dir_all(out).unwrap();
}

#[test]
fn help_and_listing() {
    let (ok, stdout, _) = rkmpm(&["--help"]);
    assert!(ok);
    for word in [
        "run",
        "check",
        "list",
        "show",
        "--out",
        "--end-time",
        "--frames",
        "--cfl",
        "--threads",
        "--quiet",
    ] {
        assert!(stdout.contains(word), "--help lacks {word}");
    }
    let (ok, stdout, _) = rkmpm(&["list"]);
    assert!(ok);
    for name in [
        "column",
        "disks",
        "bar",
        "collapse",
        "taylor",
        "penetration",
    ] {
        assert!(
            stdout.lines().any(|l| l.starts_with(name)),
            "list lacks {name}"
        );
    }
}

/// Frames are written at the steps the run takes anyway, so their number changes nothing of
/// the physics: the last frame of a run with 30 frames is the file of a run with 1, byte for
/// byte, and a run with none prints the same steps, momenta and energies.
#[test]
fn frames_do_not_change_the_physics() {
    let physics = |frames: &str| {
        let out = scratch(&format!("frames{frames}"));
        let (ok, stdout, stderr) = rkmpm(&[
            "run",
            "bar",
            "--end-time",
            "0.1",
            "--frames",
            frames,
            "--png",
            "none",
            "--quiet",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(ok, "{stderr}");
        let lines: Vec<String> = stdout
            .lines()
            .filter(|l| l.starts_with("momentum") || l.starts_with("energy"))
            .map(String::from)
            .chain(
                stdout
                    .lines()
                    .find(|l| l.starts_with("steps: "))
                    .map(|l| l.split(", wall").next().unwrap().to_string()),
            )
            .collect();
        assert!(lines.len() >= 4, "{stdout}");
        let last = match frames {
            "0" => None,
            n => Some(std::fs::read(out.join(format!("bar_{n:0>5}.vtu"))).unwrap()),
        };
        let _ = std::fs::remove_dir_all(out);
        (lines, last)
    };
    let (none, _) = physics("0");
    let (one, last_of_one) = physics("1");
    let (thirty, last_of_thirty) = physics("30");
    assert_eq!(none, thirty);
    assert_eq!(one, thirty);
    assert!(
        last_of_one.unwrap() == last_of_thirty.unwrap(),
        "the last frames differ"
    );
}

/// Frames are bounded before a step is taken, by count and by the disk they would fill.
#[test]
fn too_many_frames_are_refused_up_front() {
    let out = scratch("many");
    let (ok, _, stderr) = rkmpm(&["check", "bar", "--frames", "100000"]);
    assert!(!ok && stderr.contains("at most 10000 frames"), "{stderr}");
    let (ok, _, stderr) = rkmpm(&[
        "run",
        "bar",
        "--frames",
        "100000",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!ok && stderr.contains("at most 10000 frames"), "{stderr}");
    assert!(!out.exists());
}

/// A run that a refused step stops leaves its last good state to look at (a frame, the
/// picture, the summary) and says why it stopped in plain numbers.
#[test]
fn a_stopped_run_leaves_its_last_good_state() {
    let (ok, disks, _) = rkmpm(&["show", "disks"]);
    assert!(ok);
    let dir = scratch("stopped");
    std::fs::create_dir_all(&dir).unwrap();
    // The disks thrown at 40 m/s: they leave the grid within 0.02 s.
    let text = disks
        .replace("velocity = [0.1, 0.1]", "velocity = [40.0, 40.0]")
        .replace("end_time = 3.0", "end_time = 0.1");
    assert_ne!(text, disks);
    let file = dir.join("fast.toml");
    std::fs::write(&file, text).unwrap();
    let out = dir.join("out");
    let (ok, stdout, stderr) = rkmpm(&[
        "run",
        file.to_str().unwrap(),
        "--frames",
        "0",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!ok, "{stdout}");
    assert!(stderr.contains("the run stopped at step "), "{stderr}");
    // Four significant digits: `t = 1.234e-2 s of 1.000e-1 s`, and no detail of the stepping.
    assert!(stderr.contains(" s of 1.000e-1 s: "), "{stderr}");
    assert!(!stderr.contains("advancing from"), "{stderr}");
    assert!(!stderr.contains(") rejected: "), "{stderr}");
    // Every decimal of the reason to 4 significant digits (no 16-digit numbers).
    assert!(
        !stderr
            .split(|c: char| !(c.is_ascii_digit() || c == '.'))
            .any(|n| n.len() > 6),
        "{stderr}"
    );
    assert!(stdout.contains("energy (J/m) at the end:"), "{stdout}");
    assert!(
        out.join("disks_00000.vtu").exists(),
        "the last good state's frame"
    );
    assert!(
        out.join("disks.png").exists(),
        "the last good state's picture"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `check` refuses what `run` refuses, with the same message, before anything is computed:
/// options the step does not support (also in `[compare]`) and a picture of no field.
#[test]
fn check_refuses_what_run_refuses() {
    let (ok, disks, _) = rkmpm(&["show", "disks"]);
    assert!(ok);
    let (ok, taylor, _) = rkmpm(&["show", "taylor"]);
    assert!(ok);
    let dir = scratch("check");
    std::fs::create_dir_all(&dir).unwrap();
    let cases = [
        (
            disks.replace("rk_order = 1", "rk_order = 2"),
            "APIC with a shape function that reproduces quadratics",
        ),
        (
            disks
                .replacen("transfer = \"apic\"", "transfer = \"mls\"", 1)
                .replace(
                    "shape = \"rk\"\nrk_order = 1\nrk_support = 2.0",
                    "shape = \"bspline2\"",
                ),
            "the MLS transfer does not go with VC integration",
        ),
        (
            disks.replace(
                "shape = \"rk\"\nrk_order = 1\nrk_support = 2.0\ntransfer = \"apic\"\n\n",
                "shape = \"linear\"\ntransfer = \"mls\"\n\n",
            ),
            "[compare]: the MLS transfer needs the quadratic or cubic B-spline",
        ),
        (
            disks.replace("png = \"pressure\"", "png = \"damage\""),
            "png = \"damage\": no material of this scene has damage",
        ),
        (
            disks.replace("png = \"pressure\"", "png = \"plastic\""),
            "png = \"plastic\": choose one of",
        ),
        (
            disks.replace("png = \"pressure\"", "png = \"pressure\"\nsection = 0.5"),
            "run.section (the plane of a 3D picture) is for 3D scenes",
        ),
        (
            taylor.replace("section = 0.0002", "section = 0.5"),
            "run.section = 5e-1: the plane y = 5e-1 m lies outside the grid",
        ),
        // Settings that would do nothing, named as the scene writes them.
        (
            disks.replacen("transfer = \"apic\"", "transfer = \"apic\"\nflip = 0.5", 1),
            "options.flip does nothing here: FLIP blends with PIC only",
        ),
        (
            disks.replace(
                "shape = \"rk\"\nrk_order = 1\nrk_support = 2.0\ntransfer = \"apic\"\n\n",
                "shape = \"bspline3\"\nrk_order = 1\ntransfer = \"apic\"\n\n",
            ),
            "compare.rk_order does nothing here",
        ),
        (
            disks.replace(
                "rk_support = 2.0\ntransfer = \"apic\"\n\n",
                "rk_support = 2.0\ntransfer = \"apic\"\nvc_order = 2\n\n",
            ),
            "compare.vc_order does nothing here",
        ),
        (
            disks.replacen(
                "transfer = \"apic\"",
                "transfer = \"pic_flip\"\nflip = 1.5",
                1,
            ),
            "options.flip must lie in [0, 1], got 1.5",
        ),
        (
            disks.replacen(
                "transfer = \"apic\"",
                "transfer = \"apic\"\ncontact_friction = -1.0",
                1,
            ),
            "options.contact_friction must be a finite coefficient >= 0, got -1",
        ),
        (
            format!("{disks}\n[[walls]]\naxis = 1\nside = \"low\"\nkind = \"friction\"\n"),
            "walls[0]: a friction wall needs its coefficient",
        ),
        (
            format!(
                "{disks}\n[[walls]]\naxis = 1\nside = \"low\"\nkind = \"slip\"\nfriction = 0.3\n"
            ),
            "walls[0].friction does nothing here",
        ),
        (
            disks.replace("center = [0.75, 0.75]", "center = [0.35, 0.35]"),
            "bodies[1] overlaps bodies[0]",
        ),
        (
            disks.replacen(
                "velocity = [0.1, 0.1]",
                "velocity = [0.1, 0.1]\njitter = 0.7",
                1,
            ),
            "bodies[0]: jitter must lie in [0, 0.5), got 0.7",
        ),
    ];
    for (k, (text, message)) in cases.iter().enumerate() {
        assert!(
            text != &disks && text != &taylor,
            "case {k} changed nothing"
        );
        let file = dir.join(format!("case{k}.toml"));
        std::fs::write(&file, text).unwrap();
        let file = file.to_str().unwrap();
        let (ok, stdout, stderr) = rkmpm(&["check", file]);
        assert!(!ok, "check accepted case {k}: {stdout}");
        assert!(stderr.contains(message), "case {k}: {stderr}");
        let out = dir.join(format!("out{k}"));
        let (ok, _, run_err) = rkmpm(&["run", file, "--quiet", "--out", out.to_str().unwrap()]);
        assert!(!ok, "run accepted case {k}");
        assert!(run_err.contains(message), "case {k}: {run_err}");
        assert!(!out.exists(), "case {k}: run created its output directory");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The summary reports what the scene's materials have: plastic strain for soil, plastic strain
/// and damage for Johnson–Cook metal.
#[test]
fn the_summary_reports_damage_only_for_materials_that_have_it() {
    for (scene, end, damage) in [("collapse", "1e-3", false), ("taylor", "1e-6", true)] {
        let out = scratch(scene);
        let (ok, stdout, stderr) = rkmpm(&[
            "run",
            scene,
            "--end-time",
            end,
            "--frames",
            "0",
            "--png",
            "none",
            "--quiet",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(ok, "{scene}: {stderr}");
        assert!(stdout.contains("largest plastic strain"), "{stdout}");
        assert_eq!(stdout.contains("largest damage"), damage, "{stdout}");
        std::fs::remove_dir_all(&out).unwrap();
    }
}

/// Two disks (RK1, APIC, 20 × 20 cells, the `bodies` and any walls as TOML, `gravity` down) to 2 s, each body
/// alone too (`--split-dissipation`): returns the energy that each body loses alone and that
/// their impacts on each other take, as printed.
fn split_of_disks(name: &str, gravity: f64, bodies: &str) -> (f64, f64) {
    let dir = scratch(name);
    std::fs::create_dir_all(&dir).unwrap();
    let scene = format!(
        r#"
[grid]
origin = [0.0, 0.0]
cells = [20, 20]
cell_size = 0.05
[options]
shape = "rk"
rk_order = 1
rk_support = 2.0
transfer = "apic"
gravity = [0.0, {gravity}]
[[materials]]
name = "rubber"
model = "neo_hookean"
density = 1000.0
young = 1000.0
poisson = 0.3
{bodies}
[run]
end_time = 2.0
cfl = 0.3
frames = 0
output = "disks"
"#
    );
    let path = dir.join("disks.toml");
    std::fs::write(&path, scene).unwrap();
    let out = dir.join("out");
    let (ok, stdout, stderr) = rkmpm(&[
        "run",
        path.to_str().unwrap(),
        "--quiet",
        "--split-dissipation",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    let number_after = |label: &str| -> f64 {
        let at = stdout.find(label).expect(label) + label.len();
        let rest = stdout[at..].trim_start();
        let word = rest.split([' ', ',', '\n']).next().unwrap();
        word.parse().unwrap()
    };
    let together = number_after("(transfer, time integration) ");
    let alone = number_after("walls) ");
    let impacts = number_after("impacts on each other ");
    // The split adds up to the whole, to the printed digits.
    assert!(
        (alone + impacts - together).abs() <= 1e-4 * together.abs(),
        "{stdout}"
    );
    eprintln!("{name}: together {together:e}, alone {alone:e}, impacts {impacts:e}");
    std::fs::remove_dir_all(dir).unwrap();
    (alone, impacts)
}

/// Two disks falling side by side onto a slip floor never share a node (their supports stay
/// 0.16 m apart), and take the same time steps
/// together as alone (mirror images: the same signal speed), so the impacts' share is the
/// round-off of the ledger's sums, while each loses energy on the floor. Two disks thrown at
/// each other lose most of the energy the ledger does not account for in their impact.
#[test]
fn the_dissipation_splits_into_the_bodies_alone_and_their_impacts() {
    let floor = "[[walls]]\naxis = 1\nside = \"low\"\nkind = \"slip\"\n";
    let disk = |x: f64, y: f64, r: f64, v: f64| {
        format!(
            "[[bodies]]\nmaterial = \"rubber\"\nsphere = {{ center = [{x}, {y}], radius = \
             {r} }}\nvelocity = [{v}, {v}]\n"
        )
    };
    let apart = format!(
        "{floor}{}{}",
        disk(0.2, 0.3, 0.12, 0.0),
        disk(0.8, 0.3, 0.12, 0.0)
    );
    let (alone, impacts) = split_of_disks("split-apart", -1.0, &apart);
    assert!(alone > 0.0, "{alone:e}");
    assert!(impacts.abs() <= 1e-9 * alone, "{alone:e} {impacts:e}");
    let meet = format!(
        "{}{}",
        disk(0.3, 0.3, 0.15, 0.1),
        disk(0.7, 0.7, 0.15, -0.1)
    );
    let (alone, impacts) = split_of_disks("split-meet", 0.0, &meet);
    assert!(impacts > 3.0 * alone.abs(), "{alone:e} {impacts:e}");
    // A scene of one body has nothing to split.
    let (ok, _, stderr) = rkmpm(&[
        "run",
        "bar",
        "--quiet",
        "--split-dissipation",
        "--out",
        scratch("split-one").to_str().unwrap(),
    ]);
    assert!(
        !ok && stderr.contains("the split needs two or more"),
        "{stderr}"
    );
}
