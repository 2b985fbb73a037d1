#!/usr/bin/env bash
# Every ```c and ```fortran block of README.md and docs/*.md compiles, and every one that is a
# program (a C `main`, a Fortran `program`) runs and exits with 0. Also: rustdoc without warnings.
#
#   scripts/test-doc-snippets.sh [file.md ...]   (default: README.md docs/*.md; CARGO_TARGET_DIR is
#                                                respected, default target/)
#
# C blocks:       cc -std=c11 -Wall -Wextra -Werror -pedantic -I include, linked with the static
#                 library librkmpm.a (cargo build --release -p rkmpm-capi) and -lpthread -ldl -lm.
# Fortran blocks: gfortran -std=f2018 -Wall -Werror against bindings/fortran/rkmpm.f90 (compiled
#                 here into a temporary directory), linked the same way.
# Each program runs in a temporary directory of its own (they may write files). A block that is
# deliberately not standalone is skipped only when the line before its fence is
#   <!-- not compiled: reason -->
# Environment: CC (default cc), FC (default gfortran), RKMPM_DOC_SKIP_RUSTDOC=1 skips cargo doc,
# RKMPM_DOC_KEEP=1 keeps the temporary directory (blocks, builds, run directories and output).
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
start=$SECONDS
cc="${CC:-cc}"
fc="${FC:-gfortran}"
target_dir="${CARGO_TARGET_DIR:-$root/target}"
case "$target_dir" in /*) ;; *) target_dir="$root/$target_dir" ;; esac
export CARGO_TARGET_DIR="$target_dir"

cargo_bin="$(command -v cargo || true)"
[[ -z "$cargo_bin" && -x "$HOME/.cargo/bin/cargo" ]] && cargo_bin="$HOME/.cargo/bin/cargo"
[[ -n "$cargo_bin" ]] || { echo "cargo not found" >&2; exit 1; }

work="$(mktemp -d "${TMPDIR:-/tmp}/rkmpm-doc-snippets.XXXXXX")"
if [[ "${RKMPM_DOC_KEEP:-0}" == 1 ]]; then
  echo "keeping the blocks, builds and runs in $work"
else
  trap 'rm -rf "$work"' EXIT
fi

failures=0

# ---- rustdoc ------------------------------------------------------------------------------------
if [[ "${RKMPM_DOC_SKIP_RUSTDOC:-0}" != 1 ]]; then
  echo "== cargo doc --no-deps --lib of the engine, runner and studies (RUSTDOCFLAGS=-D warnings)"
  if RUSTDOCFLAGS="-D warnings" "$cargo_bin" doc --no-deps --lib -p rkmpm -p rkmpm-runner -p rkmpm-studies --quiet; then
    echo "rustdoc: ok"
  else
    echo "rustdoc: FAILED (warnings above)"
    failures=$((failures + 1))
  fi
fi

# ---- the library and the Fortran module -----------------------------------------------------------
echo "== cargo build --release -p rkmpm-capi (target dir $target_dir)"
"$cargo_bin" build --release -p rkmpm-capi --quiet
lib="$target_dir/release/librkmpm.a"
[[ -f "$lib" ]] || { echo "missing $lib" >&2; exit 1; }
libs=("$lib" -lpthread -ldl -lm)

moddir="$work/fortran_module"
mkdir -p "$moddir"
"$fc" -std=f2018 -c "$root/bindings/fortran/rkmpm.f90" -J "$moddir" -o "$moddir/rkmpm.o"

# ---- extract the blocks -----------------------------------------------------------------------------
# One file per block: <work>/blocks/NNN-<doc>-L<line>.c or .f90, and a manifest line
#   NNN, lang, doc file, line of the fence, block file, skip reason (empty: compile)
# separated by the ASCII unit separator (a tab would merge empty fields in `read`).
mkdir -p "$work/blocks"
if [[ $# -gt 0 ]]; then
  docs=("$@")                       # other Markdown files (absolute or relative to the repository)
else
  docs=(README.md)
  for f in docs/*.md; do [[ -f "$f" ]] && docs+=("$f"); done
fi
: >"$work/manifest"
for doc in "${docs[@]}"; do
  awk -v doc="$doc" -v dir="$work/blocks" -v manifest="$work/manifest" -v base="$(wc -l <"$work/manifest")" '
    function flush() { close(out) }
    BEGIN { inside = 0; n = base }
    {
      line = $0
      if (!inside) {
        if (match(line, /^[ \t]*```+/)) {
          fence = substr(line, RSTART, RLENGTH); sub(/^[ \t]*/, "", fence)
          info = substr(line, RSTART + RLENGTH); gsub(/[ \t]/, "", info)
          inside = 1
          if (info == "c" || info == "fortran") {
            n++
            ext = (info == "c") ? "c" : "f90"
            name = doc; gsub(/[^A-Za-z0-9_.-]/, "_", name)
            out = sprintf("%s/%03d-%s-L%d.%s", dir, n, name, NR, ext)
            printf "" > out
            # C: compiler messages give the line in the Markdown file.
            if (ext == "c") printf "#line %d \"%s\"\n", NR + 1, doc >> out
            reason = ""
            if (match(prev, /<!--[ \t]*not compiled:[^>]*-->/)) {
              reason = substr(prev, RSTART, RLENGTH)
              sub(/^<!--[ \t]*not compiled:[ \t]*/, "", reason); sub(/[ \t]*-->$/, "", reason)
              if (reason == "") reason = "(no reason given)"
            }
            printf "%03d\037%s\037%s\037%d\037%s\037%s\n", n, info, doc, NR, out, reason >> manifest
            capture = 1
          } else {
            capture = 0
          }
        }
      } else {
        t = line; sub(/^[ \t]*/, "", t); sub(/[ \t]*$/, "", t)
        if (index(t, fence) == 1 && t ~ /^`+$/ && length(t) >= length(fence)) {
          inside = 0
          if (capture) flush()
          capture = 0
        } else if (capture) {
          print line >> out
        }
      }
      prev = line
    }
    END { if (inside) { printf "%s: unclosed code fence\n", doc > "/dev/stderr"; exit 1 } }
  ' "$doc"
done

# ---- compile and run ----------------------------------------------------------------------------------
total=0; compiled=0; ran=0; skipped=0
echo "== blocks"
while IFS=$'\037' read -r id lang doc line src reason; do
  total=$((total + 1))
  where="$doc:$line ($lang)"
  if [[ -n "$reason" ]]; then
    echo "SKIP  $where: not compiled: $reason"
    skipped=$((skipped + 1))
    continue
  fi
  bdir="$work/build_$id"
  rdir="$work/run_$id"
  mkdir -p "$bdir" "$rdir"
  log="$bdir/log"
  if [[ "$lang" == c ]]; then
    flags=(-std=c11 -Wall -Wextra -Werror -pedantic -I "$root/include")
    if grep -Eq '\bmain[[:space:]]*\(' "$src"; then
      is_program=1
      build=("$cc" "${flags[@]}" "$src" -o "$bdir/prog" "${libs[@]}")
    else
      is_program=0
      build=("$cc" "${flags[@]}" -c "$src" -o "$bdir/block.o")
    fi
  else
    flags=(-std=f2018 -Wall -Werror -I "$moddir" -J "$bdir")
    if grep -Eiq '^[[:space:]]*program[[:space:]]+[a-z]' "$src"; then
      is_program=1
      build=("$fc" "${flags[@]}" "$src" "$moddir/rkmpm.o" -o "$bdir/prog" "${libs[@]}")
    else
      is_program=0
      build=("$fc" "${flags[@]}" -c "$src" -o "$bdir/block.o")
    fi
  fi
  if ! "${build[@]}" >"$log" 2>&1; then
    if [[ "$lang" == c ]]; then
      echo "FAIL  $where: does not compile"
    else
      echo "FAIL  $where: does not compile (line 1 of the block is line $((line + 1)) of $doc)"
    fi
    sed 's/^/      /' "$log"
    failures=$((failures + 1))
    continue
  fi
  compiled=$((compiled + 1))
  if [[ $is_program == 0 ]]; then
    echo "ok    $where: compiles (no main/program: not run)"
    continue
  fi
  set +e
  (cd "$rdir" && RUST_BACKTRACE=0 timeout 300 "$bdir/prog") >"$bdir/run.log" 2>&1
  rc=$?
  set -e
  if [[ $rc != 0 ]]; then
    echo "FAIL  $where: compiles, but exits with $rc"
    sed 's/^/      /' "$bdir/run.log"
    failures=$((failures + 1))
    continue
  fi
  ran=$((ran + 1))
  echo "ok    $where: compiles and runs (exit 0)"
  tail -n 3 "$bdir/run.log" | sed 's/^/      | /'
done <"$work/manifest"

echo "== $total blocks: $compiled compiled, $ran of them ran with exit 0, $skipped skipped, $failures failure(s) ($((SECONDS - start)) s)"
if [[ $failures != 0 ]]; then
  exit 1
fi
