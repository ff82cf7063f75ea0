#!/usr/bin/env python3
"""The stability matrix: `tissue run` at the extremes of every input, one cell per run, and a verdict per cell.

Axes (each varied from a base cell, for every solver kind that applies): Young's modulus 1 Pa .. 20 GPa, density
100 .. 2500 kg/m^3, molecule count 2x2x2 .. 100^3 (the big ones only with --full), aspect ratio up to 1:100 (a
thin sheet and a long ligament), stiffness ratio up to 1e6 inside one body ([[body.region]] of another E), time
step 0.1 .. 1.5 x the critical one (relaxation, dynamic), load up to 50 % strain.

Rule checked in every cell (the test fails otherwise): no silent NaN. Then: a state that turns non-finite between
the dynamic guard's reductions is never written (written_states_are_finite). Exit 0 means every number in summary.json
that the cell reports is finite; exit 3 means one stderr line names the step and the molecule; exit 2 (a time
step above the critical one without solver.allow_unstable_time_step) means one stderr line naming
solver.time_step. Any other outcome (a crash, a hang, exit 0 with a NaN) is a failure.

  tests/stability_test.py --build build --source .                  # the fast part (ctest: stability)
  tests/stability_test.py --build build --source . --full \\
      --csv docs/stability.csv --md docs/stability.md               # the whole matrix (run_scripts/stability.sh)
"""
import argparse
import csv
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BASE = """title = "stability cell"
[body]
molecules = [{nx}, {ny}, {nz}]
size = [{lx}, {ly}, {lz}]
topology = "face-diagonals"
youngs_modulus = {E}
density = {rho}
{region}
[calibration]
method = "linear"

[[fix]]
face = "z+"
mode = "clamped"

[[load]]
face = "z-"
force = [0.0, 0.0, {F}]

[solver]
kind = "{solver}"
{solver_extra}
[output]
progress = false
fields = ["positions"]
"""


class Cell:
    def __init__(self, axis, value, solver, n=(5, 5, 5), size=(1.0, 1.0, 1.0), E=1e5, rho=1000.0, strain=1e-3,
                 region_ratio=None, dt_factor=None, allow=False, steps=None, timeout=600, guards=True):
        self.axis, self.value, self.solver = axis, value, solver
        self.n, self.size, self.E, self.rho, self.strain = n, size, E, rho, strain
        self.region_ratio, self.dt_factor, self.allow, self.steps = region_ratio, dt_factor, allow, steps
        self.timeout, self.guards = timeout, guards

    def scene(self, dt=None):
        region = ""
        if self.region_ratio:
            # the lower half of the body (z below the middle) stiffer by region_ratio
            region = ("[[body.region]]\nlo = [0, 0, 0]\nhi = [%r, %r, %r]\nyoungs_modulus = %r\n"
                      % (self.size[0], self.size[1], 0.5 * self.size[2], self.E * self.region_ratio))
        area = self.size[0] * self.size[1]
        extra = ["tolerance = 1e-8" if self.solver != "dynamic" else ""]
        if dt is not None:
            extra.append("time_step = %r" % dt)
        if self.allow:
            extra.append("allow_unstable_time_step = true")
        if self.solver == "dynamic":
            extra.append("steps = %d" % (self.steps or 2000))
        return BASE.format(nx=self.n[0], ny=self.n[1], nz=self.n[2], lx=self.size[0], ly=self.size[1],
                           lz=self.size[2], E=repr(self.E), rho=repr(self.rho), region=region,
                           F=repr(-self.strain * self.E * area), solver=self.solver,
                           solver_extra="\n".join(e for e in extra if e))

    def label(self):
        return f"{self.axis}={self.value} {self.solver}" + ("" if self.guards else " -tissue_guards false")


def finite(x):
    return x is None or (isinstance(x, (int, float)) and math.isfinite(x))


