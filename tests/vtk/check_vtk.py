#!/usr/bin/env python3
"""Reads rkmpm's VTK output with a real reader (meshio for the .vtu frames, xml.etree for the
.pvd series, which meshio does not read) and checks what it holds against the scenes.

    python tests/vtk/check_vtk.py DIR

DIR holds the output of
    rkmpm run bar --quiet --out DIR
    rkmpm run bar --quiet --vtk ascii --out DIR/ascii
    rkmpm run taylor --quiet --frames 2 --end-time 2e-6 --vtk ascii --out DIR
(scripts/test-vtk.sh runs them and this): binary frames (the default) and ASCII ones, which must
hold the same values bit for bit. The scene parameters are read from runner/scenes/bar.toml and
runner/scenes/taylor.toml; the Taylor overrides are TAYLOR_FRAMES and TAYLOR_END_TIME below.

Prints one line per check group and exits 1 listing every failed check.
"""

import math
import sys
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import meshio
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
SCENES = ROOT / "runner" / "scenes"

# Particles per cell per direction of a scene's `box`/`cylinder` bodies (the engine's default; the
# scene files do not set it).
PPC = 2
# The Taylor run's overrides (must match scripts/test-vtk.sh).
TAYLOR_FRAMES = 2
TAYLOR_END_TIME = 2e-6

# What src/io/vtk.rs writes as point data: name -> components. Vectors are padded to 3 and tensors
# to 3x3 (row-major, 9 components) in 2D as in 3D.
ARRAYS = {
    "velocity": 3,
    "displacement": 3,
    "stress": 9,
    "pressure": 1,
    "volume": 1,
    "mass": 1,
    "material": 1,
}
# Written where a material of the run has them (`Sim::carries`): plastic strain for the
# elastoplastic materials, damage for Johnson-Cook with damage.
OPTIONAL = {
    "plastic_strain": 1,
    "damage": 1,
}

failures = []


class Abort(Exception):
    """A failure after which the checks of this output cannot go on."""


def check(ok, message):
    if not ok:
        failures.append(message)
    return ok


def require(ok, message):
    if not ok:
        failures.append(message)
        raise Abort(message)


def maxabs(a):
    a = np.asarray(a, dtype=float)
    return float(np.max(np.abs(a))) if a.size else 0.0


def read_pvd(pvd, frames, end_time):
    """The (time, path) pairs of a .pvd, checked: frames + 1 data sets, times increasing from 0
    to exactly end_time at end_time * k / frames, every file present."""
    require(pvd.is_file(), f"{pvd}: missing")
    try:
        root = ET.parse(pvd).getroot()
    except ET.ParseError as e:
        require(False, f"{pvd}: not well-formed XML: {e}")
    require(
        root.tag == "VTKFile" and root.get("type") == "Collection",
        f"{pvd}: root is <{root.tag} type={root.get('type')!r}>, not <VTKFile type=\"Collection\">",
    )
    sets = root.findall("./Collection/DataSet")
    require(
        len(sets) == frames + 1,
        f"{pvd}: {len(sets)} DataSet entries, expected {frames + 1} ({frames} frames + the first)",
    )
    series = []
    for k, d in enumerate(sets):
        try:
            t = float(d.get("timestep"))
        except (TypeError, ValueError):
            require(False, f"{pvd}: DataSet {k} has timestep {d.get('timestep')!r}")
        f = d.get("file")
        require(f is not None, f"{pvd}: DataSet {k} has no file attribute")
        path = pvd.parent / f
        check(path.is_file(), f"{pvd}: DataSet {k} names {f}, which does not exist")
        series.append((t, path))
    times = np.array([t for t, _ in series])
    check(times[0] == 0.0, f"{pvd}: first timestep {float(times[0])!r}, expected 0")
    check(
        np.all(np.diff(times) > 0),
        f"{pvd}: timesteps not strictly increasing (first fall after DataSet "
        f"{int(np.argmax(np.diff(times) <= 0))})",
    )
    check(
        times[-1] == end_time,
        f"{pvd}: last timestep {float(times[-1])!r}, expected exactly the end time {end_time!r}",
    )
    # Frame k is written at the first step that reaches end_time * k / frames (the steps the run
    # takes anyway), so it lies at or after that time and before the next frame's.
    due = end_time * np.arange(frames + 1) / frames
    late = times - due
    check(
        np.all(late >= -1e-12 * end_time) and np.all(times[:-1] < due[1:] + 1e-12 * end_time),
        f"{pvd}: frame k's time is not the first step at or after end_time * k / frames "
        f"(times {times.tolist()}, due {due.tolist()})",
    )
    require(all(p.is_file() for _, p in series), f"{pvd}: frame files missing")
    return series


