#!/usr/bin/env python3
"""Viscoelasticity with the cell term: nu stays constant in time (issue 16: "the same relaxation acts on every
elastic term ... so nu stays constant in time").

A 5 x 5 x 7 block, face diagonals, `homogenized` with nu = 0.4 (springs plus the per-cell term), one Prony term
(gamma = 1, tau = 1 s), a roller base and a step load on top held for 40 s (quasi-static, 1 s steps), at a strain
of about 1e-7 (linear: the geometric nonlinearity is ~1e-7). Every elastic part relaxes by the same G(t), so the
strain tensor is one creep function times the elastic one:
  - nu(t) = -lateral_strain / (elongation / rest_length) equals 0.4 at every step (1e-6);
  - the first row (t = 0, the instantaneous response) is 1 / (1 + gamma) of the last (relaxed) one (1e-6), and
    the last equals the elastic elongation of the same scene without the Prony series (1e-6);
  - 1 and 2 ranks give the same curve (1e-6 of its scale: Krylov round-off differs with the partition).
With the springs relaxing and the cells not (the state before this test), nu read 0.357 at t = 0 and 0.400 relaxed.

Usage: visco_poisson_test.py --build BUILD_DIR --source SOURCE_DIR      Prints 'N passed, M failed'."""
import csv
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import arguments_and_work, check, report, run_scene  # noqa: E402

SCENE = """
title = "nu constant in time"
[body]
molecules = [5, 5, 7]
size = [0.004, 0.004, 0.006]
topology = "face-diagonals"
youngs_modulus = 1.0e5
poisson_ratio = 0.4
[body.viscoelastic]
gamma = [1.0]
tau = [1.0]
[calibration]
method = "homogenized"
[[fix]]
face = "z-"
mode = "roller"
[[load]]
face = "z+"
force = [0.0, 0.0, 1.6e-7]
[solver]
kind = "quasi-static"
time_step = 1.0
end_time = 40.0
tolerance = 1e-12
[output]
fields = []
progress = false
"""


def main():
    a, work = arguments_and_work("visco_poisson")

    def run(label, ranks, text):
        out, r = run_scene(a.build, work, label, ranks, text)
        check(r.returncode == 0, f"{label}: exit {r.returncode}: {r.stderr[-400:]}")
        return out

    elastic = run("elastic", 1, SCENE.replace("[body.viscoelastic]\ngamma = [1.0]\ntau = [1.0]\n", "")
                  .replace('kind = "quasi-static"\ntime_step = 1.0\nend_time = 40.0\n', 'kind = "static"\n'))
    summary = json.load(open(os.path.join(elastic, "summary.json")))
    dl_elastic, length = summary["elongation"], summary["rest_length"]
    curves = {}
    for ranks in (1, 2):
        out = run(f"np{ranks}", ranks, SCENE)
        with open(os.path.join(out, "history.csv")) as f:
            rows = [(float(r["time"]), float(r["elongation"]), float(r["lateral_strain"])) for r in csv.DictReader(f)]
        curves[ranks] = rows
        worst = max(abs(-lat / (dl / length) - 0.4) for _, dl, lat in rows)
        check(worst <= 1e-6, f"{ranks} ranks: nu(t) - 0.4 at most {worst:.3e} (1e-6)")
        ratio = rows[0][1] / rows[-1][1]
        check(abs(ratio * 2.0 - 1.0) <= 1e-6, f"{ranks} ranks: instantaneous / relaxed elongation {ratio:.9f} (1/2)")
        check(abs(rows[-1][1] / dl_elastic - 1.0) <= 1e-6,
              f"{ranks} ranks: relaxed elongation / elastic {rows[-1][1] / dl_elastic:.9f} (1)")
        print(f"{ranks} ranks: {len(rows)} rows, nu error {worst:.3e}, instantaneous/relaxed {ratio:.9f}")
    scale = max(abs(r[1]) for r in curves[1])
    check(len(curves[1]) == len(curves[2]) and
          max(abs(x[1] - y[1]) for x, y in zip(curves[1], curves[2])) <= 1e-6 * scale,
          "the same curve at 1 and 2 ranks (to the solver's tolerance)")
    return report()


if __name__ == "__main__":
    sys.exit(main())
