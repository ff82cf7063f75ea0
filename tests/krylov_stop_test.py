#!/usr/bin/env python3
"""The later Newton steps' Krylov stop (newton_equilibrium.cpp, converged_or_enough): a Newton step after the first
ends its Krylov solve once CG's residual is below 0.1 of the Newton tolerance. Checked against the old path
(`-static_enough_fraction 0`: the 1e-10 relative tolerance alone) on the LAMMPS peer tension scene
(run_scripts/scenes/peer_tension.toml, 20^3, the load of the bench and 10x it), 1, 2 and 3 ranks:
  - the same Newton count, converged, the summary's residual within solver.tolerance (1e-8);
  - no more Krylov iterations in any run, fewer in total (the stop is taken);
  - elongation and the measured E within 1e-9 relative of the old path's.

Usage: krylov_stop_test.py --build BUILD_DIR --source SOURCE_DIR      Prints 'N passed, M failed'."""
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import arguments_and_work, check, report, tissue  # noqa: E402


def main():
    a, work = arguments_and_work("krylov_stop")
    scene = os.path.join(a.source, "run_scripts", "scenes", "peer_tension.toml")
    fewer = 0
    for ranks in (1, 2, 3):
        for force in (0.4, 4.0):
            runs = {}
            for label, extra in (("new", []), ("old", ["--", "-static_enough_fraction", "0"])):
                out = os.path.join(work, f"{label}_np{ranks}_f{force}")
                r = tissue(a.build, ranks, "run", scene, "--set", f"load.0.force=[0,0,-{force}]", "--set",
                           "solver.tolerance=1e-8", "--set", "output.fields=[]", "--set", "output.progress=false",
                           "--output", out, *extra)
                if check(r.returncode == 0, f"{label}, {ranks} ranks, force {force}: exit {r.returncode}: {r.stderr[-300:]}"):
                    with open(os.path.join(out, "summary.json")) as f:
                        runs[label] = json.load(f)
            if len(runs) < 2:
                continue
            new, old = runs["new"], runs["old"]
            what = f"{ranks} ranks, force {force}"
            ns, os_ = new["solver"], old["solver"]
            check(ns["converged"] and ns["residual"] <= 1e-8, f"{what}: converged, residual {ns['residual']} <= 1e-8")
            check(ns["iterations"] == os_["iterations"], f"{what}: Newton {ns['iterations']} == {os_['iterations']}")
            check(ns["linear_iterations"] <= os_["linear_iterations"],
                  f"{what}: Krylov {ns['linear_iterations']} <= {os_['linear_iterations']}")
            fewer += os_["linear_iterations"] - ns["linear_iterations"]
            for key in ("elongation", "youngs_modulus_measured"):
                rel = abs(new[key] - old[key]) / abs(old[key])
                check(rel <= 1e-9, f"{what}: {key} {new[key]!r} against {old[key]!r}: relative {rel:.2e} <= 1e-9")
    check(fewer > 0, f"the stop saved Krylov iterations in total: {fewer}")
    return report()


if __name__ == "__main__":
    sys.exit(main())
