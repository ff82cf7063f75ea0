#!/usr/bin/env bash
#                       tissue: speed and accuracy of the static and relaxation solvers
#
# What it measures: the tension test of the LAMMPS peer (run_scripts/scenes/peer_tension.toml, the exact problem of
# ../shared/peers/lammps/in.tension_fire: N^3 molecules, spacing 1, k = 1 on edges and face diagonals, z+
# clamped, 0.001 N^2 pulling the z- layer with the same force on every molecule) for N = 10 .. 100 (1,000 to
# 1,000,000 molecules), on 2 MPI ranks, solved by
#   - the static solver (SNES Newton) with five Krylov/preconditioner choices: CG + the lattice's geometric
#     multigrid on the assembled tangent (--set solver.operator=assembled, config "mg"), the same multigrid on the
#     matrix-free tangent (--set solver.operator=matrix-free, config "mf", the default on springs-only lattices
#     since branch setup18: no fine-level matrix, Chebyshev-Jacobi smoothing), CG +
#     GAMG (-pc_type gamg), CG + BoomerAMG (-pc_type hypre, N <= HYPRE_MAX_N), CG + Jacobi (-pc_type jacobi,
#     N <= JACOBI_MAX_N), at relative residual 1e-8,
#   - the relaxation solver (FIRE) at relative residual 1e-4, 1e-6 and 1e-8,
#   - the dynamic solver (undamped velocity Verlet plus [physics] viscosity c, at its default time step, half the
#     critical one), damped to rest: c = DYN_DAMPING / (N - 1) (default 3.5, the best of 1.5-4.5 tried at N = 10
#     and 20: the slowest mode, the bar's first longitudinal one, has a frequency ~ 1/(N - 1)) for
#     DYN_STEPS_PER_LAYER x (N - 1) steps (default 90: the elongation then within ~1e-8 of the converged answer).
#     The dynamic solver reports no force residual (summary.json solver.residual is null), so its accuracy is the
#     elongation's error against the reference, read every steps / DYN_POINTS steps from history.csv: one run
#     gives the whole error-against-steps curve (docs/speed_accuracy_dynamic.csv; the time at step s is estimated
#     as set-up + s / steps x the solve's time, the solve being a loop of equal steps),
#   - for BIG_NS (default none; e.g. BIG_NS="150 200"): the matrix-free static solver only (the only one that fits
#     above ~10^6 molecules on this 24 GB machine), no reference (the residual only); skipped unless MemAvailable
#     shows 1.25 kB a molecule (FORCE=1 starts anyway),
#   - and a reference: static, CG + GAMG, at relative residual 1e-10 (N <= 20) or 1e-9 (N > 20) with Krylov
#     rtol 1e-10 ("the converged static answer"; tighter runs hit the round-off floor, see reference() below).
# For every run: wall time (summary.json wall_seconds, all of the run after MPI start-up, and the process time of
# mpirun), CPU time (user + system of all ranks, cpu_s), peak resident memory (the largest rank's, and x ranks /
# molecules = bytes per molecule), Newton and Krylov iterations (relaxation: its FIRE iterations; dynamic: its
# steps), the relative force residual (summary.json solver.residual), the elongation's error against the reference and the
# measured E's error against the target E (the lattice's continuum modulus 2.5: a discretisation error, not a
# solver error). The LAMMPS FIRE peer runs in the same script, alternating with ours (ours static, LAMMPS, ours
# static, LAMMPS, ours relaxation) for N in PEER_NS on PEER_RANKS ranks: the same elongation (printed by the peer
# as ELONGATION) and the time ratio (LAMMPS loop time over the mean of the two static runs around it).
# Runs above BIGMEM_N (default 80, ~1 GB per 100,000 molecules) take the lock /tmp/tissue-bigmem.lock so that two
# big runs on a shared machine never overlap.
# Output: docs/speed_accuracy.csv (one row per run; LAMMPS rows have solver = lammps_fire) and, through
# run_scripts/plot_speed_accuracy.py, docs/speed_accuracy_pareto.png (error and residual vs CPU time),
# docs/speed_accuracy_pareto_memory.png (error vs bytes a molecule), docs/speed_accuracy_scaling.png (CPU time,
# wall time and memory vs molecules, log-log, fitted exponents; docs/speed_accuracy_exponents.csv),
# docs/speed_accuracy_iterations.png (Newton/Krylov/FIRE iterations vs N) and docs/speed_accuracy_peer.csv (the
# peer comparison). docs/bench_static_huge.csv's rows (run_scripts/bench_static_huge.sh) are drawn in the scaling
# plot as their own, labelled series.
#
# How to run (from the repository root; about 15 minutes; QUICK=1: N = 10, 20, 40 and the peer at N = 20 only,
# about 2 minutes):
#   cmake -S . -B build-bench -DCMAKE_BUILD_TYPE=Release -DTISSUE_TESTS=OFF && cmake --build build-bench -j2 --target tissue
#   apt-get install -y lammps          # the peer, binary lmp
#   run_scripts/speed_accuracy.sh      # or QUICK=1 run_scripts/speed_accuracy.sh
# Knobs (environment): TISSUE (binary, default build-bench/tissue), LMP (default lmp), NS (molecule counts per
# axis), PEER_NS, RANKS (ours, default 2), WORK (run directories, default /tmp/tissue_speed_accuracy),
# CSV (default docs/speed_accuracy.csv), JACOBI_MAX_N (CG + Jacobi only up to this N; default 40: its iterations
# grow like N), HYPRE_MAX_N (default 20: BoomerAMG's set-up on this lattice is slow), RELAX_TOLS (default
# "1e-4 1e-6 1e-8"), STATIC_CONFIGS (default "mg gamg hypre jacobi"), PEER_RANKS (default "1 2"), PEER_INPUT
# (the LAMMPS input), DYN_DAMPING, DYN_STEPS_PER_LAYER, DYN_POINTS (default 30), BIG_NS, DYN_CSV (default
# docs/speed_accuracy_dynamic.csv), APPEND=1 (add rows to an existing CSV instead of starting it), NO_REF=1 (no reference
# solve in the sweep: errors left blank; for the biggest N, where every run holds the big-memory lock), PLOT=0 (no
# plots).
# NS="", PEER_NS="", STATIC_CONFIGS="", RELAX_TOLS="" or DYNAMIC=0 skips that part. STATIC_CONFIGS default
# "mg mf gamg hypre jacobi".
#
# Steps:
#   1. Settings and checks (binary, lmp, python3 with matplotlib).
#   2. For every N: the reference static solve, the static solves (1e-8), the relaxations, the damped dynamic run;
#      then BIG_NS, matrix-free static only.
#   3. The peer: for N in PEER_NS, alternately our static and LAMMPS FIRE (1 and 2 ranks), then our relaxation.
#   4. The plots and the peer table (run_scripts/plot_speed_accuracy.py).
set -euo pipefail
cd "$(dirname "$0")/.."

