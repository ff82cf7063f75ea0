#!/usr/bin/env bash
# The anatomical example of docs/mesh.md: meshes run_scripts/scenes/cartilage_layer.geo with Debian's gmsh, runs
# run_scripts/scenes/example_cartilage.toml on NP ranks (default 2) and renders docs/examples/cartilage.png with
# ParaView (xvfb-run + pvbatch; skipped with a message when absent). With INTERIOR, the same layer as a random
# cloud inside the mesh's volume (topology = "random", INTERIOR molecules sampled inside; docs/mesh.md) into
# out/cartilage_random and docs/examples/cartilage_random.png.
#   bash run_scripts/cartilage_example.sh [NP] [H] [INTERIOR]   # H: gmsh's largest element size (default 0.0008 m)
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
NP="${1:-2}"
H="${2:-0.0008}"
INTERIOR="${3:-}"
cd "$ROOT"
[ -x build/tissue ] || bash run_scripts/build.sh tissue
command -v gmsh > /dev/null || bash run_scripts/install_deps.sh
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
out="$ROOT/out/cartilage"
name=cartilage
cloud=()
if [ -n "$INTERIOR" ]; then
  out="$ROOT/out/cartilage_random"
  name=cartilage_random
  cloud=(--set body.topology=random --set "body.interior_molecules=$INTERIOR")
fi
rm -rf "$out" && mkdir -p "$out"
gmsh -3 -format msh41 -setnumber h "$H" run_scripts/scenes/cartilage_layer.geo -o "$out/cartilage_layer.msh" \
  > "$out/gmsh.log" 2>&1 || { tail -5 "$out/gmsh.log"; exit 1; }
mpirun --oversubscribe -np "$NP" build/tissue run run_scripts/scenes/example_cartilage.toml \
  --set "body.file=$out/cartilage_layer.msh" "${cloud[@]}" --output "$out" | tee "$out/run.log"
if command -v pvbatch > /dev/null && command -v xvfb-run > /dev/null; then
  mkdir -p docs/examples
  # --force-offscreen-rendering: this Xvfb offers no GLX visual ParaView accepts
  xvfb-run -a pvbatch --force-offscreen-rendering "$ROOT/run_scripts/render_mesh.py" "$out/tissue.xdmf" \
    "cartilage layer${INTERIOR:+, random cloud of $INTERIOR inside}, $NP ranks" "$ROOT/docs/examples/$name.png" 20 > "$out/render.log" 2>&1 || echo "  rendering failed: see $out/render.log"
else
  echo "  (ParaView's pvbatch or xvfb-run missing: no image)"
fi
