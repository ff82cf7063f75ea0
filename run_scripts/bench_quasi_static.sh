#!/usr/bin/env bash
# Preconditioner reuse across quasi-static time steps (issue 16: a step of a 10^6-molecule relaxation test costs
# at most 0.3x a fresh static solve of it, and 100 steps finish on 2 ranks). ONE run of the stress-relaxation test
# (run_scripts/scenes/example_cartilage_relaxation.toml at N^3 molecules, 1 s steps) measures both, so the
# machine's load moves them alike:
#   - the fresh solve: the t = 0 step, a compression applied as a step from the undeformed state (the static
#     solve of the instantaneous lattice: Newton from scratch, the multigrid built, set-up included): the
#     solver's seconds (summary.json) minus the time from the t = 0 row of history.csv to the last;
#   - each later step: the time between its history.csv row and the one before (rows are flushed as each step
#     ends; a watcher stamps them as they appear, every 10 ms).
# The step moves the top face by DISP (m, default -8e-7: 0.02 % of the 4 mm cube) while every other molecule
# starts where it was, so the top layer alone takes it at first: at N = 100 the example's 2 % (-8e-5 m, two
# lattice spacings) inverts its cells and the run stops; 0.02 % is 2 % of a spacing there.
# MODE=hold (default): the compression is held (the relaxation test itself). MODE=ramp: the top moves by a
# further 2 % over the STEPS steps, so every step moves the holds and Newton works (the reuse under motion).
# Newton and Krylov counts per step from PETSc's -snes_converged_reason / -ksp_converged_reason; peak RSS from
# summary.json (the largest rank's). LOGVIEW=1 adds -log_view (out/bench_quasi_static[_TAG]/run.log); PETSC='...'
# adds PETSc options (PETSC='-quasi_static_extrapolate false': each step starts from the last equilibrium).
#   bash run_scripts/bench_quasi_static.sh [N] [NP] [STEPS]     # defaults 100, 2, 100
#   MODE=ramp bash run_scripts/bench_quasi_static.sh 40 2 20
#   TISSUE=path/to/tissue bash run_scripts/bench_quasi_static.sh     # another binary (default build/tissue)
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
N="${1:-100}"
NP="${2:-2}"
STEPS="${3:-100}"
MODE="${MODE:-hold}"
DISP="${DISP:--8e-7}"
cd "$ROOT"
TISSUE="${TISSUE:-build/tissue}"
[ -x "$TISSUE" ] || bash run_scripts/build.sh tissue
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
out="$ROOT/out/bench_quasi_static${TAG:+_$TAG}"
rm -rf "$out" && mkdir -p "$out"
case "$MODE" in
  hold) history="[[0.0,1.0]]" ;;
  ramp) history="[[0.0,1.0],[$STEPS.0,2.0]]" ;;
  *) echo "MODE is hold or ramp" >&2; exit 2 ;;
esac
petsc=(-snes_converged_reason -ksp_converged_reason)
[ "${LOGVIEW:-0}" = 1 ] && petsc+=(-log_view)
# shellcheck disable=SC2206  # PETSc options, split on spaces
[ -n "${PETSC:-}" ] && petsc+=(${PETSC})
# The watcher: one "seconds row-count" line each time history.csv grows.
/usr/bin/python3 - "$out/run/history.csv" "$out/stamps.txt" "$out/done" <<'PY' &
import os, sys, time
path, stamps, done = sys.argv[1], sys.argv[2], sys.argv[3]
seen = 0
with open(stamps, "w") as log:
    while True:
        try:
            with open(path) as f:
                n = sum(1 for line in f if line.endswith("\n")) - 1  # rows after the header
        except OSError:
            n = 0
        if n > seen:
            log.write(f"{time.monotonic():.4f} {n}\n")
            log.flush()
            seen = n
        if os.path.exists(done):
            break
        time.sleep(0.01)
PY
watcher=$!
set +e
mpirun --oversubscribe -np "$NP" "$TISSUE" run run_scripts/scenes/example_cartilage_relaxation.toml \
  --set "body.molecules=[$N,$N,$N]" --set "fix.1.history=$history" \
  --set "fix.1.displacement=[0.0,0.0,$DISP]" --set solver.time_step=1.0 \
  --set "solver.end_time=$STEPS.0" --set output.progress=false --output "$out/run" -- "${petsc[@]}" \
  > "$out/run.log" 2>&1
rc=$?
set -e
touch "$out/done"  # the run's end (even a failed one): the watcher stops
wait "$watcher"
[ "$rc" = 0 ] || { tail -5 "$out/run.log"; exit "$rc"; }
/usr/bin/python3 - "$out" "$STEPS" "$N" "$NP" "$MODE" "$DISP" <<'PY'
import json, re, statistics, sys
out, steps, n, np_, mode, disp = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], sys.argv[5], sys.argv[6]
summary = json.load(open(f"{out}/run/summary.json"))
solver = summary["solver"]
# Each row's time of appearance (a poll may see several rows at once: they share its stamp).
stamp = {}
for line in open(f"{out}/stamps.txt"):
    t, k = line.split()
    for row in range(len(stamp) + 1, int(k) + 1):
        stamp[row] = float(t)
rows = len(stamp)
assert rows == steps + 1, f"{rows} rows for {steps} steps"
fresh = solver["seconds"] - (stamp[rows] - stamp[1])
per_step = [stamp[k + 1] - stamp[k] for k in range(1, rows)]
# Newton and Krylov per step (t = 0 first): a step ends with a converged SNES solve; a failed one (CG on an
# indefinite tangent, then GMRES) is retried within the same step.
newton, krylov, n_now, k_now = [], [], 0, 0
for line in open(f"{out}/run.log"):
    m = re.search(r"Linear solve (?:converged|did not converge) due to \S+ iterations (\d+)", line)
    if m:
        k_now += int(m.group(1))
        continue
    m = re.search(r"Nonlinear solve (converged|did not converge) due to \S+ iterations (\d+)", line)
    if m:
        n_now += int(m.group(2))
        if m.group(1) == "converged":
            newton.append(n_now)
            krylov.append(k_now)
            n_now = k_now = 0
assert len(newton) == steps + 1, f"{len(newton)} converged solves for {steps} steps"
later_n, later_k = newton[1:], krylov[1:]
med = statistics.median(per_step)
print(f"mode {mode}, top moved by {disp} m: {n}^3 = {n ** 3:,} molecules, {np_} ranks, {steps} steps of 1 s; solver {solver['seconds']:.1f} s "
      f"in all, peak RSS {summary['peak_memory_bytes'] / 2**30:.2f} GiB (largest rank)")
print(f"fresh t = 0 solve {fresh:.2f} s ({newton[0]} Newton, {krylov[0]} Krylov)")
print(f"later steps: min {min(per_step):.3f} / median {med:.3f} / max {max(per_step):.3f} s; Newton per step "
      f"{min(later_n)}-{max(later_n)} (total {sum(later_n)}), Krylov per step {min(later_k)}-{max(later_k)} "
      f"(total {sum(later_k)})")
print(f"ratio median step / fresh solve {med / fresh:.3f} (max step / fresh {max(per_step) / fresh:.3f}); issue 16 asks <= 0.3")
print(f"| {n ** 3:,} | {np_} | {mode} | {fresh:.2f} | {min(per_step):.3f} / {med:.3f} / {max(per_step):.3f} | "
      f"{med / fresh:.3f} | {newton[0]} / {krylov[0]} | {min(later_n)}-{max(later_n)} / {min(later_k)}-{max(later_k)} | "
      f"{summary['peak_memory_bytes'] / 2**30:.2f} GiB |")
PY
