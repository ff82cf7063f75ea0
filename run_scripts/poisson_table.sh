#!/usr/bin/env bash
# Any Poisson ratio (docs/poisson.md): the tissue CLI on a 6 x 6 x 6 block (homogenized, face diagonals) for
# nu in {0, 0.1, 0.25, 0.4, 0.45, 0.49, 0.499} and cells 1:1, 1:2, 1:4 (flat) and 2:1, 4:1 (tall), at strain 1e-7:
# tension on rollers (E, both lateral nu), exact simple shear (G), confined compression (H_A); prints the largest
# relative error of each against its closed form, a markdown table (docs/poisson.md's).
#
#   bash run_scripts/poisson_table.sh            # RANKS=2 N=6 by default
set -euo pipefail
cd "$(dirname "$0")/.."
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
RANKS=${RANKS:-2}
N=${N:-6}
TISSUE=${TISSUE:-build/tissue}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
E=1000.0

scene() {  # scene KIND NU HZ -> the scene file's path
  local kind=$1 nu=$2 hz=$3 f="$work/$1_$2_$3.toml"
  local Lx Lz
  Lx=$(python3 -c "print(($N - 1) * 1.0)")
  Lz=$(python3 -c "print(($N - 1) * $hz)")
  {
    printf 'title = "poisson table"\n[body]\nmolecules = [%d, %d, %d]\nspacing = [1.0, 1.0, %s]\n' "$N" "$N" "$N" "$hz"
    printf 'topology = "face-diagonals"\nyoungs_modulus = %s\npoisson_ratio = %s\n' "$E" "$nu"
    printf '[calibration]\nmethod = "homogenized"\n'
    case $kind in
      tension)
        printf '[[fix]]\nface = "z-"\nmode = "roller"\n[[load]]\nface = "z+"\nforce = [0.0, 0.0, %s]\n' \
          "$(python3 -c "print($E * 1e-7 * $Lx * $Lx)")";;
      shear)
        local tau
        tau=$(python3 -c "print($E / (2 * (1 + $nu)) * 1e-7)")
        printf '[[fix]]\nface = "z-"\nmode = "clamped"\n'
        printf '[[load]]\nface = "z+"\nforce = [%s, 0.0, 0.0]\n' "$(python3 -c "print($tau * $Lx * $Lx)")"
        printf '[[load]]\nface = "x+"\nforce = [0.0, 0.0, %s]\n' "$(python3 -c "print($tau * $Lx * $Lz)")"
        printf '[[load]]\nface = "x-"\nforce = [0.0, 0.0, %s]\n' "$(python3 -c "print(-$tau * $Lx * $Lz)")";;
      confined)
        printf '[[fix]]\nface = "%s"\nmode = "roller"\n' z- x- x+ y- y+
        printf '[[load]]\nface = "z+"\nforce = [0.0, 0.0, %s]\n' "$(python3 -c "print(-$E * 1e-7 * $Lx * $Lx)")";;
    esac
    printf '[solver]\nkind = "static"\ntolerance = 1e-9\n[output]\ndirectory = "%s/out"\nprogress = false\n' "$work"
  } > "$f"
  echo "$f"
}

echo "| nu | cells (h_z / h_x) | E error | nu_x error | nu_y error | G error | H_A error | static seconds (3 runs) |"
echo "|---|---|---|---|---|---|---|---|"
for nu in 0.0 0.1 0.25 0.4 0.45 0.49 0.499; do
  for hz in 1.0 0.5 0.25 2.0 4.0; do
    row="| $nu | $hz |"
    seconds=0
    for kind in tension shear confined; do
      f=$(scene "$kind" "$nu" "$hz")
      mpirun --oversubscribe -np "$RANKS" "$TISSUE" run "$f" --output "$work/$kind" > /dev/null 2> "$work/err" ||
        { echo "failed: $kind nu $nu h_z $hz: $(tail -1 "$work/err")" >&2; exit 1; }
      cp "$work/$kind/summary.json" "$work/$kind.json"
    done
    python3 - "$work" "$nu" <<'PY' | sed "s/^/$row/"
import json, sys
w, nu = sys.argv[1], float(sys.argv[2])
E = 1000.0
t, s, c = (json.load(open(f"{w}/{k}.json")) for k in ("tension", "shear", "confined"))
G = E / (2 * (1 + nu))
HA = E * (1 - nu) / ((1 + nu) * (1 - 2 * nu))
def err(x, ref): return f"{(x - ref) / (ref if ref else 1):+.1e}"
nus = t["poisson_ratios_measured"]
secs = sum(d["solver"]["seconds"] for d in (t, s, c))
print(f" {err(t['youngs_modulus_measured'], E)} | {nus[0] - nu:+.1e} | {nus[1] - nu:+.1e} | "
      f"{err(s['shear_modulus_measured'], G)} | {err(c['aggregate_modulus_measured'], HA)} | {secs:.2f} |")
PY
  done
done