def read_frame(path, t, n, dim):
    """A .vtu read with meshio, checked: n points, n vertex cells, TimeValue t, every array the
    writer writes with its component count and only finite values, zero padding in 2D."""
    try:
        # meshio.vtu.read, not meshio.read: on a broken file the latter prints and calls sys.exit.
        m = meshio.vtu.read(path)
    except (Exception, SystemExit) as e:  # meshio raises many kinds
        require(False, f"{path.name}: meshio cannot read it: {type(e).__name__}: {e}")
    name = path.name
    require(
        m.points.shape == (n, 3),
        f"{name}: points have shape {m.points.shape}, expected ({n}, 3)",
    )
    check(np.all(np.isfinite(m.points)), f"{name}: non-finite point coordinates")
    cells = [(c.type, c.data.shape) for c in m.cells]
    if check(
        cells == [("vertex", (n, 1))],
        f"{name}: cells {cells}, expected one vertex cell per point [('vertex', ({n}, 1))]",
    ):
        check(
            np.array_equal(m.cells[0].data[:, 0], np.arange(n)),
            f"{name}: vertex cell p is not point p",
        )
    tv = m.field_data.get("TimeValue")
    check(
        tv is not None and np.asarray(tv).size == 1 and float(np.asarray(tv).ravel()[0]) == t,
        f"{name}: field data TimeValue {None if tv is None else np.asarray(tv).tolist()}, expected {t!r} (its .pvd timestep)",
    )
    pd = {}
    for a, comps in list(ARRAYS.items()) + list(OPTIONAL.items()):
        if a in OPTIONAL and a not in m.point_data:
            continue
        if not check(a in m.point_data, f"{name}: point data {a!r} missing"):
            continue
        v = np.asarray(m.point_data[a], dtype=float)
        if v.ndim == 1:
            v = v[:, None]
        if not check(
            v.shape == (n, comps),
            f"{name}: point data {a!r} has shape {v.shape}, expected ({n}, {comps})",
        ):
            continue
        check(np.all(np.isfinite(v)), f"{name}: point data {a!r} has non-finite values")
        pd[a] = v
    extra = sorted(set(m.point_data) - set(ARRAYS) - set(OPTIONAL))
    check(not extra, f"{name}: point data {extra} not known to this checker (add them to ARRAYS)")
    require(all(a in pd for a in ARRAYS), f"{name}: point data incomplete, cannot check further")

    stress = pd["stress"].reshape(n, 3, 3)
    scale = max(maxabs(stress), 1e-300)
    check(
        maxabs(stress - stress.transpose(0, 2, 1)) <= 1e-12 * scale,
        f"{name}: stress not symmetric (largest |s_ij - s_ji| = {maxabs(stress - stress.transpose(0, 2, 1)):.3e}"
        f" of |s| up to {scale:.3e})",
    )
    # pressure = -trace(stress) / 3 (of the 3x3 as written; zero out-of-plane stress in 2D).
    p = -np.trace(stress, axis1=1, axis2=2) / 3
    check(
        maxabs(pd["pressure"][:, 0] - p) <= 1e-12 * scale,
        f"{name}: pressure differs from -trace(stress)/3 by up to {maxabs(pd['pressure'][:, 0] - p):.3e}",
    )
    check(np.all(pd["volume"] > 0), f"{name}: volume not positive everywhere")
    check(np.all(pd["mass"] > 0), f"{name}: mass not positive everywhere")
    if "plastic_strain" in pd:
        check(np.all(pd["plastic_strain"] >= 0), f"{name}: negative plastic_strain")
    mat = pd["material"][:, 0]
    check(
        np.all(mat == np.round(mat)) and np.all(mat >= 0),
        f"{name}: material ids are not non-negative integers",
    )
    if dim == 2:
        check(maxabs(m.points[:, 2]) == 0, f"{name}: 2D points have z != 0")
        for a in ("velocity", "displacement"):
            check(maxabs(pd[a][:, 2]) == 0, f"{name}: 2D {a} has a z component")
        pad = stress.copy()
        pad[:, :2, :2] = 0
        check(maxabs(pad) == 0, f"{name}: 2D stress has out-of-plane components (3x3 padding not zero)")
    return m.points, pd


