#!/usr/bin/env bash
#                 tissue: error in E against molecule count, per calibration method and topology
#
# What it does: the tension test on an n x n x n molecule unit cube (1 m, E = 100 kPa, 100 N on the z- face as a
# uniform traction: strain 1e-3, the small-strain regime), n = 2 .. 16 by default (8 to 4,096 molecules; NS for more), for
#   topologies face-diagonals, body-diagonals, tetrahedral, and
#   methods linear, homogenized (box lattices only), tetrahedral (tetrahedral topology only), iterative,
#   statistical,
# with the z+ face on rollers (the material's modulus) and clamped (the paper's test; the continuum itself reads
# ~1.0205 E on a clamped cube, ../shared/reference/calibration.md), on 2 MPI ranks with the static solver.
# The paper expects its statistical method to improve "when larger and larger numbers of molecules are
# involved": this measures it, and whether each method converges to the material (roller) or to the clamped
# continuum value.
# Output: docs/convergence.csv (one row per run: topology, method, support, n, molecules, connections, E, error %
# against E, error % against the clamped continuum reference 1.0205 E, Poisson ratio, iterations, wall seconds,
# exit code: 3 = the solver failed, E is then that of the last good state and is not plotted)
# and docs/convergence.png (log-log |error| against molecule count, roller and clamped side by side), drawn by
# run_scripts/plot_convergence.py.
#
# How to run (from the repository root; 72 runs with the default NS: about 4 minutes on an idle 2-core machine,
# 20 minutes on a shared one at load average 14; n = 24, 32 add minutes each):
#   cmake -S . -B build-paper -DCMAKE_BUILD_TYPE=Release -DTISSUE_TESTS=OFF && cmake --build build-paper -j2 --target tissue
#   run_scripts/convergence.sh
# Knobs (environment): TISSUE (default build-paper/tissue), RANKS (default 2), NS (molecules per axis, default
# "2 4 8 16"; "2 3 4 6 8 12 16 24 32" on an idle machine), ALL_CLAMPED=1 (clamped runs for linear and statistical
# too; by default only homogenized, tetrahedral and iterative, the methods that can approach the clamped continuum), WORK (default /tmp/tissue_convergence), CSV (default docs/convergence.csv),
# PNG (default docs/convergence.png), APPEND=1 (keep the rows already in CSV and add these: a large n run on its
# own, e.g. NS=64 APPEND=1 after NS="2 4 8 16 32"), TOPOLOGIES (default "face-diagonals body-diagonals
# tetrahedral"), RUN_METHODS (only these methods), CLAMPED_MAX_N (clamped runs only for n <= this; default: all).
# Cost at large n: every run is one static solve (2 Newton iterations, ~19 CG iterations each, at every n), except
# iterative, which re-solves until C settles. Iterative therefore starts from the C it found at the previous n
# (same topology and support; from CSV when appending) instead of 3.75: C changes little with n, so it needs one
# update (2 solves, the second warm-started) instead of 3-4; on rollers C does not depend on n at all (the
# lattice is scale-free), so it needs no update. Set-up (the body and METIS on rank 0) is the rest: ~3% at n = 64.
# Measured 2026-11-23 (docs/methods.md): n = 32 takes 10-45 s a run, n = 64 (262,144 molecules, 2.3-3.3 M springs,
# 1.5 GB per rank) 2.5-10 minutes a run on the shared 2-core machine at load average 12-16 (the solve is 95% of it;
# -log_view at n = 32: GAMG set-up 36%, its V-cycles 49%, Jacobian assembly 8%), so the 64^3 runs were made
# with NS=64 APPEND=1 and, for time, without the clamped body-diagonals iterative and tetrahedral runs
# (CLAMPED_MAX_N=32 for the tetrahedral topology).
#
# Steps:
#   1. Settings and checks (binary, python3 with matplotlib).
#   2. For every n, topology, method, support: one run (summary.json under $WORK), one CSV row.
#   3. The plot.
set -euo pipefail
cd "$(dirname "$0")/.."

