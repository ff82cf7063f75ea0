#!/usr/bin/env python3
"""Every Gmsh format runs as the ASCII mesh does (io/gmsh_mesh.cpp reads through the Gmsh library): `tissue run`
on the two-layer slab (tests/meshes/two_layers.*) from binary MSH 4.1, binary MSH 2.2 and the .geo meshed at run
time, at 1 and 2 ranks, writes the summary.json numbers of the ASCII MSH 4.1 file to 1e-12 relative (every number
but times and memory; for the .geo also but the solver's final residual, a round-off-sized number that the ASCII
file's 16-digit positions, 1e-16 m off the .geo's, change by a few per cent).
With the gmsh program (skipped without it): the .geo meshed at run time gives the numbers of the same .geo meshed
by the gmsh program, saved binary (the same doubles) to 1e-12 in every one, residual included; and `mesh_size` on a .geo:
run_scripts/scenes/cube_mesh.geo with mesh_size = 0.3 gives those of the gmsh program on it with h = 0.3."""
import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

SLAB = """title = "two-layer slab"
[body]
shape = "mesh"
file = "{mesh}"
{extra}youngs_modulus = 1.0e5
density = 1000.0
[[body.region]]
name = "surface"
youngs_modulus = 3.0e5
density = 1500.0
[calibration]
method = "tetrahedral"
[[fix]]
face = "bottom"
mode = "roller"
[[load]]
face = "top"
force = [0.0, 0.0, 20.0]
[solver]
kind = "static"
tolerance = 1e-11
[output]
fields = []
progress = false
"""

CUBE = """title = "gmsh cube"
[body]
shape = "mesh"
file = "{mesh}"
{extra}youngs_modulus = 1.0e5
[calibration]
method = "tetrahedral"
[[fix]]
face = "z-"
mode = "roller"
[[load]]
face = "z+"
force = [0.0, 0.0, 100.0]
[solver]
kind = "static"
tolerance = 1e-11
[output]
fields = []
progress = false
"""

SKIP = {"scene", "wall_seconds", "seconds", "cpu_seconds", "guard_seconds", "peak_memory_bytes"}
ROUND_OFF = {"residual", "residual_history",  # solver.*: the final force residual, ~1e-11 N of round-off
             "reactions"}  # a hold's lateral reaction is round-off (1e-13 N of the 20 N load): compared below, absolute


def differences(a, b, skip=SKIP, path=""):
    """Where two summaries differ: numbers beyond 1e-12 relative, anything else not equal."""
    out = []
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k in skip:
                continue
            if k not in a or k not in b:
                out.append(f"{path}{k}: only in one")
            else:
                out += differences(a[k], b[k], skip, f"{path}{k}.")
    elif isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b)):
            out += differences(x, y, skip, f"{path}{i}.")
    elif isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        if abs(a - b) > 1e-12 * max(abs(a), abs(b)):
            out.append(f"{path.rstrip('.')}: {a!r} vs {b!r}")
    elif a != b:
        out.append(f"{path.rstrip('.')}: {a!r} vs {b!r}")
    return out


def run(tissue, template, mesh, ranks, work, name, extra=""):
    scene = work / f"{name}.toml"
    scene.write_text(template.format(mesh=mesh, extra=extra))
    out = work / f"{name}_out"
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    cmd = ["mpirun", "--oversubscribe", "-np", str(ranks), str(tissue), "run", str(scene), "--output", str(out)]
    p = subprocess.run(cmd, capture_output=True, env=env, timeout=600)
    if p.returncode != 0:
        raise RuntimeError(f"{name} at {ranks} rank(s) failed ({p.returncode}): {p.stderr.decode()[-2000:]}")
    return json.loads((out / "summary.json").read_text())


def cli_mesh(gmsh, geo, out, before=""):
    """`gmsh -3` on `geo`, saved binary (the very doubles Gmsh made: the .geo files ask for ASCII, Mesh.Binary = 0,
    which a wrapper including them overrides)."""
    wrapper = out.with_suffix(".geo")
    wrapper.write_text(f'{before}Include "{geo}";\nMesh.Binary = 1;\n')
    subprocess.run([gmsh, "-3", "-format", "msh41", str(wrapper), "-o", str(out)], check=True, capture_output=True)
    if b"4.1 1 8" not in out.read_bytes()[:64]:
        raise RuntimeError(f"{out} is not binary MSH 4.1")
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--build", required=True)
    parser.add_argument("--source", required=True)
    args = parser.parse_args()
    tissue = (Path(args.build) / "tissue").resolve()
    meshes = Path(args.source).resolve() / "tests" / "meshes"
    failed, passed = [], 0

    def check(label, reference, other, skip=SKIP):
        nonlocal passed
        diff = differences(reference, other, skip)
        if diff:
            failed.append(f"{label}: " + "; ".join(diff[:6]))
            print(f"FAIL {label}: {diff[:6]}")
        else:
            passed += 1
            print(f"ok   {label}")

    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for ranks in (1, 2):
            ref = run(tissue, SLAB, meshes / "two_layers.msh", ranks, work, f"ascii_np{ranks}")
            if ref["molecules"] != 320 or not ref["solver"]["converged"]:
                failed.append(f"the ASCII slab at {ranks} rank(s): {ref['molecules']} molecules, "
                              f"converged {ref['solver']['converged']}")
                continue
            for name in ("two_layers_bin41.msh", "two_layers_bin22.msh", "two_layers.geo"):
                other = run(tissue, SLAB, meshes / name, ranks, work, f"{name}_np{ranks}")
                check(f"{name} at {ranks} rank(s) = ASCII MSH 4.1", ref, other,
                      SKIP | ROUND_OFF if name.endswith(".geo") else SKIP)
                if name.endswith(".geo"):
                    slab_geo = other
                    # the reactions to 1e-12 of the 20 N load, absolute (their lateral parts are round-off sized)
                    worst = max(abs(x - y) for r, q in zip(ref["reactions"], other["reactions"]) for x, y in zip(r, q))
                    if worst > 1e-12 * 20.0:
                        failed.append(f"{name} at {ranks} rank(s): reactions differ by {worst:.3e} N from ASCII's")

            gmsh = shutil.which("gmsh")
            if not gmsh:
                print("skip the .geo against the gmsh program's mesh of it: no gmsh program")
                continue
            slab_bin = cli_mesh(gmsh, meshes / "two_layers.geo", work / "two_layers_cli.msh")
            check(f"two_layers.geo at {ranks} rank(s) = the gmsh program's mesh of it",
                  run(tissue, SLAB, slab_bin, ranks, work, f"slab_cli_np{ranks}"), slab_geo)
            geo = Path(args.source).resolve() / "run_scripts" / "scenes" / "cube_mesh.geo"
            cube = cli_mesh(gmsh, geo, work / "cube_h03.msh", "h = 0.3;\n")
            check(f"cube_mesh.geo, mesh_size = 0.3, at {ranks} rank(s) = the gmsh program's with h = 0.3",
                  run(tissue, CUBE, cube, ranks, work, f"cube_msh_np{ranks}"),
                  run(tissue, CUBE, geo, ranks, work, f"cube_geo_np{ranks}", extra="mesh_size = 0.3\n"))

    print(f"{passed} passed, {len(failed)} failed")
    return 1 if failed or passed == 0 else 0


if __name__ == "__main__":
    sys.exit(main())