def run_cell(tissue, launcher, cell, workdir):
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    if not cell.guards:
        env["PETSC_OPTIONS"] = (env.get("PETSC_OPTIONS", "") + " -tissue_guards false").strip()
    scene = Path(workdir) / "cell.toml"
    out = Path(workdir) / "out"
    dt = None
    critical = None
    if cell.dt_factor is not None:
        # the critical time step of this body, from a zero-step dynamic probe
        probe = Cell(cell.axis, cell.value, "dynamic", cell.n, cell.size, cell.E, cell.rho, cell.strain,
                     cell.region_ratio, steps=0)
        scene.write_text(probe.scene())
        subprocess.run(launcher + [str(tissue), "run", str(scene), "--output", str(out)], capture_output=True,
                       env=env, timeout=cell.timeout)
        critical = json.loads((out / "summary.json").read_text())["solver"]["critical_time_step"]
        dt = cell.dt_factor * critical
        subprocess.run(["rm", "-rf", str(out)])
    scene.write_text(cell.scene(dt))
    cmd = launcher + [str(tissue), "run", str(scene), "--output", str(out)]
    start = time.monotonic()
    try:
        p = subprocess.run(cmd, capture_output=True, env=env, timeout=cell.timeout)
        code, stderr = p.returncode, p.stderr.decode("utf-8", "replace")
    except subprocess.TimeoutExpired:
        code, stderr = "timeout", ""
    wall = time.monotonic() - start
    summary = {}
    if (out / "summary.json").exists():
        summary = json.loads((out / "summary.json").read_text())
    lines = [l for l in stderr.splitlines() if l.strip() and not l.startswith("tissue: ") or "tissue: " in l]
    message = ""
    problems = []
    solver = summary.get("solver", {}) or {}
    if code == 0:
        for key in ("youngs_modulus_measured", "elongation", "kinetic_energy", "energy_final"):
            if not finite(summary.get(key)):
                problems.append(f"exit 0 but {key} = {summary.get(key)}")
        # warnings (e.g. solver.tolerance raised to the round-off floor) go into the table's message column
        message = " ".join(l for l in stderr.splitlines() if "warning:" in l)
        # every cell pulls on its z- face: exit 0 without a measured modulus is a silent non-answer
        if summary.get("youngs_modulus_measured") is None:
            problems.append(f"exit 0 but no modulus measured (elongation {summary.get('elongation')}, "
                            f"residual {solver.get('residual')})")
        if not finite(solver.get("residual")):
            problems.append(f"exit 0 but residual = {solver.get('residual')}")
    elif code == 3:
        failure = [l for l in stderr.splitlines() if l.startswith("tissue: ") and ("step" in l or "iteration" in l)
                   and "molecule" in l]
        not_converged = [l for l in stderr.splitlines() if "not converged" in l]
        if not failure and not not_converged:
            problems.append("exit 3 without a line naming the step and the molecule")
        message = (failure or not_converged or [""])[-1]
        if "last good state" in message and not (out / "last_good.h5").exists():
            problems.append("last good state announced but last_good.h5 missing")
        if not cell.guards:
            # unguarded (benchmarks): no earlier state is kept, so the failed run must write no state at all
            if "-tissue_guards false" not in message:
                problems.append("unguarded failure without saying that no state was kept")
            for name in ("final.h5", "last_good.h5"):
                if (out / name).exists():
                    problems.append(f"unguarded failure wrote {name}")
    elif code == 2:
        # the refusal comes after the start-up lines (counts, critical time step) that main() prints first
        err = [l for l in stderr.splitlines() if "solver.time_step" in l]
        message = err[0] if err else ""
        if len(err) != 1:
            problems.append(f"exit 2 without one line naming solver.time_step: {stderr!r}")
        if out.exists():
            problems.append("exit 2 left output behind")
    else:
        problems.append(f"exit {code}")
        message = stderr.strip().splitlines()[-1] if stderr.strip() else ""
    n = cell.n[0] * cell.n[1] * cell.n[2]
    err = summary.get("error_percent")
    row = {
        "axis": cell.axis, "value": cell.value, "solver": cell.solver, "molecules": n,
        "dt_over_critical": cell.dt_factor if cell.dt_factor is not None else "",
        "exit": code, "converged": solver.get("converged", ""),
        "E_target": cell.E, "E_measured": summary.get("youngs_modulus_measured", ""),
        "error_percent": err if err is not None else "",
        "iterations": solver.get("iterations", ""), "residual": solver.get("residual", ""),
        "energy_drift": "", "wall_s": round(wall, 3), "message": message.replace("tissue: ", "")[:300],
        "verdict": "FAIL: " + "; ".join(problems) if problems else "ok",
    }
    if cell.solver == "dynamic" and summary.get("energy_initial") is not None:
        e0, e1 = summary.get("energy_initial"), summary.get("energy_final")
        if finite(e0) and finite(e1) and e0 is not None and e1 is not None:
            row["energy_drift"] = abs(e1 - e0) / max(abs(e0), abs(summary.get("kinetic_energy") or 0), 1e-300)
    return row


