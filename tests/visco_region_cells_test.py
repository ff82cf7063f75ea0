#!/usr/bin/env python3
"""A region's own Prony series with the cell term (issue 16): each cell relaxes by the table of the region whose
box holds its rest centre, as each spring does by its rest midpoint, so springs and cells of a region share one
G(t) and nu stays constant in time in every region.

A confined column in series: 3 x 3 x 9 molecules (h = 1 mm, 8 cell layers), face diagonals, `homogenized` with
nu = 0.4 (springs plus the per-cell term), rollers on the base and on the four lateral faces, a step force on top
held (quasi-static). The lower 3 layers relax by the body's table (gamma = [1], tau = [1] s), the upper 5 by the
region's (gamma = [2], tau = [0.4] s); E and nu are the same in both, so the elastic column is uniform and, the
lateral displacement being held everywhere, every layer is in uniaxial strain under the same axial stress: the
layers' elongations add, each with its own standard-linear-solid creep function (why not the step-strain
relaxation of two regions side by side: at their common plane the two relaxing sides pull a free molecule
sideways by different amounts, so the uniform strain is not the lattice's equilibrium there, and in series under
a step strain the answer is a convolution):
  e(t) = e_s [3/8 c_body(t) + 5/8 c_region(t)],  c(t) = 1 - gamma/(1+gamma) exp(-t / (tau (1+gamma))),
e_s the static (relaxed) elongation of the same scene. The exponential update is exact only for a force linear
within a step (second order in dt under creep), so the run uses dt = 5 ms to 1 s: checked to 1e-6 of e_s, and
the error falls as dt^2 (dt = 20 ms gives 16x it to 0.2). The lateral faces' reactions are nu/(1 - nu) times the
axial stress over each layer: constant in time exactly when every region's cells relax with its springs (nu
constant per region; with the cells on the body's table instead they drift), checked to 1e-6 of their value.
1, 2 and 3 ranks; a checkpoint and restart (1 -> 1, 2 -> 2) gives history.csv byte for byte, 2 -> 3 to 1e-9.

Usage: visco_region_cells_test.py --build BUILD_DIR --source SOURCE_DIR      Prints 'N passed, M failed'."""
import csv
import json
import math
import os
import shutil
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import arguments_and_work, check, report, run_scene, tissue  # noqa: E402

SCENE = """
title = "Prony per region with the cell term"
[body]
molecules = [3, 3, 9]
size = [0.002, 0.002, 0.008]
topology = "face-diagonals"
youngs_modulus = 1.0e5
poisson_ratio = 0.4
[body.viscoelastic]
gamma = [1.0]
tau = [1.0]
[[body.region]]
lo = [-1.0, -1.0, 0.003]
hi = [1.0, 1.0, 1.0]
youngs_modulus = 1.0e5
poisson_ratio = 0.4
[body.region.viscoelastic]
gamma = [2.0]
tau = [0.4]
[calibration]
method = "homogenized"
[[fix]]
face = "z-"
mode = "roller"
[[fix]]
face = "x-"
mode = "roller"
[[fix]]
face = "x+"
mode = "roller"
[[fix]]
face = "y-"
mode = "roller"
[[fix]]
face = "y+"
mode = "roller"
[[load]]
face = "z+"
force = [0.0, 0.0, 4.0e-7]
[solver]
kind = "quasi-static"
time_step = 0.005
end_time = 1.0
tolerance = 1e-13
[output]
fields = []
progress = false
"""
BODY = (1.0, 1.0)     # gamma, tau
REGION = (2.0, 0.4)
SHARE = 5.0 / 8.0     # the region's layers: z >= 3 mm of 8 mm


def creep(t, gamma, tau):
    return 1.0 - gamma / (1.0 + gamma) * math.exp(-t / (tau * (1.0 + gamma)))


def rows(out):
    with open(os.path.join(out, "history.csv"), newline="") as f:
        return list(csv.DictReader(f))


