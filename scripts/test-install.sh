#!/usr/bin/env bash
# Installs rkmpm with CMake into a temporary prefix (build/install-test/prefix) and builds and runs
# the outside projects of tests/install/ against it, each program checking a small simulation:
#   CMake:      find_package(rkmpm CONFIG): C with rkmpm::rkmpm (librkmpm.a) and
#               rkmpm::rkmpm_shared (librkmpm.so), Fortran with rkmpm::fortran;
#   pkg-config: C and Fortran (rkmpm, rkmpm-fortran), each linked shared and static.
# Checks with readelf that the static programs do not need librkmpm.so and the shared ones do, and
# that the installed libraries carry no debug info.
#
#   scripts/test-install.sh [CARGO_TARGET_DIR]
#
# The cargo target directory (argument, or $RKMPM_CARGO_TARGET_DIR) lets the build reuse an
# existing `cargo build --release -p rkmpm-capi`; without it cargo builds into build/install-test/rkmpm/cargo.
# Needs cmake, cc, gfortran, pkg-config and readelf.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
cargo_target_dir=${1:-${RKMPM_CARGO_TARGET_DIR:-}}

for tool in cmake cc gfortran pkg-config readelf; do
  command -v "$tool" >/dev/null || { echo "test-install: $tool is missing" >&2; exit 1; }
done

work=$root/build/install-test
prefix=$work/prefix
rm -rf "$prefix" "$work/consumers"
mkdir -p "$work/consumers"
t0=$SECONDS

step() { echo "== $*"; }
fail() { echo "test-install: FAIL: $*" >&2; exit 1; }
# needs_librkmpm_so <program> yes|no
needs_librkmpm_so() {
  if readelf -d "$1" | grep -q 'NEEDED.*\[librkmpm\.so\]'; then
    [ "$2" = yes ] || fail "$1 needs librkmpm.so but should be linked statically"
  else
    [ "$2" = no ] || fail "$1 does not need librkmpm.so"
  fi
}
run() { echo "   \$ ${*#env }"; "$@" || fail "$* exited with $?"; }

# ---- build and install ---------------------------------------------------------------------------
# Configured with the default prefix and installed with --prefix: the package must not depend
# on the prefix given at configure time.
step "configure, build and install rkmpm into $prefix"
cmake_args=(-S . -B "$work/rkmpm" -DCMAKE_BUILD_TYPE=Release)
[ -n "$cargo_target_dir" ] && cmake_args+=(-DRKMPM_CARGO_TARGET_DIR="$cargo_target_dir")
cmake "${cmake_args[@]}" >/dev/null
cmake --build "$work/rkmpm" -j 2
cmake --install "$work/rkmpm" --prefix "$prefix" | sed 's/^/   /'

version=$(sed -n 's/^version *= *"\([^"]*\)".*/\1/p' Cargo.toml | head -n 1)
pcfile=$(find "$prefix" -name rkmpm.pc)
[ -n "$pcfile" ] || fail "no rkmpm.pc installed"
libdir=$(dirname "$(dirname "$pcfile")")
for f in "$libdir/librkmpm.a" "$libdir/librkmpm.so" "$libdir/librkmpm_fortran.a" \
         "$prefix/include/rkmpm.h" "$prefix/include/rkmpm/rkmpm.mod" \
         "$libdir/cmake/rkmpm/rkmpmConfig.cmake" "$libdir/cmake/rkmpm/rkmpmConfigVersion.cmake" \
         "$libdir/pkgconfig/rkmpm.pc" "$libdir/pkgconfig/rkmpm-fortran.pc"; do
  [ -f "$f" ] || fail "not installed: $f"
done
# Lean libraries: installed without debug info (RKMPM_INSTALL_DEBUG_INFO=OFF, the default).
for f in "$libdir/librkmpm.a" "$libdir/librkmpm.so"; do
  debug_sections=$(readelf -S -W "$f" | grep -c '\.debug_info' || true)
  [ "$debug_sections" = 0 ] || fail "$f still carries debug info ($debug_sections .debug_info sections)"
  echo "   $(basename "$f"): $(du -h "$f" | cut -f1), no debug info"
