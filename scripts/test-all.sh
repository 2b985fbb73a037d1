#!/usr/bin/env bash
# Every test of rkmpm: the Rust unit, integration and doc tests (the header check among them),
# the parallel primitives' tests under Miri (scripts/test-miri.sh),
# every C and Fortran block of the docs compiled and run (scripts/test-doc-snippets.sh), the VTK
# output read back with meshio (scripts/test-vtk.sh), then the C and Fortran drivers built by
# CMake and run under CTest, then the installed package
# (CMake and pkg-config) used by outside C and Fortran projects (scripts/test-install.sh), then
# the drivers again under AddressSanitizer/LeakSanitizer/UndefinedBehaviorSanitizer
# (-DRKMPM_SANITIZE=ON).
# Installs gfortran, cmake and pkg-config with apt-get when they are missing (as root; otherwise
# says how).
set -euo pipefail
cd "$(dirname "$0")/.."

missing=()
command -v gfortran >/dev/null || missing+=(gfortran)
command -v cmake >/dev/null || missing+=(cmake)
command -v pkg-config >/dev/null || missing+=(pkg-config)
command -v cc >/dev/null || missing+=(gcc)
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "== installing ${missing[*]}"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  else
    echo "missing: ${missing[*]}; install them (e.g. sudo apt-get install ${missing[*]}) and run again" >&2
    exit 1
  fi
fi

export RUST_BACKTRACE=0
# The test targets and the doc tests; the examples (the studies' full runs) are not built here:
# clippy --all-targets checks that they compile, and each would link the engine's generic step
# anew (minutes of a fresh build).
echo "== Rust tests (cargo test --release --tests, then --doc)"
cargo test --release --tests
cargo test --release --doc

echo "== The parallel primitives under Miri (skipped, saying so, without a nightly)"
./scripts/test-miri.sh

echo "== Every C and Fortran block of README.md and docs/*.md compiles and runs; rustdoc without warnings"
./scripts/test-doc-snippets.sh

echo "== VTK output read back with a real reader (meshio, in build/vtk-venv)"
# The runner the tests above built (a `cargo build --bin rkmpm` resolves the dependencies'
# features without the dev-dependencies and would build the engine again).
RKMPM_BIN=$PWD/target/release/rkmpm ./scripts/test-vtk.sh

echo "== C and Fortran drivers (CMake + CTest)"
build=build/examples
cmake -S examples -B "$build" -DCMAKE_BUILD_TYPE=Release -DRKMPM_CARGO_TARGET_DIR="$PWD/target" >/dev/null
cmake --build "$build" -j 2
ctest --test-dir "$build" --output-on-failure

echo "== Install (CMake package, pkg-config) and outside C and Fortran projects built against it"
scripts/test-install.sh "$PWD/target"

echo "== The same drivers under AddressSanitizer, LeakSanitizer and UndefinedBehaviorSanitizer"
asan=build/examples-sanitized
cmake -S examples -B "$asan" -DCMAKE_BUILD_TYPE=Release -DRKMPM_CARGO_TARGET_DIR="$PWD/target" \
  -DRKMPM_SANITIZE=ON >/dev/null
cmake --build "$asan" -j 2
ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1 \
  ctest --test-dir "$asan" --output-on-failure
