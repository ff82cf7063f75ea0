#!/usr/bin/env bash
#                                tissue: Slurm job template
#
# Submit with:   sbatch run_scripts/slurm_job.sh SCENE.toml [OUTPUT_DIR]
#
# Sample runs:   sbatch run_scripts/slurm_job.sh run_scripts/scenes/table2.toml
#                sbatch --nodes=4 --time=12:00:00 run_scripts/slurm_job.sh big.toml out/big
#                sbatch run_scripts/slurm_job.sh big.toml out/big     # again, after the time limit: continues
#
# Description:   Runs `srun build/tissue run SCENE` and, when OUTPUT_DIR already holds a checkpoint from an
#                earlier submission, `srun build/tissue restart NEWEST_CHECKPOINT` instead, on however many tasks
#                this job has (a restart repartitions with METIS, so the node count may change between
#                submissions). Resubmit the same command until the run finishes: the job tells you which it did.
#
#                Time limit: `--signal=TERM@120` makes Slurm send SIGTERM 120 s before the limit to every task of
#                every job step (srun delivers it to the tasks themselves; no `B:` prefix, which would signal only
#                this batch shell and would need a trap forwarding it). tissue catches SIGTERM, writes
#                OUTPUT_DIR/checkpoint_<step>.h5 at the next step boundary (dynamic: within 16 steps, relaxation:
#                the current iteration), and exits 0 with "stop requested ... continue with: tissue restart ...".
#                120 s must cover one checkpoint write; see docs/checkpoint.md for the measured bandwidth
#                (a checkpoint is about 32 bytes per connection + 48 per molecule).
#
#                Checkpoints: set `[output] checkpoint_every = N` in the scene for periodic ones too (the newest 2
#                are kept; each is written to a .tmp and renamed when complete, so a node crash leaves the previous
#                one intact). Static runs have no steps to checkpoint: they are restarted from the beginning.
#
#                Exit: 0 finished or stopped cleanly (look for final.h5 to tell which), 2 bad input, 3 solver failure.
#
#SBATCH --job-name=tissue
#SBATCH --nodes=1
#SBATCH --ntasks-per-node=32
#SBATCH --cpus-per-task=1
#SBATCH --time=02:00:00
#SBATCH --signal=TERM@120
#SBATCH --output=tissue-%j.out
#SBATCH --open-mode=append
set -euo pipefail

SCENE=${1:?usage: sbatch run_scripts/slurm_job.sh SCENE.toml [OUTPUT_DIR]}
# Slurm runs a copy of this script from its spool directory: find the project from where sbatch was called.
cd "${SLURM_SUBMIT_DIR:-$(dirname "$0")/..}"
TISSUE=${TISSUE:-build/tissue}
# The output directory: the second argument, else the scene's output.directory.
OUT=${2:-$(sed -n 's/^[[:space:]]*directory[[:space:]]*=[[:space:]]*"\(.*\)".*/\1/p' "$SCENE" | head -n 1)}
OUT=${OUT:-out}

# Newest complete checkpoint (names sort by step; *.h5.tmp are unfinished writes and are never used).
NEWEST=$(ls -1 "$OUT"/checkpoint_*.h5 2>/dev/null | sort | tail -n 1 || true)

echo "tissue job ${SLURM_JOB_ID:-?}: ${SLURM_NTASKS:-?} tasks on ${SLURM_JOB_NODELIST:-?}, output $OUT"
set +e
if [[ -f "$OUT/final.h5" && -z "$NEWEST" ]] || [[ -f "$OUT/final.h5" && "$OUT/final.h5" -nt "$NEWEST" ]]; then
  echo "tissue job: $OUT/final.h5 is newer than every checkpoint: the run is finished, nothing to do"
  exit 0
elif [[ -n "$NEWEST" ]]; then
  echo "tissue job: restarting from $NEWEST"
  # A damaged newest checkpoint (exit 2) falls back to the one before it.
  srun "$TISSUE" restart "$NEWEST" --output "$OUT"
  CODE=$?
  PREVIOUS=$(ls -1 "$OUT"/checkpoint_*.h5 2>/dev/null | sort | grep -vxF "$NEWEST" | tail -n 1 || true)
  if [[ $CODE -eq 2 && -n "$PREVIOUS" ]]; then
    echo "tissue job: $NEWEST unusable; restarting from $PREVIOUS"
    srun "$TISSUE" restart "$PREVIOUS" --output "$OUT"
    CODE=$?
  fi
else
  echo "tissue job: starting $SCENE"
  srun "$TISSUE" run "$SCENE" --output "$OUT"
  CODE=$?
fi
set -e

# Stopped by the signal rather than finished: exit 0 and a checkpoint newer than any final.h5.
NEWEST=$(ls -1 "$OUT"/checkpoint_*.h5 2>/dev/null | sort | tail -n 1 || true)
if [[ $CODE -eq 0 && -n "$NEWEST" ]] && [[ ! -f "$OUT/final.h5" || "$NEWEST" -nt "$OUT/final.h5" ]]; then
  echo "tissue job: stopped at $NEWEST; resubmit: sbatch run_scripts/slurm_job.sh $SCENE $OUT"
  # To chain automatically instead, uncomment (the dependency waits for this job to end):
  # sbatch --dependency=afterany:"$SLURM_JOB_ID" run_scripts/slurm_job.sh "$SCENE" "$OUT"
fi
exit $CODE
