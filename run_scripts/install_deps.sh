#!/usr/bin/env bash
# Installs the Debian 12 packages tissue needs, and nothing when they are all present.
#
#   bash run_scripts/install_deps.sh          # build + test dependencies
#   TISSUE_EXTRAS=1 bash run_scripts/install_deps.sh   # also ParaView for rendering pictures, and SciPy for
#                                                      # run_scripts/mg_near_incompressible.py
set -euo pipefail
pkgs=(build-essential cmake pkg-config git
      openmpi-bin libopenmpi-dev
      libpetsc-real-dev libmetis-dev libhdf5-openmpi-dev hdf5-tools
      libeigen3-dev libgtest-dev
      libtoml11-dev libcli11-dev nlohmann-json3-dev libfmt-dev
      libcgal-dev gmsh libgmsh-dev   # libgmsh-dev: meshes through the Gmsh library (io/gmsh_mesh.cpp)
      python3 python3-h5py python3-meshio python3-numpy python3-matplotlib
      clang-14 libclang-rt-14-dev    # the libFuzzer targets that test.sh runs (run_scripts/fuzz.sh)
      valgrind)                      # runs the kernels' AVX2 clones in tests (tests/CMakeLists.txt)
if [ "${TISSUE_EXTRAS:-0}" = 1 ]; then pkgs+=(paraview python3-paraview xvfb python3-scipy); fi
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
echo "install_deps: installing ${missing[*]}"
SUDO=; [ "$(id -u)" -ne 0 ] && SUDO=sudo
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
