#!/usr/bin/env python3
"""Per-cell output of the cell term (docs/poisson.md): `tissue run` of a block with poisson_ratio (homogenized,
flat 2:1 cells, so the cell term carries both a volumetric part and virtual diagonals) in tension on a roller, at 1,
2 and 3 ranks, read back with h5py and the XML of tissue.xdmf. Checks: /cells/corners holds every lattice cell
once as a hexahedron in VTK corner order (checked on the rest positions: an axis-aligned box of the lattice's
spacing); /cells/volume_ratio equals, to round-off, the volume ratio of the uniform stretch measured from the
block's edges and det F recomputed here from the written positions, and to first order the closed form
(1 + eps)(1 - nu eps)^2 with eps = sigma / E; the same J at 1, 2 and 3 ranks (to round-off: Krylov sums); the XDMF's first grid is hexahedra with the volume_ratio cell attribute, the last
(meshio's) still the connections; /molecules/positions and displacements unchanged in shape; a scene without
the cell term writes no /cells; lattice.xdmf describes the box as a structured grid whose points are the lattice.

Usage: cell_output_test.py --build BUILD_DIR --source SOURCE_DIR      Prints 'N passed, M failed'."""
import argparse
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import h5py
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import check, report  # noqa: E402

N = [4, 5, 4]
H = [1.0, 1.0, 0.5]  # flat cells (1:2): the virtual diagonals are in the cell term too
E, NU, STRAIN = 1000.0, 0.4, 1e-4


def scene(nu_line):
    area = (N[0] - 1) * H[0] * (N[1] - 1) * H[1]
    return f"""
title = "cell output"
[body]
molecules = {N}
spacing = {H}
topology = "face-diagonals"
youngs_modulus = {E}
{nu_line}
[calibration]
method = "homogenized"
[[fix]]
face = "z-"
mode = "roller"
[[load]]
face = "z+"
force = [0.0, 0.0, {E * STRAIN * area}]
[solver]
kind = "static"
tolerance = 1e-11
[output]
fields = ["displacements"]
progress = false
"""


def run(build, workdir, name, text, ranks):
    path = os.path.join(workdir, name + ".toml")
    with open(path, "w") as f:
        f.write(text)
    out = os.path.join(workdir, f"{name}_np{ranks}")
    r = subprocess.run(["mpirun", "--oversubscribe", "-np", str(ranks), os.path.join(build, "tissue"), "run", path,
                        "--output", out], capture_output=True, text=True, timeout=120)
    check(r.returncode == 0, f"{name} at {ranks} ranks: exit code {r.returncode}: {r.stderr[-500:]}")
    return out


