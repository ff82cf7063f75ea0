#!/usr/bin/env bash
# The cost of history.csv rows in a dynamic run (issue 16): the LAMMPS peer's lattice (run_scripts/scenes/
# peer_lattice.toml, N^3 molecules, face diagonals) with its bottom clamped and a load on its top, so that every row
# measures an elongation and a reaction, run STEPS steps with a row every step (output.history_every = 1) and with
# rows at the first and last steps only (history_every = STEPS), REPEAT times each, alternately; prints the
# stepping seconds of each (summary.json solver.seconds, the solve alone) and the cost of a row relative to a step.
#   bash run_scripts/bench_history.sh [N] [NP] [STEPS] [REPEAT]     # defaults 50, 2, 400, 2
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
N="${1:-50}"
NP="${2:-2}"
STEPS="${3:-400}"
REPEAT="${4:-2}"
cd "$ROOT"
[ -x build/tissue ] || bash run_scripts/build.sh tissue
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
out="$ROOT/out/bench_history"
rm -rf "$out" && mkdir -p "$out"
run() {  # $1: name, $2: history_every
  mpirun --oversubscribe -np "$NP" build/tissue run run_scripts/scenes/peer_lattice.toml \
    --set "body.molecules=[$N,$N,$N]" --set "solver.steps=$STEPS" --set "output.history_every=$2" \
    --set 'fix=[{face="z-",mode="clamped"}]' --set 'load=[{face="z+",force=[0.0,0.0,1.0]}]' \
    --output "$out/$1" > "$out/$1.log"
}
for r in $(seq "$REPEAT"); do
  run "every_$r" 1
  run "ends_$r" "$STEPS"
done
/usr/bin/python3 - "$out" "$STEPS" "$N" "$NP" "$REPEAT" <<'PY'
import json, sys
out, steps, n, np_, repeat = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4], int(sys.argv[5])
sec = lambda name: json.load(open(f"{out}/{name}/summary.json"))["solver"]["seconds"]
rows = lambda name: sum(1 for _ in open(f"{out}/{name}/history.csv")) - 1
every = [sec(f"every_{r}") for r in range(1, repeat + 1)]
ends = [sec(f"ends_{r}") for r in range(1, repeat + 1)]
e, b = min(every), min(ends)
print(f"{n}^3 molecules, {np_} ranks, {steps} steps: rows every step {e:.3f} s ({rows('every_1')} rows), "
      f"rows at the ends {b:.3f} s ({rows('ends_1')} rows) (best of {repeat}: {every} / {ends}); "
      f"a row costs {(e - b) / (steps - 1) / (b / steps):.3f} of a step")
PY
