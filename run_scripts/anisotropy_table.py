#!/usr/bin/env python3
"""Anisotropic tissue (docs/anisotropy.md): the tissue CLI on a 6 x 6 x 6 block (homogenized, face diagonals, cells
1:1 and 1:1:0.5) with fibres along z (along the load), x and y (across it), at strain 1e-7: tension on rollers reads
E_L or E_T and both lateral Poisson ratios (nu_LT, nu_TT, nu_TL = nu_LT E_T / E_L), exact simple shear of the x-z
plane reads G_L (fibres along z or x) or G_T (along y). Prints a markdown table of the errors against the closed
forms (relative for moduli, absolute for Poisson ratios).

    python3 run_scripts/anisotropy_table.py [RANKS]      # from the repository root; RANKS defaults to 2
"""
import json
import os
import subprocess
import sys
import tempfile
import time

RANKS = int(sys.argv[1]) if len(sys.argv) > 1 else 2
N = 6
E_L, E_T, NU_LT, NU_TT, G_L = 20000.0, 1000.0, 0.35, 0.3, 800.0
G_T = E_T / (2 * (1 + NU_TT))
NU_TL = NU_LT * E_T / E_L
STRAIN = 1e-7


def scene(path, kind, axis, hz):
    d = [0.0, 0.0, 0.0]
    d[axis] = 1.0
    L, Lz = N - 1.0, (N - 1) * hz
    lines = [
        'title = "anisotropy table"', "[body]", f"molecules = [{N}, {N}, {N}]", f"spacing = [1.0, 1.0, {hz}]",
        'topology = "face-diagonals"', f"youngs_modulus = {E_T}", f"poisson_ratio = {NU_TT}", "[body.fibres]",
        f"direction = {d}", f"youngs_modulus = {E_L}", f"poisson_ratio = {NU_LT}", f"shear_modulus = {G_L}",
        "[calibration]", 'method = "homogenized"',
    ]
    if kind == "tension":
        E = E_L if axis == 2 else E_T
        lines += ["[[fix]]", 'face = "z-"', 'mode = "roller"', "[[load]]", 'face = "z+"',
                  f"force = [0.0, 0.0, {E * STRAIN * L * L!r}]"]
    else:
        tau = (G_T if axis == 1 else G_L) * STRAIN
        lines += ["[[fix]]", 'face = "z-"', 'mode = "clamped"',
                  "[[load]]", 'face = "z+"', f"force = [{tau * L * L!r}, 0.0, 0.0]",
                  "[[load]]", 'face = "x+"', f"force = [0.0, 0.0, {tau * L * Lz!r}]",
                  "[[load]]", 'face = "x-"', f"force = [0.0, 0.0, {-tau * L * Lz!r}]"]
    lines += ["[solver]", 'kind = "static"', "tolerance = 1e-9", "[output]",
              f'directory = "{os.path.dirname(path)}/out"', "progress = false"]
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


def run(path):
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    t = time.time()
    subprocess.run(["mpirun", "--oversubscribe", "-np", str(RANKS), "build/tissue", "run", path], check=True,
                   env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    with open(os.path.join(os.path.dirname(path), "out", "summary.json")) as f:
        return json.load(f), time.time() - t


print("| fibres along | cells (h_z / h_x) | E: closed form | E error | nu_x: closed form | nu_x error "
      "| nu_y: closed form | nu_y error | G: closed form | G error | seconds (2 runs) |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
with tempfile.TemporaryDirectory() as work:
    for axis in (2, 0, 1):
        for hz in (1.0, 0.5):
            path = os.path.join(work, "scene.toml")
            scene(path, "tension", axis, hz)
            t, s1 = run(path)
            scene(path, "shear", axis, hz)
            s, s2 = run(path)
            E = E_L if axis == 2 else E_T
            nux = NU_LT if axis == 2 else (NU_TL if axis == 0 else NU_TT)
            nuy = NU_LT if axis == 2 else (NU_TL if axis == 1 else NU_TT)
            G = G_T if axis == 1 else G_L
            nus = t["poisson_ratios_measured"]
            print(f"| {'xyz'[axis]} | {hz} | {E:g} | {t['youngs_modulus_measured'] / E - 1:+.1e} | {nux:.5g} | "
                  f"{nus[0] - nux:+.1e} | {nuy:.5g} | {nus[1] - nuy:+.1e} | {G:.6g} | "
                  f"{s['shear_modulus_measured'] / G - 1:+.1e} | {s1 + s2:.2f} |")
