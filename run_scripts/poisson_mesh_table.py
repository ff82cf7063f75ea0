#!/usr/bin/env python3
"""Any Poisson ratio on meshes (docs/poisson.md, "Meshes and random clouds"): the tissue CLI on the Gmsh unit cube
(tests/meshes/cube.geo) meshed at element sizes h, homogenized with nu in {0.1, 0.25, 0.45}, strain 1e-7:
  - tension on rollers (z- roller, traction on z+): the errors of E and both lateral nu against the target;
  - the same with the base bonded (z- clamped): the apparent modulus F l0 / (dl A), which has no closed form and
    converges as the mesh is refined (the table gives its change from the next coarser mesh), and the static
    solver's Krylov iterations (GAMG) for it.
Prints a markdown table.

    /usr/bin/python3 run_scripts/poisson_mesh_table.py [build/tissue] [ranks]
"""
import json
import os
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TISSUE = sys.argv[1] if len(sys.argv) > 1 else os.path.join(ROOT, "build", "tissue")
RANKS = int(sys.argv[2]) if len(sys.argv) > 2 else 2
E = 1000.0
ENV = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")


def mesh(work, h):
    out = os.path.join(work, f"cube_h{h}.msh")
    subprocess.run(["gmsh", "-3", "-format", "msh41", "-setnumber", "h", str(h),
                    os.path.join(ROOT, "tests", "meshes", "cube.geo"), "-o", out],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return out


def run(work, msh, nu, base):
    scene = os.path.join(work, "scene.toml")
    with open(scene, "w") as f:
        f.write(f'title = "poisson mesh table"\n[body]\nshape = "mesh"\nfile = "{msh}"\n'
                f"youngs_modulus = {E}\npoisson_ratio = {nu}\n[calibration]\nmethod = \"homogenized\"\n"
                f'[[fix]]\nface = "z-"\nmode = "{base}"\n[[load]]\nface = "z+"\nforce = [0.0, 0.0, {E * 1e-7}]\n'
                f'[solver]\nkind = "static"\ntolerance = 1e-10\n[output]\ndirectory = "{work}/out"\n'
                "progress = false\n")
    t = time.time()
    subprocess.run(["mpirun", "--oversubscribe", "-np", str(RANKS), TISSUE, "run", scene, "--output",
                    os.path.join(work, "out")], check=True, env=ENV, stdout=subprocess.DEVNULL)
    seconds = time.time() - t
    with open(os.path.join(work, "out", "summary.json")) as f:
        return json.load(f), seconds


def main():
    with tempfile.TemporaryDirectory() as work:
        print("| nu | h | molecules | E error (rollers) | nu_x error | nu_y error | E_app bonded / E | "
              "change from coarser | Krylov (bonded) | seconds (both runs) |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        meshes = {h: mesh(work, h) for h in (0.5, 0.25, 0.125, 0.0625)}
        for nu in (0.1, 0.25, 0.45, 0.49):
            previous = None
            for h, msh in meshes.items():
                s, t1 = run(work, msh, nu, "roller")
                b, t2 = run(work, msh, nu, "clamped")
                m = s["measured"] if "measured" in s else s
                mb = b["measured"] if "measured" in b else b
                Em = m["youngs_modulus_measured"]
                nus = m["poisson_ratios_measured"]
                Eb = mb["youngs_modulus_measured"] / E
                change = "" if previous is None else f"{(Eb - previous) / previous:+.2e}"
                previous = Eb
                n = s.get("molecules", "")
                print(f"| {nu} | {h} | {n} | {Em / E - 1:+.1e} | {nus[0] - nu:+.1e} | {nus[1] - nu:+.1e} | "
                      f"{Eb:.5f} | {change} | {b['solver']['linear_iterations']} ({b['solver']['iterations']} Newton) | {t1 + t2:.2f} |", flush=True)


if __name__ == "__main__":
    main()
