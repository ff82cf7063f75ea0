#!/usr/bin/env python3
"""Checkpoint/restart of the viscoelastic history (issue 16): a creep run stopped and restarted ends where the
uninterrupted run ends, and DIR/history.csv is truncated to the checkpoint's step and continued.

Quasi-static creep (a Prony strip under a ramp-and-hold force, a checkpoint every 4 steps): the run restarted
from step 8 into a copy of the run's directory on the same rank count (1 -> 1, 2 -> 2) ends with final.h5's
positions, history.csv and summary.json's state byte for byte the uninterrupted run's, with GAMG (3 x 3 x 5) and
with the lattice multigrid (9 x 9 x 17); on other rank counts (1 -> 2, 2 -> 3), whose straight runs differ by
the Krylov solver's round-off, history.csv to 1e-9 of the curve's scale.
Dynamic creep with the same Prony series (forces summed in global order, so the trajectory does not depend on the
partition): 2 -> 2, 1 -> 2 and 2 -> 3 ranks end with positions byte for byte the uninterrupted run's (history.csv:
byte for byte at 2 -> 2, to 1e-9 otherwise, its sums being MPI reductions). An elastic quasi-static run restarts
byte for byte as well. The same with the cell term (nu = 0.4: springs and cells carry the history; the cells' in
/cells/history): quasi-static 1 -> 1, 2 -> 2 byte for byte, 1 -> 2, 2 -> 3 to 1e-9; dynamic byte for byte at
2 -> 2, 1 -> 2 and 2 -> 3.

Usage: visco_restart_test.py --build BUILD_DIR --source SOURCE_DIR      Prints 'N passed, M failed'."""
import csv
import glob
import json
import os
import shutil
import sys

import h5py

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import arguments_and_work, check, report, tissue  # noqa: E402

QUASI_STATIC = """
title = "creep restart, quasi-static"
[body]
molecules = [3, 3, 5]
size = [0.02, 0.02, 0.04]
topology = "face-diagonals"
youngs_modulus = 1.0e5
[body.viscoelastic]
gamma = [1.5, 0.8]
tau = [0.5, 5.0]
[calibration]
method = "homogenized"
[[fix]]
face = "z-"
mode = "roller"
[[load]]
face = "z+"
force = [0.0, 0.0, 4.0e-3]
history = [[0.0, 0.0], [0.3, 1.0]]
[solver]
kind = "quasi-static"
time_step = 0.25
steps = 14
tolerance = 1e-10
[output]
fields = ["positions"]
checkpoint_every = 4
progress = false
"""

DYNAMIC = """
title = "creep restart, dynamic"
[body]
molecules = [3, 3, 5]
size = [0.02, 0.02, 0.04]
topology = "face-diagonals"
youngs_modulus = 1.0e5
density = 1000.0
[body.viscoelastic]
gamma = [1.5, 0.8]
tau = [2.0e-3, 2.0e-2]
[calibration]
method = "homogenized"
[[fix]]
face = "z-"
mode = "clamped"
[[load]]
face = "z+"
force = [0.0, 0.0, 4.0e-3]
[solver]
kind = "dynamic"
steps = 600
[output]
fields = ["positions"]
checkpoint_every = 250
history_every = 10
progress = false
"""

STATE_KEYS = ["elongation", "center_of_mass", "reactions", "time", "steps", "kinetic_energy"]


def with_cells(text):
    """The scene with the cell term: nu = 0.4 (springs plus one energy per lattice cell)."""
    return text.replace("youngs_modulus = 1.0e5\n", "youngs_modulus = 1.0e5\npoisson_ratio = 0.4\n", 1)


def rows(out):
    with open(os.path.join(out, "history.csv"), newline="") as f:
        return list(csv.reader(f))


def straight(build, work, name, text, ranks):
    scene = os.path.join(work, name + ".toml")
    with open(scene, "w") as f:
        f.write(text)
    out = os.path.join(work, f"{name}_np{ranks}")
    r = tissue(build, ranks, "run", scene, "--output", out)
    check(r.returncode == 0, f"{name} on {ranks} ranks: exit {r.returncode}: {r.stderr[-400:]}")
    return out


def restart(build, work, source, step, ranks, label):
    """Copies the straight run's directory (its history.csv has every row) and restarts the checkpoint of `step`
    into the copy: history.csv must come back to the straight run's."""
    out = os.path.join(work, label)
    shutil.rmtree(out, ignore_errors=True)
    shutil.copytree(source, out)
    for f in ("summary.json", "final.h5"):
        os.remove(os.path.join(out, f))
    ckpt = os.path.join(out, f"checkpoint_{step:010d}.h5")
    r = tissue(build, ranks, "restart", ckpt, "--output", out)
    check(r.returncode == 0, f"{label}: exit {r.returncode}: {r.stderr[-400:]}")
    return out


