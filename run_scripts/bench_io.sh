#!/usr/bin/env bash
#                                tissue: HDF5 write bandwidth
#
# Run with:      [REPEAT=3] bash run_scripts/bench_io.sh [SIDE ...]        (default sides: 100 160 216)
#
# Sample runs:   bash run_scripts/bench_io.sh 100               # 1 million molecules
#                RANKS=4 OUT=/scratch/me/bench bash run_scripts/bench_io.sh 216   # 10 million
#
# Description:   For each SIDE, a SIDE^3 face-diagonals box (216^3 = 10.08 million molecules, about 90 million
#                connections) is written once as a snapshot, final.h5 with every field
#                (solver.kind=dynamic, solver.steps=0: the rest state, no time stepping), by `mpirun -np RANKS
#                tissue run`. A watcher (one Python process, polling every 2 ms: no process started per poll, which
#                took CPU from the ranks on a 2-core machine) times the write from the moment final.h5.tmp appears
#                (H5Fcreate, after the rows have been put in original order) to the moment it is renamed to final.h5
#                (H5Fclose, the seal and its fsync done, on every rank); then, at once, an fsync of that file alone
#                (as dd's: nothing should be left to flush, the seal's fsync came before the rename) and the flushed
#                time is reported too. The reference, in the same sample right after it: dd of the same
#                number of bytes of zeros, `bs=1M conv=fdatasync` (1 MiB writes, timed to the end of its flush, as
#                ours ends with fsync), into the same directory. REPEAT samples (default 3), each ours then dd,
#                alternating, so that both see the same minutes of a shared machine and the same page-cache state
#                (each right after a process of the same size exited). Prints one line per sample: molecules,
#                bytes, ranks, write s, MB/s (page cache), MB/s (flushed), dd MB/s, ours / dd; then the medians and
#                the ratio of the medians (dd alone moved 1.7x between samples a minute apart: one pair decides
#                nothing). Results and machine: docs/checkpoint.md, docs/benchmarks.md.
#
#                Memory (after the sizes, in the same run; MEM_SIDE=0 skips it): for RANKS in MEM_RANKS (default
#                "1 2"), the LAMMPS peer lattice (run_scripts/scenes/peer_lattice.toml, MEM_SIDE^3 molecules, default
#                100: 10^6), 20 dynamic steps, once with `output.fields = []` (no snapshot) and once writing
#                positions and velocities every 10 steps (snapshots at steps 10 and 20, and final.h5): the peak
#                (summary.json's peak_memory_bytes, the largest rank) per molecule of both and their ratio (target:
#                at most 1.2, issue 18 item 4). Files are streamed in pieces (io/row_stream.hpp), so the ratio
#                should not grow with the sample or the rank count. Then the restart (issue 18 item 1, target 1.2):
#                the same 20 steps with a checkpoint at step 10 (`output.fields = []`), and `tissue restart` of
#                that checkpoint on the same ranks to step 20; the table's last columns are the two peaks per
#                molecule and the restart's over the run without output. Restarts read in pieces too.
set -euo pipefail
cd "$(dirname "$0")/.."
source run_scripts/io_scene.sh
TISSUE=${TISSUE:-build/tissue}
RANKS=${RANKS:-$(nproc)}
OUT=${OUT:-out/bench_io}
SIDES=("$@")
[[ ${#SIDES[@]} -gt 0 ]] || SIDES=(100 160 216)
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
mkdir -p "$OUT"

echo "machine: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), $(nproc) cores, \
$(free -g | awk '/Mem:/ {print $2}') GB; file system: $(df -hT "$OUT" | awk 'NR==2 {print $1, $2, $3}')"
REPEAT=${REPEAT:-3}
# One timed write: runs tissue, prints "t_tmp t_done t_sync" (seconds since the start) or fails.
timed_write() {  # DIR
  python3 - "$1" "$RANKS" "$TISSUE" <<'PY'
import os, subprocess, sys, time
d, ranks, tissue = sys.argv[1:4]
tmp, done = os.path.join(d, "final.h5.tmp"), os.path.join(d, "final.h5")
with open(os.path.join(d, "log"), "w") as log:
    p = subprocess.Popen(["mpirun", "--oversubscribe", "-np", ranks, tissue, "run", os.path.join(d, "scene.toml")],
                         stdout=log, stderr=subprocess.STDOUT)
    t0 = time.monotonic()
    t_tmp = t_done = t_sync = None
    # The flush of the file alone, as soon as it has its name (as dd's fdatasync flushes its file alone): it was
    # `sync -f` (the whole file system: other processes' dirty pages too) after the process had exited (its
    # teardown counted as flushing).
    def flush():
        fd = os.open(done, os.O_RDONLY)
        os.fsync(fd)
        os.close(fd)
        return time.monotonic()
    while p.poll() is None:
        if t_tmp is None and os.path.exists(tmp):
            t_tmp = time.monotonic()
        if t_tmp is not None and t_done is None and os.path.exists(done):
            t_done = time.monotonic()
            t_sync = flush()
            break
        time.sleep(0.002)
    if p.wait() != 0 or t_tmp is None:
        sys.exit(1)
    if t_done is None:
        t_done = time.monotonic()
        t_sync = flush()
    print(t_tmp - t0, t_done - t0, t_sync - t0)
PY
}
timed_dd() {  # FILE COUNT: seconds
  python3 - "$1" "$2" <<'PY'
import subprocess, sys, time
t = time.monotonic()
subprocess.run(["dd", "if=/dev/zero", "of=" + sys.argv[1], "bs=1M", "count=" + sys.argv[2], "conv=fdatasync"],
               check=True, stderr=subprocess.DEVNULL)
print(time.monotonic() - t)
PY
}
printf "%10s %12s %6s %6s %10s %14s %14s %10s %8s\n" molecules bytes ranks sample write_s "MB/s(cache)" \
  "MB/s(flushed)" "dd_MB/s" "ours/dd"
for n in "${SIDES[@]}"; do
  dir="$OUT/side$n"
  molecules=$((n * n * n))
  rows=()
  for rep in $(seq 1 "$REPEAT"); do
    rm -rf "$dir"
    mkdir -p "$dir"
    io_scene "$dir/scene.toml" "bench_io $n^3" "$n" "$dir" "$ALL_FIELDS"
    times=$(timed_write "$dir") || { echo "side $n: tissue failed, see $dir/log"; continue 2; }
    bytes=$(stat -c %s "$dir/final.h5")
    # dd of the same size, flushed, right after ours (the disk's sequential write bandwidth from one process).
    count=$(( (bytes + 1048575) / 1048576 ))
    t_dd=$(timed_dd "$dir/dd.bin" "$count")
    rm -f "$dir/dd.bin" "$dir/final.h5"
    row=$(awk -v m=$molecules -v b=$bytes -v r=$RANKS -v k=$rep -v t="$times" -v tdd="$t_dd" -v c=$count \
      'BEGIN { split(t, a, " "); w = a[2] - a[1]; f = a[3] - a[1]; if (w <= 0) w = 0.01; d = c * 1048576 / tdd / 1e6;
               printf "%10d %12.0f %6d %6d %10.2f %14.1f %14.1f %10.1f %7.0f%%", m, b, r, k, w, b / w / 1e6,
                      b / f / 1e6, d, 100 * (b / w / 1e6) / d }')
    echo "$row"
    rows+=("$row")
  done
  printf "%s\n" "${rows[@]}" | awk '{ w[NR] = $5; c[NR] = $6; f[NR] = $7; d[NR] = $8; m = $1; b = $2; r = $3 }
    function median(v, n,   i, j, t) { for (i = 1; i <= n; ++i) for (j = i + 1; j <= n; ++j) if (v[j] < v[i]) { t = v[i]; v[i] = v[j]; v[j] = t }
                                       return n % 2 ? v[(n + 1) / 2] : (v[n / 2] + v[n / 2 + 1]) / 2 }
    END { mc = median(c, NR); md = median(d, NR);
          printf "%10d %12.0f %6d %6s %10.2f %14.1f %14.1f %10.1f %7.0f%%   (medians of %d samples)\n", m, b, r, "median",
                 median(w, NR), mc, median(f, NR), md, 100 * mc / md, NR }'
done

MEM_SIDE=${MEM_SIDE:-100}
MEM_RANKS=${MEM_RANKS:-"1 2"}
[[ "$MEM_SIDE" -gt 0 ]] || exit 0
echo
printf "%10s %6s %16s %16s %8s %16s %16s %8s\n" molecules ranks "B/mol(no out)" "B/mol(output)" ratio \
  "B/mol(ckpt run)" "B/mol(restart)" ratio
for r in $MEM_RANKS; do
  peaks=()
  for mode in none snapshots checkpoint restart; do
    dir="$OUT/mem_np${r}_$mode"
    rm -rf "$dir"
    what=(run run_scripts/scenes/peer_lattice.toml --set "body.molecules=[$MEM_SIDE,$MEM_SIDE,$MEM_SIDE]")
    case $mode in
      none) sets=(--set 'output.fields=[]') ;;
      snapshots) sets=(--set 'output.fields=["positions","velocities"]' --set output.snapshot_every=10) ;;
      checkpoint) sets=(--set 'output.fields=[]' --set output.checkpoint_every=10) ;;
      restart) what=(restart "$OUT/mem_np${r}_checkpoint/checkpoint_0000000010.h5"); sets=() ;;
    esac
    mpirun --oversubscribe -np "$r" "$TISSUE" "${what[@]}" --set solver.steps=20 "${sets[@]}" \
      --output "$dir" > "$dir.log" 2>&1 || { echo "np $r $mode: tissue failed, see $dir.log"; continue 2; }
    peaks+=("$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["peak_memory_bytes"])' "$dir/summary.json")")
    [[ $mode != snapshots ]] || ls "$dir" | grep -c '\.h5$' | xargs -I{} echo "  np $r: {} snapshot files in $dir" >&2
  done
  awk -v m=$((MEM_SIDE * MEM_SIDE * MEM_SIDE)) -v r=$r -v a="${peaks[0]}" -v b="${peaks[1]}" -v c="${peaks[2]}" \
    -v d="${peaks[3]}" 'BEGIN { printf "%10d %6d %16.0f %16.0f %8.3f %16.0f %16.0f %8.3f\n", m, r, a / m, b / m, b / a,
                                  c / m, d / m, d / a }'
done