done
# And under a stated size (docs/INSTALL.md: 31 MB and 7.1 MB measured; the bounds leave 1.5x
# for a newer Rust standard library, which is most of the static one, and for rkmpm's growth;
# with debug info they are 131 MB and 61 MB, so a build that stops stripping fails here).
size_bound() {
  local size
  size=$(stat -c %s "$1")
  [ "$size" -le $(($2 * 1000 * 1000)) ] || fail "$1 is $size bytes, above the stated $2 MB"
}
size_bound "$libdir/librkmpm.a" 47
size_bound "$libdir/librkmpm.so" 11
grep -q "$root" "$libdir/cmake/rkmpm/rkmpmConfig.cmake" "$libdir/pkgconfig/"*.pc \
  && fail "an installed package file refers to the source or build tree"

# ---- CMake: find_package(rkmpm CONFIG) ----------------------------------------------------------
step "CMake consumers (find_package(rkmpm $version CONFIG REQUIRED))"
for lang in c fortran; do
  cmake -S "tests/install/$lang" -B "$work/consumers/cmake-$lang" -DCMAKE_PREFIX_PATH="$prefix" \
    -DRKMPM_REQUIRED_VERSION="$version" -DCMAKE_BUILD_TYPE=Release >/dev/null
  cmake --build "$work/consumers/cmake-$lang" -j 2 >/dev/null \
    || { cmake --build "$work/consumers/cmake-$lang"; fail "CMake $lang consumer does not build"; }
done
c=$work/consumers/cmake-c
needs_librkmpm_so "$c/app_static" no
needs_librkmpm_so "$c/app_shared" yes
echo "   C, rkmpm::rkmpm (static):"; run "$c/app_static"
echo "   C, rkmpm::rkmpm_shared (librkmpm.so found through the build rpath):"; run "$c/app_shared"
needs_librkmpm_so "$work/consumers/cmake-fortran/app" no
echo "   Fortran, rkmpm::fortran:"; run "$work/consumers/cmake-fortran/app"

# ---- pkg-config ------------------------------------------------------------------------------------
step "pkg-config consumers (PKG_CONFIG_PATH=$libdir/pkgconfig)"
export PKG_CONFIG_PATH=$libdir/pkgconfig
[ "$(pkg-config --modversion rkmpm)" = "$version" ] || fail "pkg-config --modversion rkmpm is not $version"
[ "$(pkg-config --modversion rkmpm-fortran)" = "$version" ] || fail "rkmpm-fortran version is not $version"
pc_libdir=$(pkg-config --variable=libdir rkmpm)
out=$work/consumers/pkg-config
mkdir -p "$out"
# Static: -Wl,-Bstatic makes -lrkmpm take librkmpm.a although librkmpm.so lies next to it; --static
# adds Libs.private (the system libraries the archive needs); --as-needed drops the second -lrkmpm.
static_c=(-Wl,-Bstatic $(pkg-config --libs rkmpm) -Wl,-Bdynamic -Wl,--as-needed $(pkg-config --static --libs rkmpm))
static_f=(-Wl,-Bstatic $(pkg-config --libs rkmpm-fortran) -Wl,-Bdynamic -Wl,--as-needed
          $(pkg-config --static --libs rkmpm-fortran))
set -x
cc tests/install/c/main.c -o "$out/c_shared" $(pkg-config --cflags --libs rkmpm) -lm -Wl,-rpath,"$pc_libdir"
cc tests/install/c/main.c -o "$out/c_static" $(pkg-config --cflags rkmpm) "${static_c[@]}"
gfortran tests/install/fortran/main.f90 -J "$out" -o "$out/f_shared" $(pkg-config --cflags --libs rkmpm-fortran)
gfortran tests/install/fortran/main.f90 -J "$out" -o "$out/f_static" $(pkg-config --cflags rkmpm-fortran) "${static_f[@]}"
{ set +x; } 2>/dev/null
needs_librkmpm_so "$out/c_shared" yes
needs_librkmpm_so "$out/c_static" no
needs_librkmpm_so "$out/f_shared" yes
needs_librkmpm_so "$out/f_static" no
echo "   C, shared (rpath):"; run "$out/c_shared"
echo "   C, static:"; run "$out/c_static"
echo "   Fortran, shared (LD_LIBRARY_PATH):"; run env LD_LIBRARY_PATH="$pc_libdir" "$out/f_shared"
echo "   Fortran, static:"; run "$out/f_static"

step "install test passed: 7 programs against $prefix ($((SECONDS - t0)) s)"