def positions(out):
    with h5py.File(os.path.join(out, "final.h5"), "r") as f:
        return f["/molecules/positions"][...].tobytes()


def compare(a, b, label, exact, scale=None, same_state=False):
    """exact: history.csv and the summary's state byte for byte (same rank count). Otherwise history.csv to 1e-9
    of the curve's scale (other rank counts: the reductions, and for quasi-static the Krylov solver, round
    differently); same_state: final.h5's positions byte for byte all the same."""
    if same_state:
        check(positions(a) == positions(b), f"{label}: final positions differ from the uninterrupted run's")
    ra, rb = rows(a), rows(b)
    sa, sb = json.load(open(os.path.join(a, "summary.json"))), json.load(open(os.path.join(b, "summary.json")))
    if exact:
        check(ra == rb, f"{label}: history.csv differs from the uninterrupted run's "
                        f"({len(ra)} against {len(rb)} lines)")
        for k in STATE_KEYS:
            check(sa[k] == sb[k], f"{label}: summary {k} {sa[k]} against {sb[k]}")
        return
    check(len(ra) == len(rb) and ra[0] == rb[0] and [r[:2] for r in ra] == [r[:2] for r in rb],
          f"{label}: history.csv's steps and times differ")
    worst = 0.0
    for x, y in zip(ra[1:], rb[1:]):
        for cx, cy, name in zip(x, y, ra[0]):
            if cx and cy and name != "kinetic_energy":
                worst = max(worst, abs(float(cx) - float(cy)) / scale[name])
    check(worst <= 1e-9, f"{label}: largest difference {worst:.3e} of the curve's scale (bound 1e-9)")
    print(f"{label}: largest difference {worst:.3e} of the curve's scale")


def scales(out):
    r = rows(out)
    s = {}
    for i, name in enumerate(r[0]):
        s[name] = max([abs(float(x[i])) for x in r[1:] if x[i]] + [1e-300])
    # Components that carry nothing (the lateral force, round-off) are measured against the axial ones.
    for axis_of in ("force", "reaction0"):
        big = max(s[f"{axis_of}_{a}"] for a in "xyz")
        for a in "xyz":
            s[f"{axis_of}_{a}"] = big
    return s


