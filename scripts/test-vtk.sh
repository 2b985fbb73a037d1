#!/usr/bin/env bash
# Checks rkmpm's VTK output with a real reader: runs the vibrating bar (2D, 41 frames; binary, and
# again in ASCII) and a short Taylor bar (3D, 3 frames, ASCII) with the runner into build/vtk-check/, then reads every .vtu with
# meshio and the .pvd with xml.etree (tests/vtk/check_vtk.py) and checks the series, the arrays
# and their shapes, the frame-0 particles and velocities and the bar's velocity after a period.
#
#   scripts/test-vtk.sh
#
# The Python environment is build/vtk-venv (python3 -m venv, packages of tests/vtk/requirements.txt
# from PyPI), made once and reused while the requirements are unchanged. The runner is $RKMPM_BIN
# when set (scripts/test-all.sh passes the one its tests built), else built with
# `cargo build --release --bin rkmpm` into $CARGO_TARGET_DIR (default: target/).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
t0=$SECONDS
fail() { echo "test-vtk: FAIL: $*" >&2; exit 1; }

venv=$root/build/vtk-venv
req=$root/tests/vtk/requirements.txt
stamp=$venv/requirements.installed
if [ -x "$venv/bin/python" ] && [ -f "$stamp" ] && cmp -s "$req" "$stamp"; then
  echo "== Python environment: reusing $venv"
else
  # Python 3.11 or later with a working venv module: python3 on PATH, else the system's
  # (Debian's python3-venv when it is missing).
  python=
  for p in python3 /usr/bin/python3; do
    if command -v "$p" >/dev/null &&
      "$p" -c 'import sys, venv, ensurepip; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
      python=$p
      break
    fi
  done
  if [ -z "$python" ]; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
      echo "== installing python3-venv"
      apt-get update -qq
      DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends python3-venv >/dev/null
      python=/usr/bin/python3
    else
      fail "needs Python 3.11 or later with venv (e.g. sudo apt-get install python3-venv)"
    fi
  fi
  echo "== Python environment: $python -m venv $venv ($("$python" --version 2>&1))"
  rm -rf "$venv"
  "$python" -m venv "$venv" || fail "$python -m venv failed"
  echo "== pip install -r tests/vtk/requirements.txt"
  "$venv/bin/python" -m pip install --disable-pip-version-check -q -r "$req" ||
    fail "pip install from PyPI failed"
  cp "$req" "$stamp"
fi
"$venv/bin/python" -c 'import meshio, numpy; print(f"   meshio {meshio.__version__}, numpy {numpy.__version__}")'

if [ -n "${RKMPM_BIN:-}" ]; then
  [ -x "$RKMPM_BIN" ] || fail "RKMPM_BIN=$RKMPM_BIN is not an executable"
  rkmpm=$RKMPM_BIN
  echo "== runner: $rkmpm"
else
  target=${CARGO_TARGET_DIR:-$root/target}
  echo "== cargo build --release --bin rkmpm (target dir $target)"
  CARGO_TARGET_DIR=$target cargo build --release --bin rkmpm
  rkmpm=$target/release/rkmpm
fi

out=$root/build/vtk-check
rm -rf "$out"
mkdir -p "$out"
# run NAME ARGS...: rkmpm ARGS, its output in build/vtk-check/NAME.log (shown when it fails).
run() {
  local log=$out/$1.log
  shift
  echo "   \$ rkmpm $*"
  "$rkmpm" "$@" >"$log" 2>&1 || { cat "$log" >&2; fail "rkmpm $* exited with an error"; }
}
echo "== runs into build/vtk-check/"
run bar run bar --quiet --out "$out"
run bar-ascii run bar --quiet --vtk ascii --out "$out/ascii"
run taylor run taylor --quiet --frames 2 --end-time 2e-6 --vtk ascii --out "$out"

echo "== tests/vtk/check_vtk.py build/vtk-check"
"$venv/bin/python" tests/vtk/check_vtk.py "$out" || fail "the VTK output failed its checks (above)"
echo "== test-vtk: ok ($((SECONDS - t0)) s)"