# 1. Settings and checks.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
TISSUE=${TISSUE:-build-bench/tissue}
LMP=${LMP:-lmp}
PYTHON=${PYTHON:-/usr/bin/python3}
SCENE=run_scripts/scenes/peer_tension.toml
PEER_INPUT=${PEER_INPUT:-../shared/peers/lammps/in.tension_fire}
RANKS=${RANKS:-2}
WORK=${WORK:-/tmp/tissue_speed_accuracy}
CSV=${CSV:-docs/speed_accuracy.csv}
JACOBI_MAX_N=${JACOBI_MAX_N:-40}
HYPRE_MAX_N=${HYPRE_MAX_N:-20}
STATIC_CONFIGS=${STATIC_CONFIGS-"mg mf gamg hypre jacobi"}
RELAX_TOLS=${RELAX_TOLS-"1e-4 1e-6 1e-8"}
PEER_RANKS=${PEER_RANKS-"1 2"}
BIGMEM_N=${BIGMEM_N:-80}
DYNAMIC=${DYNAMIC:-1}
DYN_DAMPING=${DYN_DAMPING:-3.5}
DYN_STEPS_PER_LAYER=${DYN_STEPS_PER_LAYER:-90}
DYN_POINTS=${DYN_POINTS:-30}
DYN_CSV=${DYN_CSV:-docs/speed_accuracy_dynamic.csv}
BIG_NS=${BIG_NS-""}
if [[ "${QUICK:-0}" == 1 ]]; then
  NS=${NS-"10 20 40"}
  PEER_NS=${PEER_NS-"20"}
