#!/usr/bin/env python3
"""DIR/history.csv and summary.json's `reactions` as a user reads them (issue 16): `tissue run` of a small quasi-
static creep scene with a ramp-and-hold load at 1 and 2 ranks, read back with the csv module. Checks: the header
is the interface's (step, time, force_x..z, elongation, kinetic_energy, reaction<i>_x..z per [[fix]]); one row per
step, t = 0 first, the breakpoint 0.3 s landed on; every cell a number; the applied force follows the history; the
roller's reaction balances it to the solver's tolerance; summary.json's reactions and time are the last row's;
the same curve at 1 and 2 ranks to 1e-10; a relaxation run's single row (its equilibrium); a static run's load
steps (each row's reactions balancing its load, the last row the summary's); and a second run into the same directory starts a new file.

Usage: history_csv_test.py --build BUILD_DIR --source SOURCE_DIR      Prints 'N passed, M failed'."""
import argparse
import csv
import json
import os
import shutil
import subprocess
import sys

SCENE = """
title = "history.csv"
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
history = [[0.0, 0.0], [0.3, 1.0]]
[solver]
kind = "quasi-static"
time_step = 0.25
end_time = 1.0
tolerance = 1e-9
[output]
fields = []
progress = false
"""
COLUMNS = ["step", "time", "force_x", "force_y", "force_z", "elongation", "kinetic_energy",
           "reaction0_x", "reaction0_y", "reaction0_z", "lateral_strain"]

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import check, report  # noqa: E402


