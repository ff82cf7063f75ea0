#!/usr/bin/env bash
# The main job: the paper's Table 2 box (Fig. 8: 10 x 10 x 10 molecules, 7560 connections, 1000 N on 1 m^2,
# E = 100 kPa) on every core with mpirun, printing the measured Young's modulus against the target.
#
#   bash run_scripts/main_job.sh            # installs what is missing, builds, runs
#   bash run_scripts/main_job.sh --set calibration.method=divided --set calibration.divisor=3.75
set -euo pipefail
cd "$(dirname "$0")/.."
# 1. Install and build.
bash run_scripts/build.sh
# 2. Run on all cores (as root Open MPI needs these two variables).
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
mpirun --oversubscribe -np "$(nproc)" build/tissue run run_scripts/scenes/table2.toml "$@"
# 3. Where the results are.
echo "summary: out/table2/summary.json; final state: out/table2/final.h5 (open out/table2/tissue.xdmf in ParaView)"
