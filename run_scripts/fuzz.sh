#!/usr/bin/env bash
# Builds the libFuzzer targets (clang, -fsanitize=fuzzer,address; a separate build directory, the main build
# stays g++) and runs each for SECONDS seconds (default 60), seeded with tests/fuzz_regressions/ and the example
# and bad scenes. Crashes land in out/fuzz/TARGET/ (crash-*, leak-*, timeout-*): copy each into
# tests/fuzz_regressions/scene/ or .../checkpoint/ so that the normal build's fuzz_regressions test replays it.
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
cmake --build "$BUILD" -j"$(nproc)" --target "${TARGETS[@]}"

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
  echo "   started $start; $(grep -E '^stat::number_of_executed_units' "out/fuzz/$t/log.txt" || true)"
done
exit $status