def fast_cells():
    cells = []
    kinds = ("static", "relaxation", "dynamic")
    for E in (1.0, 1e5, 2e10):
        for k in kinds:
            cells.append(Cell("E", E, k, E=E, n=(4, 4, 4)))
    for rho in (100.0, 2500.0):
        cells.append(Cell("density", rho, "dynamic", rho=rho, n=(4, 4, 4)))
    for k in kinds:
        cells.append(Cell("molecules", "2x2x2", k, n=(2, 2, 2)))
    cells.append(Cell("aspect", "sheet 1:100", "static", n=(11, 11, 2), size=(1.0, 1.0, 0.01)))
    cells.append(Cell("aspect", "ligament 1:100", "static", n=(2, 2, 21), size=(0.01, 0.01, 1.0)))
    cells.append(Cell("stiffness_ratio", 1e6, "static", region_ratio=1e6, n=(4, 4, 6)))
    for f in (0.5, 1.5):
        cells.append(Cell("time_step", f, "dynamic", dt_factor=f, allow=True, n=(4, 4, 4), steps=400))
    cells.append(Cell("time_step", "1.5 (not allowed)", "dynamic", dt_factor=1.5, n=(4, 4, 4)))
    # unguarded: only the final check runs, it must still refuse the blown-up state and write nothing
    cells.append(Cell("time_step", 10, "dynamic", dt_factor=10, allow=True, n=(4, 4, 4), steps=400, guards=False))
    for k in ("static", "relaxation"):
        cells.append(Cell("strain", 0.5, k, strain=0.5, n=(4, 4, 4)))
    return cells


def full_cells():
    cells = []
    kinds = ("static", "relaxation", "dynamic")
    for E in (1.0, 1e3, 1e5, 1e7, 1e9, 2e10):
        for k in kinds:
            cells.append(Cell("E", E, k, E=E))
    for rho in (100.0, 1000.0, 2500.0):
        for k in kinds:
            cells.append(Cell("density", rho, k, rho=rho))
    for n in (2, 5, 10, 20, 40):
        for k in kinds:
            cells.append(Cell("molecules", f"{n}^3", k, n=(n, n, n), timeout=3600))
    cells.append(Cell("molecules", "60^3", "dynamic", n=(60, 60, 60), steps=200, timeout=3600))
    cells.append(Cell("molecules", "100^3", "dynamic", n=(100, 100, 100), steps=50, timeout=3600))
    cells.append(Cell("molecules", "100^3", "static", n=(100, 100, 100), timeout=7200))
    for label, n, size in (("sheet 1:10", (11, 11, 2), (1.0, 1.0, 0.1)), ("sheet 1:100", (21, 21, 2), (1.0, 1.0, 0.01)),
                           ("ligament 1:10", (2, 2, 11), (0.1, 0.1, 1.0)),
                           ("ligament 1:100", (2, 2, 41), (0.01, 0.01, 1.0)),
                           ("ligament 1:100, 3x3", (3, 3, 41), (0.01, 0.01, 1.0))):
        for k in kinds:
            cells.append(Cell("aspect", label, k, n=n, size=size))
    for ratio in (1e2, 1e4, 1e6):
        for k in kinds:
            cells.append(Cell("stiffness_ratio", ratio, k, region_ratio=ratio, n=(5, 5, 8)))
    for f in (0.1, 0.5, 0.9, 1.0, 1.1, 1.2, 1.5):
        for k in ("relaxation", "dynamic"):
            cells.append(Cell("time_step", f, k, dt_factor=f, allow=f > 1.0))
    cells.append(Cell("time_step", "1.5 (not allowed)", "dynamic", dt_factor=1.5))
    cells.append(Cell("time_step", "1.5 (not allowed)", "relaxation", dt_factor=1.5))
    for s in (1e-3, 0.01, 0.1, 0.3, 0.5):
        for k in kinds:
            cells.append(Cell("strain", s, k, strain=s))
    # tiny strains: the load falls towards the round-off floor of the force residual (solver.tolerance is raised to
    # it with a warning; docs/stability.md, precision)
    for s in (1e-6, 1e-10, 1e-14):
        for k in ("static", "relaxation"):
            cells.append(Cell("strain", s, k, strain=s))
    return cells


COLUMNS = ["axis", "value", "solver", "molecules", "dt_over_critical", "exit", "converged", "E_target",
           "E_measured", "error_percent", "iterations", "residual", "energy_drift", "wall_s", "verdict", "message"]


