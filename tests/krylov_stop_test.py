#!/usr/bin/env python3
"""The later Newton steps' Krylov stop (newton_equilibrium.cpp, converged_or_enough, before_newton_step): a Newton
step after the first ends its Krylov solve once CG's residual is below 0.1 of the Newton tolerance, or below half
of what the tolerance leaves beyond the step's predicted nonlinear remainder (r_k^3 / r_(k-1)^2) when that is
more. Checked against the fixed fraction alone (`-static_enough_share 0`) and the old path
(`-static_enough_fraction 0`: the 1e-10 relative tolerance alone), 1, 2 and 3 ranks, on
  - the LAMMPS peer tension scene (run_scripts/scenes/peer_tension.toml, 20^3, the load of the bench and 10x it);
  - the cell term's block (run_scripts/scenes/poisson_block.toml, 20^3, nu = 0.45, strain 1e-4 and 1e-2):
  - the same Newton count on every path, converged, the summary's residual within solver.tolerance (1e-8);
  - Krylov iterations new <= fixed <= old in every run, fewer in total for each stop (each is taken);
  - elongation and the measured E within 1e-8 relative of the old path's (the tolerance).

Usage: krylov_stop_test.py --build BUILD_DIR --source SOURCE_DIR      Prints 'N passed, M failed'."""
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import arguments_and_work, check, report, tissue  # noqa: E402

PATHS = (("new", []), ("fixed", ["-static_enough_share", "0"]), ("old", ["-static_enough_fraction", "0"]))


def cases(source):
    peer = os.path.join(source, "run_scripts", "scenes", "peer_tension.toml")
    block = os.path.join(source, "run_scripts", "scenes", "poisson_block.toml")
    for force in (0.4, 4.0):
        yield f"peer, force {force}", peer, ["--set", f"load.0.force=[0,0,-{force}]"]
    for strain in (1e-4, 1e-2):
        force = 1.0e7 * strain * (19 * 0.001) ** 2
        yield f"nu 0.45 block, strain {strain}", block, ["--set", "body.molecules=[20,20,20]", "--set",
                                                         "body.poisson_ratio=0.45", "--set",
                                                         f"load.0.force=[0,0,{force}]"]


def main():
    a, work = arguments_and_work("krylov_stop")
    fewer = {"new": 0, "fixed": 0}
    for ranks in (1, 2, 3):
        for c, (name, scene, sets) in enumerate(cases(a.source)):
            runs = {}
            for label, extra in PATHS:
                out = os.path.join(work, f"{label}_np{ranks}_{c}")
                r = tissue(a.build, ranks, "run", scene, *sets, "--set", "solver.tolerance=1e-8", "--set",
                           "output.fields=[]", "--set", "output.progress=false", "--output", out,
                           *(["--", *extra] if extra else []))
                if check(r.returncode == 0, f"{label}, {ranks} ranks, {name}: exit {r.returncode}: {r.stderr[-300:]}"):
                    with open(os.path.join(out, "summary.json")) as f:
                        runs[label] = json.load(f)
            if len(runs) < 3:
                continue
            what = f"{ranks} ranks, {name}"
            s = {label: runs[label]["solver"] for label, _ in PATHS}
            for label, _ in PATHS:
                check(s[label]["converged"] and s[label]["residual"] <= 1e-8,
                      f"{what}, {label}: converged, residual {s[label]['residual']} <= 1e-8")
                check(s[label]["iterations"] == s["old"]["iterations"],
                      f"{what}, {label}: Newton {s[label]['iterations']} == {s['old']['iterations']}")
            k = {label: s[label]["linear_iterations"] for label, _ in PATHS}
            check(k["new"] <= k["fixed"] <= k["old"], f"{what}: Krylov new {k['new']} <= fixed {k['fixed']} <= old {k['old']}")
            fewer["new"] += k["fixed"] - k["new"]
            fewer["fixed"] += k["old"] - k["fixed"]
            for label in ("new", "fixed"):
                for key in ("elongation", "youngs_modulus_measured"):
                    rel = abs(runs[label][key] - runs["old"][key]) / abs(runs["old"][key])
                    check(rel <= 1e-8, f"{what}, {label}: {key} {runs[label][key]!r} against {runs['old'][key]!r}: "
                                       f"relative {rel:.2e} <= 1e-8")
    check(fewer["fixed"] > 0, f"the fixed fraction's stop saved Krylov iterations in total: {fewer['fixed']}")
    check(fewer["new"] > 0, f"the predicted remainder's stop saved Krylov iterations beyond it in total: {fewer['new']}")
    return report()


if __name__ == "__main__":
    sys.exit(main())
