"""The python tests' tally: check() counts a passed or failed assertion (printing the failed ones) and returns it, report()
prints 'N passed, M failed' and gives the exit code; tissue() runs build/tissue under mpirun; arguments_and_work()
reads a test's --build/--source and gives it an empty work directory; check_same_solve() compares two static runs'
summaries to the bit."""
import argparse
import os
import shutil
import subprocess

counts = {"passed": 0, "failed": 0}


def check(ok, what):
    if ok:
        counts["passed"] += 1
    else:
        counts["failed"] += 1
        print("FAILED:", what)
    return ok


def report():
    print(f"{counts['passed']} passed, {counts['failed']} failed")
    return 1 if counts["failed"] else 0


def check_same_solve(new, old, what):
    """Two static runs' summary.json (dicts) give the same solve to the bit: NEW converged, the measured elongation,
    E and nu, and the solver's residual, Newton and Krylov counts equal."""
    check(new["solver"]["converged"], f"{what}: converged")
    for key in ("elongation", "youngs_modulus_measured", "poisson_ratio_measured"):
        check(new[key] == old[key], f"{what}: {key} {new[key]!r} == {old[key]!r}")
    for key in ("residual", "iterations", "linear_iterations"):
        check(new["solver"][key] == old["solver"][key],
              f"{what}: solver.{key} {new['solver'][key]!r} == {old['solver'][key]!r}")


def arguments_and_work(name):
    """The test's arguments (--build BUILD_DIR --source SOURCE_DIR) and its work directory BUILD_DIR/tests/out/NAME,
    emptied and made."""
    p = argparse.ArgumentParser()
    p.add_argument("--build", required=True)
    p.add_argument("--source", required=True)
    a = p.parse_args()
    work = os.path.join(a.build, "tests", "out", name)
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    return a, work


def tissue(build, ranks, *args, timeout=300):
    """`mpirun -np RANKS BUILD/tissue ARGS...`, its CompletedProcess (text output captured)."""
    cmd = ["mpirun", "--oversubscribe", "-np", str(ranks), os.path.join(build, "tissue")] + list(args)
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)


def run_scene(build, work, label, ranks, text):
    """Writes `text` to WORK/LABEL.toml and runs it on `ranks` ranks into WORK/LABEL: (that directory, the
    CompletedProcess)."""
    path = os.path.join(work, label + ".toml")
    with open(path, "w") as f:
        f.write(text)
    out = os.path.join(work, label)
    return out, tissue(build, ranks, "run", path, "--output", out)
