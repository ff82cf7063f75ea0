#!/usr/bin/env python3
"""Fibre output (docs/anisotropy.md): /cells/fibre_stretch per cell and /molecules/fibre_direction, fibre_stretch
per molecule, on a box lattice (hexahedra of the cell term) and on a Gmsh cube (tetrahedra of the tetrahedron
term), read back with h5py. The bodies have fibres along x (homogenized: the calibration is exact, so a block in
tension along the fibres is stretched uniformly) and are pulled along x on a roller at 1, 2 and 3 ranks. Checks:
every cell's fibre stretch equals the uniform stretch measured from the block's x extent, and |F a| recomputed
here from the written positions; every molecule's stretch the same and its direction (1, 0, 0); the same values
at 1, 2 and 3 ranks (to round-off: the static solve's Krylov sums); the XDMF cells grid carries fibre_stretch as
a cell attribute; a body without fibres writes none of these datasets. And summary.json's youngs_modulus_target
of a fibre body is the transversely isotropic E along the load: E_L along the fibres, and for fibres at 45 degrees
to the load the closed form 1/E = (1 - c^2)^2/E_T + c^4/E_L + c^2 (1 - c^2)(1/G_L - 2 nu_LT/E_L), which the
lattice (a roller lets the block shear) measures to 1e-6. Mesh regions (tests/meshes/two_layers.msh: "deep" below
"surface", each 0.25 m): the deep layer isotropic (E_A, nu_A), the surface one with fibres along z (E_L, nu_LT)
chosen so that nu_A / E_A = nu_LT / E_L; pulled along z both layers carry the same stress and contract alike, so
the exact state is uniform per layer: E = 1 / (0.5 / E_A + 0.5 / E_L), lateral strain -nu_A sigma / E_A, the
surface tetrahedra's fibre stretch 1 + sigma / E_L and the deep ones' 0, at 1, 2 and 3 ranks.

Usage: fibre_output_test.py --build BUILD_DIR --source SOURCE_DIR      Prints 'N passed, M failed'."""
import os
import sys
import xml.etree.ElementTree as ET

import h5py
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import arguments_and_work, check, report, run_scene  # noqa: E402

E_T, NU, E_L, NU_LT, STRAIN = 1000.0, 0.3, 20000.0, 0.3, 1e-4
FIBRES = f"""[body.fibres]
direction = [1.0, 0.0, 0.0]
youngs_modulus = {E_L}
poisson_ratio = {NU_LT}
"""


def scene(body, area, fibres=True, direction="[1.0, 0.0, 0.0]", force=None):
    return f"""title = "fibre output"
[body]
{body}youngs_modulus = {E_T}
poisson_ratio = {NU}
{FIBRES.replace("[1.0, 0.0, 0.0]", direction) if fibres else ""}[calibration]
method = "homogenized"
[[fix]]
face = "x-"
mode = "roller"
[[load]]
face = "x+"
force = [{force or (E_L if fibres else E_T) * STRAIN * area}, 0.0, 0.0]
[solver]
kind = "static"
tolerance = 1e-11
[output]
fields = ["displacements"]
progress = false
"""


def gradients(rest, corners):
    """Per cell, the matrix G with F = x[corners]^T G (the one-point gradient of the output's cells): the
    trilinear hexahedron's at its centre, or the linear tetrahedron's."""
    if corners.shape[1] == 4:
        X = rest[corners]
        Dm = np.stack([X[:, a] - X[:, 0] for a in (1, 2, 3)], axis=-1)  # columns X_a - X_0
        g = np.linalg.inv(Dm)  # rows: the gradients of the shape functions of corners 1..3
        return np.concatenate([-g.sum(axis=1, keepdims=True), g], axis=1)
    unit = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])
    h = rest[corners[:, 6]] - rest[corners[:, 0]]  # the cell's edge lengths (VTK order: corner 6 opposite 0)
    return (2 * unit - 1)[None, :, :] / (4.0 * h[:, None, :])


def check_fibres(out, label, nodes):
    with h5py.File(os.path.join(out, "final.h5"), "r") as f:
        x = f["/molecules/positions"][()]
        u = f["/molecules/displacements"][()]
        corners = f["/cells/corners"][()]
        cell = f["/cells/fibre_stretch"][()][:, 0]
        direction = f["/molecules/fibre_direction"][()]
        stretch = f["/molecules/fibre_stretch"][()][:, 0]
    check(corners.shape[1] == nodes and cell.shape == (corners.shape[0],), f"{label}: {corners.shape} {cell.shape}")
    rest = x - u
    along = (x[:, 0].max() - x[:, 0].min()) / (rest[:, 0].max() - rest[:, 0].min())
    check(abs(along - 1 - STRAIN) < 0.05 * STRAIN, f"{label}: stretch {along} against 1 + {STRAIN}")
    check(np.max(np.abs(cell - along)) < 1e-12, f"{label}: cells' fibre stretch {cell.min()}..{cell.max()} = {along}")
    F = np.einsum("cai,caj->cij", x[corners], gradients(rest, corners))
    check(np.max(np.abs(np.linalg.norm(F[:, :, 0], axis=1) - cell)) < 1e-12, f"{label}: |F a| of the positions")
    check(np.max(np.abs(stretch - along)) < 1e-12, f"{label}: molecules' fibre stretch {stretch.min()}..{stretch.max()}")
    check(np.max(np.abs(direction - [1.0, 0.0, 0.0])) < 1e-9, f"{label}: molecules' fibre direction along x")
    grids = list(ET.parse(os.path.join(out, "tissue.xdmf")).getroot().find("Domain"))
    names = {a.get("Name"): a.get("Center") for a in grids[0].find("Grid").findall("Attribute")}
    check(names.get("fibre_stretch") == "Cell" and names.get("volume_ratio") == "Cell", f"{label}: xdmf {names}")
    return cell


