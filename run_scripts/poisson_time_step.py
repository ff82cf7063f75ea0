#!/usr/bin/env python3
"""The critical time step against the Poisson ratio (docs/poisson.md): for each nu, the printed bound
(summary.json solver.critical_time_step: 0.8 h_min / c_p with the cell term) and the measured stability limit of
the dynamic solver, found by bisection on the time step (a run is stable when its STEPS steps end without the
guards stopping it; solver.allow_unstable_time_step lets the steps above the bound run). Block: 6^3 molecules,
face diagonals, cells 1 x 1 x 0.5 (so the cell term exists at every nu), E = 1 kPa, density 1000 kg/m^3, roller
base and a sudden traction of E 1e-3 on top. Prints a table and writes a PNG.

Usage: python3 run_scripts/poisson_time_step.py [build/tissue] [docs/examples/poisson_time_step.png]"""
import json
import math
import os
import subprocess
import sys
import tempfile

TISSUE = sys.argv[1] if len(sys.argv) > 1 else "build/tissue"
IMAGE = sys.argv[2] if len(sys.argv) > 2 else "docs/examples/poisson_time_step.png"
RATIOS = [0.0, 0.1, 0.25, 0.4, 0.45, 0.49, 0.499]
E, RHO, STEPS, N = 1000.0, 1000.0, 3000, 6
H = [1.0, 1.0, 0.5]


def scene(nu):
    area = ((N - 1) * H[0]) * ((N - 1) * H[1])
    return (f'title = "time step"\n[body]\nmolecules = [{N}, {N}, {N}]\nspacing = {H}\ntopology = "face-diagonals"\n'
            f'youngs_modulus = {E}\ndensity = {RHO}\npoisson_ratio = {nu}\n[calibration]\nmethod = "homogenized"\n'
            f'[[fix]]\nface = "z-"\nmode = "roller"\n[[load]]\nface = "z+"\nforce = [0.0, 0.0, {E * 1e-3 * area}]\n'
            f'[solver]\nkind = "dynamic"\nsteps = {STEPS}\nallow_unstable_time_step = true\n'
            f'[output]\nfields = []\nprogress = false\n')


def run(work, nu, dt=None):
    path = os.path.join(work, "scene.toml")
    with open(path, "w") as f:
        f.write(scene(nu))
    out = os.path.join(work, "out")
    if os.path.exists(os.path.join(out, "summary.json")):
        os.remove(os.path.join(out, "summary.json"))
    cmd = [TISSUE, "run", path, "--output", out]
    if dt is not None:
        cmd += ["--set", f"solver.time_step={dt!r}"]
    r = subprocess.run(cmd, capture_output=True, text=True)
    summary = json.load(open(os.path.join(out, "summary.json"))) if os.path.exists(os.path.join(out, "summary.json")) else None
    return r.returncode == 0, summary


def main():
    rows = []
    with tempfile.TemporaryDirectory() as work:
        for nu in RATIOS:
            ok, s = run(work, nu)
            if not ok:
                sys.exit(f"nu = {nu}: the default time step failed")
            printed = s["solver"]["critical_time_step"]
            lo, hi = 0.5, 4.0  # in units of the printed bound: stable at lo, unstable at hi (checked)
            assert run(work, nu, lo * printed)[0] and not run(work, nu, hi * printed)[0], nu
            while hi - lo > 0.02:
                mid = 0.5 * (lo + hi)
                if run(work, nu, mid * printed)[0]:
                    lo = mid
                else:
                    hi = mid
            c_p = math.sqrt(E * (1 - nu) / ((1 + nu) * (1 - 2 * nu)) / RHO)
            rows.append((nu, printed, lo * printed, hi * printed, min(H) / c_p))
            print(f"nu {nu:6.3f}: printed {printed:.4e} s, stable at {lo * printed:.4e}, caught at {hi * printed:.4e} "
                  f"({lo:.2f}-{hi:.2f} x printed; h/c_p = {min(H) / c_p:.4e} s)", flush=True)
    print("\n| nu | printed (s) | stable up to (s) | caught from (s) | limit / printed | h_min / c_p (s) |")
    print("|---|---|---|---|---|---|")
    for nu, p, lo, hi, hc in rows:
        print(f"| {nu} | {p:.4e} | {lo:.4e} | {hi:.4e} | {lo / p:.2f}-{hi / p:.2f} | {hc:.4e} |")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.5))
    nus = [r[0] for r in rows]
    ax.plot(nus, [r[1] for r in rows], "o-", label="printed critical time step (0.8 h_min / c_p)")
    ax.plot(nus, [0.5 * (r[2] + r[3]) for r in rows], "s--", label="measured stability limit (dynamic)")
    ax.plot(nus, [r[4] for r in rows], ":", color="grey", label="h_min / c_p")
    ax.set_yscale("log")
    ax.set_xlabel("Poisson ratio nu")
    ax.set_ylabel("time step (s)")
    ax.set_title(f"{N}^3 block, cells 1 x 1 x 0.5, E = {E:g} Pa, density {RHO:g} kg/m^3")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(IMAGE, dpi=110)
    print("wrote", IMAGE)


if __name__ == "__main__":
    main()
