#!/usr/bin/env bash
# The examples of docs/anisotropy.md: the measured table (fibres along x, y, z; E_L, E_T, the three Poisson ratios,
# G_L, G_T at strain 1e-7) and the ligament strip pulled through the toe (quasi-static ramp to 100 N), its
# stress-strain curve (python3-matplotlib) and its fibre field rendered with ParaView (pvbatch under xvfb-run), on
# NP ranks (default 2):
#   bash run_scripts/anisotropy_examples.sh [NP]
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
NP="${1:-2}"
cd "$ROOT"
[ -x build/tissue ] || bash run_scripts/build.sh tissue
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
PYTHON="${PYTHON:-/usr/bin/python3}"  # Debian's, with python3-matplotlib
"$PYTHON" -c "import matplotlib" 2> /dev/null || { apt-get update -qq && apt-get install -y -qq python3-matplotlib; }
mkdir -p docs/examples out
"$PYTHON" run_scripts/anisotropy_table.py "$NP"
for name in ligament_fibres_aligned ligament_fibres; do
  /usr/bin/time -f "$name: %e s" mpirun --oversubscribe -np "$NP" build/tissue run \
    "run_scripts/scenes/example_$name.toml" > "out/$name.log"
done
# 10 x 4 x 2 mm strip: A = 8e-6 m^2, L = 10 mm; toe up to fibre stretch 1.03; E_L = 400 MPa (the preset)
"$PYTHON" run_scripts/plot_anisotropy.py docs/examples/ligament_fibres_curve.png out/ligament_fibres_aligned \
  out/ligament_fibres 8e-6 0.010 1.03 400e6
if command -v pvbatch > /dev/null && command -v xvfb-run > /dev/null; then
  xvfb-run -a pvbatch run_scripts/render_fibres.py "$ROOT/out/ligament_fibres/tissue.xdmf" \
    "$ROOT/docs/examples/ligament_fibres.png" 0.0005
fi
echo "plots: docs/examples/ligament_fibres_curve.png docs/examples/ligament_fibres.png"
