#!/usr/bin/env bash
#                 tissue: what the per-step guards cost (src/solvers/guards.cpp, issue #8)
#
# What it measures: the dynamic solver (the guard's most frequent work: one MPI_Allreduce of the kinetic energy
# every step, the full check every 128 steps, the energy check at each kinetic-energy doubling) and the relaxation
# solver (the full check every 128 iterations; the residual it reads is reduced by the solver anyway) on an
# N x N x N Table 2 style lattice (face diagonals, 100 kPa, 1000 N on z-), guarded and unguarded
# (-tissue_guards false, the benchmark-only switch in PETSc's options: src/solvers/guards.hpp), alternately, REPEAT pairs per solver and
# rank count. Time = summary.json solver.seconds (wall time of the solve alone, no set-up or output; fields = []
# writes no snapshot) and solver.cpu_seconds (rank 0's CPU time over the same span: far less sensitive to other
# jobs on the machine than wall time, but it also counts MPI's busy waiting). The guards do not change the
# trajectory (they only read the state), so both runs do the same steps; solver.guard_checks counts the full checks
# and solver.guard_seconds is the wall time spent inside the guard's calls (timed in the run itself, so a busy
# machine slows the guard and the steps alike: the third, least noisy measure, guard_seconds / seconds).
# Reported: per-step time of each, and the overhead = median over pairs of (guarded / unguarded - 1), with the
# smallest and largest pair (the spread is the machine's noise: other jobs share its cores).
# Output: docs/bench_guards.csv (one row per run) and a Markdown table on stdout.
#
# How to run (from the repository root; with N = 40 about a minute a run at load average 12-16 on 2 cores; the
# defaults, N = 60 and 5 pairs, are meant for a quieter machine: 40 runs):
#   cmake -S . -B build -DCMAKE_BUILD_TYPE=Release && cmake --build build -j2 --target tissue
#   run_scripts/bench_guards.sh
# Knobs (environment): TISSUE (default build/tissue), N (default 60), STEPS (dynamic steps, default 500),
# RELAX_ITERATIONS (relaxation: solver.max_iterations, default 500; the run stops there unconverged, exit 3, which
# is what is timed), NPS (rank counts, default "1 2"), REPEAT (pairs, default 5), SOLVERS (default
# "dynamic relaxation"), WORK (default /tmp/tissue_bench_guards), CSV (default docs/bench_guards.csv).
#
# Steps:
#   1. Settings and checks.
#   2. For every solver, rank count and repetition: guarded, then unguarded (the order alternates every pair).
#   3. The table.
set -euo pipefail
cd "$(dirname "$0")/.."

# 1. Settings and checks.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
TISSUE=${TISSUE:-build/tissue}
N=${N:-60}
STEPS=${STEPS:-500}
RELAX_ITERATIONS=${RELAX_ITERATIONS:-500}
NPS=${NPS:-"1 2"}
REPEAT=${REPEAT:-5}
SOLVERS=${SOLVERS:-"dynamic relaxation"}
WORK=${WORK:-/tmp/tissue_bench_guards}
CSV=${CSV:-docs/bench_guards.csv}
[ -x "$TISSUE" ] || { echo "bench_guards.sh: no binary $TISSUE (build it, see the header)" >&2; exit 1; }
mkdir -p "$WORK" "$(dirname "$CSV")"
echo "solver,ranks,pair,guards,molecules,connections,steps,guard_checks,guard_seconds,solve_seconds,seconds_per_step,cpu_seconds,cpu_seconds_per_step,exit_code" >"$CSV"

