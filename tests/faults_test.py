#!/usr/bin/env python3
"""Faults never hang a job and never lose finished work (issue 19; docs/stability.md, "Faults").

A dynamic run of a tiny box (table2.toml with 4 x 4 x 4 molecules, 20 steps, a snapshot and a checkpoint every 5
steps) under an LD_PRELOAD shim (tests/fault_inject.c) that fails one file system call as a full disk (ENOSPC),
an exhausted quota (EDQUOT) or a failing device (EIO) does, on rank 0, rank 1 or every rank, while it writes a
snapshot, a checkpoint, final.h5, summary.json (a checkpoint's or the end's), the XDMF index or a row of
history.csv, at 1, 2 and 3 ranks.
Every case must:
  - end within 30 s with the documented exit code: 3 when the faulted rank writes that file, 0 when it does not
    (rank 1 writes neither summary.json nor the XDMF index);
  - print one line (tissue's; the shim's own "fault:" line and Open MPI's "mca_fbtl_posix_pwritev: error ..."
    line aside) naming the file and the system error (when MPI-IO lost errno, or a rank is stuck in a collective
    past the write's deadline, tissue asks the system by writing the file again: probe_write_error());
  - leave no .tmp file, and every file written before the fault intact (bitwise the fault-free run's; the rows of
    history.csv so far the start of the fault-free run's);
  - for the checkpoint and final.h5 cases: the newest checkpoint left restarts and ends in the fault-free run's
    final state, bitwise.
Then: a failure injected on one rank in the middle of each collective stage that is not a write (the test hook
fault_point() of partition/agreement.hpp: TISSUE_FAULT_STAGE): the partitioning, the model build, the
calibration, the guards' reductions (dynamic and relaxation), the static solver's function evaluation (the other
ranks are inside SNES's collectives), and the reads of a restart (the header, the state), at 2 and 3 ranks. Each
must end through the stage's own agreement: within 30 s although the agreement's last resort is set to 60 s, with
one line naming the stage, exit 3 (exit 2 for a restart: an unreadable checkpoint is bad input), no .tmp.
Then: the three cases of issue 19 (an output directory that cannot be created, a file in the way; exit 2 quickly,
nothing left), and kill -9 of one rank in the middle of a checkpoint write (the job ends, the previous checkpoint
restarts).

Usage: faults_test.py --build BUILD_DIR --source SOURCE_DIR [--table FILE.md] [--only SUBSTRING]
Prints one line per case and 'N passed, M failed'; --table writes the fault table of docs/stability.md."""
import argparse
import concurrent.futures
import glob
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

import h5py

LIMIT = 30.0  # seconds a faulted run may take, at most
ENV = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
           OMPI_MCA_rmaps_base_oversubscribe="1")
# The bounds of the last resorts (partition/agreement.hpp), short for the faulted runs only: a stuck write ends
# after 5 s, a failed rank waits 5 s for the others. Fault-free runs and restarts keep the defaults.
BOUNDS = {"TISSUE_STAGE_SECONDS": "5", "TISSUE_AGREEMENT_SECONDS": "5"}
SETS = ["body.molecules=[4,4,4]", "solver.kind=dynamic", "solver.steps=20", "output.snapshot_every=5",
        "output.checkpoint_every=5", "output.history_every=1", "output.progress=false", 'output.fields=["positions","velocities"]']

