#!/usr/bin/env python3
"""The explicit topologies' accuracy table (docs/random_topology.md, .csv): every calibration method on random
clouds, on gmsh meshes and on random clouds inside gmsh meshes, of three densities each, pulled along x, y and z
(anisotropy), E measured by Eq. 3 against the target.

A random cube of n^3 molecules (n = 6, 10, 16: 216, 1000, 4096), a gmsh cube (run_scripts/scenes/cube_mesh.geo,
element sizes 0.25, 0.12, 0.07 m, meshed at run time), and the random topology inside the gmsh cube
(`mesh-random`: the cube meshed at the lattice spacing 1 / (n - 1), its boundary nodes kept and (n - 2)^3
molecules at random inside, Delaunay carved to the mesh; scene run_scripts/scenes/mesh_random_cube.toml); 1 m,
E = 100 kPa, rollers on the fixed face, 100 N on the opposite one (strain 1e-3), static solver, NP ranks.
`iterative` fits C on each axis: its row gives the C found, whose spread across x, y, z is the cloud's anisotropy
under the divided springs. `homogenized` on these bodies is one energy per tetrahedron carrying E and nu (the
springs at k = 0; docs/poisson.md, "Meshes and random clouds"). `manual` has no target modulus and is left out.

Usage (from the repository root, after building):
  /usr/bin/python3 run_scripts/random_accuracy.py [NP] [SEEDS] [TOPOLOGIES] [METHODS]
TOPOLOGIES (comma-separated, default random,mesh,mesh-random) and METHODS (comma-separated, default all below)
are run; the rows of the others are kept from docs/random_topology.csv, and the table is made from all rows.
"""
import csv
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NP = int(sys.argv[1]) if len(sys.argv) > 1 else 2
SEEDS = int(sys.argv[2]) if len(sys.argv) > 2 else 1
ALL_TOPOLOGIES = ["random", "mesh", "mesh-random"]
TOPOLOGIES = sys.argv[3].split(",") if len(sys.argv) > 3 else ALL_TOPOLOGIES
CSV = os.path.join(ROOT, "docs", "random_topology.csv")
TITLE = "# Explicit topologies: measured E per calibration method, density and axis"
BEGIN, END = "<!-- table: run_scripts/random_accuracy.py writes from here -->", "<!-- to here -->"
METHODS = ["linear", "statistical", "angles", "angles-update", "tetrahedral", "lloyd", "iterative", "homogenized"]
RUN_METHODS = sys.argv[4].split(",") if len(sys.argv) > 4 else METHODS
SIZES = [6, 10, 16]
MESH_SIZES = [0.25, 0.12, 0.07]  # gmsh element sizes (m)
AXES = {"x": ("x-", "x+", "[100.0, 0.0, 0.0]"), "y": ("y-", "y+", "[0.0, 100.0, 0.0]"),
        "z": ("z-", "z+", "[0.0, 0.0, 100.0]")}
ENV = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")


def mesh_file(h):
    """The gmsh cube at element size h, meshed once."""
    path = os.path.join(ROOT, "out", "random_accuracy", f"cube_h{h}.msh")
    if not os.path.exists(path):
        os.makedirs(os.path.dirname(path), exist_ok=True)
        subprocess.run(["gmsh", "-3", "-format", "msh41", "-setnumber", "h", str(h),
                        os.path.join(ROOT, "run_scripts", "scenes", "cube_mesh.geo"), "-o", path],
                       check=True, capture_output=True)
    return path


def run(method, n, axis, seed, topology="random"):
    fixed, loaded, force = AXES[axis]
    out = os.path.join(ROOT, "out", "random_accuracy", f"{topology}_{method}_{n}_{axis}_{seed}")
    cmd = ["mpirun", "--oversubscribe", "-np", str(NP), os.path.join(ROOT, "build", "tissue"), "run"]
    if topology == "random":
        cmd += [os.path.join(ROOT, "run_scripts", "scenes", "random_cube.toml"),
                "--set", f"body.molecules=[{n},{n},{n}]", "--set", f"body.seed={seed}"]
    elif topology == "mesh-random":  # the n^3 lattice's spacing and interior count, in the gmsh cube
        cmd += [os.path.join(ROOT, "run_scripts", "scenes", "mesh_random_cube.toml"),
                "--set", f"body.file={mesh_file(round(1 / (n - 1), 4))}",
                "--set", f"body.interior_molecules={(n - 2) ** 3}", "--set", f"body.seed={seed}"]
    else:
        cmd += [os.path.join(ROOT, "run_scripts", "scenes", "mesh_cube.toml"), "--set", f"body.file={mesh_file(n)}"]
    cmd += ["--output", out, "--set", f"calibration.method={method}", "--set", f"fix.0.face={fixed}",
            "--set", f"load.0.face={loaded}", "--set", f"load.0.force={force}"]
    p = subprocess.run(cmd, capture_output=True, env=ENV, text=True)
    row = {"topology": topology, "method": method, "size": n, "seed": seed, "axis": axis, "exit": p.returncode}
    if p.returncode != 0:
        row["note"] = (p.stderr.strip().splitlines() or [""])[0].split(": ", 2)[-1]
        return row
    with open(os.path.join(out, "summary.json")) as f:
        s = json.load(f)
    row.update(molecules=s["molecules"], connections=s["connections"], E=s["youngs_modulus_measured"], error_percent=s["error_percent"],
               divisor=s["calibration"].get("divisor"), iterations=s["solver"]["iterations"],
               wall_seconds=s["wall_seconds"])
    return row


