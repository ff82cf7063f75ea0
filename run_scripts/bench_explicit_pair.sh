#!/usr/bin/env bash
#              tissue: the explicit step of two (or more) binaries, alternating, 10^6 molecules, 1 rank
#
# What it measures: run_scripts/scenes/peer_lattice.toml (N^3 molecules, face diagonals, manual stiffness, 200
# velocity-Verlet steps) with each binary in turn, REPEAT rounds, the order reversed every other round, 1 rank,
# the guards off (-tissue_guards false; GUARDS=on: as users run it), `output.fields = []` (FIELDS=default: the
# scene default's final snapshot). Per run: summary.json solver.seconds (the stepping
# alone, wall clock), solver.cpu_seconds (its CPU time: less sensitive to a loaded machine) and the load average.
# Prints a CSV row per run and, per binary pair, the ratios old / new of the medians (> 1: the later binary is
# faster). Speed claims go through this script, never through tests.
#
# How to run (from the repository root):
#   BINS="old=<old build>/tissue new=build/tissue" REPEAT=3 bash run_scripts/bench_explicit_pair.sh
# Knobs (environment): BINS ("label=path ..."; the first is the reference), REPEAT (default 3), N (default 100),
# WORK (default /tmp/tissue_bench_explicit_pair), PYTHON (default /usr/bin/python3), GUARDS (off or on; default off),
# FIELDS (none or default; default none).
set -euo pipefail
cd "$(dirname "$0")/.."
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
BINS=${BINS:?'BINS="old=path new=path"'}
REPEAT=${REPEAT:-3}
N=${N:-100}
WORK=${WORK:-/tmp/tissue_bench_explicit_pair}
PYTHON=${PYTHON:-/usr/bin/python3}
GUARDS=${GUARDS:-off}
FIELDS=${FIELDS:-none}
case "$GUARDS" in on) GUARD_OPTION="" ;; off) GUARD_OPTION="-tissue_guards false" ;; *) echo "bench_explicit_pair: GUARDS is on or off, not '$GUARDS'" >&2; exit 2 ;; esac
case "$FIELDS" in none) FIELD_SET=(--set 'output.fields=[]') ;; default) FIELD_SET=(--set 'output.fields=["positions","displacements","forces"]') ;; *) echo "bench_explicit_pair: FIELDS is none or default, not '$FIELDS'" >&2; exit 2 ;; esac
mkdir -p "$WORK"
read -r -a pairs <<< "$BINS"
for pair in "${pairs[@]}"; do [ -x "${pair#*=}" ] || { echo "bench_explicit_pair: ${pair#*=} is not executable" >&2; exit 2; }; done
CSV="$WORK/runs.csv"
echo "round,label,solver_s,cpu_s,load" > "$CSV"
for ((r = 1; r <= REPEAT; r++)); do
  order=("${pairs[@]}")
  if ((r % 2 == 0)); then order=(); for ((i = ${#pairs[@]} - 1; i >= 0; i--)); do order+=("${pairs[$i]}"); done; fi
  for pair in "${order[@]}"; do
    label=${pair%%=*} bin=${pair#*=} dir="$WORK/$label-$r"
    rm -rf "$dir"
    PETSC_OPTIONS="${PETSC_OPTIONS:-} $GUARD_OPTION" "$bin" run run_scripts/scenes/peer_lattice.toml \
      --set "body.molecules=[$N,$N,$N]" "${FIELD_SET[@]}" --set "output.directory=$dir" > "$dir.log" 2>&1 \
      || { echo "bench_explicit_pair: $label failed, see $dir.log" >&2; exit 1; }
    load=$(cut -d' ' -f1 /proc/loadavg)
    "$PYTHON" -c "import json,sys; s=json.load(open(sys.argv[1]))['solver']; print(sys.argv[2], sys.argv[3], s['seconds'], s['cpu_seconds'], sys.argv[4], sep=',')" \
      "$dir/summary.json" "$r" "$label" "$load" | tee -a "$CSV"
  done
done
"$PYTHON" - "$CSV" <<'PY'
import csv, statistics, sys
rows = list(csv.DictReader(open(sys.argv[1])))
labels = list(dict.fromkeys(r["label"] for r in rows))
med = {l: {k: statistics.median(float(r[k]) for r in rows if r["label"] == l) for k in ("solver_s", "cpu_s")} for l in labels}
print("\n| binary | median solver.seconds | median cpu_seconds | steps/s (wall) | ratio to %s (wall / cpu) |" % labels[0])
print("|---|---|---|---|---|")
for l in labels:
    print(f"| {l} | {med[l]['solver_s']:.2f} | {med[l]['cpu_s']:.2f} | {200 / med[l]['solver_s']:.1f} | "
          f"{med[labels[0]]['solver_s'] / med[l]['solver_s']:.2f}x / {med[labels[0]]['cpu_s'] / med[l]['cpu_s']:.2f}x |")
PY
