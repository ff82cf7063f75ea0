#!/usr/bin/env bash
# Installs what is missing and builds tissue into build/ (Release). Used by main_job.sh and test.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
bash run_scripts/install_deps.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release > build.log 2>&1 || { cat build.log; exit 1; }
cmake --build build -j"$(nproc)" >> build.log 2>&1 || { tail -50 build.log; exit 1; }
rm -f build.log
