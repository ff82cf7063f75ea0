#!/usr/bin/env python3
"""`tissue fit` (src/driver/fit.cpp, io/fit_input.cpp) fits back the parameters of curves the solver itself made.

a. A standard-linear-solid creep curve (one Prony term, gamma = 1, tau = 2 s; quasi-static, a step force held 12 s):
   the elongation against time, fitted from gamma = 0.3, tau = 0.5 s at 1 and 2 ranks: both to 1e-3 relative;
   fit.json has the contract's keys; fitted.toml runs as a scene and reproduces the measured curve.
b. The same curve with 1 % Gaussian noise (seeded): each fitted value within two standard errors of the truth.
c. A parameter that does not change the curve (density, in a quasi-static run without inertia) fitted with the
   others: reported as not identifiable, naming it.
e. A two-term Prony relaxation curve (a step strain held 20 s, the reaction against time, gamma = [1.5, 0.8],
   tau = [0.4, 5] s) fitted back from gamma = [0.5, 0.5], tau = [1, 20] s, all four at 1 and 2 ranks: to 1e-3.
   Two terms with nearly the same time constant (tau = [2, 2.02] s, their gammas fitted) are reported as not
   separable (|correlation| > 0.999; at tau = [2, 2.1] s it is 0.997 and the fit still separates them).
f. E and nu from a static tension test's elongation and lateral contraction fitted together (y = ["elongation",
   "lateral_strain"], one history.csv row per load step), from E = 2 MPa, nu = 0.2 towards 1 MPa, 0.35: to 1e-4.
g. A toe-law ligament curve (issue 17's exp-linear toe on fibres along the load, a static tension through the toe
   in 10 load steps, the elongation against the load fraction): the toe's stretch and exponent (1.03, 40) fitted
   back from (1.05, 20) at 1 and 2 ranks: to 1e-3.
d. Bad input: no [fit], a CSV without the column, a row cut short, x not increasing, a start value outside its bounds, a key that
   is not a number in the scene: exit 2, one stderr line naming the file, and no forward run (nothing written).

Usage: fit_test.py --build BUILD_DIR --source SOURCE_DIR      Prints 'N passed, M failed'."""
import argparse
import csv
import json
import os
import random
import shutil
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import check, report  # noqa: E402

SCENE = """title = "SLS creep"
[body]
molecules = [3, 3, 5]
size = [0.002, 0.002, 0.004]
topology = "face-diagonals"
youngs_modulus = 1.0e6
density = {density}
[body.viscoelastic]
gamma = [{gamma}]
tau = [{tau}]
[calibration]
method = "homogenized"
[[fix]]
face = "z-"
mode = "roller"
[[load]]
face = "z+"
force = [0.0, 0.0, 0.01]
[solver]
kind = "quasi-static"
time_step = 0.25
end_time = 12.0
[output]
fields = []
progress = false
"""

# A stress-relaxation test: both ends clamped, the top moved by 1e-4 of its length at t = 0 and held.
RELAXATION = """title = "two-term relaxation"
[body]
molecules = [3, 3, 4]
size = [0.002, 0.002, 0.003]
topology = "face-diagonals"
youngs_modulus = 1.0e6
[body.viscoelastic]
gamma = [{gamma}]
tau = [{tau}]
[calibration]
method = "homogenized"
[[fix]]
face = "z-"
mode = "clamped"
[[fix]]
face = "z+"
mode = "clamped"
displacement = [0.0, 0.0, 3.0e-7]
[solver]
kind = "quasi-static"
time_step = 0.2
end_time = 20.0
[output]
fields = []
progress = false
"""

# A static tension test with free lateral faces, four load steps: history.csv's rows are the load steps.
TENSION = """title = "E and nu"
[body]
molecules = [3, 3, 5]
size = [0.002, 0.002, 0.004]
topology = "face-diagonals"
youngs_modulus = {E}
poisson_ratio = {nu}
[calibration]
method = "homogenized"
[[fix]]
face = "z-"
mode = "roller"
[[load]]
face = "z+"
force = [0.0, 0.0, 0.01]
[solver]
kind = "static"
load_steps = 4
[output]
fields = []
progress = false
"""

