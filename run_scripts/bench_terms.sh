#!/usr/bin/env bash
# Cost of the physics terms on the explicit solver: dynamic steps/s on a 60^3 face-diagonal lattice (216,000
# molecules, 1.25 M connections), one rank, with and without [physics] terms in the scene, and (optionally) for a
# build without the term code (BASE=path/to/tissue, e.g. a build of the commit before the terms).
# steps/s = 1000 / (cpu(1200 steps) - cpu(200 steps)), so set-up and output cancel; cpu = the process's user +
# system seconds (less sensitive than wall time to other jobs on a shared machine); REPS repetitions, best kept.
# Usage: bash run_scripts/bench_terms.sh [build/tissue]      (BASE=/tmp/base/build/tissue REPS=3 optional)
set -euo pipefail
TISSUE=${1:-build/tissue}
REPS=${REPS:-3}
DIR=$(mktemp -d)
cat > "$DIR/plain.toml" <<TOML
title = "explicit benchmark: 60^3 lattice, dynamic"
[body]
molecules = [60, 60, 60]
spacing = [0.001, 0.001, 0.001]
topology = "face-diagonals"
material = "cartilage"
[[fix]]
face = "z-"
[[load]]
face = "z+"
force = [0.0, 0.0, 1.0]
[solver]
kind = "dynamic"
time_step = 1e-8
[output]
directory = "$DIR/out"
fields = ["positions"]
progress = false
TOML
sed 's/^\[solver\]/[physics]\ngravity = [0.0, 0.0, -9.81]\nviscosity = 1e-4\n\n[solver]/' "$DIR/plain.toml" > "$DIR/physics.toml"
wall() {  # cpu seconds (user + system) of one run: $1 binary, $2 scene, $3 steps
  /usr/bin/time -f "%U %S" -o "$DIR/time" "$1" run "$2" --set solver.steps="$3" > /dev/null 2>&1
  awk '{print $1 + $2}' "$DIR/time"
}
rate() {  # best steps/s over REPS: $1 binary, $2 scene
  local best=0
  for _ in $(seq "$REPS"); do
    local a b
    a=$(wall "$1" "$2" 200); b=$(wall "$1" "$2" 1200)
    best=$(python3 -c "print(max($best, 1000.0 / ($b - $a)))")
  done
  echo "$best"
}
printf "%-40s %10s\n" "configuration" "steps/s"
if [ -n "${BASE:-}" ]; then printf "%-40s %10.2f\n" "without term code ($BASE)" "$(rate "$BASE" "$DIR/plain.toml")"; fi
printf "%-40s %10.2f\n" "terms compiled in, no [physics]" "$(rate "$TISSUE" "$DIR/plain.toml")"
printf "%-40s %10.2f\n" "gravity + viscosity" "$(rate "$TISSUE" "$DIR/physics.toml")"
rm -rf "$DIR"
