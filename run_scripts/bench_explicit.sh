#!/usr/bin/env bash
#                       tissue: explicit time-stepping throughput against LAMMPS
#
# What it measures: the LAMMPS peer's ../shared/peers/lammps/in.lattice_throughput problem (N^3 molecules,
# springs on cell edges and face diagonals, 8,850,600 springs for N = 100, velocity Verlet, 200 steps of 0.005)
# with our dynamic solver (run_scripts/scenes/peer_lattice.toml: solver.kind = "dynamic", solver.steps = 200, no
# load, nothing held) and with LAMMPS, alternately, on 1 and 2 ranks, for N = 50 and 100. Reported per run:
# steps per second, spring evaluations per second per core, peak resident memory per molecule, and our ratio to
# LAMMPS (and our 2-rank over our 1-rank rate).
#   - LAMMPS: steps/s = 200 / its "Loop time" (the stepping alone); memory = the sum over ranks of each rank's
#     peak resident set (/usr/bin/time %M) / molecules.
#   - Ours: summary.json wall_seconds counts set-up (scene, global body, METIS, calibration, output) as well, so
#     every size and rank count runs twice, with solver.steps = 200 and with solver.steps = 0, and
#     steps/s = 200 / (solver(200) - solver(0)), solver = summary.json solver.seconds (the solver's own clock: the
#     loop and its fixed costs, the first energy and the final check, which the 0-step run cancels; the difference
#     of the two runs' wall_seconds also carried the set-up's run-to-run spread, 2.5-3.2 s at 10^6 on 2 ranks,
#     2026-12-02); memory = peak_memory_bytes (the largest rank's) x ranks / molecules,
#     a peak that may well be set by the set-up rather than by the stepping.
#   - The start differs: LAMMPS gives the atoms random velocities (temperature 0.01); our dynamic scene starts at
#     rest and so stays at rest, but every step still computes every spring force and does the two half kicks and
#     the drift, so the work per step is the same (no neighbour lists on either side: LAMMPS rebuilds none in
#     200 steps).
#   - The roof (issue 18 item 3): a STREAM-like triad (run_scripts/triad.cpp, 256 MiB arrays) on each rank count,
#     before the first and after the last comparison, its best GB/s in the CSV (code "triad"). A step moves
#     BYTES_PER_MOLECULE bytes a molecule at the least (default 176: docs/benchmarks.md "The explicit step's bytes
#     and flops"), so triad GB/s / (BYTES_PER_MOLECULE x molecules) is the bandwidth bound in steps/s; the table
#     gives each code's fraction of it (LAMMPS's with the same bytes: its own move more).
#   - Order within a repetition: ours (200 and 0 steps), then LAMMPS: REPEAT=2 alternates ours, lmp, ours, lmp.
# Output: docs/bench_explicit.csv and a Markdown table on stdout.
#
# How to run (from the repository root; about 5 minutes on an idle 2-core machine; QUICK=1: N = 50 only):
#   cmake -S . -B build-bench -DCMAKE_BUILD_TYPE=Release -DTISSUE_TESTS=OFF && cmake --build build-bench -j2 --target tissue
#   apt-get install -y lammps
#   run_scripts/bench_explicit.sh
# Knobs (environment): TISSUE, LMP, NS (default "50 100"), NPS (default "1 2"), REPEAT (default 1), WORK, CSV,
# TISSUE_GUARDS (off: our per-step guards off, as for the quoted comparison; the CSV's guards column says which),
# FIELDS (none: `output.fields = []`, as before; default: the scene's default fields, so the final snapshot is
# written, as the issue's "guards on and the default output" memory target asks), BYTES_PER_MOLECULE, TRIAD_MIB.
#
# Steps:
#   1. Settings and checks.
#   2. The triad; for every N, rank count and repetition: ours with 200 steps, ours with 0 steps, LAMMPS; the triad.
#   3. The table: rates, ratios to LAMMPS (best against best), our 2-rank speed-up; then each repetition's pair and
#      the median of the pairs' ratios.
set -euo pipefail
cd "$(dirname "$0")/.."

# 1. Settings and checks.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
TISSUE=${TISSUE:-build-bench/tissue}
LMP=${LMP:-lmp}
PYTHON=${PYTHON:-/usr/bin/python3}
SCENE=run_scripts/scenes/peer_lattice.toml
PEER_INPUT=${PEER_INPUT:-../shared/peers/lammps/in.lattice_throughput}
WORK=${WORK:-/tmp/tissue_bench_explicit}
CSV=${CSV:-docs/bench_explicit.csv}
if [[ "${QUICK:-0}" == 1 ]]; then NS=${NS:-"50"}; else NS=${NS:-"50 100"}; fi
NPS=${NPS:-"1 2"}
REPEAT=${REPEAT:-1}
STEPS=200
FIELDS=${FIELDS:-none}
BYTES_PER_MOLECULE=${BYTES_PER_MOLECULE:-176}
TRIAD_MIB=${TRIAD_MIB:-256}
case $FIELDS in
  none) FIELD_SET='output.fields=[]' ;;
  default) FIELD_SET='output.fields=["positions","displacements","forces"]' ;;
  *) echo "bench_explicit: FIELDS is none or default" >&2; exit 1 ;;
