#!/usr/bin/env bash
#                tissue: the static solver against the LAMMPS peer, alternating in one run (issue 18 "Done when")
#
# What it measures, each pair alternating (ours, LAMMPS, ours, LAMMPS: the machine is shared, the ratios inside one
# run are what count):
#   - FIRE: the peer tension test (run_scripts/scenes/peer_tension.toml = ../shared/peers/lammps/in.tension_fire) at
#     N = FIRE_N (default 40, 64,000 molecules): our static solve to relative residual 1e-8 on RANKS ranks
#     (summary.json wall_seconds) against LAMMPS FIRE's loop time on FIRE_RANKS ranks (default 1). Target: LAMMPS at
#     least 100x our time.
#   - Verlet: the same tension test at N = VV_N (default 100, 10^6 molecules), ours static to 1e-8 on RANKS ranks,
#     against 100 velocity-Verlet steps of the same lattice by LAMMPS on RANKS ranks
#     (../shared/peers/lammps/in.lattice_throughput runs 200: half its loop time). Target: ours at most the 100
#     steps, at most 1 kB a molecule (summary.json peak_memory_bytes x ranks / molecules).
# Output: CSV (default docs/bench_static_peer.csv), one row per run, and a Markdown table of the pairs on stdout.
#
# How to run (from the repository root; N = 100 needs about 4 GB and a few minutes on an idle 2-core machine):
#   cmake -S . -B build-bench -DCMAKE_BUILD_TYPE=Release -DTISSUE_TESTS=OFF && cmake --build build-bench -j2 --target tissue
#   apt-get install -y lammps
#   run_scripts/bench_static_peer.sh
# Knobs (environment): TISSUE (default build-bench/tissue), LMP (default lmp), RANKS (ours and the Verlet peer,
# default 2), FIRE_N, FIRE_RANKS, VV_N ("" skips that comparison), REPEAT (pairs per comparison, default 2), WORK,
# CSV, TOL (default 1e-8), OPERATOR (solver.operator of ours: "" = not given, the default: matrix-free on this
# springs-only lattice since branch setup18, assembled before; or assembled, matrix-free).
# Huge pages: ours puts malloc on transparent huge pages by itself (src/huge_pages.cpp, since branch static18g);
# TISSUE_HUGE_PAGES=off in the environment measures it without. A GLIBC_TUNABLES exported here reaches both codes.
set -euo pipefail
cd "$(dirname "$0")/.."

export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
TISSUE=${TISSUE:-build-bench/tissue}
LMP=${LMP:-lmp}
PYTHON=${PYTHON:-/usr/bin/python3}
SCENE=run_scripts/scenes/peer_tension.toml
FIRE_INPUT=${FIRE_INPUT:-../shared/peers/lammps/in.tension_fire}
VV_INPUT=${VV_INPUT:-../shared/peers/lammps/in.lattice_throughput}
RANKS=${RANKS:-2}
FIRE_N=${FIRE_N-40}
FIRE_RANKS=${FIRE_RANKS:-1}
VV_N=${VV_N-100}
REPEAT=${REPEAT:-2}
TOL=${TOL:-1e-8}
OPERATOR=${OPERATOR:-}
WORK=${WORK:-/tmp/tissue_bench_static_peer}
CSV=${CSV:-docs/bench_static_peer.csv}
[[ -x "$TISSUE" ]] || { echo "bench_static_peer: $TISSUE not built (see the header)" >&2; exit 1; }
command -v "$LMP" >/dev/null || { echo "bench_static_peer: $LMP not found (apt-get install -y lammps)" >&2; exit 1; }
mkdir -p "$WORK" "$(dirname "$CSV")"
echo "comparison,pair,code,N,molecules,ranks,seconds,what,peak_bytes_largest_rank,bytes_per_molecule,newton_its,krylov_its,residual,elongation,loadavg" > "$CSV"

