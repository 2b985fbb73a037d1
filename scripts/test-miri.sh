#!/usr/bin/env bash
# Miri on the tests of the parallel primitives: the node sums' shared slices and scatter
# (src/grid/shared.rs), particle to grid's coloured schedule (src/grid/blocks.rs) and the new
# state's writer (src/step/grid_to_particle.rs). Out-of-bounds or misaligned accesses and data
# races between the threads fail them. Needs a nightly toolchain
# with the miri component: installed with rustup when missing (minimal profile); where that
# cannot be done (no rustup, no network), says so plainly and skips, exit status 0.
#   scripts/test-miri.sh
# Flags: Tree Borrows and permissive provenance, because rayon's crossbeam-epoch (which the
# node reset runs on) is flagged under Stacked Borrows and casts integers to pointers; leaks
# ignored, because rayon's pool outlives the test's main thread.
set -euo pipefail
cd "$(dirname "$0")/.."

skip() {
  echo "Miri: SKIPPED ($1); the parallel primitives' tests ran natively only"
  exit 0
}

if ! cargo +nightly miri --version >/dev/null 2>&1; then
  command -v rustup >/dev/null || skip "no rustup to install a nightly toolchain with Miri"
  if rustup toolchain list | grep -q '^nightly'; then
    echo "== adding miri and rust-src to the installed nightly toolchain (rustup)"
    timeout 900 rustup component add --toolchain nightly miri rust-src >/dev/null 2>&1 ||
      skip "rustup could not add miri to the installed nightly (offline?)"
  else
    echo "== installing a nightly toolchain with miri and rust-src (rustup, minimal profile)"
    timeout 900 rustup toolchain install nightly --profile minimal --component miri,rust-src \
      >/dev/null 2>&1 ||
      skip "rustup could not install nightly with miri (offline, or no miri in tonight's nightly)"
  fi
  cargo +nightly miri --version >/dev/null 2>&1 || skip "cargo miri does not run after the install"
fi
echo "== $(cargo +nightly miri --version)"
MIRIFLAGS="-Zmiri-tree-borrows -Zmiri-permissive-provenance -Zmiri-ignore-leaks" \
  cargo +nightly miri test -p rkmpm --lib -- grid::shared grid::blocks step::grid_to_particle
