#!/usr/bin/env bash
# Installs what is missing, builds, and runs every test (ctest: GoogleTest at 1, 2 and 3 ranks, and python
# tests reading our files with h5py and meshio).
set -euo pipefail
cd "$(dirname "$0")/.."
bash run_scripts/build.sh
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
cd build && ctest --output-on-failure -j2 "$@"
