#!/usr/bin/env bash
# Peak memory per rank and wall time of a large Gmsh mesh (#21: no rank holds the whole mesh; the largest rank at
# 3 ranks at most 0.6x the 1-rank run). The cartilage layer (run_scripts/scenes/cartilage_layer.geo) meshed at
# about 300,000 molecules, run at 1 and 3 ranks by run_scripts/peak_rss.py, which records each rank's own peak and
# that of its forked Gmsh reader. Two scenes: "build" (the model built, one dynamic step: what construction
# costs) and "static" (the example's static solve). Prints a table and appends nothing: copy it to
# docs/benchmarks.md with the date.
#   bash run_scripts/bench_mesh_memory.sh [H] [SCENES]   # H: element size (default 0.000172 m: ~300,000 molecules)
#   TISSUE=path/to/tissue bash run_scripts/bench_mesh_memory.sh     # another binary (an older build, to compare)
# Variants, alternated (the machine is shared: compare ratios of neighbouring runs, not absolute times):
#   VARIANTS='old|../old/build/tissue|;new|build/tissue|;scalable|build/tissue|-matptap_via scalable' REPEAT=2 \
#     bash run_scripts/bench_mesh_memory.sh 0.0003 static
# Each variant is LABEL|BINARY|PETSC OPTIONS (given after `--`); the 3-rank runs go variant after variant, REPEAT
# times; the 1-rank run (the memory reference) once, with the first variant. The table gives each 3-rank run's
# wall time (the whole mpirun), the solve's Newton and Krylov iterations, the elongation, and the peaks; then each
# variant's wall time as a ratio to the first variant's run of the same round.
set -euo pipefail
source "$(dirname "$0")/mesh_common.sh"  # ROOT (the working directory), MPI as root, cartilage_mesh
H="${1:-0.000172}"
SCENES="${2:-build static}"
TISSUE="${TISSUE:-$ROOT/build/tissue}"
REPEAT="${REPEAT:-1}"
if [ -z "${VARIANTS:-}" ]; then
  [ -x "$TISSUE" ] || bash run_scripts/build.sh tissue
  VARIANTS="$(basename "$(dirname "$(dirname "$TISSUE")")")|$TISSUE|"
fi
out="$ROOT/out/bench_memory"
mesh="$(cartilage_mesh "$out" "$H")"
IFS=';' read -r -a variants <<< "$VARIANTS"
for v in "${variants[@]}"; do
  IFS='|' read -r label bin opts <<< "$v"
  [ -x "$bin" ] || { echo "bench_mesh_memory: variant $label: no binary $bin" >&2; exit 2; }
done
# run LABEL BINARY OPTIONS SCENE NP DIR
run() {
  local label=$1 bin=$2 opts=$3 scene=$4 np=$5 dir=$6 extra=()
  case "$scene" in
    build) extra=(--set solver.kind=dynamic --set solver.steps=1) ;;
    static) ;;
    *) echo "unknown scene $scene (build, static)" >&2; exit 2 ;;
  esac
  local petsc=()
  read -r -a petsc <<< "$opts"
  (( ${#petsc[@]} )) && petsc=(-- "${petsc[@]}")
  rm -rf "$dir" "$dir".rank*
  local start end
  start=$(date +%s.%N)
  nice mpirun --oversubscribe -np "$np" /usr/bin/python3 run_scripts/peak_rss.py "$dir" "$bin" run \
    run_scripts/scenes/example_cartilage.toml --set "body.file=$mesh" "${extra[@]}" \
    --set 'output.fields=["positions"]' --set output.progress=false --output "$dir" "${petsc[@]}" > "$dir.log" 2>&1
  end=$(date +%s.%N)
  echo "$(echo "$end - $start" | bc)" > "$dir.seconds"
  echo "$label|$opts|$dir" >> "$out/runs.list"
}
: > "$out/runs.list"
for scene in $SCENES; do
  IFS='|' read -r label bin opts <<< "${variants[0]}"
  run "$label" "$bin" "$opts" "$scene" 1 "$out/${label}_${scene}_np1"
  for ((r = 1; r <= REPEAT; ++r)); do
    for v in "${variants[@]}"; do
      IFS='|' read -r label bin opts <<< "$v"
      run "$label" "$bin" "$opts" "$scene" 3 "$out/${label}_${scene}_np3_r$r"
    done
  done
done
/usr/bin/python3 - "$out" "$SCENES" <<'PY'
import json, re, sys
out, scenes = sys.argv[1], sys.argv[2].split()
runs = [line.rstrip("\n").split("|") for line in open(f"{out}/runs.list")]
print("| scene | variant | PETSc options | ranks | round | wall s | Newton / Krylov its | elongation | rank: own peak / reader child MiB | largest own MiB | ratio to 1 rank | wall / first variant's |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|")
base, first_wall = {}, {}
ratios = {}
for label, opts, d in runs:
    s = json.load(open(f"{d}/summary.json"))
    scene = next(x for x in scenes if f"_{x}_np" in d)
    np_ = int(re.search(r"_np(\d+)", d).group(1))
    rnd = re.search(r"_r(\d+)$", d)
    rnd = int(rnd.group(1)) if rnd else 0
    ranks = [list(map(int, open(f"{d}.rank{r}").read().split())) for r in range(np_)]
    own = max(r[0] for r in ranks) / 1024
    if np_ == 1:
        base[scene] = own
    wall = float(open(f"{d}.seconds").read())
    key = (scene, rnd)
    if np_ > 1 and key not in first_wall:
        first_wall[key] = wall
    rel = wall / first_wall[key] if np_ > 1 else float("nan")
    if np_ > 1:
        ratios.setdefault((scene, label), []).append(rel)
    sv = s["solver"]
    cells = "; ".join(f"{r}: {x[0]/1024:.0f} / {x[1]/1024:.0f}" for r, x in enumerate(ranks))
    its = f"{sv['iterations']} / {sv['linear_iterations']}"
    print(f"| {scene} | {label} | `{opts}` | {np_} | {rnd or '-'} | {wall:.1f} | {its} | {s.get('elongation')} | {cells} | "
          f"{own:.0f} | {own / base[scene]:.2f} | {'-' if np_ == 1 else f'{rel:.2f}'} |")
for (scene, label), rs in ratios.items():
    rs = sorted(rs)
    print(f"{scene} {label}: wall / first variant's, per round: {', '.join(f'{r:.2f}' for r in rs)}; median {rs[len(rs) // 2]:.2f}")
PY
