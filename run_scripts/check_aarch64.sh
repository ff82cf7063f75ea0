#!/usr/bin/env bash
#                 tissue: does the source compile for aarch64 (a cluster of ARM nodes)?
#
# What it checks: every C++ file of the program (src/, partition/, io/) compiled to an object by Debian's aarch64
# cross compiler, with the warnings the build uses. The x86-64 specifics (the AVX-512 / AVX2 clones of
# src/vector_clones.hpp, the AVX-512 kick of src/solvers/dynamic.cpp) must compile away there. This machine's
# x86-64 PETSc, MPI and HDF5 headers stand in for aarch64's (they are the same but for PETSc's configuration,
# whose x86 `#include <xmmintrin.h>` an empty header answers here); nothing is linked or run.
# Prints one line a file that fails and a count; exit 1 if any fails.
#
# How to run (from the repository root, after a native build has generated build/generated; ~3 minutes):
#   apt-get install -y g++-aarch64-linux-gnu
#   bash run_scripts/check_aarch64.sh
# Knobs (environment): CXX_AARCH64 (default aarch64-linux-gnu-g++), JOBS (default: the cores).
#
# Steps: 1. the compiler and the include directories; 2. each file compiled, JOBS at a time; 3. the count.
set -euo pipefail
cd "$(dirname "$0")/.."

# 1. The compiler, and the include directories of the native build (its compile_commands.json would do as well).
CXX_AARCH64=${CXX_AARCH64:-aarch64-linux-gnu-g++}
if ! command -v "$CXX_AARCH64" >/dev/null; then
  echo "check_aarch64: $CXX_AARCH64 not found (apt-get install -y g++-aarch64-linux-gnu)" >&2
  exit 1
fi
if [[ ! -d build/generated ]]; then
  echo "check_aarch64: build/generated missing: build natively first (bash run_scripts/build.sh tissue)" >&2
  exit 1
fi
shim=$(mktemp -d)
trap 'rm -rf "$shim"' EXIT
: > "$shim/xmmintrin.h"
petsc=$(pkg-config --variable=includedir PETSc 2>/dev/null ||
        echo /usr/lib/petscdir/petsc3.18/x86_64-linux-gnu-real/include)
flags=(-std=gnu++17 -O1 -Wall -Wextra -Wno-unused-parameter -fno-math-errno -ffp-contract=off -DFMT_SHARED
       '-DTISSUE_VERSION="aarch64-check"' '-DTISSUE_GMSH_MODULE="libtissue_gmsh.so"'
       -I. -Ibuild/generated -isystem /usr/lib/x86_64-linux-gnu/openmpi/include
       -isystem /usr/lib/x86_64-linux-gnu/openmpi/include/openmpi -isystem "$petsc"
       -isystem /usr/include/hdf5/openmpi -isystem /usr/include/eigen3 -isystem "$shim")

# 2. Every file, JOBS at a time; a failure's first error line kept.
export CXX_AARCH64 shim
printf '%s\0' "${flags[@]}" > "$shim/flags"
compile() {
  local f=$1 log
  log=$(mktemp)
  mapfile -d '' flags < "$shim/flags"
  if "$CXX_AARCH64" "${flags[@]}" -c -o /dev/null "$f" > "$log" 2>&1; then rm -f "$log"; return 0; fi
  echo "FAIL $f: $(grep -m1 'error' "$log")"
  rm -f "$log"
  return 1
}
export -f compile
files=$(git ls-files 'src/*.cpp' 'partition/*.cpp' 'io/*.cpp')
failed=0
printf '%s\n' $files | xargs -P "${JOBS:-$(nproc)}" -I{} bash -c 'compile {}' || failed=1

# 3. The count.
n=$(printf '%s\n' $files | wc -l)
if [[ $failed != 0 ]]; then
  echo "check_aarch64: failures above (of $n files)"
  exit 1
fi
echo "check_aarch64: $n files compile for aarch64"