# target: (call, errno, file, calls or bytes let through, the files that must be there afterwards)
TARGETS = {
    "snapshot": ("pwrite", "ENOSPC", "snapshot_00000010.h5", 0,
                 ["snapshot_00000005.h5", "checkpoint_0000000005.h5", "tissue.xdmf"]),
    "checkpoint": ("pwrite", "EDQUOT", "checkpoint_0000000010.h5", 0,
                   ["snapshot_00000005.h5", "snapshot_00000010.h5", "checkpoint_0000000005.h5", "tissue.xdmf"]),
    "final": ("pwrite", "EIO", "final.h5", 0,
              ["snapshot_00000015.h5", "checkpoint_0000000010.h5", "checkpoint_0000000015.h5", "tissue.xdmf"]),
    # summary.json is written with every checkpoint (the first at step 5) and at the end: the checkpoint's, then
    # the end's (after the three checkpoints' summaries: the bytes let through are set from the fault-free run's)
    "summary": ("write", "ENOSPC", "summary.json", 0, ["snapshot_00000005.h5", "checkpoint_0000000005.h5",
                                                       "tissue.xdmf"]),
    "final summary": ("write", "ENOSPC", "summary.json", None,
                      ["final.h5", "snapshot_00000015.h5", "checkpoint_0000000015.h5", "tissue.xdmf"]),
    # the second XDMF index (after snapshot 10) cannot be renamed into place: the first stays
    "xdmf": ("rename", "EIO", "tissue.xdmf", 1, ["snapshot_00000005.h5", "checkpoint_0000000005.h5", "tissue.xdmf"]),
    # history.csv (rank 0 appends a row a step): the write of a row after the first 1000 bytes (about 4 rows)
    "history": ("write", "ENOSPC", "history.csv", 1000, []),
    # the other calls, at 2 and 3 ranks: the fsync of a checkpoint before its rename (rank 0 alone syncs), the open
    # of a snapshot by MPI-IO (every rank opens it; Open MPI's MPI_File_open then hangs: the StageDeadline ends it)
    "checkpoint fsync": ("fsync", "EIO", "checkpoint_0000000010.h5", 0,
                         ["snapshot_00000005.h5", "snapshot_00000010.h5", "checkpoint_0000000005.h5", "tissue.xdmf"]),
    "snapshot open": ("open", "EDQUOT", "snapshot_00000010.h5", 0,
                      ["snapshot_00000005.h5", "checkpoint_0000000005.h5", "tissue.xdmf"]),
}
RANKS = {"checkpoint fsync": (2, 3), "snapshot open": (2, 3)}  # the others: 1, 2, 3
NOT_RANK_1 = ("summary", "final summary", "xdmf", "checkpoint fsync", "history")  # files (or calls) rank 1 never writes (makes)
STRERROR = {"ENOSPC": "No space left on device", "EDQUOT": "Disk quota exceeded", "EIO": "Input/output error"}

passed, failed, rows = 0, 0, []


def check(ok, what, detail=""):
    global passed, failed
    if ok:
        passed += 1
    else:
        failed += 1
    print(("ok    " if ok else "FAIL  ") + what + (": " + detail if detail else ""))
    sys.stdout.flush()
    return ok


def launch(np_, shim=None, fault=None):
    cmd = ["mpirun", "--quiet", "--oversubscribe", "-np", str(np_)]
    env = dict(ENV)
    if fault:
        env.update(fault)
        env.update(BOUNDS)
        cmd += ["-x", "LD_PRELOAD=" + shim] + sum((["-x", k] for k in list(fault) + list(BOUNDS)), [])
    return cmd, env


def run(cmd, env, timeout=60):
    t = time.time()
    try:
        p = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, timeout=timeout)
        return p.returncode, p.stdout, p.stderr, time.time() - t
    except subprocess.TimeoutExpired as e:
        return None, "", (e.stderr or b"").decode() if isinstance(e.stderr, bytes) else (e.stderr or ""), timeout


def positions(path):
    with h5py.File(path, "r") as f:
        return f["/molecules/positions"][...].tobytes(), int(f.attrs["step"])


# Lines that are not tissue's: the shim's log, and Open MPI's MPI-IO components reporting the failed pwrite
# ("mca_fbtl_posix_pwritev: error in (p)write(v): ...", "vulcan_write_all: fbtl_pwritev failed").
FOREIGN = ("fault:", "mca_", "vulcan_", "dynamic_", "two_phase", "individual_")


def tissue_lines(stderr):
    """stderr without the shim's log line and Open MPI's own report of the failed pwrite."""
    return [l for l in stderr.splitlines() if l.strip() and not l.startswith(FOREIGN)]


