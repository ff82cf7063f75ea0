#!/usr/bin/env python3
"""`tissue fit` (src/driver/fit.cpp, io/fit_input.cpp) fits back the parameters of curves the solver itself made.

a. A standard-linear-solid creep curve (one Prony term, gamma = 1, tau = 2 s; quasi-static, a step force held 12 s):
   the elongation against time, fitted from gamma = 0.3, tau = 0.5 s at 1 and 2 ranks: both to 1e-3 relative;
   fit.json has the contract's keys; fitted.toml runs as a scene and reproduces the measured curve.
b. The same curve with 1 % Gaussian noise (seeded): each fitted value within two standard errors of the truth.
c. A parameter that does not change the curve (density, in a quasi-static run without inertia) fitted with the
   others: reported as not identifiable, naming it.
d. Bad input: no [fit], a CSV without the column, x not increasing, a start value outside its bounds, a key that
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


def history(path):
    with open(path) as f:
        rows = [r for r in csv.DictReader(f) if r["elongation"] != ""]
    return [float(r["time"]) for r in rows], [float(r["elongation"]) for r in rows]


def write_csv(path, xs, ys):
    with open(path, "w") as f:
        f.write("time,elongation\n")
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

    # d. bad input: exit 2, one line, nothing run
    with open(os.path.join(out, "backwards.csv"), "w") as f:
        f.write("time,elongation\n0,0\n2,1\n1,2\n")
    cases = [
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