TOE = """
title = "toe-law ligament bar"
[body]
molecules = [3, 3, 6]
size = [0.002, 0.002, 0.005]
topology = "face-diagonals"
youngs_modulus = 1.0e5
poisson_ratio = 0.3
[body.fibres]
direction = [0.0, 0.0, 1.0]
youngs_modulus = 1.0e6
poisson_ratio = 0.3
toe = {{ law = "exp-linear", stretch = {stretch}, exponent = {exponent} }}
[calibration]
method = "homogenized"
[[fix]]
face = "z-"
mode = "roller"
[[load]]
face = "z+"
force = [0.0, 0.0, 0.15]
[solver]
kind = "static"
load_steps = 10
[output]
fields = []
progress = false
"""

FIT = """
[fit]
data = "{data}"
x = "time"
y = "elongation"
[fit.parameters]
{parameters}
"""


def mpi(exe, n, args):
    return (["mpirun", "--oversubscribe", "-np", str(n)] if n > 1 else []) + [exe] + args


def run(cmd):
    p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, timeout=600)
    return p.returncode, p.stdout, p.stderr


def history(path, y="elongation"):
    with open(path) as f:
        rows = [r for r in csv.DictReader(f) if r[y] != ""]
    return [float(r["time"]) for r in rows], [float(r[y]) for r in rows]


