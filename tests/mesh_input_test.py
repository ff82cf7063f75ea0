#!/usr/bin/env python3
"""Bad meshes fail cleanly: `tissue run` on a mesh scene whose mesh is missing, holds a non-tetrahedral
element, an inverted or flat tetrahedron, a version header its body does not follow, is cut short, is
partitioned, or lacks the physical group a fix, load or region names, or that asks for a random cloud in it with
a count missing, below 1 or more than fits, whose .geo Gmsh cannot read, holds no volume or makes Gmsh exit,
crash or run past its time limit (Gmsh runs in a child process), or that gives a mesh_size to a .msh or one not above 0, exits with code 2
and exactly one line on stderr naming the file and the problem, and writes nothing. A hand-made
one-tetrahedron mesh is the valid reference (it must run); the same tetrahedron as ASCII MSH 2.2 and (with the
gmsh program) binary MSH 4.1 and 2.2 must run and write its summary.json numbers (tests/mesh_formats_test.py's
comparison: 1e-12 relative, times and memory aside)."""
import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bad_input_test import Runner  # noqa: E402  the same one-line, exit-2, nothing-written checks
from mesh_formats_test import differences  # noqa: E402  summary.json numbers to 1e-12

NODES = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]


def msh(elements, nodes=NODES, version="4.1 0 8", volume_type=4):
    """A Gmsh 4.1 ASCII mesh: one volume entity (physical "body") holding `elements` (node-tag tuples) of
    `volume_type`, and two surface entities, physical "bottom" (z = 0) and "slope"."""
    lines = ["$MeshFormat", version, "$EndMeshFormat",
             "$PhysicalNames", "3", '2 2 "bottom"', '2 3 "slope"', '3 1 "body"', "$EndPhysicalNames",
             "$Entities", "0 0 2 1",
             "1 0 0 0 1 1 0 1 2 0", "2 0 0 0 1 1 1 1 3 0", "1 0 0 0 1 1 1 1 1 0", "$EndEntities",
             "$Nodes", f"1 {len(nodes)} 1 {len(nodes)}", f"3 1 0 {len(nodes)}"]
    lines += [str(i + 1) for i in range(len(nodes))]
    lines += [" ".join(str(c) for c in x) for x in nodes]
    lines += ["$EndNodes", "$Elements", f"3 {len(elements) + 2} 1 {len(elements) + 2}",
              "2 1 2 1", "1 1 3 2", "2 2 2 1", "2 2 3 4", f"3 1 {volume_type} {len(elements)}"]
    lines += [" ".join(str(v) for v in (i + 3, *e)) for i, e in enumerate(elements)]
    lines += ["$EndElements"]
    return "\n".join(lines) + "\n"


def msh22(elements, nodes=NODES):
    """The mesh of msh() as Gmsh MSH 2.2 ASCII: elements carry their physical and elementary tags."""
    lines = ["$MeshFormat", "2.2 0 8", "$EndMeshFormat",
             "$PhysicalNames", "3", '2 2 "bottom"', '2 3 "slope"', '3 1 "body"', "$EndPhysicalNames",
             "$Nodes", str(len(nodes))]
    lines += [" ".join(str(c) for c in (i + 1, *x)) for i, x in enumerate(nodes)]
    lines += ["$EndNodes", "$Elements", str(len(elements) + 2), "1 2 2 2 1 1 3 2", "2 2 2 3 2 2 3 4"]
    lines += [" ".join(str(v) for v in (i + 3, 4, 2, 1, 1, *e)) for i, e in enumerate(elements)]
    lines += ["$EndElements"]
    return "\n".join(lines) + "\n"


