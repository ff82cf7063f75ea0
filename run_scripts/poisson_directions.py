#!/usr/bin/env python3
"""Young's modulus along every direction of a lattice (docs/poisson.md, "E along directions"), from the model's
small-strain compliance measured with the tissue CLI: on an N^3 face-diagonal block (flat cells h_z = h_x / 2, so
h_x = h_y: an orthotropic tensor with x and y alike), at strain 1e-7,
  - tension along z and along x on a roller (E_z, nu_zx; E_x, nu_xy, nu_xz),
  - simple shear in the xz plane (clamped z-, traction along x on z+, complementary tractions on x-, x+) and in
    the xy plane (clamped y-, traction along x on y+, complementary tractions on x-, x+): G_xz and G_xy,
then 1/E(n) = n n : S : n n over the unit sphere. Two models: homogenized with the cell term (nu = 0.3) and
springs only, Eq. 4's linear calibration (the paper's k = E A / l0) on the same lattice. Writes a PNG with E(n) / E
against the angle from z in the xz plane and in the diagonal plane (x = y), and prints the extremes.

Usage: python3 run_scripts/poisson_directions.py [build/tissue] [docs/examples/poisson_directions.png]"""
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

TISSUE = sys.argv[1] if len(sys.argv) > 1 else "build/tissue"
IMAGE = sys.argv[2] if len(sys.argv) > 2 else "docs/examples/poisson_directions.png"
N, E, NU, STRAIN = 6, 1000.0, 0.3, 1e-7
H = [1.0, 1.0, 0.5]
L = [(N - 1) * h for h in H]
G_TARGET = E / (2 * (1 + NU))


def scene(body, fixes, loads):
    text = f'title = "E along directions"\n[body]\nmolecules = [{N}, {N}, {N}]\nspacing = {H}\n'
    text += f'topology = "face-diagonals"\nyoungs_modulus = {E}\n{body}\n'
    for face, mode in fixes:
        text += f'[[fix]]\nface = "{face}"\nmode = "{mode}"\n'
    for face, f in loads:
        text += f'[[load]]\nface = "{face}"\nforce = [{f[0]!r}, {f[1]!r}, {f[2]!r}]\n'
    return text + '[solver]\nkind = "static"\ntolerance = 1e-10\n[output]\nfields = []\nprogress = false\n'


def run(work, text):
    path = os.path.join(work, "scene.toml")
    with open(path, "w") as f:
        f.write(text)
    r = subprocess.run([TISSUE, "run", path, "--output", os.path.join(work, "out")], capture_output=True, text=True)
    if r.returncode:
        sys.exit(f"tissue failed: {r.stderr[-300:]}")
    return json.load(open(os.path.join(work, "out", "summary.json")))


def compliance(work, body):
    """S (Voigt 6 x 6) of the orthotropic lattice, from four runs."""
    sz = run(work, scene(body, [("z-", "roller")], [("z+", [0, 0, E * STRAIN * L[0] * L[1]])]))
    sx = run(work, scene(body, [("x-", "roller")], [("x+", [E * STRAIN * L[1] * L[2], 0, 0])]))
    tau = G_TARGET * STRAIN
    gxz = run(work, scene(body, [("z-", "clamped")], [("z+", [tau * L[0] * L[1], 0, 0]), ("x+", [0, 0, tau * L[1] * L[2]]),
                                                       ("x-", [0, 0, -tau * L[1] * L[2]])]))
    gxy = run(work, scene(body, [("y-", "clamped")], [("y+", [tau * L[0] * L[2], 0, 0]), ("x+", [0, tau * L[1] * L[2], 0]),
                                                       ("x-", [0, -tau * L[1] * L[2], 0])]))
    Ez, Ex = sz["youngs_modulus_measured"], sx["youngs_modulus_measured"]
    nu_zx = sz["poisson_ratios_measured"][0]
    nu_xy, nu_xz = sx["poisson_ratios_measured"]
    Gxz, Gxy = gxz["shear_modulus_measured"], gxy["shear_modulus_measured"]
    S = np.zeros((6, 6))
    S[0, 0] = S[1, 1] = 1 / Ex
    S[2, 2] = 1 / Ez
    S[0, 1] = S[1, 0] = -nu_xy / Ex
    S[0, 2] = S[2, 0] = S[1, 2] = S[2, 1] = -nu_xz / Ex
    S[3, 3] = S[4, 4] = 1 / Gxz
    S[5, 5] = 1 / Gxy
    print(f"  E_x {Ex:.6g} E_z {Ez:.6g} nu_xy {nu_xy:.6g} nu_xz {nu_xz:.6g} nu_zx {nu_zx:.6g} G_xz {Gxz:.6g} "
          f"G_xy {Gxy:.6g}")
    return S


def modulus(S, n):
    """E along unit vectors n (rows): 1 / (n n : S : n n) with Voigt shear strains doubled."""
    v = np.stack([n[:, 0] ** 2, n[:, 1] ** 2, n[:, 2] ** 2, 2 * n[:, 1] * n[:, 2], 2 * n[:, 0] * n[:, 2],
                  2 * n[:, 0] * n[:, 1]], axis=1)
    w = v.copy()
    w[:, 3:] /= 2  # stress n n in Voigt form: no factor 2
    return 1.0 / np.einsum("ki,ij,kj->k", w, S, w)


def main():
    models = {"homogenized + cell term (nu = 0.3)": f"poisson_ratio = {NU}\n[calibration]\nmethod = \"homogenized\"",
              "springs only (linear, Eq. 4)": "[calibration]\nmethod = \"linear\""}
    theta = np.linspace(0, np.pi, 181)
    sphere = np.random.default_rng(1).normal(size=(20000, 3))
    sphere /= np.linalg.norm(sphere, axis=1)[:, None]
    curves = {}
    with tempfile.TemporaryDirectory() as work:
        for name, body in models.items():
            print(name)
            S = compliance(work, body)
            xz = np.stack([np.sin(theta), 0 * theta, np.cos(theta)], axis=1)
            diag = np.stack([np.sin(theta) / np.sqrt(2), np.sin(theta) / np.sqrt(2), np.cos(theta)], axis=1)
            curves[name] = (modulus(S, xz) / E, modulus(S, diag) / E)
            e = modulus(S, sphere) / E
            print(f"  E(n) / E over the sphere: {e.min():.9f} .. {e.max():.9f}")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.5))
    deg = np.degrees(theta)
    for (name, (xz, diag)), colour in zip(curves.items(), ["C0", "C3"]):
        ax.plot(deg, xz, colour, label=f"{name}, xz plane")
        ax.plot(deg, diag, colour, linestyle="--", label=f"{name}, x = y plane")
    ax.axhline(1.0, color="grey", linewidth=0.5)
    ax.set_xlabel("angle from z (degrees)")
    ax.set_ylabel("E(direction) / E")
    ax.set_title(f"{N}^3 face-diagonal block, cells 1 x 1 x 0.5, E = {E:g} Pa")
    ax.set_ylim(0.4, 2.45)
    ax.legend(fontsize=8, loc="upper center", ncol=2)
    fig.tight_layout()
    fig.savefig(IMAGE, dpi=110)
    print("wrote", IMAGE)


if __name__ == "__main__":
    main()
