#!/usr/bin/env bash
# The stability matrix (docs/stability.md): every solver at the extremes of E, density, molecule count, aspect
# ratio, stiffness ratio, time step and strain; writes docs/stability.csv and docs/stability-table.md.
#   bash run_scripts/stability.sh            # the matrix up to 40^3 molecules
#   bash run_scripts/stability.sh --big      # and the 60^3 and 100^3 (10^6 molecules) cells: hours on 2 cores
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
[ -x "$BUILD/tissue" ] || bash run_scripts/build.sh
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
python3 tests/stability_test.py --build "$BUILD" --source . --full "$@" \
  --csv docs/stability.csv --md docs/stability-table.md
