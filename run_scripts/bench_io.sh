#!/usr/bin/env bash
#                                tissue: HDF5 write bandwidth
#
# Run with:      bash run_scripts/bench_io.sh [SIDE ...]        (default sides: 100 160 216)
#
# Sample runs:   bash run_scripts/bench_io.sh 100               # 1 million molecules
#                RANKS=4 OUT=/scratch/me/bench bash run_scripts/bench_io.sh 216   # 10 million
#
# Description:   For each SIDE, a SIDE^3 face-diagonals box (216^3 = 10.08 million molecules, about 90 million
#                connections) is written once as a snapshot, final.h5 with every field
#                (solver.kind=dynamic, solver.steps=0: the rest state, no time stepping), by `mpirun -np RANKS
#                tissue run`. A watcher polls the output directory every 10 ms: the write time is from the moment
#                final.h5.tmp appears (H5Fcreate, after the rows have been put in original order) to the moment it
#                is renamed to final.h5 (H5Fclose done, on every rank); then `sync -f` flushes it to the disk and
#                the flushed time is reported too. The reference is dd of the same number of bytes of zeros with
#                conv=fdatasync on the same file system. Prints one line per size: molecules, bytes, MB/s (page
#                cache), MB/s (flushed), dd MB/s. Results and machine: docs/checkpoint.md.
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

now() { date +%s.%N; }

echo "machine: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), $(nproc) cores, \
$(free -g | awk '/Mem:/ {print $2}') GB; file system: $(df -hT "$OUT" | awk 'NR==2 {print $1, $2, $3}')"
printf "%10s %12s %8s %10s %14s %14s %10s\n" molecules bytes ranks write_s "MB/s(cache)" "MB/s(flushed)" "dd_MB/s"
for n in "${SIDES[@]}"; do
  dir="$OUT/side$n"
  rm -rf "$dir"
  mkdir -p "$dir"
  io_scene "$dir/scene.toml" "bench_io $n^3" "$n" "$dir" "$ALL_FIELDS"
  mpirun --oversubscribe -np "$RANKS" "$TISSUE" run "$dir/scene.toml" > "$dir/log" 2>&1 &
  pid=$!
  t_tmp=""
  t_done=""
  while kill -0 $pid 2>/dev/null; do
    [[ -z "$t_tmp" && -e "$dir/final.h5.tmp" ]] && t_tmp=$(now)
    [[ -n "$t_tmp" && -z "$t_done" && -e "$dir/final.h5" ]] && { t_done=$(now); break; }
    sleep 0.01
  done
  wait $pid || { echo "side $n: tissue failed, see $dir/log"; continue; }
  [[ -n "$t_done" ]] || t_done=$(now)
  sync -f "$dir/final.h5"
  t_sync=$(now)
  bytes=$(stat -c %s "$dir/final.h5")
  molecules=$((n * n * n))
  # dd of the same size, flushed (the disk's sequential write bandwidth from one process).
  count=$(( (bytes + 1048575) / 1048576 ))
  t_dd=$(now)
  dd if=/dev/zero of="$dir/dd.bin" bs=1M count=$count conv=fdatasync 2>/dev/null
  dd_out=$(awk -v a=$t_dd -v b=$(now) 'BEGIN { print b - a }')
  rm -f "$dir/dd.bin"
  awk -v m=$molecules -v b=$bytes -v r=$RANKS -v t0=$t_tmp -v t1=$t_done -v t2=$t_sync -v tdd="$dd_out" -v c=$count \
    'BEGIN { w = t1 - t0; f = t2 - t0; if (w <= 0) w = 0.01;
             printf "%10d %12.0f %8d %10.2f %14.1f %14.1f %10.1f\n", m, b, r, w, b / w / 1e6, b / f / 1e6, c * 1048576 / tdd / 1e6 }'
  rm -f "$dir/final.h5"
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
