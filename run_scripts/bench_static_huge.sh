#!/usr/bin/env bash
# Issue 18's largest static run: the LAMMPS peer's tension test (run_scripts/scenes/peer_tension.toml, face
# diagonals, z+ clamped, 0.001 N^2 on z-) at N^3 molecules on NP ranks, solved to a relative residual of 1e-8 with
# solver.operator = "matrix-free". N = 272 is 2.01e7 molecules (issue 18's done-when: it completes on 2 ranks);
# it needs about 20 GB, so the script refuses to start when `free` shows less than an estimate of 1.25 kB a
# molecule (FORCE=1 starts anyway). One CSV row per run: wall seconds, solver seconds, set-up seconds (wall minus
# solver: model build, partition, first touch, the summary), each rank's peak resident memory (run_scripts/
# peak_rss.py, wait4's ru_maxrss, kB) and the largest times the ranks over the molecules (B a molecule),
# summary.json's peak_memory_bytes, Newton and Krylov iterations, the residual, the elongation and the load average.
# Appends to docs/bench_static_huge.csv.
#   NS="100 150" NP=2 bash run_scripts/bench_static_huge.sh     # checks; the issue's run: NS=272
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
NS="${NS:-272}"
NP="${NP:-2}"
cd "$ROOT"
[ -x build/tissue ] || bash run_scripts/build.sh tissue
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
out="$ROOT/out/bench_static_huge"
mkdir -p "$out"
CSV="${CSV:-$ROOT/docs/bench_static_huge.csv}"
[ -f "$CSV" ] || echo "date,N,molecules,ranks,wall_s,solver_s,setup_s,rank_peak_kB,bytes_per_molecule,summary_peak_bytes,newton_its,krylov_its,residual,elongation,loadavg" > "$CSV"
for n in $NS; do
  need_kb=$(( n * n * n * 5 / 4 ))  # 1.25 kB a molecule
  avail_kb=$(awk '/MemAvailable/{print $2}' /proc/meminfo)
  if [ "${FORCE:-0}" != 1 ] && [ "$avail_kb" -lt "$need_kb" ]; then
    echo "bench_static_huge.sh: N = $n needs about $((need_kb / 1048576)) GB, $((avail_kb / 1048576)) GB available: skipped" >&2
    continue
  fi
  dir="$out/$n"
  rm -rf "$dir" "$dir".rss.rank*
  load=$(awk '{print $1}' /proc/loadavg)
  mpirun --oversubscribe -np "$NP" python3 run_scripts/peak_rss.py "$dir.rss" build/tissue run \
    run_scripts/scenes/peer_tension.toml --set "body.molecules=[$n,$n,$n]" \
    --set "load.0.force=[0,0,-$(python3 -c "print(0.001*$n*$n)")]" --set solver.tolerance=1e-8 \
    --set solver.operator=matrix-free --set 'output.fields=[]' --set output.progress=false \
    --output "$dir" > "$dir.log" 2>&1
  /usr/bin/python3 - "$dir" "$n" "$NP" "$load" >> "$CSV" <<'PY'
import datetime, json, sys
d = json.load(open(sys.argv[1] + "/summary.json"))
s = d["solver"]
m = d["molecules"]
ranks = int(sys.argv[3])
peaks = [int(open(f"{sys.argv[1]}.rss.rank{r}").read().split()[2]) for r in range(ranks)]
print(",".join(str(v) for v in [datetime.datetime.utcnow().strftime("%Y-%m-%dT%H:%M"), sys.argv[2], m, d["ranks"],
      d["wall_seconds"], s["seconds"], round(d["wall_seconds"] - s["seconds"], 3), "/".join(map(str, peaks)),
      round(max(peaks) * 1024 * ranks / m), d["peak_memory_bytes"], s["iterations"], s["linear_iterations"],
      s["residual"], d["elongation"], sys.argv[4]]))
PY
  tail -n 1 "$CSV"
done
