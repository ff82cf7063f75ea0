#!/usr/bin/env python3
"""A loading-unloading hysteresis loop of a viscoelastic ligament strip (docs/viscoelastic.md, issue 16).

What it runs: a 4 x 4 x 10 mm strip (E = 400 MPa relaxed, one Prony term gamma = 1, tau = 1 s), z- clamped, its z+
face clamped and pulled to d(t) = d_a (1 - cos(w t)) / 2 and back, w tau = 1 (the loss peak), three periods with
100 breakpoints a period, quasi-static. The reaction on the moving face against d traces a loop; its area over the
last period is compared with the closed form of a linear viscoelastic solid, pi E''/E K a^2, a = d_a / 2 the
amplitude, E''/E = gamma w tau / (1 + w^2 tau^2) = 1/2, K the strip's elastic stiffness (the same strip without
the Prony series, same holds). The piecewise linear displacement and the trapezoid rule put the area within about
1e-3 of the closed form.

  python3 run_scripts/hysteresis_example.py [NP]     # writes docs/examples/visco_hysteresis.png, prints the areas

Steps: 1. write the two scenes (the history as breakpoints); 2. run them; 3. loop area against the closed form;
4. the plot.
"""
import csv
import json
import math
import os
import subprocess
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NP = sys.argv[1] if len(sys.argv) > 1 else "2"
OUT = os.path.join(ROOT, "out", "visco", "hysteresis")
D_A, TAU, GAMMA, PERIODS, PER = 4.0e-6, 1.0, 1.0, 3, 100
W = 1.0 / TAU
T = 2 * math.pi / W

SCENE = """title = "Ligament hysteresis: a sinusoidal pull to {d_a} m and back, w tau = 1"
[body]
molecules = [5, 5, 11]
size = [0.004, 0.004, 0.010]
topology = "face-diagonals"
material = "ligament"
youngs_modulus = 4.0e8
{prony}[calibration]
method = "homogenized"
[[fix]]
face = "z-"
mode = "clamped"
[[fix]]
face = "z+"
mode = "clamped"
displacement = [0.0, 0.0, {d_a}]
history = [{history}]
[solver]
kind = "quasi-static"
time_step = {dt!r}
end_time = {end!r}
tolerance = 1e-10
[output]
directory = "{out}"
fields = []
progress = false
"""


def run(name, prony, end):
    # 1. The scene: the factor (1 - cos(w t)) / 2 at the breakpoints (landed on: one step each).
    times = [T * i / PER for i in range(PERIODS * PER + 1)]
    history = ", ".join(f"[{t!r}, {0.5 * (1 - math.cos(W * t))!r}]" for t in times)
    path = os.path.join(OUT, name + ".toml")
    out = os.path.join(OUT, name)
    with open(path, "w") as f:
        f.write(SCENE.format(d_a=D_A, prony=prony, history=history, dt=T / PER, end=end, out=out))
    # 2. Run it.
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    subprocess.run(["mpirun", "--oversubscribe", "-np", NP, os.path.join(ROOT, "build", "tissue"), "run", path],
                   check=True, env=env, stdout=subprocess.DEVNULL)
    with open(os.path.join(out, "history.csv"), newline="") as f:
        return [(float(r["time"]), float(r["reaction1_z"])) for r in csv.DictReader(f)]


def main():
    os.makedirs(OUT, exist_ok=True)
    rows = run("prony", f"[body.viscoelastic]\ngamma = [{GAMMA!r}]\ntau = [{TAU!r}]\n", PERIODS * T)
    elastic = run("elastic", "", T / PER)  # one step: the elastic stiffness at d(T/PER)
    t1, r1 = elastic[-1]
    K = r1 / (D_A * 0.5 * (1 - math.cos(W * t1)))  # the reaction: the force the moving hold exerts on the strip
    # 3. The loop's area over the last period (trapezoid rule on the breakpoints).
    last = [(t, r) for t, r in rows if t >= (PERIODS - 1) * T - 1e-9 * T]
    d = [D_A * 0.5 * (1 - math.cos(W * t)) for t, _ in last]
    f = [F for _, F in last]
    area = abs(sum(0.5 * (f[i] + f[i + 1]) * (d[i + 1] - d[i]) for i in range(len(d) - 1)))
    e2 = GAMMA * W * TAU / (1 + (W * TAU) ** 2)
    want = math.pi * e2 * K * (D_A / 2) ** 2
    print(f"loop area {area:.6e} J, closed form pi (E''/E) K a^2 = {want:.6e} J (K = {K:.6e} N/m), "
          f"relative error {(area - want) / want:+.2e}")
    # 4. The plot: the whole run, the last period dark.
    dd = [D_A * 0.5 * (1 - math.cos(W * t)) for t, _ in rows]
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    ax.plot([x * 1e6 for x in dd], [r for _, r in rows], color="0.7", lw=1, label="periods 1-2 (from rest)")
    ax.plot([x * 1e6 for x in d], f, color="C0", lw=2, label=f"period {PERIODS}: area {area:.3e} J")
    ax.plot([0, D_A * 1e6], [0, K * D_A], "k--", lw=1, label="elastic (relaxed) stiffness")
    ax.set_xlabel("pull of the z+ face (um)")
    ax.set_ylabel("force on the strip (N)")
    ax.set_title(f"Ligament strip, w tau = 1: loop area {area:.3e} J vs pi E''/E K a^2 = {want:.3e} J", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    png = os.path.join(ROOT, "docs", "examples", "visco_hysteresis.png")
    fig.savefig(png, dpi=110)
    print("plot:", os.path.relpath(png, ROOT))


if __name__ == "__main__":
    main()