def number(text):
    """A CSV field back to the int or float it was written from ('' stays '')."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def main():
    rows = []
    cases = [("random", n, seed) for n in SIZES for seed in range(1, SEEDS + 1)] + \
            [("mesh", h, 1) for h in MESH_SIZES] + \
            [("mesh-random", n, seed) for n in SIZES for seed in range(1, SEEDS + 1)]
    kept = []
    if os.path.exists(CSV):  # the rows of topologies and methods not run now
        with open(CSV) as f:
            kept = [{k: (v if k in ("topology", "method", "axis", "note") else number(v)) for k, v in r.items()}
                    for r in csv.DictReader(f) if r["topology"] not in TOPOLOGIES or r["method"] not in RUN_METHODS]
    for topology, n, seed in cases:
        for method in METHODS:
            if topology not in TOPOLOGIES or method not in RUN_METHODS:
                rows += [r for r in kept if r["topology"] == topology and r["method"] == method and r["size"] == n
                         and r["seed"] == seed]
                continue
            for axis in AXES:
                r = run(method, n, axis, seed, topology)
                rows.append(r)
                print(f"{topology} {method:14s} size={n} seed={seed} {axis}: " +
                      (f"E error {r['error_percent']:+8.3f} %" if r["exit"] == 0 else f"exit {r['exit']}: {r.get('note')}"),
                      flush=True)
                if r["exit"] != 0:
                    break  # a refusal is the same on every axis
    keys = ["topology", "method", "size", "molecules", "seed", "axis", "exit", "connections", "E", "error_percent", "divisor",
            "iterations", "wall_seconds", "note"]
    with open(CSV + ".tmp", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k, "") for k in keys})
    os.replace(CSV + ".tmp", CSV)

    partial = "" if TOPOLOGIES == ALL_TOPOLOGIES and RUN_METHODS == METHODS else " " + ",".join(TOPOLOGIES)
    partial += "" if RUN_METHODS == METHODS else " " + ",".join(RUN_METHODS)
    lines = [f"Generated by `/usr/bin/python3 run_scripts/random_accuracy.py {NP} {SEEDS}{partial}`"
             + (" (the other rows kept from an earlier run)" if partial else "") + " (scene "
             "`run_scripts/scenes/random_cube.toml`; raw rows in `docs/random_topology.csv`). A 1 m cube of n^3 "
             "molecules at random (seeded, boundary molecules on the faces, interior ones by dart throwing), "
             "joined by a Delaunay tetrahedralization (CGAL); E = 100 kPa, rollers, 100 N, static solver, "
             f"{NP} ranks. Error of Eq. 3's E against the target, in %, pulled along x, y and z; the spread "
             "(largest minus smallest of the three) is the anisotropy. For `iterative` the error is met by "
             "construction: the row gives the divisor C it found on each axis. The `mesh` rows: the same cube "
             "as gmsh tetrahedra (`run_scripts/scenes/cube_mesh.geo`, element sizes 0.25, 0.12, 0.07 m, faces "
             "named x- .. z+), scene `run_scripts/scenes/mesh_cube.toml`. The `mesh-random` rows: the random "
             "topology inside that gmsh cube (`shape = \"mesh\"`, `topology = \"random\"`), meshed at the lattice "
             "spacing 1 / (n - 1) = 0.2, 0.111, 0.0667 m: its boundary nodes stay and (n - 2)^3 = 64, 512, 2744 "
             "molecules at random fill it (Delaunay, carved to the mesh), scene "
             "`run_scripts/scenes/mesh_random_cube.toml`.", "",
             "| topology | method | molecules | x | y | z | mean | spread |", "|---|---|---|---|---|---|---|---|"]
    for topology in ALL_TOPOLOGIES:
        for method in METHODS:
            for topo, n, seed in [c for c in cases if c[0] == topology]:
                sel = {r["axis"]: r for r in rows
                       if r["topology"] == topo and r["method"] == method and r["size"] == n and r["seed"] == seed}
                count = next((r["molecules"] for r in sel.values() if r.get("molecules")),
                             n ** 3 if topo == "random" else "-")
                if not sel:
                    continue
                if any(r["exit"] != 0 for r in sel.values()):
                    note = next(r.get("note", "") for r in sel.values() if r["exit"] != 0)
                    code = next(iter(sel.values()))["exit"]
                    lines.append(f"| {topo} | {method} | {count} | refused (exit {code}): {note} | | | | |")
                    continue
                if method == "iterative":
                    c = [sel[a]["divisor"] for a in "xyz"]
                    lines.append(f"| {topo} | iterative (C) | {count} | {c[0]:.4f} | {c[1]:.4f} | {c[2]:.4f} | "
                                 f"{sum(c) / 3:.4f} | {max(c) - min(c):.4f} |")
                    continue
                e = [sel[a]["error_percent"] for a in "xyz"]
                lines.append(f"| {topo} | {method} | {count} | {e[0]:+.2f} | {e[1]:+.2f} | {e[2]:+.2f} | "
                             f"{sum(e) / 3:+.2f} | {max(e) - min(e):.2f} |")
    # The table goes between the markers; the notes around it are the doc's own.
    md = os.path.join(ROOT, "docs", "random_topology.md")
    text = "\n".join([TITLE, "", BEGIN] + lines + [END]) + "\n"
    if os.path.exists(md):
        with open(md) as f:
            old = f.read()
        if BEGIN in old and END in old:
            text = old[:old.index(BEGIN)] + text[text.index(BEGIN):] + old[old.index(END) + len(END) + 1:]
    with open(md + ".tmp", "w") as f:
        f.write(text)
    os.replace(md + ".tmp", md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