def fmt(v):
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def write_md(rows, path, command):
    with open(path, "w") as f:
        f.write("<!-- generated by run_scripts/stability.sh; the prose around it lives in docs/stability.md's "
                "header (kept by the script) -->\n")
        f.write(f"Command: `{command}`\n\n")
        f.write("| " + " | ".join(COLUMNS) + " |\n|" + "---|" * len(COLUMNS) + "\n")
        for r in rows:
            f.write("| " + " | ".join(fmt(r[c]).replace("|", "/") for c in COLUMNS) + " |\n")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--build", required=True)
    parser.add_argument("--source", required=True)
    parser.add_argument("--launcher", default="")
    parser.add_argument("--full", action="store_true", help="the whole matrix (hours on 2 cores with --big)")
    parser.add_argument("--big", action="store_true", help="with --full: the 60^3 and 100^3 cells too")
    parser.add_argument("--big-only", action="store_true",
                        help="with --full --big: only the cells of 100,000 molecules and more (60^3, 100^3)")
    parser.add_argument("--only", default="", help="only the cells of this axis")
    parser.add_argument("--csv", default="")
    parser.add_argument("--md", default="")
    args = parser.parse_args()
    tissue = (Path(args.build) / "tissue").resolve()
    if not tissue.is_file():
        print(f"{tissue} does not exist: build it first")
        return 1
    cells = full_cells() if args.full else fast_cells()
    if not args.big:
        cells = [c for c in cells if c.n[0] * c.n[1] * c.n[2] < 100000]
    if args.big_only:
        cells = [c for c in cells if c.n[0] * c.n[1] * c.n[2] >= 100000]
    if args.only:
        cells = [c for c in cells if c.axis == args.only]
    # the small cells first (stable sort: axis order kept within a size), so that an interrupted run has every axis
    cells.sort(key=lambda c: c.n[0] * c.n[1] * c.n[2] >= 8000)
    rows = []
    command = " ".join(["tests/stability_test.py"] + sys.argv[1:])

    def write(partial):
        # rewritten after every cell, so that an interrupted matrix keeps the cells it finished
        note = f" (partial: {len(rows)} of {len(cells)} cells)" if partial else ""
        if args.csv:
            with open(args.csv, "w", newline="") as f:
                w = csv.DictWriter(f, fieldnames=COLUMNS)
                w.writeheader()
                w.writerows(rows)
        if args.md:
            write_md(rows, args.md, command + note)

    for cell in cells:
        with tempfile.TemporaryDirectory() as tmp:
            row = run_cell(tissue, args.launcher.split(), cell, tmp)
        rows.append(row)
        print(f"{row['verdict'][:4]:4} {cell.label():40} exit {row['exit']!s:3} conv {row['converged']!s:5} "
              f"err% {fmt(row['error_percent']):>10} it {row['iterations']!s:>7} {row['wall_s']:8.2f}s "
              f"{row['message'][:150]}", flush=True)
        write(partial=len(rows) < len(cells))
    write(partial=False)
    bad = [r for r in rows if r["verdict"] != "ok"]
    print(f"{len(rows) - len(bad)} cells ok, {len(bad)} failed the no-silent-failure rule")
    return 1 if bad or not written_states_are_finite(tissue, args.source) else 0


def written_states_are_finite(tissue, source):
    """A state that turns non-finite between the dynamic guard's periodic reductions is reported at the first step
    whose state is written, never written: a 1e300 N load blows up at step 1, and with a history row every step and
    a snapshot and a checkpoint every 5, the run must stop at step 1 (exit 3), with no snapshot or checkpoint and
    every history.csv cell finite, at 1, 2 and 3 ranks (it wrote NaN rows, snapshots and a checkpoint up to step 17
    before)."""
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    ok = True
    for np_ in (1, 2, 3):
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "out"
            cmd = ["mpirun", "--quiet", "--oversubscribe", "-np", str(np_), str(tissue), "run",
                   str(Path(source) / "run_scripts" / "scenes" / "table2.toml"), "--set", "body.molecules=[4,4,4]",
                   "--set", "solver.kind=dynamic", "--set", "solver.steps=40", "--set", "load.0.force=[0,0,-1e300]",
                   "--set", "output.history_every=1", "--set", "output.snapshot_every=5",
                   "--set", "output.checkpoint_every=5", "--output", str(out)]
            p = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120)
            written = sorted(f.name for f in list(out.glob("snapshot_*.h5")) + list(out.glob("checkpoint_*.h5")))
            rows = list(csv.reader(open(out / "history.csv"))) if (out / "history.csv").exists() else []
            cells = [c for r in rows[1:] for c in r if c]
            finite = all(math.isfinite(float(c)) for c in cells)
            good = p.returncode == 3 and "at step 1:" in p.stderr and not written and finite and len(rows) >= 2
            ok = ok and good
            print(f"{'ok' if good else 'FAIL'} non-finite at step 1, {np_} rank(s): exit {p.returncode}, "
                  f"files {written}, {len(rows) - 1} history rows, finite {finite}: "
                  f"{([l for l in p.stderr.splitlines() if l.startswith('tissue: ')] or [''])[-1][:160]}", flush=True)
    return ok


if __name__ == "__main__":
    sys.exit(main())