def scene(mesh_name, face="slope", region=None, body=""):
    text = f'[body]\nshape = "mesh"\nfile = "{mesh_name}"\nyoungs_modulus = 1.0e5\n{body}'
    if region:
        text += f'[[body.region]]\nname = "{region}"\nyoungs_modulus = 2.0e5\n'
    text += '[calibration]\nmethod = "tetrahedral"\n[[fix]]\nface = "bottom"\n'
    text += f'[[load]]\nface = "{face}"\nforce = [0.0, 0.0, 1.0]\n'
    return text


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--build", required=True)
    parser.add_argument("--source", required=True)
    args = parser.parse_args()
    tissue = (Path(args.build) / "tissue").resolve()
    runner = Runner(tissue, [])
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        # The reference: the valid one-tetrahedron mesh runs (exit 0).
        (tmp / "good.msh").write_text(msh([(1, 2, 3, 4)]))
        (tmp / "good.toml").write_text(scene("good.msh"))
        env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
        p = subprocess.run([str(tissue), "run", str(tmp / "good.toml"), "--output", str(tmp / "good_out")],
                           capture_output=True, env=env)
        if p.returncode != 0:
            print(f"FAIL the valid one-tetrahedron mesh did not run: {p.stderr.decode()}")
            return 1
        print("ok   valid one-tetrahedron mesh runs")
        # Other versions and the binary form run as the ASCII 4.1 file does.
        reference = json.loads((tmp / "good_out" / "summary.json").read_text())
        (tmp / "good22.msh").write_text(msh22([(1, 2, 3, 4)]))
        others = ["good22.msh"]
        gmsh = shutil.which("gmsh")
        for fmt in ("msh41", "msh22") if gmsh else ():
            subprocess.run([gmsh, str(tmp / "good.msh"), "-save", "-format", fmt, "-bin", "-o",
                            str(tmp / f"good_bin_{fmt}.msh")], check=True, capture_output=True)
            others.append(f"good_bin_{fmt}.msh")
        if not gmsh:
            print("skip binary one-tetrahedron meshes: no gmsh program")
        for name in others:
            (tmp / f"{name}.toml").write_text(scene(name))
            p = subprocess.run([str(tissue), "run", str(tmp / f"{name}.toml"), "--output", str(tmp / f"{name}_out")],
                               capture_output=True, env=env)
            diff = ([f"exit {p.returncode}: {p.stderr.decode()}"] if p.returncode != 0 else
                    differences(reference, json.loads((tmp / f"{name}_out" / "summary.json").read_text())))
            if diff:
                print(f"FAIL {name} does not run as good.msh: {diff[:6]}")
                return 1
            print(f"ok   {name} runs as good.msh")

        hex_nodes = NODES + [(1, 1, 0), (1, 0, 1), (0, 1, 1), (1, 1, 1)]
        cases = [  # (label, mesh file name, its text or None for missing, scene kwargs, texts the message needs)
            ("missing mesh", "absent.msh", None, {}, ["body.file", "absent.msh"]),
            ("hexahedron", "hex.msh", msh([(1, 2, 5, 3, 4, 6, 8, 7)], nodes=hex_nodes, volume_type=5), {},
             ["hex.msh", "hexahedron"]),
            ("10-node tetrahedron", "tet10.msh", msh([(1, 2, 3, 4, 1, 2, 3, 4, 1, 2)], volume_type=11), {},
             ["tet10.msh", "10-node tetrahedron"]),
            ("inverted tetrahedron", "inverted.msh", msh([(1, 3, 2, 4)]), {}, ["inverted.msh", "inverted"]),
            ("flat tetrahedron", "flat.msh", msh([(1, 2, 3, 4)], nodes=NODES[:3] + [(1, 1, 0)]), {},
             ["flat.msh", "flat"]),
            # A 2.2 header on a 4.1 body: Gmsh's own message (2.2 and binary files are read: above).
            ("version 2.2 header", "old.msh", msh([(1, 2, 3, 4)], version="2.2 0 8"), {},
             ["old.msh", "Gmsh cannot read it"]),
            ("cut short", "short.msh", msh([(1, 2, 3, 4)])[:-40], {}, ["short.msh", "line"]),
            ("unknown node", "node.msh", msh([(1, 2, 3, 9)]), {}, ["node.msh", "node 9"]),
            ("not a mesh", "text.msh", "hello\n", {}, ["text.msh", "MeshFormat"]),
            ("unknown face", "good.msh", "", {"face": "lid"}, ["load[0].face", "lid", "good.msh"]),
            ("unknown region", "good.msh", "", {"region": "cortex"}, ["body.region[0].name", "cortex", "good.msh"]),
            # topology = "random" in the mesh's volume (src/model/mesh_cloud.hpp)
            ("no interior count", "good.msh", "", {"body": 'topology = "random"\n'},
             ["body.interior_molecules", "missing"]),
            ("zero interior molecules", "good.msh", "", {"body": 'topology = "random"\ninterior_molecules = 0\n'},
             ["body.interior_molecules", ">= 1", "0"]),
            ("negative interior molecules", "good.msh", "",
             {"body": 'topology = "random"\ninterior_molecules = -5\n'}, ["body.interior_molecules", "-5"]),
            ("interior count without random", "good.msh", "", {"body": 'interior_molecules = 10\n'},
             ["body.interior_molecules", "random"]),
            ("seed without random", "good.msh", "", {"body": 'seed = 2\n'}, ["body.seed", "random"]),
            # One tetrahedron's inradius (0.21 m) is below the spacing one molecule asks for (0.28 m): no room.
            ("no room inside", "good.msh", "", {"body": 'topology = "random"\ninterior_molecules = 1\n'},
             ["body.interior_molecules", "good.msh", "placed only 0 of 1"]),
            # .geo geometries, meshed at run time (io/gmsh_mesh.cpp), and their mesh_size
            ("bad geometry", "bad.geo", 'SetFactory("OpenCASCADE");\nBox(1) = {0, 0, 0, 1, 1;\n', {},
             ["bad.geo", "Gmsh cannot read it", "line 2"]),
            ("geometry without a volume", "square.geo", 'SetFactory("OpenCASCADE");\nRectangle(1) = {0, 0, 0, 1, 1};\n',
             {}, ["square.geo", "no tetrahedra"]),
            # Gmsh runs in a child process (io/gmsh_mesh.cpp): when it exits or crashes, the run still ends in one line
            ("Gmsh exits", "exit.geo", 'SetFactory("OpenCASCADE");\nBox(1) = {0, 0, 0, 1, 1, 1};\nExit;\n', {},
             ["exit.geo", "Gmsh exited with status 0 without a result"]),
            ("Gmsh crashes", "segv.geo",
             'SetFactory("OpenCASCADE");\nBox(1) = {0, 0, 0, 1, 1, 1};\nSystemCall "kill -SEGV $PPID";\n', {},
             ["segv.geo", "Gmsh died with signal 11"]),
            ("Gmsh runs away", "loop.geo", "For i In {1:1e15}\n  x = i;\nEndFor\n", {},  # TISSUE_GMSH_SECONDS=2
             ["loop.geo", "Gmsh did not finish reading it in 2 s"]),
            ("mesh_size on a mesh file", "good.msh", "", {"body": "mesh_size = 0.1\n"}, ["body.mesh_size", ".geo"]),
            ("zero mesh_size", "cube.geo", 'SetFactory("OpenCASCADE");\nBox(1) = {0, 0, 0, 1, 1, 1};\n',
             {"body": "mesh_size = 0.0\n"}, ["body.mesh_size", "0"]),
        ]
        if gmsh:  # a partitioned mesh (tissue partitions the model itself)
            subprocess.run([gmsh, str(Path(args.source) / "tests" / "meshes" / "two_layers.msh"), "-part", "2",
                            "-save", "-format", "msh41", "-o", str(tmp / "part.msh")], check=True, capture_output=True)
            cases.append(("partitioned", "part.msh", "", {}, ["part.msh", "partitioned"]))
        for label, name, text, kw, expects in cases:
            if text:
                (tmp / name).write_text(text)
            s = tmp / f"{label.replace(' ', '_')}.toml"
            s.write_text(scene(name, **kw))
            if label == "Gmsh runs away":  # the child's time limit, cut from none (a .geo) to 2 s
                os.environ["TISSUE_GMSH_SECONDS"] = "2"
            with tempfile.TemporaryDirectory() as work:
                runner.check(label, s, expects, workdir=work)
            os.environ.pop("TISSUE_GMSH_SECONDS", None)
    for f in runner.failed:
        print(f"FAIL {f}")
    print(f"{runner.passed} passed, {len(runner.failed)} failed")
    return 1 if runner.failed or runner.passed != len(cases) else 0


if __name__ == "__main__":
    sys.exit(main())