else
  NS=${NS-"10 20 40 64 100"}
  PEER_NS=${PEER_NS-"20 40"}
fi
[[ -x "$TISSUE" ]] || { echo "speed_accuracy: $TISSUE not built (see the header)" >&2; exit 1; }
command -v "$LMP" >/dev/null || { echo "speed_accuracy: $LMP not found (apt-get install -y lammps)" >&2; exit 1; }
"$PYTHON" -c "import matplotlib" || { echo "speed_accuracy: $PYTHON has no matplotlib" >&2; exit 1; }
mkdir -p "$WORK" "$(dirname "$CSV")"
[[ "${APPEND:-0}" == 1 && -f "$DYN_CSV" ]] || echo "N,molecules,ranks,step,steps,viscosity,time_step,est_wall_s,est_cpu_s,elongation,err_vs_static_ref,kinetic_energy,loadavg" > "$DYN_CSV"
[[ "${APPEND:-0}" == 1 && -f "$CSV" ]] || echo "case,solver,config,N,molecules,ranks,tolerance,wall_s,process_s,peak_bytes,bytes_per_molecule,newton_its,krylov_its,residual,converged,elongation,err_vs_static_ref,E_measured,err_vs_E_target,loadavg,cpu_s" > "$CSV"

# The reference elongation per N (filled by the reference runs; the peer rows use it too).
declare -A REF