def run(build, workdir, ranks, out):
    cmd = ["mpirun", "--oversubscribe", "-np", str(ranks), os.path.join(build, "tissue"), "run",
           os.path.join(workdir, "scene.toml"), "--output", out]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    check(r.returncode == 0, f"{ranks} ranks: exit code {r.returncode}: {r.stderr[-500:]}")
    with open(os.path.join(out, "history.csv"), newline="") as f:
        rows = list(csv.reader(f))
    return rows, json.load(open(os.path.join(out, "summary.json")))


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--build", required=True)
    p.add_argument("--source", required=True)
    a = p.parse_args()
    workdir = os.path.join(a.build, "tests", "out", "history_csv")
    shutil.rmtree(workdir, ignore_errors=True)
    os.makedirs(workdir)
    with open(os.path.join(workdir, "scene.toml"), "w") as f:
        f.write(SCENE)
    curves = {}
    for ranks in (1, 2):
        rows, summary = run(a.build, workdir, ranks, os.path.join(workdir, f"np{ranks}"))
        check(rows[0] == COLUMNS, f"{ranks} ranks: header {rows[0]}")
        data = [[float(c) for c in r] for r in rows[1:]]  # every cell a number (a float() error fails the test)
        times = [r[1] for r in data]
        check(times == [0.0, 0.25, 0.3, 0.55, 0.8, 1.0], f"{ranks} ranks: times {times}")
        check([r[0] for r in data] == list(range(len(data))), f"{ranks} ranks: steps numbered from 0")
        for r in data:
            factor = min(r[1] / 0.3, 1.0)
            check(abs(r[4] - 4.0e-3 * factor) <= 1e-15, f"{ranks} ranks: force_z {r[4]} at t = {r[1]}")
            check(abs(r[9] + r[4]) <= 1e-8 * 4.0e-3, f"{ranks} ranks: reaction {r[9]} balances {r[4]} at t = {r[1]}")
            check(r[6] == 0.0, "no kinetic energy in a quasi-static run")
        check(data[0][5] == 0.0 and all(b[5] > a_[5] for a_, b in zip(data[1:], data[2:])),
              f"{ranks} ranks: the elongation starts at 0 and creeps: {[r[5] for r in data]}")
        check(summary["reactions"] == [data[-1][7:10]], f"{ranks} ranks: summary reactions {summary['reactions']}")
        check(summary["time"] == 1.0 and summary["steps"] == 5, f"{ranks} ranks: summary time and steps")
        check(summary["applied_force"] == data[-1][4], f"{ranks} ranks: summary applied_force {summary['applied_force']}")
        curves[ranks] = data
    # Eq. 3 reads the load applied at the run's end: stopped mid-ramp (t = 0.25 s: 5/6 of the force) and after an
    # unloading (the force back to 0: no modulus). Before, summary.json read the nominal force: E 20 % off mid-ramp
    # and a modulus from the creep left after unloading.
    for label, sets, factor in (("mid-ramp", ["solver.end_time=0.25"], 0.25 / 0.3),
                                ("unloaded", ["load.0.history=[[0.0,0.0],[0.3,1.0],[0.55,0.0]]"], 0.0)):
        out = os.path.join(workdir, label)
        cmd = ["mpirun", "--oversubscribe", "-np", "2", os.path.join(a.build, "tissue"), "run",
               os.path.join(workdir, "scene.toml"), "--output", out] + sum((["--set", s] for s in sets), [])
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        s = json.load(open(os.path.join(out, "summary.json"))) if r.returncode == 0 else {}
        F = 4.0e-3 * factor
        ok = r.returncode == 0 and abs(s["applied_force"] - F) <= 1e-15
        if ok and factor == 0.0:
            ok = s["youngs_modulus_measured"] is None
        elif ok:
            E = F * s["rest_length"] / (s["elongation"] * s["cross_section"])
            ok = abs(s["youngs_modulus_measured"] - E) <= 1e-12 * E
        check(ok, f"{label}: summary applied_force {s.get('applied_force')} (expected {F}), E "
                  f"{s.get('youngs_modulus_measured')} from it: {r.stderr[-300:]}")
    check(all(abs(x - y) <= 1e-10 * abs(curves[1][-1][5]) for x, y in
              zip([r[5] for r in curves[1]], [r[5] for r in curves[2]])), "the same elongation at 1 and 2 ranks")
    # Relaxation (FIRE): one row, the equilibrium found: step 1, time 1, the elongation and reactions of the summary.
    relax = SCENE.replace("[body.viscoelastic]\ngamma = [2.0]\ntau = [1.0]\n", "") \
        .replace('history = [[0.0, 0.0], [0.3, 1.0]]\n', "") \
        .replace('kind = "quasi-static"\ntime_step = 0.25\nend_time = 1.0\n', 'kind = "relaxation"\n')
    with open(os.path.join(workdir, "relax.toml"), "w") as f:
        f.write(relax)
    out = os.path.join(workdir, "relax")
    r = subprocess.run(["mpirun", "--oversubscribe", "-np", "2", os.path.join(a.build, "tissue"), "run",
                        os.path.join(workdir, "relax.toml"), "--output", out], capture_output=True, text=True, timeout=120)
    if check(r.returncode == 0, f"relaxation: exit code {r.returncode}: {r.stderr[-300:]}"):
        with open(os.path.join(out, "history.csv"), newline="") as f:
            rows = list(csv.reader(f))
        summary = json.load(open(os.path.join(out, "summary.json")))
        data = [[float(c) for c in row] for row in rows[1:]]
        check(rows[0] == COLUMNS and len(data) == 1 and data[0][:2] == [1.0, 1.0],
              f"relaxation: one row, step 1 at time 1: {rows}")
        check(data[0][5] == summary["elongation"] and [data[0][7:10]] == summary["reactions"],
              "relaxation: the row's elongation and reactions are the summary's")

    # Static in three load steps: one row a load step (time = the loads' fraction), each row's reactions balancing
    # its own applied force (the last row's come from the final residual's evaluation, not a second one: a stale
    # step's reactions would balance 2/3 of the load), and the summary's reactions the last row's, at 1 and 2 ranks.
    static = relax.replace('kind = "relaxation"\n', 'kind = "static"\nload_steps = 3\n')
    with open(os.path.join(workdir, "static.toml"), "w") as f:
        f.write(static)
    for ranks in (1, 2):
        out = os.path.join(workdir, f"static_np{ranks}")
        r = subprocess.run(["mpirun", "--oversubscribe", "-np", str(ranks), os.path.join(a.build, "tissue"), "run",
                            os.path.join(workdir, "static.toml"), "--output", out], capture_output=True, text=True,
                           timeout=120)
        if not check(r.returncode == 0, f"static, {ranks} ranks: exit code {r.returncode}: {r.stderr[-300:]}"):
            continue
        with open(os.path.join(out, "history.csv"), newline="") as f:
            rows = list(csv.reader(f))
        summary = json.load(open(os.path.join(out, "summary.json")))
        data = [[float(c) for c in row] for row in rows[1:]]
        check(rows[0] == COLUMNS and [row[0] for row in data] == [1.0, 2.0, 3.0], f"static: three rows: {rows}")
        for row in data:
            check(abs(row[4] - 4.0e-3 * row[1]) <= 1e-15, f"static, {ranks} ranks: force_z {row[4]} at {row[1]}")
            check(abs(row[9] + row[4]) <= 1e-8 * 4.0e-3, f"static, {ranks} ranks: reaction {row[9]} balances {row[4]}")
        check(data[-1][1] == 1.0 and [data[-1][7:10]] == summary["reactions"] and data[-1][5] == summary["elongation"],
              f"static, {ranks} ranks: the last row is the summary's: {data[-1]} {summary['reactions']}")

    # A second run into the same directory writes a new history.csv, not rows after the old ones.
    rows, _ = run(a.build, workdir, 1, os.path.join(workdir, "np1"))
    check(len(rows) == 7, f"a second run rewrites history.csv ({len(rows)} lines)")
    return report()


if __name__ == "__main__":
    sys.exit(main())
