#!/usr/bin/env bash
# Throughput benchmark of rkmpm against NVIDIA Warp (CPU) and Taichi (CPU), same run, same machine.
#
#   scripts/bench.sh            # full matrix (about 25 minutes on 2 cores)
#   scripts/bench.sh --quick    # smoke test: 4096 particles in 2D and 3D, 10 steps
#   scripts/bench.sh --no-peers # rkmpm only (no venv)
#   scripts/bench.sh --native   # rkmpm compiled for this CPU (-C target-cpu=native), as the peers'
#                               # JIT compilers compile their kernels; results get the suffix -native
#
# Makes a venv in build/bench-venv with pinned warp-lang, taichi and numpy from PyPI (CPython 3.11),
# builds studies/examples/throughput.rs in release (CARGO_TARGET_DIR, default /tmp/bench-target),
# runs bench/run_matrix.py and bench/skips.py (what each skip saves) and writes build/bench-results[-quick].csv and .md. Timings are noisy
# when other work runs on the machine: compare ratios within one run.
set -euo pipefail
cd "$(dirname "$0")/.."

QUICK=()
PEERS=1
NATIVE=0
EXTRA=()
for arg in "$@"; do
    case "$arg" in
        --quick) QUICK=(--quick) ;;
        --no-peers) PEERS=0; EXTRA+=(--no-peers) ;;
        --native) NATIVE=1 ;;
        -h|--help) sed -n 2,13p "$0"; exit 0 ;;
        *) EXTRA+=("$arg") ;;
    esac
done

if [ "$NATIVE" = 1 ]; then
    export RUSTFLAGS="${RUSTFLAGS:-} -C target-cpu=native"
    export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-/tmp/bench-target-native}"
else
    export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-/tmp/bench-target}"
fi
mkdir -p build
VENV=build/bench-venv
PY=python3
if [ "$PEERS" = 1 ]; then
    if [ ! -x "$VENV/bin/python" ]; then
        python3 -m venv "$VENV"
    fi
    "$VENV/bin/python" -m pip install -q --disable-pip-version-check \
        warp-lang==1.19.0 taichi==1.7.4 numpy==2.4.6
    PY="$VENV/bin/python"
    # Keep Warp's kernel cache inside build/.
    export WARP_CACHE_PATH="$PWD/build/bench-warp-cache"
fi

cargo build --release --example throughput
EXAMPLE="$CARGO_TARGET_DIR/release/examples/throughput"

SUFFIX=""
[ ${#QUICK[@]} -gt 0 ] && SUFFIX="-quick"
[ "$NATIVE" = 1 ] && SUFFIX="$SUFFIX-native"
OUT="build/bench-results$SUFFIX.csv"
{
    echo "command: scripts/bench.sh $*"
    echo "git: $(git rev-parse --short HEAD 2>/dev/null || echo '?') ($(git status --porcelain 2>/dev/null | wc -l) files changed)"
    echo "rustc: $(rustc --version); RUSTFLAGS: ${RUSTFLAGS:-(none)}"
    [ "$PEERS" = 1 ] && echo "python: $("$PY" --version), $("$PY" -m pip list 2>/dev/null | grep -iE '^(warp-lang|taichi|numpy) ' | tr -s ' ' | paste -sd, -)"
    echo "cpu: $(lscpu | sed -n 's/^Model name: *//p'), $(nproc) cores; $(lscpu | grep -o 'avx512f' | head -1 || true)"
    "$PY" bench/run_matrix.py --example "$EXAMPLE" --python "$PY" --out "$OUT" "${QUICK[@]}" "${EXTRA[@]}"
    echo
    python3 bench/skips.py --example "$EXAMPLE" "${QUICK[@]}"
} 2>&1 | tee "build/bench-results$SUFFIX.md"
