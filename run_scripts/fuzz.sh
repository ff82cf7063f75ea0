#!/usr/bin/env bash
# Builds the libFuzzer targets (clang, -fsanitize=fuzzer,address; a separate build directory, the main build
# stays g++) and runs each for SECONDS seconds (default 60), seeded with tests/fuzz_regressions/ and the example
# and bad scenes. Crashes land in out/fuzz/TARGET/ (crash-*, leak-*, timeout-*): copy each into
# tests/fuzz_regressions/scene/ or .../checkpoint/ so that the normal build's fuzz_regressions test replays it.
# A crash-* of fuzz_checkpoint with TISSUE_FUZZ_RESEAL=1 is the input before the target resealed it: reseal it
# (reseal() in tests/checkpoint_test.py) before copying, or it stops at the seal.
#
#   bash run_scripts/fuzz.sh [SECONDS] [TARGET ...]     # targets: fuzz_scene fuzz_scene_set fuzz_checkpoint
set -euo pipefail
cd "$(dirname "$0")/.."
SECONDS_EACH=${1:-60}
shift || true
TARGETS=("$@")
[ ${#TARGETS[@]} -gt 0 ] || TARGETS=(fuzz_scene fuzz_scene_set fuzz_checkpoint)
BUILD=${FUZZ_BUILD:-build-fuzz}

CC=${CC_FUZZ:-clang-14} CXX=${CXX_FUZZ:-clang++-14} \
  cmake -S . -B "$BUILD" -DCMAKE_BUILD_TYPE=Release -DTISSUE_FUZZ=ON -DTISSUE_TESTS=OFF >/dev/null
BUILD_TARGETS=("${TARGETS[@]}")
# fuzz_checkpoint: the ASan-built program too, to replay the HDF5 crash inputs end to end (below)
[[ " ${TARGETS[*]} " == *" fuzz_checkpoint "* ]] && BUILD_TARGETS+=(tissue)
cmake --build "$BUILD" -j"$(nproc)" --target "${BUILD_TARGETS[@]}"

export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
# LeakSanitizer reports what MPI, PETSc and HDF5 keep until exit; leaks are not what these targets look for.
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=0:abort_on_error=1}
status=0
for t in "${TARGETS[@]}"; do
  corpus=out/fuzz/$t/corpus
  mkdir -p "$corpus"
  seeds=()
  max_len=16384
  case $t in
    fuzz_scene) seeds=(tests/fuzz_regressions/scene run_scripts/scenes tests/bad_scenes) ;;
    fuzz_scene_set) seeds=(tests/fuzz_regressions/scene_set) ;;
    # seeded with sealed files written by the current tissue (seed_sealed_*.h5, ~16 KiB: longer inputs are cut to
    # max_len, which would break the seal of every seed) next to the old unsealed seeds and crash inputs
    fuzz_checkpoint) seeds=(tests/fuzz_regressions/checkpoint); max_len=65536 ;;
  esac
  existing=()
  for s in "${seeds[@]}"; do [ -d "$s" ] && existing+=("$s"); done
  echo "== $t: $SECONDS_EACH s (corpus $corpus, seeds ${existing[*]:-none})"
  start=$(date -u +%FT%TZ)
  if ! "$BUILD/tests/fuzz/$t" "$corpus" "${existing[@]}" -max_total_time="$SECONDS_EACH" -timeout=10 \
      -rss_limit_mb=4096 -max_len="$max_len" -artifact_prefix="out/fuzz/$t/" -print_final_stats=1 \
      > "out/fuzz/$t/log.txt" 2>&1; then
    echo "   $t FOUND A PROBLEM (see out/fuzz/$t/log.txt and out/fuzz/$t/crash-*)"
    status=1
  fi
  # (the last: a child that died printed libFuzzer's stats of its own)
  echo "   started $start; $(grep -E '^stat::number_of_executed_units' "out/fuzz/$t/log.txt" | tail -n1 || true)"
  # HDF5 parses a checkpoint in a child process first (io/isolated_parse.cpp): an input that crashes HDF5 kills
  # that child, the unit ends in an InputError and the run goes on. libFuzzer's death callback, inherited by the
  # child, still saves such an input as crash-* (and ASan's report is in the log): those are refused files, listed
  # here, not failures. A crash of the fuzzer process itself fails the run as before.
  if [ "$t" = fuzz_checkpoint ]; then
    children=$(grep -c '^==[0-9]*==ERROR: AddressSanitizer' "out/fuzz/$t/log.txt" || true)
    [ "$children" = 0 ] || echo "   $children ASan reports in isolated parse children (inputs refused with exit 2)"
  fi
done

# The checkpoint crash inputs through the ASan-built program: `tissue restart FILE` must exit 2 with one stderr line
# naming FILE and nothing else (ASan's report of a dying child goes to out/fuzz/replay/asan.PID), at 1 and 2 ranks.
# The H5Aexists and H5MM_strdup inputs crash HDF5 under ASan: their line must say that the child died with signal 6
# (SIGABRT).
if [[ " ${TARGETS[*]} " == *" fuzz_checkpoint "* ]]; then
  replay=out/fuzz/replay
  rm -rf "$replay"
  mkdir -p "$replay"
  checked=0
  for f in tests/fuzz_regressions/checkpoint/crash-*; do
    for np in 1 2; do
      code=0
      ASAN_OPTIONS=detect_leaks=0:abort_on_error=1:log_path=$PWD/$replay/asan \
        mpirun --quiet --oversubscribe -np $np "$BUILD/tissue" restart "$f" --output "$replay/out" \
        > "$replay/stdout" 2> "$replay/stderr" || code=$?
      lines=$(grep -c . "$replay/stderr" || true)
      line=$(head -n1 "$replay/stderr")
      ok=1
      [ "$code" = 2 ] && [ "$lines" = 1 ] && [[ "$line" == "$f: "* ]] && [ ! -e "$replay/out" ] || ok=0
      case $f in
        *H5Aexists*|*H5MM_strdup*) [[ "$line" == "$f: HDF5 could not parse the file (the child process parsing it died with signal 6): corrupt or crafted checkpoint" ]] || ok=0 ;;
      esac
      if [ $ok = 1 ]; then
        checked=$((checked + 1))
      else
        echo "   replay FAILED: tissue restart $f at $np ranks: exit $code, $lines stderr lines: $(head -c 600 "$replay/stderr")"
        status=1
      fi
    done
  done
  echo "== replay of tests/fuzz_regressions/checkpoint/crash-* through ASan-built tissue restart: $checked runs ok;" \
       "$(ls "$replay" | grep -c '^asan' || true) ASan reports of dying children in $replay"
fi
exit $status
