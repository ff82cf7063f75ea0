#!/usr/bin/env python3
"""The static solver on explicit topologies larger than the lattice multigrid's coarsest level: a random cloud
(1,728 molecules) and a gmsh cube meshed at run time (1,201 molecules). Their molecule ids are no lattice
indices, so the solver must take GAMG, not the lattice multigrid (which once built a 'lattice' from the nominal
size and stopped in PETSc on mismatched sizes). Each body is pulled in tension at 1, 2 and 3 ranks: the static
solve must converge, the elongation must agree across rank counts to 1e-9 relative (round-off only), and the
relaxation solver (FIRE, another method) must reach the same elongation to 1e-6. At 2 and 3 ranks also with
GAMG kept across Newton iterations and aggregating unsmoothed (-static_gamg_reuse_molecules 0: what bodies from
20,000 molecules get): the same elongation as 1 rank to 1e-9, converged, and no more than the rebuild rule's
Krylov iterations.

Usage: unstructured_static_test.py --build BUILD_DIR --source SOURCE_DIR      Prints 'N passed, M failed'."""
import argparse
import json
import os
import shutil
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import check, report  # noqa: E402


def run(tissue, scene, out, ranks, extra):
    cmd = ["mpirun", "--oversubscribe", "-np", str(ranks), tissue, "run", scene, "--output", out,
           "--set", "output.fields=[]"] + extra
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        print(" ".join(cmd), "\n", p.stdout[-2000:], p.stderr[-2000:])
        return None
    return json.load(open(os.path.join(out, "summary.json")))


def main():
    a = argparse.ArgumentParser()
    a.add_argument("--build", required=True)
    a.add_argument("--source", required=True)
    a = a.parse_args()
    os.environ.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    tissue = os.path.join(a.build, "tissue")
    scenes = os.path.join(a.source, "run_scripts", "scenes")
    work = os.path.join(a.build, "tests", "out", "unstructured_static")
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    mesh = os.path.join(work, "cube.msh")
    subprocess.run(["gmsh", "-3", "-format", "msh41", "-setnumber", "h", "0.1",
                    os.path.join(scenes, "cube_mesh.geo"), "-o", mesh], check=True, capture_output=True)
    cases = {"random": (os.path.join(scenes, "random_cube.toml"), ["--set", "body.molecules=[12,12,12]"], 1728),
             "mesh": (os.path.join(scenes, "mesh_cube.toml"), ["--set", "body.file=" + mesh], 1201)}
    for name, (scene, extra, molecules) in cases.items():
        static = {}
        for ranks in (1, 2, 3):
            s = run(tissue, scene, os.path.join(work, f"{name}_np{ranks}"), ranks, extra)
            check(s is not None, f"{name}: static run at {ranks} ranks")
            if s is None:
                continue
            check(s["molecules"] == molecules, f"{name}: {s['molecules']} molecules, expected {molecules}")
            check(s["solver"]["converged"], f"{name}: static did not converge at {ranks} ranks")
            static[ranks] = s["elongation"]
            if ranks == 1:
                continue
            k = run(tissue, scene, os.path.join(work, f"{name}_np{ranks}_reuse"), ranks,
                    extra + ["--", "-static_gamg_reuse_molecules", "0"])
            check(k is not None and k["solver"]["converged"], f"{name}: static with GAMG kept, {ranks} ranks")
            if k is None or 1 not in static:
                continue
            rel = abs(k["elongation"] - static[1]) / abs(static[1])
            check(rel < 1e-9, f"{name}: elongation with GAMG kept at {ranks} ranks differs from 1 rank by {rel:.2e}")
            its, fresh = k["solver"]["linear_iterations"], s["solver"]["linear_iterations"]
            check(its <= 2 * fresh + 10, f"{name}: GAMG kept took {its} Krylov iterations, rebuilt {fresh}")
        for ranks in (2, 3):
            if 1 in static and ranks in static:
                rel = abs(static[ranks] - static[1]) / abs(static[1])
                check(rel < 1e-9, f"{name}: elongation at {ranks} ranks differs from 1 rank by {rel:.2e}")
        r = run(tissue, scene, os.path.join(work, f"{name}_relax"), 2,
                extra + ["--set", "solver.kind=relaxation", "--set", "solver.tolerance=1e-10"])
        check(r is not None and r["solver"]["converged"], f"{name}: relaxation run")
        if r is not None and 1 in static:
            rel = abs(r["elongation"] - static[1]) / abs(static[1])
            check(rel < 1e-6, f"{name}: relaxation elongation differs from static by {rel:.2e}")
    return report()


if __name__ == "__main__":
    sys.exit(main())
