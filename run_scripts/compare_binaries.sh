#!/usr/bin/env bash
#                 tissue: two binaries, the same scenes, the same numbers (issue 21's acceptance check)
#
# What it does: runs a FIXED set of scenes with two `tissue` binaries, OLD and NEW, at 1 and 2 MPI ranks, and checks
# that every number in every summary.json agrees to a relative 1e-12 (|a - b| <= 1e-12 max(|a|, |b|) + 1e-300),
# every string, boolean and null is equal, and no key is missing or extra (run_scripts/compare_summaries.py, which
# also holds THE list of excluded run-dependent keys, with why: wall and CPU times, peak memory, version, the scene
# path; `python3 run_scripts/compare_summaries.py --excluded` prints it). Both binaries must also end every run
# with the same exit code (a scene may expect 2 or 3: a refused input, a failing solver; a failed run that wrote a
# summary has it compared too). It prints one line per scene and rank count: name, ranks, PASS/FAIL, the largest
# relative difference over all compared numbers (and where), a note; then every differing key with both values.
# The HDF5 files of every run (final.h5, snapshots, checkpoints: every molecule's position, velocity, force, every
# connection) are compared too when h5diff is installed (H5=1, the default then): the same file names on both
# sides, and every dataset to the same relative tolerance (`h5diff -p RTOL`), root attributes excluded (they carry
# the version string; step, time and counts are in summary.json).
# Both binaries run the scene files of THIS checkout (run_scripts/scenes), so a change of a scene is not a change of
# a binary.
#
# The scenes (each at 1 and 2 ranks; shrunk with --set where a default is slow; names for SCENES= below):
#   table2_<method>        the paper's Table 2 box (run_scripts/scenes/table2.toml, clamped, static, as
#                          run_scripts/paper_tables.sh runs it: calibration.divisor = 3.75) with every method the paper
#                          compares: linear, divided, angles, angles-update, statistical, iterative; tetrahedral where
#                          it is valid (body.topology = tetrahedral), and where it is not (face diagonals: exit 2
#                          expected from both); homogenized on rollers (ours, the material's own modulus)
#   fig7_a_iterative, fig7_b_angles, fig7_c_statistical, fig7_d_angles-update: the paper's Table 1 objects;
#   fig7_b_angles-update   exit 3 expected (Newton fails at once on the rectangular object, docs/paper_tables.md)
#   dynamic_drop           example_drop.toml (gravity, viscosity, a plane obstacle), 400 velocity Verlet steps
#   relaxation_table2      table2.toml with the FIRE relaxation solver to 1e-6
#   dynamic_cyclic         example_ligament_cyclic.toml (a cyclic load, viscosity), 1000 steps, a snapshot every 500
#   dynamic_lattice        peer_lattice.toml at 20^3 with z+ clamped and 10 N on z- (the stencil force kernel), 200 steps
#   static_lattice_mg      peer_tension.toml at 33^3 = 35,937 molecules to 1e-8: the lattice multigrid (table2's 1000
#                          molecules get GAMG) and METIS on the block graph (past 32,768 molecules)
#   mesh_cube              mesh_cube.toml on a gmsh cube (element size 0.25, meshed once, both binaries read it)
#   mesh_random_cube       mesh_random_cube.toml in that cube, 64 random interior molecules
#   random_cube            random_cube.toml, the default 1000-molecule Delaunay cloud
#   two_pads               example_two_pads.toml: two bodies, molecule contact, relaxation
#   restart_dynamic        example_drop.toml, 400 steps, a checkpoint every 200; then `tissue restart` from step 200:
#                          the checkpointing run's summary, the restart's, and (CROSS=1) NEW restarting OLD's
#                          checkpoint against OLD's restart (the checkpoint format unchanged) are all compared
#   restart_relaxation     table2.toml relaxation to 1e-6, a checkpoint every 100 iterations, restarted from 100
# Not in the set: partition.method = "ptscotch" at 2 ranks, which is not reproducible from one run to the next of the
# SAME binary (table2, 5 runs: 3 different outcomes, 47, 49 or 52 CG iterations, the elongation 5e-13 apart, with the
# same edge cut; SCOTCH_randomReset() before every SCOTCH_dgraphMapCompute did not change that, so it is not the
# seed; presumably PT-Scotch's threads or the order in which its messages arrive), so no tolerance fits it.
# About 110 runs of 1-7 s: all 50 lines took 4 min 4 s on this 2-core VM at load average 5-7.5 (others compiling;
# 2026-12-01), plus the OLD build if BASE is given (5-6 minutes, once).
# Tested: HEAD against itself (OLD = NEW = build/tissue, and OLD built by BASE in a worktree): every line PASS with
# every number bit for bit equal (max_rel 0); between two runs of one binary only the excluded keys ever differed
# (wall_seconds, solver.seconds, solver.cpu_seconds, solver.guard_seconds, peak_memory_bytes in every run; scene in
# the restarts). Negative controls: NEW_ARGS='--set calibration.divisor=3.7500000001' SCENES=table2_divided gives
# FAIL with calibration.divisor, elongation, youngs_modulus_measured, error_percent (rel 1e-11 .. 3e-11) and the
# residual listed; NEW_ARGS='--set physics.viscosity=2.000000001e-4' SCENES='dynamic_drop restart_dynamic' FAILs on
# the summaries and on final.h5, the snapshot and the checkpoint (h5diff); `python3 run_scripts/compare_summaries.py
# --self-test` perturbs a summary in 15 ways and checks each verdict.
#
# Sample runs (from the repository root):
#   BASE=main run_scripts/compare_binaries.sh                  # OLD built from `main` (git worktree in out/), NEW = build/tissue
#   run_scripts/compare_binaries.sh /tmp/old/tissue build/tissue    # two binaries you built
#   OLD=/tmp/old/tissue NEW=build/tissue SCENES='table2_* restart_*' RANKS=2 run_scripts/compare_binaries.sh
#   SCENES=list run_scripts/compare_binaries.sh                # print the scene names and exit
#   SCENES=none BASE=main run_scripts/compare_binaries.sh      # only build OLD; print "OLD path", "NEW path" (compare_speed.sh)
#   BASE=d47e42f PATCHES="$(ls run_scripts/compare_patches/*.patch)" run_scripts/compare_binaries.sh
#                                                              # OLD = d47e42f plus the bug fixes made since (the
#                                                              # "bug-fix baseline"; run_scripts/compare_patches/README.md)
# Knobs (environment): OLD, NEW (binaries; the arguments win; NEW defaults to build/tissue), BASE (a git revision:
# OLD is built from it with `git worktree add --detach $WORK/base-<sha>` and `cmake --build ... --target tissue`
# under nice, once: a later run reuses it; remove it with `git worktree remove --force $WORK/base-<sha>`),
# PATCHES (with BASE: patch files, relative to the root, applied in order with `git apply` to the BASE worktree,
# which is then $WORK/base-<sha>-patched-<hash of the patches>),
# SCENES (space-separated names or shell patterns, default all), RANKS (default "1 2"), RTOL (default 1e-12),
# WORK (default out/compare; runs in $WORK/runs/<scene>/np<ranks>/{old,new}, each with its .log),
# RUN_TIMEOUT (s per run, default 300; exit 124 = timed out), CROSS (default 1), H5 (default 1 if h5diff exists),
# PYTHON (default /usr/bin/python3),
# NEW_ARGS (extra options, split at blanks, given to NEW's `run`s only: a negative control that must FAIL, e.g.
# NEW_ARGS='--set calibration.divisor=3.7500000001' OLD=build/tissue SCENES=table2_divided ...).
# Exit code: 0 every scene PASS, 1 any FAIL, 2 a missing prerequisite (binary, build, gmsh, python3).
#
# Steps:
#   1. Settings, the binaries (building OLD from BASE if asked), checks.
#   2. The scene table (name, expected exit code, scene file, --set options).
#   3. Every selected scene x rank count: OLD, then NEW (restarts: both checkpointing runs, both restarts, NEW from
#      OLD's checkpoint); exit codes, summaries and HDF5 files compared, one line each.
#   4. The tally; exit 1 if anything differed.
set -euo pipefail
# Binaries given as arguments or in OLD, NEW are relative to the directory this was started in; the rest to the root.
abs() { if [[ -z "$1" || "$1" == /* ]]; then echo "$1"; else echo "$PWD/$1"; fi; }
OLD_GIVEN=$(abs "${1:-${OLD:-}}"); NEW_GIVEN=$(abs "${2:-${NEW:-}}")
cd "$(dirname "$0")/.."
ROOT=$PWD

# 1. Settings, binaries, checks.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
PYTHON=${PYTHON:-/usr/bin/python3}
WORK=${WORK:-out/compare}
RANKS=${RANKS:-"1 2"}
RTOL=${RTOL:-1e-12}
RUN_TIMEOUT=${RUN_TIMEOUT:-300}
CROSS=${CROSS:-1}
read -r -a NEW_ARGS <<< "${NEW_ARGS:-}"
H5=${H5:-$(command -v h5diff > /dev/null && echo 1 || echo 0)}
SCENES=${SCENES:-"*"}
OLD=$OLD_GIVEN
NEW=${NEW_GIVEN:-build/tissue}
COMPARE=$ROOT/run_scripts/compare_summaries.py
mkdir -p "$WORK"
WORK=$(cd "$WORK" && pwd)
die() { echo "compare_binaries: $*" >&2; exit 2; }

if [[ "$SCENES" != list ]]; then
  "$PYTHON" -c 'import json' 2>/dev/null || die "no $PYTHON (set PYTHON)"
  if [[ -z "$OLD" ]]; then
    [[ -n "${BASE:-}" ]] || die "no OLD binary: give OLD NEW as arguments, OLD=path, or BASE=<git revision> (see the header)"
    sha=$(git rev-parse --verify "${BASE}^{commit}") || die "BASE=$BASE is not a git revision"
    tree=$WORK/base-$sha
    read -r -a patches <<< "${PATCHES:-}"
    if (( ${#patches[@]} )); then  # a patched OLD lives apart from the plain one, named by the patches' contents
      for p in "${patches[@]}"; do [[ -f "$p" ]] || die "PATCHES: no file $p"; done
      tree=$tree-patched-$(cat "${patches[@]}" | sha1sum | cut -c1-12)
    fi
    OLD=$tree/build/tissue
    if [[ ! -x "$OLD" ]]; then
      echo "building OLD from $BASE ($sha) in $tree (log: $tree.build.log)" >&2
      if [[ ! -d "$tree" ]]; then
        git worktree add --detach "$tree" "$sha" > "$tree.build.log" 2>&1 \
          || die "git worktree add failed, see $tree.build.log"
        for p in "${patches[@]}"; do  # (a patch not applying leaves the tree: remove it as above)
          git -C "$tree" apply --index "$ROOT/$p" >> "$tree.build.log" 2>&1 || die "patch $p does not apply to $BASE"
          echo "applied $p" >> "$tree.build.log"
        done
      fi
      t0=$(date +%s)
      ( cd "$tree" && nice -n 10 cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DTISSUE_TESTS=OFF \
          && nice -n 10 cmake --build build -j2 --target tissue ) >> "$tree.build.log" 2>&1 \
        || die "building $BASE failed, see $tree.build.log"
      echo "built OLD in $(( $(date +%s) - t0 )) s" >&2
    fi
  fi
  for b in "$OLD" "$NEW"; do [[ -x "$b" ]] || die "no binary $b (build it: cmake --build build -j2 --target tissue)"; done
  OLD=$(realpath "$OLD"); NEW=$(realpath "$NEW")
  if [[ "$SCENES" == none ]]; then echo "OLD $OLD"; echo "NEW $NEW"; exit 0; fi   # the binaries only
fi

# 2. The scene table. add NAME EXPECTED_EXIT SCENE_FILE [--set options...]; add_restart NAME CHECKPOINT_STEP
#    SCENE_FILE [--set options...] (the run must write checkpoint_<STEP>.h5; the restart is expected to exit 0).
#    Every run also gets --set output.progress=false; @MESH@ is replaced by the gmsh cube's path.
S=run_scripts/scenes
NAMES=(); declare -A EXPECT ARGS KIND CKSTEP
add() { local n=$1; NAMES+=("$n"); KIND[$n]=run; EXPECT[$n]=$2; shift 2; ARGS[$n]=$(printf '%s\x1f' "$@"); }
add_restart() { local n=$1; NAMES+=("$n"); KIND[$n]=restart; EXPECT[$n]=0; CKSTEP[$n]=$2; shift 2; ARGS[$n]=$(printf '%s\x1f' "$@"); }
T2=("$S/table2.toml" --set calibration.divisor=3.75 --set 'output.fields=[]')  # as paper_tables.sh runs it
for m in linear divided angles angles-update statistical iterative; do
  add "table2_$m" 0 "${T2[@]}" --set "calibration.method=$m"
done
add table2_tetrahedral 0 "${T2[@]}" --set calibration.method=tetrahedral --set body.topology=tetrahedral
add table2_tetrahedral_refused 2 "${T2[@]}" --set calibration.method=tetrahedral   # face diagonals: exit 2
add table2_homogenized_roller 0 "${T2[@]}" --set calibration.method=homogenized --set fix.0.mode=roller
add fig7_a_iterative 0 "$S/fig7_a.toml" --set calibration.method=iterative
add fig7_b_angles 0 "$S/fig7_b.toml" --set calibration.method=angles
add fig7_b_angles-update 3 "$S/fig7_b.toml" --set calibration.method=angles-update   # Newton fails: exit 3
add fig7_c_statistical 0 "$S/fig7_c.toml" --set calibration.method=statistical
add fig7_d_angles-update 0 "$S/fig7_d.toml" --set calibration.method=angles-update
add dynamic_drop 0 "$S/example_drop.toml" --set solver.steps=400 --set output.snapshot_every=200
add relaxation_table2 0 "$S/table2.toml" --set solver.kind=relaxation --set solver.tolerance=1e-6
add dynamic_cyclic 0 "$S/example_ligament_cyclic.toml" --set solver.steps=1000 --set output.snapshot_every=500
add dynamic_lattice 0 "$S/peer_lattice.toml" --set 'body.molecules=[20,20,20]' --set 'fix=[{face = "z+"}]' \
  --set 'load=[{face = "z-", force = [0.0, 0.0, -10.0]}]'
add static_lattice_mg 0 "$S/peer_tension.toml" --set 'body.molecules=[33,33,33]' --set 'load.0.force=[0,0,-1.089]' \
  --set solver.tolerance=1e-8
add mesh_cube 0 "$S/mesh_cube.toml" --set body.file=@MESH@
add mesh_random_cube 0 "$S/mesh_random_cube.toml" --set body.file=@MESH@ --set body.interior_molecules=64
add random_cube 0 "$S/random_cube.toml"
add two_pads 0 "$S/example_two_pads.toml"
add_restart restart_dynamic 200 "$S/example_drop.toml" --set solver.steps=400 --set output.checkpoint_every=200 \
  --set 'output.fields=[]'
add_restart restart_relaxation 100 "$S/table2.toml" --set solver.kind=relaxation --set solver.tolerance=1e-6 \
  --set output.checkpoint_every=100 --set 'output.fields=[]'

SELECTED=()
read -r -a PATTERNS <<< "$SCENES"   # (no pathname expansion: the patterns match scene names, not files)
for n in "${NAMES[@]}"; do
  for p in "${PATTERNS[@]}"; do
    # shellcheck disable=SC2254
    case $n in $p) SELECTED+=("$n"); break ;; esac
  done
done
if [[ "$SCENES" == list ]]; then
  for n in "${NAMES[@]}"; do printf '%-28s %-7s expected exit %s\n' "$n" "${KIND[$n]}" "${EXPECT[$n]}"; done
  exit 0
fi
(( ${#SELECTED[@]} )) || die "SCENES='$SCENES' selects no scene (SCENES=list prints them)"

MESH=$WORK/cube_h0.25.msh
if printf '%s\n' "${SELECTED[@]}" | grep -q '^mesh_' && [[ ! -s "$MESH" ]]; then
  command -v gmsh > /dev/null || die "the mesh scenes need gmsh (apt-get install -y gmsh)"
  gmsh -3 -format msh41 -setnumber h 0.25 "$S/cube_mesh.geo" -o "$MESH" > "$MESH.log" 2>&1 || die "gmsh failed, see $MESH.log"
fi

echo "OLD $OLD"
echo "NEW $NEW"
(( ${#NEW_ARGS[@]} == 0 )) || echo "NEW's runs also get: ${NEW_ARGS[*]} (a negative control)"
echo "HDF5 files compared (h5diff): $( [[ "$H5" == 1 ]] && echo yes || echo no)"
echo "ranks: $RANKS; relative tolerance $RTOL; runs in $WORK/runs; excluded keys: $("$PYTHON" "$COMPARE" --excluded | awk '{printf "%s%s", s, $1; s=", "}')"
printf '%-28s %5s  %-4s  %-34s %s\n' scene ranks test "largest relative difference" note

# 3. The runs. tissue NP BINARY DIR ARGS...: one run, output in DIR, log in DIR.log; prints the exit code.
tissue() {
  local np=$1 bin=$2 dir=$3 rc=0; shift 3
  rm -rf "$dir" "$dir.log"; mkdir -p "$(dirname "$dir")"
  timeout "$RUN_TIMEOUT" mpirun --oversubscribe -np "$np" "$bin" "$@" --output "$dir" > "$dir.log" 2>&1 || rc=$?
  echo "$rc"
}
# compare LABEL OLD_DIR OLD_RC NEW_DIR NEW_RC EXPECTED: the exit codes, then the summaries (when there are any).
# Sets CMP_OK (0/1), CMP_REL (the largest relative difference, "-" if none compared), CMP_NOTE, and appends the
# differences to DETAILS.
compare() {
  local label=$1 od=$2 orc=$3 nd=$4 nrc=$5 expect=$6 out rc=0
  CMP_OK=1; CMP_REL="-"; CMP_NOTE=""
  if [[ "$orc" != "$nrc" ]]; then
    CMP_OK=0; CMP_NOTE="$label: exit codes differ: old $orc, new $nrc (logs $od.log, $nd.log)"; return
  fi
  [[ "$orc" == "$expect" ]] || CMP_NOTE="$label: both exit $orc, expected $expect (see $nd.log)"
  if [[ ! -f "$od/summary.json" && ! -f "$nd/summary.json" ]]; then
    CMP_NOTE="${CMP_NOTE:-$label: both exit $orc, no summary}"; return
  fi
  out=$("$PYTHON" "$COMPARE" --rtol "$RTOL" "$od/summary.json" "$nd/summary.json" 2>&1) || rc=$?
  CMP_REL=$(tail -n 1 <<< "$out" | sed -n 's/^max_rel //p')
  [[ -n "$CMP_REL" ]] || CMP_REL="-"
  if (( rc != 0 )); then
    CMP_OK=0
    DETAILS+="$label (old $od, new $nd):"$'\n'"$(sed '$d' <<< "$out")"$'\n'
  fi
  [[ "$H5" == 1 ]] || return 0
  local f h5out h5rc
  for f in $( { ls "$od"; ls "$nd"; } 2> /dev/null | grep '\.h5$' | sort -u); do
    if [[ ! -f "$od/$f" || ! -f "$nd/$f" ]]; then
      CMP_OK=0; CMP_NOTE+="${CMP_NOTE:+; }$label: $f in one run only"
      DETAILS+="$label: $f exists in only one of $od, $nd"$'\n'; continue
    fi
    H5_COUNT=$((H5_COUNT + 1)); h5rc=0
    h5out=$(h5diff -p "$RTOL" --exclude-attribute / "$od/$f" "$nd/$f" 2>&1) || h5rc=$?
    if (( h5rc != 0 )); then
      CMP_OK=0; CMP_NOTE+="${CMP_NOTE:+; }$label: $f differs"; DETAILS+="$label: $f differs (h5diff -p $RTOL --exclude-attribute / $od/$f $nd/$f):"$'\n'"$(head -n 20 <<< "$h5out")"$'\n'
    fi
  done
}
# maxrel A B: the larger of two "R at PATH" strings ("-" counts as nothing).
maxrel() {
  if [[ "$1" == "-" ]]; then echo "$2"; elif [[ "$2" == "-" ]]; then echo "$1"
  else "$PYTHON" -c 'import sys; a, b = sys.argv[1], sys.argv[2]; print(a if float(a.split()[0]) >= float(b.split()[0]) else b)' "$1" "$2"; fi
}

DETAILS=""; FAILED=(); UNEXPECTED=(); COUNT=0
START=$(date +%s)
for name in "${SELECTED[@]}"; do
  IFS=$'\x1f' read -r -a args <<< "${ARGS[$name]}"
  args=("${args[@]//@MESH@/$MESH}")
  for np in $RANKS; do
    base=$WORK/runs/$name/np$np
    t0=$(date +%s)
    ok=1; rel="-"; notes=(); H5_COUNT=0
    if [[ "${KIND[$name]}" == run ]]; then
      orc=$(tissue "$np" "$OLD" "$base/old" run "${args[@]}" --set output.progress=false)
      nrc=$(tissue "$np" "$NEW" "$base/new" run "${args[@]}" --set output.progress=false "${NEW_ARGS[@]}")
      compare "$name" "$base/old" "$orc" "$base/new" "$nrc" "${EXPECT[$name]}"
      ok=$CMP_OK; rel=$CMP_REL; [[ -z "$CMP_NOTE" ]] || notes+=("$CMP_NOTE")
    else
      step=${CKSTEP[$name]}
      ck=$(printf 'checkpoint_%010d.h5' "$step")
      orc=$(tissue "$np" "$OLD" "$base/old" run "${args[@]}" --set output.progress=false)
      nrc=$(tissue "$np" "$NEW" "$base/new" run "${args[@]}" --set output.progress=false "${NEW_ARGS[@]}")
      compare "$name/checkpointing-run" "$base/old" "$orc" "$base/new" "$nrc" "${EXPECT[$name]}"
      ok=$CMP_OK; rel=$CMP_REL; [[ -z "$CMP_NOTE" ]] || notes+=("$CMP_NOTE")
      if [[ -f "$base/old/$ck" && -f "$base/new/$ck" ]]; then
        orc=$(tissue "$np" "$OLD" "$base/old-restart" restart "$base/old/$ck" --set output.progress=false)
        nrc=$(tissue "$np" "$NEW" "$base/new-restart" restart "$base/new/$ck" --set output.progress=false)
        compare "$name/restart" "$base/old-restart" "$orc" "$base/new-restart" "$nrc" 0
        (( CMP_OK )) || ok=0; rel=$(maxrel "$rel" "$CMP_REL"); [[ -z "$CMP_NOTE" ]] || notes+=("$CMP_NOTE")
        if [[ "$CROSS" == 1 ]]; then  # NEW reads OLD's checkpoint: must give OLD's own restart
          nrc=$(tissue "$np" "$NEW" "$base/new-restart-of-old" restart "$base/old/$ck" --set output.progress=false)
          compare "$name/new-restarts-old-checkpoint" "$base/old-restart" "$orc" "$base/new-restart-of-old" "$nrc" 0
          (( CMP_OK )) || ok=0; rel=$(maxrel "$rel" "$CMP_REL"); [[ -z "$CMP_NOTE" ]] || notes+=("$CMP_NOTE")
        fi
      else
        ok=0; notes+=("$name: no $ck in $base/old or $base/new")
      fi
    fi
    COUNT=$((COUNT + 1))
    (( ok )) || FAILED+=("$name np$np")
    for n in "${notes[@]}"; do [[ "$n" == *expected* ]] && UNEXPECTED+=("$name np$np"); done
    printf '%-28s %5s  %-4s  %-34s %s\n' "$name" "$np" "$( (( ok )) && echo PASS || echo FAIL)" "$rel" \
      "$(( $(date +%s) - t0 )) s$( (( H5_COUNT )) && echo ", $H5_COUNT h5 files")${notes[*]:+; $(IFS=';'; echo "${notes[*]}")}"
  done
done

# 4. The tally.
echo
echo "$COUNT scene runs in $(( $(date +%s) - START )) s: $(( COUNT - ${#FAILED[@]} )) PASS, ${#FAILED[@]} FAIL"
if (( ${#UNEXPECTED[@]} )); then
  echo "warning: both binaries ended with an unexpected exit code (the same one) in: ${UNEXPECTED[*]}"
fi
if (( ${#FAILED[@]} )); then
  echo "FAIL: ${FAILED[*]}"
  [[ -z "$DETAILS" ]] || { echo; echo "differences (key path: old value, new value):"; printf '%s' "$DETAILS"; }
  exit 1
fi
echo "every summary agrees (relative $RTOL; excluded keys: python3 run_scripts/compare_summaries.py --excluded)"
