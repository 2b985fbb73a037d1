"""Runs the throughput matrix (rkmpm methods x dims x particle counts x threads, and the peers on the
matching quadratic B-spline APIC configuration), writes a CSV and prints Markdown tables.
The method `bspline2-mls` is the quadratic B-spline with the MLS transfer (`--transfer mls`), the
peers' own transfer; it runs material-point only, with exactly S(N) steps like the peers.
Called by scripts/bench.sh, which makes the venv and builds the example; see that script.

Every rkmpm run: 1 warm-up step, then S(N) = clamp(1e7 / N, 10, 100) timed steps, stopping early
after 3 s (at least 3 steps), except rkmpm's quadratic B-spline APIC material-point run, which the
peers mirror: that one always takes exactly S(N) steps, like Warp and Taichi. A run predicted (from
the same method at the previous count) to need more than --run-budget seconds for warm-up plus 3
steps, or more memory than --mem-limit-gb, is skipped and listed as skipped.
"""

import argparse
import csv
import datetime
import os
import platform
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from block import HEADER, per_direction  # noqa: E402

FIELDS = HEADER.split(",") + ["wall_seconds", "max_rss_mb", "status", "note"]
METHODS = ["linear", "bspline2", "bspline2-mls", "bspline3", "rk1", "rk2"]


def steps_for(n, quick):
    return 10 if quick else max(10, min(100, int(round(1e7 / n))))


