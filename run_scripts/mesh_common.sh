# Sourced by the mesh benchmarks (bench_mesh.sh, bench_mesh_memory.sh): the repository root, MPI as root, and
# the cartilage layer (run_scripts/scenes/cartilage_layer.geo) meshed once per element size.
#   source "$(dirname "$0")/mesh_common.sh"; mesh=$(cartilage_mesh OUT_DIR H)
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1

# Prints the path of OUT_DIR/cartilage_hH.msh, meshing it first (Gmsh 4.1 format) unless it is there already;
# written to a .tmp and renamed, so an interrupted run leaves no half mesh behind.
cartilage_mesh() {
  local out="$1" h="$2"
  local mesh="$out/cartilage_h$h.msh"
  mkdir -p "$out"
  command -v gmsh > /dev/null || bash run_scripts/install_deps.sh >&2
  if [ ! -s "$mesh" ]; then
    echo "meshing (h = $h) ..." >&2
    nice gmsh -3 -format msh41 -setnumber h "$h" run_scripts/scenes/cartilage_layer.geo -o "$mesh.tmp" \
      > "$out/gmsh.log" 2>&1
    mv "$mesh.tmp" "$mesh"
  fi
  echo "$mesh"
}
