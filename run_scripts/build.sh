#!/usr/bin/env bash
# Installs what is missing and builds tissue into build/ (Release).
#
#   bash run_scripts/build.sh                # everything: the program and every test (what test.sh runs)
#   bash run_scripts/build.sh tissue [...]   # only the listed targets, tests not configured (what main_job.sh runs)
#
# With targets the build is configured with -DTISSUE_TESTS=OFF, without them with -DTISSUE_TESTS=ON;
# TISSUE_TESTS=ON|OFF in the environment overrides that (e.g. to build one test target). Output goes to build.log,
# which is shown (its end) only when something fails.
set -euo pipefail
cd "$(dirname "$0")/.."
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then tests=${TISSUE_TESTS:-ON}; else tests=${TISSUE_TESTS:-OFF}; fi
target_args=()
for t in "${targets[@]}"; do target_args+=(--target "$t"); done
bash run_scripts/install_deps.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DTISSUE_TESTS="$tests" > build.log 2>&1 || { cat build.log; exit 1; }
cmake --build build -j"$(nproc)" "${target_args[@]}" >> build.log 2>&1 || { tail -50 build.log; exit 1; }
rm -f build.log
