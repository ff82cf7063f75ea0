#!/usr/bin/env bash
# Preconditioner reuse across quasi-static time steps: a stress-relaxation test (run_scripts/scenes/
# example_cartilage_relaxation.toml at N^3 molecules, a 2 % step compression held) solved for its t = 0 step alone
# (a fresh Newton solve: set-up, multigrid, solve) and for STEPS more steps; prints the fresh step's seconds, the
# mean seconds of a later step and their ratio (issue 16 asks <= 0.3 at 10^6 molecules), from summary.json's
# solver.seconds.
#   bash run_scripts/bench_quasi_static.sh [N] [NP] [STEPS]     # defaults 40, 2, 10
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
N="${1:-40}"
NP="${2:-2}"
STEPS="${3:-10}"
cd "$ROOT"
[ -x build/tissue ] || bash run_scripts/build.sh tissue
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
out="$ROOT/out/bench_quasi_static"
rm -rf "$out" && mkdir -p "$out"
run() {  # $1: name, $2: end time (s)
  mpirun --oversubscribe -np "$NP" build/tissue run run_scripts/scenes/example_cartilage_relaxation.toml \
    --set "body.molecules=[$N,$N,$N]" --set 'fix.1.history=[[0.0,1.0]]' --set solver.time_step=1.0 \
    --set "solver.end_time=$2" --set output.progress=false --output "$out/$1" > "$out/$1.log"
}
run fresh 0
run steps "$STEPS"
/usr/bin/python3 - "$out" "$STEPS" "$N" "$NP" <<'PY'
import json, sys
out, steps, n, np_ = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
fresh = json.load(open(f"{out}/fresh/summary.json"))["solver"]
more = json.load(open(f"{out}/steps/summary.json"))["solver"]
per_step = (more["seconds"] - fresh["seconds"]) / steps
print(f"{n}^3 molecules, {np_} ranks: fresh step {fresh['seconds']:.3f} s ({fresh['iterations']} Newton, "
      f"{fresh['linear_iterations']} Krylov); later steps {per_step:.3f} s each over {steps} "
      f"({more['iterations'] - fresh['iterations']} Newton, {more['linear_iterations'] - fresh['linear_iterations']} "
      f"Krylov in all); ratio {per_step / fresh['seconds']:.2f}")
PY
