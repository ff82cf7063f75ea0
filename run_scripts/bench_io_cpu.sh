#!/usr/bin/env bash
#                                tissue: the CPU a snapshot write costs, old binary against new
#
# Run with:      bash run_scripts/bench_io_cpu.sh OLD_TISSUE NEW_TISSUE [SIDE] [RANKS] [REPEAT]
#
# Sample run:    bash run_scripts/bench_io_cpu.sh ../integ3/build/tissue build/tissue 100 1 3
#
# Description:   The write's CPU seconds (user + system, all ranks, /usr/bin/time of mpirun) do not depend on how
#                loaded the machine is, its wall time does (a writer given a fraction of a core, while dd waits on
#                the disk). For a SIDE^3 face-diagonals box (default 100: 10^6 molecules), `solver.steps = 0`
#                (the rest state, no time stepping), each binary runs twice per repetition, alternating old and new:
#                once writing final.h5 with every field (379 MB at 100^3) and once with `output.fields = []` (no
#                snapshot at all). The write's CPU is the difference; MB/s a core = the file's bytes over it.
#                Prints one line per binary and repetition, then the medians. Same scene as bench_io.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
OLD=${1:?old tissue binary}
NEW=${2:?new tissue binary}
SIDE=${3:-100}
RANKS=${4:-1}
REPEAT=${5:-3}
OUT=${OUT:-out/bench_io_cpu}
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
mkdir -p "$OUT"
source run_scripts/io_scene.sh
io_scene "$OUT/all.toml" "bench_io_cpu $SIDE^3" "$SIDE" "$OUT/all" "$ALL_FIELDS"
io_scene "$OUT/none.toml" "bench_io_cpu $SIDE^3" "$SIDE" "$OUT/none" "[]"
cpu() {  # $1 binary, $2 scene: user + system seconds of the whole run
  rm -rf "${OUT:?}/$2"
  /usr/bin/time -f "%U %S" -o "$OUT/time" mpirun --oversubscribe -np "$RANKS" "$1" run "$OUT/$2.toml" > "$OUT/$2.log" 2>&1
  awk '{ print $1 + $2 }' "$OUT/time"
}
echo "uptime: $(uptime)"
printf "%4s %5s %12s %12s %12s %12s %14s\n" rep which cpu_all_s cpu_none_s write_cpu_s bytes "MB/s_a_core"
rows=()
for rep in $(seq 1 "$REPEAT"); do
  for which in old new; do
    bin=$OLD
    [[ $which == new ]] && bin=$NEW
    a=$(cpu "$bin" all)
    bytes=$(stat -c %s "$OUT/all/final.h5")
    n=$(cpu "$bin" none)
    line=$(awk -v r=$rep -v w=$which -v a=$a -v n=$n -v b=$bytes \
      'BEGIN { d = a - n; printf "%4d %5s %12.2f %12.2f %12.2f %12d %14.1f", r, w, a, n, d, b, (d > 0 ? b / d / 1e6 : 0) }')
    echo "$line"
    rows+=("$line")
  done
done
echo "uptime: $(uptime)"
for which in old new; do
  printf "%s\n" "${rows[@]}" | awk -v w=$which '$2 == w { print $5 }' | sort -n |
    awk -v w=$which -v b="$(stat -c %s "$OUT/all/final.h5")" '{ v[NR] = $1 } END { m = v[int((NR + 1) / 2)];
      printf "median %s: write CPU %.2f s, %.1f MB/s a core\n", w, m, b / m / 1e6 }'
done
