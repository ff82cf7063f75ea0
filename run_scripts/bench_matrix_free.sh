#!/usr/bin/env bash
# The matrix-free static solver against the assembled one (issue 18, items 1-2): the LAMMPS peer's tension test
# (run_scripts/scenes/peer_tension.toml, face diagonals, z+ clamped, 0.001 N^2 on z-) at N^3 molecules, solved
# to a relative residual of 1e-8 with solver.operator = "assembled" and "matrix-free", alternating, on NP ranks.
# One CSV row per run: wall seconds (summary.json wall_seconds), solver seconds, peak bytes per molecule
# (summary.json's peak_memory_bytes, the largest rank's, times the ranks over the molecules: as speed_accuracy.sh),
# Newton and Krylov iterations, elongation, and the load average. Appends to docs/bench_matrix_free.csv.
#   NS="46 100" NP=2 bash run_scripts/bench_matrix_free.sh
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
NS="${NS:-46 100}"
NP="${NP:-2}"
cd "$ROOT"
[ -x build/tissue ] || bash run_scripts/build.sh tissue
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
out="$ROOT/out/bench_matrix_free"
mkdir -p "$out"
CSV="${CSV:-$ROOT/docs/bench_matrix_free.csv}"
[ -f "$CSV" ] || echo "date,N,molecules,ranks,operator,wall_s,solver_s,peak_bytes,bytes_per_molecule,newton_its,krylov_its,residual,elongation,loadavg" > "$CSV"
for n in $NS; do
  for op in assembled matrix-free; do
    dir="$out/${n}_${op}"
    rm -rf "$dir"
    load=$(awk '{print $1}' /proc/loadavg)
    mpirun --oversubscribe -np "$NP" build/tissue run run_scripts/scenes/peer_tension.toml \
      --set "body.molecules=[$n,$n,$n]" --set "load.0.force=[0,0,-$(python3 -c "print(0.001*$n*$n)")]" \
      --set solver.tolerance=1e-8 --set "solver.operator=$op" --set 'output.fields=[]' --set output.progress=false \
      --output "$dir" > "$dir.log" 2>&1
    /usr/bin/python3 - "$dir/summary.json" "$n" "$op" "$load" >> "$CSV" <<'PY'
import datetime, json, sys
d = json.load(open(sys.argv[1]))
s = d["solver"]
m = d["molecules"]
print(",".join(str(v) for v in [datetime.datetime.utcnow().strftime("%Y-%m-%dT%H:%M"), sys.argv[2], m, d["ranks"], sys.argv[3],
      d["wall_seconds"], s["seconds"], d["peak_memory_bytes"], round(d["peak_memory_bytes"] * d["ranks"] / m),
      s["iterations"], s["linear_iterations"], s["residual"], d["elongation"], sys.argv[4]]))
PY
    tail -n 1 "$CSV"
  done
done
