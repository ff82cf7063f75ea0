#!/usr/bin/env python3
"""A growing quasi-static time step for long creep (solver.time_step_growth, solver.max_time_step; issue 16).

a. Standard-linear-solid creep under a step force (3 x 3 x 4 face diagonals on a roller, gamma = 2, tau = 1 s) to
   t = 30 s, against the closed form eps(t) = eps_inf [1 - gamma/(1+gamma) exp(-t/(tau (1+gamma)))], eps_inf the
   static solve's elongation: with steps growing by 1.1 from 0.05 s up to 2 s, at 1 and 2 ranks, the largest error
   stays below 2e-3 eps_inf in fewer than a tenth of the uniform run's steps (the uniform 0.05 s run for scale).
b. Breakpoints: a load history with breakpoints at 1 s and 10 s: both landed on, and the step after each starts
   from time_step again; the steps grow by exactly the factor between them and stop at max_time_step.
c. Checkpoint/restart keeps the current step: restarted at step 12 (1 -> 1, 2 -> 2 ranks) the run ends byte for
   byte where the uninterrupted one ends.
d. Bad input: a growth below 1, a max_time_step below time_step, a growth on a dynamic run: exit 2, one line.

Usage: time_step_growth_test.py --build BUILD_DIR --source SOURCE_DIR      Prints 'N passed, M failed'."""
import csv
import json
import math
import os
import shutil
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import arguments_and_work, check, report, tissue  # noqa: E402

SCENE = """
title = "SLS creep, growing time step"
[body]
molecules = [3, 3, 4]
size = [0.02, 0.02, 0.03]
topology = "face-diagonals"
youngs_modulus = 1.0e5
[body.viscoelastic]
gamma = [2.0]
tau = [1.0]
[calibration]
method = "homogenized"
[[fix]]
face = "z-"
mode = "roller"
[[load]]
face = "z+"
force = [0.0, 0.0, 4.0e-3]
[solver]
kind = "quasi-static"
time_step = 0.05
end_time = 30.0
tolerance = 1e-11
[output]
fields = []
progress = false
"""
GAMMA, TAU = 2.0, 1.0


def rows(out):
    with open(os.path.join(out, "history.csv"), newline="") as f:
        return [{k: float(v) if v else None for k, v in r.items()} for r in csv.DictReader(f)]


def main():
    a, work = arguments_and_work("time_step_growth")
    scene = os.path.join(work, "creep.toml")
    with open(scene, "w") as f:
        f.write(SCENE)

    def run(label, ranks, *sets, extra=()):
        out = os.path.join(work, label)
        args = ["run", scene, "--output", out] + sum((["--set", s] for s in sets), []) + list(extra)
        r = tissue(a.build, ranks, *args)
        check(r.returncode == 0, f"{label}: exit {r.returncode}: {r.stderr[-400:]}")
        return out

    # a. closed-form creep
    static = run("static", 1, "solver.kind=static")
    e_inf = json.load(open(os.path.join(static, "summary.json")))["elongation"]

    def worst(out):
        return max(abs(r["elongation"] - e_inf * (1 - GAMMA / (1 + GAMMA) * math.exp(-r["time"] / (TAU * (1 + GAMMA)))))
                   for r in rows(out)) / e_inf

    uniform = run("uniform", 1)
    steps_uniform = len(rows(uniform)) - 1
    for ranks in (1, 2):
        grown = run(f"grown_np{ranks}", ranks, "solver.time_step_growth=1.1", "solver.max_time_step=2.0")
        r = rows(grown)
        err = worst(grown)
        check(err < 2e-3, f"a. {ranks} ranks: largest creep error {err:.3e} of eps_inf (bound 2e-3)")
        check(len(r) - 1 < steps_uniform / 10, f"a. {ranks} ranks: {len(r) - 1} steps against {steps_uniform} uniform")
        check(r[-1]["time"] == 30.0, f"a. {ranks} ranks: ends at t = 30 s ({r[-1]['time']})")
        print(f"a. {ranks} ranks: {len(r) - 1} growing steps, largest error {err:.3e} eps_inf; uniform 0.05 s: "
              f"{steps_uniform} steps, {worst(uniform):.3e}")

    # b. breakpoints landed on, the step restarting from time_step after each, growth and cap exact
    hist = run("breakpoints", 1, "solver.time_step_growth=1.5", "solver.max_time_step=1.0",
               "load.0.history=[[0.0, 0.5], [1.0, 0.5], [10.0, 1.0]]")
    t = [r["time"] for r in rows(hist)]
    check(1.0 in t and 10.0 in t, f"b. the breakpoints 1 s and 10 s landed on: {t}")
    h = [t2 - t1 for t1, t2 in zip(t, t[1:])]
    for b in (1.0, 10.0):
        i = t.index(b)
        check(abs(h[i] - 0.05) <= 1e-12, f"b. the step after {b} s is time_step again ({h[i]})")
    i = t.index(1.0)
    check(all(abs(h[k + 1] - min(1.5 * h[k], 1.0)) <= 1e-12 for k in range(i, i + 6)),
          f"b. the steps grow by 1.5 up to 1 s: {h[i:i + 8]}")
    check(max(h) <= 1.0 + 1e-12, f"b. no step above max_time_step ({max(h)})")

    # c. restart keeps the current step
    for ranks in (1, 2):
        grown = run(f"ckpt_np{ranks}", ranks, "solver.time_step_growth=1.1", "solver.max_time_step=2.0",
                    "output.checkpoint_every=12")
        copy = grown + "_restart"
        shutil.copytree(grown, copy)
        os.remove(os.path.join(copy, "summary.json"))
        r = tissue(a.build, ranks, "restart", os.path.join(copy, "checkpoint_0000000024.h5"), "--output", copy)
        check(r.returncode == 0, f"c. restart {ranks} ranks: exit {r.returncode}: {r.stderr[-300:]}")
        same = open(os.path.join(copy, "history.csv")).read() == open(os.path.join(grown, "history.csv")).read()
        check(same, f"c. {ranks} -> {ranks} ranks: history.csv byte for byte the uninterrupted run's")

    # d. bad input
    for what, sets in (("growth below 1", ["solver.time_step_growth=0.9"]),
                       ("max below time_step", ["solver.max_time_step=0.01"]),
                       ("dynamic", ["solver.kind=dynamic", "solver.steps=10", "solver.time_step_growth=1.1"])):
        out = os.path.join(work, "bad_" + what.replace(" ", "_"))
        r = subprocess.run([os.path.join(a.build, "tissue"), "run", scene, "--output", out] +
                           sum((["--set", s] for s in sets), []), capture_output=True, text=True, timeout=120)
        lines = r.stderr.strip().splitlines()
        check(r.returncode == 2 and len(lines) == 1 and "solver." in lines[0] and not os.path.exists(out),
              f"d. {what}: exit {r.returncode}, {r.stderr.strip()[-200:]!r}")
    return report()


if __name__ == "__main__":
    sys.exit(main())