def main():
    a, work = arguments_and_work("visco_region_cells")

    def run(label, ranks, text):
        out, r = run_scene(a.build, work, label, ranks, text)
        check(r.returncode == 0, f"{label}: exit {r.returncode}: {r.stderr[-400:]}")
        return out

    static = run("static", 1, SCENE.replace('kind = "quasi-static"\ntime_step = 0.005\nend_time = 1.0\n',
                                            'kind = "static"\n'))
    summary = json.load(open(os.path.join(static, "summary.json")))
    e_s = summary["elongation"]
    lateral_s = summary["reactions"][1][0]  # x-: nu/(1-nu) times the axial stress, over the face

    def errors(out):
        r = rows(out)
        e = max(abs(float(x["elongation"]) - e_s * ((1 - SHARE) * creep(float(x["time"]), *BODY) +
                                                    SHARE * creep(float(x["time"]), *REGION))) for x in r) / e_s
        # The lateral reaction of every row: constant (its static value) when nu is constant in each region.
        lat = max(abs(float(x["reaction1_x"]) / lateral_s - 1.0) for x in r)
        return e, lat, r

    curves = {}
    for ranks in (1, 2, 3):
        out = run(f"np{ranks}", ranks, SCENE)
        e, lat, r = errors(out)
        curves[ranks] = r
        check(e <= 1e-6, f"{ranks} ranks: elongation against the two layers' creep, {e:.3e} of e_s (1e-6)")
        check(lat <= 1e-6, f"{ranks} ranks: lateral reaction / its static value - 1 up to {lat:.3e} (1e-6)")
        print(f"{ranks} ranks: {len(r)} rows, elongation error {e:.3e} of e_s, lateral reaction drift {lat:.3e}")
    # The first row is the instantaneous response: each layer at 1 / (1 + gamma) of its relaxed strain.
    first = float(curves[1][0]["elongation"]) / e_s
    want = (1 - SHARE) / (1 + BODY[0]) + SHARE / (1 + REGION[0])
    check(abs(first - want) <= 1e-6, f"instantaneous elongation {first:.9f} of e_s ({want:.9f})")
    for ranks in (2, 3):
        worst = max(abs(float(x["elongation"]) - float(y["elongation"])) for x, y in zip(curves[1], curves[ranks]))
        check(len(curves[1]) == len(curves[ranks]) and worst <= 1e-9 * e_s,
              f"{ranks} ranks: the 1-rank curve to {worst / e_s:.3e} of e_s (1e-9)")

    # Second order in dt: at 4x the step the error is about 16x (the discretization dominates at 5 ms).
    coarse = run("coarse", 1, SCENE.replace("time_step = 0.005", "time_step = 0.02"))
    e_fine, _, _ = errors(os.path.join(work, "np1"))
    e_coarse, _, _ = errors(coarse)
    order = math.log(e_coarse / e_fine) / math.log(4.0)
    check(1.8 <= order <= 2.2, f"error order in dt {order:.2f} (2)")
    print(f"dt = 20 ms: {e_coarse:.3e}, dt = 5 ms: {e_fine:.3e}: order {order:.2f}")

    # Checkpoint and restart of the per-region cell history (/cells/history).
    ck = SCENE.replace("time_step = 0.005\nend_time = 1.0", "time_step = 0.05\nend_time = 1.0").replace(
        "progress = false",
                                                                   "progress = false\ncheckpoint_every = 8")
    for src, dst in ((1, 1), (2, 2), (2, 3)):
        straight = run(f"ck_np{src}", src, ck) if not os.path.isdir(os.path.join(work, f"ck_np{src}")) \
            else os.path.join(work, f"ck_np{src}")
        out = os.path.join(work, f"ck_{src}to{dst}")
        shutil.rmtree(out, ignore_errors=True)
        shutil.copytree(straight, out)
        for f in ("summary.json", "final.h5"):
            if os.path.exists(os.path.join(out, f)):
                os.remove(os.path.join(out, f))
        r = tissue(a.build, dst, "restart", os.path.join(out, "checkpoint_0000000008.h5"), "--output", out)
        check(r.returncode == 0, f"restart {src} -> {dst}: exit {r.returncode}: {r.stderr[-400:]}")
        if src == dst:
            same = open(os.path.join(out, "history.csv")).read() == open(os.path.join(straight, "history.csv")).read()
            check(same, f"restart {src} -> {dst}: history.csv byte for byte the straight run's")
        else:
            ref = run(f"ck_np{dst}", dst, ck)
            ra, rb = rows(ref), rows(out)
            worst = max(abs(float(x["elongation"]) - float(y["elongation"])) for x, y in zip(ra, rb)) / e_s
            check(len(ra) == len(rb) and worst <= 1e-9,
                  f"restart {src} -> {dst}: {worst:.3e} of e_s from the straight {dst}-rank run (1e-9)")
        # The restart carried the history: the column still creeps after the checkpoint's step.
        r2 = rows(out)
        check(float(r2[-1]["elongation"]) > 1.05 * float(r2[8]["elongation"]), f"restart {src} -> {dst}: creeps on")
    # A hold stepped by more than a lattice spacing inverts the cells beside it at once: one line, exit 3 (before,
    # a NaN tolerance reached PETSc, which aborted every rank).
    bad = SCENE.replace('[[load]]\nface = "z+"\nforce = [0.0, 0.0, 4.0e-7]\n',
                        '[[fix]]\nface = "z+"\nmode = "roller"\ndisplacement = [0.0, 0.0, -2.5e-3]\n')
    out, r = run_scene(a.build, work, "inverting_step", 2, bad)
    lines = [l for l in r.stderr.strip().splitlines() if l.startswith("tissue: quasi-static")]
    check(r.returncode == 3 and len(lines) == 1 and "not finite" in lines[0],
          f"a hold stepped past the lattice spacing: exit {r.returncode}, {r.stderr.strip()[-300:]!r}")
    return report()


if __name__ == "__main__":
    sys.exit(main())