# ours COMPARISON PAIR N: our static solve, one row (seconds = summary.json wall_seconds).
ours() {
  local comparison=$1 pair=$2 n=$3 dir="$WORK/ours-$1-$2" force
  force=$("$PYTHON" -c "print(0.001*$n*$n)")
  local extra=()
  [[ -n "$OPERATOR" ]] && extra+=(--set "solver.operator=$OPERATOR")
  rm -rf "$dir"
  mpirun -np "$RANKS" "$TISSUE" run "$SCENE" --set "body.molecules=[$n,$n,$n]" --set "load.0.force=[0,0,-$force]" \
    --set "solver.tolerance=$TOL" "${extra[@]}" --set output.fields=[] --set output.progress=false --output "$dir" > "$dir.log" 2>&1 \
    || { echo "bench_static_peer: our run failed, see $dir.log" >&2; return 1; }
  "$PYTHON" - "$dir/summary.json" "$comparison" "$pair" "$n" >> "$CSV" <<'EOF'
import json, sys
d = json.load(open(sys.argv[1]))
comparison, pair, n = sys.argv[2:5]
s = d["solver"]
print(",".join(str(v) for v in [comparison, pair, "tissue_static", n, d["molecules"], d["ranks"], d["wall_seconds"],
      "wall_seconds", d["peak_memory_bytes"], round(d["peak_memory_bytes"] * d["ranks"] / d["molecules"]),
      s["iterations"], s.get("linear_iterations") or 0, s["residual"], repr(d["elongation"]),
      open("/proc/loadavg").read().split()[0]]))
EOF
  tail -n 1 "$CSV"
}

# peer COMPARISON PAIR N NP INPUT: one LAMMPS run, one row (FIRE: the loop time; Verlet: 100 of its 200 steps).
peer() {
  local comparison=$1 pair=$2 n=$3 np=$4 input=$5 log="$WORK/lammps-$1-$2.log"
  rm -f "$log".rss.*
  mpirun -np "$np" sh -c '/usr/bin/time -f "MAXRSS_KB %M" -o "$0.rss.$OMPI_COMM_WORLD_RANK" "$@"' "$log" \
    "$LMP" -in "$input" -var N "$n" -log none > "$log" 2>&1
  cat "$log".rss.* >> "$log"
  "$PYTHON" - "$log" "$comparison" "$pair" "$n" "$np" >> "$CSV" <<'EOF'
import re, sys
log, comparison, pair, n, np = sys.argv[1:6]
n, np = int(n), int(np)
text = open(log).read()
m = re.search(r"Loop time of ([0-9.eE+-]+) on \d+ procs for (\d+) steps", text)
loop, steps = float(m.group(1)), int(m.group(2))
peak = max(int(x) * 1024 for x in re.findall(r"MAXRSS_KB (\d+)", text))
rss = sum(int(x) * 1024 for x in re.findall(r"MAXRSS_KB (\d+)", text))
el = re.search(r"ELONGATION (\S+)", text)
if comparison == "fire":
    seconds, what = loop, f"FIRE loop time ({steps} iterations)"
else:
    seconds, what = loop * 100 / steps, f"100 velocity-Verlet steps ({steps} in {loop:.3f} s)"
print(",".join(str(v) for v in [comparison, pair, "lammps", n, n**3, np, round(seconds, 4), what, peak,
      round(rss / n**3), "", "", "", el.group(1) if el else "", open("/proc/loadavg").read().split()[0]]))
EOF
  tail -n 1 "$CSV"
}

for rep in $(seq "$REPEAT"); do
  if [[ -n "$FIRE_N" ]]; then
    ours fire "$rep" "$FIRE_N"
    peer fire "$rep" "$FIRE_N" "$FIRE_RANKS" "$FIRE_INPUT"
  fi
done
for rep in $(seq "$REPEAT"); do
  if [[ -n "$VV_N" ]]; then
    ours verlet "$rep" "$VV_N"
    peer verlet "$rep" "$VV_N" "$RANKS" "$VV_INPUT"
  fi
done

"$PYTHON" - "$CSV" <<'EOF'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
print("\n| comparison | pair | N | ours static s | ours B/molecule | Newton / Krylov | LAMMPS s | LAMMPS / ours | load |")
print("|---|---|---|---|---|---|---|---|---|")
for (c, p) in sorted({(r["comparison"], r["pair"]) for r in rows}):
    o = [r for r in rows if r["comparison"] == c and r["pair"] == p and r["code"] == "tissue_static"]
    l = [r for r in rows if r["comparison"] == c and r["pair"] == p and r["code"] == "lammps"]
    if not (o and l):
        continue
    o, l = o[0], l[0]
    print(f"| {'LAMMPS FIRE' if c == 'fire' else 'LAMMPS 100 Verlet steps'} | {p} | {o['N']} | {float(o['seconds']):.3f} | "
          f"{o['bytes_per_molecule']} | {o['newton_its']} / {o['krylov_its']} | {float(l['seconds']):.3f} | "
          f"{float(l['seconds']) / float(o['seconds']):.2f}x | {o['loadavg']} / {l['loadavg']} |")
EOF