def run(cmd, env_extra):
    """Runs cmd; returns (csv line or None, wall seconds, max RSS MB, stderr tail)."""
    env = dict(os.environ)
    env.update(env_extra)
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        t0 = time.perf_counter()
        p = subprocess.Popen(cmd, stdout=out, stderr=err, env=env)
        _, status, usage = os.wait4(p.pid, 0)
        p.returncode = os.waitstatus_to_exitcode(status)
        wall = time.perf_counter() - t0
        out.seek(0)
        err.seek(0)
        line = None
        for s in out.read().splitlines():
            if s.split(",")[0] in ("rkmpm", "warp", "taichi"):
                line = s
        tail = " ".join(err.read().strip().splitlines()[-2:])[-300:]
        if p.returncode != 0:
            line = None
        return line, wall, usage.ru_maxrss / 1024.0, tail


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--example", required=True, help="path of the built throughput example")
    ap.add_argument("--python", default=sys.executable)
    ap.add_argument("--out", required=True, help="results CSV")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--no-peers", action="store_true")
    ap.add_argument("--run-budget", type=float, default=60.0)
    ap.add_argument("--mem-limit-gb", type=float, default=12.0)
    ap.add_argument("--time-limit", type=float, default=1800.0, help="whole matrix, seconds")
    ap.add_argument("--methods", default=",".join(METHODS), help="comma-separated subset")
    ap.add_argument("--counts", help="comma-separated DIM:N pairs, e.g. 3:100000,3:1000000")
    a = ap.parse_args()
    methods = a.methods.split(",")

    if a.quick:
        counts = [(2, 4096), (3, 4096)]
    else:
        counts = [(2, 10**4), (3, 10**4), (2, 10**5), (3, 10**5), (2, 10**6), (3, 10**6), (2, 4 * 10**6)]
    if a.counts:
        counts = [tuple(int(v) for v in c.split(":")) for c in a.counts.split(",")]
    threads = [1, 2]
    start = time.perf_counter()
    rows = []
    last = {}  # (method, vc, dim) -> (particles, particle_steps_per_s, rss_mb)

    def record(line, wall, rss, status, note, fallback):
        if line:
            row = dict(zip(HEADER.split(","), line.split(",")))
        else:
            row = dict(zip(HEADER.split(","), fallback))
        row.update(wall_seconds=f"{wall:.2f}", max_rss_mb=f"{rss:.0f}", status=status, note=note)
        rows.append(row)
        with open(a.out, "w", newline="") as f:
            w = csv.DictWriter(f, FIELDS)
            w.writeheader()
            w.writerows(rows)
        shown = line if line else ",".join(fallback)
        print(f"[{time.perf_counter() - start:7.1f} s] {status:8s} {shown} {note}", flush=True)

    for dim, n in counts:
        steps = steps_for(n, a.quick)
        for method in methods:
            mls = method == "bspline2-mls"
            for vc in (False, True) if not mls else (False,):
                matching = method in ("bspline2", "bspline2-mls") and not vc
                for t in threads:
                    fallback = ["rkmpm", str(dim), method, "vc" if vc else "mp", "", str(per_direction(n, dim) ** dim), "", str(t)]
                    fallback += [""] * (len(HEADER.split(",")) - len(fallback))
                    if time.perf_counter() - start > a.time_limit:
                        record(None, 0, 0, "skipped", "time limit of the matrix reached", fallback)
                        continue
                    prev = last.get((method, vc, dim))
                    if prev and not matching:
                        step_s = n / prev[1]
                        mem_gb = prev[2] * n / prev[0] / 1024.0
                        if 4 * step_s > a.run_budget or mem_gb > a.mem_limit_gb:
                            record(None, 0, 0, "skipped",
                                   f"predicted {step_s:.1f} s/step, {mem_gb:.1f} GB", fallback)
                            continue
                    cmd = [a.example, "--dim", str(dim), "--method", "bspline2" if mls else method,
                           "--particles", str(n), "--steps", str(steps), "--warmup", "1"]
                    if mls:
                        cmd += ["--transfer", "mls"]
                    if vc:
                        cmd.append("--vc")
                    if not matching:
                        cmd += ["--max-seconds", "3", "--min-steps", "3"]
                    line, wall, rss, tail = run(cmd, {"RAYON_NUM_THREADS": str(t)})
                    if line is None:
                        record(None, wall, rss, "failed", tail, fallback)
                        continue
                    f = line.split(",")
                    f[2] = method  # bspline2-mls runs as bspline2 with --transfer mls
                    line = ",".join(f)
                    last[(method, vc, dim)] = (int(f[5]), float(f[11]), rss)
                    record(line, wall, rss, "ok", tail, fallback)
        if a.no_peers:
            continue
        peers = [("warp", 1), ("taichi", 1), ("taichi", 2)]
        for engine, t in peers:
            fallback = [engine, str(dim), "bspline2", "mp", "apic", str(per_direction(n, dim) ** dim), "", str(t)]
            fallback += [""] * (len(HEADER.split(",")) - len(fallback))
            if time.perf_counter() - start > a.time_limit:
                record(None, 0, 0, "skipped", "time limit of the matrix reached", fallback)
                continue
            cmd = [a.python, os.path.join(HERE, f"{engine}_mpm.py"), "--dim", str(dim),
                   "--particles", str(n), "--steps", str(steps), "--warmup", "1", "--threads", str(t)]
            line, wall, rss, tail = run(cmd, {})
            if line is None:
                record(None, wall, rss, "failed", tail, fallback)
            else:
                record(line, wall, rss, "ok", "", fallback)
    print(f"\nmatrix took {time.perf_counter() - start:.0f} s; results in {a.out}\n")
    print(report(rows))