def write_csv(path, xs, ys, y="elongation"):
    with open(path, "w") as f:
        f.write("time,%s\n" % y)
        for x, y in zip(xs, ys):
            f.write("%.17g,%.17g\n" % (x, y))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", required=True)
    ap.add_argument("--source", required=True)
    args = ap.parse_args()
    exe = os.path.join(args.build, "tissue")
    out = os.path.join(args.build, "tests", "out", "fit")
    shutil.rmtree(out, ignore_errors=True)
    os.makedirs(out)

    # The measured curve: the solver's own, at the true parameters.
    truth = {"body.viscoelastic.gamma.0": 1.0, "body.viscoelastic.tau.0": 2.0}
    with open(os.path.join(out, "truth.toml"), "w") as f:
        f.write(SCENE.format(gamma=1.0, tau=2.0, density=1000.0))
    code, _, err = run([exe, "run", os.path.join(out, "truth.toml"), "--output", os.path.join(out, "truth")])
    if not check(code == 0, "the true creep curve runs: " + err.strip()[-300:]):
        return report()
    xs, ys = history(os.path.join(out, "truth", "history.csv"))
    check(len(xs) > 20 and ys[-1] > 1.5 * ys[0] > 0, "the curve creeps (%d rows, %s -> %s)" % (len(xs), ys[:1], ys[-1:]))
    write_csv(os.path.join(out, "clean.csv"), xs, ys)
    rng = random.Random(5)
    noisy = [y * (1 + 0.01 * rng.gauss(0, 1)) for y in ys]
    write_csv(os.path.join(out, "noisy.csv"), xs, noisy)

    params = ('"body.viscoelastic.gamma.0" = [0.01, 100.0]\n"body.viscoelastic.tau.0" = [0.01, 100.0]\n')

    def fit_scene(name, data, parameters=params, density=1000.0):
        path = os.path.join(out, name + ".toml")
        with open(path, "w") as f:
            f.write(SCENE.format(gamma=0.3, tau=0.5, density=density) + FIT.format(data=data, parameters=parameters))
        return path

    # a. noise-free, 1 and 2 ranks
    for ranks in (1, 2):
        scene = fit_scene("clean%d" % ranks, "clean.csv")
        d = os.path.join(out, "clean%d" % ranks)
        code, stdout, err = run(mpi(exe, ranks, ["fit", scene, "--output", d]))
        if not check(code == 0, "a. fit on %d ranks exits 0: %s" % (ranks, err.strip()[-300:])):
            continue
        with open(os.path.join(d, "fit.json")) as f:
            r = json.load(f)
        for key in ("parameters", "standard_errors", "residual_norm", "forward_runs", "converged", "correlation"):
            check(key in r, "a. fit.json has %s" % key)
        for key, value in truth.items():
            got = r["parameters"][key]
            check(abs(got - value) <= 1e-3 * value, "a. %d ranks: %s = %.6g, truth %g (1e-3)" % (ranks, key, got, value))
        print("      %d ranks: %d forward runs, |r| %.3e, %s" % (ranks, r["forward_runs"], r["residual_norm"],
                                                                  r["parameters"]))
        # fitted.toml is a scene: run it, and it gives the measured curve
        code, _, err = run([exe, "run", os.path.join(d, "fitted.toml"), "--output", os.path.join(d, "rerun")])
        if check(code == 0, "a. fitted.toml runs: " + err.strip()[-200:]):
            _, fy = history(os.path.join(d, "rerun", "history.csv"))
            worst = max(abs(a - b) for a, b in zip(fy, ys)) / max(ys)
            check(worst < 1e-3, "a. the fitted scene's curve is the measured one (%.2e of the largest)" % worst)

    # b. 1 % noise: within two standard errors
    scene = fit_scene("noisy", "noisy.csv")
    d = os.path.join(out, "noisy")
    code, _, err = run([exe, "fit", scene, "--output", d])
    if check(code == 0, "b. noisy fit exits 0: " + err.strip()[-300:]):
        with open(os.path.join(d, "fit.json")) as f:
            r = json.load(f)
        for key, value in truth.items():
            got, se = r["parameters"][key], r["standard_errors"][key]
            check(se is not None and se > 0 and abs(got - value) <= 2 * se,
                  "b. %s = %.5g +- %s, truth %g (two standard errors)" % (key, got, se, value))
        check(r["identifiable"], "b. gamma and tau are identifiable from the noisy curve")

    # c. density does not change a quasi-static curve
    scene = fit_scene("density", "clean.csv", params + '"body.density" = [500.0, 2000.0]\n')
    d = os.path.join(out, "density")
    code, _, err = run([exe, "fit", scene, "--output", d])
    if check(code == 0, "c. fit with density exits 0: " + err.strip()[-300:]):
        with open(os.path.join(d, "fit.json")) as f:
            r = json.load(f)
        check(not r["identifiable"] and "body.density" in r["notes"],
              "c. density reported as not identifiable: %s" % r["notes"])

    # e. a two-term Prony relaxation curve, and two terms the curve cannot tell apart
    def relaxation(name, gamma, tau):
        path = os.path.join(out, name + ".toml")
        with open(path, "w") as f:
            f.write(RELAXATION.format(gamma="%r, %r" % gamma, tau="%r, %r" % tau))
        return path

    code, _, err = run([exe, "run", relaxation("relax_truth", (1.5, 0.8), (0.4, 5.0)), "--output",
                        os.path.join(out, "relax_truth")])
    check(code == 0, "e. the relaxation curve runs: " + err.strip()[-300:])
    rx, ry = history(os.path.join(out, "relax_truth", "history.csv"), "reaction0_z")
    write_csv(os.path.join(out, "relax.csv"), rx, ry, "reaction0_z")
    check(abs(ry[0]) > 2.0 * abs(ry[-1]) > 0, "e. the reaction relaxes (%s -> %s)" % (ry[0], ry[-1]))
    prony = "".join('"body.viscoelastic.%s" = [%r, %r]\n' % (k, lo, hi) for k, lo, hi in (
        ("gamma.0", 0.01, 10.0), ("gamma.1", 0.01, 10.0), ("tau.0", 0.05, 2.0), ("tau.1", 2.0, 50.0)))
    truth2 = {"body.viscoelastic.gamma.0": 1.5, "body.viscoelastic.gamma.1": 0.8, "body.viscoelastic.tau.0": 0.4,
              "body.viscoelastic.tau.1": 5.0}
    for ranks in (1, 2):
        scene = relaxation("relax_fit%d" % ranks, (0.5, 0.5), (1.0, 20.0))
        with open(scene, "a") as f:
            f.write(FIT.format(data="relax.csv", parameters=prony).replace('y = "elongation"', 'y = "reaction0_z"'))
        d = os.path.join(out, "relax_fit%d" % ranks)
        code, _, err = run(mpi(exe, ranks, ["fit", scene, "--output", d]))
        if not check(code == 0, "e. two-term fit on %d ranks exits 0: %s" % (ranks, err.strip()[-300:])):
            continue
        r = json.load(open(os.path.join(d, "fit.json")))
        for key, value in truth2.items():
            got = r["parameters"][key]
            check(abs(got - value) <= 1e-3 * value, "e. %d ranks: %s = %.6g, truth %g (1e-3)" % (ranks, key, got, value))
        check(r["identifiable"], "e. %d ranks: the two terms are separable: %s" % (ranks, r["notes"]))
        print("      e. %d ranks: %d forward runs, |r| %.3e, %s" % (ranks, r["forward_runs"], r["residual_norm"],
                                                                     r["parameters"]))
    code, _, err = run([exe, "run", relaxation("close_truth", (1.0, 1.0), (2.0, 2.02)), "--output",
                        os.path.join(out, "close_truth")])
    cx, cy = history(os.path.join(out, "close_truth", "history.csv"), "reaction0_z")
    write_csv(os.path.join(out, "close.csv"), cx, cy, "reaction0_z")
    scene = relaxation("close_fit", (0.8, 1.2), (2.0, 2.02))
    close = "".join('"body.viscoelastic.%s" = [%r, %r]\n' % (k, lo, hi) for k, lo, hi in (
        ("gamma.0", 0.01, 10.0), ("gamma.1", 0.01, 10.0)))
    with open(scene, "a") as f:
        f.write(FIT.format(data="close.csv", parameters=close).replace('y = "elongation"', 'y = "reaction0_z"'))
    d = os.path.join(out, "close_fit")
    code, _, err = run([exe, "fit", scene, "--output", d])
    if check(code == 0, "e. close time constants: fit exits 0: " + err.strip()[-300:]):
        r = json.load(open(os.path.join(d, "fit.json")))
        check(not r["identifiable"] and "cannot be separated" in r["notes"],
              "e. gamma.0 and gamma.1 of tau = 2 s and 2.02 s reported as not separable: %s" % r["notes"])

    # f. E and nu from elongation and lateral contraction, fitted together
    with open(os.path.join(out, "tension_truth.toml"), "w") as f:
        f.write(TENSION.format(E=1.0e6, nu=0.35))
    code, _, err = run([exe, "run", os.path.join(out, "tension_truth.toml"), "--output", os.path.join(out, "tension")])
    check(code == 0, "f. the tension test runs: " + err.strip()[-300:])
    with open(os.path.join(out, "tension", "history.csv")) as f:
        rows = list(csv.DictReader(f))
    check(len(rows) == 4 and all(r["lateral_strain"] != "" for r in rows),
          "f. one row per load step with the lateral strain (%d rows)" % len(rows))
    with open(os.path.join(out, "tension.csv"), "w") as f:
        f.write("time,elongation,lateral_strain\n")
        for r in rows:
            f.write("%s,%s,%s\n" % (r["time"], r["elongation"], r["lateral_strain"]))
    summary = json.load(open(os.path.join(out, "tension", "summary.json")))
    axial = float(rows[-1]["elongation"]) / summary["rest_length"]
    check(abs(-float(rows[-1]["lateral_strain"]) / axial - summary["poisson_ratio_measured"]) <= 1e-12,
          "f. lateral_strain / axial strain is the summary's poisson_ratio_measured")
    scene = os.path.join(out, "tension_fit.toml")
    with open(scene, "w") as f:
        f.write(TENSION.format(E=2.0e6, nu=0.2) + FIT.format(
            data="tension.csv", parameters='"body.youngs_modulus" = [1.0e5, 1.0e7]\n"body.poisson_ratio" = [0.0, 0.45]\n')
            .replace('y = "elongation"', 'y = ["elongation", "lateral_strain"]'))
    d = os.path.join(out, "tension_fit")
    code, _, err = run(mpi(exe, 2, ["fit", scene, "--output", d]))
    if check(code == 0, "f. E and nu fit exits 0: " + err.strip()[-300:]):
        r = json.load(open(os.path.join(d, "fit.json")))
        for key, value in (("body.youngs_modulus", 1.0e6), ("body.poisson_ratio", 0.35)):
            got = r["parameters"][key]
            check(abs(got - value) <= 1e-4 * value, "f. %s = %.8g, truth %g (1e-4)" % (key, got, value))
        check(r["y"] == ["elongation", "lateral_strain"] and set(r["residual_norms"]) == set(r["y"]),
              "f. fit.json names both y columns and their residual norms")
        print("      f. %d forward runs, %s" % (r["forward_runs"], r["parameters"]))

    # g. a toe-law ligament curve: the toe's stretch and exponent
    with open(os.path.join(out, "toe_truth.toml"), "w") as f:
        f.write(TOE.format(stretch=1.03, exponent=40.0))
    code, _, err = run([exe, "run", os.path.join(out, "toe_truth.toml"), "--output", os.path.join(out, "toe")])
    check(code == 0, "g. the toe-law tension runs: " + err.strip()[-300:])
    xs, ys = history(os.path.join(out, "toe", "history.csv"))
    # the toe: the first load step stretches more per newton than the last (stiffening)
    check(len(xs) == 10 and ys[0] / xs[0] > 1.5 * (ys[-1] - ys[-2]) / (xs[-1] - xs[-2]),
          "g. 10 rows, stiffening through the toe (%s)" % ys[:2])
    write_csv(os.path.join(out, "toe.csv"), xs, ys)
    for n in (1, 2):
        scene = os.path.join(out, "toe_fit_np%d.toml" % n)
        with open(scene, "w") as f:
            f.write(TOE.format(stretch=1.05, exponent=20.0) + FIT.format(
                data="toe.csv",
                parameters='"body.fibres.toe.stretch" = [1.005, 1.1]\n"body.fibres.toe.exponent" = [5.0, 200.0]\n'))
        d = os.path.join(out, "toe_fit_np%d" % n)
        code, _, err = run(mpi(exe, n, ["fit", scene, "--output", d]))
        if check(code == 0, "g. toe fit at %d ranks exits 0: %s" % (n, err.strip()[-300:])):
            r = json.load(open(os.path.join(d, "fit.json")))
            for key, value in (("body.fibres.toe.stretch", 1.03), ("body.fibres.toe.exponent", 40.0)):
                got = r["parameters"][key]
                check(abs(got - value) <= 1e-3 * value, "g. %d ranks: %s = %.8g, truth %g (1e-3)" % (n, key, got, value))
            print("      g. %d ranks: %d forward runs, %s" % (n, r["forward_runs"], r["parameters"]))

    # d. bad input: exit 2, one line, nothing run
    with open(os.path.join(out, "backwards.csv"), "w") as f:
        f.write("time,elongation\n0,0\n2,1\n1,2\n")
    with open(os.path.join(out, "clean.csv")) as f:  # a row cut short in the middle: refused, not dropped
        rows = f.read().splitlines()
    with open(os.path.join(out, "ragged.csv"), "w") as f:
        f.write("\n".join(rows[:3] + [rows[3].split(",")[0]] + rows[4:]) + "\n")
    cases = [
        ("a row cut short", fit_scene("bad5", "ragged.csv"), [], "line 4"),
        ("no [fit]", os.path.join(out, "truth.toml"), [], "fit"),
        ("no such column", fit_scene("bad1", "clean.csv"), ["--set", "fit.y=reaction0_z"], "reaction0_z"),
        ("x not increasing", fit_scene("bad2", "backwards.csv"), [], "not strictly increasing"),
        ("start outside bounds", fit_scene("bad3", "clean.csv"), ["--set", "body.viscoelastic.tau.0=500"], "outside"),
        ("not a number", fit_scene("bad4", "clean.csv", params + '"title" = [0.0, 1.0]\n'), [], "not a number"),
    ]
    for what, scene, extra, needle in cases:
        d = os.path.join(out, "bad_" + what.replace(" ", "_"))
        code, _, err = run([exe, "fit", scene, "--output", d] + extra)
        lines = err.strip().splitlines()
        check(code == 2 and len(lines) == 1 and needle in err and not os.path.exists(os.path.join(d, "forward")),
              "d. %s: exit %d, %r" % (what, code, err.strip()[-200:]))
    return report()


if __name__ == "__main__":
    sys.exit(main())
