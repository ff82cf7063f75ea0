#!/usr/bin/env python3
"""Read tissue's snapshots with independent readers: h5py for the HDF5 files, meshio's XDMF TimeSeriesReader
for the index. The files come from `mpirun -np 2 snapshot_test --gtest_filter=Snapshot.WritesLatticeSeries`
(2 ranks, so the writer really gathers scrambled blocks), and every value is checked against the closed forms
of tests/snapshot_test.cpp, repeated here.

Usage: snapshot_readers_test.py --build BUILD_DIR --source SOURCE_DIR
Prints 'N passed, M failed'; exits nonzero on any failure."""
import argparse
import os
import shutil
import subprocess
import sys

import h5py
import meshio
import numpy as np

NX, NY, NZ = 4, 3, 2
N = NX * NY * NZ
C = (NX - 1) * NY * NZ
STEPS = [0, 10]
TIMES = [0.0, 0.5]
RANKS = 2

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import check, report  # noqa: E402


def close(a, b, what):
    a = np.asarray(a)
    b = np.asarray(b)
    check(a.shape == b.shape and np.allclose(a, b, rtol=1e-15, atol=0.0),
          f"{what}: got shape {a.shape}, expected {b.shape}"
          + ("" if a.shape != b.shape else f", max diff {np.max(np.abs(a - b)) if a.size else 0}"))


# ---- the closed forms of snapshot_test.cpp ----
def lattice(ident, c):
    ijk = (ident % NX, (ident // NX) % NY, ident // (NX * NY))
    return (0.1, 0.2, 0.3)[c] * ijk[c]


def displacement(ident, c, step):
    return 1e-3 * (step + 1) * (ident + 1) * (c + 1)


def position(ident, c, step):
    return lattice(ident, c) + displacement(ident, c, step)


def velocity(ident, c, step):
    return (step + 1) * (-float(ident) + 0.5 * c)


def endpoint(cid, e):
    i, j, k = cid % (NX - 1), (cid // (NX - 1)) % NY, cid // ((NX - 1) * NY)
    return i + NX * (j + NY * k) + e


def field(fn, step):
    return np.array([[fn(i, c, step) for c in range(3)] for i in range(N)])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", required=True)
    ap.add_argument("--source", required=True)
    args = ap.parse_args()

    out = os.path.join(os.path.abspath(args.build), "tests", "out", "readers")
    shutil.rmtree(out, ignore_errors=True)
    os.makedirs(out)
    exe = os.path.join(os.path.abspath(args.build), "tests", "snapshot_test")
    env = dict(os.environ, TISSUE_SNAPSHOT_DIR=out, OMPI_ALLOW_RUN_AS_ROOT="1",
               OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMPI_MCA_rmaps_base_oversubscribe="1")
    run = subprocess.run(["mpirun", "--oversubscribe", "-np", str(RANKS), exe,
                          "--gtest_filter=Snapshot.WritesLatticeSeries"],
                         env=env, capture_output=True, text=True, timeout=300)
    check(run.returncode == 0, f"snapshot_test wrote the files (exit {run.returncode}):\n{run.stdout}{run.stderr}")
    if run.returncode != 0:
        return report()

    prefix = os.path.join(out, f"snapshot_np{RANKS}")
    for step, time in zip(STEPS, TIMES):
        name = f"{prefix}_step{step}.h5"
        with h5py.File(name, "r") as f:
            a = f.attrs
            # Strings are fixed-length UTF-8 attributes (no global heap, io/hdf5_file.cpp): h5py gives bytes.
            check(all(not a.get_id(k).get_type().is_variable_str() for k in ("kind", "title", "version")),
                  f"{name}: string attributes are fixed-length")
            check(a["kind"] == b"snapshot", f"{name}: kind {a['kind']!r}")
            check(a["title"].decode() == "lattice 4 x 3 x 2 & <test>", f"{name}: title {a['title']!r}")
            check(int(a["step"]) == step and float(a["time"]) == time, f"{name}: step/time")
            check(int(a["molecules"]) == N and int(a["connections"]) == C, f"{name}: counts")
            check(int(a["ranks"]) == RANKS, f"{name}: ranks {a['ranks']}")
            check(isinstance(a["version"], bytes) and a["version"] != b"", f"{name}: version {a['version']!r}")
            check("forces" not in f["molecules"], f"{name}: an absent field left /molecules/forces")
            check(sorted(f["molecules"].keys()) == ["displacements", "positions", "velocities"],
                  f"{name}: molecule datasets {sorted(f['molecules'].keys())}")
            check(f["molecules/positions"].dtype == np.float64, f"{name}: positions dtype")
            check(f["connections/endpoints"].dtype == np.int64, f"{name}: endpoints dtype")
            close(f["molecules/positions"][()], field(position, step), f"{name}: positions")
            close(f["molecules/displacements"][()], field(displacement, step), f"{name}: displacements")
            close(f["molecules/velocities"][()], field(velocity, step), f"{name}: velocities")
            ends = np.array([[endpoint(c, 0), endpoint(c, 1)] for c in range(C)], dtype=np.int64)
            check(np.array_equal(f["connections/endpoints"][()], ends), f"{name}: endpoints")
            close(f["connections/strain"][()], np.array([[0.01 * c * (step + 1)] for c in range(C)]),
                  f"{name}: strain")
            close(f["connections/force"][()], np.array([[100.0 + c + step] for c in range(C)]), f"{name}: force")

    xdmf = f"{prefix}.xdmf"
    with meshio.xdmf.TimeSeriesReader(xdmf) as reader:
        points, cells = reader.read_points_cells()
        # meshio keeps the first frame's mesh for the whole series.
        close(points, field(position, STEPS[0]), "meshio points")
        check(len(cells) == 1 and cells[0].type == "line", f"meshio cells {[c.type for c in cells]}")
        ends = np.array([[endpoint(c, 0), endpoint(c, 1)] for c in range(C)])
        check(np.array_equal(cells[0].data, ends), "meshio line connectivity")
        check(reader.num_steps == len(STEPS), f"meshio steps {reader.num_steps}")
        for k, (step, time) in enumerate(zip(STEPS, TIMES)):
            t, point_data, cell_data = reader.read_data(k)
            check(t == time, f"meshio step {k}: time {t}")
            check(sorted(point_data) == ["displacement", "velocity"], f"meshio point data {sorted(point_data)}")
            close(point_data["displacement"], field(displacement, step), f"meshio step {k} displacement")
            close(point_data["velocity"], field(velocity, step), f"meshio step {k} velocity")
            check(sorted(cell_data) == ["connection_force", "strain"], f"meshio cell data {sorted(cell_data)}")
            close(np.ravel(cell_data["strain"][0]), [0.01 * c * (step + 1) for c in range(C)],
                  f"meshio step {k} strain")
            close(np.ravel(cell_data["connection_force"][0]), [100.0 + c + step for c in range(C)],
                  f"meshio step {k} connection_force")

    return report()


if __name__ == "__main__":
    sys.exit(main())
