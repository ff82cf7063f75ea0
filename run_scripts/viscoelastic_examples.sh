#!/usr/bin/env bash
# The examples of docs/viscoelastic.md: ligament creep under a constant pull and cartilage stress relaxation after
# a ramped compression, both quasi-static with Prony-series connections, and a loading-unloading hysteresis loop
# (run_scripts/hysteresis_example.py), on NP ranks (default 2); plots their history.csv into docs/examples/visco_*.png
# (python3-matplotlib).
#   bash run_scripts/viscoelastic_examples.sh [NP]
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
NP="${1:-2}"
cd "$ROOT"
[ -x build/tissue ] || bash run_scripts/build.sh tissue
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
PYTHON="${PYTHON:-/usr/bin/python3}"  # Debian's, with python3-matplotlib
"$PYTHON" -c "import matplotlib" 2> /dev/null || { apt-get update -qq && apt-get install -y -qq python3-matplotlib; }
mkdir -p docs/examples
for name in ligament_creep cartilage_relaxation cartilage_confined_relaxation; do
  scene="run_scripts/scenes/example_$name.toml"
  /usr/bin/time -f "$name: %e s" mpirun --oversubscribe -np "$NP" build/tissue run "$scene" > "out/visco_$name.log"
done
"$PYTHON" run_scripts/plot_history.py docs/examples/visco_ligament_creep.png \
  "Ligament creep, 40 N on 16 mm^2 (E = 400 MPa relaxed)" \
  "out/visco/ligament_creep:force_z:applied force (N)" "out/visco/ligament_creep:elongation:elongation (m)"
"$PYTHON" run_scripts/plot_history.py docs/examples/visco_cartilage_relaxation.png \
  "Cartilage stress relaxation, 2 % ramped in 1 s and held" \
  "out/visco/cartilage_relaxation:reaction1_z:reaction of the moving face (N)"
# confined compression: against the closed form c H_A(t) A eps, c from an elastic run of the same compression
mpirun --oversubscribe -np "$NP" build/tissue run run_scripts/scenes/example_cartilage_confined_relaxation.toml \
  --set 'body.viscoelastic.gamma=[0.0,0.0]' --set 'fix.1.history=[[0.0,1.0]]' --set solver.end_time=0.25 \
  --output out/visco/cartilage_confined_elastic > out/visco_cartilage_confined_elastic.log
"$PYTHON" run_scripts/plot_confined_relaxation.py out/visco/cartilage_confined_relaxation \
  out/visco/cartilage_confined_elastic docs/examples/visco_cartilage_confined.png
"$PYTHON" run_scripts/hysteresis_example.py "$NP"  # the loading-unloading loop against pi E''/E K a^2
echo "plots: docs/examples/visco_ligament_creep.png docs/examples/visco_cartilage_relaxation.png docs/examples/visco_cartilage_confined.png docs/examples/visco_hysteresis.png"