# 1. Settings and checks.
TISSUE=${TISSUE:-build-paper/tissue}
RANKS=${RANKS:-2}
NS=${NS:-"2 4 8 16"}
WORK=${WORK:-/tmp/tissue_convergence}
CSV=${CSV:-docs/convergence.csv}
PNG=${PNG:-docs/convergence.png}
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
[ -x "$TISSUE" ] || { echo "convergence.sh: no binary $TISSUE (build it, see the header)" >&2; exit 1; }
/usr/bin/python3 -c 'import matplotlib' || { echo "convergence.sh: needs python3-matplotlib" >&2; exit 1; }
mkdir -p "$WORK" "$(dirname "$CSV")"
header="topology,method,support,n,molecules,connections,E,error_percent,error_vs_clamped_continuum_percent,poisson,divisor,iterations,wall_seconds,exit_code"
if [ -z "${APPEND:-}" ] || [ ! -s "$CSV" ]; then echo "$header" >"$CSV"; fi
# The iterative method's start value of C: the one found at the largest n so far (same topology and support).
start_divisor() {  # topology support
  awk -F, -v t="$1" -v s="$2" '$1 == t && $2 == "iterative" && $3 == s && $11 != "" && $14 == 0 && $4 + 0 > n {
    n = $4 + 0; c = $11 } END { print (c == "" ? "3.75" : c) }' "$CSV"
}

# 2. The runs.
methods_for() {
  case $1 in
    tetrahedral) echo "linear tetrahedral iterative statistical";;
    *)           echo "linear homogenized iterative statistical";;
  esac
}
for n in $NS; do
  for topology in ${TOPOLOGIES:-face-diagonals body-diagonals tetrahedral}; do
    for method in $(methods_for "$topology"); do
      if [ -n "${RUN_METHODS:-}" ] && [[ " $RUN_METHODS " != *" $method "* ]]; then continue; fi
      for support in roller clamped; do
        if [ "$support" = clamped ] && [ -n "${CLAMPED_MAX_N:-}" ] && [ "$n" -gt "$CLAMPED_MAX_N" ]; then continue; fi
        # Clamped: only the methods that can converge to the clamped continuum (the others drift anyway).
        if [ "$support" = clamped ] && [ -z "${ALL_CLAMPED:-}" ]; then
          case $method in linear|statistical) continue;; esac
        fi
        dir=$WORK/$topology/$method/$support/$n
        rm -rf "$dir"; mkdir -p "$dir"
        divisor=3.75
        [ "$method" = iterative ] && divisor=$(start_divisor "$topology" "$support")
        rc=0
        mpirun --oversubscribe -np "$RANKS" "$TISSUE" run run_scripts/scenes/table2.toml \
          --set "body.molecules=[$n,$n,$n]" --set 'body.size=[1.0,1.0,1.0]' --set "body.topology=$topology" \
          --set "calibration.method=$method" --set "calibration.divisor=$divisor" --set "fix.0.mode=$support" \
          --set 'load.0.force=[0.0,0.0,-100.0]' --set output.progress=false --set 'output.fields=[]' \
          --output "$dir/out" >"$dir/log" 2>&1 || rc=$?
        /usr/bin/python3 - "$dir/out/summary.json" "$topology" "$method" "$support" "$n" "$rc" >>"$CSV" <<'PY'
import json, os, sys
path, topology, method, support, n, rc = sys.argv[1:]
if not os.path.exists(path) or rc == "2":
    print(",".join([topology, method, support, n] + [""] * 9 + [rc])); sys.exit()
j = json.load(open(path))
E = j["youngs_modulus_measured"]
row = [topology, method, support, n, j["molecules"], j["connections"], repr(E), repr(j["error_percent"]),
       repr(100 * (E / (1.0205 * j["youngs_modulus_target"]) - 1)), repr(j["poisson_ratio_measured"]),
       repr((j.get("calibration") or {}).get("divisor")) if (j.get("calibration") or {}).get("divisor") else "", j["solver"]["iterations"], repr(j["wall_seconds"]), rc]
print(",".join(str(x) for x in row))
PY
        printf 'n=%-3s %-15s %-12s %-8s rc=%s\n' "$n" "$topology" "$method" "$support" "$rc"
      done
    done
  done
done

# 3. The plot.
/usr/bin/python3 run_scripts/plot_convergence.py "$CSV" "$PNG"