def main():
    a, work = arguments_and_work("visco_restart")

    # Quasi-static: checkpoints at steps 4, 8, 12 (the newest two kept: 8 and 12).
    qs = {n: straight(a.build, work, "qs", QUASI_STATIC, n) for n in (1, 2, 3)}
    for n in (1, 2, 3):
        check(sorted(os.path.basename(f) for f in glob.glob(os.path.join(qs[n], "checkpoint_*.h5"))) ==
              ["checkpoint_0000000008.h5", "checkpoint_0000000012.h5"], f"quasi-static {n} ranks: checkpoints kept")
        check(len(rows(qs[n])) == 1 + 16, f"quasi-static {n} ranks: 16 rows (t = 0, the breakpoint 0.3 s and 14 steps)")
    for src, dst in ((1, 1), (2, 2)):
        out = restart(a.build, work, qs[src], 8, dst, f"qs_{src}to{dst}")
        compare(out, qs[src], f"quasi-static {src} -> {dst} ranks", exact=True, same_state=True)
    scale = scales(qs[1])
    for src, dst in ((1, 2), (2, 3)):
        out = restart(a.build, work, qs[src], 8, dst, f"qs_{src}to{dst}")
        compare(out, qs[dst], f"quasi-static {src} -> {dst} ranks", exact=False, scale=scale)
    # The creep went on after the restart: the elongation grows from step 8 to the end.
    r = rows(qs[1])
    e = r[0].index("elongation")
    check(float(r[-1][e]) > 1.05 * float(r[9][e]), "quasi-static: the strip creeps after the checkpoint's step")

    # Dynamic: checkpoints at 250 and 500; rows every 10 steps (0, 10, ..., 600).
    dyn = {n: straight(a.build, work, "dyn", DYNAMIC, n) for n in (1, 2)}
    check(len(rows(dyn[1])) == 1 + 61, "dynamic: a row every 10 steps, step 0 included")
    check(positions(dyn[1]) == positions(dyn[2]), "dynamic: the straight runs on 1 and 2 ranks end bit for bit alike")
    out = restart(a.build, work, dyn[2], 250, 2, "dyn_2to2")
    compare(out, dyn[2], "dynamic 2 -> 2 ranks", exact=True, same_state=True)
    for src, dst in ((1, 2), (2, 3)):
        out = restart(a.build, work, dyn[src], 250, dst, f"dyn_{src}to{dst}")
        compare(out, dyn[src], f"dynamic {src} -> {dst} ranks", exact=False, scale=scales(dyn[1]), same_state=True)
    # The history is what the restart carried: the strip creeps across the checkpoint's step.
    r = rows(dyn[1])
    e = r[0].index("elongation")
    check(float(r[-1][e]) > 1.2 * float(r[1][e]), "dynamic: the strip creeps")

    # Quasi-static on a lattice the lattice multigrid serves (reused across steps, rebuilt at checkpoints and
    # restarts): 1 -> 1 and 2 -> 2 byte for byte.
    mg = QUASI_STATIC.replace("molecules = [3, 3, 5]", "molecules = [9, 9, 17]").replace("4.0e-3", "4.0")
    big = {n: straight(a.build, work, "mg", mg, n) for n in (1, 2)}
    for n in (1, 2):
        out = restart(a.build, work, big[n], 8, n, f"mg_{n}to{n}")
        compare(out, big[n], f"quasi-static, lattice multigrid, {n} -> {n} ranks", exact=True, same_state=True)

    # The cell term (poisson_ratio, fibres) carries its own history per cell (/cells/history, in cell id order):
    # quasi-static 1 -> 1 and 2 -> 2 byte for byte, 1 -> 2 and 2 -> 3 to 1e-9 of the curve's scale (the Krylov
    # solver's round-off); dynamic (forces summed in global order) byte for byte on every rank count.
    cells_qs = {n: straight(a.build, work, "cells_qs", with_cells(QUASI_STATIC), n) for n in (1, 2, 3)}
    for src, dst in ((1, 1), (2, 2)):
        out = restart(a.build, work, cells_qs[src], 8, dst, f"cells_qs_{src}to{dst}")
        compare(out, cells_qs[src], f"cells, quasi-static {src} -> {dst} ranks", exact=True, same_state=True)
    for src, dst in ((1, 2), (2, 3)):
        out = restart(a.build, work, cells_qs[src], 8, dst, f"cells_qs_{src}to{dst}")
        compare(out, cells_qs[dst], f"cells, quasi-static {src} -> {dst} ranks", exact=False,
                scale=scales(cells_qs[1]))
    r = rows(cells_qs[1])
    e = r[0].index("elongation")
    check(float(r[-1][e]) > 1.05 * float(r[9][e]), "cells, quasi-static: the block creeps after the checkpoint")
    cells_dyn = {n: straight(a.build, work, "cells_dyn", with_cells(DYNAMIC), n) for n in (1, 2, 3)}
    check(positions(cells_dyn[1]) == positions(cells_dyn[2]) == positions(cells_dyn[3]),
          "cells, dynamic: the straight runs on 1, 2 and 3 ranks end bit for bit alike")
    for src, dst in ((2, 2), (1, 2), (2, 3)):
        out = restart(a.build, work, cells_dyn[src], 250, dst, f"cells_dyn_{src}to{dst}")
        compare(out, cells_dyn[src], f"cells, dynamic {src} -> {dst} ranks", exact=src == dst,
                scale=scales(cells_dyn[1]), same_state=True)
    # The checkpoint holds what the restart needs: 2 x 2 x 4 cells x 27 (S, then one tensor per Prony term).
    with h5py.File(os.path.join(cells_qs[2], "checkpoint_0000000008.h5"), "r") as f:
        held = f["/cells/history"][...]
    check(held.shape == (16, 27), f"/cells/history has shape {held.shape}, expected (16, 27)")
    # (non-zero, so the byte-for-byte restarts above could not come out without it)
    check(abs(held[:, 9:]).max() > 0 and abs(held[:, :9]).max() > 0, "/cells/history holds a non-zero history")
    # What a checkpoint holds: the history, C connections x (1 + 2 Prony terms) (`tissue info`).
    r = tissue(a.build, 1, "info", os.path.join(qs[1], "checkpoint_0000000012.h5"))
    check(r.returncode == 0 and "/connections/history [" in r.stdout and " x 3]" in r.stdout.split("/connections/history")[1][:20],
          f"tissue info names /connections/history: {r.stdout[-300:]}")
    r = tissue(a.build, 1, "info", os.path.join(cells_qs[1], "checkpoint_0000000012.h5"))
    check(r.returncode == 0 and "/cells/history [16 x 27]" in r.stdout, f"tissue info names /cells/history: {r.stdout[-300:]}")
    # An elastic quasi-static run (no history) is checkpointed and restarted too.
    plain = os.path.join(work, "elastic.toml")
    with open(plain, "w") as f:
        f.write(QUASI_STATIC.replace("[body.viscoelastic]\ngamma = [1.5, 0.8]\ntau = [0.5, 5.0]\n", ""))
    out = os.path.join(work, "elastic")
    r = tissue(a.build, 2, "run", plain, "--output", out)
    check(r.returncode == 0, f"elastic quasi-static run: exit {r.returncode}: {r.stderr[-300:]}")
    again = restart(a.build, work, out, 8, 2, "elastic_2to2")
    compare(again, out, "elastic quasi-static 2 -> 2 ranks", exact=True, same_state=True)
    return report()


if __name__ == "__main__":
    sys.exit(main())
