#!/usr/bin/env python3
"""One MPI rank's peak resident memory, its forked children's included (the Gmsh reader runs in one).

    mpirun -np 3 python3 run_scripts/peak_rss.py OUT_PREFIX build/tissue run SCENE ...

Runs the command and writes OUT_PREFIX.rankR (R: OMPI_COMM_WORLD_RANK) with four numbers in kB: the process's own
peak (VmHWM, polled every 10 ms), the largest peak among its children (VmHWM of each while alive), wait4's
ru_maxrss (exact: the larger of the process's peak and its children's), and the process's own peak plus its
children's (an upper bound on what the rank needed at once). Exits with the command's exit code.
"""
import os
import sys
import time


def hwm(pid):
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return 0


def children(pid):
    ids = []
    try:
        for task in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{task}/children") as f:
                ids += f.read().split()
    except OSError:
        pass
    return ids


out, cmd = sys.argv[1], sys.argv[2:]
pid = os.fork()
if pid == 0:
    os.execvp(cmd[0], cmd)
own = child = 0
while True:
    done, status, usage = os.wait4(pid, os.WNOHANG)
    if done == pid:
        break
    own = max(own, hwm(pid))
    for c in children(pid):
        child = max(child, hwm(c))
    time.sleep(0.01)
own = max(own, 0)
rank = os.environ.get("OMPI_COMM_WORLD_RANK", "0")
tmp = f"{out}.rank{rank}.tmp"
with open(tmp, "w") as f:
    f.write(f"{own} {child} {usage.ru_maxrss} {own + child}\n")
os.replace(tmp, f"{out}.rank{rank}")
sys.exit(os.waitstatus_to_exitcode(status))