def report(rows):
    """Markdown: rkmpm throughput per method, then the peer comparison with ratios."""
    for r in rows:  # rows not measured carry the nominal count in older CSVs
        r["particles"] = str(per_direction(int(r["particles"]), int(r["dim"])) ** int(r["dim"]))
    ok = [r for r in rows if r["status"] == "ok"]

    def get(engine, dim, method, vc, n, t):
        for r in ok:
            if (r["engine"], r["dim"], r["method"], r["vc"], r["particles"], r["threads"]) == (
                engine, str(dim), method, vc, str(n), str(t)):
                return r
        return None

    out = []
    configs = sorted({(int(r["dim"]), int(r["particles"])) for r in rows if r["engine"] == "rkmpm"})
    for dim in (2, 3):
        ns = sorted({n for d, n in configs if d == dim})
        if not ns:
            continue
        out.append(f"**rkmpm, {dim}D: million particle-steps/s (1 thread / 2 threads)**\n")
        out.append("| method | " + " | ".join(f"N = {n:,}" for n in ns) + " |")
        out.append("|---|" + "---|" * len(ns))
        for method in METHODS:
            for vc in ("mp", "vc"):
                cells = []
                for n in ns:
                    parts = []
                    for t in (1, 2):
                        r = get("rkmpm", dim, method, vc, n, t)
                        parts.append(f"{float(r['particle_steps_per_s']) / 1e6:.3g}" if r else "–")
                    cells.append(" / ".join(parts))
                if all(c == "– / –" for c in cells):
                    continue
                label = f"{method}{' + VC' if vc == 'vc' else ''}{' (PIC)' if method == 'rk2' else ''}"
                out.append(f"| {label} | " + " | ".join(cells) + " |")
        out.append("")
    out.append("**Quadratic B-spline APIC, neo-Hookean, f64: million particle-steps/s and ratios "
               "rkmpm / peer (same run)**\n")
    out.append("| dim | N | steps | rkmpm 1T | rkmpm 2T | Warp 1T | Taichi 1T | Taichi 2T | "
               "rkmpm 1T / Warp | rkmpm 1T / Taichi 1T | rkmpm 2T / Taichi 2T | rkmpm 2T / Warp | "
               "KE rkmpm vs Warp | rkmpm MLS 1T / 2T | MLS 1T / Warp | MLS 2T / Warp | "
               "KE MLS vs Warp |")
    out.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for dim, n in configs:
        r1 = get("rkmpm", dim, "bspline2", "mp", n, 1)
        r2 = get("rkmpm", dim, "bspline2", "mp", n, 2)
        w = get("warp", dim, "bspline2", "mp", n, 1)
        t1 = get("taichi", dim, "bspline2", "mp", n, 1)
        t2 = get("taichi", dim, "bspline2", "mp", n, 2)
        if not (w or t1 or t2):
            continue

        def v(r):
            return float(r["particle_steps_per_s"]) if r else None

        def m(r):
            return f"{v(r) / 1e6:.3g}" if r else "–"

        def ratio(a, b):
            return f"{v(a) / v(b):.2f}" if a and b else "–"

        def ke(r):
            if r and w:
                return f"{abs(float(r['kinetic_energy']) / float(w['kinetic_energy']) - 1):.1e}"
            return "–"

        l1 = get("rkmpm", dim, "bspline2-mls", "mp", n, 1)
        l2 = get("rkmpm", dim, "bspline2-mls", "mp", n, 2)
        out.append(f"| {dim}D | {int(n):,} | {(r1 or w or t1)['steps']} | {m(r1)} | {m(r2)} | {m(w)} | "
                   f"{m(t1)} | {m(t2)} | {ratio(r1, w)} | {ratio(r1, t1)} | {ratio(r2, t2)} | "
                   f"{ratio(r2, w)} | {ke(r1)} | {m(l1)} / {m(l2)} | {ratio(l1, w)} | "
                   f"{ratio(l2, w)} | {ke(l1)} |")
    skipped = [r for r in rows if r["status"] != "ok"]
    if skipped:
        out.append("\nNot measured:\n")
        for r in skipped:
            out.append(f"- {r['engine']} {r['dim']}D {r['method']} {r['vc']} N={r['particles']} "
                       f"{r['threads']}T: {r['status']} ({r['note']})")
    return "\n".join(out)


def machine():
    model = "?"
    try:
        for s in subprocess.run(["lscpu"], capture_output=True, text=True).stdout.splitlines():
            if s.startswith("Model name"):
                model = s.split(":", 1)[1].strip()
    except OSError:
        pass
    return (f"{datetime.datetime.now().isoformat(timespec='seconds')}, {platform.node()}, "
            f"CPU {model}, {os.cpu_count()} logical CPUs, load average {os.getloadavg()}")


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--report":
        with open(sys.argv[2]) as f:
            print(report(list(csv.DictReader(f))))
    else:
        print("machine:", machine(), flush=True)
        main()
