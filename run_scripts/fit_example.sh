#!/usr/bin/env bash
#                 tissue fit: a creep curve back to its Prony series (docs/fit.md)
#
# What it does:
#   1. makes the "measured" curve: the solver's own creep of run_scripts/scenes/fit_creep.toml at gamma = 1,
#      tau = 2 s, with 1 % Gaussian noise (seeded), into out/fit_example/measured.csv;
#   2. fits gamma and tau from the scene's start values (0.3, 0.5 s) on NP ranks: out/fit_creep/fit.json,
#      fitted.toml and the fitted run's history.csv;
#   3. plots measured and fitted curves into docs/examples/fit_creep.png (run_scripts/plot_fit.py);
#   4. the start-value study: the same fit from a grid of start values, one line each (forward runs, result).
# Sample runs:
#   bash run_scripts/fit_example.sh            # 2 ranks
#   NP=1 STUDY=0 bash run_scripts/fit_example.sh
set -euo pipefail
cd "$(dirname "$0")/.."
NP=${NP:-2}
STUDY=${STUDY:-1}
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
TISSUE=${TISSUE:-build/tissue}
PY=/usr/bin/python3  # Debian's, with python3-matplotlib
mkdir -p out/fit_example docs/examples
SCENE=run_scripts/scenes/fit_creep.toml

# 1. The measured curve (the [fit] table is not part of a plain run: strip it).
sed '/^\[fit\]/,$d' "$SCENE" > out/fit_example/truth.toml
"$TISSUE" run out/fit_example/truth.toml --set body.viscoelastic.gamma.0=1.0 --set body.viscoelastic.tau.0=2.0 \
  --set output.progress=false --output out/fit_example/truth > /dev/null
$PY - <<'PYEOF'
import csv, random
rows = [r for r in csv.DictReader(open("out/fit_example/truth/history.csv")) if r["elongation"]]
rng = random.Random(5)
with open("out/fit_example/measured.csv", "w") as f:
    f.write("time,elongation\n")
    for r in rows:
        f.write("%s,%.17g\n" % (r["time"], float(r["elongation"]) * (1 + 0.01 * rng.gauss(0, 1))))
PYEOF

# 2. The fit.
start=$(date +%s.%N)
mpirun --oversubscribe -np "$NP" "$TISSUE" fit "$SCENE" --output out/fit_creep
echo "fit on $NP ranks: $(echo "$(date +%s.%N) - $start" | bc) s"

# 3. The picture.
$PY run_scripts/plot_fit.py out/fit_creep docs/examples/fit_creep.png

# 4. How the result depends on the start values.
if [ "$STUDY" = 1 ]; then
  echo "start gamma, start tau -> forward runs, gamma, tau, |r|"
  for g in 0.05 0.3 5.0 50.0; do
    for t in 0.05 0.5 10.0 80.0; do
      mpirun --oversubscribe -np "$NP" "$TISSUE" fit "$SCENE" --set body.viscoelastic.gamma.0=$g \
        --set body.viscoelastic.tau.0=$t --set output.progress=false --output out/fit_study > /dev/null 2>&1 || true
      $PY -c "import json; r = json.load(open('out/fit_study/fit.json')); p = r['parameters']; \
print('%5g, %5g -> %3d, %.5f, %.5f, %.3e' % ($g, $t, r['forward_runs'], p['body.viscoelastic.gamma.0'], \
p['body.viscoelastic.tau.0'], r['residual_norm']))"
      rm -f out/fit_study/fit.json
    done
  done
fi
