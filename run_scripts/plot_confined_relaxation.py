#!/usr/bin/env python3
"""Cartilage stress relaxation in confined compression (docs/viscoelastic.md): the moving face's reaction against
time from history.csv, with the linear viscoelastic closed form of a ramp of t_r to strain eps, then held:
  R(t) = c H_A A eps g(t),  g(t) = (t + sum_i gamma_i tau_i (1 - exp(-t/tau_i))) / t_r      (t <= t_r)
                            g(t) = 1 + sum_i gamma_i (tau_i/t_r)(exp(t_r/tau_i) - 1) exp(-t/tau_i)  (t >= t_r)
H_A = E (1 - nu)/((1 + nu)(1 - 2 nu)) the relaxed aggregate modulus, c the elastic lattice's reaction at the same
compression over H_A A eps (the geometric nonlinearity of a finite strain; read from an elastic run's history.csv).
Prints the largest difference over the curve relative to the relaxed reaction.
  plot_confined_relaxation.py RUN_DIR ELASTIC_DIR OUT.png"""
import csv
import math
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

E, NU, SIDE, STRAIN, RAMP = 6.4e5, 0.185, 0.004, 0.02, 1.0  # example_cartilage_confined_relaxation.toml
GAMMA, TAU = [2.0, 1.0], [1.0, 15.0]


def reaction(path):
    with open(path + "/history.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return [float(r["time"]) for r in rows], [-float(r["reaction1_z"]) for r in rows]


def g(t):
    if t <= RAMP:
        return (t + sum(gm * tau * (1 - math.exp(-t / tau)) for gm, tau in zip(GAMMA, TAU))) / RAMP
    return 1 + sum(gm * tau / RAMP * math.expm1(RAMP / tau) * math.exp(-t / tau) for gm, tau in zip(GAMMA, TAU))


def main():
    run, elastic, png = sys.argv[1:4]
    h_a = E * (1 - NU) / ((1 + NU) * (1 - 2 * NU))
    linear = h_a * SIDE * SIDE * STRAIN
    c = reaction(elastic)[1][-1] / linear
    t, r = reaction(run)
    closed = [c * linear * g(x) for x in t]
    worst = max(abs(a - b) for a, b in zip(r, closed)) / (c * linear)
    print(f"H_A = {h_a:.6g} Pa, H_A A eps = {linear:.6g} N, elastic lattice c = {c:.6f}; peak {max(r):.6g} N at "
          f"t = {t[r.index(max(r))]:g} s, {r[-1]:.6g} N at {t[-1]:g} s (closed form {closed[-1]:.6g} N); largest "
          f"difference {worst:.2e} of the relaxed reaction")
    fig, ax = plt.subplots(figsize=(7, 4.2))
    ax.plot(t, r, "o", ms=2.5, label="tissue, quasi-static (reaction of the moving face)")
    fine = [i * t[-1] / 2000 for i in range(2001)]
    ax.plot(fine, [c * linear * g(x) for x in fine], "-", lw=1, label="closed form c H_A(t) A eps, ramp and hold")
    ax.axhline(c * linear, ls=":", color="grey", lw=1, label="relaxed: c H_A A eps")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("compressive reaction (N)")
    ax.set_title("Cartilage, confined compression: 2 % in 1 s, held (E = 0.64 MPa, nu = 0.185)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(png, dpi=110)


if __name__ == "__main__":
    main()
