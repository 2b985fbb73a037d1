"""What each skip saves: rkmpm's throughput example on the benchmark block with one feature turned on
at a time (the work a scene that does not need it skips), one thread, 2D and 3D, and the time per
phase of the base run. Called by scripts/bench.sh after the matrix; prints Markdown.

    python3 bench/skips.py --example /tmp/bench-target/release/examples/throughput [--quick]
"""

import argparse
import subprocess
import sys

VARIANTS = [
    ("base: quadratic B-spline, APIC, elastic, no gravity", []),
    ("+ VC (VC sums, boundary points)", ["--vc"]),
    ("+ gravity (body-force sums)", ["--gravity"]),
    ("+ return mapping (Drucker-Prager that stays elastic)", ["--material", "drucker-prager"]),
    ("APIC -> PIC (no affine matrices)", ["--transfer", "pic"]),
    ("+ 200 empty cells on every side", ["--padding", "200"]),
    ("stencils stored node by node instead of 1D factors", ["--stored-stencils"]),
]


def run(example, dim, n, steps, extra, threads="1"):
    cmd = [example, "--dim", str(dim), "--method", "bspline2", "--particles", str(n),
           "--steps", str(steps), "--warmup", "1", "--phases"] + extra
    p = subprocess.run(cmd, capture_output=True, text=True, env={"RAYON_NUM_THREADS": threads})
    if p.returncode != 0:
        return None, p.stderr.strip()
    line = [s for s in p.stdout.splitlines() if s.startswith("rkmpm,")][-1]
    return float(line.split(",")[11]), p.stderr


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--example", required=True)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    sizes = [(2, 4096, 10), (3, 4096, 10)] if a.quick else [(2, 250000, 40), (3, 125000, 20)]
    print("## What each skip saves (one thread, million particle-steps/s)\n")
    print("| variant | " + " | ".join(f"{d}D, N = {n}" for d, n, _ in sizes) + " |")
    print("|---|" + "---|" * len(sizes))
    base = {}
    phases = {}
    for name, extra in VARIANTS:
        cells = []
        for dim, n, steps in sizes:
            rate, err = run(a.example, dim, n, steps, extra)
            if rate is None:
                cells.append(f"failed ({err[-80:]})")
                continue
            if not extra:
                base[dim] = rate
                phases[dim] = [s for s in err.splitlines() if s.startswith("phase")]
            ratio = rate / base[dim] if dim in base else float("nan")
            cells.append(f"{rate / 1e6:.2f} ({ratio:.2f}x)")
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)
    print("\nRatios are against the base run of the same column (same run).\n")
    for dim, lines in phases.items():
        print(f"Time per phase of the {dim}D base run (ns per particle-step, share):\n")
        print("```")
        print("\n".join(lines))
        print("```\n")


if __name__ == "__main__":
    sys.exit(main())
