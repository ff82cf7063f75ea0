#!/usr/bin/env bash
# The stability matrix (docs/stability.md): every solver at the extremes of E, density, molecule count, aspect
# ratio, stiffness ratio, time step and strain; writes docs/stability.csv and docs/stability-table.md.
#   bash run_scripts/stability.sh            # the matrix up to 40^3 molecules
#   bash run_scripts/stability.sh --big      # and the 60^3 and 100^3 (10^6 molecules) cells: hours on 2 cores
#   bash run_scripts/stability.sh --big-only # only the 60^3 and 100^3 cells (dynamic 60^3, dynamic and static
#                                            # 100^3), into docs/stability-big.csv and docs/stability-big-table.md
# With --big or --big-only the runs hold `flock /tmp/tissue-bigmem.lock` (the 10^6-molecule static solve needs
# ~13 GB on one rank: one such job at a time on a shared machine).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${BUILD:-build}
[ -x "$BUILD/tissue" ] || bash run_scripts/build.sh tissue
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
csv=docs/stability.csv md=docs/stability-table.md lock=()
for a in "$@"; do
  case $a in
    --big) lock=(flock /tmp/tissue-bigmem.lock) ;;
    --big-only) lock=(flock /tmp/tissue-bigmem.lock); csv=docs/stability-big.csv md=docs/stability-big-table.md ;;
  esac
done
args=("$@")
[[ " ${args[*]} " == *" --big-only "* ]] && args+=(--big)
"${lock[@]}" python3 tests/stability_test.py --build "$BUILD" --source . --full "${args[@]}" --csv "$csv" --md "$md"