def check_cells(out, ranks):
    molecules = N[0] * N[1] * N[2]
    cells = (N[0] - 1) * (N[1] - 1) * (N[2] - 1)
    with h5py.File(os.path.join(out, "final.h5"), "r") as f:
        x = f["/molecules/positions"][()]
        u = f["/molecules/displacements"][()]
        corners = f["/cells/corners"][()]
        J = f["/cells/volume_ratio"][()]
    check(x.shape == (molecules, 3) and u.shape == (molecules, 3), f"{ranks} ranks: molecule datasets {x.shape}")
    check(corners.shape == (cells, 8) and J.shape == (cells, 1), f"{ranks} ranks: cells {corners.shape} {J.shape}")
    check(len(np.unique(corners[:, 0])) == cells, f"{ranks} ranks: every cell once")
    # VTK hexahedron order on the rest lattice: (0,0,0) (1,0,0) (1,1,0) (0,1,0), then the same at z + h_z.
    rest = x - u
    unit = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])
    offsets = rest[corners] - rest[corners[:, :1]]
    check(np.allclose(offsets, unit * np.array(H), atol=1e-12), f"{ranks} ranks: hexahedra in VTK corner order")
    # The uniform stretch measured on the block's edges: every cell's J is their product.
    stretch = [(x[:, a].max() - x[:, a].min()) / ((N[a] - 1) * H[a]) for a in range(3)]
    J_measured = stretch[0] * stretch[1] * stretch[2]
    check(np.max(np.abs(J[:, 0] - J_measured)) < 1e-12,
          f"{ranks} ranks: J {J[:, 0].min()}..{J[:, 0].max()} against the measured stretch {J_measured}")
    # J recomputed here from the file's positions: F = sum_a x_a (x) g_a at the cell centre (trilinear cell)
    signs = 2 * unit - 1
    g = signs / (4.0 * np.array(H))
    F = np.einsum("cai,aj->cij", x[corners], g)
    check(np.max(np.abs(np.linalg.det(F) - J[:, 0])) < 1e-13, f"{ranks} ranks: J = det F of the written positions")
    eps = STRAIN  # sigma / E
    J_closed = (1 + eps) * (1 - NU * eps) ** 2
    # first order: the difference is O(eps^2) against J - 1 = O(eps (1 - 2 nu))
    check(abs(J_measured - J_closed) < 1e-3 * abs(J_closed - 1),
          f"{ranks} ranks: J - 1 = {J_measured - 1} against (1 + eps)(1 - nu eps)^2 - 1 = {J_closed - 1}")
    # the XDMF: cells first (hexahedra, volume_ratio), connections last (meshio reads the last collection)
    grids = list(ET.parse(os.path.join(out, "tissue.xdmf")).getroot().find("Domain"))
    check([g.get("Name") for g in grids] == ["cells", "tissue"], f"{ranks} ranks: xdmf grids")
    frame = grids[0].find("Grid")
    topology = frame.find("Topology")
    check(topology.get("TopologyType") == "Hexahedron" and topology.get("NumberOfElements") == str(cells),
          f"{ranks} ranks: xdmf topology {topology.attrib}")
    names = {a.get("Name"): a.get("Center") for a in frame.findall("Attribute")}
    check(names.get("volume_ratio") == "Cell" and names.get("displacement") == "Node", f"{ranks} ranks: {names}")
    check(grids[1].find("Grid").find("Topology").get("TopologyType") == "Polyline", f"{ranks} ranks: connections")
    return J


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--build", required=True)
    p.add_argument("--source", required=True)
    a = p.parse_args()
    workdir = os.path.join(a.build, "tests", "out", "cell_output")
    shutil.rmtree(workdir, ignore_errors=True)
    os.makedirs(workdir)
    J = {}
    for ranks in (1, 2, 3):
        J[ranks] = check_cells(run(a.build, workdir, "cells", scene(f"poisson_ratio = {NU}"), ranks), ranks)
    # the static solve's Krylov sums differ with the partition: J agrees to round-off, not bit for bit
    check(max(np.max(np.abs(J[r] - J[1])) for r in (2, 3)) < 1e-13, "the same J at 1, 2, 3 ranks")
    # without poisson_ratio (cubic cells, nu = 1/4): no cell term, no /cells, one grid
    global H
    H = [1.0, 1.0, 1.0]
    out = run(a.build, workdir, "springs", scene(""), 2)
    with h5py.File(os.path.join(out, "final.h5"), "r") as f:
        check("cells" not in f, "no /cells without the cell term")
    grids = list(ET.parse(os.path.join(out, "tissue.xdmf")).getroot().find("Domain"))
    check([g.get("Name") for g in grids] == ["tissue"], "one xdmf grid without the cell term")
    check_lattice_xdmf(out)
    return report()


def check_lattice_xdmf(out):
    """lattice.xdmf (io/xdmf.hpp): the box as a structured grid whose point (i, j, k), x fastest, is molecule
    i + n_x (j + n_y k): the rest positions read through that shape are the lattice i h_x, j h_y, k h_z."""
    grid = ET.parse(os.path.join(out, "lattice.xdmf")).getroot().find("Domain").find("Grid").find("Grid")
    topology = grid.find("Topology")
    check(topology.get("TopologyType") == "3DSMesh" and topology.get("Dimensions") == f"{N[2]} {N[1]} {N[0]}",
          f"lattice.xdmf topology {topology.attrib}")
    check(grid.find("Geometry").find("DataItem").text == "final.h5:/molecules/positions", "lattice.xdmf geometry")
    check([a.get("Name") for a in grid.findall("Attribute")] == ["displacement"], "lattice.xdmf: node fields only")
    with h5py.File(os.path.join(out, "final.h5"), "r") as f:
        rest = (f["/molecules/positions"][:] - f["/molecules/displacements"][:]).reshape(N[2], N[1], N[0], 3)
    k, j, i = np.meshgrid(*(np.arange(n) for n in (N[2], N[1], N[0])), indexing="ij")
    lattice = np.stack([i * H[0], j * H[1], k * H[2]], axis=-1)
    check(np.max(np.abs(rest - lattice)) < 1e-12, "lattice.xdmf: the structured grid's points are the lattice")


if __name__ == "__main__":
    sys.exit(main())
