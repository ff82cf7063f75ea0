#!/usr/bin/env python3
"""The quasi-static solver's extrapolated start (issue 16): each step's Newton starts from
x_n + (x_n - x_(n-1)) dt_n / dt_(n-1) on the free molecules, and the answers are those of the start from x_n.

A linear ramp of a held displacement on an elastic bar (rollers on z- and z+, the top moved by 4e-6 m = 1e-4
strain over 10 steps of 1 s; E = 1e9 Pa): the response is linear up to the geometric nonlinearity, so the
extrapolation is exact up to it, and
  - every step converges in no more Newton iterations than the same step started from x_n
    (-quasi_static_extrapolate false), and the ramp in fewer in all;
  - every history.csv row equals that run's to the solve tolerance (relative 1e-10 of the reactions: bound 1e-8),
    and the reaction is the closed form of the ramp, E A eps(t), eps(t) = 1e-4 t / 10 s, to 2e-4 (the lattice's
    geometric nonlinearity at 1e-4 strain, ~0.7 x the strain);
  - 1, 2 and 3 ranks give the same rows to 1e-8;
  - a checkpoint every 4 steps, restarted from step 4 on the same rank count (1, 2, 3), ends with history.csv and
    final.h5's positions byte for byte the uninterrupted run's (both start the step after a checkpoint from x_n).
The same ramp on a 9 x 9 x 17 bar (the lattice multigrid), 2 ranks: fewer Newton iterations in all, same rows.

Usage: quasi_static_extrapolation_test.py --build BUILD_DIR --source SOURCE_DIR      Prints 'N passed, M failed'."""
import csv
import os
import re
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import arguments_and_work, check, report, tissue  # noqa: E402
from visco_restart_test import positions, restart  # noqa: E402  (h5py, the restart into a copy of the run)

E, AREA, LENGTH, D, T = 1.0e9, 0.02 * 0.02, 0.04, 4.0e-6, 10.0

SCENE = """
title = "elastic ramp, quasi-static"
[body]
molecules = [3, 3, 5]
size = [0.02, 0.02, 0.04]
topology = "face-diagonals"
youngs_modulus = 1.0e9
[calibration]
method = "homogenized"
[[fix]]
face = "z-"
mode = "roller"
[[fix]]
face = "z+"
mode = "roller"
displacement = [0.0, 0.0, 4.0e-6]
history = [[0.0, 0.0], [10.0, 1.0]]
[solver]
kind = "quasi-static"
time_step = 1.0
steps = 10
tolerance = 1e-10
[output]
fields = ["positions"]
checkpoint_every = 4
progress = false
"""


def rows(out):
    with open(os.path.join(out, "history.csv"), newline="") as f:
        return list(csv.DictReader(f))


def newton_per_step(log):
    """Newton iterations of each converged quasi-static step (t = 0 first), from -snes_converged_reason."""
    its, now = [], 0
    for line in log.splitlines():
        m = re.search(r"Nonlinear solve (converged|did not converge) due to \S+ iterations (\d+)", line)
        if m:
            now += int(m.group(2))
            if m.group(1) == "converged":
                its.append(now)
                now = 0
    return its


def run(build, work, label, ranks, text, *petsc):
    scene = os.path.join(work, label + ".toml")
    with open(scene, "w") as f:
        f.write(text)
    out = os.path.join(work, label)
    r = tissue(build, ranks, "run", scene, "--output", out, "--", "-snes_converged_reason", *petsc)
    check(r.returncode == 0, f"{label}: exit {r.returncode}: {r.stderr[-400:]}")
    return out, newton_per_step(r.stdout)


def largest_difference(a, b, scale):
    return max(abs(float(x[k]) - float(y[k])) / scale for x, y in zip(a, b)
               for k in ("reaction0_z", "reaction1_z", "reaction1_x", "reaction1_y"))


def compare_runs(label, work, name_on, name_off, steps):
    """The extrapolated run against the one started from x_n: Newton iterations and rows."""
    (on, its_on), (off, its_off) = name_on, name_off
    check(len(its_on) == steps + 1 and len(its_off) == steps + 1,
          f"{label}: {steps + 1} converged solves each, got {len(its_on)} and {len(its_off)}")
    check(all(a <= b for a, b in zip(its_on, its_off)) and sum(its_on) < sum(its_off),
          f"{label}: Newton per step {its_on} against {its_off} from x_n (each no more, fewer in all)")
    ra, rb = rows(on), rows(off)
    scale = max(abs(float(r["reaction1_z"])) for r in rb)
    diff = largest_difference(ra, rb, scale)
    check(len(ra) == len(rb) == steps + 1 and diff <= 1e-8,
          f"{label}: rows differ from the start from x_n by {diff:.2e} of the largest reaction (bound 1e-8)")
    print(f"{label}: Newton per step {its_on} (from x_n: {its_off}); rows equal to {diff:.2e}")
    return ra


def main():
    a, work = arguments_and_work("quasi_static_extrapolation")

    straight = {}
    for n in (1, 2, 3):
        on = run(a.build, work, f"ramp_np{n}", n, SCENE)
        off = run(a.build, work, f"ramp_off_np{n}", n, SCENE, "-quasi_static_extrapolate", "false")
        ra = compare_runs(f"{n} ranks", work, on, off, 10)
        straight[n] = on[0]
        # The closed form of the ramp: R(t) = E A eps(t) on the moved face (pulling up), minus that on the base.
        worst = 0.0
        for r in ra[1:]:
            expect = E * AREA * D * float(r["time"]) / T / LENGTH
            worst = max(worst, abs(float(r["reaction1_z"]) - expect) / expect,
                        abs(-float(r["reaction0_z"]) - expect) / expect)
        check(worst <= 2e-4, f"{n} ranks: reactions against E A eps(t): {worst:.2e} (bound 2e-4)")
        print(f"{n} ranks: reactions against E A eps(t) to {worst:.2e}")
    scale = max(abs(float(r["reaction1_z"])) for r in rows(straight[1]))
    for n in (2, 3):
        diff = largest_difference(rows(straight[n]), rows(straight[1]), scale)
        check(diff <= 1e-8, f"{n} ranks against 1: {diff:.2e} (bound 1e-8)")

    for n in (1, 2, 3):
        out = restart(a.build, work, straight[n], 4, n, f"restart_np{n}")
        if os.path.exists(os.path.join(out, "final.h5")):
            with open(os.path.join(out, "history.csv"), "rb") as f1, \
                    open(os.path.join(straight[n], "history.csv"), "rb") as f2:
                check(f1.read() == f2.read(), f"restart {n} -> {n} ranks: history.csv differs from the straight run's")
            check(positions(out) == positions(straight[n]),
                  f"restart {n} -> {n} ranks: final positions differ from the straight run's")

    mg = SCENE.replace("molecules = [3, 3, 5]", "molecules = [9, 9, 17]")
    on = run(a.build, work, "mg_np2", 2, mg)
    off = run(a.build, work, "mg_off_np2", 2, mg, "-quasi_static_extrapolate", "false")
    compare_runs("lattice multigrid, 2 ranks", work, on, off, 10)
    return report()


if __name__ == "__main__":
    sys.exit(main())
