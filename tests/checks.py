"""The python tests' tally: check() counts a passed or failed assertion (printing the failed ones) and returns it, report()
prints 'N passed, M failed' and gives the exit code; tissue() runs build/tissue under mpirun."""
import os
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