# ours CASE SOLVER CONFIG N TOL [PETSc options...]: one run of ours, one CSV row; extra tissue arguments (--set ...)
# in the array SETS.
SETS=()
ours() {
  local case=$1 solver=$2 config=$3 n=$4 tol=$5
  shift 5
  local dir="$WORK/$case-$solver-$config-$n-$tol" force t0 t1 code=0 extra=() lock=()
  (( $# )) && extra=(-- "$@")
  (( n > BIGMEM_N )) && lock=(flock /tmp/tissue-bigmem.lock)
  force=$("$PYTHON" -c "print(0.001*$n*$n)")
  # dynamic runs carry no tolerance: their TOL column names the viscosity (c=...), set through SETS
  local toler=(--set "solver.tolerance=$tol")
  [[ "$solver" == dynamic ]] && toler=()
  rm -rf "$dir"
  t0=$(date +%s.%N)
  "${lock[@]}" /usr/bin/time -f "CPU %U %S" -o "$dir.cpu" mpirun -np "$RANKS" "$TISSUE" run "$SCENE" --set "body.molecules=[$n,$n,$n]" \
    --set "load.0.force=[0,0,-$force]" --set "solver.kind=$solver" "${toler[@]}" \
    --set output.fields=[] --set output.progress=false --output "$dir" "${SETS[@]}" "${extra[@]}" > "$dir.log" 2>&1 || code=$?
  (( code == 0 )) || echo "  ($case $solver $config N=$n: exit code $code, see $dir.log)" >&2
  t1=$(date +%s.%N)
  [[ -f "$dir/summary.json" ]] || return 0
  "$PYTHON" - "$dir/summary.json" "$case" "$solver" "$config" "$n" "$tol" "$t0" "$t1" "${REF[$n]:-}" "$dir.cpu" \
      "$DYN_CSV" >> "$CSV" <<'EOF'
import csv, json, re, sys
d = json.load(open(sys.argv[1]))
case, solver, config, n, tol, t0, t1, ref, cpufile, dyn_csv = sys.argv[2:12]
m = re.search(r"CPU (\S+) (\S+)", open(cpufile).read())
cpu = round(float(m.group(1)) + float(m.group(2)), 2) if m else ""
s = d["solver"]
el = d["elongation"]
err = abs(el - float(ref)) / abs(float(ref)) if ref else ""
E, Et = d["youngs_modulus_measured"], d["youngs_modulus_target"]
load = open("/proc/loadavg").read().split()[0]
# the dynamic solver reports no residual (null): the CSV leaves it blank
res = "" if s["residual"] is None else s["residual"]
print(",".join(str(v) for v in [case, solver, config, n, d["molecules"], d["ranks"], tol, d["wall_seconds"],
      round(float(t1) - float(t0), 3), d["peak_memory_bytes"], round(d["peak_memory_bytes"] * d["ranks"] / d["molecules"]),
      s["iterations"], s.get("linear_iterations") or 0, res, s["converged"], repr(el), err, E,
      abs(E - Et) / Et, load, cpu]))
if solver == "dynamic":
    # the error-against-steps curve from history.csv: the solve is a loop of equal steps, so the time at step k is
    # the set-up (wall minus the solve) plus k / steps of the solve; CPU time split in the same proportion
    steps, solve = d["steps"], s["seconds"]
    wall = d["wall_seconds"]
    with open(dyn_csv, "a") as out:
        for r in csv.DictReader(open(sys.argv[1].replace("summary.json", "history.csv"))):
            k = int(r["step"])
            ew = wall - solve + solve * k / steps
            ec = cpu * ew / wall if cpu != "" else ""
            e = float(r["elongation"]) if r["elongation"] else float("nan")
            er = abs(e - float(ref)) / abs(float(ref)) if ref else ""
            out.write(",".join(str(v) for v in [n, d["molecules"], d["ranks"], k, steps, tol.removeprefix("c="), s["time_step"],
                                                round(ew, 4), ec if ec == "" else round(ec, 4), repr(e), er,
                                                r["kinetic_energy"], load]) + "\n")
EOF
  tail -n 1 "$CSV" | awk -F, '{printf "  %-6s %-10s %-7s N=%-4s tol=%-6s wall %8.3f s  mem %6d B/mol  its %6s/%-6s  err %s\n", $1,$2,$3,$4,$7,$8,$11,$12,$13,$17}'
}

# peer N RANKS: one LAMMPS FIRE run, one CSV row (wall_s = LAMMPS's loop time, process_s = the whole process).
peer() {
  local n=$1 np=$2 log="$WORK/lammps-$1-np$2.log" t0 t1
  t0=$(date +%s.%N)
  # each rank's /usr/bin/time writes its own file: on one shared log the ranks' lines interleave
  rm -f "$log".rss.*
  mpirun -np "$np" sh -c '/usr/bin/time -f "MAXRSS_KB %M CPU %U %S" -o "$0.rss.$OMPI_COMM_WORLD_RANK" "$@"' "$log" \
    "$LMP" -in "$PEER_INPUT" -var N "$n" -log none > "$log" 2>&1
  cat "$log".rss.* >> "$log"
  t1=$(date +%s.%N)
  "$PYTHON" - "$log" "$n" "$np" "$t0" "$t1" "${REF[$n]:-}" >> "$CSV" <<'EOF'
import re, sys
log, n, np, t0, t1, ref = sys.argv[1:7]
text = open(log).read()
n, np = int(n), int(np)
loop = float(re.search(r"Loop time of ([0-9.eE+-]+)", text).group(1))
its = int(re.search(r"Iterations, force evaluations = (\d+) (\d+)", text).group(1))
fnorm = float(re.search(r"Force two-norm initial, final = \S+ (\S+)", text).group(1))
el = float(re.search(r"ELONGATION (\S+)", text).group(1))
rss = sum(int(x) * 1024 for x in re.findall(r"MAXRSS_KB (\d+)", text))  # all ranks
peak = max(int(x) * 1024 for x in re.findall(r"MAXRSS_KB (\d+)", text))
err = abs(el - float(ref)) / abs(float(ref)) if ref else ""
load = open("/proc/loadavg").read().split()[0]
cpu = round(sum(float(u) + float(s) for u, s in re.findall(r"MAXRSS_KB \d+ CPU (\S+) (\S+)", text)), 2)
# residual: the final force 2-norm relative to the applied load's 2-norm (0.001 per molecule of the N^2 face)
print(",".join(str(v) for v in ["peer", "lammps_fire", f"np{np}", n, n**3, np, "ftol=1e-8", loop,
      round(float(t1) - float(t0), 3), peak, round(rss / n**3), its, 0, fnorm / (0.001 * n), True, repr(el), err, "",
      "", load, cpu]))
EOF
  tail -n 1 "$CSV" | awk -F, '{printf "  %-6s %-11s %-6s N=%-4s       loop %8.3f s (process %7.2f s)  mem %6d B/mol  its %6s  err %s\n", $1,$2,$3,$4,$8,$9,$11,$12,$17}'
}

# reference CASE N: the converged static answer, REF[N]. Its tolerance is 1e-10 up to N = 20 and 1e-9 above, with
# tight Krylov solves: below about 1e-10 (N = 20) to 2e-10 (N = 100) the residual is at its round-off floor
# (|x| ~ N times machine epsilon per force, over 3 N^3 components), Newton's line search fails and the run spends
# minutes in load cut-backs. The elongation is then converged far below the 1e-6 that matters here.
reference() {
  local case=$1 n=$2 tol=1e-9
  (( n <= 20 )) && tol=1e-10
  ours "$case" static ref "$n" "$tol" -ksp_rtol 1e-10
  if [[ "$(tail -n 1 "$CSV" | cut -d, -f15)" != True ]]; then
    echo "speed_accuracy: the reference static solve for N = $n did not converge; errors for N = $n are void" >&2
  fi
  REF[$n]=$(tail -n 1 "$CSV" | cut -d, -f16)
  # the reference row's own error is zero by definition
  sed -i '$ s/^\(\([^,]*,\)\{16\}\)[^,]*/\10/' "$CSV"
}

# 2. The sweep over N.
for n in $NS; do
  echo "N = $n ($((n * n * n)) molecules), $RANKS ranks"
  [[ "${NO_REF:-0}" == 1 ]] || reference sweep "$n"
  for config in $STATIC_CONFIGS; do
    case $config in
      mg) SETS=(--set solver.operator=assembled); ours sweep static mg "$n" 1e-8; SETS=() ;;
      mf) SETS=(--set solver.operator=matrix-free); ours sweep static mf "$n" 1e-8; SETS=() ;;
      gamg) ours sweep static gamg "$n" 1e-8 -pc_type gamg ;;
      hypre) if (( n <= HYPRE_MAX_N )); then ours sweep static hypre "$n" 1e-8 -pc_type hypre; fi ;;
      jacobi) if (( n <= JACOBI_MAX_N )); then ours sweep static jacobi "$n" 1e-8 -pc_type jacobi; fi ;;
    esac
  done
  for tol in $RELAX_TOLS; do ours sweep relaxation fire "$n" "$tol"; done
  if [[ "$DYNAMIC" == 1 ]]; then
    visc=$("$PYTHON" -c "print(f'{$DYN_DAMPING / ($n - 1):.6g}')")
    steps=$((DYN_STEPS_PER_LAYER * (n - 1)))
    SETS=(--set "physics.viscosity=$visc" --set "solver.steps=$steps"
          --set "output.history_every=$(( (steps + DYN_POINTS - 1) / DYN_POINTS ))")
    ours sweep dynamic damped "$n" "c=$visc"
    SETS=()
  fi
