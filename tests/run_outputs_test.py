#!/usr/bin/env python3
"""A user's run read back with independent readers: `mpirun -np 2 tissue run` on a small tension scene, then
h5py opens final.h5, meshio opens tissue.xdmf, and json reads summary.json. Checks: the datasets are in original
molecule order (positions - displacements = the rest lattice computed here), the elongation recomputed from the
file equals the summary's, Eq. 3 recomputed equals the summary's E, every contract key of summary.json exists,
and the same run on 1 and 3 ranks gives the same elongation to 1e-10.

Usage: run_outputs_test.py --build BUILD_DIR --source SOURCE_DIR      Prints 'N passed, M failed'."""
import argparse
import json
import os
import shutil
import subprocess
import sys

import h5py
import meshio
import numpy as np

SCENE = """
title = "outputs"
[body]
molecules = [4, 5, 6]
spacing = [0.1, 0.12, 0.09]
topology = "face-diagonals"
youngs_modulus = 1.0e5
[[fix]]
face = "z+"
[[load]]
face = "z-"
force = [0.0, 0.0, -20.0]
[solver]
kind = "static"
tolerance = 1e-12
[output]
fields = ["positions", "displacements", "velocities", "forces", "connection_strain", "connection_force"]
progress = false
"""
NX, NY, NZ = 4, 5, 6
H = (0.1, 0.12, 0.09)
KEYS = ["molecules", "connections", "ranks", "youngs_modulus_target", "youngs_modulus_measured", "error_percent",
        "elongation", "rest_length", "cross_section", "poisson_ratio_measured", "calibration", "solver", "time",
        "steps", "kinetic_energy", "center_of_mass_initial", "center_of_mass", "contact_force", "wall_seconds",
        "peak_memory_bytes"]

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import check, report  # noqa: E402


def run(build, workdir, ranks):
    out = os.path.join(workdir, f"np{ranks}")
    cmd = ["mpirun", "--oversubscribe", "-np", str(ranks), os.path.join(build, "tissue"), "run",
           os.path.join(workdir, "scene.toml"), "--output", out]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    check(r.returncode == 0, f"{ranks} ranks: exit code {r.returncode}: {r.stderr[-500:]}")
    return out


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--build", required=True)
    p.add_argument("--source", required=True)
    a = p.parse_args()
    workdir = os.path.join(a.build, "tests", "out", "run_outputs")
    shutil.rmtree(workdir, ignore_errors=True)
    os.makedirs(workdir)
    with open(os.path.join(workdir, "scene.toml"), "w") as f:
        f.write(SCENE)

    out = run(a.build, workdir, 2)
    summary = json.load(open(os.path.join(out, "summary.json")))
    for k in KEYS:
        check(k in summary, f"summary.json has {k}")
    check(summary["molecules"] == NX * NY * NZ and summary["ranks"] == 2, "summary counts")

    # The rest lattice, in original order: id = i + nx (j + ny k).
    k, j, i = np.meshgrid(range(NZ), range(NY), range(NX), indexing="ij")
    rest = np.stack([i.ravel() * H[0], j.ravel() * H[1], k.ravel() * H[2]], axis=1)
    with h5py.File(os.path.join(out, "final.h5"), "r") as f:
        x = f["/molecules/positions"][...]
        u = f["/molecules/displacements"][...]
        check(x.shape == (NX * NY * NZ, 3), "positions shape")
        check(np.allclose(x - u, rest, atol=1e-14, rtol=0), "positions - displacements = rest lattice, in id order")
        ends = f["/connections/endpoints"][...]
        check(ends.shape == (summary["connections"], 2), "endpoints shape")
        check(bool(np.all(ends[:, 0] < ends[:, 1])), "endpoints a < b")
        strain = f["/connections/strain"][...].ravel()
        force = f["/connections/force"][...].ravel()
        length = np.linalg.norm(x[ends[:, 1]] - x[ends[:, 0]], axis=1)
        rest_len = np.linalg.norm(rest[ends[:, 1]] - rest[ends[:, 0]], axis=1)
        check(np.allclose(strain, (length - rest_len) / rest_len, rtol=1e-9, atol=1e-15), "strain from positions")
        check(bool(np.all(np.sign(force) == np.sign(strain)) or np.allclose(force, 0)), "force sign = strain sign")
        fz = f["/molecules/forces"][...]
        bottom, top = k.ravel() == 0, k.ravel() == NZ - 1
        # Reactions: the connection forces on the clamped top balance the 20 N load.
        check(abs(fz[top, 2].sum() + 20.0) < 1e-8, f"reaction {fz[top, 2].sum()} balances the load")
        check(f.attrs["ranks"] == 2 and f.attrs["molecules"] == NX * NY * NZ, "file attributes")
    elongation = (-u[bottom, 2]).mean() - (-u[top, 2]).mean()
    check(abs(elongation - summary["elongation"]) <= 1e-14 * abs(elongation), "elongation recomputed from h5")
    l0, A = (NZ - 1) * H[2], (NX - 1) * H[0] * (NY - 1) * H[1]
    check(abs(summary["rest_length"] - l0) < 1e-15 and abs(summary["cross_section"] - A) < 1e-15, "l0 and A")
    E = 20.0 * l0 / (elongation * A)
    check(abs(E - summary["youngs_modulus_measured"]) <= 1e-12 * E, "Eq. 3 recomputed")

    reader = meshio.xdmf.TimeSeriesReader(os.path.join(out, "tissue.xdmf"))
    points, cells = reader.read_points_cells()
    check(np.allclose(points, x), "meshio points = h5py positions")
    check(sum(len(c.data) for c in cells) == summary["connections"], "meshio cells = connections")
    t, point_data, cell_data = reader.read_data(0)
    check(np.allclose(point_data["displacement"], u), "meshio displacement")

    for ranks in (1, 3):
        other = json.load(open(os.path.join(run(a.build, workdir, ranks), "summary.json")))
        check(abs(other["elongation"] - summary["elongation"]) <= 1e-10 * abs(elongation),
              f"{ranks} ranks: same elongation ({other['elongation']!r} vs {summary['elongation']!r})")

    return report()


if __name__ == "__main__":
    sys.exit(main())