esac
[[ -x "$TISSUE" ]] || { echo "bench_explicit: $TISSUE not built (see the header)" >&2; exit 1; }
command -v "$LMP" >/dev/null || { echo "bench_explicit: $LMP not found (apt-get install -y lammps)" >&2; exit 1; }
mkdir -p "$WORK" "$(dirname "$CSV")"
# The processor, printed with the table: the ratio depends on it (docs/benchmarks.md, "A Zen 4 host": its slower
# divider makes our step 1.3x slower than on Zen 5, LAMMPS's hardly).
HOST_CPU=$("$PYTHON" -c "
f = {}
for line in open('/proc/cpuinfo'):
    k, _, v = line.partition(':')
    f.setdefault(k.strip(), v.strip())
flags = f.get('flags', '').split()
vec = 'AVX-512' if 'avx512f' in flags else 'AVX2' if 'avx2' in flags else 'no AVX2'
print(f\"{f.get('model name', '?')}, family {f.get('cpu family', '?')} model {f.get('model', '?')}, {vec}\")
")
echo "bench_explicit: processor $HOST_CPU"
echo "code,N,molecules,springs,ranks,steps,wall_s,setup_s,loop_s,steps_per_s,spring_evals_per_s_per_core,peak_bytes,bytes_per_molecule,process_s,loadavg,guards,fields,triad_GBps,triad_when" > "$CSV"
# The triad, built here (mpicxx) so that it runs on the same machine in the same run.
TRIAD="$WORK/triad"
mpicxx -O3 -march=native -o "$TRIAD" run_scripts/triad.cpp
triad() {
  local np
  for np in $NPS; do
    mpirun -np "$np" "$TRIAD" "$TRIAD_MIB" | "$PYTHON" -c "
import sys
w = sys.stdin.read().split()[1:]  # "triad", then name value pairs
v = dict(zip(w[0::2], w[1::2]))
load = open('/proc/loadavg').read().split()[0]
print(','.join(str(x) for x in ['triad', '', '', '', v['ranks']] + [''] * 9 + [load, '', '', v['best_GBps_24B'], '$1']))
" >> "$CSV"
    tail -n 1 "$CSV"
  done
}
triad before
# Our per-step guards (src/solvers/guards.hpp) are on unless TISSUE_GUARDS=off: LAMMPS has none, so the speed
# comparison is made with them off; with them on, a run also keeps the last good state (48 B a molecule).
GUARDS=${TISSUE_GUARDS:-on}
# The binary's switch is PETSc's option -tissue_guards (every rank inherits PETSC_OPTIONS); binaries built before
# 2026-12-01 read TISSUE_GUARDS itself.
if [ "$GUARDS" = off ]; then export PETSC_OPTIONS="${PETSC_OPTIONS:-} -tissue_guards false"; fi

# ours N NP STEPS: prints "wall_seconds peak_memory_bytes connections process_seconds solver_seconds"
ours() {
  local n=$1 np=$2 steps=$3 dir="$WORK/ours-$1-np$2-s$3" t0 t1
  rm -rf "$dir"
  t0=$(date +%s.%N)
  mpirun -np "$np" "$TISSUE" run "$SCENE" --set "body.molecules=[$n,$n,$n]" --set "solver.steps=$steps" \
    --set "$FIELD_SET" --set output.progress=false --output "$dir" > "$dir.log" 2>&1 \
    || { echo "bench_explicit: our run N=$n np=$np steps=$steps failed, see $dir.log" >&2; return 1; }
  t1=$(date +%s.%N)
  "$PYTHON" -c "import json,sys; d=json.load(open('$dir/summary.json')); print(d['wall_seconds'], d['peak_memory_bytes'], d['connections'], $t1-$t0, d['solver']['seconds'])"
}

# 2. Alternate ours and LAMMPS.
for n in $NS; do
  for np in $NPS; do
    for rep in $(seq "$REPEAT"); do
      echo "N = $n ($((n * n * n)) molecules), $np rank(s), repetition $rep"
      read -r w200 p200 conn proc200 s200 < <(ours "$n" "$np" "$STEPS")
      read -r w0 p0 _ proc0 s0 < <(ours "$n" "$np" 0)
      "$PYTHON" - >> "$CSV" <<EOF
n, np, steps = $n, $np, $STEPS
w200, w0, peak, conn = $w200, $w0, $p200, $conn
loop = $s200 - $s0
rate = steps / loop
load = open("/proc/loadavg").read().split()[0]
print(",".join(str(v) for v in ["tissue", n, n**3, conn, np, steps, w200, w0, round(loop, 4), rate,
      rate * conn / np, peak, round(peak * np / n**3), $proc200, load, "$GUARDS", "$FIELDS", "", ""]))
EOF
      tail -n 1 "$CSV"
      log="$WORK/lammps-$n-np$np-$rep.log"
      t0=$(date +%s.%N)
      # each rank's /usr/bin/time writes its own file: on one shared log the ranks' lines interleave
      rm -f "$log".rss.*
      mpirun -np "$np" sh -c '/usr/bin/time -f "MAXRSS_KB %M" -o "$0.rss.$OMPI_COMM_WORLD_RANK" "$@"' "$log" \
        "$LMP" -in "$PEER_INPUT" -var N "$n" -log none > "$log" 2>&1
      cat "$log".rss.* >> "$log"
      t1=$(date +%s.%N)
      "$PYTHON" - "$log" "$n" "$np" "$t0" "$t1" "$STEPS" >> "$CSV" <<'EOF'
import re, sys
log, n, np, t0, t1, steps = sys.argv[1:7]
n, np, steps = int(n), int(np), int(steps)
text = open(log).read()
loop = float(re.search(r"Loop time of ([0-9.eE+-]+) on \d+ procs for (\d+) steps", text).group(1))
# the bond count: the sum of the two create_bonds reports ("Added N bonds, new total = M"): take the last total
totals = re.findall(r"new total = (\d+)", text)
springs = int(totals[-1]) if totals else ""
rss = sum(int(x) * 1024 for x in re.findall(r"MAXRSS_KB (\d+)", text))
rate = steps / loop
load = open("/proc/loadavg").read().split()[0]
print(",".join(str(v) for v in ["lammps", n, n**3, springs, np, steps, "", "", loop, rate,
      rate * springs / np if springs else "", max(int(x) * 1024 for x in re.findall(r"MAXRSS_KB (\d+)", text)),
      round(rss / n**3), round(float(t1) - float(t0), 3), load, "", "", "", ""]))
EOF
      tail -n 1 "$CSV"
    done
  done
done

triad after

# 3. The table.
echo
echo "processor: $HOST_CPU"
"$PYTHON" - "$CSV" "$BYTES_PER_MOLECULE" <<'EOF'
import csv, statistics, sys
from collections import defaultdict
rows = list(csv.DictReader(open(sys.argv[1])))
step_bytes = float(sys.argv[2])
# the roof: each rank count's lower triad (before / after)
roof = {}
for r in rows:
    if r["code"] == "triad":
        roof[int(r["ranks"])] = min(roof.get(int(r["ranks"]), 1e30), float(r["triad_GBps"]))
rows = [r for r in rows if r["code"] != "triad"]
best = defaultdict(dict)  # (N, ranks) -> code -> the best (highest) rate over repetitions, and its row
for r in rows:
    key = (int(r["N"]), int(r["ranks"]))
    if float(r["steps_per_s"]) > float(best[key].get(r["code"], {}).get("steps_per_s", 0)):
        best[key][r["code"]] = r
print("\n| N | molecules | ranks | LAMMPS steps/s | ours steps/s | ours / LAMMPS | ours Mspring/s/core | LAMMPS Mspring/s/core "
      "| ours B/molecule | LAMMPS B/molecule | ours set-up s | ours 2 ranks / 1 rank | triad GB/s | bound steps/s "
      "| ours / bound | LAMMPS / bound |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
for (n, np), c in sorted(best.items()):
    l, o = c.get("lammps"), c.get("tissue")
    if not (l and o):
        continue
    one = best.get((n, 1), {}).get("tissue")
    sp = f"{float(o['steps_per_s']) / float(one['steps_per_s']):.2f}x" if one and np == 2 else ""
    print(f"| {n} | {n**3:,} | {np} | {float(l['steps_per_s']):.1f} | {float(o['steps_per_s']):.1f} | "
          f"{float(o['steps_per_s']) / float(l['steps_per_s']):.2f}x | "
          f"{float(o['spring_evals_per_s_per_core']) / 1e6:.0f} | {float(l['spring_evals_per_s_per_core']) / 1e6:.0f} | "
          f"{o['bytes_per_molecule']} | {l['bytes_per_molecule']} | {float(o['setup_s']):.2f} | {sp} | ", end="")
    gb = roof.get(np)
    if gb:
        bound = gb * 1e9 / (step_bytes * n**3)
        print(f"{gb:.1f} | {bound:.0f} | {float(o['steps_per_s']) / bound:.0%} | {float(l['steps_per_s']) / bound:.0%} |")
    else:
        print(" | | | |")
# The table's ratio is best against best; this host's speed swings minute by minute (docs/benchmarks.md), so each
# repetition's pair (ours, then LAMMPS right after it) and their median are printed too.
pairs = defaultdict(lambda: {"tissue": [], "lammps": []})
for r in rows:
    pairs[(int(r["N"]), int(r["ranks"]))][r["code"]].append(float(r["steps_per_s"]))
for (n, np), c in sorted(pairs.items()):
    ratios = [o / l for o, l in zip(c["tissue"], c["lammps"])]
    if ratios:
        print(f"N = {n}, {np} rank(s): ours / LAMMPS pair by pair " + ", ".join(f"{x:.2f}x" for x in ratios) +
              f"; median {statistics.median(ratios):.2f}x")
EOF
