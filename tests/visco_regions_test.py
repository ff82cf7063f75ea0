#!/usr/bin/env python3
"""A Prony series per region ([[body.region]] with its own [body.region.viscoelastic]; issue 16).

A 4 x 3 x 5 bar, rectangular topology, linear calibration, both ends clamped and the top moved by 1e-4 of its
length at t = 0 and held (quasi-static, 0.25 s steps to 10 s). Under that uniform strain every axial spring is
stretched alike and the lateral ones not at all, so each spring relaxes by its own table and the reaction is
R(t) = R_el (w G_region(t) + (1 - w) G_body(t)), R_el the elastic reaction (the same scene without Prony series)
and w the region's share of the axial stiffness: the region x <= 1.5 h holds the columns at x = 0 and h, whose
tributary widths h/2 + h are half of 3 h, so w = 1/2. G = 1 + sum gamma_i exp(-t / tau_i) with the body's
gamma = [0.5], tau = [3] s and the region's gamma = [2, 1], tau = [0.5, 8] s. Checked to 1e-9 relative at 1 and
2 ranks; a region table equal to the body's gives the body-only run byte for byte; a mesh region's Prony table is
refused (exit 2).

Usage: visco_regions_test.py --build BUILD_DIR --source SOURCE_DIR      Prints 'N passed, M failed'."""
import csv
import json
import math
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import arguments_and_work, check, report, tissue  # noqa: E402

SCENE = """
title = "Prony per region"
[body]
molecules = [4, 3, 5]
size = [0.03, 0.02, 0.04]
topology = "rectangular"
youngs_modulus = 1.0e5
[body.viscoelastic]
gamma = [0.5]
tau = [3.0]
[[body.region]]
lo = [-1.0, -1.0, -1.0]
hi = [0.015, 1.0, 1.0]
youngs_modulus = 1.0e5
[body.region.viscoelastic]
gamma = [{region_gamma}]
tau = [{region_tau}]
[calibration]
method = "linear"
[[fix]]
face = "z-"
mode = "clamped"
[[fix]]
face = "z+"
mode = "clamped"
displacement = [0.0, 0.0, 4.0e-6]
[solver]
kind = "quasi-static"
time_step = 0.25
end_time = 10.0
tolerance = 1e-12
[output]
fields = []
progress = false
"""


def G(t, gamma, tau):
    return 1.0 + sum(g * math.exp(-t / s) for g, s in zip(gamma, tau))


def main():
    a, work = arguments_and_work("visco_regions")

    def run(label, ranks, text, *sets):
        path = os.path.join(work, label + ".toml")
        with open(path, "w") as f:
            f.write(text)
        out = os.path.join(work, label)
        r = tissue(a.build, ranks, "run", path, "--output", out, *sum((["--set", s] for s in sets), []))
        check(r.returncode == 0, f"{label}: exit {r.returncode}: {r.stderr[-400:]}")
        return out

    two = SCENE.format(region_gamma="2.0, 1.0", region_tau="0.5, 8.0")
    elastic = SCENE.replace("[body.region.viscoelastic]\ngamma = [{region_gamma}]\ntau = [{region_tau}]\n", "") \
        .replace("[body.viscoelastic]\ngamma = [0.5]\ntau = [3.0]\n", "")
    static = run("elastic", 1, elastic, "solver.end_time=0.0")
    r_el = json.load(open(os.path.join(static, "summary.json")))["reactions"][1][2]
    curves = {}
    for ranks in (1, 2):
        out = run(f"regions_np{ranks}", ranks, two)
        with open(os.path.join(out, "history.csv")) as f:
            rows = [(float(r["time"]), float(r["reaction1_z"])) for r in csv.DictReader(f)]
        curves[ranks] = rows
        worst = max(abs(R - r_el * (0.5 * G(t, [2.0, 1.0], [0.5, 8.0]) + 0.5 * G(t, [0.5], [3.0]))) / abs(r_el)
                    for t, R in rows)
        check(worst <= 1e-9, f"{ranks} ranks: reaction against R_el (G_region + G_body) / 2: {worst:.3e} (1e-9)")
        print(f"{ranks} ranks: {len(rows)} rows, largest relative error {worst:.3e}")
    check(max(abs(x[1] - y[1]) for x, y in zip(curves[1], curves[2])) <= 1e-9 * abs(r_el),
          "the same curve at 1 and 2 ranks")

    # A region whose table is the body's: the body-only run, byte for byte.
    same = run("same_table", 2, SCENE.format(region_gamma="0.5", region_tau="3.0"))
    body_only = SCENE.replace("[body.region.viscoelastic]\ngamma = [{region_gamma}]\ntau = [{region_tau}]\n", "")
    plain = run("body_only", 2, body_only)
    check(open(os.path.join(same, "history.csv")).read() == open(os.path.join(plain, "history.csv")).read(),
          "a region with the body's table: the body-only run byte for byte")

    # A mesh region has no Prony table of its own: refused.
    mesh = os.path.join(a.source, "tests", "meshes")
    msh = next((os.path.abspath(os.path.join(mesh, f)) for f in sorted(os.listdir(mesh)) if f.endswith(".msh")), None)
    if msh:
        text = ('title = "mesh"\n[body]\nshape = "mesh"\nfile = "%s"\nyoungs_modulus = 1.0e5\n'
                '[[body.region]]\nname = "a"\n[body.region.viscoelastic]\ngamma = [1.0]\ntau = [1.0]\n' % msh)
        path = os.path.join(work, "mesh.toml")
        with open(path, "w") as f:
            f.write(text)
        r = subprocess.run([os.path.join(a.build, "tissue"), "run", path, "--output", os.path.join(work, "mesh")],
                           capture_output=True, text=True, timeout=120)
        lines = r.stderr.strip().splitlines()
        check(r.returncode == 2 and len(lines) == 1 and "viscoelastic" in lines[0],
              f"a mesh region's Prony table refused: exit {r.returncode}: {r.stderr.strip()[-200:]!r}")
    return report()


if __name__ == "__main__":
    sys.exit(main())