# 2. The runs.
run() {  # solver ranks pair guards(on|off)
  local solver=$1 np=$2 pair=$3 guards=$4 dir=$WORK/$1/np$2/$3/$4 rc=0
  rm -rf "$dir"; mkdir -p "$dir"
  local sets=(--set "body.molecules=[$N,$N,$N]" --set "solver.kind=$solver" --set output.progress=false
              --set 'output.fields=[]')
  if [ "$solver" = dynamic ]; then sets+=(--set "solver.steps=$STEPS"); else
    sets+=(--set "solver.max_iterations=$RELAX_ITERATIONS" --set solver.tolerance=1e-14); fi
  mpirun -np "$np" "$TISSUE" run run_scripts/scenes/table2.toml "${sets[@]}" \
    --output "$dir/out" -- -tissue_guards "$([ "$guards" = on ] && echo true || echo false)" >"$dir/log" 2>&1 || rc=$?
  /usr/bin/python3 - "$dir/out/summary.json" "$solver" "$np" "$pair" "$guards" "$rc" >>"$CSV" <<'PY'
import json, sys
path, solver, np_, pair, guards, rc = sys.argv[1:]
j = json.load(open(path))
steps = j["solver"]["iterations"]
s = j["solver"]
print(",".join(str(x) for x in (solver, np_, pair, guards, j["molecules"], j["connections"], steps, s["guard_checks"],
                                repr(s["guard_seconds"]),
                                repr(s["seconds"]), repr(s["seconds"] / steps), repr(s["cpu_seconds"]),
                                repr(s["cpu_seconds"] / steps), rc)))
PY
  printf '%-10s np=%s pair %s guards %-3s rc=%s %s\n' "$solver" "$np" "$pair" "$guards" "$rc" "$(tail -1 "$CSV" | cut -d, -f11,13)"
}
for solver in $SOLVERS; do
  for np in $NPS; do
    for pair in $(seq 1 "$REPEAT"); do
      if [ $((pair % 2)) = 1 ]; then run "$solver" "$np" "$pair" on; run "$solver" "$np" "$pair" off
      else run "$solver" "$np" "$pair" off; run "$solver" "$np" "$pair" on; fi
    done
  done
done

# 3. The table.
/usr/bin/python3 - "$CSV" <<'PY'
import csv, statistics, sys
rows = list(csv.DictReader(open(sys.argv[1])))
pairs_n = max(int(r["pair"]) for r in rows)
print("| solver | ranks | molecules | steps | full checks | measure | per step guarded (median) | unguarded (median) "
      "| overhead: median [min, max] over %d pairs |" % pairs_n)
print("|---|---|---|---|---|---|---|---|---|")
for key in sorted({(r["solver"], r["ranks"]) for r in rows}):
    mine = [r for r in rows if (r["solver"], r["ranks"]) == key]
    checks = sorted({r["guard_checks"] for r in mine if r["guards"] == "on"})
    for column, label in (("cpu_seconds_per_step", "CPU s"), ("seconds_per_step", "wall s")):
        by = {(r["pair"], r["guards"]): float(r[column]) for r in mine}
        pairs = sorted({r["pair"] for r in mine})
        both = [p for p in pairs if (p, "on") in by and (p, "off") in by]
        ratios = [by[(p, "on")] / by[(p, "off")] - 1 for p in both]
        on = statistics.median(by[(p, "on")] for p in both)
        off = statistics.median(by[(p, "off")] for p in both)
        print("| %s | %s | %s | %s | %s | %s | %.4g | %.4g | %+.2f %% [%+.2f, %+.2f] |" % (
            key[0], key[1], mine[0]["molecules"], mine[0]["steps"], "/".join(checks), label, on, off,
            100 * statistics.median(ratios), 100 * min(ratios), 100 * max(ratios)))
    share = [float(r["guard_seconds"]) / float(r["solve_seconds"]) for r in mine if r["guards"] == "on"]
    print("| %s | %s | %s | %s | %s | time inside the guards / solve time (guarded runs) | | | %.2f %% [%.2f, %.2f] |" % (
        key[0], key[1], mine[0]["molecules"], mine[0]["steps"], "/".join(checks), 100 * statistics.median(share),
        100 * min(share), 100 * max(share)))
PY
