#!/usr/bin/env bash
# Installs what is missing, builds, and runs every test (ctest: GoogleTest at 1, 2 and 3 ranks, and python
# tests reading our files with h5py and meshio), then the fuzzers for a bounded time.
#
#   bash run_scripts/test.sh [CTEST ARGS]
# TISSUE_FUZZ_SECONDS (default 30): seconds per libFuzzer target (fuzz_scene, fuzz_scene_set, fuzz_checkpoint),
# each seeded with the committed corpus (tests/fuzz_regressions, run_scripts/scenes, tests/bad_scenes); a crash,
# an AddressSanitizer report or a unit slower than 10 s fails the run (exit 1, the input is in out/fuzz/TARGET/). The targets
# are built with clang-14 in build-fuzz (install_deps.sh installs clang-14 and libclang-rt-14-dev); the first
# build takes a few minutes, later ones only what changed. 0 skips the fuzzing.
set -euo pipefail
cd "$(dirname "$0")/.."
bash run_scripts/build.sh   # no targets: the program and every test (TISSUE_TESTS=ON)
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
(cd build && ctest --output-on-failure -j2 "$@")
FUZZ_SECONDS=${TISSUE_FUZZ_SECONDS:-30}
if [ "$FUZZ_SECONDS" != 0 ]; then
  bash run_scripts/fuzz.sh "$FUZZ_SECONDS"
fi
