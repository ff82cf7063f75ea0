#!/usr/bin/env python3
"""The round-off floor of a quasi-static scene driven only by displacements (issue 16): the residual's reference
is the force the step carries (the reactions), and solver.tolerance is checked against that same reference, not
against 1 N.

A 3 x 3 x 5 Prony bar (E = 1e9 Pa, gamma = 1, tau = 1 s), both ends clamped, the top moved by d at t = 0 and held
(no applied force). The springs' round-off is ~1e-9 N; the reactions are ~840 N at d = 4e-5 m.
  - d = 4e-5 m, tolerance 1e-11: reachable against the reactions (floor ~1.4e-12), though not against 1 N (1.1e-9):
    no warning, tolerance_used = 1e-11, and at every row the two holds' reactions balance (no load: their sum is
    zero, Newton's third law summed over the bar) to 2e-11 of the reaction. Against 1 N the tolerance was raised
    to 1.1e-9 and they balanced to 5e-9 only.
  - d = 4e-11 m (reactions ~8e-4 N), tolerance 1e-11: the floor against the reactions (~1.4e-6) is used, with one
    warning naming the reactions; tolerance_used is that floor.
  - d = 4e-17 m (reactions ~1e-9 N, the round-off itself): refused, exit 3 with one line (no equilibrium can be
    resolved). Against 1 N the run "converged" on noise.
1, 2 and 3 ranks alike.

Usage: quasi_static_reference_test.py --build BUILD_DIR --source SOURCE_DIR      Prints 'N passed, M failed'."""
import csv
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import arguments_and_work, check, report, run_scene  # noqa: E402

SCENE = """
title = "displacement-only relaxation"
[body]
molecules = [3, 3, 5]
size = [0.02, 0.02, 0.04]
topology = "face-diagonals"
youngs_modulus = 1.0e9
[body.viscoelastic]
gamma = [1.0]
tau = [1.0]
[calibration]
method = "homogenized"
[[fix]]
face = "z-"
mode = "clamped"
[[fix]]
face = "z+"
mode = "clamped"
displacement = [0.0, 0.0, DISPLACEMENT]
[solver]
kind = "quasi-static"
time_step = 0.5
steps = 4
tolerance = 1e-11
[output]
fields = []
progress = false
"""


def main():
    a, work = arguments_and_work("quasi_static_reference")

    def run(label, ranks, displacement):
        return run_scene(a.build, work, label, ranks, SCENE.replace("DISPLACEMENT", displacement))

    for ranks in (1, 2, 3):
        out, r = run(f"reachable_np{ranks}", ranks, "4.0e-5")
        if not check(r.returncode == 0, f"{ranks} ranks, d = 4e-5: exit {r.returncode}: {r.stderr[-300:]}"):
            continue
        check("warning" not in r.stderr, f"{ranks} ranks, d = 4e-5: no warning: {r.stderr[-300:]}")
        s = json.load(open(os.path.join(out, "summary.json")))
        check(s["solver"]["converged"] and s["solver"]["tolerance_used"] == 1e-11,
              f"{ranks} ranks, d = 4e-5: tolerance_used {s['solver']['tolerance_used']} (asked 1e-11)")
        with open(os.path.join(out, "history.csv"), newline="") as f:
            rows = list(csv.DictReader(f))
        check(len(rows) == 5, f"{ranks} ranks: 5 rows, got {len(rows)}")
        worst = max(abs(float(w["reaction0_z"]) + float(w["reaction1_z"])) / abs(float(w["reaction1_z"])) for w in rows)
        check(worst <= 2e-11 and abs(float(rows[0]["reaction1_z"])) > 100,
              f"{ranks} ranks, d = 4e-5: the reactions balance to {worst:.2e} (bound 2e-11)")
        print(f"{ranks} ranks, d = 4e-5 m: reactions {float(rows[0]['reaction1_z']):.6g} N at t = 0, "
              f"balanced to {worst:.2e}")

        out, r = run(f"floor_np{ranks}", ranks, "4.0e-11")
        s = json.load(open(os.path.join(out, "summary.json"))) if r.returncode == 0 else {"solver": {}}
        used = s["solver"].get("tolerance_used", 0)
        warnings = [line for line in r.stderr.splitlines() if "warning" in line]
        check(r.returncode == 0 and len(warnings) == 1 and "reactions" in warnings[0] and 1e-7 < used < 1e-5,
              f"{ranks} ranks, d = 4e-11: exit {r.returncode}, one warning naming the reactions, tolerance_used "
              f"{used}: {r.stderr[-300:]}")
        print(f"{ranks} ranks, d = 4e-11 m: tolerance_used {used:.3g}")

        out, r = run(f"unreachable_np{ranks}", ranks, "4.0e-17")
        lines = [line for line in r.stderr.splitlines() if line.startswith("tissue: ") and "round-off" in line]
        check(r.returncode == 3 and len(lines) == 1 and "reactions" in lines[0] and "no equilibrium" in lines[0],
              f"{ranks} ranks, d = 4e-17: exit {r.returncode} with one line: {r.stderr[-300:]}")
    return report()


if __name__ == "__main__":
    sys.exit(main())
