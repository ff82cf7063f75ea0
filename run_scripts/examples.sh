#!/usr/bin/env bash
# The example scenes of docs/examples.md: runs each on NP ranks (default 2) and renders its final state to
# docs/examples/<name>.png with ParaView (xvfb-run + pvbatch; skipped with a message when absent).
# Usage: bash run_scripts/examples.sh [build/tissue]        (NP=3 bash run_scripts/examples.sh ...)
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
TISSUE=$(realpath "${1:-$ROOT/build/tissue}")
NP=${NP:-2}
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
mkdir -p "$ROOT/docs/examples"
for name in indenter two_pads drop ligament_cyclic; do
  scene="$ROOT/run_scripts/scenes/example_$name.toml"
  out="$ROOT/out/example_$name"
  echo "== $name"
  mpirun --oversubscribe -np "$NP" "$TISSUE" run "$scene" --output "$out" --set output.progress=false
  /usr/bin/python3 - "$out/summary.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
keys = ["molecules", "ranks", "contact_force", "body_contact_force", "center_of_mass", "kinetic_energy", "time",
        "wall_seconds"]
print("  " + ", ".join(f"{k} = {s.get(k)}" for k in keys))
print(f"  solver: {s['solver']['kind']}, {s['solver']['iterations']} iterations, residual {s['solver']['residual']}, "
      f"converged {s['solver']['converged']}")
PY
  if command -v pvbatch > /dev/null && command -v xvfb-run > /dev/null; then
    xvfb-run -a pvbatch "$ROOT/run_scripts/render_example.py" "$out/tissue.xdmf" "$scene" \
      "$ROOT/docs/examples/$name.png" > "$out/render.log" 2>&1 || echo "  rendering failed: see $out/render.log"
    echo "  image: docs/examples/$name.png"
  else
    echo "  (ParaView's pvbatch or xvfb-run missing: no image)"
  fi
done