def same_state(h5, reference_dir):
    """Whether a snapshot or checkpoint holds the fault-free run's positions at its step (checkpoints are compared
    with the snapshot of their step: the fault-free run keeps only its newest two checkpoints)."""
    data, step = positions(h5)
    for ref in (os.path.join(reference_dir, os.path.basename(h5)),
                os.path.join(reference_dir, "snapshot_%08d.h5" % step), os.path.join(reference_dir, "final.h5")):
        if os.path.exists(ref) and positions(ref) == (data, step):
            return True
    return False


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--build", required=True)
    parser.add_argument("--source", required=True)
    parser.add_argument("--table", help="write the fault table (markdown) to this file")
    parser.add_argument("--only", default="", help="run only the cases whose name holds this text")
    args = parser.parse_args()
    exe = os.path.join(args.build, "tissue")
    shim = os.path.join(args.build, "tests", "libfault_inject.so")
    scene = os.path.join(args.source, "run_scripts", "scenes", "table2.toml")
    if not os.path.exists(shim):
        print("FAIL  the fault shim " + shim + " is not built (target fault_inject)")
        return 1
    work = tempfile.mkdtemp(prefix="tissue_faults_")
    sets = sum((["--set", s] for s in SETS), [])
    start = time.time()

    # The fault-free runs: what every faulted run must keep, bitwise.
    reference = {}
    for np_ in (1, 2, 3):
        out = os.path.join(work, "reference_np%d" % np_)
        cmd, env = launch(np_)
        rc, _, err, _ = run(cmd + [exe, "run", scene, *sets, "--output", out], env)
        check(rc == 0, "fault-free run at %d ranks" % np_, err.strip()[-300:])
        reference[np_] = out

    def fault_case(target, who, np_):
        call, errno_name, file_name, after, kept = TARGETS[target]
        if after is None:  # the end's summary.json: past the three checkpoints' (each a little shorter)
            after = int(3.5 * os.path.getsize(os.path.join(reference[np_], "summary.json")))
        name = "%s rank %s at %d ranks (%s %s)" % (target, who, np_, call, errno_name)
        out = os.path.join(work, "%s_r%s_np%d" % (target.replace(" ", "_"), who, np_))
        fault = {"TISSUE_FAULT_CALL": call, "TISSUE_FAULT_ERRNO": errno_name, "TISSUE_FAULT_RANK": who,
                 "TISSUE_FAULT_FILE": os.path.join(out, file_name), "TISSUE_FAULT_AFTER": str(after),
                 "TISSUE_FAULT_LOG": "1"}
        cmd, env = launch(np_, shim, fault)
        rc, _, err, seconds = run(cmd + [exe, "run", scene, *sets, "--output", out], env, timeout=LIMIT + 30)
        injected = "fault:" in err
        # rank 1 writes neither summary.json nor the XDMF index, and does not fsync: its fault never fires there
        writes = who != "1" or target not in NOT_RANK_1
        expected = 3 if writes else 0
        lines = tissue_lines(err)
        problems = []
        if rc is None:
            problems.append("did not end within %.0f s" % (LIMIT + 30))
        elif seconds > LIMIT:
            problems.append("took %.1f s (limit %.0f s)" % (seconds, LIMIT))
        if rc != expected:
            problems.append("exit %s, expected %d" % (rc, expected))
        if writes and not injected:
            problems.append("the fault was never injected")
        how = ""
        if expected == 3:
            if len(lines) != 1:
                problems.append("%d lines on stderr, expected one: %r" % (len(lines), lines))
            elif file_name not in lines[0]:
                problems.append("the line does not name %s: %r" % (file_name, lines[0]))
            elif STRERROR[errno_name] not in lines[0]:
                problems.append("the line does not name the system error (%s): %r" % (STRERROR[errno_name], lines[0]))
            else:
                how = "stuck write ended (StageDeadline, probe)" if "did not finish" in lines[0] else "agreed error"
        tmp = glob.glob(os.path.join(out, "*.tmp")) + glob.glob(os.path.join(out, ".tissue-probe*"))
        if tmp:
            problems.append("left " + ", ".join(os.path.basename(t) for t in tmp))
        for k in (kept if expected == 3 else os.listdir(reference[np_])):
            if not os.path.exists(os.path.join(out, k)):
                problems.append("lost " + k)
        # Every HDF5 file there is the fault-free run's, bitwise.
        for h5 in sorted(glob.glob(os.path.join(out, "*.h5"))):
            try:
                if not same_state(h5, reference[np_]):
                    problems.append(os.path.basename(h5) + " differs from the fault-free run's")
            except Exception as e:  # noqa: BLE001 - any unreadable file is a loss
                problems.append("%s unreadable (%s)" % (os.path.basename(h5), e))
        # The rows written before the fault are kept: history.csv (its whole lines) is a prefix of the fault-free
        # run's.
        history = os.path.join(out, "history.csv")
        if os.path.exists(history):
            text = open(history).read()
            text = text[:text.rfind("\n") + 1]
            if not text or not open(os.path.join(reference[np_], "history.csv")).read().startswith(text):
                problems.append("history.csv is not the start of the fault-free run's")
        elif expected == 3:
            problems.append("lost history.csv")
        restarted = ""
        if expected == 3 and target in ("checkpoint", "final", "checkpoint fsync") and not problems:
            newest = sorted(glob.glob(os.path.join(out, "checkpoint_*.h5")))[-1]
            cmd, env = launch(np_)
            rc2, _, err2, _ = run(cmd + [exe, "restart", newest, "--output", out + "/restart"], env)
            final = os.path.join(out, "restart", "final.h5")
            if rc2 != 0 or not os.path.exists(final) or \
                    positions(final) != positions(os.path.join(reference[np_], "final.h5")):
                problems.append("the newest checkpoint %s did not restart to the fault-free final state (exit "
                                "%s: %s)" % (os.path.basename(newest), rc2, err2.strip()[-200:]))
            else:
                restarted = "; " + os.path.basename(newest) + " restarts (bitwise)"
        detail = "; ".join(problems) if problems else \
            "exit %d in %.1f s%s%s" % (rc, seconds, " - " + lines[0] if lines else "", restarted)
        kept_now = sorted(os.path.basename(p) for p in glob.glob(os.path.join(out, "*"))
                          if os.path.basename(p) != "restart")
        return not problems, name, detail, (
            target, who, np_, "%s %s" % (call, errno_name), rc, seconds,
            how or ("fault never fires: rank 1 does not write it" if not writes else ""),
            ", ".join(kept_now) + restarted)

    # Two cases at a time (each is mostly mpirun's start-up and waiting): the matrix in about two minutes.
    cases = [(t, w, n) for t in TARGETS for n in RANKS.get(t, (1, 2, 3)) for w in ("0", "1", "all")
             if not (w == "1" and n == 1) and args.only in "%s rank %s at %d ranks (%s %s)" % (
                 t, w, n, TARGETS[t][0], TARGETS[t][1])]
    with concurrent.futures.ThreadPoolExecutor(max_workers=2) as pool:
        for ok, name, detail, row in pool.map(lambda c: fault_case(*c), cases):
            check(ok, name, detail)
            rows.append(row)

    # Issue 19's bad locations: exit 2, one line naming output.directory, quickly, nothing left behind.
    blocker = os.path.join(work, "a_file")
    with open(blocker, "w") as f:
        f.write("in the way\n")
    for np_ in (1, 2, 3):
        for label, directory in (("/proc/tissue_out", "/proc/tissue_out"), ("a file", blocker),
                                 ("under a file", os.path.join(blocker, "out"))):
            if args.only and args.only not in "location " + label:
                continue
            cmd, env = launch(np_)
            rc, _, err, seconds = run(cmd + [exe, "run", scene, *sets, "--output", directory], env)
            lines = [l for l in err.splitlines() if l.strip()]
            ok = rc == 2 and len(lines) == 1 and "output.directory" in lines[0] and seconds < 10 and \
                os.path.isfile(blocker)
            check(ok, "output.directory %s at %d ranks" % (label, np_),
                  "exit %s in %.1f s: %s" % (rc, seconds, " | ".join(lines)))
            rows.append(("output.directory " + label, "-", np_, "-", rc, seconds, "checked before the model is built",
                         "nothing written"))

    # kill -9 of one rank in the middle of the step-10 checkpoint: the job ends, the step-5 checkpoint restarts.
    for np_ in (2, 3):
        name = "kill -9 of rank 1 during a checkpoint write at %d ranks" % np_
        if args.only and args.only not in name:
            continue
        out = os.path.join(work, "kill_np%d" % np_)
        fault = {"TISSUE_FAULT_CALL": "pwrite", "TISSUE_FAULT_ERRNO": "SIGKILL", "TISSUE_FAULT_RANK": "1",
                 "TISSUE_FAULT_FILE": os.path.join(out, "checkpoint_0000000010.h5"), "TISSUE_FAULT_AFTER": "0",
                 "TISSUE_FAULT_LOG": "1"}
        cmd, env = launch(np_, shim, fault)
        rc, _, err, seconds = run(cmd + [exe, "run", scene, *sets, "--output", out], env, timeout=LIMIT + 30)
        problems = []
        if rc is None or seconds > LIMIT:
            problems.append("did not end within %.0f s" % LIMIT)
        if rc == 0:
            problems.append("exit 0 after a rank was killed")
        newest = sorted(glob.glob(os.path.join(out, "checkpoint_*.h5")))
        restarted = ""
        if not newest or not newest[-1].endswith("checkpoint_0000000005.h5"):
            problems.append("the newest checkpoint is %s, expected checkpoint_0000000005.h5" % newest)
        else:
            cmd, env = launch(np_)
            rc2, _, err2, _ = run(cmd + [exe, "restart", newest[-1], "--output", out + "/restart"], env)
            final = os.path.join(out, "restart", "final.h5")
            if rc2 != 0 or positions(final) != positions(os.path.join(reference[np_], "final.h5")):
                problems.append("checkpoint_0000000005.h5 did not restart to the fault-free state: " + err2[-200:])
            else:
                restarted = "; checkpoint_0000000005.h5 restarts (bitwise)"
        check(not problems, name, "; ".join(problems) if problems else "exit %s in %.1f s%s" % (rc, seconds, restarted))
        rows.append(("kill -9 during checkpoint", "1", np_, "pwrite SIGKILL", rc, seconds, "the launcher ends the job",
                     ", ".join(sorted(os.path.basename(p) for p in glob.glob(os.path.join(out, "*"))
                                      if os.path.basename(p) != "restart")) + restarted))

    # A failure on one rank inside a collective stage that is not a write: agreed at that stage, within seconds.
    # The last resorts are set beyond the limit (60 s), so a case that reaches them fails.
    stage_bounds = {"TISSUE_STAGE_SECONDS": "60", "TISSUE_AGREEMENT_SECONDS": "60"}
    checkpoint_np = {np_: os.path.join(reference[np_], "checkpoint_0000000015.h5") for np_ in (1, 2, 3)}
    # name: (stage, faulted rank, calls let through, extra --set, restart?, expected exit)
    stages = {
        "partition (METIS on rank 0)": ("partition", "0", 0, ["partition.method=metis"], False, 3),
        "partition (box bisection)": ("partition", "1", 0, ["partition.method=blocks"], False, 3),
        "model build": ("build", "1", 0, [], False, 3),
        "calibration": ("calibration", "1", 0, [], False, 3),
        "guard reduction, dynamic": ("guard", "1", 1, [], False, 3),
        "guard reduction, relaxation": ("guard", "1", 0, ["solver.kind=relaxation", "solver.max_iterations=300"],
                                        False, 3),
        "static solver, function evaluation": ("static", "1", 2, ["solver.kind=static"], False, 3),
        "restart, header read": ("restart", "1", 2, [], True, 2),
        "restart, state read": ("restart", "1", 7, [], True, 2),
    }

    def stage_case(label, np_):
        stage, who, after, extra, restart, expected = stages[label]
        out = os.path.join(work, "stage_%s_np%d" % (re.sub(r"\W+", "_", label), np_))
        fault = {"TISSUE_FAULT_STAGE": stage, "TISSUE_FAULT_STAGE_RANK": who, "TISSUE_FAULT_STAGE_AFTER": str(after)}
        cmd = ["mpirun", "--quiet", "--oversubscribe", "-np", str(np_)] + \
            sum((["-x", k] for k in list(fault) + list(stage_bounds)), [])
        env = dict(ENV, **fault, **stage_bounds)
        args_ = ["restart", checkpoint_np[np_]] if restart else ["run", scene, *sets, *sum((["--set", e] for e in extra), [])]
        rc, _, err, seconds = run(cmd + [exe, *args_, "--output", out], env, timeout=LIMIT + 60)
        lines = [l for l in err.splitlines() if l.strip()]
        problems = []
        if rc is None or seconds > LIMIT:
            problems.append("did not end within %.0f s (%s)" % (LIMIT, "hung" if rc is None else "%.1f s" % seconds))
        if rc != expected:
            problems.append("exit %s, expected %d" % (rc, expected))
        if len(lines) != 1:
            problems.append("%d lines on stderr, expected one: %r" % (len(lines), lines[:4]))
        elif "stage " + stage not in lines[0] or "job aborted" in lines[0]:
            problems.append("the line does not name the stage or came from the last resort: %r" % lines[0])
        tmp = glob.glob(os.path.join(out, "*.tmp"))
        if tmp:
            problems.append("left " + ", ".join(os.path.basename(t) for t in tmp))
        name = "injected failure in the %s, rank %s, at %d ranks" % (label, who, np_)
        detail = "; ".join(problems) if problems else "exit %d in %.1f s - %s" % (rc, seconds, lines[0])
        kept_now = sorted(os.path.basename(p) for p in glob.glob(os.path.join(out, "*")))
        return not problems, name, detail, ("stage: " + label, who, np_, "throw", rc, seconds,
                                            "agreed at the stage" if not problems else "FAILED",
                                            ", ".join(kept_now) or "nothing written")

    cases = [(l, n) for l in stages for n in (2, 3) if args.only in "stage " + l]
    with concurrent.futures.ThreadPoolExecutor(max_workers=2) as pool:
        for ok, name, detail, row in pool.map(lambda c: stage_case(*c), cases):
            check(ok, name, detail)
            rows.append(row)

    def short(text):
        """File names in the table: checkpoint_0000000005.h5 -> ckpt 5, snapshot_00000010.h5 -> snap 10."""
        return re.sub(r"snapshot_0*(\d+)\.h5", r"snap \1", re.sub(r"checkpoint_0*(\d+)\.h5", r"ckpt \1", text))

    # The agreement's last resort: rank 1 fails while rank 0 waits in a collective rank 1 left
    # (tests/agreement_stuck.cpp).
    if not args.only or args.only in "agreement":
        stuck = os.path.join(args.build, "tests", "agreement_stuck")
        cmd, env = launch(2)
        env["TISSUE_AGREEMENT_SECONDS"] = "3"
        rc, _, err, seconds = run(cmd + ["-x", "TISSUE_AGREEMENT_SECONDS", stuck], env, timeout=LIMIT + 30)
        lines = [l for l in err.splitlines() if l.strip()]
        ok = rc == 3 and seconds < LIMIT and len(lines) == 1 and "job aborted" in lines[0]
        check(ok, "a failed rank whose peers are stuck in the stage ends the job at 2 ranks",
              "exit %s in %.1f s: %s" % (rc, seconds, " | ".join(lines)))
        rows.append(("failed rank, peers stuck in the stage", "1", 2, "-", rc, seconds,
                     "MPI_Abort after TISSUE_AGREEMENT_SECONDS (3 s here)", "-"))

    if args.table:
        rows[:] = [r[:7] + (short(r[7]),) for r in rows]
        with open(args.table, "w") as f:
            f.write("| case | faulted rank | ranks | call, errno | exit | seconds | how it ended | what was kept |\n")
            f.write("|---|---|---|---|---|---|---|---|\n")
            for r in rows:
                f.write("| %s | %s | %d | %s | %s | %.1f | %s | %s |\n" % r)
    print("%d passed, %d failed (%.0f s)" % (passed, failed, time.time() - start))
    shutil.rmtree(work, ignore_errors=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