def lattice_indices(x, spacing, name, what):
    """Indices i with x = (i + 1/2) * spacing (to 1e-12), or None."""
    i = np.round(x / spacing - 0.5)
    err = maxabs(x - (i + 0.5) * spacing)
    if check(err <= 1e-12, f"{name}: {what} off the particle lattice (i + 1/2) h/{PPC} by up to {err:.3e}"):
        return i.astype(np.int64)
    return None


def check_series_consistency(name, frames):
    """Across frames: same particles in the same order (position - displacement is the frame-0
    position), mass and material unchanged, plastic strain never decreasing."""
    x0, d0 = frames[0]
    check(maxabs(d0["displacement"]) == 0, f"{name} frame 0: displacement not zero")
    for k, (x, d) in enumerate(frames):
        ref = x - d["displacement"]
        err = maxabs(ref - x0)
        check(
            err <= 1e-12 * max(maxabs(x0), 1e-300),
            f"{name} frame {k}: points - displacement differ from the frame-0 points by {err:.3e}"
            " (particles reordered or displacement wrong)",
        )
        check(np.array_equal(d["mass"], d0["mass"]), f"{name} frame {k}: particle masses changed")
        check(np.array_equal(d["material"], d0["material"]), f"{name} frame {k}: material ids changed")
        if k > 0 and "plastic_strain" in d:
            prev = frames[k - 1][1]["plastic_strain"]
            check(
                np.all(d["plastic_strain"] >= prev),
                f"{name} frame {k}: plastic_strain decreased for some particle",
            )