done

# BIG_NS: the matrix-free static solve alone, no reference (its cost is the run's again); memory checked first.
for n in $BIG_NS; do
  need_kb=$(( n * n * n * 5 / 4 ))  # 1.25 kB a molecule (docs/bench_static_huge.csv: 834-1,647 B measured)
  avail_kb=$(awk '/MemAvailable/{print $2}' /proc/meminfo)
  if [[ "${FORCE:-0}" != 1 ]] && (( avail_kb < need_kb )); then
    echo "speed_accuracy: N = $n needs about $((need_kb / 1048576)) GB, $((avail_kb / 1048576)) GB available: skipped (FORCE=1 runs it)" >&2
    continue
  fi
  echo "N = $n ($((n * n * n)) molecules), $RANKS ranks, matrix-free static only"
  SETS=(--set solver.operator=matrix-free)
  ours big static mf "$n" 1e-8
  SETS=()
done

# 3. The peer, alternating with ours (the same machine state for both).
for n in $PEER_NS; do
  echo "peer: N = $n, LAMMPS FIRE (ftol 1e-8 absolute) vs ours (relative residual 1e-8)"
  [[ -n "${REF[$n]:-}" ]] || reference peer "$n"
  for np in $PEER_RANKS; do
    ours peer static mg "$n" 1e-8
    peer "$n" "$np"
    ours peer static mg "$n" 1e-8
    peer "$n" "$np"
    ours peer relaxation fire "$n" 1e-8
  done
done

# 4. Plots and the peer table.
[[ "${PLOT:-1}" == 1 ]] || exit 0
"$PYTHON" run_scripts/plot_speed_accuracy.py "$CSV" docs "$DYN_CSV"