def main():
    a, work = arguments_and_work("fibre_output")
    lattice = 'molecules = [5, 4, 4]\nsize = [4.0, 3.0, 1.5]\ntopology = "face-diagonals"\n'  # 1:1:1/2 cells
    mesh = f'shape = "mesh"\nfile = "{os.path.join(a.source, "tests", "meshes", "cube_h0.5.msh")}"\n'
    for label, body, area, nodes in (("lattice", lattice, 3.0 * 1.5, 8), ("mesh", mesh, 1.0, 4)):
        cells = {}
        for ranks in (1, 2, 3):
            out, r = run_scene(a.build, work, f"{label}_np{ranks}", ranks, scene(body, area))
            check(r.returncode == 0, f"{label} at {ranks} ranks: exit {r.returncode}: {r.stderr[-400:]}")
            if r.returncode == 0:
                cells[ranks] = check_fibres(out, f"{label} at {ranks} ranks", nodes)
        if len(cells) == 3:
            check(max(np.max(np.abs(cells[r] - cells[1])) for r in (2, 3)) < 1e-13, f"{label}: the same at 1-3 ranks")
        out, r = run_scene(a.build, work, f"{label}_no_fibres", 2, scene(body, area, fibres=False))
        check(r.returncode == 0, f"{label} without fibres: exit {r.returncode}: {r.stderr[-400:]}")
        with h5py.File(os.path.join(out, "final.h5"), "r") as f:
            check("fibre_stretch" not in f["/cells"] and "fibre_stretch" not in f["/molecules"],
                  f"{label} without fibres: no fibre datasets")
    check_mesh_regions(a, work)
    # the summary's target along the load
    import json
    c2 = 0.5
    G_L = E_T / (2 * (1 + NU))  # the default G_L (docs/anisotropy.md)
    E45 = 1 / ((1 - c2) ** 2 / E_T + c2 ** 2 / E_L + c2 * (1 - c2) * (1 / G_L - 2 * NU_LT / E_L))
    for label, direction, target in (("aligned", "[1.0, 0.0, 0.0]", E_L), ("oblique", "[1.0, 1.0, 0.0]", E45)):
        out, r = run_scene(a.build, work, label, 1, scene(lattice, 4.5, direction=direction,
                                                           force=target * STRAIN * 4.5))
        check(r.returncode == 0, f"{label}: exit {r.returncode}: {r.stderr[-400:]}")
        with open(os.path.join(out, "summary.json")) as f:
            summary = json.load(f)
        check(abs(summary["youngs_modulus_target"] / target - 1) < 1e-12,
              f"{label}: target {summary['youngs_modulus_target']} against {target}")
        check(abs(summary["youngs_modulus_measured"] / target - 1) < 2 * STRAIN,  # geometric nonlinearity ~ strain
              f"{label}: measured {summary['youngs_modulus_measured']} against {target}")
    return report()


def check_mesh_regions(a, work):
    E_A, NU_A, E_L2, NU_LT2, SIGMA = 1000.0, 0.1, 2000.0, 0.2, 1e-4
    text = f"""title = "two layers"
[body]
shape = "mesh"
file = "{os.path.join(a.source, "tests", "meshes", "two_layers.msh")}"
youngs_modulus = {E_A}
poisson_ratio = {NU_A}
[[body.region]]
name = "surface"
youngs_modulus = 500.0
poisson_ratio = 0.3
[body.region.fibres]
direction = [0.0, 0.0, 1.0]
youngs_modulus = {E_L2}
poisson_ratio = {NU_LT2}
[calibration]
method = "homogenized"
[[fix]]
face = "bottom"
mode = "roller"
[[load]]
face = "top"
force = [0.0, 0.0, {SIGMA}]
[solver]
kind = "static"
tolerance = 1e-10
[output]
fields = ["displacements"]
progress = false
"""
    import json
    E = 1 / (0.5 / E_A + 0.5 / E_L2)
    for ranks in (1, 2, 3):
        out, r = run_scene(a.build, work, f"layers_np{ranks}", ranks, text)
        check(r.returncode == 0, f"layers at {ranks} ranks: exit {r.returncode}: {r.stderr[-400:]}")
        if r.returncode != 0:
            continue
        with open(os.path.join(out, "summary.json")) as f:
            measured = json.load(f)["youngs_modulus_measured"]
        check(abs(measured / E - 1) < 1e-6, f"layers at {ranks} ranks: E {measured} against {E}")
        with h5py.File(os.path.join(out, "final.h5"), "r") as f:
            x = f["/molecules/positions"][()]
            u = f["/molecules/displacements"][()]
            corners = f["/cells/corners"][()]
            stretch = f["/cells/fibre_stretch"][()][:, 0]
        rest = x - u
        for axis in (0, 1):
            lateral = (x[:, axis].max() - x[:, axis].min()) / (rest[:, axis].max() - rest[:, axis].min()) - 1
            check(abs(lateral / (-NU_A * SIGMA / E_A) - 1) < 1e-5,
                  f"layers at {ranks} ranks: lateral strain {lateral} against {-NU_A * SIGMA / E_A}")
        surface = rest[corners][:, :, 2].mean(axis=1) > 0.25
        check(np.max(np.abs(stretch[surface] - (1 + SIGMA / E_L2))) < 1e-12 and np.all(stretch[~surface] == 0),
              f"layers at {ranks} ranks: fibre stretch {stretch[surface].min()}..{stretch[surface].max()} on the "
              f"surface layer's {surface.sum()} tetrahedra, 0 on the deep layer's {(~surface).sum()}")


if __name__ == "__main__":
    sys.exit(main())
