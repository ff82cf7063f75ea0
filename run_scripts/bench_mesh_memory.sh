#!/usr/bin/env bash
# Peak memory per rank of a large Gmsh mesh (#21: no rank holds the whole mesh; the largest rank at 3 ranks at
# most 0.6x the 1-rank run). The cartilage layer (run_scripts/scenes/cartilage_layer.geo) meshed at about
# 300,000 molecules, run at 1 and 3 ranks by run_scripts/peak_rss.py, which records each rank's own peak and
# that of its forked Gmsh reader. Two scenes: "build" (the model built, one dynamic step: what construction
# costs) and "static" (the example's static solve). Prints a table and appends nothing: copy it to
# docs/benchmarks.md with the date.
#   bash run_scripts/bench_mesh_memory.sh [H] [SCENES]   # H: element size (default 0.000172 m: ~300,000 molecules)
#   TISSUE=path/to/tissue bash run_scripts/bench_mesh_memory.sh     # another binary (an older build, to compare)
set -euo pipefail
source "$(dirname "$0")/mesh_common.sh"  # ROOT (the working directory), MPI as root, cartilage_mesh
H="${1:-0.000172}"
SCENES="${2:-build static}"
TISSUE="${TISSUE:-$ROOT/build/tissue}"
[ -x "$TISSUE" ] || bash run_scripts/build.sh tissue
out="$ROOT/out/bench_memory"
mesh="$(cartilage_mesh "$out" "$H")"
tag="$(basename "$(dirname "$(dirname "$TISSUE")")")"
for scene in $SCENES; do
  case "$scene" in
    build) extra=(--set solver.kind=dynamic --set solver.steps=1) ;;
    static) extra=() ;;
    *) echo "unknown scene $scene (build, static)" >&2; exit 2 ;;
  esac
  for np in 1 3; do
    dir="$out/${tag}_${scene}_np$np"
    rm -rf "$dir" "$dir".rank*
    start=$(date +%s.%N)
    nice mpirun --oversubscribe -np "$np" /usr/bin/python3 run_scripts/peak_rss.py "$dir" "$TISSUE" run \
      run_scripts/scenes/example_cartilage.toml --set "body.file=$mesh" "${extra[@]}" \
      --set 'output.fields=["positions"]' --set output.progress=false --output "$dir" > "$dir.log" 2>&1
    end=$(date +%s.%N)
    echo "$(echo "$end - $start" | bc)" > "$dir.seconds"
  done
done
/usr/bin/python3 - "$out" "$tag" "$SCENES" <<'PY'
import json, sys
out, tag, scenes = sys.argv[1], sys.argv[2], sys.argv[3].split()
print(f"binary: {tag}")
print("| scene | ranks | molecules | wall s | rank: own peak MiB / reader child MiB / wait4 max MiB | largest rank (max of own and reader) MiB | ratio to 1 rank | largest own + reader MiB | ratio |")
print("|---|---|---|---|---|---|---|---|---|")
for scene in scenes:
    base = None
    for np_ in (1, 3):
        d = f"{out}/{tag}_{scene}_np{np_}"
        s = json.load(open(f"{d}/summary.json"))
        ranks = [list(map(int, open(f"{d}.rank{r}").read().split())) for r in range(np_)]
        largest = max(r[2] for r in ranks) / 1024
        summed = max(r[3] for r in ranks) / 1024
        if base is None:
            base = (largest, summed)
        cells = "; ".join(f"{r}: {x[0]/1024:.0f} / {x[1]/1024:.0f} / {x[2]/1024:.0f}" for r, x in enumerate(ranks))
        wall = float(open(f"{d}.seconds").read())
        print(f"| {scene} | {np_} | {s['molecules']:,} | {wall:.1f} | {cells} | {largest:.0f} | {largest/base[0]:.2f} | "
              f"{summed:.0f} | {summed/base[1]:.2f} |")
PY