def check_bar(out):
    scene = tomllib.loads((SCENES / "bar.toml").read_text())
    h = scene["grid"]["cell_size"]
    (body,) = scene["bodies"]
    (mat,) = scene["materials"]
    lo, hi = np.array(body["box"]["min"]), np.array(body["box"]["max"])
    amp = body["sine_velocity"]["amplitude"][0]
    b = body["sine_velocity"]["wavenumber"]
    rho, young = mat["density"], mat["young"]
    end, nframes = scene["run"]["end_time"], scene["run"]["frames"]
    period = 2 * math.pi / (b * math.sqrt(young / rho))
    require(
        abs(end - period) <= 1e-12 * period,
        f"runner/scenes/bar.toml: end_time {end} is not one period {period} of the bar: update this checker",
    )
    s = h / PPC
    counts = np.round((hi - lo) / s).astype(int)
    n = int(np.prod(counts))  # 64 x 4 = 256

    series = read_pvd(out / f"{scene['run']['output']}.pvd", nframes, end)
    frames = []
    for t, path in series:
        frames.append(read_frame(path, t, n, 2))
    print(f"  bar: {len(series)} frames of {n} particles read with meshio {meshio.__version__}")

    # Frame 0: the lattice x = (i + 1/2) h/2, y = h + (j + 1/2) h/2, each node once.
    x0, d0 = frames[0]
    ii = lattice_indices(x0[:, 0] - lo[0], s, "bar frame 0", "x")
    jj = lattice_indices(x0[:, 1] - lo[1], s, "bar frame 0", "y")
    if ii is not None and jj is not None:
        inside = (ii >= 0) & (ii < counts[0]) & (jj >= 0) & (jj < counts[1])
        check(np.all(inside), "bar frame 0: particles outside the bar's box")
        nodes = set(zip(ii.tolist(), jj.tolist()))
        check(
            len(nodes) == n,
            f"bar frame 0: {len(nodes)} distinct lattice nodes for {n} particles (duplicates)",
        )
    v_exact = amp * np.sin(b * x0[:, 0])
    v0 = d0["velocity"]
    check(
        maxabs(v0[:, 0] - v_exact) <= 1e-12,
        f"bar frame 0: v_x differs from {amp} sin({b} x) by {maxabs(v0[:, 0] - v_exact):.3e}",
    )
    check(maxabs(v0[:, 1:]) == 0, "bar frame 0: v_y, v_z not zero")
    check(maxabs(d0["stress"]) == 0, "bar frame 0: stress not zero")
    check(
        maxabs(d0["volume"] - s**2) <= 1e-12 * s**2,
        f"bar frame 0: particle volume not (h/{PPC})^2 = {s**2:.6e}",
    )
    check(
        maxabs(d0["mass"] - rho * s**2) <= 1e-12 * rho * s**2,
        f"bar frame 0: particle mass not density (h/{PPC})^2",
    )
    check(np.all(d0["material"] == 0), "bar: material ids not all 0 (one material)")
    check("plastic_strain" not in d0, "bar: plastic_strain written for an elastic material")

    check_series_consistency("bar", frames)

    # Every frame: the bar stays in its box grown by h/10. The displacement amplitude is
    # amp / omega = 0.01 / (5 pi) = 6.4e-4 = 0.02 h, so h/10 is 5 times it and still far below the
    # particle spacing h/2.
    margin = h / 10
    for k, (x, _) in enumerate(frames):
        out_of_box = np.any((x[:, :2] < lo - margin) | (x[:, :2] > hi + margin), axis=1)
        check(
            not out_of_box.any(),
            f"bar frame {k}: {int(out_of_box.sum())} points outside the box "
            f"[{lo.tolist()}, {hi.tolist()}] grown by h/10 (x range {x[:, 0].min():.4e}..{x[:, 0].max():.4e}, "
            f"y range {x[:, 1].min():.4e}..{x[:, 1].max():.4e})",
        )

    # v(x, t) = amp cos(omega t) sin(b x): +profile at t = T, -profile at T/2, zero at T/4.
    # The discrete bar's period is off the continuum one by about 0.03 %, which moves cos(omega t)
    # by less than 1e-5 at t = T and T/2 and by about 2e-3 (relative to amp) at T/4, and the
    # scheme loses about 0.13 % of the energy over the period (0.07 % of the velocity): the
    # measured mean v_x after one period is 0.07 % low and no particle is off by more than 0.1 %
    # of the amplitude. The 2 % tolerance leaves a margin of about 20 for other platforms and
    # small changes of the scheme, and still fails a wrong frame time or frame order, a sign
    # error, a lost or scaled velocity, or a bar that damps or drifts out of phase.
    mean0 = v0[:, 0].mean()
    tol = 0.02
    for k, sign, what in ((nframes, 1.0, "one period"), (nframes // 2, -1.0, "half a period")):
        v = frames[k][1]["velocity"]
        mean = v[:, 0].mean()
        check(
            abs(mean - sign * mean0) <= tol * abs(mean0),
            f"bar frame {k} ({what}): mean v_x {mean:.6e}, expected {sign * mean0:.6e} within 2 %",
        )
        err = maxabs(v[:, 0] - sign * v0[:, 0])
        check(
            err <= tol * amp,
            f"bar frame {k} ({what}): v_x differs from {'+' if sign > 0 else '-'}the initial profile "
            f"by up to {err:.3e}, more than 2 % of the amplitude {amp}",
        )
        check(maxabs(v[:, 1]) <= 1e-6 * amp, f"bar frame {k}: v_y {maxabs(v[:, 1]):.3e} not ~0 (nu = 0)")
    if nframes % 4 == 0:
        k = nframes // 4
        vq = maxabs(frames[k][1]["velocity"][:, 0])
        check(vq <= tol * amp, f"bar frame {k} (quarter period): |v_x| up to {vq:.3e}, expected ~0")
    last = frames[-1][1]["velocity"][:, 0].mean()
    print(
        f"  bar: frame 0 lattice and sine profile exact; one period later mean v_x {last:.6e} vs "
        f"{mean0:.6e} ({(last / mean0 - 1) * 100:+.3f} %)"
    )


def check_taylor(out):
    scene = tomllib.loads((SCENES / "taylor.toml").read_text())
    h = scene["grid"]["cell_size"]
    (body,) = scene["bodies"]
    (mat,) = scene["materials"]
    cyl = body["cylinder"]
    require(
        cyl["axis"] == 2 and cyl["base"] == [0.0, 0.0, 0.0],
        "runner/scenes/taylor.toml: the rod is no longer along z from the origin: update this checker",
    )
    radius, length = cyl["radius"], cyl["length"]
    vel = np.array(body["velocity"])
    rho = mat["density"]
    s = h / PPC

    # The expected particles: lattice nodes ((i, j, k) + 1/2) h/2 of the quarter rod x, y >= 0
    # (symmetry walls), inside the cylinder.
    ni, nk = int(math.ceil(radius / s)), int(round(length / s))
    r = (np.arange(ni) + 0.5) * s
    inside_r = (r[:, None] ** 2 + r[None, :] ** 2) <= radius**2
    n = int(inside_r.sum()) * nk  # 52 * 81 = 4212

    series = read_pvd(out / f"{scene['run']['output']}.pvd", TAYLOR_FRAMES, TAYLOR_END_TIME)
    frames = [read_frame(path, t, n, 3) for t, path in series]
    print(f"  taylor: {len(series)} frames of {n} particles (3D) read with meshio")

    x0, d0 = frames[0]
    idx = [lattice_indices(x0[:, a], s, "taylor frame 0", "xyz"[a]) for a in range(3)]
    if all(i is not None for i in idx):
        i, j, k = idx
        ok = (i >= 0) & (j >= 0) & (k >= 0) & (k < nk)
        ok &= (x0[:, 0] ** 2 + x0[:, 1] ** 2) <= radius**2
        check(np.all(ok), f"taylor frame 0: {int((~ok).sum())} points outside the quarter rod")
        check(
            len(set(zip(i.tolist(), j.tolist(), k.tolist()))) == n,
            "taylor frame 0: duplicate lattice nodes",
        )
    check(
        maxabs(d0["velocity"] - vel) == 0,
        f"taylor frame 0: velocity not {vel.tolist()} everywhere (differs by {maxabs(d0['velocity'] - vel):.3e})",
    )
    check(maxabs(d0["stress"]) == 0, "taylor frame 0: stress not zero")
    check(np.all(d0["plastic_strain"] == 0), "taylor frame 0: plastic_strain not zero")
    check(
        maxabs(d0["mass"] - rho * s**3) <= 1e-12 * rho * s**3,
        f"taylor frame 0: particle mass not density (h/{PPC})^3",
    )

    check_series_consistency("taylor", frames)

    x, d = frames[-1]
    t = series[-1][0]
    # The rod has hit the wall z = 0 (slip): no point through it or the symmetry planes, none
    # farther than the free flight |v| t above the rod's top; the far end still flies at ~227 m/s.
    travel = float(np.linalg.norm(vel)) * t
    margin = 0.05 * s
    check(
        x.min(axis=0).min() >= -margin,
        f"taylor frame {len(frames) - 1}: points through a wall or symmetry plane (min {x.min(axis=0).tolist()})",
    )
    check(x[:, 2].max() <= length + margin, "taylor: points above the rod's initial top")
    top = x0[:, 2] > length - 2 * h
    check(
        np.allclose(d["velocity"][top], vel, rtol=0, atol=0.01 * abs(vel[2])),
        "taylor: the rod's top (no wave has reached it) is not still at the impact velocity",
    )
    check(
        np.allclose(x[top] - x0[top], vel * t, rtol=0, atol=0.01 * travel),
        f"taylor: the rod's top did not move by v t = {travel:.3e} m",
    )
    eps = d["plastic_strain"][:, 0]
    check(eps.max() > 0, "taylor: no plastic strain after the impact")
    sv = d["stress"].reshape(-1, 3, 3)
    check(np.all(np.isfinite(sv)) and maxabs(sv) > 0, "taylor: no stress after the impact")
    print(
        f"  taylor: frame 0 lattice and velocity {vel.tolist()} exact; at t = {t:.1e} s largest "
        f"plastic strain {eps.max():.3f}, largest |stress| {maxabs(sv):.3e} Pa"
    )


def vtk_format(path):
    """How a .vtu stores its arrays, read from its bytes: "binary" (every array appended, raw)
    or "ascii" (every array as text), else "mixed"."""
    data = path.read_bytes()
    xml = data.split(b"<AppendedData", 1)[0]
    appended = xml.count(b'format="appended"')
    ascii_ = xml.count(b'format="ascii"') - 1  # less the TimeValue field, text in both
    raw = b'<AppendedData encoding="raw">' in data
    if appended > 0 and ascii_ == 0 and raw:
        return "binary"
    if appended == 0 and ascii_ > 0 and not raw:
        return "ascii"
    return "mixed"


def check_formats(out):
    """The bar's frames binary, the Taylor bar's ASCII (--vtk ascii), and the bar's ASCII run
    the same values as its binary run, bit for bit, frame by frame."""
    binary = sorted(out.glob("bar_*.vtu"))
    text = sorted((out / "ascii").glob("bar_*.vtu"))
    require(binary, "formats: no bar frames")
    for path in binary:
        check(vtk_format(path) == "binary", f"{path.name}: {vtk_format(path)}, expected binary")
    for path in sorted(out.glob("taylor_*.vtu")) + text:
        check(vtk_format(path) == "ascii", f"{path}: {vtk_format(path)}, expected ascii")
    require(
        [p.name for p in text] == [p.name for p in binary],
        f"formats: ascii/ holds {len(text)} bar frames, the binary run {len(binary)}",
    )
    size = [sum(p.stat().st_size for p in paths) for paths in (binary, text)]
    for b, a in zip(binary, text):
        mb, ma = meshio.vtu.read(b), meshio.vtu.read(a)
        check(np.array_equal(mb.points, ma.points), f"{b.name}: points differ between the formats")
        for name in mb.point_data:
            check(
                np.array_equal(mb.point_data[name], ma.point_data[name]),
                f"{b.name}: {name} differs between the formats",
            )
    print(
        f"  formats: {len(binary)} bar frames equal bit for bit in binary and ASCII; "
        f"binary {size[0] / 1e6:.2f} MB, ASCII {size[1] / 1e6:.2f} MB"
    )


def main():
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    out = Path(sys.argv[1])
    for name, run in (("bar", check_bar), ("taylor", check_taylor), ("formats", check_formats)):
        before = len(failures)
        try:
            run(out)
        except Abort:
            pass
        except Exception as e:  # a checker bug or an unexpected file: still a failure
            failures.append(f"{name}: {type(e).__name__}: {e}")
        print(f"{name}: {'ok' if len(failures) == before else 'FAILED'}")
    if failures:
        print(f"check_vtk: {len(failures)} failed check(s):", file=sys.stderr)
        for f in failures[:20]:
            print(f"  - {f}", file=sys.stderr)
        if len(failures) > 20:
            print(f"  ... and {len(failures) - 20} more", file=sys.stderr)
        return 1
    print("check_vtk: all checks passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
