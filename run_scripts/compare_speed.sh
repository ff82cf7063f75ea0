#!/usr/bin/env bash
#                 tissue: two binaries, the same measurements, alternating: the speed ratio new / old
#
# What it measures: the measurements of run_scripts/bench_explicit.sh and run_scripts/speed_accuracy.sh (without
# LAMMPS), each made with the OLD and the NEW binary in turn, REPEAT times, the order swapped every repetition (old
# new, new old, old new, ...) so that a machine that speeds up or slows down during the run favours neither:
#   explicit_np1, explicit_np2   bench_explicit.sh's: the LAMMPS peer's throughput lattice
#                                (run_scripts/scenes/peer_lattice.toml, EXPLICIT_N^3 molecules, face diagonals, velocity
#                                Verlet) run with solver.steps = 200 and with solver.steps = 0; the time is
#                                wall(200) - wall(0) (summary.json wall_seconds: the stepping alone), also as steps/s
#   static_npR                   speed_accuracy.sh's: the peer's tension test (run_scripts/scenes/peer_tension.toml,
#                                STATIC_N^3 molecules, load 0.001 N^2) with the static solver (Newton, CG + the lattice
#                                multigrid) to 1e-8 on RANKS ranks; the time is wall_seconds (the whole run)
#   relaxation_npR               the same test with the FIRE relaxation solver to RELAX_TOL
# For each measurement it prints the median time of each binary over the repetitions, the ratio new / old of the
# medians (< 1: NEW is faster), the smallest and largest ratio of the pairs run back to back, the ratio of the peak
# memory (summary.json peak_memory_bytes, the largest rank's), and whether the two binaries did the same work (the
# same solver iterations). Every run's row is in $WORK/speed.csv. The guards follow TISSUE_GUARDS in the
# environment as in bench_explicit.sh (default on; TISSUE_GUARDS=off for the LAMMPS-comparable numbers: the script
# then also sets PETSC_OPTIONS=-tissue_guards false, the switch of binaries from 2026-12-01 on).
# On a shared machine the ratios of the medians are what to read; run it when the machine is otherwise idle. The
# same code against itself at load average 7 on 2 cores (2026-12-01, 2 min 51 s with the defaults) gave medians
# within 0.997-1.074 of each other but single pairs from 0.62 to 1.69: at such a load use REPEAT=5 or more, and
# read nothing into a ratio within 10 % of 1.
#
# Sample runs (from the repository root; about 3 minutes with the defaults):
#   BASE=main run_scripts/compare_speed.sh                      # OLD built from `main` as compare_binaries.sh does
#   run_scripts/compare_speed.sh /tmp/old/tissue build/tissue
#   REPEAT=5 EXPLICIT_N=100 STATIC_N=64 run_scripts/compare_speed.sh OLD NEW      # the docs' sizes (about 15 min)
#   MEASUREMENTS='static_np2 relaxation_np2' run_scripts/compare_speed.sh OLD NEW
# Knobs (environment): OLD, NEW, BASE (as run_scripts/compare_binaries.sh: the arguments win; NEW defaults to
# build/tissue; BASE builds OLD in out/compare/base-<sha> once), REPEAT (default 3), EXPLICIT_N (default 50),
# STATIC_N (default 40), RELAX_TOL (default 1e-8), RANKS (static and relaxation, default 2), MEASUREMENTS (default
# "explicit_np1 explicit_np2 static_npR relaxation_npR" with R = RANKS), WORK (default out/compare_speed),
# PYTHON (default /usr/bin/python3).
#
# Steps:
#   1. Settings and the binaries (compare_binaries.sh with SCENES=none builds OLD from BASE).
#   2. REPEAT rounds; in each, every measurement with both binaries, the order alternating; a CSV row per run.
#   3. The table: medians, ratios new / old, memory, same work.
set -euo pipefail
# Binaries from 2026-12-01 on read the guards' switch from PETSc's options; older ones read TISSUE_GUARDS itself.
if [ "${TISSUE_GUARDS:-on}" = off ]; then export PETSC_OPTIONS="${PETSC_OPTIONS:-} -tissue_guards false"; fi
# Binaries given as arguments or in OLD, NEW are relative to the directory this was started in; the rest to the root.
abs() { if [[ -z "$1" || "$1" == /* ]]; then echo "$1"; else echo "$PWD/$1"; fi; }
OLD_GIVEN=$(abs "${1:-${OLD:-}}"); NEW_GIVEN=$(abs "${2:-${NEW:-}}")
cd "$(dirname "$0")/.."

# 1. Settings and binaries.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
PYTHON=${PYTHON:-/usr/bin/python3}
WORK=${WORK:-out/compare_speed}
REPEAT=${REPEAT:-3}
EXPLICIT_N=${EXPLICIT_N:-50}
STATIC_N=${STATIC_N:-40}
RELAX_TOL=${RELAX_TOL:-1e-8}
RANKS=${RANKS:-2}
MEASUREMENTS=${MEASUREMENTS:-"explicit_np1 explicit_np2 static_np$RANKS relaxation_np$RANKS"}
STEPS=200
bins=$(SCENES=none OLD=$OLD_GIVEN NEW=${NEW_GIVEN:-build/tissue} run_scripts/compare_binaries.sh) || exit 2
OLD=$(sed -n 's/^OLD //p' <<< "$bins"); NEW=$(sed -n 's/^NEW //p' <<< "$bins")
echo "OLD $OLD"
echo "NEW $NEW"
mkdir -p "$WORK"
CSV=$WORK/speed.csv
echo "measurement,binary,round,ranks,N,time_s,wall_s,wall0_s,steps_per_s,peak_bytes,iterations,linear_iterations,loadavg" > "$CSV"

# tissue BINARY NP DIR ARGS...: one run (exit code 0 required), its summary in DIR.
tissue() {
  local bin=$1 np=$2 dir=$3; shift 3
  rm -rf "$dir"
  mpirun --oversubscribe -np "$np" "$bin" run "$@" --set 'output.fields=[]' --set output.progress=false \
    --output "$dir" > "$dir.log" 2>&1 || { echo "compare_speed: run failed, see $dir.log" >&2; exit 1; }
}
# row MEASUREMENT WHICH ROUND NP N DIR [DIR0]: one CSV row from DIR/summary.json (and DIR0's for the explicit one).
row() {
  "$PYTHON" - "$@" >> "$CSV" <<'EOF'
import json, sys
m, which, rnd, np, n, d = sys.argv[1:7]
s = json.load(open(d + "/summary.json"))
wall = s["wall_seconds"]
wall0 = json.load(open(sys.argv[7] + "/summary.json"))["wall_seconds"] if len(sys.argv) > 7 else ""
t = wall - wall0 if wall0 != "" else wall
rate = 200 / t if wall0 != "" and t > 0 else ""
load = open("/proc/loadavg").read().split()[0]
print(",".join(str(v) for v in [m, which, rnd, np, n, round(t, 6), wall, wall0, rate, s["peak_memory_bytes"],
      s["solver"]["iterations"], s["solver"].get("linear_iterations") or "", load]))
EOF
}
# measure MEASUREMENT WHICH BINARY ROUND
measure() {
  local m=$1 which=$2 bin=$3 rnd=$4 np=${1##*_np} d=$WORK/$1-$2-$4 n force
  case $m in
    explicit_np*)
      n=$EXPLICIT_N
      tissue "$bin" "$np" "$d" run_scripts/scenes/peer_lattice.toml --set "body.molecules=[$n,$n,$n]" --set "solver.steps=$STEPS"
      tissue "$bin" "$np" "$d-0" run_scripts/scenes/peer_lattice.toml --set "body.molecules=[$n,$n,$n]" --set solver.steps=0
      row "$m" "$which" "$rnd" "$np" "$n" "$d" "$d-0" ;;
    static_np*|relaxation_np*)
      n=$STATIC_N; force=$("$PYTHON" -c "print(0.001*$n*$n)")
      local kind=static tol=1e-8
      [[ $m == relaxation_* ]] && kind=relaxation tol=$RELAX_TOL
      tissue "$bin" "$np" "$d" run_scripts/scenes/peer_tension.toml --set "body.molecules=[$n,$n,$n]" \
        --set "load.0.force=[0,0,-$force]" --set "solver.kind=$kind" --set "solver.tolerance=$tol"
      row "$m" "$which" "$rnd" "$np" "$n" "$d" ;;
    *) echo "compare_speed: unknown measurement $m" >&2; exit 2 ;;
  esac
  tail -n 1 "$CSV" | awk -F, '{printf "  %-16s %-3s round %s: %8.3f s  (load %s)\n", $1, $2, $3, $6, $13}'
}

# 2. The rounds, alternating.
START=$(date +%s)
for rnd in $(seq "$REPEAT"); do
  echo "round $rnd of $REPEAT"
  for m in $MEASUREMENTS; do
    if (( rnd % 2 )); then measure "$m" old "$OLD" "$rnd"; measure "$m" new "$NEW" "$rnd"
    else measure "$m" new "$NEW" "$rnd"; measure "$m" old "$OLD" "$rnd"; fi
  done
done
echo "runs took $(( $(date +%s) - START )) s; rows in $CSV"

# 3. The table.
"$PYTHON" - "$CSV" <<'EOF'
import csv, statistics, sys
rows = list(csv.DictReader(open(sys.argv[1])))
ms = list(dict.fromkeys(r["measurement"] for r in rows))
print("\n| measurement | N | ranks | old median s | new median s | new / old | pairs: min..max | old steps/s | new steps/s "
      "| peak memory new / old | same work |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
for m in ms:
    o = {r["round"]: r for r in rows if r["measurement"] == m and r["binary"] == "old"}
    n = {r["round"]: r for r in rows if r["measurement"] == m and r["binary"] == "new"}
    to = statistics.median(float(r["time_s"]) for r in o.values())
    tn = statistics.median(float(r["time_s"]) for r in n.values())
    pairs = [float(n[k]["time_s"]) / float(o[k]["time_s"]) for k in o if k in n]
    rate = lambda t: "%.1f" % (200 / t) if m.startswith("explicit") and t > 0 else "-"
    mem = statistics.median(float(r["peak_bytes"]) for r in n.values()) / statistics.median(
        float(r["peak_bytes"]) for r in o.values())
    work = {(r["iterations"], r["linear_iterations"]) for r in list(o.values()) + list(n.values())}
    r0 = next(iter(o.values()))
    print("| %s | %s | %s | %.3f | %.3f | **%.3f** | %.3f..%.3f | %s | %s | %.3f | %s |" % (
        m, r0["N"], r0["ranks"], to, tn, tn / to, min(pairs), max(pairs), rate(to), rate(tn), mem,
        "yes" if len(work) == 1 else "NO: iterations %s" % sorted(work)))
print("\nnew / old < 1: NEW is faster. Times: explicit = wall(200 steps) - wall(0 steps); static, relaxation = "
      "summary.json wall_seconds.")
EOF
